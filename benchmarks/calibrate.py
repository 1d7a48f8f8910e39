"""Benchmark of calibration on the measured data: fit time, NUTS cost, and the fast approximation.

Run: ``python benchmarks/calibrate.py [--out benchmarks/results/calibrate.json] [--t-end 10]
[--chains 4 --warmup 500 --samples 500] [--direct-iterations 20]``. The JSON holds:

* ``fit``: the least-squares fit of Y, first call (with compilation) and a second, compiled call;
* ``laplace``: the Gauss–Newton approximation at that fit (the fast approximation; its cost is the fit's);
* ``nuts``: the full NUTS run through the emulator (wall time including the emulator's build and
  validation, minimum bulk ESS per second, R-hat, divergences) and its agreement with the Laplace interval;
* ``nuts_direct``: a short NUTS run through the ODE itself (forward-mode gradients), with the wall
  time of the full run extrapolated from it: the baseline the emulator is measured against.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax import calibration as cal
from growjax import posterior as gpost
from growjax.data import experiment as ex
from growjax.data import sets as xs

REPO = Path(__file__).resolve().parents[1]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "calibrate.json"))
    parser.add_argument("--t-end", type=float, default=10.0)
    parser.add_argument("--chains", type=int, default=4)
    parser.add_argument("--warmup", type=int, default=500)
    parser.add_argument("--samples", type=int, default=500)
    parser.add_argument("--direct-iterations", type=int, default=20, help="warm-up = draws of the direct baseline")
    args = parser.parse_args()
    folder = ex.shared_experiment_dir()
    exp = (
        ex.read(folder / "experiment.csv")
        if folder
        else ex.read(REPO / "src" / "growjax" / "data" / "datasets" / "synthetic_forward.csv")
    )
    base = gj.reference()
    cfg = gj.Config(t1=args.t_end)
    inputs = ex.to_inputs(exp, "forward", base, cfg.t0, cfg.t1)
    one = xs.ExperimentSet.single(exp, defaults=base, inputs=inputs, sensors=["length"])
    out = {"data": exp.source, "t_end_s": args.t_end, "device": str(jax.devices()[0])}

    start = time.perf_counter()
    res = cal.fit(one, ["Y"], config=cfg)
    first = time.perf_counter() - start
    start = time.perf_counter()
    res = cal.fit(one, ["Y"], config=cfg)
    out["fit"] = {
        "wall_s_first_call_with_compile": first,
        "wall_s_compiled": time.perf_counter() - start,
        **res.summary(),
    }
    out["laplace"] = gpost.laplace(res)

    keep = exp.time <= args.t_end
    t, y = jnp.asarray(exp.time[keep]), jnp.asarray(exp["robot_length_m"][keep])

    def loss(theta):
        traj = gj.simulate(gj.replace(base, Y=theta[0], ext=theta[1], n=theta[2]), inputs, cfg)
        return jnp.sum((jnp.interp(t, traj.time, traj.length) - y) ** 2)

    theta = jnp.array([7900.0, 7000.0, 1.0])
    grad = jax.jit(jax.jacfwd(loss))
    jax.block_until_ready(grad(theta))
    start = time.perf_counter()
    for _ in range(3):
        jax.block_until_ready(grad(theta))
    out["gradient_s_forward_mode"] = (time.perf_counter() - start) / 3

    post = gpost.sample(
        one,
        config=cfg,
        chains=args.chains,
        warmup=args.warmup,
        samples=args.samples,
        progress=True,
    )
    s = post.summary
    steps = np.asarray(post.idata.sample_stats["n_steps"]) if "n_steps" in post.idata.sample_stats else None
    lap = out["laplace"]["robot.yield_pressure"]
    out["nuts"] = {
        **s,
        "ess_bulk_per_s": s["ess_bulk_min"] / post.wall_s,
        "mean_leapfrog_steps": None if steps is None else float(steps.mean()),
        "laplace_mean_difference_in_sd": (lap["mean"] - s["parameters"]["Y"]["mean"]) / s["parameters"]["Y"]["sd"],
        "laplace_sd_ratio": lap["sd"] / s["parameters"]["Y"]["sd"],
    }
    if args.direct_iterations > 0:
        k = args.direct_iterations
        direct = gpost.sample(
            one,
            config=cfg,
            chains=args.chains,
            warmup=k,
            samples=k,
            progress=True,
            emulate=False,
        )
        out["nuts_direct"] = {
            "wall_s": direct.wall_s,
            "chains": args.chains,
            "warmup": k,
            "samples": k,
            "extrapolated_wall_s": direct.wall_s * (args.warmup + args.samples) / (2 * k),
            "Y_mean": direct.summary["parameters"]["Y"]["mean"],
        }
        out["speedup_emulated_over_direct"] = out["nuts_direct"]["extrapolated_wall_s"] / post.wall_s
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2, default=str) + "\n")
    print(json.dumps(out, indent=2, default=str))


if __name__ == "__main__":
    main()
