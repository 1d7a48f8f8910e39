"""Coverage of the fit's 90 % interval of Y on reference-made data that the fitted model does not reproduce.

Run: ``python benchmarks/coverage_discrepancy.py [--per-group 30] [--out
benchmarks/results/coverage_discrepancy.json]``.

Data: the shipped reference-configuration traces (``data/reference_lengths.csv``: the published pulse, Y from
5 to 15 kPa), fitted by the fast configuration, with one of:

* ``none``: white sensor noise of 0.2 mm alone;
* ``smooth``: a smooth random perturbation (a squared-exponential Gaussian process, a kernel other than the
  likelihood's, time scale 0.3, 1 or 3 s) of 0.02–0.5 mm RMS, plus the white noise;
* ``correlated``: correlated sensor noise (AR(1), correlation time 0.2 s) of 0.02–0.5 mm sd plus 0.05 mm white;
* ``rig``: the rig's toleranced parameters drawn from their declared tolerances (a new reference run per set),
  plus the white noise.

Each set is fitted with the Matérn-3/2 discrepancy and the tolerances that describe how its rig was made:
none for the first three groups (the rig is the nominal one), the default budget for ``rig`` (the data drawn
from it); ``--budget default`` fits every group as ``growjax fit`` does, with the default budget (the rig's errors
inferred though the rig is nominal). The rig's errors are parameters of the model, as ``growjax fit`` fits them
(``rig_tangents=True``); ``--no-rig-tangents``: its secants, relinearised, or with ``--no-relinearise`` linearised
once at nominal (the fit's ``relinearise=False``). The ``none`` sets are also fitted under independent noise, to
compare the widths (no blanket inflation: the discrepancy's interval within 1.5× of the independent one). Target: the
90 % interval covers the true Y in 0.80–0.97 of the sets of each group.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax import calibration as cal
from growjax.calibration import tolerance as tl
from growjax.data import experiment as ex
from growjax.data import sets as xs

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment

sys.path.insert(0, str(REPO / "data"))
import make_synthetic as mk

NOISE = 2e-4  # m
SIZES = (2e-5, 5e-5, 1e-4, 2e-4, 5e-4)  # m RMS
SMOOTH_TIMES = (0.3, 1.0, 3.0)  # s
Y = "robot.yield_pressure"


def smooth_perturbation(rng, t, size, scale):
    """A squared-exponential GP draw on t, rescaled to RMS ``size`` (m)."""
    k = np.exp(-0.5 * ((t[:, None] - t[None, :]) / scale) ** 2) + 1e-9 * np.eye(t.size)
    d = np.linalg.cholesky(k) @ rng.standard_normal(t.size)
    return d * size / np.sqrt(np.mean(d**2))


def ar1(rng, t, sd, tau):
    phi = np.exp(-np.diff(t, prepend=t[0] - (t[1] - t[0])) / tau)
    x = np.empty(t.size)
    x[0] = rng.normal(0.0, sd)
    for i in range(1, t.size):
        x[i] = phi[i] * x[i - 1] + rng.normal(0.0, sd * np.sqrt(1.0 - phi[i] ** 2))
    return x


def rig_traces(n, seed, t):
    """(Y truths, lengths (n, T), drawn relative offsets) from reference runs with the rig's tolerances drawn."""
    base = mk.case_parameters({})
    budget = tl.default_budget(base)
    rng = np.random.default_rng(seed)
    ys = rng.uniform(6e3, 12e3, n)
    offsets = {k: rng.normal(0.0, u, n) for k, u in budget.items()}
    inputs = mk.reference_inputs("published")
    config = gj.Config(fidelity="reference", t1=float(t[-1]))
    ts = jnp.asarray(np.concatenate([[config.t0], t]))

    def run(y, offs):
        p = gj.replace(base, Y=y, **{k: gj.get(base, k) * jnp.exp(offs[k]) for k in budget})
        traj = gj.simulate(p, inputs, config, ts=ts)
        return traj.length[1:], traj.status

    lengths, status = jax.jit(jax.vmap(run))(jnp.asarray(ys), {k: jnp.asarray(v) for k, v in offsets.items()})
    return ys, np.asarray(lengths), np.asarray(status), offsets


