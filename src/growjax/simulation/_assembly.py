"""What both assemblies share: the state layout, the scaled field, and every law between the network and the
state rates that does not depend on how the hydraulic network is resolved.

An assembly (`growjax.simulation.fast`, `growjax.simulation.reference`) owns only its network's states and its
solver; the drive (PID and ideal torque, or the stepper), the robot's length, the effects' view of the rod and
of the instant, the constants of the valve and rod laws and the masking of failed states are written here once.
All quantities SI.
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

import growjax.model.effects as fx
from growjax.model.effects import Instant, Rod
from growjax.model.hydraulics import ValveNetwork, valve_network
from growjax.model.motor import (
    ideal_torque_drive_force,
    motor_derivatives,
    motor_equilibrium_offset,
    pid_output,
    winding_voltages,
)
from growjax.model.params import Parameters
from growjax.model.pump import SyringePump, syringe_load_force
from growjax.model.robot import RodBalance, rod_balance
from growjax.model.signals import Inputs
from growjax.simulation.config import Config

OUTPUTS = ("length", "pressure", "robot_flow", "syringe_displacement", "robot_pressure")


def layout(params: Parameters, drive: str, forward: tuple, inverse: tuple) -> tuple[tuple, tuple]:
    """(state names, scales) for ``drive``: the assembly's base ``(names, scales)`` pair, effect states last."""
    names, scales = forward if drive == "forward" else inverse
    extra = tuple(f"{e.name}.{s}" for e in params.effects for s in e.state_names)
    return names + extra, scales + fx.state_scales(params.effects, drive)


def vector_fields(forward_rates: Callable, inverse_rates: Callable, layout_of: Callable) -> tuple[Callable, Callable]:
    """(rates, vector_field) of an assembly from its per-drive rate functions.

    ``rates(t, y, params, inputs, config, prep)`` → (unscaled rates, outputs) for ``config.drive``;
    ``vector_field(t, ys, args)`` is the scaled field diffrax integrates, ``args`` = (params, inputs, config, prep).
    """

    traced = {"forward": eqx.filter_jit(forward_rates), "inverse": eqx.filter_jit(inverse_rates)}

    def rates(t, y, params, inputs, config, prep):
        return traced[config.drive](t, y, params, inputs, config, prep)

    def vector_field(t, ys, args):
        params, inputs, config, prep = args
        scales = jnp.asarray(layout_of(params, config.drive)[1])
        return rates(t, ys * scales, params, inputs, config, prep)[0] / scales

    return rates, vector_field


def scaled_initial_state(
    params: Parameters, drive: str, base: list, scales: Float[ArrayLike, " n"]
) -> Float[Array, " n"]:
    """The scaled state at t0 from the assembly's base states (SI) and the effects' own; ``scales`` (n,)."""
    y = jnp.concatenate([jnp.stack(base), fx.initial_states(params.effects, params, drive)])
    return y / jnp.asarray(scales)


# -- constants of the hot laws ---------------------------------------------------------------------------


def valves_and_rod(params: Parameters, config: Config) -> tuple[ValveNetwork, RodBalance]:
    """The constants of the valve network and of the rod balance under ``config``'s regularisation widths; the
    check valve cracks at the robot's yield pressure unless it has a cracking pressure of its own."""
    robot = params.robot
    crack = robot.yield_pressure if params.check_valve.crack_pressure is None else params.check_valve.crack_pressure
    valves = valve_network(
        params.check_valve, params.valve, params.fluid, crack, config.crack_width, config.switch_width
    )
    return valves, rod_balance(robot, (config.velocity_eps, config.stop_width))


# -- the robot as the effects see it ----------------------------------------------------------------------


def robot_length(
    params: Parameters, displacement: Float[ArrayLike, ""], effect_states: Float[Array, " K"]
) -> Float[Array, ""]:
    """Robot length (m): initial length plus the displacement the volume makes, less the effects' offset."""
    return params.robot.initial_length + displacement - fx.length_offset(params.effects, effect_states)


