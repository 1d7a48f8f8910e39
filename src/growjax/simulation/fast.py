"""The fast configuration: the same components with the lines lumped, solved by an L-stable Rosenbrock method.

Three reductions of the reference assembly (`growjax.simulation.reference`), each of a mode far
faster than anything the robot's length shows:

* the hoses, orifice, tank and node P form one chamber: their series drops equalise in
  < 15 µs; the pump sees the series drop of the lines at its flow
  (`growjax.model.hydraulics.line_pressure_drop`), and the sensor reads the chamber;
* the forward drive's platform is massless (its mode is 8 ns): its velocity balances the drive
  against the screws, the line drop and the syringes' end stop, in closed form
  (`growjax.model.pump.platform_velocity`); the lines' drop is taken at its laminar slope;
* the state of the chamber is the liquid volume it stores, not its pressure. The pressure
  follows from the exact stored-volume law of the liquid–air mixture
  (`growjax.model.fluid.pressure_at_stored_fraction`), so the volume balance is a linear
  invariant of the ODE, which a Rosenbrock method keeps to rounding error through every
  pulse edge.

Everything else, the rod and valve balance (`growjax.model.robot.inflow`), the motor, the
PID and every added effect (`growjax.model.effects`), is the same code as the reference's.
The remaining stiffness (the opened bypass, ~1e5 s⁻¹; the stepper rotor, ~3e5 s⁻¹) is
damped by the L-stable ROS34PW2 method (`growjax.simulation.rosenbrock`) with the exact Jacobian,
at steps set by the slow dynamics, with input edges declared to the step-size controller.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

import growjax.model.effects as fx
import growjax.model.hydraulics as hy
import growjax.simulation._assembly as assembly
from growjax.model.fluid import (
    StorageLaw,
    pressure_at_stored_fraction,
    storage_law,
    stored_volume_fraction,
)
from growjax.model.hydraulics import ValveNetwork
from growjax.model.params import Parameters
from growjax.model.pump import platform_velocity
from growjax.model.robot import INFLOW_MAX_ITERATIONS, RodBalance, inflow
from growjax.simulation.config import Config

__all__ = [
    "FORWARD_SCALES",
    "FORWARD_STATES",
    "INVERSE_SCALES",
    "INVERSE_STATES",
    "SHARED_BATCH_MIN",
    "Prepared",
    "initial_state",
    "layout",
    "line_pressure",
    "line_resistance",
    "lines_volume",
    "prepare",
    "pressure_of",
    "rod_solve",
    "stored_volume",
]

FORWARD_STATES = ("stored_volume", "x_platform", "robot_displacement", "wall_strain", "z_integral", "z_filter")
FORWARD_SCALES = (1e-6, 1e-2, 1e-4, 1e-6, 1e6, 1e7)  # error control weights the length 100x more than the pressure loop
INVERSE_STATES = (
    "stored_volume",
    "rotor_angle",
    "rotor_speed",
    "current_a",
    "current_b",
    "robot_displacement",
    "wall_strain",
)
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
    share_values: bool = eqx.field(static=True, default=False)  # set for large batches: `_computed_once`


def prepare(params: Parameters, config: Config) -> Prepared:
    """The `Prepared` constants of ``params`` under ``config``."""
    valves, rod = assembly.valves_and_rod(params, config)
    # The published law's velocity term is ~1e-10 of the rod forces: one fixed-point pass is exact, also while
    # every velocity-dependent effect is at zero (decided at run time: a superset model's candidates switched off,
    # where the Newton solve would triple the cost of every field evaluation).
    velocity_effects = [e for e in params.effects if e.velocity_dependent]
    iterations = 0 if rod_solve(params) == "one pass" else INFLOW_MAX_ITERATIONS
    newton = None
    if rod_solve(params) == "newton where present":
        newton = jnp.any(jnp.stack([e.present() for e in velocity_effects]))
    return Prepared(storage_law(params.fluid), valves, rod, line_resistance(params), newton, iterations)


def rod_solve(params: Parameters) -> str:
    """How the rod balance is solved in every field evaluation, decided statically: ``"one pass"`` (the published
    law, no velocity-dependent effect), ``"newton"`` (the Lockhart law) or ``"newton where present"`` (the
    published law with velocity-dependent effects: Newton at run time only where one of them is nonzero)."""
    velocity_effects = any(e.velocity_dependent for e in params.effects)
    if params.robot.growth_law != "reference":
        return "newton"
    return "newton where present" if velocity_effects else "one pass"


# -- the lumped chamber ----------------------------------------------------------------------------------


def lines_volume(params: Parameters, wall_strain: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Volume of the lumped chamber, m³: the hoses at wall strain δ (``wall_strain``, m) and the tank."""
    return hy.strained_volume(params.tube, wall_strain, params.pump.n_syringes) + params.tank.volume


