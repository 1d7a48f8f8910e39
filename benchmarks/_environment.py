"""The machine and versions a benchmark ran on, recorded in its results file (``"environment"``)."""

from __future__ import annotations

import datetime
import os
import platform


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def environment() -> dict:
    import jax
    import jaxlib

    import growjax

    return {
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d"),
        "machine": f"{_cpu()}, {os.cpu_count()} cores",
        "device": str(jax.devices()[0].platform),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "growjax": growjax.__version__,
    }


def use_all_cpu_cores() -> int:
    """Expose every CPU core (``GROWJAX_CPU_DEVICES`` overrides) as a JAX device, as ``growjax sweep`` and ``fit``
    do; call before JAX starts its backend. The number of devices asked for."""
    import jax

    n = int(os.environ.get("GROWJAX_CPU_DEVICES", len(os.sched_getaffinity(0)) or 1))
    jax.config.update("jax_num_cpu_devices", n)
    return n
