"""One control design end to end: design on the fast model, evaluate on a chosen configuration, summarise."""

from __future__ import annotations

import math
import time

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax.calibration import tolerance as tl
from growjax.control.controllers import MPC, LengthPID, run_closed_loop, score
from growjax.control.plant import Plant, with_microstepping
from growjax.control.profile import (
    optimize_profile,
    optimize_steps,
    simulate_profile,
    simulate_steps,
)
from growjax.control.targets import Target, plant_params
from growjax.control.tuning import (
    DEFAULT_LOG_GAINS,
    parameter_draws,
    pid_cost_fn,
    plan_steps,
    tune_pid,
    tune_stepper,
)
from growjax.model import params as gp
from growjax.model.limits import limits

__all__ = ["design_controller"]


def design_controller(
    target: Target,
    drive: str,
    method: str,
    t1: float,
    robust: str | None = None,
    n_draws: int = 8,
    iterations: int = 10,
    microsteps: int = 1,
    evaluate_on: str = "reference",
    seed: int = 0,
    figure=None,
    knot_dt: float = 0.2,
    base: gj.Parameters | None = None,
    tolerances: dict | None = None,
) -> dict:
    """One design (drive × method) for ``target`` over [0, t1] s, evaluated on ``evaluate_on``. → JSON-ready dict.

    ``base``: the plant's parameters (default `growjax.reference` of ``drive``), started at the target's
    first length (`plant_params`); the design and its evaluation both use them.
    ``robust``: an ArviZ posterior file; the feedback gains are then tuned on the cost averaged over
    ``n_draws`` of its draws (`parameter_draws`). ``tolerances`` {parameter: relative sd}
    (`growjax.calibration.tolerance`; None or {}: the rig as ``base`` gives it): the feedback gains are tuned on
    the cost averaged over ``n_draws`` draws of the rig, each toleranced parameter ψ·exp(u z), z ~ N(0, 1)
    (`growjax.calibration.tolerance.rig_draws`), jointly with the posterior's draws where ``robust`` is given.
    Only the forward drive's feedback design is tuned on draws; ValueError for tolerances with any other design.
    """
    params = plant_params(drive, target, base=base)
    tol = tl.budget(params, tolerances or {}, use_default=False)
    if tol and (drive, method) != ("forward", "feedback"):
        raise ValueError(
            f"rig tolerances enter the forward drive's feedback design only (its gains are tuned on "
            f"draws of the rig); the {drive} drive's {method} design takes none"
        )
    lim = limits(params)
    evaluate_cfg = gj.Config(fidelity=evaluate_on, drive=drive, t1=t1)
    summary: dict = {
        "drive": drive,
        "method": method,
        "t_end_s": t1,
        "evaluated_on": evaluate_on,
        "pressure_limit_Pa": lim.membrane_limit,
        "max_demand_Pa": lim.pressure_ceiling,
    }
    start = time.perf_counter()
    if drive == "inverse":
        if method == "mpc":
            raise ValueError("the MPC is designed for the forward drive; use --method feedback for the stepper")
        if method == "open-loop":
            # schedules made on the fast model; the one tracking best there is run blind
            ctrl, plan_rmse, ticks, counts = plan_steps(params, target, t1, microsteps)
            on_model, planned_by = {"step controller on the model": plan_rmse}, "step controller on the model"
            if microsteps == 1:  # the lead search reads a full-step schedule off the target
                lead, lead_rmse, lead_ticks, lead_counts = optimize_steps(params, target, t1)
                on_model["lead search"] = lead_rmse
                summary["lead_search_lead_s"] = lead
                if lead_rmse < plan_rmse:
                    planned_by, ticks, counts = "lead search", lead_ticks, lead_counts
            summary["design_s"] = time.perf_counter() - start
            ts = target.time[(target.time >= evaluate_cfg.t0) & (target.time <= t1)]
            driven = with_microstepping(params) if microsteps > 1 else params
            tr = simulate_steps(driven, target, ticks, counts, evaluate_cfg, ts)
            res = score(ts, np.asarray(tr.length), np.asarray(tr.pressure), counts, ticks, target, lim, int(tr.status))
            summary["profile"] = {
                "planned_by": planned_by,
                "model_rmse_m": on_model,
                "controller": {"rate_Hz": ctrl.rate, "lead_s": ctrl.lead, "microsteps": ctrl.microsteps},
                "tick_s": ticks.tolist(),
                "steps": counts.tolist(),
            }
        else:
            ctrl, _ = tune_stepper(params, target, t1, microsteps)
            summary["design_s"] = time.perf_counter() - start
            res = run_closed_loop(Plant.make(params, evaluate_cfg, microstep=microsteps > 1), ctrl, target, t1, lim)
            gate = ctrl.pressure_gate if math.isfinite(ctrl.pressure_gate) else None  # JSON has no infinity
            summary["gains"] = {
                "rate_Hz": ctrl.rate,
                "lead_s": ctrl.lead,
                "deadband_steps": ctrl.deadband,
                "microsteps": ctrl.microsteps,
                "pressure_gate_Pa": gate,
            }
    else:
        prof = optimize_profile(params, target, t1, knot_dt=knot_dt, iterations=iterations, lim=lim)
        summary["profile_optimisation_s"] = prof.wall_s
        summary["profile"] = {"knots_s": prof.knots.tolist(), "demand_Pa": prof.demand.tolist()}
        if method == "open-loop":
            summary["design_s"] = time.perf_counter() - start
            tr = simulate_profile(params, target, prof, evaluate_cfg)
            res = score(
                np.asarray(tr.time),
                np.asarray(tr.length),
                np.asarray(tr.pressure),
                prof.demand,
                prof.knots,
                target,
                lim,
                int(tr.status),
            )
        elif method == "feedback":
            pid = LengthPID(jnp.asarray(DEFAULT_LOG_GAINS), jnp.asarray(prof.knots), jnp.asarray(prof.demand))
            draws = parameter_draws(n_draws, seed, robust, params) if robust else {}
            posterior_names = {gp.resolve_name(params, k) for k in draws}
            draws |= {k: v for k, v in tl.rig_draws(n_draws, params, tol, seed).items() if k not in posterior_names}
            cost = pid_cost_fn(params, target, t1, pid, draws or None, lim)
            tuned = tune_pid(cost, pid.log_gains, iterations)
            summary["tuning_s"] = tuned.wall_s
            summary["gains"] = tuned.gains
            summary["tuning_cost_history"] = tuned.cost_history
            summary["robust_draws"] = (
                None if not draws else {"source": robust, "n": n_draws, "seed": seed, "rig_tolerances": tol}
            )
            pid = eqx.tree_at(lambda c: c.log_gains, pid, jnp.asarray(tuned.log_gains))
            summary["design_s"] = time.perf_counter() - start
            res = run_closed_loop(Plant.make(params, evaluate_cfg), pid, target, t1, lim)
        else:
            mpc = MPC()
            summary["design_s"] = time.perf_counter() - start
            res = run_closed_loop(Plant.make(params, evaluate_cfg), mpc, target, t1, lim)
            summary["mpc_step_s_median"] = float(np.median(res.step_s[1:]))
            summary["mpc_step_s_p95"] = float(np.percentile(res.step_s[1:], 95))
            summary["mpc"] = {"dt_s": mpc.dt, "horizon": mpc.horizon, "w_move": mpc.w_move}
    summary["evaluation_s"] = time.perf_counter() - start - summary["design_s"]
    summary["tracking_rmse_m"] = res.rmse_m
    summary["pressure_limit_crossed"] = res.pressure_limit_crossed
    summary["peak_pressure_Pa"] = float(np.nanmax(res.pressure))
    summary["status"] = gj.status_name(res.status) if res.status != 1 else "pressure_limit"
    if figure is not None:
        from growjax.plotting import control_figure

        summary["figure"] = str(
            control_figure(
                res,
                target,
                figure,
                lim,
                f"{drive} drive, {method}: RMSE {1e3 * res.rmse_m:.2f} mm ({evaluate_on})",
                drive,
            )
        )
    return summary