def stored_volume(
    params: Parameters, pressure: Float[ArrayLike, "*b"], wall_strain: Float[ArrayLike, "*b"]
) -> Float[Array, "*b"]:
    """Liquid volume in the lumped chamber beyond its unstrained volume at gauge 0, m³, at gauge ``pressure`` (Pa)
    and wall strain ``wall_strain`` (m)."""
    volume = lines_volume(params, wall_strain)
    return volume * (1.0 + stored_volume_fraction(params.fluid, pressure)) - lines_volume(params, 0.0)


def line_pressure(
    params: Parameters,
    stored: Float[ArrayLike, "*b"],
    wall_strain: Float[ArrayLike, "*b"],
    storage: StorageLaw | None = None,
) -> Float[Array, "*b"]:
    """Gauge pressure of the lumped chamber, Pa, the inverse of `stored_volume`.

    Args:
        params: the parameters.
        stored: the liquid volume stored, m³.
        wall_strain: the hoses' wall strain, m.
        storage: the fluid's storage law (default: computed from ``params.fluid``).

    Returns:
        The gauge pressure, Pa.
    """
    volume = lines_volume(params, wall_strain)
    law = storage if storage is not None else storage_law(params.fluid)
    return pressure_at_stored_fraction(law, (stored + lines_volume(params, 0.0)) / volume - 1.0)


def initial_state(params: Parameters, config: Config) -> jax.Array:
    """Scaled state at t0: syringes full, robot at its initial length, hoses and tank at their initial pressures."""
    tube, tank = params.tube, params.tank
    n = params.pump.n_syringes
    wall0 = tube.diameter_compliance * tube.initial_pressure
    hose = hy.strained_volume(tube, wall0)
    stored = n * (hose * (1.0 + stored_volume_fraction(params.fluid, tube.initial_pressure)) - tube.volume)
    stored = stored + tank.volume * stored_volume_fraction(params.fluid, tank.initial_pressure)
    zero = jnp.zeros_like(stored)
    if config.drive == "forward":
        base = [stored, zero, zero, zero + wall0, zero, zero]
    else:
        base = [stored, zero, zero, zero, zero, zero, zero + wall0]
    return assembly.scaled_initial_state(params, config.drive, base, layout(params, config.drive)[1])


# -- the vector field -----------------------------------------------------------------------------------


def _robot_side(params, inputs, prep, t, pressure, displacement, effect_states):
    """Flow into the robot, its pressure and length at chamber pressure ``pressure``."""
    length = assembly.robot_length(params, displacement, effect_states)
    catheter = assembly.catheter_length(inputs, t)
    force = assembly.effect_force(params, effect_states, prep.rod, t, pressure, length, catheter)
    q, p_r = inflow(prep.rod, prep.valves, pressure, length, catheter, force, prep.inflow_iterations, prep.newton)
    return q, p_r, length


