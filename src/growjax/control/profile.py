"""Open-loop design: the forward drive's pressure-demand profile by least squares through `growjax.simulation.simulate`,
and the stepper's step schedules (integer commands: searched, not differentiated). SI units."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

import growjax as gj
from growjax.calibration.least_squares import levenberg_marquardt, linearise
from growjax.control.plant import catheter_signal
from growjax.control.targets import Target, rmse, step_length
from growjax.model.limits import Limits, limits
from growjax.model.params import Parameters

__all__ = [
    "MAX_STEP",
    "ProfileResult",
    "optimize_profile",
    "optimize_steps",
    "profile_inputs",
    "simulate_profile",
    "simulate_steps",
    "step_commands",
]


class ProfileResult(NamedTuple):
    """An optimised demand profile.

    Attributes:
        knots: (K,) s.
        demand: (K,) Pa.
        cost_history: the sum of squared residuals at the first guess and after each accepted step.
        rmse_m: the tracking RMSE on the configuration optimised on, m.
        wall_s: the optimisation's wall time, s.
    """

    knots: Float[np.ndarray, " K"]  # s
    demand: Float[np.ndarray, " K"]  # Pa
    cost_history: list
    rmse_m: float  # on the configuration optimised on
    wall_s: float


# Pa: the most a knot moves in one step. Longer Gauss–Newton steps from the first guess (up to the whole
# demand range on a 10 s target) leave the range where the linearised length holds, and are rejected.
MAX_STEP = 60e3


def profile_inputs(target: Target, knots: Float[ArrayLike, " K"], values: Float[ArrayLike, " K"]) -> gj.Inputs:
    """The forward drive's inputs: the demand through ``values`` (Pa) at ``knots`` (s), the target's catheter."""
    return gj.Inputs(catheter_length=catheter_signal(target), pressure_demand=gj.KnotProfile(knots, values))


def optimize_profile(
    params: Parameters,
    target: Target,
    t1: float | None = None,
    knot_dt: float = 0.2,
    iterations: int = 15,
    lim: Limits | None = None,
    smooth: float = 1e-3,
    initial: float = 120e3,
    config: gj.Config | None = None,
    lead: float = 0.0,
) -> ProfileResult:
    """The forward drive's pressure-demand profile (piecewise linear, knots every ``knot_dt`` s) that makes the
    length follow ``target``, by `growjax.calibration.least_squares.levenberg_marquardt` on the tracking residuals.

    Residuals: length error on the target's grid (mm), ``smooth``·knot differences (per 10 kPa), and the sensed
    pressure's excess over ``lim.pressure_ceiling`` (per kPa); the knots are kept in [0, ``lim.pressure_ceiling``] (the
    engine's bounds). A trial point is scored by one solve and linearised once accepted: residuals and
    Jacobian in one forward-mode pass through `growjax.simulation.simulate` (all knots in one solve,
    `growjax.calibration.least_squares.linearise`); a step moves each knot by at most `MAX_STEP`.
    ``iterations``: at most that many accepted steps (fewer where the engine converges first).
    ``cost_history``: Σ r² at the first guess and after each accepted step.
    """
    t0w = time.perf_counter()
    lim = lim or limits(params)
    t1 = t1 if t1 is not None else float(target.time[-1])
    config = config or gj.Config(t1=t1, adjoint="forward")
    knots = np.arange(0.0, t1 + knot_dt - 1e-9, knot_dt)
    ts = target.time[(target.time >= config.t0) & (target.time <= t1)]
    ref = jnp.asarray(target.at(ts))
    breaks = gj.input_breaks(profile_inputs(target, knots, np.full(knots.size, initial)), config)
    scale = 1e5  # Pa per unit of the optimised variable

    def residuals(x):
        values = x * scale
        tr = gj.simulate(params, profile_inputs(target, knots, values), config, ts=ts, breaks=breaks)
        err = (tr.length - ref) / 1e-3
        over = jax.nn.relu(tr.pressure - lim.pressure_ceiling) / 1e3
        return jnp.concatenate([err, np.sqrt(smooth) * jnp.diff(x) * 10.0, over])

    scored, linearised = jax.jit(residuals), jax.jit(lambda x: linearise(residuals, x))
    history, last = [], []  # Σ r² at the first guess and each accepted point; Σ r² of the last point scored

    def score(x):
        r = scored(x)
        last[:] = [float(jnp.sum(r**2))]
        return r

    def linearise_accepted(x):  # the engine linearises the first guess and each point it accepts
        r, jac = linearised(x)
        if not history or bool(jnp.all(jnp.isfinite(jac))):
            history.append(last.pop() if last else float(jnp.sum(r**2)))
        return r, jac

    hi = lim.pressure_ceiling / scale
    x = np.full(knots.size, initial / scale)
    if lead == 0.0:  # a first guess from the target's speed: demand rises with the growth speed needed
        speed = np.gradient(target.at(knots + knot_dt), knots)
        x = np.clip(0.6 + 12.0 * np.maximum(speed, 0.0) / 1e-2 * 0.1, 0.0, hi)
    bounds = (np.zeros(knots.size), np.full(knots.size, hi))
    x, _, _, r, _ = levenberg_marquardt(
        linearise_accepted, x, max_steps=iterations, bounds=bounds, max_move=MAX_STEP / scale, residuals=score
    )
    n = ts.size
    return ProfileResult(
        knots, x * scale, history, float(np.sqrt(np.mean((r[:n] * 1e-3) ** 2))), time.perf_counter() - t0w
    )


def simulate_profile(params: Parameters, target: Target, profile: ProfileResult, config: gj.Config) -> gj.Trajectory:
    """The trajectory of the forward drive under an optimised profile (any configuration), on the target's grid."""
    ts = target.time[(target.time >= config.t0) & (target.time <= config.t1)]
    return gj.simulate(params, profile_inputs(target, profile.knots, profile.demand), config, ts=ts)


