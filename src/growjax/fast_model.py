"""The fast configuration: the same components with the lines lumped, solved by an L-stable Rosenbrock method.

Three reductions of the reference assembly (:mod:`growjax.reference_model`), each of a mode far
faster than anything the robot's length shows:

* the hoses, orifice, tank and node P form one chamber: their series drops equalise in
  < 15 µs; the pump sees the series drop of the lines at its flow
  (:func:`growjax.hydraulics.line_pressure_drop`), and the sensor reads the chamber;
* the forward drive's platform is massless (its mode is 8 ns): its velocity balances the drive
  against the screws, the line drop and the syringes' end stop, in closed form
  (:func:`growjax.pump.platform_velocity`); the lines' drop is taken at its laminar slope;
* the state of the chamber is the liquid volume it stores, not its pressure. The pressure
  follows from the exact stored-volume law of the liquid–air mixture
  (:func:`growjax.fluid.pressure_at_stored_fraction`), so the volume balance is a linear
  invariant of the ODE, which a Rosenbrock method keeps to rounding error through every
  pulse edge.

Everything else, the rod and valve balance (:func:`growjax.robot.inflow`), the motor, the
PID and every added effect (:mod:`growjax.effects`), is the same code as the reference's.
The remaining stiffness (the opened bypass, ~1e5 s⁻¹; the stepper rotor, ~3e5 s⁻¹) is
damped by the L-stable ROS34PW2 method (:mod:`growjax._rosenbrock`) with the exact Jacobian,
at steps set by the slow dynamics, with input edges declared to the step-size controller.
"""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from growjax import _assembly as assembly
from growjax import effects as fx
from growjax import hydraulics as hy
from growjax import xla_flags
from growjax._rosenbrock import evaluate, integrate, spread
from growjax.config import Config
from growjax.effects import Instant, Rod
from growjax.fluid import (
    StorageLaw,
    pressure_at_stored_fraction,
    storage_law,
    stored_volume_fraction,
)
from growjax.hydraulics import ValveNetwork, valve_network
from growjax.motor import (
    ideal_torque_drive_force,
    motor_derivatives,
    motor_equilibrium_offset,
    pid_output,
    winding_voltages,
)
from growjax.params import Parameters
from growjax.pump import platform_velocity, syringe_load_force
from growjax.robot import (
    INFLOW_MAX_ITERATIONS,
    RodBalance,
    inflow,
    pressure_limit,
    rod_balance,
)
from growjax.trajectory import finish

FORWARD_STATES = ("stored_volume", "x_platform", "robot_displacement", "wall_strain", "z_integral", "z_filter")
FORWARD_SCALES = (1e-6, 1e-2, 1e-4, 1e-6, 1e6, 1e7)  # error control weights the length 100x more than the pressure loop
INVERSE_STATES = ("stored_volume", "rotor_angle", "rotor_speed", "current_a", "current_b", "robot_displacement", "wall_strain")
INVERSE_SCALES = (1e-7, 1e-2, 1.0, 1.0, 1.0, 1e-3, 1e-7)


def layout(params: Parameters, drive: str) -> tuple[tuple, tuple]:
    """(state names, scales) of the fast configuration for a drive, effect states last."""
    return assembly.layout(params, drive, (FORWARD_STATES, FORWARD_SCALES), (INVERSE_STATES, INVERSE_SCALES))


class Prepared(eqx.Module):
    """Constants of the hot laws, computed once per solve (not in every evaluation of the vector field)."""

    storage: StorageLaw
    valves: ValveNetwork
    rod: RodBalance
    line_resistance: jax.Array  # Pa·s/m³
    newton: jax.Array | None  # bool: a velocity-dependent force is present (None: decided statically)
    inflow_iterations: int = eqx.field(static=True)
    share_values: bool = eqx.field(static=True, default=False)  # set for large batches: :func:`_computed_once`


def prepare(params: Parameters, config: Config) -> Prepared:
    """The :class:`Prepared` constants of ``params`` under ``config``."""
    robot = params.robot
    crack = robot.yield_pressure if params.check_valve.crack_pressure is None else params.check_valve.crack_pressure
    valves = valve_network(params.check_valve, params.valve, params.fluid, crack, config.crack_width, config.switch_width)
    rod = rod_balance(robot, (config.velocity_eps, config.stop_width))
    # The published law's velocity term is ~1e-10 of the rod forces: one fixed-point pass is exact, also while
    # every velocity-dependent effect is at zero (decided at run time: a superset model's candidates switched off,
    # where the Newton solve would triple the cost of every field evaluation).
    velocity_effects = [e for e in params.effects if e.velocity_dependent]
    iterations = 0 if _rod_solve(params) == "one pass" else INFLOW_MAX_ITERATIONS
    newton = None
    if _rod_solve(params) == "newton where present":
        newton = jnp.any(jnp.stack([e.present() for e in velocity_effects]))
    return Prepared(storage_law(params.fluid), valves, rod, line_resistance(params), newton, iterations)


