"""End-to-end calibration of the public MAMMOBOT experiment: fits, identifiability, posteriors of two growth laws, LOO.

Run from the repository root::

    python calibration/calibrate_public.py [--quick] [--out out/calibration] \
        [--results calibration/results/calibration.json]

Every step uses the default likelihood of ``growjax fit`` and ``growjax posterior``: the length as the model plus
a Matérn-3/2 discrepancy plus sensor noise, the rig's default tolerance budget with the rig's errors inferred
(fit: fitted as nuisance parameters with the tolerances as Gaussian priors; posterior: marginalised exactly).
Steps (forward drive, fast configuration, 0–10 s):

1. fit of Y (reference growth law) with its 90 % interval and its budget by source, and the fit of Y, ext
   and n that names the directions the data cannot determine; for contrast, the fit of Y under independent
   noise with the rig taken as exact (``--discrepancy none``);
2. NUTS posterior of Y, ext, n, σ and the discrepancy's hyperparameters (reference law), 4 chains × 500 + 500,
   through the emulator of the model (ext and n are flat: directly through the model every draw would hit
   the tree-depth cap); the fit's interval of Y beside the posterior's, and the posterior's predictive band;
3. NUTS posterior of Y, φ_L, n_L and the rest (Lockhart law), same settings, through its emulator (directly
   through the model it would take ~30–50 h here: ``benchmarks/nuts_direct.py``);
4. PSIS-LOO comparison of the two laws (ArviZ), the Laplace-against-NUTS check, figures and ``report.json``
   in ``--out``; the figures the Results page reads in ``--results`` (with the machine and versions).

``--quick`` (a smoke run): 0–2 s, 2 chains × 150 + 150; writes no ``--results`` unless it is given.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import growjax as gj
from growjax import calibration as cal
from growjax import posterior as gpost
from growjax.data import experiment as ex
from growjax.data import sets as xs
from growjax.plotting import posterior_figures, predictive_figure, trajectory_figure

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment

Y = "robot.yield_pressure"


def _prior_sd(p: gpost.Prior) -> float:
    if p.log:
        return float(np.sqrt((np.log(p.high) - np.log(p.low)) ** 2 / 12.0))  # sd of ln θ
    return (p.high - p.low) / np.sqrt(12.0)


def _identification(idata, priors) -> dict:
    """Posterior sd over prior sd per parameter (in ln θ for log-uniform priors): ~0 determined, ~1 not."""
    out = {}
    for p in priors:
        x = np.asarray(idata.posterior[p.site]).ravel()
        x = np.log(x) if p.log else x
        out[p.site] = float(x.std() / _prior_sd(p))
    return out


def _band(result, observed_times):
    pp = np.asarray(result.idata.posterior_predictive["length"])
    pp = pp.reshape(-1, pp.shape[-1])
    lo, hi = gpost.predictive_band(pp)
    mu = np.asarray(result.idata.posterior_predictive["length_model"]).reshape(-1, pp.shape[-1])
    return lo, hi, np.median(mu, axis=0)


def _interval(estimate, interval) -> dict:
    lo, hi = interval
    return {"estimate_Pa": float(estimate), "interval_90_Pa": [float(lo), float(hi)], "width_Pa": float(hi - lo)}


def page_record(report: dict, y_fit, all_fit, contrast, results: dict, priors: dict) -> dict:
    """What the Results page shows: Y under the default likelihood (fit and posterior, both laws), its budget,
    the predictive band's coverage, LOO, and the independent-noise fit as a contrast."""
    fit = _interval(y_fit.estimate[Y], y_fit.interval_90[Y])
    fit.update(
        budget_sd_Pa=y_fit.budget.get(Y, {}),
        rmse_length_m=y_fit.rmse_length_m,
        rig_offset=next(iter(y_fit.rig_offset.values()), {}),  # the experiment's rig
        wall_s=y_fit.wall_s,
    )
    posterior = {}
    for law, res in results.items():
        s = res.summary
        posterior[law] = {
            "parameters": {k: {"mean": v["mean"], "interval_90": v["interval_90"]} for k, v in s["parameters"].items()},
            **{
                k: s[k]
                for k in ("coverage_90", "coverage_90_new_experiment", "rhat_max", "ess_bulk_min", "divergences")
            },
            "posterior_sd_over_prior_sd": report["posterior"][law]["posterior_sd_over_prior_sd"],
            "priors": {p.site: {"low": p.low, "high": p.high, "log": p.log} for p in priors[law]},
            "wall_s": res.wall_s,
        }
    y_post = posterior["reference"]["parameters"]["Y"]["interval_90"]
    independent = _interval(contrast.estimate[Y], contrast.interval_90[Y])
    independent.update(rmse_length_m=contrast.rmse_length_m)
    return {
        "environment": environment(),
        "command": "python calibration/calibrate_public.py",
        "data": Path(str(report["data"])).name,
        "t_end_s": report["t_end_s"],
        "chains": report["chains"],
        "warmup": report["warmup"],
        "samples": report["samples"],
        "likelihood": {
            "discrepancy": y_fit.discrepancy,
            "tolerances": y_fit.tolerances,
            "rig": y_fit.rig,
            "samples_used": y_fit.samples_used,
        },
        "fit": fit,
        "fit_Y_ext_n": {"estimate": all_fit.estimate, "undetermined_directions": all_fit.undetermined},
        "posterior": posterior,
        "fit_over_posterior_width_Y": fit["width_Pa"] / (y_post[1] - y_post[0]),
        "loo": report["loo"],
        "independent_noise_fit": independent,
        "wall_s": report["wall_s"],
    }


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="out/calibration")
    parser.add_argument(
        "--results",
        default=None,
        help="the Results page's figures (JSON); default calibration/results/calibration.json, none with --quick",
    )
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    results_path = args.results or (None if args.quick else str(REPO / "calibration" / "results" / "calibration.json"))
    folder = ex.shared_experiment_dir()
    if folder is None:
        raise SystemExit("the public experiment (../shared/data/mammobot) is not beside this checkout")
    exp = ex.read(folder / "experiment.csv")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_end, chains, warmup, samples = (2.0, 2, 150, 150) if args.quick else (10.0, 4, 500, 500)
    report = {"data": exp.source, "t_end_s": t_end, "chains": chains, "warmup": warmup, "samples": samples}
    clock = time.perf_counter()

    # 1. Fits (reference growth law), the default likelihood; independent noise for contrast.
    base = gj.reference()
    cfg = gj.Config(t1=t_end, adjoint="forward")
    inputs = ex.to_inputs(exp, "forward", base, cfg.t0, cfg.t1)
    one = xs.ExperimentSet.single(exp, defaults=base, inputs=inputs, sensors=["length"])
    y_fit = cal.fit(one, ["Y"], config=cfg)
    report["fit_Y"] = y_fit.summary()
    all_fit = cal.fit(one, ["Y", "ext", "n"], config=cfg)
    report["fit_Y_ext_n"] = all_fit.summary()
    contrast = cal.fit(one, ["Y"], likelihood=cal.Likelihood(discrepancy="none"), config=cfg)
    report["fit_Y_independent_noise"] = contrast.summary()
    traj = gj.simulate(gj.replace(base, **y_fit.estimate), inputs, cfg)
    trajectory_figure(
        traj,
        out / "fit.png",
        measured=(exp.time, exp["robot_length_m"]),
        title=f"fitted Y = {y_fit.estimate[Y]:.0f} Pa: RMSE {1e3 * y_fit.rmse_length_m:.2f} mm",
    )
    print(f"[{time.perf_counter() - clock:.0f} s] fits done", flush=True)

    # 2–3. Posteriors of both growth laws.
    # Lockhart's posterior sits against two bounds of its box (Y = 5 kPa, n_L = 0.25): a higher target
    # acceptance shortens the steps there (one-off comparison, 2000 draws: 9 divergences at 0.9, 3 at 0.98).
    laws = {
        "reference": (base, gpost.paper_priors(), 0.9),
        "lockhart": (gj.reference(growth_law="lockhart"), gpost.lockhart_priors(), 0.98),
    }
    results, report["posterior"] = {}, {}
    for law, (law_base, priors, accept) in laws.items():
        law_inputs = ex.to_inputs(exp, "forward", law_base, cfg.t0, cfg.t1)
        res = gpost.sample(
            xs.ExperimentSet.single(exp, defaults=law_base, inputs=law_inputs),
            config=cfg,
            priors=priors,
            chains=chains,
            warmup=warmup,
            samples=samples,
            progress=False,
            target_accept=accept,
            emulate=True,
        )  # direct NUTS: max tree depth (reference), ~30–50 h (Lockhart)
        res.idata.to_netcdf(str(out / f"posterior_{law}.nc"))
        summary = dict(res.summary)
        summary["posterior_sd_over_prior_sd"] = _identification(res.idata, priors)
        report["posterior"][law] = summary
        results[law] = res
        posterior_figures(res.idata, [p.site for p in priors] + ["sigma_mm"], out, prefix=f"{law}_")
        print(
            f"[{time.perf_counter() - clock:.0f} s] posterior ({law}) done: wall {res.wall_s:.0f} s, "
            f"R-hat {summary['rhat_max']:.4f}, divergences {summary['divergences']}",
            flush=True,
        )

    # 4. LOO, Laplace against NUTS, figures.
    report["loo"] = gpost.compare_loo(results)
    lap = gpost.laplace(y_fit)[Y]
    nuts = report["posterior"]["reference"]["parameters"]["Y"]
    report["laplace_vs_nuts_Y"] = {
        "laplace": lap,
        "nuts": {k: nuts[k] for k in ("mean", "sd", "interval_90")},
        "mean_difference_in_nuts_sd": (lap["mean"] - nuts["mean"]) / nuts["sd"],
        "sd_ratio": lap["sd"] / nuts["sd"],
        "laplace_wall_s": y_fit.wall_s,
    }
    keep = (exp.time >= cfg.t0) & (exp.time <= cfg.t1)
    predictive_figure(
        exp.time[keep],
        exp["robot_length_m"][keep],
        {law: _band(r, exp.time[keep]) for law, r in results.items()},
        out / "predictive.png",
        title="posterior predictive, reference and Lockhart growth laws",
    )
    report["wall_s"] = time.perf_counter() - clock
    (out / "report.json").write_text(json.dumps(report, indent=2, default=str) + "\n")
    if results_path:
        record = page_record(report, y_fit, all_fit, contrast, results, {k: v[1] for k, v in laws.items()})
        Path(results_path).parent.mkdir(parents=True, exist_ok=True)
        text = json.dumps(record, indent=1, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))
        Path(results_path).write_text(text + "\n")
        print("wrote", results_path)
    print(json.dumps({k: report[k] for k in ("loo", "laplace_vs_nuts_Y", "wall_s")}, indent=2, default=str))


if __name__ == "__main__":
    main()
