"""The reference configuration: the shipped network node by node, solved by a stiff ESDIRK method.

Topology: drive → lead screws → platform → 2 syringes → 2 hoses →
junction → orifice → tank → nozzle → node P (sensor) → check valve ∥ 3-way bypass →
robot. The hoses and the tank are chambers with their own pressures; the platform has its
1 g mass. Node pressures between resistances are algebraic and eliminated in
:func:`network` by two scalar root solves (hose–orifice–tank series flow, and the massless
rod coupled to the valve network through the nozzle). Solved by Kvaerno5 with tight
tolerances; slow but as close to the published model as growjax gets, it is what the fast
configuration (:mod:`growjax.fast_model`) is measured against. diffrax is imported where a solve is traced:
the fast configuration's users do not pay its import.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp

from growjax import _assembly as assembly
from growjax import effects as fx
from growjax import hydraulics as hy
from growjax._smooth import bracketed_root
from growjax.config import Config
from growjax.effects import Instant, Rod
from growjax.motor import (
    ideal_torque_drive_force,
    motor_derivatives,
    motor_equilibrium_offset,
    pid_output,
    winding_voltages,
)
from growjax.params import Parameters
from growjax.pump import platform_force, syringe_load_force
from growjax.robot import RodBalance, pressure_limit, rod_balance, rod_pressure
from growjax.trajectory import finish

if TYPE_CHECKING:
    import diffrax

FORWARD_STATES = ("x_platform", "v_platform", "p_tube", "wall_strain", "p_tank", "robot_displacement", "z_integral", "z_filter")
FORWARD_SCALES = (1e-3, 1e-3, 1e5, 1e-7, 1e5, 1e-3, 1e4, 1e5)
INVERSE_STATES = ("rotor_angle", "rotor_speed", "current_a", "current_b", "p_tube", "wall_strain", "p_tank", "robot_displacement")
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


class Prepared(NamedTuple):
    """Constants of the rod and valve laws, computed once per solve."""

    valves: hy.ValveNetwork
    rod: RodBalance


def prepare(params: Parameters, config: Config) -> Prepared:
    robot = params.robot
    crack = robot.yield_pressure if params.check_valve.crack_pressure is None else params.check_valve.crack_pressure
    valves = hy.valve_network(params.check_valve, params.valve, params.fluid, crack, config.crack_width, config.switch_width)
    return Prepared(valves, rod_balance(robot, (config.velocity_eps, config.stop_width)))


def network(params: Parameters, inputs, config: Config, prep: Prepared, t, v_platform, p_tube, p_tank, displacement,
            effect_states) -> Network:
    """Solve the resistive network for flows and node pressures given the chamber pressures and motions."""
    fl, pump, robot = params.fluid, params.pump, params.robot
    n = pump.n_syringes

    q_syringe = pump.syringe_area * v_platform
    p_syringe = p_tube + hy.pipeline_half_pressure_drop(params.tube, fl, q_syringe)

    # Hoses → junction → orifice → tank: unknown is the orifice drop.
    k_or = hy.orifice_conductance(params.orifice.area, params.orifice.discharge_coefficient, fl)
    p_cr_or = hy.critical_pressure(0.5 * (p_tube + p_tank), params.orifice.b_lam)
    dp_chambers = p_tube - p_tank

    def series_residual(dp_or):
        q = hy.orifice_flow(k_or, dp_or, p_cr_or)
        drop = hy.pipeline_half_pressure_drop(params.tube, fl, q / n) + hy.pipeline_half_pressure_drop(params.tank, fl, q)
        return dp_chambers - drop - dp_or

    dp_or = bracketed_root(series_residual, jnp.minimum(dp_chambers, 0.0), jnp.maximum(dp_chambers, 0.0), atol=1e-9)
    q_series = hy.orifice_flow(k_or, dp_or, p_cr_or)

    # Tank → nozzle → node P → valves → robot, with the rod balance: unknown is Δ = P − p_robot.
    length = robot.initial_length + displacement - fx.length_offset(params.effects, effect_states)
    catheter = jnp.maximum(inputs.catheter_length(t), 0.0)

    def rod(sensor, v):
        force = fx.rod_force(params.effects, effect_states, Rod(t, sensor, v, length, catheter,
                                                                params.robot.inner_radius, prep.rod.area))
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
    dp_tube, d_wall = hy.chamber_pressure_rate(params.tube, params.fluid, p_tube, wall_strain, net.syringe_flow - net.series_flow / n)
    dp_tank, _ = hy.chamber_pressure_rate(params.tank, params.fluid, p_tank, 0.0, net.series_flow - net.robot_flow - leak)
    return dp_tube, d_wall, dp_tank


def _forward_rates(t, y, params, inputs, config, prep):
    x_p, v_p, p_tube, wall, p_tank, xi, z_i, z_d = y[:8]
    e = y[8:]
    net = network(params, inputs, config, prep, t, v_p, p_tube, p_tank, xi, e)
    u, dz_i, dz_d = pid_output(params.pid, inputs.pressure_demand(t) - net.sensor_pressure, z_i, z_d)
    pump = params.pump
    commanded = ideal_torque_drive_force(pump.syringe_area, pump.n_syringes, u)
    drive = fx.applied_drive(params.effects, e, commanded)
    accel = platform_force(pump, drive, net.syringe_pressure, x_p, v_p, config.stop_width) / pump.platform_mass
    leak = fx.chamber_outflow(params.effects, e, t, p_tank)
    dp_tube, d_wall, dp_tank = _chambers(params, net, p_tube, wall, p_tank, leak)
    instant = Instant(t, net.sensor_pressure, net.robot_pressure, net.robot_flow, net.robot_velocity, net.length, commanded)
    rates = jnp.concatenate([
        jnp.stack([v_p, accel, dp_tube, d_wall, dp_tank, net.robot_flow / prep.rod.area, dz_i, dz_d]),
        fx.rates(params.effects, e, instant),
    ])
    return rates, (net, x_p)


def _inverse_rates(t, y, params, inputs, config, prep):
    angle, omega, i_a, i_b, p_tube, wall, p_tank, xi = y[:8]
    e = y[8:]
    pump, motor = params.pump, params.motor
    ratio = pump.screw_ratio
    x_p, v_p = angle / ratio, omega / ratio
    net = network(params, inputs, config, prep, t, v_p, p_tube, p_tank, xi, e)
    v_a, v_b = winding_voltages(motor, inputs.steps(t))
    torque, di_a, di_b = motor_derivatives(motor, angle + motor_equilibrium_offset(motor), omega, i_a, i_b, v_a, v_b)
    applied = fx.applied_drive(params.effects, e, torque)
    # Each motor drives one screw and one syringe; the platform mass is shared between the screws.
    load = -syringe_load_force(pump, net.syringe_pressure, x_p, v_p, config.stop_width) / (pump.n_syringes * ratio)
    inertia = motor.rotor_inertia + pump.platform_mass / (pump.n_syringes * ratio**2)
    damping = motor.rotor_damping + pump.screw_viscous_friction
    d_omega = (applied - damping * omega - load) / inertia
    leak = fx.chamber_outflow(params.effects, e, t, p_tank)
    dp_tube, d_wall, dp_tank = _chambers(params, net, p_tube, wall, p_tank, leak)
    instant = Instant(t, net.sensor_pressure, net.robot_pressure, net.robot_flow, net.robot_velocity, net.length, torque)
    rates = jnp.concatenate([
        jnp.stack([omega, d_omega, di_a, di_b, dp_tube, d_wall, dp_tank, net.robot_flow / prep.rod.area]),
        fx.rates(params.effects, e, instant),
    ])
    return rates, (net, x_p)


# The scaled field diffrax integrates: ``vector_field(t, ys, (params, inputs, config, prep))``.
_rates, vector_field = assembly.vector_fields(_forward_rates, _inverse_rates, lambda p, d: layout(p, d))


def initial_state(params: Parameters, config: Config) -> jax.Array:
    """Scaled initial state: syringes full on their stop, robot at its initial length, lines at their initial pressures."""
    tube, tank = params.tube, params.tank
    wall0 = tube.diameter_compliance * tube.initial_pressure
    zero = jnp.zeros_like(jnp.asarray(tube.initial_pressure, float))
    if config.drive == "forward":
        base = [zero, zero, zero + tube.initial_pressure, zero + wall0, zero + tank.initial_pressure, zero, zero, zero]
    else:
        base = [zero, zero, zero, zero, zero + tube.initial_pressure, zero + wall0, zero + tank.initial_pressure, zero]
    y = jnp.concatenate([jnp.stack(base), fx.initial_states(params.effects, params, config.drive)])
    return y / jnp.asarray(layout(params, config.drive)[1])


def _outputs(t, ys, params, inputs, config, prep):
    scales = jnp.asarray(layout(params, config.drive)[1])
    net, x_p = _rates(t, ys * scales, params, inputs, config, prep)[1]
    return net.length, net.sensor_pressure, net.robot_flow, x_p, net.robot_pressure


def pressure_limit_event(pressure, limit) -> diffrax.Event:
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

    return diffrax.Event(lambda t, y, args, **kw: 1.0 - pressure(t, y) / limit,
                         root_finder=optx.Bisection(rtol=1e-12, atol=1e-9, flip=True))


def save_at(ts) -> diffrax.SaveAt:
    """What the reference saves: the state at ``ts`` and the final time and state."""
    import diffrax

    return diffrax.SaveAt(subs=[diffrax.SubSaveAt(ts=ts), diffrax.SubSaveAt(t1=True)])


def solver_status(sol):
    """A diffrax solution's result as an integrator status: 0 reached t1, 1 stopped by the event, 2 failed."""
    import diffrax

    return jnp.where(sol.result == diffrax.RESULTS.successful, 0,
                     jnp.where(sol.result == diffrax.RESULTS.event_occurred, 1, 2))