def _rod_solve(params: Parameters) -> str:
    """How the rod balance is solved in every field evaluation, decided statically: ``"one pass"`` (the published
    law, no velocity-dependent effect), ``"newton"`` (the Lockhart law) or ``"newton where present"`` (the
    published law with velocity-dependent effects: Newton at run time only where one of them is nonzero)."""
    velocity_effects = any(e.velocity_dependent for e in params.effects)
    if params.robot.growth_law != "reference":
        return "newton"
    return "newton where present" if velocity_effects else "one pass"


# -- the lumped chamber ----------------------------------------------------------------------------------


def lines_volume(params: Parameters, wall_strain):
    """Volume of the lumped chamber, m³: the hoses at wall strain δ (m) and the tank."""
    tube = params.tube
    hoses = params.pump.n_syringes * jnp.pi * (tube.hydraulic_diameter + wall_strain) ** 2 / 4.0 * tube.length
    return hoses + params.tank.volume


def stored_volume(params: Parameters, pressure, wall_strain):
    """Liquid volume in the lumped chamber beyond its unstrained volume at gauge 0, m³ (pressure in Pa)."""
    volume = lines_volume(params, wall_strain)
    return volume * (1.0 + stored_volume_fraction(params.fluid, pressure)) - lines_volume(params, 0.0)


def line_pressure(params: Parameters, stored, wall_strain, storage: StorageLaw | None = None):
    """Gauge pressure of the lumped chamber, Pa, holding ``stored`` m³ (inverse of :func:`stored_volume`)."""
    volume = lines_volume(params, wall_strain)
    law = storage if storage is not None else storage_law(params.fluid)
    return pressure_at_stored_fraction(law, (stored + lines_volume(params, 0.0)) / volume - 1.0)


def initial_state(params: Parameters, config: Config) -> jax.Array:
    """Scaled state at t0: syringes full, robot at its initial length, hoses and tank at their initial pressures."""
    tube, tank = params.tube, params.tank
    n = params.pump.n_syringes
    wall0 = tube.diameter_compliance * tube.initial_pressure
    hose = jnp.pi * (tube.hydraulic_diameter + wall0) ** 2 / 4.0 * tube.length
    stored = n * (hose * (1.0 + stored_volume_fraction(params.fluid, tube.initial_pressure)) - tube.volume)
    stored = stored + tank.volume * stored_volume_fraction(params.fluid, tank.initial_pressure)
    zero = jnp.zeros_like(stored)
    if config.drive == "forward":
        base = [stored, zero, zero, zero + wall0, zero, zero]
    else:
        base = [stored, zero, zero, zero, zero, zero, zero + wall0]
    y = jnp.concatenate([jnp.stack(base), fx.initial_states(params.effects, params, config.drive)])
    return y / jnp.asarray(layout(params, config.drive)[1])


# -- the vector field -----------------------------------------------------------------------------------


def _robot_side(params, inputs, prep, t, pressure, displacement, effect_states):
    """Flow into the robot, its pressure and length at chamber pressure ``pressure``."""
    length = params.robot.initial_length + displacement - fx.length_offset(params.effects, effect_states)
    catheter = jnp.maximum(inputs.catheter_length(t), 0.0)

    def effect_force(v):
        return fx.rod_force(params.effects, effect_states, Rod(t, pressure, v, length, catheter,
                                                               params.robot.inner_radius, prep.rod.area))

    q, p_r = inflow(prep.rod, prep.valves, pressure, length, catheter, effect_force, prep.inflow_iterations,
                    prep.newton)
    return q, p_r, length


def line_resistance(params: Parameters):
    """Resistance of the lines from the syringes to the chamber, Pa·s/m³: the slope of
    :func:`growjax.hydraulics.line_pressure_drop` at zero flow and gauge 0. The drop it gives,
    n² A_s² R ≈ 35 N·s/m against the screws' 1.2e5 N·s/m, changes the platform speed by < 3e-4,
    so its turbulent part and its pressure dependence are left out of the fast configuration."""

    def drop(q):
        return hy.line_pressure_drop(params.tube, params.orifice, params.tank, params.fluid, q,
                                     params.pump.n_syringes, jnp.zeros_like(q))

    zero = jnp.zeros_like(jnp.asarray(params.tank.area, float))
    return jax.jvp(drop, (zero,), (jnp.ones_like(zero),))[1]


def _wall_rate(params, pressure, wall):
    tube = params.tube
    return (tube.diameter_compliance * pressure - wall) / tube.wall_time_constant


SHARED_BATCH_MIN = 16  # members of a batched solve from which the field computes its shared values once


def _computed_once(*values):
    """``values`` unchanged (exactly: a product with the identity, float64), through an array XLA must materialise.

    XLA:CPU fuses a batched field into one loop kernel that evaluates each state rate on its own, recomputing
    what the rates share (the robot's inflow, the platform speed) once per rate: 936 operations for 338
    distinct. A dot is never fused into that loop, so values passed through one are computed once (a 500-set
    sweep: 3.8 s → 2.6 s, ``benchmarks/sweep.py --profile 500``). Used in batched solves of at least
    ``SHARED_BATCH_MIN`` members (``Prepared.share_values``); in one run the extra launch costs more than it
    saves. XLA drops ``jax.lax.optimization_barrier`` on CPU before fusing: a barrier does not do this.
    A non-finite value makes the others NaN (0·∞): the run has failed either way.
    """
    stacked = jnp.stack(values)
    stacked = jnp.dot(jnp.eye(len(values), dtype=stacked.dtype), stacked, precision=jax.lax.Precision.HIGHEST)
    return tuple(stacked[i] for i in range(len(values)))


