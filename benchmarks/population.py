"""Hierarchical populations: coverage of the population's median and spread, and of a new robot's predictive band.

Run: ``python benchmarks/population.py [--populations 20] [--robots 8] [--workers 1] [--resume]
[--out benchmarks/results/population.json]``; ``--resume`` keeps the populations already done with the same
settings (in ``--out`` and its partial file) and runs the rest.

Each population: ``--robots`` robots with Y_i ~ LogNormal(ln 8 kPa, 0.1) on one rig drawn from the default
tolerance budget, each run under its own seeded random pulse train (amplitude 80–180 kPa, period 1–2.5 s,
duty 40–90 %, delay 0.1–0.5 s, sampled every 10 ms), 10 s, made by the reference configuration with 0.2 mm
white length noise; a ninth robot of the same population on the same rig under a fresh pulse train is held
out. Fitted jointly by the fast configuration (``Y@robot``, rig inferred), then the population posterior
(NUTS, 4 × (500 + 500)). Targets: exp(μ) covers the true median 8 kPa and s the true 0.1 in 0.80–0.97 of the
populations; the new robot's 90 % predictive band holds 0.80–0.97 of its points.
Each population's record keeps the joint fit's linearised likelihood (``likelihood``: ln Ŷ of each robot, the rig's
errors, their covariance), the input the population's NUTS samples, so samplers can be compared on it; the whole
record goes to ``--out`` with the suffix ``.full.json``, ``--out`` itself keeps the rest (small enough to keep in the
repository).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

MEDIAN, SPREAD = 8e3, 0.1  # Pa, sd of ln Y
NOISE = 2e-4  # m
TIME = np.round(np.arange(1, 1001) * 0.01, 10)  # s
CATHETER = 0.004 + 0.004 * TIME  # m


def make_population(seed: int, robots: int, rtol: float):
    """(true Y (R + 1,), rig offsets, [Experiment] R + 1, statuses): the last robot is held out."""
    import jax
    import jax.numpy as jnp

    import growjax as gj
    from growjax.calibration import tolerance as tl
    from growjax.data.experiment import Experiment

    rng = np.random.default_rng(seed)
    base = gj.reference("forward")
    ys = MEDIAN * np.exp(SPREAD * rng.standard_normal(robots + 1))
    offsets = {n: float(rng.normal(0.0, u)) for n, u in tl.default_budget(base).items()}
    rig = gj.replace(base, **{n: gj.get(base, n) * np.exp(b) for n, b in offsets.items()})
    cols = []
    for _ in range(robots + 1):
        train = gj.PulseTrain(
            rng.uniform(80e3, 180e3), rng.uniform(1.0, 2.5), rng.uniform(0.4, 0.9), rng.uniform(0.1, 0.5)
        )
        cols.append(np.asarray(train(jnp.asarray(TIME))))
    config = gj.Config(fidelity="reference", t1=10.0, rtol=rtol, atol=rtol)
    ts = jnp.asarray(np.concatenate([[config.t0], TIME]))
    inputs = [
        gj.Inputs(
            catheter_length=gj.Sampled(jnp.asarray(TIME), jnp.asarray(CATHETER)),
            pressure_demand=gj.Sampled(jnp.asarray(TIME), jnp.asarray(c)),
        )
        for c in cols
    ]
    breaks = [gj.input_breaks(i, config) for i in inputs]
    sizes = [max(b[j].size for b in breaks) for j in range(2)]
    breaks = tuple(
        jnp.stack([jnp.concatenate([b[j], jnp.full(sizes[j] - b[j].size, config.t1 + 1.0)]) for b in breaks])
        for j in range(2)
    )
    stacked = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *inputs)

    def run(y, inp, jumps, kinks):
        traj = gj.simulate(gj.replace(rig, Y=y), inp, config, ts=ts, breaks=(jumps, kinks))
        return traj.length[1:], traj.status

    lengths, status = jax.jit(jax.vmap(run))(jnp.asarray(ys), stacked, *breaks)
    lengths = np.asarray(lengths) + rng.normal(0.0, NOISE, (robots + 1, TIME.size))
    exps = [
        Experiment(
            TIME,
            {"robot_length_m": lengths[i], "catheter_length_m": CATHETER, "pressure_demand_Pa": cols[i]},
            f"robot-{i}",
        )
        for i in range(robots + 1)
    ]
    return ys, offsets, exps, np.asarray(status)


def one_population(task: tuple) -> dict:
    seed, robots, rtol, chains, warmup, samples = task
    import growjax as gj
    from growjax import calibration as cal
    from growjax.data import sets as xs
    from growjax.posterior import population as pop

    clock = time.perf_counter()
    ys, offsets, exps, status = make_population(seed, robots, rtol)
    if np.any(status != gj.OK):
        return {"seed": seed, "skipped": f"a reference run failed ({status.tolist()})"}
    made = time.perf_counter() - clock
    runs = xs.ExperimentSet(tuple(xs.Run(e.source, e, robot=e.source) for e in exps[:-1]))
    t0 = time.perf_counter()
    fit = cal.fit(runs, ["Y@robot"], config=gj.Config(t1=10.0), starts=1, scout=16)
    fit_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    post = pop.sample_population(fit, "Y", chains=chains, warmup=warmup, samples=samples, seed=seed)
    nuts_s = time.perf_counter() - t0
    held = xs.Run("held-out", exps[-1], robot="held-out")
    band = pop.predict_new_robot(post, held, gj.Config(t1=10.0), draws=400, seed=seed)
    y9 = np.asarray(exps[-1]["robot_length_m"])[-band["times"].size :]
    med = post.interval(np.exp(post.mu))
    sd = post.interval(post.s)
    return {
        "seed": seed,
        "truth_Y_Pa": ys.tolist(),
        "rig_offsets": offsets,
        "median_Pa": {"median": med[1], "interval_90": [med[0], med[2]], "covered": bool(med[0] <= MEDIAN <= med[2])},
        "spread": {"median": sd[1], "interval_90": [sd[0], sd[2]], "covered": bool(sd[0] <= SPREAD <= sd[2])},
        "robots_covered": float(
            np.mean(
                [
                    np.quantile(np.exp(post.ln_theta[:, i]), 0.05)
                    <= ys[i]
                    <= np.quantile(np.exp(post.ln_theta[:, i]), 0.95)
                    for i in range(robots)
                ]
            )
        ),
        "new_robot_band_coverage": float(np.mean((y9 >= band["lower"]) & (y9 <= band["upper"]))),
        "new_robot_band_width_mm": float(1e3 * np.median(band["upper"] - band["lower"])),
        "diagnostics": post.diagnostics,
        "fit_status": fit.status,
        "likelihood": _likelihood(fit),
        "make_s": made,
        "fit_s": fit_s,
        "nuts_s": nuts_s,
    }


def _likelihood(fit) -> dict:
    """The joint fit's Gaussian that the population's NUTS samples: each robot's ln Ŷ (SI), the rig's errors and
    their covariance, so that samplers can be compared on the benchmark's populations without remaking them."""
    from growjax.posterior import population as pop

    robots, _, z_hat, b_hat, cov = pop.linearised_likelihood(fit, "robot.yield_pressure")
    return {
        "robots": list(robots),
        "ln_y_hat": z_hat.tolist(),
        "rig_vector": b_hat.tolist(),
        "covariance": cov.tolist(),
    }


