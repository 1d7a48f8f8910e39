"""One control design end to end: design on the fast model, evaluate on a chosen configuration, summarise."""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import growjax as gj
from growjax.calibration import tolerance as tl
from growjax.control.controllers import MPC, ClosedLoopResult, LengthPID, run_closed_loop, score
from growjax.control.plant import Plant, with_microstepping
from growjax.control.profile import (
    ProfileResult,
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
from growjax.model.limits import Limits, limits

__all__ = ["design_controller"]


def design_controller(
    target: Target,
    drive: str,
    method: str,
    t1: float,
    *,
    robust: str | None = None,
    n_draws: int = 8,
    iterations: int = 10,
    microsteps: int = 1,
    evaluate_on: str = "reference",
    seed: int = 0,
    figure: str | Path | None = None,
    knot_dt: float = 0.2,
    base: gj.Parameters | None = None,
    tolerances: dict[str, float] | None = None,
) -> dict:
    """One control design (drive × method) for ``target`` over [0, t1], designed on the fast model and evaluated on
    ``evaluate_on``.

    Only the forward drive's feedback design is tuned on draws (of a posterior, of the rig or both).

    Args:
        target: the desired length.
        drive: ``"forward"`` (pressure demand) or ``"inverse"`` (the stepper).
        method: ``"open-loop"``, ``"feedback"`` or (forward drive) ``"mpc"``.
        t1: the end of the run, s.
        robust: an ArviZ posterior file; the feedback gains are then tuned on the cost averaged over ``n_draws``
            of its draws (`parameter_draws`).
        n_draws: draws of the posterior and of the rig.
        iterations: iterations of the profile's least squares and of the gains' descent.
        microsteps: the stepper's microsteps per full step (1: full steps).
        evaluate_on: the fidelity the design is evaluated on, ``"reference"`` or ``"fast"``.
        seed: the draws' seed.
        figure: where to write the closed loop's figure; None: no figure.
        knot_dt: the spacing of the forward drive's demand knots, s.
        base: the plant's parameters (default `growjax.reference` of ``drive``), started at the target's first
            length (`plant_params`); the design and its evaluation both use them.
        tolerances: {parameter: relative sd} of the rig (`growjax.calibration.tolerance`; None or {}: the rig
            as ``base`` gives it): the feedback gains are tuned on the cost averaged over ``n_draws`` draws of
            the rig, each toleranced parameter ψ·exp(u z), z ~ N(0, 1) (`growjax.calibration.tolerance.rig_draws`),
            jointly with the posterior's draws where ``robust`` is given.

    Returns:
        The JSON-ready summary: the design (profile, gains or schedule), its times (s), and its evaluation
        (tracking RMSE m, peak pressure Pa, whether the membrane limit was crossed, the run's status).

    Raises:
        ValueError: for tolerances with any design but the forward drive's feedback, or the MPC on the stepper.
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
    design = _Design(params, target, t1, lim, evaluate_cfg, summary, time.perf_counter())
    options = dict(microsteps=microsteps, knot_dt=knot_dt, iterations=iterations, robust=robust, n_draws=n_draws)
    res = _designed(design, drive, method, seed=seed, tol=tol, **options)
    summary |= _evaluation(res, time.perf_counter() - design.start - summary["design_s"])
    if figure is not None:
        from growjax.plotting import control_figure

        title = f"{drive} drive, {method}: RMSE {1e3 * res.rmse_m:.2f} mm ({evaluate_on})"
        summary["figure"] = str(control_figure(res, target, figure, lim, title, drive))
    return summary


def _evaluation(res: ClosedLoopResult, seconds: float) -> dict:
    """The summary's evaluation of a run: its time (s), tracking RMSE (m), peak pressure (Pa) and status."""
    return {
        "evaluation_s": seconds,
        "tracking_rmse_m": res.rmse_m,
        "pressure_limit_crossed": res.pressure_limit_crossed,
        "peak_pressure_Pa": float(np.nanmax(res.pressure)),
        "status": gj.status_name(res.status) if res.status != 1 else "pressure_limit",
    }


def _designed(
    design: _Design,
    drive: str,
    method: str,
    *,
    microsteps: int,
    knot_dt: float,
    iterations: int,
    robust: str | None,
    n_draws: int,
    seed: int,
    tol: dict,
) -> ClosedLoopResult:
    """The design of ``method`` for ``drive`` (options as `design_controller` takes them), run on the
    evaluation's configuration; the forward drive's profile enters the summary."""
    if drive == "inverse":
        if method == "mpc":
            raise ValueError("the MPC is designed for the forward drive; use --method feedback for the stepper")
        if method == "open-loop":
            return _stepper_open_loop(design, microsteps)
        return _stepper_feedback(design, microsteps)
    prof = optimize_profile(
        design.params, design.target, design.t1, knot_dt=knot_dt, iterations=iterations, lim=design.lim
    )
    design.summary["profile_optimisation_s"] = prof.wall_s
    design.summary["profile"] = {"knots_s": prof.knots.tolist(), "demand_Pa": prof.demand.tolist()}
    if method == "open-loop":
        return _forward_open_loop(design, prof)
    if method == "feedback":
        return _forward_feedback(design, prof, robust, n_draws, seed, tol, iterations)
    return _forward_mpc(design)


@dataclasses.dataclass
class _Design:
    """What every design shares: the plant's parameters, the target, the run's end (s), the limits, the
    evaluation's configuration, the summary the design adds to, and the clock's start (s)."""

    params: gj.Parameters
    target: Target
    t1: float
    lim: Limits
    evaluate_cfg: gj.Config
    summary: dict
    start: float

    def designed(self) -> None:
        """Note the design's time in the summary."""
        self.summary["design_s"] = time.perf_counter() - self.start


def _stepper_open_loop(d: _Design, microsteps: int) -> ClosedLoopResult:
    """The stepper's schedule planned on the fast model (the one tracking best there), run blind."""
    ctrl, plan_rmse, ticks, counts = plan_steps(d.params, d.target, d.t1, microsteps=microsteps)
    on_model, planned_by = {"step controller on the model": plan_rmse}, "step controller on the model"
    if microsteps == 1:  # the lead search reads a full-step schedule off the target
        lead, lead_rmse, lead_ticks, lead_counts = optimize_steps(d.params, d.target, d.t1)
        on_model["lead search"] = lead_rmse
        d.summary["lead_search_lead_s"] = lead
        if lead_rmse < plan_rmse:
            planned_by, ticks, counts = "lead search", lead_ticks, lead_counts
    d.designed()
    ts = d.target.time[(d.target.time >= d.evaluate_cfg.t0) & (d.target.time <= d.t1)]
    driven = with_microstepping(d.params) if microsteps > 1 else d.params
    tr = simulate_steps(driven, d.target, ticks, counts, d.evaluate_cfg, ts)
    res = score(ts, np.asarray(tr.length), np.asarray(tr.pressure), counts, ticks, d.target, d.lim, int(tr.status))
    d.summary["profile"] = {
        "planned_by": planned_by,
        "model_rmse_m": on_model,
        "controller": {"rate_Hz": ctrl.rate, "lead_s": ctrl.lead, "microsteps": ctrl.microsteps},
        "tick_s": ticks.tolist(),
        "steps": counts.tolist(),
    }
    return res


def _stepper_feedback(d: _Design, microsteps: int) -> ClosedLoopResult:
    """The step controller tuned on the fast model, in closed loop on the evaluation's plant."""
    ctrl, _ = tune_stepper(d.params, d.target, d.t1, microsteps=microsteps)
    d.designed()
    res = run_closed_loop(Plant.make(d.params, d.evaluate_cfg, microstep=microsteps > 1), ctrl, d.target, d.t1, d.lim)
    gate = ctrl.pressure_gate if math.isfinite(ctrl.pressure_gate) else None  # JSON has no infinity
    d.summary["gains"] = {
        "rate_Hz": ctrl.rate,
        "lead_s": ctrl.lead,
        "deadband_steps": ctrl.deadband,
        "microsteps": ctrl.microsteps,
        "pressure_gate_Pa": gate,
    }
    return res


def _forward_open_loop(d: _Design, prof: ProfileResult) -> ClosedLoopResult:
    """The optimised demand profile, run blind."""
    d.designed()
    tr = simulate_profile(d.params, d.target, prof, d.evaluate_cfg)
    return score(
        np.asarray(tr.time),
        np.asarray(tr.length),
        np.asarray(tr.pressure),
        prof.demand,
        prof.knots,
        d.target,
        d.lim,
        int(tr.status),
    )


def _forward_feedback(
    d: _Design, prof: ProfileResult, robust: str | None, n_draws: int, seed: int, tol: dict, iterations: int
) -> ClosedLoopResult:
    """The length PID over the profile as feed-forward, its gains tuned on the fast model (over draws of the
    posterior and the rig where given), in closed loop on the evaluation's plant."""
    pid = LengthPID(jnp.asarray(DEFAULT_LOG_GAINS), jnp.asarray(prof.knots), jnp.asarray(prof.demand))
    draws = parameter_draws(n_draws, seed, robust, d.params) if robust else {}
    posterior_names = {gp.resolve_name(d.params, k) for k in draws}
    draws |= {k: v for k, v in tl.rig_draws(n_draws, d.params, tol, seed).items() if k not in posterior_names}
    cost = pid_cost_fn(d.params, d.target, d.t1, pid, draws or None, d.lim)
    tuned = tune_pid(cost, pid.log_gains, iterations=iterations)
    d.summary["tuning_s"] = tuned.wall_s
    d.summary["gains"] = tuned.gains
    d.summary["tuning_cost_history"] = tuned.cost_history
    d.summary["robust_draws"] = (
        None if not draws else {"source": robust, "n": n_draws, "seed": seed, "rig_tolerances": tol}
    )
    pid = eqx.tree_at(lambda c: c.log_gains, pid, jnp.asarray(tuned.log_gains))
    d.designed()
    return run_closed_loop(Plant.make(d.params, d.evaluate_cfg), pid, d.target, d.t1, d.lim)


def _forward_mpc(d: _Design) -> ClosedLoopResult:
    """The MPC on the fast model, in closed loop on the evaluation's plant, with its compute time per tick."""
    mpc = MPC()
    d.designed()
    res = run_closed_loop(Plant.make(d.params, d.evaluate_cfg), mpc, d.target, d.t1, d.lim)
    d.summary["mpc_step_s_median"] = float(np.median(res.step_s[1:]))
    d.summary["mpc_step_s_p95"] = float(np.percentile(res.step_s[1:], 95))
    d.summary["mpc"] = {"dt_s": mpc.dt, "horizon": mpc.horizon, "w_move": mpc.w_move}
    return res
