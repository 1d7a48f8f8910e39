"""What a simulation returns, and how a solver's raw output becomes it (written once for both configurations)."""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

# Status codes of a trajectory.
OK, PRESSURE_LIMIT, SOLVER_FAILED = 0, 1, 2
STATUS_NAMES = {OK: "ok", PRESSURE_LIMIT: "pressure_limit", SOLVER_FAILED: "solver_failed"}


def status_name(code) -> str:
    """Human-readable status of a trajectory."""
    return STATUS_NAMES.get(int(code), f"unknown({int(code)})")


class Trajectory(eqx.Module):
    """Simulated outputs on the save grid (arrays of shape (T,), NaN after a stop) and run status.

    Attributes:
        time: s.  length: robot length, m.  pressure: sensed pressure P before the check valve, Pa.
        robot_flow: m³/s into the robot.  syringe_displacement: platform travel, m.
        robot_pressure: Pa inside the robot.  pressure_demand: Pa (forward drive).
        status: 0 ok, 1 pressure limit crossed (the run stopped there unless configured not to),
            2 solver failure (non-finite state, step budget, NaN parameters).
        limit_time: s at which the pressure limit was first crossed (NaN if never).
        t_final: s where the integration ended.  n_steps: accepted solver steps.
        final_state: the solver's state at ``t_final`` (layout per configuration, see its ``STATES``).
    """

    time: jax.Array
    length: jax.Array
    pressure: jax.Array
    robot_flow: jax.Array
    syringe_displacement: jax.Array
    robot_pressure: jax.Array
    pressure_demand: jax.Array
    status: jax.Array
    limit_time: jax.Array
    t_final: jax.Array
    n_steps: jax.Array
    final_state: jax.Array


def pressure_limit_event(pressure, limit) -> diffrax.Event:
    """The event that stops a run where the sensed pressure crosses ``limit`` (Pa).

    ``pressure(t, y)`` is the configuration's sensed pressure (Pa) of its state. The crossing is
    located by bisection inside the step that crossed (to 1 ns and 1e-9 of the limit): bisection
    needs only the sign change the step guarantees, where Newton on the dense output can leave
    the step across a pulse edge and fail. The condition 1 − p/limit decreases through its root,
    as does the stand-in diffrax gives batch members without an event (the time left in the
    step), so one fixed bracket orientation serves a whole ``vmap`` batch, with no sign checks.
    """
    return diffrax.Event(lambda t, y, args, **kw: 1.0 - pressure(t, y) / limit,
                         root_finder=optx.Bisection(rtol=1e-12, atol=1e-9, flip=True))


def save_at(ts) -> diffrax.SaveAt:
    """What both configurations save: the state at ``ts`` and the final time and state."""
    return diffrax.SaveAt(subs=[diffrax.SubSaveAt(ts=ts), diffrax.SubSaveAt(t1=True)])


def solver_status(sol: diffrax.Solution):
    """A diffrax solution's result as an integrator status: 0 reached t1, 1 stopped by the event, 2 failed."""
    return jnp.where(sol.result == diffrax.RESULTS.successful, 0,
                     jnp.where(sol.result == diffrax.RESULTS.event_occurred, 1, 2))


def finish(ts, outputs: dict, limit, demand, stop_at_limit: bool, *, t_final, status, n_steps, final_state) -> Trajectory:
    """A :class:`Trajectory` from the outputs on ``ts`` (field → (T,) array) and the integrator's end.

    ``status`` is the integrator's: 0 reached t1, 1 stopped by the pressure-limit event, 2 failed.
    Samples after ``t_final`` are NaN. The pressure limit is flagged at the event (when it stopped
    the run) or at the first save time above it (when it did not).
    """
    event = status == 1
    after = ts > t_final + 1e-12
    clean = {k: jnp.where(after, jnp.nan, v) for k, v in outputs.items()}
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(v) | after) for v in clean.values()]))
    above = clean["pressure"] > limit
    first_above = ts[jnp.argmax(above)]
    stopped = event & stop_at_limit
    limit_time = jnp.where(stopped, t_final, jnp.where(jnp.any(above), first_above, jnp.nan))
    failed = (status == 2) | ~finite
    code = jnp.where(stopped, PRESSURE_LIMIT,
                     jnp.where(failed, SOLVER_FAILED, jnp.where(jnp.isfinite(limit_time), PRESSURE_LIMIT, OK)))
    return Trajectory(
        time=ts, length=clean["length"], pressure=clean["pressure"], robot_flow=clean["robot_flow"],
        syringe_displacement=clean["syringe_displacement"], robot_pressure=clean["robot_pressure"],
        pressure_demand=demand, status=code, limit_time=limit_time, t_final=t_final,
        n_steps=n_steps, final_state=final_state,
    )