def _kept(out: Path, partial: Path, args) -> list[dict]:
    """Populations of an earlier run with the same settings, from its results file and its partial file."""
    same = ("robots", "rtol", "chains", "warmup", "samples")
    rows = {}
    out = full_path(out) if full_path(out).exists() else out
    if out.exists():
        earlier = json.loads(out.read_text())
        if any(earlier["arguments"][k] != getattr(args, k) for k in same):
            raise SystemExit(f"{out}: made with other settings ({', '.join(same)} must match); not resumed")
        rows.update({r["seed"]: r for r in earlier["populations"]})
    if partial.exists():
        rows.update({r["seed"]: r for r in map(json.loads, filter(str.strip, partial.read_text().splitlines()))})
    return list(rows.values())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--populations", type=int, default=20)
    ap.add_argument("--robots", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rtol", type=float, default=1e-6, help="the reference configuration's tolerance")
    ap.add_argument("--chains", type=int, default=4)
    ap.add_argument("--warmup", type=int, default=500)
    ap.add_argument("--samples", type=int, default=500)
    ap.add_argument("--workers", type=int, default=1, help="populations run at a time, one process each")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "population.json"))
    ap.add_argument(
        "--resume", action="store_true", help="keep the populations already in --out and its partial file; run the rest"
    )
    args = ap.parse_args()
    clock = time.perf_counter()
    partial = Path(args.out).with_suffix(".partial.jsonl")  # rows as they finish, kept if the run is cut short
    partial.parent.mkdir(parents=True, exist_ok=True)
    rows = _kept(Path(args.out), partial, args) if args.resume else []
    if not args.resume:
        partial.write_text("")
    done = {r["seed"] for r in rows}
    tasks = [
        (args.seed + k, args.robots, args.rtol, args.chains, args.warmup, args.samples)
        for k in range(args.populations)
        if args.seed + k not in done
    ]

    def keep(row):
        rows.append(row)
        with partial.open("a") as fh:
            fh.write(json.dumps(row) + "\n")

    if args.workers > 1:
        import multiprocessing as mp
        from concurrent.futures import as_completed

        with ProcessPoolExecutor(args.workers, mp_context=mp.get_context("spawn")) as pool:
            for fut in as_completed([pool.submit(one_population, t) for t in tasks]):
                keep(fut.result())
    else:
        for t in tasks:
            keep(one_population(t))
    rows.sort(key=lambda r: r["seed"])
    for r in rows:
        if "skipped" in r:
            print(f"population {r['seed']}: {r['skipped']}", flush=True)
            continue
        print(
            f"population {r['seed']:2d}: median {r['median_Pa']['interval_90']} "
            f"{'covers' if r['median_Pa']['covered'] else 'misses'}; s {np.round(r['spread']['interval_90'], 3)} "
            f"{'covers' if r['spread']['covered'] else 'misses'}; new-robot band {r['new_robot_band_coverage']:.2f}; "
            f"fit {r['fit_s']:.0f} s, NUTS {r['nuts_s']:.1f} s",
            flush=True,
        )
    done = [r for r in rows if "skipped" not in r]
    summary = {
        "populations": len(done),
        "robots": args.robots,
        "median_coverage_90": float(np.mean([r["median_Pa"]["covered"] for r in done])),
        "spread_coverage_90": float(np.mean([r["spread"]["covered"] for r in done])),
        "robot_coverage_90": float(np.mean([r["robots_covered"] for r in done])),
        "new_robot_band_coverage": float(np.mean([r["new_robot_band_coverage"] for r in done])),
        "median_fit_s": float(np.median([r["fit_s"] for r in done])),
        "median_nuts_s": float(np.median([r["nuts_s"] for r in done])),
        "max_divergences": int(max(r["diagnostics"]["divergences"] for r in done)),
        "wall_s": time.perf_counter() - clock,
    }
    print(json.dumps(summary, indent=1))
    from _environment import environment

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    record = {"environment": environment(), "arguments": vars(args), "summary": summary, "populations": rows}
    full_path(out).write_text(json.dumps(record, indent=1))
    compact = [{k: v for k, v in r.items() if k != "likelihood"} for r in rows]
    out.write_text(json.dumps({**record, "populations": compact}, indent=1))


def full_path(out: Path) -> Path:
    """Where the whole record goes, each population's linearised likelihood included (``--out`` holds the rest)."""
    return out.with_suffix(".full.json")


if __name__ == "__main__":
    main()
