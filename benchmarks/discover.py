"""The discovery matrix: every catalogue effect × two magnitudes × seeds, plus clean seeds.

Run: ``python benchmarks/discover.py [--seeds 10] [--clean 20] [--t-end 10] [--effects NAME ...] [--factors 1 2]
[--first-seed 1000] [--first-clean-seed 2000] [--tolerance NAME=REL ...] [--baseline N] [--merge FILE ...]``
→ ``benchmarks/results/discover.json``. Data come from :func:`growjax.data.synthetic.make_experiment`
(the reference configuration; one noise-free trace per effect and magnitude, seeds add noise), and
every run is :func:`growjax.discover.discover` over the whole catalogue on the fast configuration.

Reported: the share of runs that name the hidden effect (or, where it trades with a base parameter or
another effect, report it confounded), the share that claim another catalogue effect, the false-positive rate on clean
data (any effect claimed or confounded), the coverage of the magnitude by its 90 % interval where the effect is named,
the median RMSE after / noise, and what a run's time is made of (fits, linearisations, wall time per linearisation).
A linearisation's time per candidate switched on, and what it is made of: ``benchmarks/discover_linearise.py
--per-effect``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import growjax as gj
from growjax import discover as gd
from growjax.calibration import Likelihood
from growjax.calibration import tolerance as tl
from growjax.data import experiment as ex
from growjax.data import synthetic as sy
from growjax.data.sets import ExperimentSet
from growjax.model import effects as fx
from growjax.model import params as gp

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment


def one_run(effect, magnitude, seed, t_end, discrepancy="matern32", tolerances=None):
    exp = sy.make_experiment(effect, magnitude, seed=seed, t_end=t_end)
    cfg = gj.Config(t1=t_end)
    inputs = ex.to_inputs(exp, "forward", gj.reference(), cfg.t0, cfg.t1)
    start = time.perf_counter()
    res = gd.discover(
        ExperimentSet.single(exp, inputs=inputs),
        config=cfg,
        likelihood=Likelihood(discrepancy=discrepancy, tolerances=tolerances),
    )
    truth = exp.metadata
    named = res.effect == effect
    confounded = res.effect == "confounded" and effect in res.confounded_with  # not if another effect is claimed
    covered = None
    if named and truth["parameter"] in res.parameters:
        lo, hi = res.parameters[truth["parameter"]]["interval_90"]
        covered = bool(lo <= truth["magnitude"] <= hi)
    return {
        "effect": effect,
        "magnitude": magnitude,
        "seed": seed,
        "found": res.effect,
        "named": named,
        "confounded": confounded,
        "covered": covered,
        "rmse_before_m": res.rmse_before_m,
        "rmse_after_m": res.rmse_after_m,
        "noise_m": truth["noise_sd"]["robot_length_m"],
        "wall_s": time.perf_counter() - start,
        "fits": res.fits,
        "linearisations": res.linearisations,
        # why: each round's 2ΔlogL per candidate, the confounded ones (with their rivals), the misfit test
        "lr_statistics": [{n: s["lr_statistic"] for n, s in scores.items()} for scores in res.evidence],
        "confounded_with": {
            n: {
                "parameter": c["parameter"],
                "correlation": c["correlation"],
                "rival_effects": c.get("rival_effects", []),
            }
            for n, c in res.confounded_with.items()
        },
        "threshold": res.threshold,
        "misfit_before": res.misfit_before,
        "tolerances": tolerances,
    }


def tolerances_of(options: list) -> dict | None:
    """discover's ``tolerances`` from ``--tolerance`` options: None (the default budget), {} for ``none``, or the
    default budget with the options over it."""
    if not options:
        return None
    if [o.strip().lower() for o in options] == ["none"]:
        return {}
    base = gj.reference()
    return {**tl.default_budget(base), **{gp.resolve_name(base, n): u for n, u in map(tl.parse, options)}}


def rig_label(runs) -> str:
    """How the runs scored the rig: the default budget, known exactly, or the budget with overrides."""
    labels, default = set(), tl.default_budget(gj.reference())
    for r in runs:
        tol = r.get("tolerances")
        labels.add(
            "default tolerance budget"
            if tol is None
            else "known (tolerances 0)"
            if not tol
            else "default budget, " + ", ".join(f"{n} {u:g}" for n, u in tol.items() if default.get(n) != u)
        )
    return "; ".join(sorted(labels))


def summarise(runs, baseline, args) -> dict:
    """The matrix's figures from its runs (and the independent-noise baseline runs)."""
    hidden = [r for r in runs if r["effect"] is not None]
    clean = [r for r in runs if r["effect"] is None]
    covered = [r["covered"] for r in hidden if r["covered"] is not None]
    summary = {
        "environment": environment(),
        "t_end_s": args.t_end,
        "factors": args.factors,
        "rig": rig_label(runs),
        "named_or_confounded_share": float(np.mean([r["named"] or r["confounded"] for r in hidden]))
        if hidden
        else None,
        "named_share_per_effect": {
            e: float(np.mean([r["named"] for r in hidden if r["effect"] == e])) for e in args.effects if hidden
        },
        "wrong_effect_share": float(np.mean([r["found"] in fx.CATALOGUE and r["found"] != r["effect"] for r in hidden]))
        if hidden
        else None,
        "false_positive_rate": float(np.mean([r["found"] != "none" for r in clean])) if clean else None,
        "interval_coverage": float(np.mean(covered)) if covered else None,
        "median_rmse_after_over_noise": statistics.median(r["rmse_after_m"] / r["noise_m"] for r in hidden)
        if hidden
        else None,
        "median_wall_s": statistics.median(r["wall_s"] for r in runs),
        # what a run's time is made of: fits × LM steps, each a linearisation of the superset (one forward-mode solve)
        "median_fits": statistics.median(r["fits"] for r in runs),
        "median_linearisations": statistics.median(r["linearisations"] for r in runs),
        "median_wall_ms_per_linearisation": statistics.median(1e3 * r["wall_s"] / r["linearisations"] for r in runs),
        # the same clean seeds under independent noise: the discrepancy likelihood's cost, in one process
        "wall_ratio_to_independent": statistics.median(r["wall_s"] for r in clean[: len(baseline)])
        / statistics.median(r["wall_s"] for r in baseline)
        if baseline
        else None,
        "baseline_runs": baseline,
        "runs": runs,
    }
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--clean", type=int, default=20)
    parser.add_argument("--t-end", type=float, default=10.0)
    parser.add_argument("--effects", nargs="+", default=list(fx.CATALOGUE))
    parser.add_argument(
        "--factors",
        nargs="+",
        type=float,
        default=[1.0, 2.0],
        help="magnitudes as multiples of each effect's moderate magnitude (default 1 2)",
    )
    parser.add_argument("--first-seed", type=int, default=1000, help="seed of the first hidden-effect run")
    parser.add_argument("--first-clean-seed", type=int, default=2000, help="seed of the first clean run")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "discover.json"))
    parser.add_argument(
        "--tolerance",
        action="append",
        default=[],
        metavar="NAME=REL",
        help="a rig tolerance over the default budget, as for `growjax discover` (repeat; 'none': "
        "the rig known exactly)",
    )
    parser.add_argument(
        "--baseline",
        type=int,
        default=0,
        help="run the first N clean seeds also under independent noise (the likelihood discovery "
        "had before the discrepancy), for the ratio of median wall times",
    )
    parser.add_argument(
        "--merge",
        nargs="+",
        default=None,
        metavar="FILE",
        help="join matrices written by earlier runs (e.g. seeds split over two processes) into --out",
    )
    args = parser.parse_args()
    if args.merge:
        parts = [json.loads(Path(f).read_text()) for f in args.merge]
        runs = [r for part in parts for r in part["runs"]]
        baseline = [r for part in parts for r in part.get("baseline_runs", [])]
        summary = summarise(runs, baseline, args)
        summary["merged_from"] = [Path(f).name for f in args.merge]
        Path(args.out).write_text(json.dumps(summary, indent=2, default=str) + "\n")
        print(json.dumps({k: v for k, v in summary.items() if k not in ("runs", "baseline_runs")}, indent=2))
        return
    rig = tolerances_of(args.tolerance)
    runs = []
    for effect in args.effects:
        for factor in args.factors:
            magnitude = factor * sy.moderate_magnitude(effect)
            for seed in range(args.seeds):
                runs.append(one_run(effect, magnitude, args.first_seed + seed, args.t_end, tolerances=rig))
                print(json.dumps(runs[-1]), flush=True)
    for seed in range(args.clean):
        runs.append(one_run(None, None, args.first_clean_seed + seed, args.t_end, tolerances=rig))
        print(json.dumps(runs[-1]), flush=True)
    baseline = [
        one_run(None, None, args.first_clean_seed + seed, args.t_end, discrepancy="none")
        for seed in range(min(args.baseline, args.clean))
    ]
    summary = summarise(runs, baseline, args)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(summary, indent=2, default=str) + "\n")
    print(json.dumps({k: v for k, v in summary.items() if k != "runs"}, indent=2))


if __name__ == "__main__":
    main()
