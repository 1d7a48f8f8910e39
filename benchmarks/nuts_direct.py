"""NUTS directly through the model (no emulator) on the public experiment, Lockhart growth law.

Run: ``python benchmarks/nuts_direct.py [--chains 4 --warmup 500 --samples 500] [--target-accept 0.98]
[--max-tree-depth 10] [--vectorised-gradient] [--gradients-only] [--small-loops] [--sequential]
[--geometry [TARGET_ACCEPT ...] [--logit]] [--out benchmarks/results/nuts_direct.json]`` (``--small-loops``: the
opt-in option of `growjax.simulation.xla_flags`).

Reads ``../shared/data/mammobot/experiment.csv`` (the shipped synthetic forward experiment when it is
absent). Chains run in parallel, one per CPU device (the script exposes ``--chains`` devices;
``--sequential``: one after another): the forward-mode solve vmapped over chains costs about as much
as the chains' gradients in sequence (``--vectorised-gradient`` times it), and vectorised chains wait
for the deepest tree. The JSON holds the wall time (compile and the Laplace start included), the time
of one gradient (measured apart, after compilation: NumPyro's ``jacfwd`` through the model, one tangent
per unconstrained site, against :func:`growjax.posterior.with_model_tangents`, one per parameter, which
``posterior.sample`` uses), the mean tree size while sampling, R-hat, bulk ESS, divergences and the
posterior summary, against the targets (10 minutes, R-hat ≤ 1.01, no divergences).
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
from growjax import posterior as gpost
from growjax.data import experiment as ex
from growjax.data import sets as xs
from growjax.simulation import xla_flags

REPO = Path(__file__).resolve().parents[1]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--chains", type=int, default=4)
    parser.add_argument("--warmup", type=int, default=500)
    parser.add_argument("--samples", type=int, default=500)
    parser.add_argument("--target-accept", type=float, default=0.98)
    parser.add_argument("--t-end", type=float, default=10.0)
    parser.add_argument("--max-tree-depth", type=int, default=10)
    parser.add_argument(
        "--vectorised-gradient",
        action="store_true",
        help="also time the gradient vmapped over the chains (members stepped together in one solve)",
    )
    parser.add_argument("--gradients-only", action="store_true", help="time the gradients and stop (no sampling)")
    parser.add_argument(
        "--small-loops",
        action="store_true",
        help="the opt-in XLA:CPU option that compiles the solver's loop whole (growjax.simulation.xla_flags)",
    )
    parser.add_argument(
        "--geometry",
        type=float,
        nargs="*",
        metavar="TARGET_ACCEPT",
        help="instead of sampling through the model: NUTS on the model linearised at the posterior mode "
        "(seconds), at these target acceptance rates (default 0.8 0.9 0.95 0.98)",
    )
    parser.add_argument(
        "--logit",
        action="store_true",
        help="with --geometry: every prior in NumPyro's logit coordinate (no softplus coordinate for "
        "priors pressed against a bound, posterior.bound_start)",
    )
    parser.add_argument("--sequential", action="store_true", help="chains one after another on one device")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "nuts_direct.json"))
    args = parser.parse_args()
    if args.small_loops and not xla_flags.apply():
        raise SystemExit("--small-loops: JAX started before the option could be set")
    if not args.sequential:
        jax.config.update("jax_num_cpu_devices", max(args.chains, 1))  # one chain per device, before JAX starts
    folder = ex.shared_experiment_dir()
    exp = (
        ex.read(folder / "experiment.csv")
        if folder
        else ex.read(REPO / "src" / "growjax" / "data" / "datasets" / "synthetic_forward.csv")
    )
    base = gj.reference(growth_law="lockhart")
    cfg = gj.Config(t1=args.t_end)
    inputs = ex.to_inputs(exp, "forward", base, cfg.t0, cfg.t1)
    if args.geometry is not None:
        out = geometry(
            exp,
            inputs,
            base,
            cfg,
            args.chains,
            args.warmup,
            args.samples,
            args.geometry or [0.8, 0.9, 0.95, 0.98],
            args.max_tree_depth,
            args.logit,
        )
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
        print(json.dumps(out, indent=2))
        return
    gradient_all_sites_s = gradient_time(exp, inputs, base, cfg, 1, model_tangents=False)
    gradient_s = gradient_time(exp, inputs, base, cfg, 1)
    print(
        f"one gradient of the log density (one chain): {1e3 * gradient_all_sites_s:.0f} ms with a tangent per "
        f"unconstrained site, {1e3 * gradient_s:.0f} ms with one per parameter (with_model_tangents)",
        flush=True,
    )
    gradient_vec_s = None
    if args.vectorised_gradient:
        gradient_vec_s = gradient_time(exp, inputs, base, cfg, args.chains)
        print(f"one vmapped gradient ({args.chains} chains): {1e3 * gradient_vec_s:.0f} ms", flush=True)
    if args.gradients_only:
        return
    res = gpost.sample(
        xs.ExperimentSet.single(exp, defaults=base, inputs=inputs, sensors=["length"]),
        config=cfg,
        priors=gpost.lockhart_priors(),
        chains=args.chains,
        warmup=args.warmup,
        samples=args.samples,
        progress=True,
        target_accept=args.target_accept,
        emulate=False,
        max_tree_depth=args.max_tree_depth,
        chain_method="sequential" if args.sequential else None,
    )
    stats = res.idata.sample_stats
    steps = float(np.asarray(stats["n_steps"]).mean()) if "n_steps" in stats else None
    s = res.summary
    out = {
        "data": exp.source,
        "device": str(jax.devices()[0]),
        "law": "lockhart",
        "t_end_s": args.t_end,
        "chains": args.chains,
        "warmup": args.warmup,
        "samples": args.samples,
        "target_accept": args.target_accept,
        "max_tree_depth": args.max_tree_depth,
        "wall_s": res.wall_s,
        "chain_method": res.summary["chain_method"],
        "devices": jax.local_device_count(),
        "small_loops": xla_flags.applied(),
        "gradient_s_one_chain": gradient_s,
        "gradient_s_one_chain_tangent_per_site": gradient_all_sites_s,
        "laplace_s": res.summary["laplace_s"],
        "gradient_s_vmapped_chains": gradient_vec_s,
        "tree_size_sampling_mean": steps,
        "projected_sampling_s_4x(500+500)": None if steps is None else 4 * 1000 * steps * gradient_s,
        "rhat_max": s["rhat_max"],
        "ess_bulk_min": s["ess_bulk_min"],
        "divergences": s["divergences"],
        "parameters": s["parameters"],
        "coverage_90": s["coverage_90"],
        "targets": {"wall_s": 600.0, "rhat_max": 1.01, "divergences": 0},
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2, default=str) + "\n")
    print(json.dumps(out, indent=2, default=str))


def gradient_time(exp, inputs, base, cfg, chains: int, model_tangents: bool = True) -> float:
    """Seconds per forward-mode gradient of the log density: at one point, or at ``chains`` points at once
    (vmapped, as vectorised chains run it), after compilation; ``model_tangents``: through
    :func:`growjax.posterior.with_model_tangents` (as ``posterior.sample`` runs it)."""
    keep = (exp.time >= cfg.t0) & (exp.time <= cfg.t1)  # the window posterior.sample fits
    t, y = exp.time[keep], exp["robot_length_m"][keep]
    mean = gpost.direct_mean(base, inputs, cfg.replace(adjoint="forward"), t)
    if model_tangents:
        mean = gpost.with_model_tangents(mean, [p.name for p in gpost.lockhart_priors()])
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


def geometry(exp, inputs, base, cfg, chains, warmup, samples, target_accepts, max_tree_depth, logit=False) -> dict:
    """Tree sizes, divergences and R-hat of NUTS (as ``posterior.sample`` sets it up) on the model linearised in
    θ at the posterior mode, μ ≈ μ₀ + J(θ − θ₀), priors, transforms and σ exact: what the posterior's shape in
    NUTS's coordinates alone asks for, in seconds instead of hours. Leapfrog steps per chain × the gradient's
    time bounds a run through the model (its curvature away from the mode is not in this surrogate).

    The coordinates are ``posterior.sample``'s (:func:`growjax.posterior.bound_start`: a prior pressed against a
    bound in a softplus coordinate, start and mass matrix found again there); ``logit``: every prior in NumPyro's
    own coordinate, as before that."""
    import arviz_base as azb
    import arviz_stats as azs
    import numpyro
    from numpyro.infer import MCMC, NUTS

    keep = (exp.time >= cfg.t0) & (exp.time <= cfg.t1)
    y = jnp.asarray(exp["robot_length_m"][keep])
    priors = gpost.lockhart_priors()
    names = [p.name for p in priors]
    mean = gpost.direct_mean(base, inputs, cfg.replace(adjoint="forward"), exp.time[keep])

    def make_model(m, priors=priors):
        return functools.partial(gpost.growth_model, mean_length=m, priors=priors)

    start = time.perf_counter()
    init, inverse_mass = gpost.precondition(make_model(mean), priors, mean, y, make_model=make_model)
    laplace_s = time.perf_counter() - start
    v0 = jnp.asarray([init[p.site] for p in priors])
    mu0, jac = jax.jit(gpost.value_and_jacobian(mean, tuple(names)))(v0)  # the model's Jacobian at the start

    def linear(theta):
        return mu0 + jac @ (jnp.stack([theta[n] for n in names]) - v0)

    sampled, start, mass = priors, init, inverse_mass
    if not logit:
        sampled, start, mass = gpost.bound_start(make_model, priors, linear, y, init, inverse_mass)
    model = make_model(linear, sampled)
    rows = []
    for accept in target_accepts:
        kernel = NUTS(
            model,
            dense_mass=True,
            target_accept_prob=accept,
            max_tree_depth=max_tree_depth,
            inverse_mass_matrix=mass,
            init_strategy=numpyro.infer.init_to_value(values=start),
        )
        mcmc = MCMC(
            kernel,
            num_warmup=warmup,
            num_samples=samples,
            num_chains=chains,
            progress_bar=False,
            chain_method="vectorized",
        )
        mcmc.warmup(jax.random.PRNGKey(0), y, extra_fields=("diverging", "num_steps"), collect_warmup=True)
        warm = {k: np.asarray(v) for k, v in mcmc.get_extra_fields(group_by_chain=True).items()}
        mcmc.post_warmup_state = mcmc.last_state
        mcmc.run(mcmc.post_warmup_state.rng_key, y, extra_fields=("diverging", "num_steps"))
        draw = {k: np.asarray(v) for k, v in mcmc.get_extra_fields(group_by_chain=True).items()}
        sites = [p.site for p in priors] + ["sigma"]
        post = {k: np.asarray(v) for k, v in mcmc.get_samples(group_by_chain=True).items() if k in sites}
        rhat = azs.rhat(azb.convert_to_dataset(post))
        rows.append(
            {
                "target_accept": accept,
                "leapfrog_per_draw_warmup": float(warm["num_steps"].mean()),
                "leapfrog_per_draw_sampling": float(draw["num_steps"].mean()),
                "leapfrog_per_chain": float(warm["num_steps"].sum(1).mean() + draw["num_steps"].sum(1).mean()),
                "divergences_warmup": int(warm["diverging"].sum()),
                "divergences_sampling": int(draw["diverging"].sum()),
                "rhat_max": float(max(float(rhat[k]) for k in post)),
                "posterior_90": {k: np.quantile(v, [0.05, 0.95]).tolist() for k, v in post.items()},
            }
        )
        print(rows[-1], flush=True)
    coordinates = {p.site: gpost.coordinate(p) for p in sampled}
    return {
        "data": exp.source,
        "law": "lockhart",
        "surrogate": "model linearised in θ at the posterior mode",
        "mode": init,
        "laplace_s": laplace_s,
        "chains": chains,
        "warmup": warmup,
        "samples": samples,
        "max_tree_depth": max_tree_depth,
        "coordinates": coordinates,
        "rows": rows,
    }


if __name__ == "__main__":
    main()