def fit_row(t, data, inputs, truth, relinearise=True, rig_tangents=True, **options):
    one = xs.ExperimentSet.single(ex.from_arrays(t, data), inputs=inputs)
    config = gj.Config(t1=10.0)
    res = cal.fit(
        one,
        ["Y"],
        likelihood=cal.Likelihood(**options),
        config=config,
        starts=1,
        scout=16,
        relinearise=relinearise,
        rig_tangents=rig_tangents,
    )
    extra = {"linearisations": res.linearisations} if res.rig == "inferred" else {}
    lo, hi = res.interval_90[Y]
    return {
        "truth_Pa": truth,
        "estimate_Pa": res.estimate[Y],
        "se_Pa": res.standard_error[Y],
        "interval_90_Pa": [lo, hi],
        "covered": bool(lo <= truth <= hi),
        "width_Pa": hi - lo,
        "discrepancy": res.discrepancy,
        "rmse_m": res.rmse_length_m,
        "wall_s": res.wall_s,
        **extra,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--per-group", type=int, default=30, help="data sets per perturbed group (the clean group: a third)"
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--groups", nargs="+", default=["none", "smooth", "correlated", "rig"])
    ap.add_argument(
        "--budget",
        choices=["group", "default"],
        default="group",
        help="group: the tolerances the group's rig was made with; default: the default budget for all",
    )
    ap.add_argument(
        "--rig-tangents",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="the rig's errors as parameters of the model (default, as growjax fit); --no-rig-tangents: its secants",
    )
    ap.add_argument(
        "--relinearise",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="with --no-rig-tangents: the fit's relinearise (default on, as growjax fit)",
    )
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "coverage_discrepancy.json"))
    args = ap.parse_args()
    clock = time.perf_counter()
    t, lengths, cases = mk.read_reference_lengths()
    published = [k for k, c in cases.items() if c["demand"] == "published" and set(c["parameters"]) == {"Y"}]
    inputs = mk.reference_inputs("published")
    rng = np.random.default_rng(args.seed)
    rows = {g: [] for g in args.groups}
    n_clean = max(10, args.per_group // 3)
    for g in args.groups:
        n = n_clean if g == "none" else args.per_group
        if g == "rig":
            ys, traces, status, offsets = rig_traces(n, args.seed + 1, t)
        for k in range(n):
            size = SIZES[k % len(SIZES)]
            if g == "rig":
                if int(status[k]) != gj.OK:
                    continue
                truth, clean = float(ys[k]), traces[k]
            else:
                case = published[(k * 7 + args.seed) % len(published)]
                truth, clean = cases[case]["parameters"]["Y"], lengths[case]
            if g == "smooth":
                extra = smooth_perturbation(rng, t, size, SMOOTH_TIMES[k % len(SMOOTH_TIMES)])
                noise = rng.normal(0.0, NOISE, t.size)
            elif g == "correlated":
                extra, noise = ar1(rng, t, size, 0.2), rng.normal(0.0, 5e-5, t.size)
            else:
                extra, noise = 0.0, rng.normal(0.0, NOISE, t.size)
            data = clean + extra + noise
            row = {
                "size_m": size if g in ("smooth", "correlated") else 0.0,
                "default": fit_row(
                    t,
                    data,
                    inputs,
                    truth,
                    relinearise=args.relinearise,
                    rig_tangents=args.rig_tangents,
                    **({} if g == "rig" or args.budget == "default" else {"tolerances": {}}),
                ),
            }
            if g == "none":
                row["independent"] = fit_row(t, data, inputs, truth, discrepancy="none")
            if g == "rig":
                row["offsets"] = {name: float(v[k]) for name, v in offsets.items()}
            rows[g].append(row)
            d = row["default"]
            print(
                f"{g:10s} {k:3d} size {1e3 * row['size_m']:.2f} mm: Y {d['estimate_Pa']:7.0f} for {truth:7.0f} Pa, "
                f"90 % [{d['interval_90_Pa'][0]:7.0f}, {d['interval_90_Pa'][1]:7.0f}] covered {d['covered']}",
                flush=True,
            )
    summary = {}
    for g, rs in rows.items():
        cov = float(np.mean([r["default"]["covered"] for r in rs])) if rs else float("nan")
        summary[g] = {"sets": len(rs), "coverage_90": cov}
        if g == "none" and rs:
            ratio = [r["default"]["width_Pa"] / r["independent"]["width_Pa"] for r in rs]
            summary[g]["width_ratio_vs_independent"] = {"median": float(np.median(ratio)), "max": float(np.max(ratio))}
            summary[g]["coverage_90_independent"] = float(np.mean([r["independent"]["covered"] for r in rs]))
        print(g, summary[g], flush=True)
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
