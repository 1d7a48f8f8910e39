"""One process of the multi-process sweep test (tests/test_distributed.py); not a test module itself.

    python tests/_distributed_worker.py OUT.json [COORDINATOR NUM_PROCESSES PROCESS_ID]

Without the coordinator arguments it runs the sweep in this one process; with them it first
joins a ``jax.distributed`` run (CPU backend, ``--devices`` CPU devices per process). Either way
it writes the full sweep result, and the process/device counts it saw, to OUT.json.
"""

import argparse
import json
import os
import sys
from pathlib import Path

import jax

REPO = Path(__file__).resolve().parents[1]
N_POINTS, CHUNK, SEED, T1 = 10, 4, 0, 1.0  # 3 chunks of 4 rows, the last one padded


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("coordinator", nargs="?")
    ap.add_argument("num_processes", nargs="?", type=int)
    ap.add_argument("process_id", nargs="?", type=int)
    ap.add_argument("--devices", type=int, default=1, help="CPU devices per process")
    args = ap.parse_args()

    jax.config.update("jax_platforms", "cpu")
    jax.config.update("jax_num_cpu_devices", args.devices)
    if os.environ.get("GROWJAX_CACHE_DIR"):  # set by tests/conftest.py; the same cache as the test run
        jax.config.update("jax_compilation_cache_dir", os.environ["GROWJAX_CACHE_DIR"])
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    if args.coordinator:
        jax.distributed.initialize(
            coordinator_address=args.coordinator,
            num_processes=args.num_processes,
            process_id=args.process_id,
            initialization_timeout=120,
        )

    import growjax as gj
    from growjax import sweep as sw
    from growjax.data import experiment as ex

    exp = ex.read(REPO / "src" / "growjax" / "data" / "datasets" / "synthetic_forward.csv")
    base = gj.reference()
    inputs = ex.to_inputs(exp, "forward", base)
    dims = (sw.Dimension("robot.yield_pressure", 5e3, 15e3), sw.Dimension("robot.extensibility", 4000.0, 10000.0))
    result = sw.lhs_sweep(
        N_POINTS,
        base,
        inputs,
        gj.Config(t1=T1),
        dims,
        seed=SEED,
        measured=(exp.time, exp["robot_length_m"]),
        chunk_size=CHUNK,
    )
    report = {
        "process_index": jax.process_index(),
        "process_count": jax.process_count(),
        "device_count": jax.device_count(),
        "local_device_count": jax.local_device_count(),
        "n_devices": result.n_devices,
        "names": list(result.names),
        "values": result.values.tolist(),
        # repr keeps every bit of a float64 (and NaN) through JSON
        "rmse": [repr(float(v)) for v in result.rmse],
        "final_length": [repr(float(v)) for v in result.final_length],
        "status": [int(s) for s in result.status],
    }
    Path(args.out).write_text(json.dumps(report))
    if args.coordinator:
        jax.distributed.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