def catheter_length(inputs: Inputs, t: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """Catheter length in contact at ``t`` (m), never negative."""
    return jnp.maximum(inputs.catheter_length(t), 0.0)


def effect_force(
    params: Parameters,
    effect_states: Float[Array, " K"],
    rod: RodBalance,
    t: Float[ArrayLike, ""],
    pressure: Float[ArrayLike, ""],
    length: Float[ArrayLike, ""],
    catheter: Float[ArrayLike, ""],
) -> Callable[[Float[ArrayLike, ""]], Float[Array, ""]]:
    """``v → F`` (N): the effects' force opposing growth at robot velocity v (m/s), sensed pressure ``pressure``."""

    def force(velocity):
        view = Rod(
            t=t,
            pressure=pressure,
            velocity=velocity,
            length=length,
            catheter_length=catheter,
            inner_radius=params.robot.inner_radius,
            area=rod.area,
        )
        return fx.rod_force(params.effects, effect_states, view)

    return force


def state_rates(
    params: Parameters,
    effect_states: Float[Array, " K"],
    base: list,
    *,
    t: Float[ArrayLike, ""],
    pressure: Float[ArrayLike, ""],
    robot_pressure: Float[ArrayLike, ""],
    robot_flow: Float[ArrayLike, ""],
    area: Float[ArrayLike, ""],
    length: Float[ArrayLike, ""],
    drive: Float[ArrayLike, ""],
) -> Float[Array, " n"]:
    """The unscaled rates: the assembly's ``base`` rates, then the effects' states' at this instant (SI)."""
    instant = Instant(
        t=t,
        pressure=pressure,
        robot_pressure=robot_pressure,
        robot_flow=robot_flow,
        velocity=robot_flow / area,
        length=length,
        drive=drive,
    )
    return jnp.concatenate([jnp.stack(base), fx.rates(params.effects, effect_states, instant)])


# -- the drives ---------------------------------------------------------------------------------------------


def pid_drive(
    params: Parameters,
    inputs: Inputs,
    t: Float[ArrayLike, ""],
    sensed: Float[ArrayLike, ""],
    z_integral: Float[ArrayLike, ""],
    z_filter: Float[ArrayLike, ""],
    effect_states: Float[Array, " K"],
) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
    """The forward drive: PID on the sensed pressure (Pa) → (commanded force N, applied force N, ż_I, ż_D)."""
    pump = params.pump
    u, dz_i, dz_d = pid_output(params.pid, inputs.pressure_demand(t) - sensed, z_integral, z_filter)
    commanded = ideal_torque_drive_force(pump.syringe_area, pump.n_syringes, u)
    return commanded, fx.applied_drive(params.effects, effect_states, commanded), dz_i, dz_d


def platform_of_rotor(
    pump: SyringePump, angle: Float[ArrayLike, ""], omega: Float[ArrayLike, ""]
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """(platform displacement m, velocity m/s) of the stepper's rotor angle (rad) and speed (rad/s)."""
    return angle / pump.screw_ratio, omega / pump.screw_ratio


def stepper(
    params: Parameters,
    inputs: Inputs,
    t: Float[ArrayLike, ""],
    angle: Float[ArrayLike, ""],
    omega: Float[ArrayLike, ""],
    i_a: Float[ArrayLike, ""],
    i_b: Float[ArrayLike, ""],
    syringe_pressure: Float[ArrayLike, ""],
    effect_states: Float[Array, " K"],
    stop_width: float,
) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
    """The inverse drive: the stepper turning a screw per syringe → (torque N·m, dω/dt, di_A/dt, di_B/dt).

    ``syringe_pressure`` (Pa) at the syringe outlets; each motor drives one screw and one syringe, the
    platform's mass is shared between the screws.
    """
    pump, motor = params.pump, params.motor
    ratio = pump.screw_ratio
    x_p, v_p = platform_of_rotor(pump, angle, omega)
    v_a, v_b = winding_voltages(motor, inputs.steps(t))
    torque, di_a, di_b = motor_derivatives(motor, angle + motor_equilibrium_offset(motor), omega, i_a, i_b, v_a, v_b)
    applied = fx.applied_drive(params.effects, effect_states, torque)
    load = -syringe_load_force(pump, syringe_pressure, x_p, v_p, stop_width) / (pump.n_syringes * ratio)
    inertia = motor.rotor_inertia + pump.platform_mass / (pump.n_syringes * ratio**2)
    damping = motor.rotor_damping + pump.screw_viscous_friction
    return torque, (applied - damping * omega - load) / inertia, di_a, di_b


# -- outputs of a solve ---------------------------------------------------------------------------------------


def outputs_where_finite(
    outputs: Callable,
    ts: Float[Array, " T"],
    states: Float[Array, "T n"],
    fallback: Float[Array, " n"],
) -> tuple[dict[str, Float[Array, " T"]], Float[Array, "T n"]]:
    """(``{output: (T,)}``, the states evaluated (T, n)) of ``outputs(t, y) → dict`` at the saved states (T, n); a
    state that is not finite (a failed run) is evaluated at ``fallback`` (n,) instead and its outputs are NaN."""
    finite = jnp.all(jnp.isfinite(states), axis=1)
    safe = jnp.where(finite[:, None], states, fallback)
    nan = jnp.where(finite, 0.0, jnp.nan)
    values = jax.vmap(outputs)(ts, safe)
    return {k: v + nan for k, v in values.items()}, safe