def _forward_rates(t, y, params, inputs, config, prep):
    """Unscaled rates and the instant's outputs of the forward drive."""
    stored, x_p, xi, wall, z_i, z_d = y[:6]
    e = y[6:]
    pump = params.pump
    pressure = line_pressure(params, stored, wall, prep.storage)
    u, dz_i, dz_d = pid_output(params.pid, inputs.pressure_demand(t) - pressure, z_i, z_d)
    commanded = ideal_torque_drive_force(pump.syringe_area, pump.n_syringes, u)
    drive = fx.applied_drive(params.effects, e, commanded)
    v_p = platform_velocity(pump, drive, pressure, prep.line_resistance, x_p, config.stop_width)
    q_r, p_r, length = _robot_side(params, inputs, prep, t, pressure, xi, e)
    if prep.share_values:
        q_r, p_r, v_p = _computed_once(q_r, p_r, v_p)
    leak = fx.chamber_outflow(params.effects, e, t, pressure)
    area = prep.rod.area
    instant = Instant(t, pressure, p_r, q_r, q_r / area, length, commanded)
    rates = jnp.concatenate([
        jnp.stack([pump.n_syringes * pump.syringe_area * v_p - q_r - leak, v_p, q_r / area,
                   _wall_rate(params, pressure, wall), dz_i, dz_d]),
        fx.rates(params.effects, e, instant),
    ])
    return rates, (length, pressure, q_r, x_p, p_r)


def _inverse_rates(t, y, params, inputs, config, prep):
    """Unscaled rates and the instant's outputs of the inverse (stepper) drive (its driver: ``params.motor``)."""
    stored, angle, omega, i_a, i_b, xi, wall = y[:7]
    e = y[7:]
    pump, motor = params.pump, params.motor
    ratio = pump.screw_ratio
    x_p, v_p = angle / ratio, omega / ratio
    pressure = line_pressure(params, stored, wall, prep.storage)
    v_a, v_b = winding_voltages(motor, inputs.steps(t))
    torque, di_a, di_b = motor_derivatives(motor, angle + motor_equilibrium_offset(motor), omega, i_a, i_b, v_a, v_b)
    applied = fx.applied_drive(params.effects, e, torque)
    # Each motor drives one screw and one syringe; the platform mass is shared between the screws.
    syringe_pressure = pressure + prep.line_resistance * pump.n_syringes * pump.syringe_area * v_p
    load = -syringe_load_force(pump, syringe_pressure, x_p, v_p, config.stop_width) / (pump.n_syringes * ratio)
    inertia = motor.rotor_inertia + pump.platform_mass / (pump.n_syringes * ratio**2)
    damping = motor.rotor_damping + pump.screw_viscous_friction
    d_omega = (applied - damping * omega - load) / inertia
    q_r, p_r, length = _robot_side(params, inputs, prep, t, pressure, xi, e)
    if prep.share_values:
        q_r, p_r, d_omega = _computed_once(q_r, p_r, d_omega)
    leak = fx.chamber_outflow(params.effects, e, t, pressure)
    area = prep.rod.area
    instant = Instant(t, pressure, p_r, q_r, q_r / area, length, torque)
    rates = jnp.concatenate([
        jnp.stack([pump.n_syringes * pump.syringe_area * v_p - q_r - leak, omega, d_omega, di_a, di_b,
                   q_r / area, _wall_rate(params, pressure, wall)]),
        fx.rates(params.effects, e, instant),
    ])
    return rates, (length, pressure, q_r, x_p, p_r)


# The scaled field diffrax integrates: ``vector_field(t, ys, (params, inputs, config, prep))``.
_rates, vector_field = assembly.vector_fields(_forward_rates, _inverse_rates, lambda p, d: layout(p, d))


def pressure_of(params: Parameters, config: Config, ys, storage: StorageLaw | None = None):
    """Chamber pressure (Pa) of a scaled state."""
    scales = layout(params, config.drive)[1]
    wall_index = 3 if config.drive == "forward" else 6
    return line_pressure(params, ys[0] * scales[0], ys[wall_index] * scales[wall_index], storage)


# -- the solve ------------------------------------------------------------------------------------------


# Loosest of rtol and this bounds the sensitivities' error control (see _integrate).
SENSITIVITY_TOL_FLOOR = 1e-6

OUTPUTS = ("length", "pressure", "robot_flow", "syringe_displacement", "robot_pressure")


class Run(eqx.Module):
    """The differentiable part of a solve: outputs on the save grid (field → (T,)), the final state (n,) and time (s)."""

    outputs: dict
    final_state: jax.Array
    t_final: jax.Array


