"""Forward-mode derivative of the closed-loop PID tracking cost against central differences.

Run: ``python benchmarks/control_gradient.py [--t-end 10] [--out benchmarks/results/control_gradient.json]``.

Why ``control.tune_pid`` takes its gradient by central differences over 0.02 decades: ``jax.jacfwd`` through
the closed loop (``control.pid_loop``, each tick integrated by the Rosenbrock loop) agrees with fine central
differences over 2 s, but at tuned high gains and over 5–10 s both diverge or turn erratic: the loop's
tangent grows along the run and the cost is rough on small scales. The script evaluates
∂J/∂log₁₀(Kp, Ki, Kd) of ``control.pid_cost_fn`` (fast configuration, public experiment or the shipped
synthetic data, the published pressure as the feed-forward) at the default gains and at a tuned set, by
``jax.jacfwd`` and by central differences with steps 0.02 and 1e-4 decades, with the time of one
forward-mode gradient.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from growjax import control as gc
from growjax.data import experiment as ex

REPO = Path(__file__).resolve().parents[1]
TUNED_GAINS = (6.47e8, 8.22e6, 2.24e4)  # Kp Pa/m, Ki Pa/(m·s), Kd Pa·s/m: tune_pid's result on the public data


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "control_gradient.json"))
    args = ap.parse_args(argv)
    folder = ex.shared_experiment_dir()
    data = (
        folder / "experiment.csv"
        if folder
        else REPO / "src" / "growjax" / "data" / "datasets" / "synthetic_forward.csv"
    )
    t_end = args.t_end
    target = gc.target_from_experiment(ex.read(data), t_end)
    params = gc.plant_params("forward", target)
    knots = jnp.linspace(0.0, t_end, 51)
    pid = gc.LengthPID(jnp.asarray(gc.DEFAULT_LOG_GAINS), knots, jnp.full(knots.shape, 150e3))
    cost = gc.pid_cost_fn(params, target, t_end, pid)
    forward = jax.jit(jax.jacfwd(cost))
    rows = []
    for label, x in (("default", jnp.asarray(gc.DEFAULT_LOG_GAINS)), ("tuned", jnp.log10(jnp.asarray(TUNED_GAINS)))):
        jax.block_until_ready(forward(x))
        start = time.perf_counter()
        g = np.asarray(forward(x))
        wall = time.perf_counter() - start
        row = {
            "point": label,
            "log10_gains": np.asarray(x).tolist(),
            "cost": float(cost(x)),
            "forward_mode": g.tolist(),
            "forward_mode_s": wall,
        }
        for h in (0.02, 1e-4):
            row[f"central_{h:g}"] = [
                (float(cost(x.at[i].add(h))) - float(cost(x.at[i].add(-h)))) / (2 * h) for i in range(x.size)
            ]
        rows.append(row)
        print(
            f"{label:8s} J = {row['cost']:.5f} mm²   forward mode {np.array2string(g, precision=5)} ({wall:.2f} s)\n"
            f"{'':8s} central 0.02 {np.array2string(np.asarray(row['central_0.02']), precision=5)}   "
            f"central 1e-4 {np.array2string(np.asarray(row['central_0.0001']), precision=5)}",
            flush=True,
        )
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"data": str(data), "t_end_s": t_end, "rows": rows}, indent=1) + "\n")
    return {"rows": rows}


if __name__ == "__main__":
    main()
