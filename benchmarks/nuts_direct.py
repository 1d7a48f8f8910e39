"""NUTS directly through the model (no emulator) on the public experiment, Lockhart growth law (issue 9).

Run: ``python benchmarks/nuts_direct.py [--chains 4 --warmup 500 --samples 500] [--target-accept 0.98]
[--max-tree-depth 10] [--vectorised-gradient] [--gradients-only] [--small-loops]
[--out benchmarks/results/nuts_direct.json]`` (``--small-loops``: the opt-in option of :mod:`growjax.xla_flags`).

Reads ``../shared/data/mammobot/experiment.csv`` (the shipped synthetic forward experiment when it is
absent). Chains run one after another: the forward-mode solve vmapped over chains costs about as much
as the chains' gradients in sequence (``--vectorised-gradient`` times it), and vectorised chains wait
for the deepest tree. The JSON holds the wall time (compile included), the time of one
gradient (measured apart, after compilation), the mean tree size while sampling, R-hat, bulk ESS,
divergences and the posterior summary, against the targets (10 minutes, R-hat ≤ 1.01, no divergences).
A full run's sampling time is chains × (warm-up + draws) × mean tree size × gradient time, so a short
run (``--chains 1 --warmup 20 --samples 10``) profiles it.
"""

from __future__ import annotations

import argparse
import functools
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from numpyro.infer.util import initialize_model

import growjax as gj
from growjax import experiment as ex
from growjax import posterior as gpost
from growjax import xla_flags

REPO = Path(__file__).resolve().parents[1]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--chains", type=int, default=4)
    parser.add_argument("--warmup", type=int, default=500)
    parser.add_argument("--samples", type=int, default=500)
    parser.add_argument("--target-accept", type=float, default=0.98)
    parser.add_argument("--t-end", type=float, default=10.0)
    parser.add_argument("--max-tree-depth", type=int, default=10)
    parser.add_argument("--vectorised-gradient", action="store_true",
                        help="also time the gradient vmapped over the chains (members stepped together in one solve)")
    parser.add_argument("--gradients-only", action="store_true", help="time the gradients and stop (no sampling)")
    parser.add_argument("--small-loops", action="store_true",
                        help="the opt-in XLA:CPU option that compiles the solver's loop whole (growjax.xla_flags)")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "nuts_direct.json"))
    args = parser.parse_args()
    if args.small_loops and not xla_flags.apply():
        raise SystemExit("--small-loops: JAX started before the option could be set")
    folder = ex.shared_experiment_dir()
    exp = ex.read(folder / "experiment.csv") if folder else ex.read(REPO / "data" / "synthetic_forward.csv")
    base = gj.reference(growth_law="lockhart")
    cfg = gj.Config(t1=args.t_end)
    inputs = ex.to_inputs(exp, "forward", base, cfg.t0, cfg.t1)
    gradient_s = gradient_time(exp, inputs, base, cfg, 1)
    print(f"one gradient of the log density (one chain): {1e3 * gradient_s:.0f} ms", flush=True)
    gradient_vec_s = None
    if args.vectorised_gradient:
        gradient_vec_s = gradient_time(exp, inputs, base, cfg, args.chains)
        print(f"one vmapped gradient ({args.chains} chains): {1e3 * gradient_vec_s:.0f} ms", flush=True)
    if args.gradients_only:
        return
    res = gpost.sample(exp.time, exp["robot_length_m"], inputs, base, cfg, priors=gpost.lockhart_priors(),
                       chains=args.chains, warmup=args.warmup, samples=args.samples, progress=True,
                       target_accept=args.target_accept, emulate=False, max_tree_depth=args.max_tree_depth,
                       chain_method="sequential")
    stats = res.idata.sample_stats
    steps = float(np.asarray(stats["n_steps"]).mean()) if "n_steps" in stats else None
    s = res.summary
    out = {"data": exp.source, "device": str(jax.devices()[0]), "law": "lockhart", "t_end_s": args.t_end,
           "chains": args.chains, "warmup": args.warmup, "samples": args.samples,
           "target_accept": args.target_accept, "max_tree_depth": args.max_tree_depth, "wall_s": res.wall_s,
           "chain_method": "sequential", "small_loops": xla_flags.applied(), "gradient_s_one_chain": gradient_s,
           "gradient_s_vmapped_chains": gradient_vec_s,
           "tree_size_sampling_mean": steps,
           "projected_sampling_s_4x(500+500)": None if steps is None else 4 * 1000 * steps * gradient_s,
           "rhat_max": s["rhat_max"], "ess_bulk_min": s["ess_bulk_min"], "divergences": s["divergences"],
           "parameters": s["parameters"], "coverage_90": s["coverage_90"],
           "targets": {"wall_s": 600.0, "rhat_max": 1.01, "divergences": 0}}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2, default=str) + "\n")
    print(json.dumps(out, indent=2, default=str))


def gradient_time(exp, inputs, base, cfg, chains: int) -> float:
    """Seconds per forward-mode gradient of the log density: at one point, or at ``chains`` points at once
    (vmapped, as vectorised chains run it), after compilation."""
    keep = (exp.time >= cfg.t0) & (exp.time <= cfg.t1)  # the window posterior.sample fits
    t, y = exp.time[keep], exp["robot_length_m"][keep]
    mean = gpost.direct_mean(base, inputs, cfg.replace(adjoint="forward"), t)
    model = functools.partial(gpost.growth_model, mean_length=mean, priors=gpost.lockhart_priors())
    key = jax.random.PRNGKey(0) if chains == 1 else jax.random.split(jax.random.PRNGKey(0), chains)
    info = initialize_model(key, model, model_args=(jnp.asarray(y),), forward_mode_differentiation=True)
    grad = jax.jacfwd(info.potential_fn)
    grad = jax.jit(grad if chains == 1 else jax.vmap(grad))
    z = info.param_info.z
    jax.block_until_ready(grad(z))
    start = time.perf_counter()
    for _ in range(3):
        jax.block_until_ready(grad(z))
    return (time.perf_counter() - start) / 3


if __name__ == "__main__":
    main()