def _relative_size(theta, direction, typical):
    """How large a direction is relative to the values it perturbs: max |d|/|θ| over the leaves (–). Where θ = 0
    the leaf's ``typical`` size stands in (an effect parameter: the top of its physical range; a leak of
    3e-13 m³/(s·Pa) absent at 0 and moved along d = 1 must be shifted by ε·1e-12, not by ε), and where that is
    0 too, |d| itself."""
    ratios = [jnp.max(jnp.abs(d) / jnp.maximum(jnp.where(jnp.abs(x) > 0, jnp.abs(x),
                                                         jnp.where(jnp.abs(c) > 0, jnp.abs(c), jnp.abs(d))), 1e-300))
              for x, d, c in zip(jax.tree_util.tree_leaves(theta), jax.tree_util.tree_leaves(direction),
                                 jax.tree_util.tree_leaves(typical))
              if jnp.issubdtype(jnp.result_type(d), jnp.floating) and jnp.size(d)]
    return jnp.max(jnp.stack(ratios)) if ratios else jnp.asarray(0.0)


def _typical(params: Parameters):
    """``params`` with each effect's parameters set to the top of their physical ranges (their typical size)."""
    effects = tuple(dataclasses.replace(e, **{f: max(abs(lo), abs(hi)) for f, (lo, hi) in e.ranges.items()})
                    for e in params.effects)
    return dataclasses.replace(params, effects=effects)


def _shifted(theta, direction, step):
    """θ + step·d, leaf by leaf (leaves that are not floating point are left alone)."""
    def shift(x, d):
        if jnp.issubdtype(jnp.result_type(x), jnp.floating) and jnp.size(x):
            return x + step * d
        return x

    return jax.tree_util.tree_map(shift, theta, direction)


def _member(params, inputs, config: Config, jump_ts, step_ts):
    """One member's solver inputs: (θ = (params, inputs, prepared constants), scaled initial state, sorted
    breaks, jump flags)."""
    theta = (params, inputs, prepare(params, config))
    times = jnp.concatenate([jump_ts, step_ts])
    order = jnp.argsort(times)
    is_jump = jnp.concatenate([jnp.ones(jump_ts.shape, bool), jnp.zeros(step_ts.shape, bool)])
    return theta, initial_state(params, config), times[order], is_jump[order]


def _callbacks(config: Config):
    """(field, outputs, event) of the scaled state, each ``(t, y, θ)`` with θ from :func:`_member`."""

    def field(t, y, th):
        p, i, pr = th
        return vector_field(t, y, (p, i, config, pr))

    def outputs(t, y, th):
        p, i, pr = th
        scales = jnp.asarray(layout(p, config.drive)[1])
        length, pressure, q_r, x_p, p_r = _rates(t, y * scales, p, i, config, pr)[1]
        return dict(zip(OUTPUTS, (length, pressure, q_r, x_p, p_r)))

    event = None
    if config.stop_at_pressure_limit:
        def event(t, y, th):  # decreases through 0 where the sensed pressure crosses the limit
            p, _, pr = th
            return 1.0 - pressure_of(p, config, y, pr.storage) / pressure_limit(p.robot)

    return field, outputs, event


def _primal(run, ts, y0, theta, outputs):
    """(primal Run on ts, state block on ts (T, 1 + p, n), primal states there). A non-finite state (a failed
    run) is evaluated at y0 instead and its outputs are NaN."""
    block = evaluate(run.steps, ts) if run.saved is None else run.saved
    finite = jnp.all(jnp.isfinite(block[:, 0]), axis=1)
    saved = jnp.where(finite[:, None], block[:, 0], y0)
    nan = jnp.where(finite, 0.0, jnp.nan)
    values = jax.vmap(outputs, in_axes=(0, 0, None))(ts, saved, theta)
    return Run({k: v + nan for k, v in values.items()}, run.y_final[0], run.t_final), block, saved


def _forward_mode_tangents(params: Parameters, config: Config) -> bool:
    """Whether the sensitivities' field is taken in forward mode, else by central differences (``config.tangents``;
    decided when a solve is traced). ``jax.jvp`` evaluates the primal field, and its inner Newton solve, once for
    all p directions where differences evaluate it 1 + 2p times; but its many small operations are launched one
    by one unless the solver's loop is compiled whole (:mod:`growjax.xla_flags`). ``"auto"`` takes forward mode
    where the loop is compiled whole or the rod balance is solved by Newton in every evaluation (the Lockhart law)
    (``python benchmarks/simulate.py --tangents``, 3 parameters: Lockhart 31 ms against 60 ms by differences with
    small loops, 88 against 115 ms without; published law 17 against 24 ms with, but 62 against 41 ms without)."""
    if config.tangents == "auto":
        return xla_flags.applied() or _rod_solve(params) == "newton"
    return config.tangents == "forward"


def _sensitivities(params, inputs, config: Config, jump_ts, step_ts, directions):
    """One member's sensitivity problem along ``directions`` (see :func:`_integrate`): (θ_s, sizes |d|/|θ| (p,),
    S0 (p, n)), θ_s for the callbacks of :func:`_sensitivity_callbacks`."""
    build = _forward_sensitivities if _forward_mode_tangents(params, config) else _difference_sensitivities
    return build(params, inputs, config, jump_ts, step_ts, directions)


