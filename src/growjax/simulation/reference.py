"""The reference configuration: the shipped network node by node, solved by a stiff ESDIRK method.

Topology: drive → lead screws → platform → 2 syringes → 2 hoses →
junction → orifice → tank → nozzle → node P (sensor) → check valve ∥ 3-way bypass →
robot. The hoses and the tank are chambers with their own pressures; the platform has its
1 g mass. Node pressures between resistances are algebraic and eliminated in
`network` by two scalar root solves (hose–orifice–tank series flow, and the massless
rod coupled to the valve network through the nozzle). Solved by Kvaerno5 with tight
tolerances; slow but as close to the published model as growjax gets, it is what the fast
configuration (`growjax.simulation.fast`) is measured against. diffrax is imported where a solve is traced:
the fast configuration's users do not pay its import.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int

import growjax.model.effects as fx
import growjax.model.hydraulics as hy
import growjax.simulation._assembly as assembly
from growjax.model.params import Parameters
from growjax.model.pump import platform_force
from growjax.model.robot import RodBalance, pressure_limit, rod_pressure
from growjax.model.signals import Inputs
from growjax.model.smooth import bracketed_root
from growjax.simulation.config import Config
from growjax.simulation.trajectory import Trajectory, finish

__all__ = [
    "FORWARD_SCALES",
    "FORWARD_STATES",
    "INVERSE_SCALES",
    "INVERSE_STATES",
    "Network",
    "Prepared",
    "initial_state",
    "layout",
    "network",
    "outputs",
    "prepare",
    "pressure_limit_event",
    "save_at",
    "solve",
    "solver_status",
]

if TYPE_CHECKING:
    import diffrax

FORWARD_STATES = (
    "x_platform",
    "v_platform",
    "p_tube",
    "wall_strain",
    "p_tank",
    "robot_displacement",
    "z_integral",
    "z_filter",
)
FORWARD_SCALES = (1e-3, 1e-3, 1e5, 1e-7, 1e5, 1e-3, 1e4, 1e5)
INVERSE_STATES = (
    "rotor_angle",
    "rotor_speed",
    "current_a",
    "current_b",
    "p_tube",
    "wall_strain",
    "p_tank",
    "robot_displacement",
)
INVERSE_SCALES = (1e-2, 1.0, 1.0, 1.0, 1e5, 1e-7, 1e5, 1e-3)


def layout(params: Parameters, drive: str) -> tuple[tuple, tuple]:
    """(state names, scales) of the reference configuration for a drive, effect states last."""
    return assembly.layout(params, drive, (FORWARD_STATES, FORWARD_SCALES), (INVERSE_STATES, INVERSE_SCALES))


class Network(NamedTuple):
    """Algebraic quantities of the hydraulic network at one instant (SI units)."""

    syringe_pressure: jax.Array  # Pa, at each syringe outlet
    syringe_flow: jax.Array  # m³/s out of each syringe
    series_flow: jax.Array  # m³/s from the hoses through the orifice into the tank
    robot_flow: jax.Array  # m³/s into the robot
    sensor_pressure: jax.Array  # Pa, node P before the check valve
    robot_pressure: jax.Array  # Pa, inside the robot
    robot_velocity: jax.Array  # m/s
    length: jax.Array  # m


class Prepared(eqx.Module):
    """Constants of the rod and valve laws, computed once per solve."""

    valves: hy.ValveNetwork
    rod: RodBalance


def prepare(params: Parameters, config: Config) -> Prepared:
    """The `Prepared` constants of ``params`` under ``config``."""
    valves, rod = assembly.valves_and_rod(params, config)
    return Prepared(valves=valves, rod=rod)


def network(
    params: Parameters,
    inputs: Inputs,
    config: Config,
    prep: Prepared,
    t: Float[ArrayLike, ""],
    v_platform: Float[ArrayLike, ""],
    p_tube: Float[ArrayLike, ""],
    p_tank: Float[ArrayLike, ""],
    displacement: Float[ArrayLike, ""],
    effect_states: Float[Array, " K"],
) -> Network:
    """Solve the resistive network for flows and node pressures given the chamber pressures and motions.

    Args:
        params: the parameters, effects applied.
        inputs: the input signals.
        config: the configuration.
        prep: the `Prepared` constants.
        t: the time, s.
        v_platform: the platform's velocity, m/s.
        p_tube: the hoses' gauge pressure, Pa.
        p_tank: the tank's gauge pressure, Pa.
        displacement: the robot's displacement from its initial length, m.
        effect_states: (K,) the effects' states.

    Returns:
        The `Network`'s flows (m³/s), pressures (Pa), velocity (m/s) and length (m).
    """
    fl, pump = params.fluid, params.pump
    n = pump.n_syringes

    q_syringe = pump.syringe_area * v_platform
    p_syringe = p_tube + hy.pipeline_half_pressure_drop(params.tube, fl, q_syringe)

    # Hoses → junction → orifice → tank: unknown is the orifice drop.
    k_or = hy.orifice_conductance(params.orifice.area, params.orifice.discharge_coefficient, fl)
    p_cr_or = hy.critical_pressure(0.5 * (p_tube + p_tank), params.orifice.b_lam)
    dp_chambers = p_tube - p_tank

    def series_residual(dp_or):
        q = hy.orifice_flow(k_or, dp_or, p_cr_or)
        drop = hy.pipeline_half_pressure_drop(params.tube, fl, q / n) + hy.pipeline_half_pressure_drop(
            params.tank, fl, q
        )
        return dp_chambers - drop - dp_or

    dp_or = bracketed_root(series_residual, jnp.minimum(dp_chambers, 0.0), jnp.maximum(dp_chambers, 0.0), atol=1e-9)
    q_series = hy.orifice_flow(k_or, dp_or, p_cr_or)

    # Tank → nozzle → node P → valves → robot, with the rod balance: unknown is Δ = P − p_robot.
    length = assembly.robot_length(params, displacement, effect_states)
    catheter = assembly.catheter_length(inputs, t)

    def rod(sensor, v):
        force = assembly.effect_force(params, effect_states, prep.rod, t, sensor, length, catheter)(v)
        return rod_pressure(prep.rod, sensor, v, length, catheter, force)

    def branch(delta):
        q = hy.valve_network_flow(prep.valves, delta, p_tank - 0.5 * delta)
        p_nozzle_b = p_tank - hy.pipeline_half_pressure_drop(params.tank, fl, q)
        sensor = p_nozzle_b + hy.nozzle_pressure_drop(params.nozzle, fl, -q, p_nozzle_b, config.flow_width)
        v = q / prep.rod.area
        return q, sensor, rod(sensor, v), v

    def branch_residual(delta):
        _, sensor, p_r, _ = branch(delta)
        return sensor - p_r - delta

    delta0 = p_tank - rod(p_tank, jnp.zeros_like(p_tank))
    delta = bracketed_root(branch_residual, jnp.minimum(delta0, 0.0), jnp.maximum(delta0, 0.0), x0=delta0, atol=1e-9)
    q_robot, sensor, p_r, v = branch(delta)
    return Network(p_syringe, q_syringe, q_series, q_robot, sensor, p_r, v, length)


def _chambers(params, net, p_tube, wall_strain, p_tank, leak):
    n = params.pump.n_syringes
    dp_tube, d_wall = hy.chamber_pressure_rate(
        params.tube, params.fluid, p_tube, wall_strain, net.syringe_flow - net.series_flow / n
    )
    dp_tank, _ = hy.chamber_pressure_rate(
        params.tank, params.fluid, p_tank, 0.0, net.series_flow - net.robot_flow - leak
    )
    return dp_tube, d_wall, dp_tank


def _forward_rates(t, y, params, inputs, config, prep):
    x_p, v_p, p_tube, wall, p_tank, xi, z_i, z_d = y[:8]
    e = y[8:]
    net = network(params, inputs, config, prep, t, v_p, p_tube, p_tank, xi, e)
    commanded, drive, dz_i, dz_d = assembly.pid_drive(params, inputs, t, net.sensor_pressure, z_i, z_d, e)
    pump = params.pump
    accel = platform_force(pump, drive, net.syringe_pressure, x_p, v_p, config.stop_width) / pump.platform_mass
    leak = fx.chamber_outflow(params.effects, e, t, p_tank)
    dp_tube, d_wall, dp_tank = _chambers(params, net, p_tube, wall, p_tank, leak)
    base = [v_p, accel, dp_tube, d_wall, dp_tank, net.robot_flow / prep.rod.area, dz_i, dz_d]
    return _rates_of(params, e, base, t, net, prep, commanded), (net, x_p)


def _inverse_rates(t, y, params, inputs, config, prep):
    angle, omega, i_a, i_b, p_tube, wall, p_tank, xi = y[:8]
    e = y[8:]
    x_p, v_p = assembly.platform_of_rotor(params.pump, angle, omega)
    net = network(params, inputs, config, prep, t, v_p, p_tube, p_tank, xi, e)
    torque, d_omega, di_a, di_b = assembly.stepper(
        params, inputs, t, angle, omega, i_a, i_b, net.syringe_pressure, e, config.stop_width
    )
    leak = fx.chamber_outflow(params.effects, e, t, p_tank)
    dp_tube, d_wall, dp_tank = _chambers(params, net, p_tube, wall, p_tank, leak)
    base = [omega, d_omega, di_a, di_b, dp_tube, d_wall, dp_tank, net.robot_flow / prep.rod.area]
    return _rates_of(params, e, base, t, net, prep, torque), (net, x_p)


def _rates_of(params, effect_states, base, t, net: Network, prep: Prepared, drive):
    return assembly.state_rates(
        params,
        effect_states,
        base,
        t=t,
        pressure=net.sensor_pressure,
        robot_pressure=net.robot_pressure,
        robot_flow=net.robot_flow,
        area=prep.rod.area,
        length=net.length,
        drive=drive,
    )


# The scaled field diffrax integrates: ``vector_field(t, ys, (params, inputs, config, prep))``.
rates, vector_field = assembly.vector_fields(_forward_rates, _inverse_rates, lambda p, d: layout(p, d))


def initial_state(params: Parameters, config: Config) -> jax.Array:
    """Scaled initial state: syringes full on their stop, robot at its initial length, lines at their initial
    pressures."""
    tube, tank = params.tube, params.tank
    wall0 = tube.diameter_compliance * tube.initial_pressure
    zero = jnp.zeros_like(jnp.asarray(tube.initial_pressure, float))
    if config.drive == "forward":
        base = [zero, zero, zero + tube.initial_pressure, zero + wall0, zero + tank.initial_pressure, zero, zero, zero]
    else:
        base = [zero, zero, zero, zero, zero + tube.initial_pressure, zero + wall0, zero + tank.initial_pressure, zero]
    return assembly.scaled_initial_state(params, config.drive, base, layout(params, config.drive)[1])


def outputs(
    t: Float[ArrayLike, ""], ys: Float[Array, " n"], params: Parameters, inputs: Inputs, config: Config, prep: Prepared
) -> dict[str, Float[Array, ""]]:
    """The outputs ({name: value}, SI: length, pressure, robot_flow, syringe_displacement, robot_pressure) of a
    scaled state ``ys`` (n,) at time ``t`` (s)."""
    scales = jnp.asarray(layout(params, config.drive)[1])
    net, x_p = rates(t, ys * scales, params, inputs, config, prep)[1]
    values = (net.length, net.sensor_pressure, net.robot_flow, x_p, net.robot_pressure)
    return dict(zip(assembly.OUTPUTS, values))


def pressure_limit_event(
    pressure: Callable[[Float[Array, ""], Float[Array, " n"]], Float[Array, ""]], limit: Float[ArrayLike, ""]
) -> diffrax.Event:
    """The event that stops a run where the sensed pressure crosses ``limit`` (Pa).

    ``pressure(t, y)`` is the configuration's sensed pressure (Pa) of its state. The crossing is
    located by bisection inside the step that crossed (to 1 ns and 1e-9 of the limit): bisection
    needs only the sign change the step guarantees, where Newton on the dense output can leave
    the step across a pulse edge and fail. The condition 1 − p/limit decreases through its root,
    as does the stand-in diffrax gives batch members without an event (the time left in the
    step), so one fixed bracket orientation serves a whole ``vmap`` batch, with no sign checks.
    """
    import diffrax
    import optimistix as optx

    return diffrax.Event(
        lambda t, y, args, **kw: 1.0 - pressure(t, y) / limit,
        root_finder=optx.Bisection(rtol=1e-12, atol=1e-9, flip=True),
    )


def save_at(ts: Float[Array, " T"]) -> diffrax.SaveAt:
    """What the reference saves: the state at ``ts`` (s) and the final time and state."""
    import diffrax

    return diffrax.SaveAt(subs=[diffrax.SubSaveAt(ts=ts), diffrax.SubSaveAt(t1=True)])


def solver_status(sol: diffrax.Solution) -> Int[Array, "*B"]:
    """A diffrax solution's result as an integrator status: 0 reached t1, 1 stopped by the event, 2 failed."""
    import diffrax

    return jnp.where(
        sol.result == diffrax.RESULTS.successful, 0, jnp.where(sol.result == diffrax.RESULTS.event_occurred, 1, 2)
    )


