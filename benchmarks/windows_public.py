"""Fits of Y on disjoint windows of the public experiment: do the windows agree within their intervals?

Run: ``python benchmarks/windows_public.py [--data DIR] [--out benchmarks/results/windows_public.json]``.

Forward drive, fast configuration. Y is fitted on 0–10 s, its halves and its thirds, under the default
likelihood (Matérn-3/2 discrepancy, the rig's default tolerance budget), under the discrepancy without
tolerances, and under independent noise (``discrepancy="none"``). For every pair of disjoint windows it
prints |ΔY| in combined standard errors, sqrt(se₁² + se₂²), and in the standard error of the difference itself
(the rig is the same in every window: a tolerance moves both windows' Y, each by its own gain, so it adds
Σ u²(gain₁ − gain₂)² to the difference's variance rather than the sum of both windows' shares).
Targets: every pair within 2 combined standard errors; the 0–10 s interval at most a third of the
paper's Y box (5–15 kPa).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from growjax import calibration as cal
from growjax.data import sets as xs

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment
from _public import public_experiment

WINDOWS = [(0.0, 10.0), (0.0, 5.0), (5.0, 10.0), (0.0, 3.4), (3.4, 6.7), (6.7, 10.0)]
PAIRS = [((0.0, 5.0), (5.0, 10.0)), ((0.0, 3.4), (3.4, 6.7)), ((3.4, 6.7), (6.7, 10.0)), ((0.0, 3.4), (6.7, 10.0))]
LIKELIHOODS = {
    "discrepancy+tolerances": {"discrepancy": "matern32"},
    "discrepancy": {"discrepancy": "matern32", "tolerances": {}},
    "independent": {"discrepancy": "none"},
}
Y = "robot.yield_pressure"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="folder of the public experiment (default: ../shared/data/mammobot)")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "windows_public.json"))
    args = ap.parse_args()
    exp, base, config, inputs = public_experiment(args.data)
    rows = {}
    for label, options in LIKELIHOODS.items():
        for w in WINDOWS:
            one = xs.ExperimentSet.single(exp, defaults=base, inputs=inputs, window=w, sensors=["length"])
            res = cal.fit(one, ["Y"], likelihood=cal.Likelihood(**options), config=config)
            budget = res.budget[Y]
            rig = sum(v**2 for k, v in budget.items() if k in res.tolerances)
            se = res.standard_error[Y]
            rows[f"{label} {w[0]:g}-{w[1]:g}"] = {
                "likelihood": label,
                "window_s": list(w),
                "Y_Pa": res.estimate[Y],
                "se_Pa": se,
                "se_without_tolerances_Pa": float(np.sqrt(max(se**2 - rig, 0.0))),
                "interval_90_Pa": list(res.interval_90[Y]),
                "rmse_length_m": res.rmse_length_m,
                "budget_sd_Pa": budget,
                "tolerance_gain_Pa": next(iter(res.tolerance_gain.get(Y, {}).values()), {}),
                "tolerances": res.tolerances,
                "discrepancy": res.discrepancy,
                "samples_used": res.samples_used,
                "wall_s": res.wall_s,
                "status": res.status,
            }
            r = rows[f"{label} {w[0]:g}-{w[1]:g}"]
            lo, hi = r["interval_90_Pa"]
            print(
                f"{label:24s} {w[0]:4.1f}-{w[1]:4.1f} s: Y {r['Y_Pa']:7.0f} Pa, 90 % [{lo:7.0f}, {hi:7.0f}], "
                f"RMSE {1e3 * r['rmse_length_m']:.2f} mm, {r['wall_s']:.1f} s",
                flush=True,
            )
    pairs = []
    for label in LIKELIHOODS:
        for a, b in PAIRS:
            ra, rb = rows[f"{label} {a[0]:g}-{a[1]:g}"], rows[f"{label} {b[0]:g}-{b[1]:g}"]
            dy = abs(ra["Y_Pa"] - rb["Y_Pa"])
            z = dy / np.hypot(ra["se_Pa"], rb["se_Pa"])
            shared = sum(
                (ra["tolerance_gain_Pa"][k] - rb["tolerance_gain_Pa"][k]) ** 2 * u**2
                for k, u in ra["tolerances"].items()
            )
            z_diff = dy / np.sqrt(ra["se_without_tolerances_Pa"] ** 2 + rb["se_without_tolerances_Pa"] ** 2 + shared)
            pairs.append({"likelihood": label, "a": a, "b": b, "dY_Pa": dy, "z": z, "z_difference": z_diff})
            print(
                f"{label:24s} {a} vs {b}: |ΔY| {dy:6.0f} Pa = {z:.2f} combined se "
                f"({z_diff:.2f} se of the difference, the shared rig counted once)"
            )
    full = rows["discrepancy+tolerances 0-10"]
    width_share = (full["interval_90_Pa"][1] - full["interval_90_Pa"][0]) / 10e3
    print(f"0-10 s interval: {width_share:.2f} of the 5-15 kPa box (target <= 0.33)")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "environment": environment(),
                "rows": rows,
                "pairs": pairs,
                "interval_share_of_box": width_share,
                "wall_s": time.process_time(),
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
