"""Scale-out: a sweep sharded across 2 ``jax.distributed`` processes equals the same sweep in one process.

Two worker processes (CPU backend, 2 CPU devices each, a coordinator on localhost) run one
10-point Latin-hypercube sweep together (3 chunks of 4 rows, the last padded), and a third
process runs it alone over the same number of devices (4). Every worker must return the full
result, bit for bit that of the single process. (A single-*device* run differs from any
multi-device one at solver-tolerance level, ~1e-7 relative, whether in one process or several,
so the reference uses 4 devices too.)

Marked slow; run it with ``pytest tests/test_distributed.py -m slow``.
"""

import contextlib
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

WORKER = Path(__file__).resolve().parent / "_distributed_worker.py"
TIMEOUT_S = 240
DEVICES_PER_PROCESS = 2


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _worker_env() -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu")  # GROWJAX_CACHE_DIR (tests/conftest.py) passes through
    env.pop("XLA_FLAGS", None)  # a forced host device count would override --devices
    for key in [k for k in env if k.lower() in ("http_proxy", "https_proxy", "all_proxy", "grpc_proxy")]:
        env.pop(key)  # the coordinator is on localhost; gRPC must not go through a proxy
    return env


def _run_all(jobs: dict, tmp_path: Path) -> dict:
    """Start every job (name → argv), wait for all (killing all on a timeout); name → (rc, stderr tail)."""
    env, procs = _worker_env(), {}
    with contextlib.ExitStack() as logs:
        for name, argv in jobs.items():
            log = logs.enter_context(open(tmp_path / f"{name}.log", "w"))
            procs[name] = subprocess.Popen(
                [sys.executable, str(WORKER), *argv],
                stdout=log,
                stderr=subprocess.STDOUT,
                env=env,
                cwd=WORKER.parents[1],
            )
        deadline = time.monotonic() + TIMEOUT_S
        try:
            for proc in procs.values():
                proc.wait(timeout=max(1.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
        finally:
            for proc in procs.values():
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
    return {name: (procs[name].returncode, (tmp_path / f"{name}.log").read_text()[-3000:]) for name in jobs}


# Three processes each trace and compile the model (~20 s of CPU apiece; the program has host
# callbacks, so the persistent cache cannot share it): ~90 s on a busy 2-core machine.
@pytest.mark.slow
def test_sweep_across_two_processes_equals_one_process(tmp_path):
    coordinator = f"127.0.0.1:{_free_port()}"
    dev = ["--devices", str(DEVICES_PER_PROCESS)]
    jobs = {
        "process0": [str(tmp_path / "process0.json"), coordinator, "2", "0", *dev],
        "process1": [str(tmp_path / "process1.json"), coordinator, "2", "1", *dev],
        "single": [str(tmp_path / "single.json"), "--devices", str(2 * DEVICES_PER_PROCESS)],
    }
    start = time.perf_counter()
    outcome = _run_all(jobs, tmp_path)
    elapsed = time.perf_counter() - start
    for name, (rc, log) in outcome.items():
        assert rc == 0, (
            f"{name} exited with {rc} (timeout {TIMEOUT_S} s; -9 = killed) after {elapsed:.0f} s; "
            f"its output:\n{log}\n--- all outputs ---\n"
            + "\n".join(f"[{n}] rc={r}\n{text}" for n, (r, text) in outcome.items())
        )

    single, *workers = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("single", "process0", "process1"))
    assert (single["process_count"], single["device_count"], single["n_devices"]) == (1, 4, 4)
    for i, w in enumerate(workers):
        assert w["process_index"] == i
        assert (w["process_count"], w["local_device_count"]) == (2, DEVICES_PER_PROCESS)
        assert w["device_count"] == w["n_devices"] == 2 * DEVICES_PER_PROCESS, "the sweep did not span both processes"
        assert w["names"] == single["names"] == ["robot.yield_pressure", "robot.extensibility"]
        np.testing.assert_array_equal(w["values"], single["values"])
        assert w["status"] == single["status"]
        for key in ("rmse", "final_length"):
            got, want = np.array(w[key], float), np.array(single[key], float)
            np.testing.assert_array_equal(got, want, err_msg=f"process {i}: {key} differs from the one-process sweep")
    # A real result, not all failures or NaN: every point simulated and scored against the data.
    assert single["status"] == [0] * 10
    assert np.all(np.isfinite(np.array(single["rmse"], float)))
    assert np.all(np.array(single["final_length"], float) > 0)
