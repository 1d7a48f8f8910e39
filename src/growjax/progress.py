"""Progress output that fits where it goes: a bar on a terminal, a plain line every ~10 % elsewhere, nothing
when quiet.

``bar(total, desc, unit, enabled)`` returns an object with ``update(n)`` and ``close()`` (also a context
manager): ``tqdm`` where the stream is a terminal; `Lines` where it is a file or a pipe (a log of a
batch job: at most ~11 lines of ~60 characters per bar); `Silent` when not ``enabled``.
``note(text, enabled)`` writes one line (a phase starting or ending) on the same stream. The stream is
``sys.stderr`` unless given, read when called (so that a redirected or captured stream is the one used).
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Any, TextIO

__all__ = ["Lines", "Silent", "bar", "is_terminal", "note", "terminal"]

STEP = 0.1  # a line each time this share of the total is passed (non-terminal streams)


def is_terminal(stream: TextIO) -> bool:
    """Whether ``stream`` is an interactive terminal."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


class Silent:
    """A progress object that shows nothing."""

    def update(self, n: int = 1) -> None:
        """Count ``n`` more steps done."""

    def close(self) -> None:
        """End the progress."""

    def __enter__(self) -> Silent:
        return self

    def __exit__(self, *exc: object) -> bool:
        self.close()
        return False


class Lines(Silent):
    """One line ``desc: k/total unit (p %), t s`` each time another ``step`` of ``total`` is done, and at the end;
    thread-safe.

    Args:
        total: the number of steps.
        desc, unit: the line's label and the steps' unit (plural with an s).
        stream: where the lines go (``sys.stderr`` if None).
        step: the share of ``total`` between lines.
    """

    def __init__(self, total: int, desc: str, unit: str = "", stream=None, step: float = STEP):
        self.total, self.desc, self.unit, self.step = max(int(total), 0), desc, unit, step
        self.stream = stream if stream is not None else sys.stderr
        self.done, self._shown, self._written, self._closed = 0, 0, -1, False
        self._start = time.perf_counter()
        self._lock = threading.Lock()

    def update(self, n: int = 1) -> None:
        """Count ``n`` more steps done; write a line where another ``step`` of the total is passed."""
        with self._lock:
            self.done += n
            if (
                self.total
                and self.done < self.total
                and self.done / self.total >= (self._shown + 1) * self.step - 1e-12
            ):
                self._shown = int(self.done / self.total / self.step + 1e-9)
                self._write()

    def close(self) -> None:
        """Write the last line (unless written) and end."""
        with self._lock:
            if not self._closed and self.total and self._written != self.done:
                self._write()
            self._closed = True

    def _write(self) -> None:
        self._written = self.done
        unit = f" {self.unit}s" if self.unit else ""
        pct = 100.0 * self.done / self.total
        _write_line(
            f"{self.desc}: {self.done}/{self.total}{unit} ({pct:.0f} %), {time.perf_counter() - self._start:.1f} s",
            self.stream,
        )


_WRITING = threading.Lock()  # one line at a time, whole, from any thread


def _write_line(text: str, stream: TextIO) -> None:
    with _WRITING:
        stream.write(text + "\n")
        stream.flush()


def bar(total: int, desc: str, unit: str = "", enabled: bool = True, stream: TextIO | None = None) -> Any:
    """A progress object, with ``update(n)`` and ``close()`` and usable as a context manager.

    Args:
        total: the number of steps.
        desc: its label.
        unit: the steps' unit, or none.
        enabled: whether it shows anything.
        stream: where it goes (default ``sys.stderr``, read when called).

    Returns:
        ``tqdm`` on a terminal, `Lines` elsewhere, `Silent` when not ``enabled``.
    """
    if not enabled:
        return Silent()
    stream = stream if stream is not None else sys.stderr
    if is_terminal(stream):
        from tqdm import tqdm

        return tqdm(total=total, desc=desc, unit=unit or "it", file=stream, leave=True)
    return Lines(total, desc, unit, stream)


def note(text: str, enabled: bool = True, stream: TextIO | None = None) -> None:
    """Write one line of progress (a phase starting or ending) on ``stream`` (default ``sys.stderr``), unless not
    ``enabled``."""
    if enabled:
        _write_line(text, stream if stream is not None else sys.stderr)


def terminal(stream: TextIO | None = None) -> bool:
    """Whether progress goes to a terminal (``sys.stderr`` unless ``stream``): where bars belong."""
    return is_terminal(stream if stream is not None else sys.stderr)
