"""XLA:CPU options: an opt-in one that compiles the solver's loop into one kernel ("small loops"), and the
quick compile the sweep's program takes.

**Small loops.** XLA:CPU runs a compiled program as a sequence of operations, each launched on its own (a few µs),
except a ``while`` loop whose operations it can all emit as one kernel and whose data fit under a size limit
(``xla_cpu_small_while_loop_byte_threshold``, 1 kB by default): that loop runs as one compiled function.
With the limit raised, the solver's loop (`growjax.simulation.rosenbrock`) qualifies when its linear solve is
written in elementwise operations instead of a LAPACK call, which it is while this option is in
``XLA_FLAGS``. Measured on a 2-core CPU (``benchmarks/simulate.py``, README "Benchmarks"): a 10 s simulation
10–11 ms instead of 15.5–17 ms, a forward-mode gradient in 3 parameters 24–33 ms instead of 41–47 ms; but a
linearisation of ``discover``'s 8-effect superset 72 ms instead of 54 ms, compiles take longer (the default test run
6 min 28 s instead of 4 min 22 s), and batched solves (sweeps) are not compiled whole (their per-member
step records are scatters, which the kernel emitter does not take). So it is off by default; turn it on for
long runs of the base model (many likelihood gradients), before JAX starts its backend::

    XLA_FLAGS="--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=1000000000" growjax ...

or ``growjax.simulation.xla_flags.apply()`` first thing in a script.

**Quick compile** (`QUICK_COMPILE`): XLA:CPU's older fusion emitters (``xla_cpu_use_fusion_emitters``
off) compile a program 15–30 % faster, and the code they emit runs slower: a single 10 s simulation 22 ms
instead of 14 ms (``benchmarks/simulate.py``), the 500-set sweep 5–7 % longer. A sweep of up to
``growjax.sweep.QUICK_COMPILE_ROWS`` sets, which compiles once and runs once, takes them
(`compile_quickly`, its program only); so do the ``growjax simulate`` and ``growjax fit`` processes
(`apply_quick_compile`) and the test suite, made of compiles (``tests/conftest.py``). Everything else
keeps XLA's default. They round differently, so an adaptive step can move: the fast configuration's 10 s run
of the published pulse differs by up to 0.3 µm in length (2 s: 9 nm), at nearly every sample. The choice is
therefore `growjax.Config.quick_compile`, made explicit by `growjax.Config.resolved`
(`quick_compile_in_force`), and compiled programs are keyed on it.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import jax

__all__ = [
    "FULL_BACKEND",
    "QUICK_COMPILE",
    "QUICK_COMPILE_VERIFIED",
    "SMALL_LOOP_BYTES",
    "SMALL_LOOP_OPTION",
    "applied",
    "apply",
    "apply_quick_compile",
    "compile_quickly",
    "compiling",
    "quick_compile_applied",
    "quick_compile_flags",
    "quick_compile_in_force",
    "quick_compile_known",
    "with_small_loops",
]

SMALL_LOOP_OPTION = "xla_cpu_small_while_loop_byte_threshold"
SMALL_LOOP_BYTES = 1_000_000_000
QUICK_COMPILE = {"xla_cpu_use_fusion_emitters": False}
QUICK_COMPILE_VERIFIED = ("0.10.",)  # jaxlib release series known to have the option
# XLA:CPU's own default backend optimisation, for a program whose run is a long loop of a small model (a batch of
# NUTS chains on an emulator), which a process at a lower level (the test run's 0) would run 2-3x slower
# (simulation-based calibration, 100 chains of 300 steps, compile included: 23 s at level 0, 10-15 s at 3).
FULL_BACKEND = {"xla_backend_optimization_level": 3}


def with_small_loops(flags: str, limit: int = SMALL_LOOP_BYTES) -> str:
    """``flags`` (an ``XLA_FLAGS`` string) with the small-loop limit raised to ``limit`` bytes, unless it already
    sets that option (a user's own setting wins)."""
    if SMALL_LOOP_OPTION in flags:
        return flags
    option = f"{SMALL_LOOP_OPTION}={limit}"
    parts = flags.split()
    for i, part in enumerate(parts):
        if part.startswith("--xla_backend_extra_options="):
            parts[i] = f"{part},{option}"
            return " ".join(parts)
    return " ".join([*parts, f"--xla_backend_extra_options={option}"])


def _backend_started() -> bool:
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):  # a JAX without that private function: assume not started
        return False