def _sensitivity_callbacks(params: Parameters, config: Config):
    """(tangent field ``(t, y, S, θ_s) → (f, S')``, output tangents ``(t, y, S, θ_s) → {output: (p,)}``)."""
    return (_forward_callbacks if _forward_mode_tangents(params, config) else _difference_callbacks)(config)


def _difference_step(size):
    """Step ε along each direction (p,) that moves the parameters by (machine ε)^⅓ of themselves (0 where |d| = 0)."""
    return jnp.where(size > 0, jnp.finfo(jnp.result_type(float)).eps ** (1 / 3) / jnp.where(size > 0, size, 1.0), 0.0)


def _difference_sensitivities(params, inputs, config: Config, jump_ts, step_ts, directions):
    """One member's sensitivity problem along ``directions`` = (parameter tangents, input tangents), each leaf
    with a leading axis p: (θ_s = (θ, θ moved by ±εd (2p, …), ±ε (2p,), 1/2ε (p,)), sizes |d|/|θ| (p,),
    S0 (p, n)), for :func:`_difference_callbacks`."""
    d_params, d_inputs = directions
    theta = _member(params, inputs, config, jump_ts, step_ts)[0]
    typical = (_typical(params), inputs)
    size = jax.vmap(lambda dp, di: _relative_size((params, inputs), (dp, di), typical))(d_params, d_inputs)  # (p,)
    step = _difference_step(size)
    signed = jnp.concatenate([step, -step])  # (2p,): central differences
    both = jax.tree_util.tree_map(lambda d: jnp.concatenate([d, d]), (d_params, d_inputs))
    moved = jax.vmap(lambda dp, di, e: _member(*_shifted((params, inputs), (dp, di), e), config, jump_ts,
                                               step_ts)[0])(*both, signed)
    quotient = jnp.where(step > 0, 0.5 / jnp.where(step > 0, step, 1.0), 0.0)
    if theta[2].newton is not None:  # Newton where the point or any shifted one needs it: one flag for all of them
        newton = theta[2].newton | jnp.any(moved[2].newton)
        theta = eqx.tree_at(lambda th: th[2].newton, theta, newton)
        moved = eqx.tree_at(lambda th: th[2].newton, moved, newton)
    theta_s = (theta, moved, signed, quotient)
    s0 = _central(quotient, jax.vmap(lambda p: initial_state(p, config))(moved[0]))
    return theta_s, size, s0


def _moved_axes(moved):
    """``vmap`` axes of the shifted members: 0, except for the Newton flag they share (None)."""
    axes = jax.tree_util.tree_map(lambda _: 0, moved)
    if moved[2].newton is not None:
        axes = eqx.tree_at(lambda th: th[2].newton, axes, None)
    return axes


def _central(quotient, values):
    """(values at θ + εd − values at θ − εd)/2ε: (2p, …) → (p, …)."""
    n_dir = quotient.shape[0]
    return (values[:n_dir] - values[n_dir:]) * quotient.reshape((-1,) + (1,) * (values.ndim - 1))


def _difference_callbacks(config: Config):
    """(tangent field, output tangents) over θ_s from :func:`_difference_sensitivities`: central difference
    quotients of the primal field and outputs along every direction, in one batched evaluation."""
    field, outputs, _ = _callbacks(config)

    def tangent_field(t, y, sens, th):
        theta, moved, signed, quotient = th
        shifted = jax.vmap(lambda s, e, m: field(t, y + e * s, m), in_axes=(0, 0, _moved_axes(moved)))(
            jnp.concatenate([sens, sens]), signed, moved)
        return field(t, y, theta), _central(quotient, shifted)

    def output_tangents(t, y, sens, th):
        _, moved, signed, quotient = th
        shifted = jax.vmap(lambda s, e, m: outputs(t, y + e * s, m), in_axes=(0, 0, _moved_axes(moved)))(
            jnp.concatenate([sens, sens]), signed, moved)
        return {k: _central(quotient, shifted[k]) for k in OUTPUTS}

    return tangent_field, output_tangents


def _forward_sensitivities(params, inputs, config: Config, jump_ts, step_ts, directions):
    """One member's sensitivity problem along ``directions`` = (parameter tangents, input tangents), each leaf
    with a leading axis p: (θ_s = (θ, dθ: the tangents of θ's floating-point leaves (p, …)), sizes |d|/|θ| (p,),
    S0 (p, n)), for :func:`_forward_callbacks`."""
    d_params, d_inputs = directions
    theta = _member(params, inputs, config, jump_ts, step_ts)[0]
    typical = (_typical(params), inputs)
    size = jax.vmap(lambda dp, di: _relative_size((params, inputs), (dp, di), typical))(d_params, d_inputs)  # (p,)
    if theta[2].newton is not None:  # Newton also where a small move along a direction needs it (an effect at 0)
        moved = jax.vmap(lambda dp, di, e: _member(*_shifted((params, inputs), (dp, di), e), config, jump_ts,
                                                   step_ts)[0][2].newton)(d_params, d_inputs, _difference_step(size))
        theta = eqx.tree_at(lambda th: th[2].newton, theta, theta[2].newton | jnp.any(moved))
    point, fixed = eqx.partition((params, inputs), eqx.is_inexact_array)
    d_point = eqx.filter((d_params, d_inputs), jax.tree_util.tree_map(eqx.is_inexact_array, (params, inputs)))

    def floating(x):  # θ's and the initial state's floating-point leaves at the floating-point leaves x
        p, i = eqx.combine(x, fixed)
        return eqx.filter(_member(p, i, config, jump_ts, step_ts)[0], eqx.is_inexact_array), initial_state(p, config)

    d_theta, s0 = jax.vmap(lambda d: jax.jvp(floating, (point,), (d,))[1])(d_point)
    return (theta, d_theta), size, s0


