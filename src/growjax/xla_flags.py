"""An opt-in XLA:CPU option: compile the solver's loop into one kernel ("small loops").

XLA:CPU runs a compiled program as a sequence of operations, each launched on its own (a few µs), except a
``while`` loop whose operations it can all emit as one kernel and whose data fit under a size limit
(``xla_cpu_small_while_loop_byte_threshold``, 1 kB by default): that loop runs as one compiled function.
With the limit raised, the solver's loop (:mod:`growjax._rosenbrock`) qualifies when its linear solve is
written in elementwise operations instead of a LAPACK call, which it is while this option is in
``XLA_FLAGS``. Measured on a 2-core CPU (``benchmarks/simulate.py``, README "Benchmarks"): a 10 s simulation
10–11 ms instead of 15.5–17 ms, a forward-mode gradient in 3 parameters 24–33 ms instead of 41–47 ms; but a
linearisation of ``discover``'s 8-effect superset 72 ms instead of 54 ms, compiles take longer (the default test run
6 min 28 s instead of 4 min 22 s), and batched solves (sweeps) are not compiled whole (their per-member
step records are scatters, which the kernel emitter does not take). So it is off by default; turn it on for
long runs of the base model (many likelihood gradients), before JAX starts its backend::

    XLA_FLAGS="--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=1000000000" growjax ...

or ``growjax.xla_flags.apply()`` first thing in a script.
"""

from __future__ import annotations

import os
import re

SMALL_LOOP_OPTION = "xla_cpu_small_while_loop_byte_threshold"
SMALL_LOOP_BYTES = 1_000_000_000


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
