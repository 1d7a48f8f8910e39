"""Control study on 0–10 s: length control that knows its own uncertainty.

Designs on the fast configuration, evaluates tracking on the reference configuration
(``gj.Config(fidelity="reference")``): the optimised open-loop demand profile, the tuned length PID
(forward drive), the MPC, the open-loop step schedule and the closed-loop step controller (stepper),
and the robust against point-estimate tuning of the PID over held-out parameter draws.
Target: the measured length of the public experiment (../shared/data/mammobot), else the shipped
synthetic data. Prints a table and writes benchmarks/results/control.json.

    python benchmarks/control.py [--t-end 10] [--robust-only | --stepper-only] [--train-draws 8] [--test-draws 32]

``--stepper-only`` runs the two stepper designs alone (→ benchmarks/results/control_stepper.json).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax import control as gc
from growjax.data import experiment as ex
from growjax.data.datasets import default_data_path

HERE = Path(__file__).resolve().parent
from _environment import environment  # the script's folder is on the path


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--iterations", type=int, default=12)
    ap.add_argument("--train-draws", type=int, default=8)
    ap.add_argument("--test-draws", type=int, default=32)
    ap.add_argument("--posterior", default=None, help="ArviZ posterior (.nc); default Gaussian Y ± 5 %% (seeded)")
    ap.add_argument("--skip-reference", action="store_true")
    ap.add_argument(
        "--robust-only",
        action="store_true",
        help="only the profile, the point and the robust PID tuning and their held-out evaluation",
    )
    ap.add_argument("--stepper-only", action="store_true", help="only the stepper designs (open-loop and closed-loop)")
    args = ap.parse_args()
    T = args.t_end
    folder = ex.shared_experiment_dir()
    data = folder / "experiment.csv" if folder else default_data_path()
    target = gc.target_from_experiment(ex.read(data), T)
    ev = "fast" if args.skip_reference else "reference"
    res: dict = {"data": str(data), "t_end_s": T, "evaluated_on": ev, "methods": {}}

    def record(name, r: gc.ClosedLoopResult, **extra):
        res["methods"][name] = {
            "tracking_rmse_m": r.rmse_m,
            "pressure_limit_crossed": r.pressure_limit_crossed,
            "peak_pressure_Pa": float(np.nanmax(r.pressure)),
            **extra,
        }
        print(
            f"{name:38s} RMSE {1e3 * r.rmse_m:6.3f} mm  peak {np.nanmax(r.pressure) / 1e3:6.1f} kPa  "
            f"limit crossed {r.pressure_limit_crossed}  {extra}",
            flush=True,
        )

    if args.stepper_only:
        stepper_methods(res, target, T, ev)
        write(res, "control_stepper.json")
        return

    # forward drive: open-loop profile
    p = gc.plant_params("forward", target)
    lim = gj.limits(p)
    t0 = time.perf_counter()
    prof = gc.optimize_profile(p, target, T, knot_dt=0.2, iterations=args.iterations, lim=lim)
    res["profile_optimisation_s"] = time.perf_counter() - t0
    print(
        f"profile optimised in {res['profile_optimisation_s']:.1f} s, fast RMSE {1e3 * prof.rmse_m:.3f} mm", flush=True
    )
    cfg_ev = gj.Config(fidelity=ev, t1=T)
    tr = gc.simulate_profile(p, target, prof, cfg_ev)
    r = gc.score(
        np.asarray(tr.time),
        np.asarray(tr.length),
        np.asarray(tr.pressure),
        prof.demand,
        prof.knots,
        target,
        lim,
        int(tr.status),
    )
    record("forward open-loop profile", r, knots=int(prof.knots.size))

    # forward drive: length PID, tuned (point estimate)
    pid0 = gc.LengthPID(jnp.asarray(gc.DEFAULT_LOG_GAINS), jnp.asarray(prof.knots), jnp.asarray(prof.demand))
    cost = gc.pid_cost_fn(p, target, T, pid0, None, lim)
    cost(pid0.log_gains)  # compile
    tuned = gc.tune_pid(cost, pid0.log_gains, iterations=args.iterations)
    res["pid_tuning_s"] = tuned.wall_s
    res["pid_gains_point"] = tuned.gains
    res["pid_cost_history_point"] = tuned.cost_history
    pid = eqx.tree_at(lambda c: c.log_gains, pid0, jnp.asarray(tuned.log_gains))
    r = gc.run_closed_loop(gc.Plant.make(p, cfg_ev), pid, target, T, lim)
    record("forward feedback (length PID)", r, tuning_s=round(tuned.wall_s, 1))
    if not args.robust_only:
        other_methods(res, record, target, T, ev, p, cfg_ev, lim)
    robust_study(args, res, target, T, p, lim, prof, pid0, tuned)
    write(res, "control_robust.json" if args.robust_only else "control.json")


def write(res, name):
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "results" / name).write_text(
        json.dumps({"environment": environment(), **res}, indent=2, default=float) + "\n"
    )
    print("wrote", HERE / "results" / name)


def other_methods(res, record, target, T, ev, p, cfg_ev, lim):
    """MPC (forward) and both stepper designs, evaluated on ``ev``."""
    # forward drive: MPC
    r = gc.run_closed_loop(gc.Plant.make(p, cfg_ev), gc.MPC(), target, T, lim)
    res["mpc_step_s_median"] = float(np.median(r.step_s[1:]))
    res["mpc_step_s_p95"] = float(np.percentile(r.step_s[1:], 95))
    record("forward MPC", r, step_ms_median=round(1e3 * res["mpc_step_s_median"], 1))
    stepper_methods(res, target, T, ev)


def stepper_methods(res, target, T, ev):
    """The open-loop step schedule, the closed-loop full-step controller and the 1/16-microstep controller,
    designed on the fast configuration and evaluated on ``ev``: `growjax.control.design_controller`, as the CLI runs
    them."""
    for name, method, microsteps in (
        ("inverse open-loop steps", "open-loop", 1),
        ("inverse feedback (step controller)", "feedback", 1),
        ("inverse feedback, 1/16 microstep", "feedback", 16),
    ):
        s = gc.design_controller(target, "inverse", method, T, microsteps=microsteps, evaluate_on=ev)
        setting = s.get("gains") or {k: s["profile"][k] for k in ("planned_by", "model_rmse_m", "controller")}
        res["methods"][name] = {
            k: s[k] for k in ("tracking_rmse_m", "pressure_limit_crossed", "peak_pressure_Pa", "design_s")
        } | setting
        print(
            f"{name:38s} RMSE {1e3 * s['tracking_rmse_m']:6.3f} mm  peak {s['peak_pressure_Pa'] / 1e3:6.1f} kPa  "
            f"limit crossed {s['pressure_limit_crossed']}  {setting}  design {s['design_s']:.0f} s",
            flush=True,
        )


def robust_study(args, res, target, T, p, lim, prof, pid0, tuned):
    """Robust (draw-averaged) against point-estimate PID tuning, both scored on held-out draws (fast configuration)."""
    train = gc.parameter_draws(args.train_draws, 0, args.posterior, p)
    test = gc.parameter_draws(args.test_draws, 1, args.posterior, p)
    robust_cost = gc.pid_cost_fn(p, target, T, pid0, train, lim)
    robust_cost(pid0.log_gains)
    rob = gc.tune_pid(robust_cost, pid0.log_gains, iterations=args.iterations)
    res["pid_gains_robust"] = rob.gains
    res["robust_tuning_s"] = rob.wall_s
    held = {}
    for name, lg in (("point", tuned.log_gains), ("robust", rob.log_gains)):
        e = []
        for i in range(args.test_draws):
            pd = gj.replace(p, **{k: float(v[i]) for k, v in test.items()})
            c = eqx.tree_at(lambda c: c.log_gains, pid0, jnp.asarray(lg))
            e.append(gc.run_closed_loop(gc.Plant.make(pd, gj.Config(t1=T)), c, target, T, lim).rmse_m)
        e = np.asarray(e)
        held[name] = {"median_m": float(np.median(e)), "p95_m": float(np.percentile(e, 95)), "max_m": float(e.max())}
        print(
            f"held-out {name:6s} tuning: median {1e3 * held[name]['median_m']:.3f} mm, "
            f"95th {1e3 * held[name]['p95_m']:.3f} mm",
            flush=True,
        )
    e = []
    for i in range(args.test_draws):
        pd = gj.replace(p, **{k: float(v[i]) for k, v in test.items()})
        tr = gc.simulate_profile(pd, target, prof, gj.Config(t1=T))
        e.append(gc.rmse(np.asarray(tr.time), np.asarray(tr.length), target))
    e = np.asarray(e)
    held["open_loop"] = {"median_m": float(np.median(e)), "p95_m": float(np.percentile(e, 95))}
    print(f"held-out open-loop profile: median {1e3 * np.median(e):.3f} mm, 95th {1e3 * np.percentile(e, 95):.3f} mm")
    res["held_out"] = held
    res["draws"] = {
        "source": args.posterior or "Gaussian, Y relative s.d. 5 % (seeded)",
        "train": args.train_draws,
        "test": args.test_draws,
        "train_seed": 0,
        "test_seed": 1,
    }


if __name__ == "__main__":
    main()
