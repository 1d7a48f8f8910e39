"""Assembly of the drive chain into one ODE and the pure function :func:`simulate`.

Topology (PHYSICS.md §1): drive → lead screws → platform → 2 syringes → 2 hoses →
junction → orifice → tank → nozzle → node P (sensor) → check valve ∥ 3-way bypass →
robot. Node pressures between resistances are algebraic; they are eliminated in
:func:`network` by two scalar root solves (tube–orifice–tank series flow, and the
massless robot rod coupled to the valve network). States are scaled to O(1).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from growjax import hydraulics as hy
from growjax._smooth import bracketed_root
from growjax.motor import (
    ideal_torque_drive_force,
    motor_derivatives,
    motor_equilibrium_offset,
    pid_output,
    winding_voltages,
)
from growjax.params import DRIVES, Parameters
from growjax.pump import platform_force, syringe_load_force
from growjax.robot import pressure_limit, robot_pressure
from growjax.signals import Inputs

# Status codes of a trajectory.
OK, PRESSURE_LIMIT, SOLVER_FAILED = 0, 1, 2
STATUS_NAMES = {OK: "ok", PRESSURE_LIMIT: "pressure_limit", SOLVER_FAILED: "solver_failed"}

# State layout and scales (state / scale is O(1)): forward drive, then inverse drive.
FORWARD_STATES = ("x_platform", "v_platform", "p_tube", "wall_strain", "p_tank", "robot_displacement", "z_integral", "z_filter")
FORWARD_SCALES = (1e-3, 1e-3, 1e5, 1e-7, 1e5, 1e-3, 1e4, 1e5)
INVERSE_STATES = ("rotor_angle", "rotor_speed", "current_a", "current_b", "p_tube", "wall_strain", "p_tank", "robot_displacement")
INVERSE_SCALES = (1e-2, 1.0, 1.0, 1.0, 1e5, 1e-7, 1e5, 1e-3)


@dataclasses.dataclass(frozen=True, kw_only=True)
class SimulationSettings:
    """Settings shared by every assembly of the model (keyword-only; hashable).

    Attributes:
        t0, t1: integration window, s (the shipped model starts at 0.001 s).
        stop_at_pressure_limit: stop and flag a run when the sensed pressure crosses the membrane limit.
        velocity_eps: regularisation of |v|^n at v = 0, m/s.
        stop_width: C¹ band of end stops, m (and m/s for their velocity gate).
        crack_width: C¹ band of the check-valve opening, Pa.
        switch_width: band over which the bypass opens as the valve pressure drop turns negative, Pa.
        extra_rod_forces: callables ``(t, length, velocity, sensor_pressure, params) -> N`` pushing the rod
            outward; the plug-in point for candidate effects (must not increase with velocity).
    """

    t0: float = 0.001
    t1: float = 10.0
    stop_at_pressure_limit: bool = True
    velocity_eps: float = 1e-6
    stop_width: float = 1e-6
    crack_width: float = 50.0
    switch_width: float = 10.0
    extra_rod_forces: tuple[Callable, ...] = ()

    def __post_init__(self):
        if not self.t1 > self.t0:
            raise ValueError(f"t1 ({self.t1} s) must be after t0 ({self.t0} s)")


@dataclasses.dataclass(frozen=True)
class Config(SimulationSettings):
    """Static settings of the reference simulation (hashable: it is a static argument of ``jit``).

    Attributes (besides :class:`SimulationSettings`):
        drive: ``"forward"`` (pressure demand, PID, ideal torque) or ``"inverse"`` (desired length, stepper).
        rtol, atol: step-size control on the scaled states.
        max_steps: solver step budget.
        flow_width: band of the nozzle's loss-coefficient switch, m³/s.
        adjoint: ``"reverse"`` (checkpointed, for ``jax.grad``) or ``"forward"`` (for ``jax.jvp``/``jacfwd``).
    """

    drive: str = "forward"
    rtol: float = 1e-6
    atol: float = 1e-6
    max_steps: int = 200_000
    flow_width: float = 1e-10
    adjoint: str = "reverse"

    def __post_init__(self):
        if self.drive not in DRIVES:
            raise ValueError(f"drive must be one of {DRIVES}, got {self.drive!r}")
        super().__post_init__()


class Network(NamedTuple):
    """Algebraic quantities of the hydraulic network at one instant (SI units)."""

    syringe_pressure: jax.Array  # Pa, at each syringe outlet
    syringe_flow: jax.Array  # m³/s out of each syringe
    series_flow: jax.Array  # m³/s from the hoses through the orifice into the tank
    robot_flow: jax.Array  # m³/s into the robot
    sensor_pressure: jax.Array  # Pa, node P before the check valve
    robot_pressure: jax.Array  # Pa, inside the robot
    robot_velocity: jax.Array  # m/s


def _crack_pressure(params: Parameters):
    cv = params.check_valve
    return params.robot.yield_pressure if cv.crack_pressure is None else cv.crack_pressure


def _extra_force(config: Config, params, t, length, velocity, sensor_pressure):
    total = 0.0
    for force in config.extra_rod_forces:
        total = total + force(t, length, velocity, sensor_pressure, params)
    return total


def network(params: Parameters, inputs: Inputs, config: Config, t, v_platform, p_tube, p_tank, displacement) -> Network:
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

    dp_or = bracketed_root(series_residual, jnp.minimum(dp_chambers, 0.0), jnp.maximum(dp_chambers, 0.0))
    q_series = hy.orifice_flow(k_or, dp_or, p_cr_or)

    # Tank → nozzle → node P → valves → robot, with the rod balance: unknown is Δ = P − p_robot.
    length = robot.initial_length + displacement
    catheter = jnp.maximum(inputs.catheter_length(t), 0.0)
    widths = (config.velocity_eps, config.stop_width)
    crack = _crack_pressure(params)

    def branch(delta):
        q = hy.valve_network_flow(
            params.check_valve, params.valve, fl, delta, p_tank - 0.5 * delta, crack, config.crack_width, config.switch_width
        )
        p_nozzle_b = p_tank - hy.pipeline_half_pressure_drop(params.tank, fl, q)
        sensor = p_nozzle_b + hy.nozzle_pressure_drop(params.nozzle, fl, -q, p_nozzle_b, config.flow_width)
        v = q / robot.area
        extra = _extra_force(config, params, t, length, v, sensor)
        p_r = robot_pressure(robot, sensor, v, length, catheter, extra, widths)
        return q, sensor, p_r, v

    def branch_residual(delta):
        _, sensor, p_r, _ = branch(delta)
        return sensor - p_r - delta

    extra0 = _extra_force(config, params, t, length, 0.0, p_tank)
    delta0 = p_tank - robot_pressure(robot, p_tank, 0.0, length, catheter, extra0, widths)
    delta = bracketed_root(branch_residual, jnp.minimum(delta0, 0.0), jnp.maximum(delta0, 0.0))
    q_robot, sensor, p_r, v = branch(delta)
    return Network(p_syringe, q_syringe, q_series, q_robot, sensor, p_r, v)


def _chambers(params, net, p_tube, wall_strain, p_tank):
    n = params.pump.n_syringes
    dp_tube, d_wall = hy.chamber_pressure_rate(params.tube, params.fluid, p_tube, wall_strain, net.syringe_flow - net.series_flow / n)
    dp_tank, _ = hy.chamber_pressure_rate(params.tank, params.fluid, p_tank, 0.0, net.series_flow - net.robot_flow)
    return dp_tube, d_wall, dp_tank


def _unscale(y, scales):
    return y * jnp.asarray(scales)


def _forward_field(t, y, args):
    params, inputs, config = args
    x_p, v_p, p_tube, wall, p_tank, xi, z_i, z_d = _unscale(y, FORWARD_SCALES)
    net = network(params, inputs, config, t, v_p, p_tube, p_tank, xi)
    u, dz_i, dz_d = pid_output(params.pid, inputs.pressure_demand(t) - net.sensor_pressure, z_i, z_d)
    pump = params.pump
    drive = ideal_torque_drive_force(pump.syringe_area, pump.n_syringes, u)
    accel = platform_force(pump, drive, net.syringe_pressure, x_p, v_p, config.stop_width) / pump.platform_mass
    dp_tube, d_wall, dp_tank = _chambers(params, net, p_tube, wall, p_tank)
    rates = jnp.stack([v_p, accel, dp_tube, d_wall, dp_tank, net.robot_flow / params.robot.area, dz_i, dz_d])
    return rates / jnp.asarray(FORWARD_SCALES)


def _inverse_field(t, y, args):
    params, inputs, config = args
    angle, omega, i_a, i_b, p_tube, wall, p_tank, xi = _unscale(y, INVERSE_SCALES)
    pump, motor = params.pump, params.motor
    ratio = pump.screw_ratio
    x_p, v_p = angle / ratio, omega / ratio
    net = network(params, inputs, config, t, v_p, p_tube, p_tank, xi)
    v_a, v_b = winding_voltages(motor, inputs.steps(t))
    torque, di_a, di_b = motor_derivatives(motor, angle + motor_equilibrium_offset(motor), omega, i_a, i_b, v_a, v_b)
    # Each motor drives one screw and one syringe; the platform mass is shared between the screws.
    load = -syringe_load_force(pump, net.syringe_pressure, x_p, v_p, config.stop_width) / (pump.n_syringes * ratio)
    inertia = motor.rotor_inertia + pump.platform_mass / (pump.n_syringes * ratio**2)
    damping = motor.rotor_damping + pump.screw_viscous_friction
    d_omega = (torque - damping * omega - load) / inertia
    dp_tube, d_wall, dp_tank = _chambers(params, net, p_tube, wall, p_tank)
    rates = jnp.stack([omega, d_omega, di_a, di_b, dp_tube, d_wall, dp_tank, net.robot_flow / params.robot.area])
    return rates / jnp.asarray(INVERSE_SCALES)


def initial_state(params: Parameters, config: Config):
    """Scaled initial state: syringes full on their stop, robot at its initial length, lines at their initial pressures."""
    tube, tank = params.tube, params.tank
    wall0 = tube.diameter_compliance * tube.initial_pressure
    if config.drive == "forward":
        y = [0.0, 0.0, tube.initial_pressure, wall0, tank.initial_pressure, 0.0, 0.0, 0.0]
        scales = FORWARD_SCALES
    else:
        y = [0.0, 0.0, 0.0, 0.0, tube.initial_pressure, wall0, tank.initial_pressure, 0.0]
        scales = INVERSE_SCALES
    return jnp.stack([jnp.asarray(v, float) for v in y]) / jnp.asarray(scales)


class Trajectory(eqx.Module):
    """Simulated outputs on the save grid (arrays of shape (T,), NaN after a stop) and run status.

    Attributes:
        time: s.  length: robot length, m.  pressure: sensed pressure P before the check valve, Pa.
        robot_flow: m³/s into the robot.  syringe_displacement: platform travel, m.
        robot_pressure: Pa inside the robot.  pressure_demand: Pa (forward drive).
        status: 0 ok, 1 pressure limit crossed (run stopped there), 2 solver failure.
        limit_time: s at which the pressure limit was crossed (NaN if never).
        t_final: s where the integration ended.  n_steps: accepted solver steps.
        final_state: scaled state at ``t_final``.
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