def step_commands(
    params: Parameters,
    target: Target,
    rate: float,
    lead: float,
    t1: float,
    lim: Limits | None = None,
    microsteps: int = 1,
) -> tuple[Float[np.ndarray, " K"], Float[np.ndarray, " K"]]:
    """Open-loop stepper command: (tick times (s), step counts) = round(demand(t + lead)·microsteps)/microsteps
    at ``rate`` Hz (≤ ``lim.max_step_rate``) over [0, t1) s, ``lead`` s ahead of the target, at most one step per
    tick, back steps included; ValueError where ``rate`` exceeds the motor's step rate."""
    lim = lim or limits(params)
    ticks = np.arange(0.0, t1, 1.0 / rate)
    demand = (target.at(ticks + lead) - target.length[0]) / step_length(params)
    if rate > lim.max_step_rate:
        raise ValueError(f"tick rate {rate} Hz exceeds the motor's step rate {lim.max_step_rate} steps/s")
    per_tick = 1.0  # one step per tick: a jump of two or more full steps at one edge makes the rotor skip
    k, counts = 0.0, []
    for d in demand:
        k += float(np.clip(np.round((d - k) * microsteps) / microsteps, -per_tick, per_tick))
        counts.append(k)
    return ticks, np.asarray(counts)


def optimize_steps(
    params: Parameters,
    target: Target,
    t1: float,
    rate: float = 50.0,
    leads: Sequence[float] | None = None,
    config: gj.Config | None = None,
) -> tuple[float, float, Float[np.ndarray, " K"], Float[np.ndarray, " K"]]:
    """The open-loop step schedule (integer steps: a search over the lead time, not gradients) of the stepper
    drive minimising the length RMSE on ``config`` (default fast). → (best lead s, RMSE m, ticks, counts)."""
    config = config or gj.Config(drive="inverse", t1=t1)
    leads = np.linspace(0.0, 0.4, 9) if leads is None else leads
    ts = target.time[(target.time >= config.t0) & (target.time <= t1)]
    best = None
    for lead in leads:
        ticks, counts = step_commands(params, target, rate, lead, t1)
        tr = simulate_steps(params, target, ticks, counts, config, ts)
        e = rmse(ts, tr.length, target)
        if best is None or e < best[1]:
            best = (float(lead), e, ticks, counts)
    return best


def simulate_steps(
    params: Parameters,
    target: Target,
    ticks: Float[np.ndarray, " K"],
    counts: Float[np.ndarray, " K"],
    config: gj.Config,
    ts: Float[ArrayLike, " T"],
) -> gj.Trajectory:
    """Simulate the stepper drive on the save grid ``ts`` (s) under a step schedule (tick times s, step counts;
    only the changes enter the inputs)."""
    change = np.concatenate([[counts[0] != 0], np.diff(counts) != 0])
    sched = gj.StepSchedule(jnp.asarray(ticks[change]), jnp.asarray(counts[change]))
    inputs = gj.Inputs(catheter_length=catheter_signal(target), steps=sched)
    return gj.simulate(params, inputs, config, ts=ts)