def _forward_callbacks(config: Config):
    """(tangent field, output tangents) over θ_s from :func:`_forward_sensitivities`: forward-mode derivatives of the
    primal field and outputs along every direction, the primal (and its inner Newton solve) evaluated once."""
    field, outputs, _ = _callbacks(config)

    def along(fn, t, y, sens, th):
        theta, d_theta = th
        x, fixed = eqx.partition(theta, eqx.is_inexact_array)

        def one(s, d):
            return jax.jvp(lambda y_, x_: fn(t, y_, eqx.combine(x_, fixed)), (y, x), (s, d))

        return jax.vmap(one, out_axes=(None, 0))(sens, d_theta)

    def tangent_field(t, y, sens, th):
        return along(field, t, y, sens, th)

    def output_tangents(t, y, sens, th):
        return along(outputs, t, y, sens, th)[1]

    return tangent_field, output_tangents


def _tangent_run(run, ts, saved, block, th, output_tangents):
    """Tangent :class:`Run` (outputs field → (p, T)) of one member from its state block on ts (T, 1 + p, n)."""
    d_values = jax.vmap(output_tangents, in_axes=(0, 0, 0, None), out_axes=1)(ts, saved, block[:, 1:], th)
    # A tangent solve that stopped early (step budget) has no sensitivities past its end: NaN, never frozen.
    reached = (ts <= run.t_final) | (run.status == 1)
    d_values = {k: jnp.where(reached, v, jnp.nan) for k, v in d_values.items()}
    return Run(d_values, run.y_final[1:], jnp.zeros(run.y_final.shape[0] - 1))


def _sensitivity_run(params, config: Config, y0, theta_s, size, s0, tangent_field, **kw):
    """The state and its sensitivities integrated together (:func:`growjax._rosenbrock.integrate`; ``kw``: breaks,
    jumps, batched), θ_s from :func:`_sensitivities`, with twice the step budget of a plain solve. With
    forward-mode tangents the state's Jacobian is taken in forward mode too: the field's ``jvp`` is compiled
    anyway, and under the Lockhart law each difference column would repeat the rod balance's Newton solve
    (one Jacobian in 3 parameters on the public experiment, small loops: 16 ms against 18 ms)."""
    rtol, atol = config.tolerances
    field, _, event = _callbacks(config)
    # The difference quotients carry roundoff of ~1e-10 relative: tighter sensitivity control only burns steps.
    s_rtol, s_atol = max(rtol, SENSITIVITY_TOL_FLOOR), max(atol, SENSITIVITY_TOL_FLOOR)
    return integrate(lambda t, y, th: field(t, y, th[0]), y0, config.t0, config.t1, args=theta_s,
                     tangent_field=tangent_field, s0=s0, s_rtol=s_rtol, s_atol=s_atol * jnp.maximum(size, 1e-12),
                     rtol=rtol, atol=atol, max_steps=2 * config.step_budget,
                     forward_jacobian=_forward_mode_tangents(params, config),
                     event=None if event is None else (lambda t, y, th: event(t, y, th[0])), **kw)


def _integrate_batch(params, inputs, config: Config, ts, jump_ts, step_ts, directions=None):
    """The solve of a batch (every argument with a leading axis B; ``directions`` leaves (B, p, …)) in one loop:
    (Run, tangent Run or None, status, steps), each with the leading axis B."""
    rtol, atol = config.tolerances
    field, outputs, event = _callbacks(config)
    theta, y0, breaks, jumps = jax.vmap(lambda p, i, j, s: _member(p, i, config, j, s))(params, inputs, jump_ts, step_ts)
    if y0.shape[0] >= SHARED_BATCH_MIN:
        theta = (*theta[:-1], dataclasses.replace(theta[-1], share_values=True))
    if directions is None:
        run = integrate(field, y0, config.t0, config.t1, args=theta, breaks=breaks, jumps=jumps, rtol=rtol, atol=atol,
                        max_steps=config.step_budget, event=event, batched=True, save_ts=ts)
        primal = jax.vmap(lambda r, t, y, th: _primal(r, t, y, th, outputs)[0])(run, ts, y0, theta)
        return primal, None, run.status, run.steps.count
    theta_s, size, s0 = jax.vmap(lambda p, i, j, s, d: _sensitivities(p, i, config, j, s, d))(
        params, inputs, jump_ts, step_ts, directions)
    tangent_field, output_tangents = _sensitivity_callbacks(params, config)
    run = _sensitivity_run(params, config, y0, theta_s, size, s0, tangent_field, breaks=breaks, jumps=jumps, batched=True)

    def member(r, t, y, th):
        primal, block, saved = _primal(r, t, y, th[0], outputs)
        return primal, _tangent_run(r, t, saved, block, th, output_tangents)

    primal, tangent = jax.vmap(member)(run, ts, y0, theta_s)
    return primal, tangent, run.status, run.steps.count


