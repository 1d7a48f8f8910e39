"""Simulation-based calibration on data made by the reference configuration (data the fast model did not make).

Run: ``python benchmarks/sbc_reference.py [--replicates 100] [--t-end 0.8] [--noise-scale 2e-4]
[--out benchmarks/results/sbc_reference.json]``.

Y and σ are drawn from the prior (Y uniform 5–15 kPa, σ ~ HalfNormal(noise scale)); each replicate's clean
length comes from the **reference** configuration at its Y (published pulse train, 0–t_end), plus σ-noise;
NUTS samples Y and σ through the emulator of the fast configuration (its RMS error and the fast configuration's
error against the reference, ``--model-error``, join the noise; by default that error is measured here, over
the same window and samples, at 5 Y across the box: its largest RMS). A
calibrated posterior covers the truth with its 90 % interval in 0.8–0.97 of replicates
and ranks it uniformly. This is the check the default test run makes on data from the emulator itself.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import numpy as np
from scipy import stats

import growjax as gj
from growjax import posterior as gpost
from growjax.posterior import emulator as em

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "data"))
import make_synthetic as mk


def main():
    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--replicates", type=int, default=100)
    ap.add_argument("--t-end", type=float, default=0.8)
    ap.add_argument("--noise-scale", type=float, default=2e-4, help="σ ~ HalfNormal(this), m")
    ap.add_argument("--warmup", type=int, default=150)
    ap.add_argument("--samples", type=int, default=150)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--model-error",
        type=float,
        default=None,
        help="fast-vs-reference error joined to the noise, m (default: measured over the window; 0: none)",
    )
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "sbc_reference.json"))
    args = ap.parse_args()
    clock = time.perf_counter()
    cfg = gj.Config(t1=args.t_end)
    inputs = mk.reference_inputs("published")
    times = np.arange(0.01, args.t_end + 1e-9, 0.01)
    priors = gpost.paper_priors()[:1]
    emu = em.validate(em.build([em.Axis("Y", 5e3, 15e3, 41)], gj.reference(), inputs, cfg, times))
    reference = cfg.replace(fidelity="reference")
    breaks = gj.input_breaks(inputs, reference)

    def truth_model(values):  # {qualified name: (replicates,)} → (replicates, m) clean lengths, m
        out = []
        for i in range(len(next(iter(values.values())))):
            params = gj.replace(gj.reference(), **{name: float(v[i]) for name, v in values.items()})
            out.append(np.asarray(gj.simulate(params, inputs, reference, ts=times, breaks=breaks).length))
        return np.stack(out)

    if args.model_error is None:  # the fast configuration's own error here, at 5 Y across the prior's box
        ys = np.linspace(5e3, 15e3, 5)
        fast = np.stack(
            [
                np.asarray(gj.simulate(gj.replace(gj.reference(), Y=y), inputs, cfg, ts=times, breaks=breaks).length)
                for y in ys
            ]
        )
        ref = truth_model({"robot.yield_pressure": ys})
        model_error = float(np.max(np.sqrt(np.mean((fast - ref) ** 2, axis=1))))
    else:
        model_error = args.model_error
    res = gpost.sbc(
        emu,
        priors,
        replicates=args.replicates,
        warmup=args.warmup,
        samples=args.samples,
        seed=args.seed,
        noise_scale=args.noise_scale,
        truth_model=truth_model,
        model_error=model_error,
    )
    uniform = {
        s: float(stats.chisquare(np.histogram(r, bins=5, range=(0, res["draws"] + 1))[0]).pvalue)
        for s, r in res["ranks"].items()
    }
    out = {
        "replicates": args.replicates,
        "t_end_s": args.t_end,
        "noise_scale_m": args.noise_scale,
        "model_error_m": model_error,
        "emulator_error_rms_m": float(emu.error_rms),
        "coverage_90": res["coverage"],
        "rank_uniformity_p": uniform,
        "divergences": res["divergences"],
        "wall_s": time.perf_counter() - clock,
        "target_coverage": [0.8, 0.97],
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