def solve(params: Parameters, inputs, config: Config, ts, jump_ts, step_ts):
    """Integrate the reference configuration and return a :class:`growjax.trajectory.Trajectory` on ``ts``."""
    import diffrax

    rtol, atol = config.tolerances
    prep = prepare(params, config)
    args = (params, inputs, config, prep)
    limit = pressure_limit(params.robot)
    event = None
    if config.stop_at_pressure_limit:
        event = pressure_limit_event(lambda t, y: _outputs(t, y, params, inputs, config, prep)[1], limit)
    controller = diffrax.ClipStepSizeController(
        diffrax.PIDController(rtol=rtol, atol=atol, pcoeff=0.3, icoeff=0.4, dtmax=0.05),
        step_ts=step_ts, jump_ts=jump_ts)
    adjoint = diffrax.ForwardMode() if config.adjoint == "forward" else diffrax.RecursiveCheckpointAdjoint()
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field), diffrax.Kvaerno5(), config.t0, config.t1, 1e-7, initial_state(params, config),
        args=args, saveat=save_at(ts), stepsize_controller=controller, adjoint=adjoint, event=event,
        max_steps=config.step_budget, throw=False,
    )
    saved = sol.ys[0]
    finite = jnp.all(jnp.isfinite(saved), axis=1)
    safe = jnp.where(finite[:, None], saved, initial_state(params, config))
    length, pressure, q_r, x_p, p_r = jax.vmap(lambda t, y: _outputs(t, y, params, inputs, config, prep))(ts, safe)
    nan = jnp.where(finite, 0.0, jnp.nan)
    outputs = {"length": length + nan, "pressure": pressure + nan, "robot_flow": q_r + nan,
               "syringe_displacement": x_p + nan, "robot_pressure": p_r + nan}
    demand = jax.vmap(inputs.pressure_demand)(ts)
    return finish(ts, outputs, limit, demand, config.stop_at_pressure_limit, t_final=sol.ts[1][-1],
                  status=solver_status(sol), n_steps=sol.stats["num_accepted_steps"], final_state=sol.ys[1][-1])