def _integrate(params, inputs, config: Config, ts, jump_ts, step_ts, directions=None):
    """(Run, tangent Run with a leading axis p or None, status, accepted steps).

    ``directions`` = (parameter tangents, input tangents), each leaf with a leading axis p: the
    sensitivities along them are integrated with the state, under its error control. Their field
    (``config.tangents``, :func:`_forward_mode_tangents`) is either the vector field's ``jax.jvp`` along
    each direction, the primal evaluated once, or its central difference quotient (as CVODES does by
    default), (f(y + εS, θ + εd) − f(y − εS, θ − εd))/2ε, with ε fixed per direction so that the
    parameters move by (machine ε)^⅓ of themselves, one batched evaluation of the primal field for
    all directions. (The two agree to the quotients' error, ~1e-5 relative, ``tests/test_growth_law.py``;
    the ``jvp`` batched over directions that XLA:CPU miscompiled when this solver was written is computed
    correctly now.)
    """
    rtol, atol = config.tolerances
    field, outputs, event = _callbacks(config)
    theta, y0, breaks, jumps = _member(params, inputs, config, jump_ts, step_ts)
    if directions is None:
        run = integrate(field, y0, config.t0, config.t1, args=theta, breaks=breaks, jumps=jumps, rtol=rtol, atol=atol,
                        max_steps=config.step_budget, event=event)
        primal = _primal(run, ts, y0, theta, outputs)[0]
        return primal, None, run.status, run.steps.count
    theta_s, size, s0 = _sensitivities(params, inputs, config, jump_ts, step_ts, directions)
    tangent_field, output_tangents = _sensitivity_callbacks(params, config)
    run = _sensitivity_run(params, config, y0, theta_s, size, s0, tangent_field, breaks=breaks, jumps=jumps)
    primal, block, saved = _primal(run, ts, y0, theta, outputs)
    return primal, _tangent_run(run, ts, saved, block, theta_s, output_tangents), run.status, run.steps.count


@functools.cache
def _plain_solver(config: Config):
    """``(params, inputs, ts, jump_ts, step_ts) → (Run, status, steps)``; under ``vmap`` the members are
    stepped together in one loop (:func:`_integrate_batch`) instead of a vmapped loop per member."""

    def plain(params, inputs, ts, jump_ts, step_ts):
        primal, _, status, n_steps = _integrate(params, inputs, config, ts, jump_ts, step_ts)
        return primal, status, n_steps

    solver = jax.custom_batching.custom_vmap(plain)

    @solver.def_vmap
    def together(axis_size, in_batched, *args):
        args = spread(args, in_batched, axis_size)
        primal, _, status, n_steps = _integrate_batch(*args[:2], config, *args[2:])
        out = (primal, status, n_steps)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return solver


def _tangent_solver(config: Config):
    """``(params, inputs, ts, jump_ts, step_ts, d_params, d_inputs) → (Run, tangent Run, status, steps)`` for
    directions with a leading axis p, batched over directions by merging them into one solve (``custom_vmap``)."""

    def plain(params, inputs, ts, jump_ts, step_ts, d_params, d_inputs):
        return _integrate(params, inputs, config, ts, jump_ts, step_ts, (d_params, d_inputs))

    solver = jax.custom_batching.custom_vmap(plain)

    @solver.def_vmap
    def merge_directions(axis_size, in_batched, params, inputs, ts, jump_ts, step_ts, d_params, d_inputs):
        args = (params, inputs, ts, jump_ts, step_ts, d_params, d_inputs)
        if any(jax.tree_util.tree_leaves(in_batched[:5])):  # the point itself is batched: members stepped together
            args = spread(args, in_batched, axis_size)
            out = _integrate_batch(*args[:2], config, *args[2:5], directions=args[5:])
            return out, jax.tree_util.tree_map(lambda _: True, out)

        def flat(x, batched):  # (axis_size, p, …) → (axis_size·p, …)
            x = x if batched else jnp.broadcast_to(x, (axis_size,) + jnp.shape(x))
            return x.reshape((axis_size * x.shape[1],) + x.shape[2:])

        dp = jax.tree_util.tree_map(flat, d_params, in_batched[5])
        di = jax.tree_util.tree_map(flat, d_inputs, in_batched[6])
        primal, tangent, status, n_steps = solver(params, inputs, ts, jump_ts, step_ts, dp, di)
        tangent = jax.tree_util.tree_map(lambda x: x.reshape((axis_size, -1) + x.shape[1:]), tangent)
        unbatched = jax.tree_util.tree_map(lambda _: False, (primal, status, n_steps))
        return (primal, tangent, status, n_steps), (unbatched[0], jax.tree_util.tree_map(lambda _: True, tangent),
                                                    unbatched[1], unbatched[2])

    return solver


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _run(params, inputs, config: Config, ts, jump_ts, step_ts):
    """(Run, status, accepted steps) of the fast configuration; derivatives by error-controlled forward sensitivities."""
    return _plain_solver(config)(params, inputs, ts, jump_ts, step_ts)


