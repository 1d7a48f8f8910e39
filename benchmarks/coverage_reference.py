"""Fit intervals against the truth on data made by the reference configuration (data the fast model did not make).

Run: ``python benchmarks/coverage_reference.py [--seeds 1] [--out benchmarks/results/coverage_reference.json]``.

For each of the five shipped reference-made experiments (``growjax/data/datasets/reference_lengths.csv``: the
published pulse train, 0–10 s, Y from 6 to 14 kPa) plus Gaussian noise of 0.2 mm (seeds 100 + k, as the default test
run draws them, then further seeds), ``growjax.calibration.fit`` estimates Y on the fast configuration twice: with the
noise alone in its covariance, and with the fast configuration's measured model error added (the default). Printed per
case: the estimate's error in standard errors of each, and whether each 90 % interval covers the truth.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import numpy as np

import growjax as gj
from growjax import calibration as cal
from growjax.data import experiment as ex
from growjax.data import sets as xs

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "data"))
import make_synthetic as mk

NOISE = 2e-4  # m
CASES = ["published_Y6000", "published_Y7920", "published_Y10000", "published_Y12000", "published_Y14000"]


def main():
    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=1, help="noise draws per case")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "coverage_reference.json"))
    args = ap.parse_args()
    clock = time.perf_counter()
    t, lengths, cases = mk.read_reference_lengths()
    inputs = mk.reference_inputs("published")
    rows = []
    for s in range(args.seeds):
        for k, name in enumerate(CASES):
            truth = cases[name]["parameters"]["Y"]
            data = lengths[name] + np.random.default_rng(100 + k + 5 * s).normal(0.0, NOISE, t.size)
            row = {"case": name, "seed": 100 + k + 5 * s, "truth_Pa": truth}
            for label, error in (("noise_only", 0.0), ("with_model_error", None)):
                res = cal.fit(
                    xs.ExperimentSet.single(ex.from_arrays(t, data), inputs=inputs),
                    ["Y"],
                    likelihood=cal.Likelihood(sigma_length=NOISE, model_error=error),
                    config=gj.Config(t1=10.0),
                    starts=1,
                    scout=0,
                )
                est, se = res.estimate["robot.yield_pressure"], res.standard_error["robot.yield_pressure"]
                lo, hi = res.interval_90["robot.yield_pressure"]
                row[label] = {
                    "estimate_Pa": est,
                    "se_Pa": se,
                    "error_in_se": (est - truth) / se,
                    "covered": bool(lo < truth < hi),
                    "rmse_m": res.rmse_length_m,
                }
            rows.append(row)
            print(
                f"{name:18s} seed {row['seed']}: Y {row['noise_only']['estimate_Pa']:8.1f} for {truth:7.1f} Pa; "
                f"error {row['noise_only']['error_in_se']:+.2f} se (noise only, covered "
                f"{row['noise_only']['covered']}), {row['with_model_error']['error_in_se']:+.2f} se "
                f"(with model error, covered {row['with_model_error']['covered']})",
                flush=True,
            )
    out = {
        "noise_m": NOISE,
        "model_error_m": cal.FAST_MODEL_ERROR,
        "cases": rows,
        "covered": {label: sum(r[label]["covered"] for r in rows) for label in ("noise_only", "with_model_error")},
        "n": len(rows),
        "wall_s": time.perf_counter() - clock,
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(f"covered: {out['covered']} of {out['n']}")


if __name__ == "__main__":
    main()
