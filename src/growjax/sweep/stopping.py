"""Stop a chunked run between chunks on SIGINT or SIGTERM; a second signal stops it at once."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator

__all__ = ["SIGNALS", "Stopper"]

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Stopper:
    """Within ``with Stopper() as stop:``, SIGINT and SIGTERM set ``stop.signal`` (the loop checks it after each
    chunk); a second signal raises ``KeyboardInterrupt`` at once, or, inside ``stop.writing()``, right after the
    write. Handlers are installed only in the main thread (elsewhere signals keep Python's behaviour).

    Args:
        announce: whether the first signal writes a line on ``sys.stderr``.

    Attributes:
        signal: the first signal received, or None.
    """

    def __init__(self, announce: bool = True) -> None:
        self.signal: int | None = None
        self.announce = announce
        self._writing = False
        self._now = False
        self._previous: dict = {}

    def __enter__(self) -> Stopper:
        if threading.current_thread() is threading.main_thread():
            for s in SIGNALS:
                self._previous[s] = signal.signal(s, self._handle)
        return self

    def __exit__(self, *exc: object) -> bool:
        for s, handler in self._previous.items():
            signal.signal(s, handler)
        self._previous.clear()
        return False

    def _handle(self, signum, frame):
        if self.signal is None:
            self.signal = signum
            if self.announce:
                print(
                    f"growjax: {signal.Signals(signum).name} received: stopping after the chunk in flight "
                    "(again: stop now, dropping it)",
                    file=sys.stderr,
                    flush=True,
                )
            return
        if self._writing:
            self._now = True
            return
        raise KeyboardInterrupt

    @contextlib.contextmanager
    def writing(self) -> Iterator[None]:
        """A block that a second signal does not cut (a chunk being written to disk)."""
        self._writing = True
        try:
            yield
        finally:
            self._writing = False
        if self._now:
            raise KeyboardInterrupt
