"""What every command module shares: the protocol it follows, the process it asks for, how its run fails or
stops, its outputs (checked before the run, listed where it is interrupted), its output folder and its progress
lines.

A command is one module of ``growjax.cli`` (listed in ``growjax.cli.COMMANDS``) that defines:

* ``NAME`` (str): the command's name on the command line;
* ``HELP`` (str): its one line in ``growjax --help``;
* ``PROCESS`` (`Process`): the process setup it needs before JAX starts its backend;
* ``add_arguments(parser)``: its options, the shared groups of `growjax.cli.options` among them;
* ``run(args) -> dict``: the work; returns the JSON summary (``"command": NAME`` in it); raises `RunFailed` (a run
  failed: exit 1, the summary still written), ``ValueError`` or the data's errors (bad input: exit 2) or `Stopped`
  (exit with its status);
* ``summary_lines(summary) -> list[str]``: the few lines for people, in mm and kPa.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import signal
import time
from collections.abc import Callable
from pathlib import Path

OK = 0
"""Exit status: every run succeeded."""
RUN_FAILED = 1
"""Exit status: a run failed (the reason on standard error, the summary still written)."""
BAD_INPUT = 2
"""Exit status: a bad option or file (one line naming it)."""
SHOWN_WRITTEN = 4  # files an interrupted command names (then how many more)


class RunFailed(Exception):
    """A run finished but failed (solver failure, failed sweep member, fit not converged, limit crossed).

    Args:
        reason: one line naming the failure.
        summary: the command's JSON summary, written all the same.
    """

    def __init__(self, reason: str, summary: dict):
        super().__init__(reason)
        self.summary = summary


class Stopped(Exception):
    """The command stopped before its end, its work kept (a sweep's chunks).

    Args:
        message: one line: what was kept and how to complete it.
        status: the exit status (128 + a signal's number, or a command's own).
    """

    def __init__(self, message: str, status: int):
        super().__init__(message)
        self.status = status


class Interrupted(KeyboardInterrupt):
    """A signal that stops a command as Ctrl-C does (SIGTERM), raised in the main thread.

    Args:
        signum: the signal's number.
    """

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signal = signum


@contextlib.contextmanager
def terminate_as_interrupt():
    """Within the block, SIGTERM raises `Interrupted` in the main thread (the previous handler restored after it;
    elsewhere than the main thread, nothing changes)."""

    def handle(signum, frame):
        raise Interrupted(signum)

    try:
        previous = signal.signal(signal.SIGTERM, handle)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def interrupted_status(error: BaseException) -> int:
    """The exit status of a command stopped by ``error`` (a ``KeyboardInterrupt``): 128 + the signal's number."""
    return 128 + int(getattr(error, "signal", signal.SIGINT))


@dataclasses.dataclass(frozen=True)
class Process:
    """The process setup a command needs, made before JAX starts its backend.

    Attributes:
        workflow: a workflow command: JAX's compile cache on, bad input reported as exit 2 and the summary for
            people printed even with ``--json -`` (on stderr). False: a listing (``params``, ``effects``).
        quick_compile: XLA's quicker emitters (`growjax.simulation.xla_flags.apply_quick_compile`) where
            ``--fidelity fast``: a compile-bound command.
        cpu_devices: every CPU core exposed as a JAX device (sweeps shard over them, a set's runs spread over them,
            NUTS chains run one per device); ``GROWJAX_CPU_DEVICES`` overrides.
        devices_at_least: the option (its ``dest``) whose value is the least number of devices wanted, or None.
        whole_loop: a function of the parsed arguments: whether the solver's loop is compiled whole
            (`growjax.simulation.xla_flags.apply`), or None.
    """

    workflow: bool = True
    quick_compile: bool = False
    cpu_devices: bool = False
    devices_at_least: str | None = None
    whole_loop: Callable | None = None

    def apply(self, args) -> None:
        """Set the process up for the parsed arguments ``args`` (nothing for a listing)."""
        if not self.workflow:
            return
        enable_compile_cache()
        from growjax.simulation import xla_flags

        if self.quick_compile and args.fidelity == "fast":
            xla_flags.apply_quick_compile()
        if self.cpu_devices:
            use_all_cpu_cores(getattr(args, self.devices_at_least) if self.devices_at_least else 1)
        if self.whole_loop is not None and self.whole_loop(args):
            xla_flags.apply()


def enable_compile_cache() -> None:
    """JAX's persistent compile cache in ``$GROWJAX_CACHE_DIR`` (default ``~/.cache/growjax/jax``)."""
    import jax

    cache = os.environ.get("GROWJAX_CACHE_DIR", str(Path.home() / ".cache" / "growjax" / "jax"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


def use_all_cpu_cores(at_least: int = 1) -> None:
    """Expose every CPU core, and at least ``at_least``, as a JAX device (``GROWJAX_CPU_DEVICES`` overrides; an
    ``XLA_FLAGS`` that sets the host device count wins)."""
    import jax

    wanted = os.environ.get("GROWJAX_CPU_DEVICES")
    n = int(wanted) if wanted else max(os.cpu_count() or 1, at_least)
    if "xla_force_host_platform_device_count" in os.environ.get("XLA_FLAGS", ""):
        return
    try:
        jax.config.update("jax_num_cpu_devices", n)
    except (AttributeError, RuntimeError):
        pass  # older JAX, or the backend is already initialised


def check_outputs(args) -> None:
    """Refuse, before any work, outputs that cannot be written: ``--out`` (a folder, made where missing) and
    ``--json`` (a file; ``-`` is stdout).

    Raises:
        ValueError: one line naming the option, the path and the problem.
    """
    out = getattr(args, "out", None)
    if out is not None and getattr(args, "resume", None) is None:
        _check_writable("--out", Path(out), folder=True)
    where = getattr(args, "json", None)
    if where and where != "-":
        _check_writable("--json", Path(where), folder=False)


def _check_writable(option: str, path: Path, folder: bool) -> None:
    """ValueError where ``path`` cannot be written as a folder (``folder``) or as a file."""
    what = "a folder" if folder else "a file"
    if path.exists():
        if folder != path.is_dir():
            raise ValueError(f"{option} {path}: names {what}, and {path} is {'a file' if folder else 'a folder'}")
        if not os.access(path, os.W_OK | (os.X_OK if folder else 0)):
            raise ValueError(f"{option} {path}: {'the folder' if folder else 'the file'} is not writable")
        return
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{option} {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{option} {path}: cannot write in {parent} (not writable)")


def outputs_now(args) -> dict:
    """{path: (modification time ns, size)} of what the command may write: the entries of ``--out`` and the
    ``--json`` file, as they stand (compare with `written`)."""
    paths = []
    out = getattr(args, "out", None)
    if out is not None and Path(out).is_dir():
        paths += sorted(Path(out).iterdir())
    where = getattr(args, "json", None)
    if where and where != "-":
        paths.append(Path(where))
    stamps = {}
    for p in paths:
        with contextlib.suppress(OSError):
            st = p.stat()
            stamps[str(p)] = (st.st_mtime_ns, st.st_size)
    return stamps


def written(args, before: dict) -> list[str]:
    """The outputs made or changed since ``before`` (`outputs_now` then)."""
    return [p for p, stamp in outputs_now(args).items() if before.get(p) != stamp]


def interrupted_line(args, before: dict, error: BaseException) -> str:
    """The one line of a command stopped by ``error`` (Ctrl-C, SIGTERM): what it wrote since ``before``."""
    how = "interrupted" if getattr(error, "signal", signal.SIGINT) == signal.SIGINT else f"stopped by {error}"
    files = written(args, before)
    if not files:
        return f"{how} before writing anything"
    more = f" and {len(files) - SHOWN_WRITTEN} more" if len(files) > SHOWN_WRITTEN else ""
    return f"{how}; wrote {', '.join(files[:SHOWN_WRITTEN])}{more}"


def out_dir(args) -> Path:
    """The command's ``--out`` folder, made where missing."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    return out


def note(args, text: str) -> float:
    """One line of progress on stderr (none with ``--quiet``).

    Returns:
        The time, s (``time.perf_counter``).
    """
    from growjax import progress as prog

    prog.note(text, not args.quiet)
    return time.perf_counter()


__all__ = [
    "BAD_INPUT",
    "OK",
    "RUN_FAILED",
    "Interrupted",
    "Process",
    "RunFailed",
    "Stopped",
    "check_outputs",
    "enable_compile_cache",
    "interrupted_line",
    "interrupted_status",
    "note",
    "out_dir",
    "outputs_now",
    "terminate_as_interrupt",
    "use_all_cpu_cores",
    "written",
]
