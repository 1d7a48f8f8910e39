"""The machine, versions and command a benchmark ran with, recorded in its results file (``"environment"``)."""

from __future__ import annotations

import datetime
import os
import platform
import shlex
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# The one-minute load average as the benchmark starts (this module is imported first): the other work on the
# machine, before the benchmark's own processes add theirs.
LOAD_AT_START = round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _command() -> str:
    """The command line that ran this process, with the script's path relative to the repository."""
    script = Path(sys.argv[0]).resolve()
    name = str(script.relative_to(REPO)) if script.is_relative_to(REPO) else sys.argv[0]
    return shlex.join(["python", name, *sys.argv[1:]])


def environment() -> dict:
    """The date, CPU model and count, the one-minute load average as the benchmark started (other work on the
    machine), the JAX device, the versions of Python, jax and growjax, and the command line."""
    import jax
    import jaxlib

    import growjax

    return {
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d"),
        "machine": f"{_cpu()}, {os.cpu_count()} cores",
        "cpu_model": _cpu(),
        "cpu_count": os.cpu_count(),
        "load_1min": LOAD_AT_START,
        "device": str(jax.devices()[0].platform),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "growjax": growjax.__version__,
        "command": _command(),
    }


def use_all_cpu_cores() -> int:
    """Expose every CPU core (``GROWJAX_CPU_DEVICES`` overrides) as a JAX device, as ``growjax sweep`` and ``fit``
    do; call before JAX starts its backend. The number of devices asked for."""
    import jax

    n = int(os.environ.get("GROWJAX_CPU_DEVICES", len(os.sched_getaffinity(0)) or 1))
    jax.config.update("jax_num_cpu_devices", n)
    return n
