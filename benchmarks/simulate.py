"""Benchmark one 10 s simulation and one forward-mode gradient: compile time and wall time after compilation.

Run: ``python benchmarks/simulate.py [--out benchmarks/results/simulate.json] [--repeat 10] [--small-loops]
[--tangents]`` (``--small-loops``: the opt-in option of :mod:`growjax.simulation.xla_flags`; write ``--out`` elsewhere to
keep both).

Uses the shared experiment when it is beside the checkout, else the shipped synthetic data.
Wall times are the median of ``--repeat`` (≥ 10 by default) calls after the first; no persistent
compilation cache, so ``compile_s`` (first call less the median) is a cold compile. Measured:

* the 10 s forward simulation in the default (fast) configuration, target ≤ 20 ms;
* ``jax.jacfwd`` (``Config(adjoint="forward")``) of the Gaussian log-likelihood of the measured
  length (σ = 0.2 mm, samples in [t0, t1]) in (Y Pa, ext, n), target ≤ 60 ms;
* for information: the forward drive at rtol 1e-6 and the inverse (stepper) drive at the default
  tolerance, with their solver steps and ``realtime_factor`` = wall / simulated time.
* ``--tangents``: the same gradient, and the Lockhart law's in (Y, φ_L, n_L) at the public experiment's
  posterior mode (the direct NUTS benchmark's), with the sensitivities' field in forward mode and by central
  differences (``Config.tangents``), in this process one after the other: the ratio is the measurement.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _environment import environment  # benchmarks/ is on sys.path when run as a script

import growjax as gj
from growjax.data import experiment as ex
from growjax.simulation import xla_flags
from growjax.simulation.metrics import length_rmse

REPO = Path(__file__).resolve().parents[1]
SIGMA = 2e-4  # m, noise scale of the length likelihood
GRADIENT_PARAMETERS = ("Y", "ext", "n")
LOCKHART_PARAMETERS = ("robot.yield_pressure", "robot.lockhart_rate", "robot.lockhart_exponent")
LOCKHART_AT = (5054.0, 2.05e-3, 0.259)  # the public experiment's posterior mode (benchmarks/nuts_direct.py --geometry)
TARGETS = {"simulate_s": 0.020, "gradient_s": 0.060}


def timed(fn, repeat: int) -> tuple[float, list[float], object]:
    """(first-call s, later-call walls s, last result) of ``fn()``, each blocked until ready."""
    start = time.perf_counter()
    result = jax.block_until_ready(fn())
    first = time.perf_counter() - start
    walls = []
    for _ in range(repeat):
        start = time.perf_counter()
        result = jax.block_until_ready(fn())
        walls.append(time.perf_counter() - start)
    return first, walls, result


def bench_simulation(drive: str, exp, repeat: int, rtol: float | None = None) -> dict:
    """One 10 s simulation of ``drive`` at the published parameters (default grid)."""
    params = gj.reference(drive)
    config = gj.Config(drive=drive, rtol=rtol, atol=rtol)
    inputs = ex.to_inputs(exp, drive, params, config.t0, config.t1)
    first, walls, traj = timed(lambda: gj.simulate(params, inputs, config), repeat)
    wall = statistics.median(walls)
    out = {
        "drive": drive,
        "rtol": config.tolerances[0],
        "compile_s": first - wall,
        "wall_s": wall,
        "wall_min_s": min(walls),
        "repeats": repeat,
        "solver_steps": int(traj.n_steps),
        "status": gj.status_name(traj.status),
        "realtime_factor": wall / (config.t1 - config.t0),
    }
    if "robot_length_m" in exp:
        out["rmse_length_m"] = float(length_rmse(traj, exp.time, exp["robot_length_m"], config.t0, config.t1))
    return out


def log_likelihood_fn(exp, sigma: float = SIGMA, law: str = "reference", tangents: str = "auto"):
    """θ → Gaussian log-likelihood of the measured length (σ m) over the 10 s window: θ = (Y Pa, ext, n) under
    the published law, (Y Pa, φ_L m/s, n_L) under ``law="lockhart"`` (started at :data:`LOCKHART_AT`)."""
    base = gj.reference("forward", growth_law=law)
    names = GRADIENT_PARAMETERS if law == "reference" else LOCKHART_PARAMETERS
    if law != "reference":
        base = gj.replace(base, **dict(zip(names, LOCKHART_AT)))
    config = gj.Config(adjoint="forward", tangents=tangents)
    inputs = ex.to_inputs(exp, "forward", base, config.t0, config.t1)
    t = np.asarray(exp.time)
    keep = (t >= config.t0) & (t <= config.t1)
    times, observed = t[keep], jnp.asarray(np.asarray(exp["robot_length_m"])[keep])
    breaks = gj.input_breaks(inputs, config)
    constant = -times.size * np.log(sigma * np.sqrt(2.0 * np.pi))

    def log_likelihood(theta):
        params = gj.replace(base, **dict(zip(names, theta)))
        length = gj.simulate(params, inputs, config, ts=times, breaks=breaks).length
        return constant - 0.5 * jnp.sum(((length - observed) / sigma) ** 2)

    theta0 = jnp.asarray([float(gj.get(base, name)) for name in names])
    return log_likelihood, theta0


def bench_gradient(exp, repeat: int, law: str = "reference", tangents: str = "auto") -> dict:
    """Forward-mode gradient (``jax.jacfwd``) of the log-likelihood (see :func:`log_likelihood_fn`)."""
    log_likelihood, theta0 = log_likelihood_fn(exp, law=law, tangents=tangents)
    gradient = jax.jit(jax.jacfwd(log_likelihood))
    first, walls, grad = timed(lambda: gradient(theta0), repeat)
    wall = statistics.median(walls)
    return {
        "law": law,
        "tangents": tangents,
        "parameters": list(GRADIENT_PARAMETERS if law == "reference" else LOCKHART_PARAMETERS),
        "at": [float(v) for v in theta0],
        "sigma_m": SIGMA,
        "log_likelihood": float(jax.jit(log_likelihood)(theta0)),
        "gradient": [float(g) for g in grad],
        "compile_s": first - wall,
        "wall_s": wall,
        "wall_min_s": min(walls),
        "repeats": repeat,
    }


def verdict(value: float, target: float) -> str:
    return "PASS" if value <= target else "MISS"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "simulate.json"))
    parser.add_argument("--repeat", type=int, default=10)
    parser.add_argument(
        "--small-loops",
        action="store_true",
        help="the opt-in XLA:CPU option that compiles the solver's loop whole (growjax.simulation.xla_flags)",
    )
    parser.add_argument(
        "--tangents",
        action="store_true",
        help="also time both laws' gradients with forward-mode and difference tangents (Config.tangents)",
    )
    args = parser.parse_args()
    small_loops = xla_flags.apply() if args.small_loops else xla_flags.applied()
    folder = ex.shared_experiment_dir()
    exp = (
        ex.read(folder / "experiment.csv")
        if folder
        else ex.read(REPO / "src" / "growjax" / "data" / "datasets" / "synthetic_forward.csv")
    )
    fast = bench_simulation("forward", exp, args.repeat)
    gradient = bench_gradient(exp, args.repeat)
    results = {
        "data": exp.source,
        "device": str(jax.devices()[0]),
        "environment": environment(),
        "small_loops": small_loops,
        "simulation": fast,
        "gradient": gradient,
        "other_runs": [
            bench_simulation("forward", exp, args.repeat, 1e-6),
            bench_simulation("inverse", exp, args.repeat),
        ],
        "targets": TARGETS,
    }
    if args.tangents:
        results["tangents"] = [
            bench_gradient(exp, args.repeat, law, mode)
            for law in ("reference", "lockhart")
            for mode in ("forward", "differences")
        ]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=2) + "\n")
    print(f"data: {exp.source}")
    print(
        f"10 s simulation (fast, forward) after compile: {1e3 * fast['wall_s']:.1f} ms median of {args.repeat} "
        f"(target <= {1e3 * TARGETS['simulate_s']:.0f} ms) {verdict(fast['wall_s'], TARGETS['simulate_s'])}; "
        f"compile {fast['compile_s']:.1f} s, {fast['solver_steps']} steps"
    )
    print(
        f"jacfwd of the 10 s log-likelihood in (Y, ext, n): {1e3 * gradient['wall_s']:.1f} ms median of {args.repeat} "
        f"(target <= {1e3 * TARGETS['gradient_s']:.0f} ms) {verdict(gradient['wall_s'], TARGETS['gradient_s'])}; "
        f"compile {gradient['compile_s']:.1f} s"
    )
    for row in results.get("tangents", []):
        print(
            f"  gradient, {row['law']} law, {row['tangents']} tangents: {1e3 * row['wall_s']:.1f} ms "
            f"(compile {row['compile_s']:.1f} s)"
        )
    for run in results["other_runs"]:
        print(
            f"  {run['drive']} rtol {run['rtol']:g}: {1e3 * run['wall_s']:.1f} ms, {run['solver_steps']} steps, "
            f"{run['status']} (information)"
        )


if __name__ == "__main__":
    main()