def _outputs(t, y, args):
    params, inputs, config = args
    if config.drive == "forward":
        x_p, v_p, p_tube, _, p_tank, xi, _, _ = _unscale(y, FORWARD_SCALES)
    else:
        angle, omega, _, _, p_tube, _, p_tank, xi = _unscale(y, INVERSE_SCALES)
        x_p, v_p = angle / params.pump.screw_ratio, omega / params.pump.screw_ratio
    net = network(params, inputs, config, t, v_p, p_tube, p_tank, xi)
    return {
        "length": params.robot.initial_length + xi,
        "pressure": net.sensor_pressure,
        "robot_flow": net.robot_flow,
        "syringe_displacement": x_p,
        "robot_pressure": net.robot_pressure,
        "state": y,
    }


def _save_grid(config: Config, save_dt: float = 0.01) -> np.ndarray:
    n = round((config.t1 - config.t0) / save_dt)
    return np.linspace(config.t0, config.t1, n + 1)


def _solve(params, inputs, config: Config, ts, jump_ts):
    field = _forward_field if config.drive == "forward" else _inverse_field
    args = (params, inputs, config)
    limit = pressure_limit(params.robot)
    event = None
    if config.stop_at_pressure_limit:

        def crossed(t, y, args, **kwargs):
            return _outputs(t, y, args)["pressure"] - limit

        event = diffrax.Event(crossed, root_finder=optx.Newton(rtol=1e-8, atol=1e-8))
    controller = diffrax.PIDController(rtol=config.rtol, atol=config.atol, pcoeff=0.3, icoeff=0.4, dtmax=0.05)
    if jump_ts is not None:
        controller = diffrax.ClipStepSizeController(controller, jump_ts=jnp.asarray(jump_ts))
    adjoint = diffrax.ForwardMode() if config.adjoint == "forward" else diffrax.RecursiveCheckpointAdjoint()
    saveat = diffrax.SaveAt(
        subs=[diffrax.SubSaveAt(ts=ts, fn=_outputs), diffrax.SubSaveAt(t1=True, fn=lambda t, y, a: t)]
    )
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Kvaerno5(),
        config.t0,
        config.t1,
        1e-7,
        initial_state(params, config),
        args=args,
        saveat=saveat,
        stepsize_controller=controller,
        adjoint=adjoint,
        event=event,
        max_steps=config.max_steps,
        throw=False,
    )
    out, t_end = sol.ys
    t_final = t_end[0]
    stopped = sol.result == diffrax.RESULTS.event_occurred
    failed = ~((sol.result == diffrax.RESULTS.successful) | stopped)
    after = ts > t_final + 1e-12
    clean = {k: jnp.where(after if v.ndim == 1 else after[:, None], jnp.nan, v) for k, v in out.items()}
    crossed_grid = clean["pressure"] > limit
    first_cross = ts[jnp.argmax(crossed_grid)]
    limit_time = jnp.where(stopped, t_final, jnp.where(jnp.any(crossed_grid), first_cross, jnp.nan))
    status = jnp.where(failed, SOLVER_FAILED, jnp.where(jnp.isfinite(limit_time), PRESSURE_LIMIT, OK))
    last = jnp.clip(jnp.sum(~after) - 1, 0, ts.shape[0] - 1)
    demand = jax.vmap(inputs.pressure_demand)(ts)
    return Trajectory(
        time=ts,
        length=clean["length"],
        pressure=clean["pressure"],
        robot_flow=clean["robot_flow"],
        syringe_displacement=clean["syringe_displacement"],
        robot_pressure=clean["robot_pressure"],
        pressure_demand=demand,
        status=status,
        limit_time=limit_time,
        t_final=t_final,
        n_steps=sol.stats["num_accepted_steps"],
        final_state=clean["state"][last],
    )


