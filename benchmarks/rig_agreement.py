"""Fit and posterior treat the rig alike: Y's 90 % interval from ``growjax fit`` (the rig inferred, the default;
and ``--rig fixed``) beside the posterior's, with coverage, on reference-made data with the default budget on.

Run: ``python benchmarks/rig_agreement.py [--per-group 10] [--posterior-every 1]``
``[--out benchmarks/results/rig_agreement.json]``.

Data: reference-configuration runs of the published pulse train (Y uniform on 6–12 kPa), 0.2 mm white noise at
100 Hz, in two groups: ``nominal`` (the rig exactly nominal: the shipped reference traces) and ``drawn`` (each
set's rig drawn from the default tolerance budget, a new reference run per set), plus the shipped synthetic
experiment. Every set is fitted by the fast configuration with the default likelihood and tolerance budget:
``fit`` with the rig inferred (relinearised where the data put the rig, the default) and with it fixed, and every
``--posterior-every``-th set also by NUTS through the emulator (``posterior --emulate``'s priors: Y, ext, n; the rig
linearised where its own fit puts it, the default). Targets: the posterior's and the inferred fit's widths
within 25 % of each other; coverage 0.80–0.97 per group.
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
from growjax import posterior as gpost
from growjax.data import experiment as ex
from growjax.data import sets as xs

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment
from coverage_discrepancy import NOISE, rig_traces

sys.path.insert(0, str(REPO / "data"))
import make_synthetic as mk

Y = "robot.yield_pressure"


def interval_row(lo, hi, truth, estimate, wall):
    return {
        "estimate_Pa": estimate,
        "interval_90_Pa": [lo, hi],
        "width_Pa": hi - lo,
        "covered": bool(lo <= truth <= hi),
        "wall_s": wall,
    }


def fit_row(t, data, inputs, base, truth, rig, pressure=None):
    res = cal.fit(
        xs.ExperimentSet.single(ex.from_arrays(t, data, pressure), defaults=base, inputs=inputs),
        ["Y"],
        likelihood=cal.Likelihood(rig=rig),
        config=gj.Config(t1=10.0),
        starts=1,
        scout=16,
    )
    return {
        **interval_row(*res.interval_90[Y], truth, res.estimate[Y], res.wall_s),
        "linearisations": res.linearisations,
    }


def posterior_row(t, data, inputs, base, truth, args):
    clock = time.perf_counter()
    res = gpost.sample(
        xs.ExperimentSet.single(ex.from_arrays(t, data), defaults=base, inputs=inputs),
        config=gj.Config(t1=10.0),
        priors=gpost.paper_priors(),
        chains=args.chains,
        warmup=args.warmup,
        samples=args.samples,
        progress=False,
        emulate=True,
    )
    y = res.summary["parameters"]["Y"]
    row = interval_row(*y["interval_90"], truth, y["mean"], time.perf_counter() - clock)
    row.update(
        coverage_band_90=res.summary["coverage_90"],
        coverage_band_90_new_experiment=res.summary["coverage_90_new_experiment"],
        rhat_max=res.summary["rhat_max"],
        divergences=res.summary["divergences"],
        linearisations=res.summary["linearisations"],
        rig_centre=res.summary["rig_centre"],
    )
    return row


def data_sets(args):
    """(group, truth, times, data, inputs, base, pressure) per set."""
    t, lengths, cases = mk.read_reference_lengths()
    inputs = mk.reference_inputs("published")
    base = mk.case_parameters({})
    rng = np.random.default_rng(args.seed)
    published = sorted(k for k, c in cases.items() if c["demand"] == "published" and set(c["parameters"]) == {"Y"})
    for k in range(args.per_group):
        case = published[k % len(published)]
        yield (
            "nominal",
            cases[case]["parameters"]["Y"],
            t,
            lengths[case] + rng.normal(0.0, NOISE, t.size),
            inputs,
            base,
            None,
        )
    ys, traces, status, _ = rig_traces(args.per_group, args.seed + 1, t)
    for k in range(args.per_group):
        if int(status[k]) == gj.OK:
            yield "drawn", float(ys[k]), t, traces[k] + rng.normal(0.0, NOISE, t.size), inputs, base, None
    path = files("growjax.data") / "datasets" / "synthetic_forward.csv"
    exp = ex.read(path)
    record = json.loads(Path(str(path)).with_suffix(".json").read_text())
    truth = float(record["truth"]["Y"])
    shipped_base = gj.replace(gj.reference("forward"), Y=truth)
    config = gj.Config(t1=10.0)
    yield (
        "shipped",
        truth,
        exp.time,
        exp["robot_length_m"],
        ex.to_inputs(exp, "forward", shipped_base, config.t0, 10.0),
        shipped_base,
        exp["pressure_Pa"] if "pressure_Pa" in exp else None,
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-group", type=int, default=10)
    ap.add_argument("--posterior-every", type=int, default=1, help="NUTS on every k-th set (0: none)")
    ap.add_argument("--chains", type=int, default=4)
    ap.add_argument("--warmup", type=int, default=500)
    ap.add_argument("--samples", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "rig_agreement.json"))
    args = ap.parse_args()
    clock = time.perf_counter()
    rows = []
    for i, (group, truth, t, data, inputs, base, pressure) in enumerate(data_sets(args)):
        row = {
            "group": group,
            "truth_Pa": truth,
            "fit_inferred": fit_row(t, data, inputs, base, truth, "inferred", pressure),
            "fit_fixed": fit_row(t, data, inputs, base, truth, "fixed", pressure),
        }
        if args.posterior_every and (i % args.posterior_every == 0 or group == "shipped"):
            row["posterior"] = posterior_row(t, data, inputs, base, truth, args)
            row["width_ratio_fit_over_posterior"] = row["fit_inferred"]["width_Pa"] / row["posterior"]["width_Pa"]
        rows.append(row)
        shown = " ".join(
            f"{k} [{r['interval_90_Pa'][0]:.0f}, {r['interval_90_Pa'][1]:.0f}]"
            for k in ("fit_inferred", "fit_fixed", "posterior")
            if (r := row.get(k))
        )
        print(f"{group:8s} {i:3d} Y {truth:.0f} Pa: {shown}", flush=True)
    summary = {}
    for group in ("nominal", "drawn", "shipped"):
        rs = [r for r in rows if r["group"] == group]
        if not rs:
            continue
        s = {"sets": len(rs)}
        for k in ("fit_inferred", "fit_fixed", "posterior"):
            have = [r[k] for r in rs if k in r]
            if have:
                s[k] = {
                    "sets": len(have),
                    "coverage_90": float(np.mean([h["covered"] for h in have])),
                    "median_width_Pa": float(np.median([h["width_Pa"] for h in have])),
                }
        ratios = [r["width_ratio_fit_over_posterior"] for r in rs if "width_ratio_fit_over_posterior" in r]
        if ratios:
            s["width_ratio_fit_over_posterior"] = {
                "min": float(np.min(ratios)),
                "median": float(np.median(ratios)),
                "max": float(np.max(ratios)),
            }
            s["posterior"]["band_coverage_90"] = float(
                np.mean([r["posterior"]["coverage_band_90"] for r in rs if "posterior" in r])
            )
        s["inferred_over_fixed_width"] = float(
            np.median([r["fit_inferred"]["width_Pa"] / r["fit_fixed"]["width_Pa"] for r in rs])
        )
        summary[group] = s
        print(group, json.dumps(s), flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "environment": environment(),
                "arguments": vars(args),
                "summary": summary,
                "rows": rows,
                "wall_s": time.perf_counter() - clock,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