def solve(
    params: Parameters,
    inputs: Inputs,
    config: Config,
    ts: Float[Array, " T"],
    jump_ts: Float[Array, " J"],
    step_ts: Float[Array, " K"],
    start: tuple[Float[ArrayLike, ""], Float[ArrayLike, ""], Float[Array, " n"]] | None = None,
) -> Trajectory:
    """Integrate the reference configuration.

    Args:
        params: the parameters, effects applied.
        inputs: the input signals.
        config: the configuration, resolved.
        ts: (T,) the save grid, s.
        jump_ts: (J,) the inputs' jump times, s, padded beyond t1.
        step_ts: (K,) their slope-break times, s, padded beyond t1.
        start: (t_start s, t_end s, scaled state (n,)), each may be traced: the window and the initial state in
            place of ``config``'s.

    Returns:
        The `growjax.Trajectory` on ``ts``.
    """
    import diffrax

    rtol, atol = config.tolerances
    prep = prepare(params, config)
    args = (params, inputs, config, prep)
    limit = pressure_limit(params.robot)
    event = None
    if config.stop_at_pressure_limit:
        event = pressure_limit_event(lambda t, y: outputs(t, y, params, inputs, config, prep)["pressure"], limit)
    controller = diffrax.ClipStepSizeController(
        diffrax.PIDController(rtol=rtol, atol=atol, pcoeff=0.3, icoeff=0.4, dtmax=0.05),
        step_ts=step_ts,
        jump_ts=jump_ts,
    )
    adjoint = diffrax.ForwardMode() if config.adjoint == "forward" else diffrax.RecursiveCheckpointAdjoint()
    t0, t1, y0 = (config.t0, config.t1, initial_state(params, config)) if start is None else start
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field),
        diffrax.Kvaerno5(),
        t0,
        t1,
        1e-7,
        y0,
        args=args,
        saveat=save_at(ts),
        stepsize_controller=controller,
        adjoint=adjoint,
        event=event,
        max_steps=config.step_budget,
        throw=False,
    )
    values, _ = assembly.outputs_where_finite(
        lambda t, y: outputs(t, y, params, inputs, config, prep), ts, sol.ys[0], y0
    )
    demand = jax.vmap(inputs.pressure_demand)(ts)
    return finish(
        ts,
        values,
        limit,
        demand,
        config.stop_at_pressure_limit,
        t_final=sol.ts[1][-1],
        status=solver_status(sol),
        n_steps=sol.stats["num_accepted_steps"],
        final_state=sol.ys[1][-1],
    )