_solve_jit = eqx.filter_jit(_solve)


def simulate(params: Parameters, inputs: Inputs, config: Config = Config(), ts=None, jump_ts=None) -> Trajectory:
    """Simulate the robot: (parameters, inputs, configuration) → :class:`Trajectory`.

    Pure and usable under ``jax.jit``, ``jax.vmap`` and ``jax.grad`` (with respect to
    any leaf of ``params``). ``ts`` (s, sorted, within [t0, t1]) is the save grid,
    default every 10 ms. Input discontinuities (pulse edges, motor steps) are found
    from ``inputs`` when they are concrete, or can be given as ``jump_ts``.
    A failed solve is reported in ``status``, never raised.

    With a :class:`growjax.quasistatic.QuasiStaticConfig` the reduced forward model runs
    instead (fixed grid ``config.save_grid()``; ``ts`` and ``jump_ts`` are not used).
    """
    from growjax import quasistatic

    if isinstance(config, quasistatic.QuasiStaticConfig):
        if ts is not None:
            raise ValueError("the quasi-static model saves on config.save_grid(); do not pass ts")
        return quasistatic.simulate(params, inputs, config)
    if ts is None:
        ts = _save_grid(config)
    if jump_ts is None:
        try:
            jump_ts = inputs.jump_times(config.t0, config.t1)
        except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
            jump_ts = None
    return _solve_jit(params, inputs, config, jnp.asarray(ts, float), _pad_jumps(jump_ts, config.t1))


def _pad_jumps(jump_ts, t1, block: int = 32):
    """Jump times padded (beyond t1, never reached) to a multiple of ``block``, so inputs with a
    similar number of edges share one compiled solver."""
    if jump_ts is None:
        return None
    jump_ts = np.asarray(jump_ts, float)
    size = block * max(1, -(-jump_ts.size // block))
    return np.concatenate([jump_ts, np.full(size - jump_ts.size, t1 + 1.0)])


def status_name(code) -> str:
    """Human-readable status of a trajectory."""
    return STATUS_NAMES.get(int(code), f"unknown({int(code)})")