def apply() -> bool:
    """Raise the small-loop limit in ``XLA_FLAGS`` if JAX's backend has not started; whether it is in force
    (False: JAX started before, or ``XLA_FLAGS`` sets a low limit of its own)."""
    if SMALL_LOOP_OPTION not in os.environ.get("XLA_FLAGS", "") and not _backend_started():
        os.environ["XLA_FLAGS"] = with_small_loops(os.environ.get("XLA_FLAGS", ""))
    return applied()


def applied() -> bool:
    """Whether ``XLA_FLAGS`` sets the small-loop limit high enough for the solver's loop (≥ 1e8 bytes): the
    solver then writes its linear solve in elementwise operations (read when a solve is traced)."""
    found = re.search(SMALL_LOOP_OPTION + r"=(\d+)", os.environ.get("XLA_FLAGS", ""))
    return found is not None and int(found.group(1)) >= 10**8


def compile_quickly(lowered: jax.stages.Lowered, quick: bool = True) -> jax.stages.Compiled:
    """``lowered.compile()`` under `QUICK_COMPILE` or XLA's default emitters, whatever the process's flags (a plain
    compile where they give that already).

    Args:
        lowered: the lowered program (``jax.jit(f).lower(...)``).
        quick: `QUICK_COMPILE` if True, else XLA's default emitters.

    Returns:
        The compiled program; under XLA's default where this jaxlib lacks the option.
    """
    ((name, value),) = QUICK_COMPILE.items()
    if bool(quick) == quick_compile_applied():
        return lowered.compile()
    try:
        return lowered.compile(compiler_options={name: value if quick else not value})
    except Exception as err:  # jaxlib raises its own runtime error type for an unknown option
        if "compile option" not in str(err):
            raise
        return lowered.compile()


_COMPILING: contextvars.ContextVar = contextvars.ContextVar("growjax_quick_compile", default=None)


@contextlib.contextmanager
def compiling(quick: bool) -> Iterator[None]:
    """A context within which the program being traced is compiled by `compile_quickly` with ``quick``, not under
    the process's flags (what `quick_compile_in_force` answers)."""
    token = _COMPILING.set(bool(quick))
    try:
        yield
    finally:
        _COMPILING.reset(token)


def quick_compile_applied() -> bool:
    """Whether ``XLA_FLAGS`` sets `QUICK_COMPILE` for every program of this process."""
    ((name, value),) = QUICK_COMPILE.items()
    return f"--{name}={str(value).lower()}" in os.environ.get("XLA_FLAGS", "")


def quick_compile_in_force() -> bool:
    """Whether the program traced now is compiled with `QUICK_COMPILE`: the choice of the
    `compiling` block around it, else the process's (`quick_compile_applied`)."""
    chosen = _COMPILING.get()
    return quick_compile_applied() if chosen is None else chosen


def quick_compile_flags(flags: str) -> str:
    """``flags`` (an ``XLA_FLAGS`` string) with `QUICK_COMPILE` for every program of a process, unless it
    already sets that option. Only for a jaxlib known to have it: XLA aborts the process on an unknown flag
    (check with `quick_compile_known` in another process)."""
    ((name, value),) = QUICK_COMPILE.items()
    if name in flags:
        return flags
    return " ".join([*flags.split(), f"--{name}={str(value).lower()}"])


def quick_compile_known() -> bool:
    """Whether this environment's jaxlib takes `QUICK_COMPILE`: a release series it was verified in
    (`QUICK_COMPILE_VERIFIED`), else asked of a new interpreter (~1 s)."""
    import jaxlib

    if jaxlib.__version__.startswith(QUICK_COMPILE_VERIFIED):
        return True

    check = f"import jax; jax.jit(lambda x: x + 1.0).lower(1.0).compile(compiler_options={QUICK_COMPILE!r})"
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["JAX_PLATFORMS"] = "cpu"
    run = subprocess.run([sys.executable, "-c", check], capture_output=True, env=env, timeout=120, check=False)
    return run.returncode == 0


def apply_quick_compile() -> bool:
    """`QUICK_COMPILE` for every program of this process, if JAX's backend has not started, this jaxlib has
    the option and ``XLA_FLAGS`` does not set it; whether it is in force."""
    ((name, _),) = QUICK_COMPILE.items()
    flags = os.environ.get("XLA_FLAGS", "")
    if name not in flags and not _backend_started() and quick_compile_known():
        os.environ["XLA_FLAGS"] = quick_compile_flags(flags)
    return quick_compile_applied()
