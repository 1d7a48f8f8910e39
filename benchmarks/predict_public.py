"""Prediction beyond the fitted window of the public experiment: posterior on 0–7 s, 90 % band on 7–10 s.

Run: ``python benchmarks/predict_public.py [--chains 4 --warmup 500 --samples 500]``
``[--out benchmarks/results/predict_public.json]``.

Forward drive, reference growth law, the paper's priors, NUTS through the emulator (as ``growjax posterior
--emulate``). The predictive band on 7–10 s comes from :func:`growjax.posterior.forecast`: each draw's model
over 0–10 s, its discrepancy on 7–10 s conditioned on its residuals on 0–7 s, and noise. Printed: the share of
measured samples on 7–10 s inside the 90 % band (target 0.80–0.97) beside the band of the independent-noise
likelihood, the NUTS wall time, and a figure.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from growjax import posterior as gpost
from growjax.calibration import Likelihood
from growjax.data import sets as xs

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _environment import environment
from _public import public_experiment


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="folder of the public experiment (default: ../shared/data/mammobot)")
    ap.add_argument("--chains", type=int, default=4)
    ap.add_argument("--warmup", type=int, default=500)
    ap.add_argument("--samples", type=int, default=500)
    ap.add_argument("--split", type=float, default=7.0, help="end of the fitted window, s")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "predict_public.json"))
    args = ap.parse_args()
    exp, base, config, inputs = public_experiment(args.data)
    priors = gpost.paper_priors()
    later = (exp.time > args.split) & (exp.time <= 10.0)
    t_new, y_new = exp.time[later], exp["robot_length_m"][later]
    out, bands = {}, {}
    for label, kind in (("discrepancy", "matern32"), ("independent", "none")):
        clock = time.perf_counter()
        one = xs.ExperimentSet.single(exp, defaults=base, inputs=inputs, window=(config.t0, args.split))
        res = gpost.sample(
            one,
            config=config,
            priors=priors,
            likelihood=Likelihood(discrepancy=kind),
            chains=args.chains,
            warmup=args.warmup,
            samples=args.samples,
            progress=False,
            emulate=True,
        )
        nuts_s = time.perf_counter() - clock
        draws = gpost.forecast(res, priors, base, inputs, config, t_new)
        lo, hi = gpost.predictive_band(draws)
        coverage = float(np.mean((y_new >= lo) & (y_new <= hi)))
        bands[label] = (lo, hi)
        y = res.summary["parameters"]["Y"]
        out[label] = {
            "coverage_90_after_split": coverage,
            "Y_mean_Pa": y["mean"],
            "Y_interval_90_Pa": y["interval_90"],
            "rhat_max": res.summary["rhat_max"],
            "ess_bulk_min": res.summary["ess_bulk_min"],
            "divergences": res.summary["divergences"],
            "wall_s": nuts_s,
            "samples_used": res.summary["samples_used"],
            "discrepancy": {
                k: res.summary["parameters"][k]
                for k in ("delta_amplitude", "delta_time_scale")
                if k in res.summary["parameters"]
            },
        }
        print(
            f"{label:12s}: Y {y['mean']:.0f} Pa (90 % {y['interval_90'][0]:.0f}-{y['interval_90'][1]:.0f}); "
            f"band on {args.split:g}-10 s covers {coverage:.2f} of the measured samples; "
            f"R-hat {res.summary['rhat_max']:.3f}, {res.summary['divergences']} divergences, {nuts_s:.0f} s",
            flush=True,
        )
    path = Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"environment": environment(), "settings": vars(args), **out}, indent=1))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(exp.time, 1e3 * exp["robot_length_m"], "k-", lw=1, label="measured")
    for (label, (lo, hi)), colour in zip(bands.items(), ("C0", "C3")):
        ax.fill_between(
            t_new,
            1e3 * lo,
            1e3 * hi,
            color=colour,
            alpha=0.3,
            label=f"90 % band, {label} ({out[label]['coverage_90_after_split']:.0%} covered)",
        )
    ax.axvline(args.split, color="grey", ls="--", lw=0.8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("length (mm)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path.with_suffix(".png"), dpi=120)


if __name__ == "__main__":
    main()
