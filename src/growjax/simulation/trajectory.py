"""What a simulation returns, and how a solver's raw output becomes it (written once for both configurations).

No diffrax here: the fast configuration runs without importing it (the reference's diffrax glue is in
`growjax.simulation.reference`)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int

__all__ = ["OK", "PRESSURE_LIMIT", "SOLVER_FAILED", "STATUS_NAMES", "Trajectory", "finish", "status_name"]

OK = 0
"""Status of a trajectory: the run reached the end of its window."""
PRESSURE_LIMIT = 1
"""Status of a trajectory: the sensed pressure crossed the membrane's limit, and the run stopped there."""
SOLVER_FAILED = 2
"""Status of a trajectory: the solver failed (a non-finite state, the step budget spent, NaN parameters)."""
STATUS_NAMES = {OK: "ok", PRESSURE_LIMIT: "pressure_limit", SOLVER_FAILED: "solver_failed"}


def status_name(code: int | Int[ArrayLike, ""]) -> str:
    """The name of a trajectory's status code (`STATUS_NAMES`), ``"unknown(code)"`` for another."""
    return STATUS_NAMES.get(int(code), f"unknown({int(code)})")


class Trajectory(eqx.Module):
    """Simulated outputs on the save grid (arrays of shape (T,), NaN after a stop) and run status; a batch
    (`growjax.simulate_members`, ``jax.vmap``) adds leading axes ``*B`` to every field.

    Attributes:
        time: the save grid, s.
        length: robot length, m.
        pressure: sensed pressure P before the check valve, Pa.
        robot_flow: flow into the robot, m³/s.
        syringe_displacement: platform travel, m.
        robot_pressure: pressure inside the robot, Pa.
        pressure_demand: the forward drive's demand, Pa.
        status: 0 ok, 1 pressure limit crossed (the run stopped there unless configured not to),
            2 solver failure (non-finite state, step budget, NaN parameters).
        limit_time: when the pressure limit was first crossed, s (NaN if never).
        t_final: where the integration ended, s.
        n_steps: accepted solver steps.
        final_state: (n,) the solver's scaled state at ``t_final`` (layout per configuration, see its ``STATES``).
    """

    time: Float[Array, "*B T"]
    length: Float[Array, "*B T"]
    pressure: Float[Array, "*B T"]
    robot_flow: Float[Array, "*B T"]
    syringe_displacement: Float[Array, "*B T"]
    robot_pressure: Float[Array, "*B T"]
    pressure_demand: Float[Array, "*B T"]
    status: Int[Array, "*B"]
    limit_time: Float[Array, "*B"]
    t_final: Float[Array, "*B"]
    n_steps: Int[Array, "*B"]
    final_state: Float[Array, "*B n"]


def finish(
    ts: Float[Array, " T"],
    outputs: dict[str, Float[Array, " T"]],
    limit: Float[ArrayLike, ""],
    demand: Float[Array, " T"],
    stop_at_limit: bool,
    *,
    t_final: Float[Array, ""],
    status: Int[Array, ""],
    n_steps: Int[Array, ""],
    final_state: Float[Array, " n"],
) -> Trajectory:
    """A `Trajectory` from a solver's outputs and end.

    Samples after ``t_final`` are NaN. The pressure limit is flagged at the event (when it stopped
    the run) or at the first save time above it (when it did not).

    Args:
        ts: (T,) the save grid, s.
        outputs: {field: (T,)} on ``ts``, SI (``length``, ``pressure``, ``robot_flow``, ``syringe_displacement``,
            ``robot_pressure``).
        limit: the pressure limit, Pa.
        demand: (T,) the pressure demand, Pa.
        stop_at_limit: whether the pressure limit stops a run.
        t_final: the integrator's end, s.
        status: the integrator's: 0 reached t1, 1 stopped by the pressure-limit event, 2 failed.
        n_steps: accepted steps.
        final_state: (n,) the scaled state at ``t_final``.

    Returns:
        The trajectory.
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
    code = jnp.where(
        stopped,
        PRESSURE_LIMIT,
        jnp.where(failed, SOLVER_FAILED, jnp.where(jnp.isfinite(limit_time), PRESSURE_LIMIT, OK)),
    )
    return Trajectory(
        time=ts,
        length=clean["length"],
        pressure=clean["pressure"],
        robot_flow=clean["robot_flow"],
        syringe_displacement=clean["syringe_displacement"],
        robot_pressure=clean["robot_pressure"],
        pressure_demand=demand,
        status=code,
        limit_time=limit_time,
        t_final=t_final,
        n_steps=n_steps,
        final_state=final_state,
    )