def line_resistance(params: Parameters) -> Float[Array, ""]:
    """Resistance of the lines from the syringes to the chamber, Pa·s/m³: the slope of
    `growjax.model.hydraulics.line_pressure_drop` at zero flow and gauge 0. The drop it gives,
    n² A_s² R ≈ 35 N·s/m against the screws' 1.2e5 N·s/m, changes the platform speed by < 3e-4,
    so its turbulent part and its pressure dependence are left out of the fast configuration."""

    def drop(q):
        return hy.line_pressure_drop(
            params.tube, params.orifice, params.tank, params.fluid, q, params.pump.n_syringes, jnp.zeros_like(q)
        )

    zero = jnp.zeros_like(jnp.asarray(params.tank.area, float))
    return jax.jvp(drop, (zero,), (jnp.ones_like(zero),))[1]


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
    commanded, drive, dz_i, dz_d = assembly.pid_drive(params, inputs, t, pressure, z_i, z_d, e)
    v_p = platform_velocity(pump, drive, pressure, prep.line_resistance, x_p, config.stop_width)
    q_r, p_r, length = _robot_side(params, inputs, prep, t, pressure, xi, e)
    if prep.share_values:
        q_r, p_r, v_p = _computed_once(q_r, p_r, v_p)
    leak = fx.chamber_outflow(params.effects, e, t, pressure)
    area = prep.rod.area
    base = [
        pump.n_syringes * pump.syringe_area * v_p - q_r - leak,
        v_p,
        q_r / area,
        hy.wall_strain_rate(params.tube, pressure, wall),
        dz_i,
        dz_d,
    ]
    rates = assembly.state_rates(
        params,
        e,
        base,
        t=t,
        pressure=pressure,
        robot_pressure=p_r,
        robot_flow=q_r,
        area=area,
        length=length,
        drive=commanded,
    )
    return rates, (length, pressure, q_r, x_p, p_r)


def _inverse_rates(t, y, params, inputs, config, prep):
    """Unscaled rates and the instant's outputs of the inverse (stepper) drive (its driver: ``params.motor``)."""
    stored, angle, omega, i_a, i_b, xi, wall = y[:7]
    e = y[7:]
    pump = params.pump
    x_p, v_p = assembly.platform_of_rotor(pump, angle, omega)
    pressure = line_pressure(params, stored, wall, prep.storage)
    syringe_pressure = pressure + prep.line_resistance * pump.n_syringes * pump.syringe_area * v_p
    torque, d_omega, di_a, di_b = assembly.stepper(
        params, inputs, t, angle, omega, i_a, i_b, syringe_pressure, e, config.stop_width
    )
    q_r, p_r, length = _robot_side(params, inputs, prep, t, pressure, xi, e)
    if prep.share_values:
        q_r, p_r, d_omega = _computed_once(q_r, p_r, d_omega)
    leak = fx.chamber_outflow(params.effects, e, t, pressure)
    area = prep.rod.area
    base = [
        pump.n_syringes * pump.syringe_area * v_p - q_r - leak,
        omega,
        d_omega,
        di_a,
        di_b,
        q_r / area,
        hy.wall_strain_rate(params.tube, pressure, wall),
    ]
    rates = assembly.state_rates(
        params,
        e,
        base,
        t=t,
        pressure=pressure,
        robot_pressure=p_r,
        robot_flow=q_r,
        area=area,
        length=length,
        drive=torque,
    )
    return rates, (length, pressure, q_r, x_p, p_r)


# The scaled field diffrax integrates: ``vector_field(t, ys, (params, inputs, config, prep))``.
rates, vector_field = assembly.vector_fields(_forward_rates, _inverse_rates, lambda p, d: layout(p, d))


def pressure_of(
    params: Parameters, config: Config, ys: Float[Array, " n"], storage: StorageLaw | None = None
) -> Float[Array, ""]:
    """Chamber pressure (Pa) of a scaled state ``ys`` (n,) (the layout of ``config.drive``); ``storage`` as in
    `line_pressure`."""
    scales = layout(params, config.drive)[1]
    wall_index = 3 if config.drive == "forward" else 6
    return line_pressure(params, ys[0] * scales[0], ys[wall_index] * scales[wall_index], storage)