@_run.defjvp
def _run_jvp(config, primals, tangents):
    params, inputs, ts, jump_ts, step_ts = primals
    d_params, d_inputs = tangents[0], tangents[1]
    # The primal is a plain solve: under jax.linearize (optimistix, numpyro) it must not depend on the
    # tangents, whose error control moves the steps of the solve that carries them.
    primal, status, n_steps = _plain_solver(config)(params, inputs, ts, jump_ts, step_ts)

    def one(x):
        return jnp.asarray(x)[None]

    tangent = _tangent_solver(config)(params, inputs, ts, jump_ts, step_ts,
                                      jax.tree_util.tree_map(one, d_params), jax.tree_util.tree_map(one, d_inputs))[1]
    tangent = jax.tree_util.tree_map(lambda x: x[0], tangent)
    zero = np.zeros((), dtype=jax.dtypes.float0)
    return (primal, status, n_steps), (tangent, zero, zero)


def solve(params: Parameters, inputs, config: Config, ts, jump_ts, step_ts):
    """Integrate the fast configuration and return a :class:`growjax.trajectory.Trajectory` on ``ts``.

    Differentiable in ``params`` and ``inputs`` in forward mode (``jax.jvp``, ``jax.jacfwd``): the
    sensitivities are integrated with the state under the same error control
    (:func:`growjax._rosenbrock.integrate`), and a batch of directions is one solve. Reverse mode
    (``jax.grad``) is not supported by this configuration.
    """
    run, status, n_steps = _run(params, inputs, config, ts, jump_ts, step_ts)
    return _trajectory(params, inputs, config, ts, run, status, n_steps)


def solve_members(params: Parameters, inputs, config: Config, ts, jump_ts, step_ts):
    """:func:`solve` for a batch of parameter sets (every leaf of ``params`` with a leading axis B; inputs, ``ts``
    and breaks shared): a :class:`growjax.trajectory.Trajectory` with a leading axis B.

    The members are stepped together in one loop, as under ``jax.vmap(solve)``, but the one-member solve is
    never traced (``custom_vmap`` traces it to learn its output shapes: 0.46 s of the 500-set sweep's
    compile). Not differentiable: differentiate ``jax.vmap(solve)``.
    """
    return _members(params, inputs, config, ts, jump_ts, step_ts)


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _members(params, inputs, config: Config, ts, jump_ts, step_ts):
    """The batched solve of :func:`solve_members`; its derivative rule refuses (no error-controlled tangents here)."""
    size = jax.tree_util.tree_leaves(params)[0].shape[0]
    inputs_b, ts_b, jump_b, step_b = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (size,) + jnp.shape(x)),
                                                            (inputs, ts, jump_ts, step_ts))
    run, _, status, n_steps = _integrate_batch(params, inputs_b, config, ts_b, jump_b, step_b)
    return jax.vmap(_trajectory, in_axes=(0, None, None, None, 0, 0, 0))(params, inputs, config, ts, run, status, n_steps)


@_members.defjvp
def _members_jvp(config, primals, tangents):
    raise TypeError("fast_model.solve_members (simulate_members) is not differentiable: differentiate "
                    "jax.vmap(simulate) instead")


def _trajectory(params, inputs, config: Config, ts, run: Run, status, n_steps):
    """The :class:`growjax.trajectory.Trajectory` of a primal :class:`Run` on ``ts``."""
    demand = jax.vmap(inputs.pressure_demand)(ts)
    return finish(ts, run.outputs, pressure_limit(params.robot), demand, config.stop_at_pressure_limit,
                  t_final=run.t_final, status=status, n_steps=n_steps, final_state=run.final_state)


def solve_with_sensitivities(params: Parameters, inputs, config: Config, ts, jump_ts, step_ts, directions):
    """(:class:`growjax.trajectory.Trajectory` on ``ts``, tangent outputs {field: (p, T)}) from one solve that
    integrates the state with its sensitivities along ``directions`` = (parameter tangents, input tangents),
    each leaf with a leading axis p (:func:`_integrate`).

    Cheaper by one plain solve than ``jax.jvp`` through :func:`solve`, whose primal comes from a plain solve so
    that it never depends on the tangents (``jax.linearize`` needs that); here the primal is the sensitivity
    solve's own, whose steps the tangents' error control also sets (they differ within the tolerance). For
    fixed directions (a Jacobian), where that dependence is harmless. Tangents past a stop are NaN.
    """
    primal, tangent, status, n_steps = _integrate(params, inputs, config, ts, jump_ts, step_ts, directions)
    traj = _trajectory(params, inputs, config, ts, primal, status, n_steps)
    after = ts > primal.t_final + 1e-12
    return traj, {k: jnp.where(after, jnp.nan, v) for k, v in tangent.outputs.items()}
