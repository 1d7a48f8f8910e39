"""A forward experiment with the pressure recorded and a stepper experiment of the same robot, fitted alone and
jointly: Y consistent across them within the intervals.

Run: ``python benchmarks/mixed_set.py [--out benchmarks/results/mixed_set.json]``.

The forward experiment is the shipped synthetic one (Y = 9 kPa, length and pressure); the stepper experiment is
made here by the reference configuration (inverse drive, Y = 9 kPa, the desired length a ramp at 4 mm/s, held
from 30 mm), with 0.2 mm of length noise. Each is fitted alone and both jointly (`Y@robot`, one rig).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from importlib.resources import files
from pathlib import Path

import numpy as np

import growjax as gj
from growjax import calibration as cal
from growjax.data import experiment as ex
from growjax.data import sets as xs
from growjax.data.experiment import Experiment

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment

Y = "robot.yield_pressure@robot"


def stepper_experiment(seed: int) -> Experiment:
    t = np.round(np.arange(1, 1001) * 0.01, 10)
    catheter = 0.004 + 0.004 * t
    desired = np.minimum(0.004 * t, 0.03)
    base = gj.replace(gj.reference("inverse"), Y=9000.0)
    spec = Experiment(t, {"robot_length_m": desired, "desired_length_m": desired, "catheter_length_m": catheter})
    config = gj.Config(fidelity="reference", drive="inverse", t1=10.0)
    traj = gj.simulate(
        base, ex.to_inputs(spec, "inverse", base, config.t0, config.t1), config, ts=np.concatenate([[config.t0], t])
    )
    assert int(traj.status) == gj.OK, gj.status_name(traj.status)
    length = np.asarray(traj.length)[1:] + np.random.default_rng(seed).normal(0.0, 2e-4, t.size)
    return Experiment(t, {"robot_length_m": length, "desired_length_m": desired, "catheter_length_m": catheter})


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "mixed_set.json"))
    args = ap.parse_args()
    forward = ex.read(files("growjax.data") / "datasets" / "synthetic_forward.csv")
    runs = (
        xs.Run("forward", forward, drive="forward", sensors=("length", "pressure")),
        xs.Run("stepper", stepper_experiment(args.seed), drive="inverse"),
    )
    rows = {}
    for label, chosen in (("forward", (0,)), ("stepper", (1,)), ("joint", (0, 1))):
        clock = time.perf_counter()
        chosen_runs = xs.ExperimentSet(tuple(runs[i] for i in chosen))
        res = cal.fit(chosen_runs, ["Y@robot"], config=gj.Config(t1=10.0), starts=1, scout=16)
        rows[label] = {
            "estimate_Pa": res.estimate[Y],
            "interval_90_Pa": list(res.interval_90[Y]),
            "programs": res.programs,
            "wall_s": time.perf_counter() - clock,
            "rmse_length_m": [r["rmse_length_m"] for r in res.runs],
        }
        print(label, json.dumps(rows[label]), flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"environment": environment(), "truth_Pa": 9000.0, **rows}, indent=1))


if __name__ == "__main__":
    main()
