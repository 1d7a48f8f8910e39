"""Benchmark one 10 s simulation per drive: compile time, wall time after compilation, solver steps.

Run: ``python benchmarks/simulate.py [--out benchmarks/results/simulate.json]``. Uses the shared
experiment when it is beside the checkout, else the shipped synthetic data. Wall time is the
median of ``--repeat`` calls; ``realtime_factor`` = wall / simulated time (a same-process ratio).
No persistent compilation cache, so compile_s is a cold compile.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import jax

import growjax as gj
from growjax import experiment as ex
from growjax.metrics import length_rmse

REPO = Path(__file__).resolve().parents[1]


def bench(drive: str, exp, repeat: int, rtol: float) -> dict:
    params = gj.reference(drive)
    config = gj.Config(drive=drive, rtol=rtol, atol=rtol)
    inputs = ex.to_inputs(exp, drive, params)
    start = time.perf_counter()
    traj = jax.block_until_ready(gj.simulate(params, inputs, config))
    first = time.perf_counter() - start
    walls = []
    for _ in range(repeat):
        start = time.perf_counter()
        traj = jax.block_until_ready(gj.simulate(params, inputs, config))
        walls.append(time.perf_counter() - start)
    wall = statistics.median(walls)
    out = {
        "drive": drive,
        "rtol": rtol,
        "compile_s": first - wall,
        "wall_s": wall,
        "wall_min_s": min(walls),
        "solver_steps": int(traj.n_steps),
        "status": gj.status_name(traj.status),
        "realtime_factor": wall / (config.t1 - config.t0),
    }
    if "robot_length_m" in exp:
        out["rmse_length_m"] = float(length_rmse(traj, exp.time, exp["robot_length_m"], config.t0, config.t1))
    return out


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "simulate.json"))
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    folder = ex.shared_experiment_dir()
    exp = ex.read(folder / "experiment.csv") if folder else ex.read(REPO / "data" / "synthetic_forward.csv")
    results = {
        "data": exp.source,
        "device": str(jax.devices()[0]),
        "runs": [bench("forward", exp, args.repeat, 1e-6), bench("forward", exp, args.repeat, 1e-4),
                 bench("inverse", exp, args.repeat, 1e-5)],
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
