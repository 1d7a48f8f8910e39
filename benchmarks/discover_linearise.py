"""One linearisation of discover's superset model (residuals, Jacobian and pressure in one forward-mode solve).

Run: ``python benchmarks/discover_linearise.py [--candidates all|no-velocity] [--batch 6] [--per-effect]``.

On ``growjax/data/datasets/discovery/active_channel_force.csv`` (10 s) with the 8-effect superset (or the 5 effects whose rod
force does not depend on the velocity), for a model with Y and the pull fitted: tracing and lowering, then
XLA's compile, timed apart; the first call and the median of 5 later calls. ``--batch B`` also times B such
models linearised under one ``vmap`` (members stepped together) against the same B one after another: why
``discover`` spreads its fits over threads (one per core) instead of batching them on a CPU. ``--per-effect``
times a linearisation with each candidate on, at discover's three starts (what a fit's step costs), and one
simulation with it on (its time and the solver's accepted steps: where the cost comes from).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax import discover as gd
from growjax.data import experiment as ex

REPO = Path(__file__).resolve().parents[1]
NO_VELOCITY = ("active_channel_force", "fluid_leak", "actuation_lag", "trapped_air", "retraction_folding")


def timed(fn, repeat: int = 5):
    """(first call s, median of ``repeat`` later calls s)."""
    start = time.perf_counter()
    jax.block_until_ready(fn())
    first = time.perf_counter() - start
    walls = []
    for _ in range(repeat):
        start = time.perf_counter()
        jax.block_until_ready(fn())
        walls.append(time.perf_counter() - start)
    return first, statistics.median(walls)


def main():
    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--candidates", choices=("all", "no-velocity"), default="all")
    ap.add_argument("--batch", type=int, default=0)
    ap.add_argument(
        "--per-effect",
        action="store_true",
        help="also time one linearisation with each candidate on, at each of discover's starts",
    )
    args = ap.parse_args()
    exp = ex.read(REPO / "src" / "growjax" / "data" / "datasets" / "discovery" / "active_channel_force.csv")
    cfg = gj.Config(t1=10.0)
    inputs = ex.to_inputs(exp, "forward", gj.reference(), cfg.t0, cfg.t1)
    keep = exp.time >= cfg.t0
    names = tuple(gd.fx.CATALOGUE) if args.candidates == "all" else NO_VELOCITY
    problem = gd.make_candidates(
        exp.time[keep], exp["robot_length_m"][keep], inputs, names, gj.reference(), ("Y",), cfg
    )
    k, p, q = len(names), 1, 3
    mask = np.zeros(k)
    mask[names.index("active_channel_force")] = 1.0
    select = np.zeros((p + k, q))
    select[0, 0] = select[p + names.index("active_channel_force"), 1] = 1.0
    model = (jnp.asarray(mask), jnp.asarray(select), jnp.zeros(p + k))
    w = jnp.asarray([0.0, 0.3, 0.0])
    start = time.perf_counter()
    lowered = gd.linearised.lower(w, problem, *model)
    lower_s = time.perf_counter() - start
    start = time.perf_counter()
    lowered.compile()
    compile_s = time.perf_counter() - start
    print(
        f"{len(names)} candidates: tracing and lowering {lower_s:.1f} s ({lowered.as_text().count(chr(10))} lines of "
        f"StableHLO), XLA compile {compile_s:.1f} s"
    )
    first, wall = timed(lambda: gd.linearised(w, problem, *model))
    print(f"{len(names)} candidates: first call after that {first:.1f} s, then {1e3 * wall:.0f} ms per linearisation")
    if args.per_effect:
        primal = eqx.filter_jit(
            lambda z, mk: gj.simulate(
                problem.parameters(z, mk), problem.inputs, problem.config, ts=problem.times, breaks=problem.breaks
            )
        )

        def simulation(j):
            """(ms, accepted steps) of one simulation of the superset with effect j on (None: none) at the 6 % start."""
            z, mk = np.zeros(p + k), np.zeros(k)
            if j is not None:
                mk[j] = 1.0
                z[p + j] = 0.0 if bool(problem.signed[j]) else float(np.log(np.expm1(10.0 * gd.START_FRACTIONS[1])))
            z, mk, last = jnp.asarray(z), jnp.asarray(mk), {}

            def run():
                last["trajectory"] = primal(z, mk)
                return last["trajectory"].length

            _, wall = timed(run, repeat=3)
            return 1e3 * wall, int(last["trajectory"].n_steps)

        ms, steps = simulation(None)
        print(f"  {'(no effect on)':22s} one simulation {ms:4.0f} ms, {steps} steps")
        for j, name in enumerate(names):
            m, sel = np.zeros(k), np.zeros((p + k, q))
            m[j] = sel[0, 0] = sel[p + j, 1] = 1.0
            row = []
            for frac in gd.START_FRACTIONS:  # the effect at 2, 6 and 20 % of its range's top (u of discover's starts)
                u = 0.0 if bool(problem.signed[j]) else float(np.log(np.expm1(10.0 * frac)))
                wj = jnp.asarray([0.0, u, 0.0])
                model_j = (jnp.asarray(m), jnp.asarray(sel), jnp.zeros(p + k))
                _, wall = timed(lambda wj=wj, model_j=model_j: gd.linearised(wj, problem, *model_j), repeat=3)
                row.append(f"{1e3 * wall:5.0f}")
            ms, steps = simulation(j)
            print(
                f"  {name:22s} ms per linearisation at the starts {' '.join(row)}; one simulation {ms:4.0f} ms, "
                f"{steps} steps"
            )
    if args.batch:
        ws = jnp.stack([w.at[1].set(-1.0 + 0.3 * b) for b in range(args.batch)])
        batched = eqx.filter_jit(
            jax.vmap(lambda x, m, s, z: gd.linearised(x, problem, m, s, z), in_axes=(0, None, None, None))
        )
        _, loop = timed(lambda: [gd.linearised(x, problem, *model) for x in ws])
        _, vmapped = timed(lambda: batched(ws, *model))
        print(f"{args.batch} linearisations: {loop:.2f} s one after another, {vmapped:.2f} s under one vmap")


if __name__ == "__main__":
    main()
