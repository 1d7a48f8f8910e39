"""Quasi-static reduction of the forward drive, for batched sweeps and sampling.

The reference assembly (:mod:`growjax.model`) resolves time scales from 8 ns (platform
mass against the screw damping) to seconds. Over the seconds that matter for the
robot's length, the fast modes sit on their slow manifolds, so this reduction
(singular perturbation, same parameters, same component laws) keeps six states:

* the hoses, orifice, tank, nozzle and node P form one chamber at pressure P: the
  series drops between them are < 1 Pa at the robot's flows (PHYSICS.md §7), and
  they equalise in < 10 µs;
* the platform is massless: its velocity balances the drive force against the screw
  damping, the laminar hose drop and the syringes' end stop (closed form);
* the rod balance is solved by fixed-point passes for the reference growth law (its
  velocity term is ~1e-10 of the other forces, so the iteration contracts at once),
  and by a bracketed Newton solve for Lockhart's law, where it is not small.

States: P (Pa), platform travel x_p (m), hose wall strain δ (m), PID integral and
filter states, robot displacement ξ (m). The ODE is integrated on a fixed grid by the
two-stage Rosenbrock W-method ROS2 (order 2 for any Jacobian approximation), with the
stiff P–P entry of the Jacobian exact: the opened bypass couples P to the robot with
a rate near 1e5 s⁻¹. A fixed grid has no data-dependent loops, so ``vmap`` runs every
member in lockstep at full vector speed, and reverse-mode gradients are plain scans.

Agreement with the reference is measured, not assumed: ``tests/test_quasistatic.py``
and ``benchmarks/sweep.py`` report the length difference over the sweep box.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from growjax import hydraulics as hy
from growjax._smooth import unrolled_root
from growjax.fluid import bulk_modulus
from growjax.model import SimulationSettings, _crack_pressure, _extra_force
from growjax.motor import ideal_torque_drive_force, pid_output
from growjax.params import Parameters
from growjax.robot import LOCKHART_PRESSURE_SCALE, pressure_limit, robot_pressure
from growjax.signals import Inputs

STATES = ("pressure", "x_platform", "wall_strain", "z_integral", "z_filter", "robot_displacement")
SCALES = (1e5, 1e-3, 1e-7, 1e4, 1e5, 1e-3)
GAMMA = 1.0 + 1.0 / np.sqrt(2.0)  # ROS2 (Verwer et al. 1999)


@dataclasses.dataclass(frozen=True)
class QuasiStaticConfig(SimulationSettings):
    """Static settings of the quasi-static forward model (hashable).

    Attributes (besides :class:`growjax.model.SimulationSettings`; the pressure limit flags the run and
    NaNs the samples after the crossing, as in the reference):
        save_dt: output spacing, s (the reference's 10 ms grid).
        substeps: fixed solver steps per output interval (step = save_dt / substeps).
        rod_iterations: fixed-point passes of the rod balance (reference growth law).
        rod_iterations_lockhart: safeguarded Newton steps of the rod balance (Lockhart growth law).
    """

    save_dt: float = 0.01
    substeps: int = 10
    rod_iterations: int = 1
    rod_iterations_lockhart: int = 16
    drive: str = dataclasses.field(default="forward", init=False)

    def __post_init__(self):
        super().__post_init__()
        if self.substeps < 1 or self.save_dt <= 0:
            raise ValueError("substeps must be ≥ 1 and save_dt > 0")

    @property
    def n_saves(self) -> int:
        """Output intervals: every ``save_dt`` from t0, the last one ending at t1."""
        return max(1, math.ceil((self.t1 - self.t0) / self.save_dt - 1e-9))

    def save_grid(self) -> np.ndarray:
        """Output times, s: t0 + k·save_dt, then t1. Pulse edges on a multiple of ``save_dt / substeps`` from t0
        fall on step boundaries, so no step straddles a discontinuity of the demand."""
        return np.append(self.t0 + self.save_dt * np.arange(self.n_saves), self.t1)


def robot_flow(params: Parameters, config: QuasiStaticConfig, t, pressure, length, catheter):
    """Forward flow into the robot through the check valve (m³/s) and the robot pressure (Pa), from node pressure P.

    The rod balance is met by fixed-point passes on the velocity (published growth law) or
    by an unrolled Newton solve (Lockhart's law). Reverse flow (through the bypass) is not
    here: it is the equalisation of :func:`equalise`.
    """
    robot, cv = params.robot, params.check_valve
    widths = (config.velocity_eps, config.stop_width)

    def rod(v):
        extra = _extra_force(config, params, t, length, v, pressure)
        return robot_pressure(robot, pressure, v, length, catheter, extra, widths)

    def flow(p_r):
        dp = pressure - p_r
        return hy.check_valve_flow(cv, params.fluid, dp, pressure - 0.5 * dp, _crack_pressure(params), config.crack_width)

    if robot.growth_law == "reference":
        p_r = rod(0.0)
        for _ in range(config.rod_iterations):
            p_r = rod(flow(p_r) / robot.area)
        return flow(p_r), p_r

    # Lockhart: the growth term is of the order of the valve drop, so the fixed point does not
    # contract. Unknown: the excess x = p_r − p_0 over the rest pressure p_0 = p_r(v = 0), with
    # Q_cv(P − p_0 − x) = A_r φ_L (x/p_ref)^(n_L). Since Q_cv(P − p_0 − x) ≤ Q_cv(P − p_0), x ≤ x_hi :=
    # p_ref (Q_cv(P − p_0)/(A_r φ_L))^(1/n_L). Both sides are near power laws, so the residual is taken in
    # logs, ln Q_cv − ln(A_r φ_L) − n_L ln(x/p_ref), over u = ln(x/x_hi) ∈ [−40, 0]: nearly linear in u,
    # decreasing, well conditioned for any n_L. The rod's stop forces enter at v = 0 (ends of stroke only).
    p_0 = rod(0.0)
    phi, n_l = robot.lockhart_rate, robot.lockhart_exponent
    room = jnp.maximum(pressure - p_0, 0.0)
    tiny = 1e-30  # m³/s: floor of the valve flow inside the logarithm
    q_max = jnp.maximum(flow(p_0), tiny)  # floored before the power: finite tangents below cracking
    x_hi = jnp.maximum(jnp.minimum(room, LOCKHART_PRESSURE_SCALE * (q_max / (robot.area * phi)) ** (1.0 / n_l)), 1e-12)

    def residual(u):
        x = x_hi * jnp.exp(u)
        return jnp.log(flow(p_0 + x) + tiny) - jnp.log(robot.area * phi) - n_l * jnp.log(x / LOCKHART_PRESSURE_SCALE)

    u = unrolled_root(residual, jnp.asarray(-40.0), jnp.asarray(0.0), iterations=config.rod_iterations_lockhart)
    p_r = p_0 + x_hi * jnp.exp(u)
    return flow(p_r), p_r


def _static_robot_pressure(params, config, t, length, catheter, p_guess):
    """P* with P* = p_r(P*, v = 0): the node pressure at which the robot is in equilibrium (Pa)."""
    p = p_guess
    for _ in range(3):  # contraction factor 2π r_i μ_c L_c / A_r ≈ 0.02: error ~1e-5 Pa
        extra = _extra_force(config, params, t, length, 0.0, p)
        p = robot_pressure(params.robot, p, 0.0, length, catheter, extra, (config.velocity_eps, config.stop_width))
    return p


def charged_volume(params: Parameters, wall, p_from, p_to):
    """Liquid volume (m³) that raises the chamber from ``p_from`` to ``p_to`` (Pa): ∫ V/E(p) dp, 3-point Gauss–Legendre."""
    nodes, weights = np.polynomial.legendre.leggauss(3)
    mid, half = 0.5 * (p_to + p_from), 0.5 * (p_to - p_from)
    volume = _chamber_volume(params, wall)
    return half * sum(w * volume / bulk_modulus(params.fluid, mid + half * x) for x, w in zip(nodes, weights))


def equalise(params: Parameters, inputs: Inputs, config: QuasiStaticConfig, t, y):
    """Reverse flow as an instantaneous equalisation (unscaled state in, out).

    When the node pressure P falls below P*, the robot's pressure at rest, the opened
    bypass (conductance ~1e-7 m³/s/Pa against a chamber compliance ~1e-12 m³/Pa: a
    ~10 µs mode) drains the robot back until P = P*. The robot retracts by the volume
    that charges the chamber to P*, limited by its retract stop (zero length).
    """
    p, x_p, wall, z_i, z_d, xi = y
    robot = params.robot
    length = robot.initial_length + xi
    catheter = jnp.maximum(inputs.catheter_length(t), 0.0)
    p_star = _static_robot_pressure(params, config, t, length, catheter, p)
    below = p < p_star
    target = jnp.where(below, p_star, p)
    needed = charged_volume(params, wall, p, target)
    available = robot.area * jnp.maximum(length, 0.0)
    vol = jnp.minimum(needed, available)
    # If the stop limits the retraction, raise P by the volume available (local compliance).
    compliance = _chamber_volume(params, wall) / bulk_modulus(params.fluid, p)
    p_new = jnp.where(vol < needed, p + vol / compliance, target)
    return jnp.stack([p_new, x_p, wall, z_i, z_d, xi - vol / robot.area])


def platform_velocity(params: Parameters, u, pressure, x_platform):
    """Massless-platform velocity (m/s): drive n A_s u against screw damping, the hose drop and the syringe stop.

    Force balance n A_s u = b_p v + n A_s (P + 2 R_h A_s v) + K_p·pen·|v|, closed form: the
    hoses are laminar (Re < 300 at the robot's flows), the orifice and tank drops
    (< 1 Pa) are neglected, and the inelastic stop resists retraction beyond the full
    mark (x_p < 0) only.
    """
    pump = params.pump
    n, a_s = pump.n_syringes, pump.syringe_area
    r_hose = 2.0 * hy.pipeline_half_pressure_drop(params.tube, params.fluid, 1e-12) / 1e-12
    damping = pump.screw_damping + n * a_s * a_s * r_hose
    push = ideal_torque_drive_force(a_s, n, u) - n * a_s * pressure
    stop = n * pump.penetration_coefficient * jnp.maximum(-x_platform, 0.0)
    return jnp.where(push >= 0.0, push / damping, push / (damping + stop))


def _rates(t, y, params: Parameters, inputs: Inputs, config: QuasiStaticConfig):
    """Unscaled state derivatives (and diagnostics) at time t (s)."""
    p, x_p, wall, z_i, z_d, xi = y
    robot, tube, fl = params.robot, params.tube, params.fluid
    length = robot.initial_length + xi
    catheter = jnp.maximum(inputs.catheter_length(t), 0.0)
    u, dz_i, dz_d = pid_output(params.pid, inputs.pressure_demand(t) - p, z_i, z_d)
    v_p = platform_velocity(params, u, p, x_p)
    q_robot, p_r = robot_flow(params, config, t, p, length, catheter)

    n = params.pump.n_syringes
    e = bulk_modulus(fl, p)
    d = tube.hydraulic_diameter
    d_wall = (tube.diameter_compliance * p - wall) / tube.wall_time_constant
    wall_flow = n * jnp.pi * (d + wall) / 2.0 * tube.length * (1.0 + p / e) * d_wall
    volume = _chamber_volume(params, wall)
    q_pump = n * params.pump.syringe_area * v_p
    dp = (q_pump - q_robot - wall_flow) * e / volume
    rates = jnp.stack([dp, v_p, d_wall, dz_i, dz_d, q_robot / robot.area])
    return rates, (q_robot, p_r, x_p)


def _field(t, ys, params, inputs, config):
    scales = jnp.asarray(SCALES)
    return _rates(t, ys * scales, params, inputs, config)[0] / scales


def _chamber_volume(params: Parameters, wall):
    tube = params.tube
    n = params.pump.n_syringes
    return n * jnp.pi * (tube.hydraulic_diameter + wall) ** 2 / 4.0 * tube.length + params.tank.volume


def initial_state(params: Parameters, inputs: Inputs, config: QuasiStaticConfig) -> jax.Array:
    """Scaled initial state: one chamber at the volume-weighted initial pressure of the lines, equalised with the robot.

    The reference drains the robot back through the bypass in the first millisecond
    until P reaches the robot's pressure; :func:`equalise` does that at once.
    """
    tube, tank = params.tube, params.tank
    n = params.pump.n_syringes
    v_tube, v_tank = n * tube.volume, tank.volume
    p0 = (v_tube * tube.initial_pressure + v_tank * tank.initial_pressure) / (v_tube + v_tank)
    y = jnp.stack([jnp.asarray(v, float) for v in (p0, 0.0, tube.diameter_compliance * p0, 0.0, 0.0, 0.0)])
    return equalise(params, inputs, config, config.t0, y) / jnp.asarray(SCALES)


def _solve_unrolled(a, b):
    """x with a x = b for a small dense (d, d) matrix: Gaussian elimination, unrolled (vectorises under vmap).

    No pivoting: a = I − γ h J is dominated by its unit diagonal except along the stiff
    pressure and stop entries, whose diagonal then dominates.
    """
    d = b.shape[0]
    a = [[a[i, j] for j in range(d)] for i in range(d)]
    b = [b[i] for i in range(d)]
    for k in range(d):
        for i in range(k + 1, d):
            m = a[i][k] / a[k][k]
            for j in range(k + 1, d):
                a[i][j] = a[i][j] - m * a[k][j]
            b[i] = b[i] - m * b[k]
    x = [None] * d
    for i in reversed(range(d)):
        acc = b[i]
        for j in range(i + 1, d):
            acc = acc - a[i][j] * x[j]
        x[i] = acc / a[i][i]
    return jnp.stack(x)


def _ros2_step(t, ys, h, params, inputs, config):
    """One ROS2 step, W = I − γ h J with the exact Jacobian of the scaled field (L-stable, order 2).

    Reverse flow is handled by :func:`equalise` after the step.
    """
    inside = 1e-7 * h  # evaluate the inputs just inside the step, never across an edge at its ends
    def field(y):
        return _field(t + inside, y, params, inputs, config)

    f0, linear = jax.linearize(field, ys)
    jac = jax.vmap(linear, out_axes=1)(jnp.eye(ys.shape[0]))
    w = jnp.eye(ys.shape[0]) - GAMMA * h * jac
    k1 = _solve_unrolled(w, f0)
    f1 = _field(t + h - inside, ys + h * k1, params, inputs, config)
    k2 = _solve_unrolled(w, f1 - 2.0 * k1)
    scales = jnp.asarray(SCALES)
    y_new = (ys + h * (1.5 * k1 + 0.5 * k2)) * scales
    return equalise(params, inputs, config, t + h, y_new) / scales


def simulate(params: Parameters, inputs: Inputs, config: QuasiStaticConfig = QuasiStaticConfig()):
    """Simulate the quasi-static forward model → :class:`growjax.Trajectory` on ``config.save_grid()``.

    Pure, jit/vmap/grad-able (fixed grid, no data-dependent loops). Status: 0 ok,
    1 pressure limit crossed (samples after the crossing are NaN), 2 non-finite state.
    """
    from growjax.model import OK, PRESSURE_LIMIT, SOLVER_FAILED, Trajectory

    grid = config.save_grid()
    ts = jnp.asarray(grid)
    steps = jnp.asarray(np.diff(grid) / config.substeps)
    scales = jnp.asarray(SCALES)
    limit = pressure_limit(params.robot)

    def outputs(t, ys):
        y = ys * scales
        _, (q_robot, p_r, x_p) = _rates(t, y, params, inputs, config)
        return jnp.stack([params.robot.initial_length + y[5], y[0], q_robot, x_p, p_r])

    def interval(ys, span):
        t_start, t_end, h = span

        def sub(k, y):
            return _ros2_step(t_start + k * h, y, h, params, inputs, config)

        ys = jax.lax.fori_loop(0, config.substeps, sub, ys)
        return ys, (outputs(t_end, ys), ys)

    y0 = initial_state(params, inputs, config)
    _ys_final, (out, states) = jax.lax.scan(interval, y0, (ts[:-1], ts[1:], steps))
    out = jnp.concatenate([outputs(ts[0], y0)[None], out])
    states = jnp.concatenate([y0[None], states])
    finite = jnp.all(jnp.isfinite(out), axis=1)
    crossed = (out[:, 1] > limit) & bool(config.stop_at_pressure_limit)
    bad = ~finite | crossed
    first_bad = jnp.where(jnp.any(bad), jnp.argmax(bad), ts.shape[0])
    after = jnp.arange(ts.shape[0]) >= first_bad
    out = jnp.where(after[:, None], jnp.nan, out)
    failed = jnp.any(~finite)
    any_cross = jnp.any(crossed)
    status = jnp.where(
        any_cross & (jnp.argmax(crossed) <= jnp.where(failed, jnp.argmax(~finite), ts.shape[0])),
        PRESSURE_LIMIT,
        jnp.where(failed, SOLVER_FAILED, OK),
    )
    limit_time = jnp.where(any_cross, ts[jnp.argmax(crossed)], jnp.nan)
    last = jnp.clip(first_bad - 1, 0, ts.shape[0] - 1)
    demand = jax.vmap(inputs.pressure_demand)(ts)
    return Trajectory(
        time=ts,
        length=out[:, 0],
        pressure=out[:, 1],
        robot_flow=out[:, 2],
        syringe_displacement=out[:, 3],
        robot_pressure=out[:, 4],
        pressure_demand=demand,
        status=status,
        limit_time=limit_time,
        t_final=jnp.where(jnp.isfinite(limit_time), limit_time, ts[last]),
        n_steps=jnp.asarray(config.n_saves * config.substeps),
        final_state=states[last],
    )
