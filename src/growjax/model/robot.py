"""The growing element: force balance of the everting robot (paper eq. 7).

The robot is a massless single-acting cylinder of annular area A_r = π(r_o² − r_i²).
The Simulink force S_F (eq. 1) acts on its rod, so the rod balance A_r p_r + S_F − F_c = 0
gives the robot pressure p_r needed to move at velocity v:

    p_r = Y + F_AC/A_r − P·2π r_i μ_c L_c/A_r + p_g(v) + (F_c + F_hs + F_e)/A_r

with F_c the cylinder's end stops, F_hs the rod hard stop and F_e the forces of added
effects (`growjax.model.effects`), all opposing the motion. The catheter-friction term enters
with the sign that *assists* growth, as in the shipped model.

Two growth laws set the velocity term p_g(v) (``GrowingRobot.growth_law``):

* ``"reference"`` — the shipped diagram's sgn(v)|v/ext|^n (Pa). With the published ext it is
  ~1e-10 of the other forces, so ext and n cannot be identified.
* ``"lockhart"`` — Lockhart's law v = φ_L·((p_r − p_0)/p_ref)^(n_L) while the robot grows,
  with φ_L a velocity (m/s) at the reference excess p_ref = 1 kPa and p_0 the rest pressure.
  Its inverse p_g(v) = p_ref·(v/φ_L)^(1/n_L) for v > 0 (and 0 while it holds or retracts: the law
  describes irreversible extension of the membrane) gives the everting membrane a physically
  sized resistance in series with the check valve. A deviation added beside the reference,
  not in place of it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

import growjax.model.hydraulics as hy
from growjax.model.pump import cylinder_stop_force
from growjax.model.smooth import smooth_abs_power, smooth_ramp

__all__ = [
    "BRACKET_LOGIT",
    "GROWTH_LAWS",
    "INFLOW_BRACKET_TOL",
    "INFLOW_MAX_ITERATIONS",
    "INFLOW_NEWTON_TOL",
    "LOCKHART_PRESSURE_SCALE",
    "GrowingRobot",
    "RodBalance",
    "catheter_friction_gain",
    "growth_pressure",
    "hard_stop_force",
    "inflow",
    "lockhart_pressure",
    "pressure_limit",
    "rod_balance",
    "rod_pressure",
    "velocity_pressure",
]

GROWTH_LAWS = ("reference", "lockhart")
LOCKHART_PRESSURE_SCALE = 1e3  # Pa: p_ref of the Lockhart law
INFLOW_MAX_ITERATIONS = 40  # cap on the rod balance's Newton steps (a few usually suffice)
INFLOW_NEWTON_TOL = 1e-7  # stop once a Newton step moves the logit less: quadratic convergence leaves ~1e-14
INFLOW_BRACKET_TOL = 1e-12  # or once the bracket has shrunk to this (relative to max(1, |z|)): roundoff
BRACKET_LOGIT = 40.0  # the rod balance's root is sought in z ∈ (−40, 40), x/X ∈ (4e-18, 1 − 4e-18)


class GrowingRobot(eqx.Module):
    """Everting membrane robot.

    Attributes:
        yield_pressure: Y, Pa; growth needs the pressure to exceed it.
        extensibility: ext, the velocity-term divisor, (m/s)·Pa^(−1/n) in the paper's reading.
        growth_exponent: n (–).
        inner_radius: r_i, m.  outer_radius: r_o, m.
        membrane_thickness: t_m, m.  membrane_yield_stress: σ_y, Pa.
        safety_factor: on the membrane hoop-stress limit (–).
        catheter_friction: μ_c (–), friction coefficient between catheter and membrane.
        active_channel_force: F_AC, N, pull of the active channel (0 in the shipped model).
        stroke: maximum elongation from zero length, m.  initial_length: L(t0), m.
        hard_stop_bound: ±bound of the rod hard stop, m (never reached in normal use).
        hard_stop_stiffness: stiffness of the rod hard stop, N/m.
        hard_stop_damping: damping of the rod hard stop, N·s/m.
        penetration_coefficient: end-stop coefficient of the cylinder, N·s/m².
        growth_law: ``"reference"`` or ``"lockhart"`` (static; see the module docstring).
        lockhart_rate: φ_L, m/s: growth speed at 1 kPa above the rest pressure (Lockhart law only).
        lockhart_exponent: n_L (–), Lockhart law only.
    """

    yield_pressure: float = 7920.459191723583
    extensibility: float = 48232.296630787474
    growth_exponent: float = 0.9129087546820797
    inner_radius: float = 4.5e-4
    outer_radius: float = 1.5e-3
    membrane_thickness: float = 3.5e-5
    membrane_yield_stress: float = 4.0e7
    safety_factor: float = 5.0
    catheter_friction: float = 0.01
    active_channel_force: float = 0.0
    stroke: float = 0.08
    initial_length: float = 0.01
    hard_stop_bound: float = 0.08
    hard_stop_stiffness: float = 1e6
    hard_stop_damping: float = 150.0
    penetration_coefficient: float = 1e12
    lockhart_rate: float = 1.5e-4
    lockhart_exponent: float = 1.0
    growth_law: str = eqx.field(static=True, default="reference")

    def __check_init__(self):
        if self.growth_law not in GROWTH_LAWS:
            raise ValueError(f"growth_law must be one of {GROWTH_LAWS}, got {self.growth_law!r}")

    @property
    def area(self) -> Float[ArrayLike, ""]:
        """Annular piston area A_r, m²."""
        return jnp.pi * (self.outer_radius**2 - self.inner_radius**2)


def pressure_limit(robot: GrowingRobot) -> Float[ArrayLike, "*b"]:
    """Safe pressure of the membrane: 2 t_m σ_y / (r_o · safety factor) (paper eq. 8).

    Args:
        robot: the robot (its fields may carry a batch axis).

    Returns:
        The limit, Pa.
    """
    return 2.0 * robot.membrane_thickness * robot.membrane_yield_stress / (robot.outer_radius * robot.safety_factor)


def catheter_friction_gain(robot: GrowingRobot, catheter_length: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """The catheter's friction force per unit pressure P, per unit area: k = 2π r_i μ_c L_c / A_r.

    Args:
        robot: the robot.
        catheter_length: L_c, m.

    Returns:
        k (–).
    """
    return 2.0 * jnp.pi * robot.inner_radius * robot.catheter_friction * catheter_length / robot.area


class RodBalance(eqx.Module):
    """Constants of the rod balance of a `GrowingRobot`, computed once per solve (`rod_balance`).

    Attributes:
        area: A_r, m².
        rest: Y + F_AC/A_r, Pa.
        friction: 2π r_i μ_c / A_r, per m of catheter, 1/m.
        law_scale: 1/ext (reference) or 1/φ_L (Lockhart), s/m.
        law_exponent: n (reference) or 1/n_L (Lockhart).
        stop_per_area: K_p/A_r, the end stops' coefficient per area.
        extend_limit: stroke − L0, m of displacement.
        retract_limit: −L0, m.
        initial_length: L0, m.
        hard_bound: the rod hard stop's bound, m.
        hard_stiffness_per_area: Pa/m.
        hard_damping_per_area: Pa·s/m.
        velocity_eps: the growth law's regularisation, m/s.
        stop_width: the stops' transition band, m.
        growth_law: ``"reference"`` or ``"lockhart"``.
    """

    area: jax.Array  # A_r, m²
    rest: jax.Array  # Y + F_AC/A_r, Pa
    friction: jax.Array  # 2π r_i μ_c / A_r, per m of catheter (–/m)
    law_scale: jax.Array  # 1/ext (reference) or 1/φ_L (Lockhart), s/m
    law_exponent: jax.Array  # n (reference) or 1/n_L (Lockhart)
    stop_per_area: jax.Array  # K_pen/A_r, N·s/m² per m²
    extend_limit: jax.Array  # stroke − L0, m of displacement
    retract_limit: jax.Array  # −L0
    initial_length: jax.Array  # L0, m
    hard_bound: jax.Array  # m
    hard_stiffness_per_area: jax.Array  # Pa/m
    hard_damping_per_area: jax.Array  # Pa·s/m
    velocity_eps: float  # m/s
    stop_width: float  # m
    growth_law: str = eqx.field(static=True)


def rod_balance(robot: GrowingRobot, widths: tuple[float, float]) -> RodBalance:
    """The `RodBalance` of a robot.

    Args:
        robot: the robot.
        widths: (velocity_eps m/s, stop_width m) of the regularisations.

    Returns:
        The constants.
    """
    velocity_eps, stop_width = widths
    area = robot.area
    if robot.growth_law == "lockhart":
        scale, exponent = 1.0 / robot.lockhart_rate, 1.0 / robot.lockhart_exponent
    else:
        scale, exponent = 1.0 / robot.extensibility, robot.growth_exponent
    return RodBalance(
        area=area,
        rest=robot.yield_pressure + robot.active_channel_force / area,
        friction=2.0 * jnp.pi * robot.inner_radius * robot.catheter_friction / area,
        law_scale=scale,
        law_exponent=exponent,
        stop_per_area=robot.penetration_coefficient / area,
        extend_limit=robot.stroke - robot.initial_length,
        retract_limit=-robot.initial_length,
        initial_length=robot.initial_length,
        hard_bound=robot.hard_stop_bound,
        hard_stiffness_per_area=robot.hard_stop_stiffness / area,
        hard_damping_per_area=robot.hard_stop_damping / area,
        velocity_eps=velocity_eps,
        stop_width=stop_width,
        growth_law=robot.growth_law,
    )


def growth_pressure(rod: RodBalance, velocity: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Growth-law term p_g(v) of the rod balance, regularised at v = 0 over ``rod.velocity_eps``.

    Reference: sgn(v)|v/ext|^n (eq. 1). Lockhart: p_ref (v/φ_L)^(1/n_L) for v > 0, 0 otherwise
    (the inverse of v = φ_L((p_r − p_0)/p_ref)^(n_L)).

    Args:
        rod: the rod balance's constants.
        velocity: v, m/s.

    Returns:
        ψ(v), Pa.
    """
    eps = rod.velocity_eps
    if rod.growth_law == "lockhart":
        return lockhart_pressure(velocity, rod.law_scale, rod.law_exponent, eps)
    return smooth_abs_power(velocity * rod.law_scale, rod.law_exponent, eps * rod.law_scale)


def lockhart_pressure(
    velocity: Float[ArrayLike, "*b"],
    inverse_speed: Float[ArrayLike, "*b"],
    exponent: Float[ArrayLike, "*b"],
    eps: float,
) -> Float[Array, "*b"]:
    """Excess pressure of Lockhart's law to grow at a velocity: p_ref·(κ·v)^m for v > 0, 0 otherwise (p_ref = 1 kPa),
    the inverse of v = ((p − p₀)/p_ref)^(1/m)/κ.

    Args:
        velocity: v, m/s.
        inverse_speed: κ, s/m.
        exponent: m.
        eps: the band over which the ramp of v and the power are regularised (C¹ at v = 0), m/s.

    Returns:
        The excess pressure, Pa.
    """
    growth = smooth_ramp(velocity, eps) * inverse_speed
    return LOCKHART_PRESSURE_SCALE * smooth_abs_power(growth, exponent, eps * inverse_speed)


def velocity_pressure(robot: GrowingRobot, velocity: Float[ArrayLike, "*b"], velocity_eps: float) -> Float[Array, "*b"]:
    """p_g(v) of a robot's growth law (`growth_pressure`).

    Args:
        robot: the robot.
        velocity: v, m/s.
        velocity_eps: the regularisation at v = 0, m/s.

    Returns:
        p_g(v), Pa.
    """
    return growth_pressure(rod_balance(robot, (velocity_eps, 1e-6)), velocity)


def hard_stop_force(
    robot: GrowingRobot, length: Float[ArrayLike, "*b"], velocity: Float[ArrayLike, "*b"], width: float
) -> Float[Array, "*b"]:
    """Rod hard-stop force, opposing motion beyond ±bound (the reference's 'smooth' model).

    Args:
        robot: the robot.
        length: its length, m.
        velocity: its velocity, m/s.
        width: the stop's transition band, m.

    Returns:
        The force, N.
    """
    rod = rod_balance(robot, (1e-6, width))
    return rod.area * _hard_stop_pressure(rod, length, velocity)


def _hard_stop_pressure(rod: RodBalance, length, velocity):
    width = rod.stop_width
    x = length - rod.initial_length
    pen_up = smooth_ramp(x - rod.hard_bound, width)
    pen_lo = smooth_ramp(-rod.hard_bound - x, width)
    gate = jnp.clip(pen_up / width, 0.0, 1.0) + jnp.clip(pen_lo / width, 0.0, 1.0)
    return rod.hard_stiffness_per_area * (pen_up - pen_lo) + rod.hard_damping_per_area * velocity * gate


def rod_pressure(
    rod: RodBalance,
    sensor_pressure: Float[ArrayLike, "*b"],
    velocity: Float[ArrayLike, "*b"],
    length: Float[ArrayLike, "*b"],
    catheter_length: Float[ArrayLike, "*b"],
    force: Float[ArrayLike, "*b"],
) -> Float[Array, "*b"]:
    """Robot chamber pressure p_r satisfying the massless rod balance at a velocity.

    Args:
        rod: the rod balance's constants.
        sensor_pressure: P, the sensed pressure, Pa (the catheter's friction grows with it).
        velocity: v, m/s.
        length: the robot's length, m.
        catheter_length: L_c, m.
        force: the sum of the added effects' forces opposing growth, N.

    Returns:
        p_r, Pa.
    """
    displacement = length - rod.initial_length
    stops = rod.stop_per_area * (
        cylinder_stop_force(1.0, displacement, velocity, rod.extend_limit, rod.retract_limit, rod.stop_width)
    ) + _hard_stop_pressure(rod, length, velocity)
    rest = rod.rest - rod.friction * catheter_length * sensor_pressure
    return rest + growth_pressure(rod, velocity) + stops + force / rod.area


def inflow(
    rod: RodBalance,
    valves: hy.ValveNetwork,
    pressure: Float[ArrayLike, "*b"],
    length: Float[ArrayLike, "*b"],
    catheter_length: Float[ArrayLike, "*b"],
    effect_force: Callable[[Float[Array, "*b"]], Float[Array, "*b"]],
    iterations: int = INFLOW_MAX_ITERATIONS,
    newton: Bool[ArrayLike, ""] | None = None,
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    """Flow into the robot and its pressure, from the node pressure before the valves.

    Solves the series balance of the valve network (check valve ∥ bypass,
    `growjax.model.hydraulics.valve_network_flow`) and the rod: q = Q_valves(P − p_r), p_r = rod_pressure(v = q/A_r).
    With p_rest the rod pressure at rest and s = sign(P − p_rest) the direction of motion, the unknown is the
    pressure the motion adds, x = s·(p_r − p_rest) ∈ (0, X), X = |P − p_rest|:

        f(x) = ln(s·(p_r(v(P − p_rest − s·x)) − p_rest)) − ln x = 0,    decreasing in x.

    In z = ln(x/(X − x)) both ends of f are asymptotically linear (power laws of the growth law at x → 0, of the
    valve at x → X). Safeguarded Newton steps from z = 0, each capped at ±8, bisect the bracket the evaluations
    have found where a step would leave it, and stop once a Newton step moves z < 1e-7 (quadratic convergence
    leaves ~1e-14 after it) or the bracket has shrunk to roundoff: the root for every growth law and effect force,
    converged to roundoff (the sensitivities' difference quotients amplify any residual of it). A residual of
    exactly 0 ends the search there, and a step past an end of the bracket no evaluation has moved tries that end
    first. Derivatives are implicit.

    Args:
        rod: the rod balance's constants.
        valves: the valve network's constants.
        pressure: P, the node pressure before the valves, Pa.
        length: the robot's length, m.
        catheter_length: the catheter's length inside the robot, m.
        effect_force: the effects' force opposing growth (N) at velocity v (m/s); non-decreasing in v.
        iterations: the most Newton steps; 0 takes one fixed-point pass instead, exact when the motion's pressure
            is negligible against the valve's (the published law: x ~ 1e-5 Pa).
        newton: where given, the Newton solve runs only where it is True and the one pass where False
            (``lax.cond``: the pass alone is paid when every velocity-dependent force is absent).

    Returns:
        (q, the flow into the robot, m³/s; p_r, the robot's pressure, Pa).
    """
    if iterations > 0 and newton is not None:
        return jax.lax.cond(
            newton,
            lambda: inflow(rod, valves, pressure, length, catheter_length, effect_force, iterations),
            lambda: inflow(rod, valves, pressure, length, catheter_length, effect_force, 0),
        )
    p_robot = functools.partial(_robot_pressure_at, rod, pressure, length, catheter_length, effect_force)
    valves_at = functools.partial(_valve_flow, valves, pressure)
    p_rest = p_robot(jnp.zeros_like(pressure))
    delta0 = pressure - p_rest
    if iterations == 0:
        delta = delta0 - (p_robot(valves_at(delta0) / rod.area) - p_rest)
        return valves_at(delta), pressure - delta

    s = jnp.where(delta0 >= 0.0, 1.0, -1.0)
    span = jnp.maximum(jnp.abs(delta0), 1e-12)
    excess = functools.partial(_excess, p_robot, valves_at, rod.area, p_rest, delta0, s)
    residual = functools.partial(_log_residual, excess, span)
    solve = functools.partial(_bracketed_newton, iterations=iterations)
    z = jax.lax.stop_gradient(jax.lax.custom_root(residual, jnp.zeros_like(delta0), solve, _no_tangent))
    x = _implicit_root(excess, span, z)
    delta = delta0 - s * x
    return valves_at(delta), pressure - delta


_LOG_FLOOR = 1e-30  # Pa: floor inside the logarithms of the rod balance's residual


def _robot_pressure_at(rod, pressure, length, catheter_length, effect_force, v):
    return rod_pressure(rod, pressure, v, length, catheter_length, effect_force(v))


def _valve_flow(valves, pressure, delta):
    """The valves' flow (m³/s) at a drop ``delta`` (Pa) across them below ``pressure``."""
    return hy.valve_network_flow(valves, delta, pressure - 0.5 * delta)


def _excess(p_robot, valves_at, area, p_rest, delta0, s, x):
    """The pressure the motion adds (Pa) when ``x`` of the drop is spent on it."""
    return s * (p_robot(valves_at(delta0 - s * x) / area) - p_rest)


def _log_residual(excess, span, z):
    """f of the rod balance in the logit z of x/X."""
    x = span * jax.nn.sigmoid(z)
    return jnp.log(jnp.maximum(excess(x), 0.0) + _LOG_FLOOR) - jnp.log(x + _LOG_FLOOR)


def _newton_step(f, carry):
    """One safeguarded Newton step on the decreasing ``f`` inside the bracket [lo, hi] every evaluation narrows;
    a step that leaves the bracket bisects it instead, so steep stretches (a friction force turning over
    FRICTION_VELOCITY) cannot throw the iterate off."""
    z, lo, hi, _, k = carry
    fz, dfz = jax.jvp(f, (z,), (jnp.ones_like(z),))
    lo, hi = jnp.where(fz > 0.0, z, lo), jnp.where(fz > 0.0, hi, z)
    step = z - jnp.clip(fz / jnp.where(dfz < 0.0, dfz, -1.0), -8.0, 8.0)
    inside = (step > lo) & (step < hi) & jnp.isfinite(step)
    # A step past an end of the bracket that no evaluation has moved goes to that end: where the root lies
    # beyond it (f keeps its sign there; a motion's pressure below 4e-18 of the span) that end is the answer.
    low_edge, high_edge = (step <= lo) & (lo <= -BRACKET_LOGIT), (step >= hi) & (hi >= BRACKET_LOGIT)
    z_new = jnp.where(
        inside, step, jnp.where(low_edge, -BRACKET_LOGIT, jnp.where(high_edge, BRACKET_LOGIT, 0.5 * (lo + hi)))
    )
    exact = fz == 0.0  # the root itself (its bracket end would otherwise be bisected away)
    beyond = ((z <= -BRACKET_LOGIT) & (fz < 0.0)) | ((z >= BRACKET_LOGIT) & (fz > 0.0))
    z_new = jnp.where(exact | beyond, z, z_new)
    converged = (inside & (jnp.abs(z_new - z) <= INFLOW_NEWTON_TOL)) | exact | beyond
    collapsed = hi - lo <= INFLOW_BRACKET_TOL * jnp.maximum(1.0, jnp.abs(z_new))
    return z_new, lo, hi, jnp.all(converged | collapsed), k + 1


def _bracketed_newton(f, z, iterations: int):
    """The root of the decreasing ``f`` in (−BRACKET_LOGIT, BRACKET_LOGIT) from ``z``, in at most ``iterations``
    safeguarded Newton steps."""

    def moving(carry):
        return ~carry[3] & (carry[4] < iterations)

    bound = jnp.full_like(z, BRACKET_LOGIT)
    start = (z, -bound, bound, jnp.asarray(False), 0)
    return jax.lax.while_loop(moving, functools.partial(_newton_step, f), start)[0]


def _no_tangent(g, y):  # the root's derivative is taken below, not through the logit
    return jnp.zeros_like(y)


def _implicit_root(excess, span, z):
    """x at the root z, carrying its derivatives by the implicit function theorem on g(x) = excess(x) − x, whose
    slope is ≤ −1 (never singular, unlike the log–logit form's where the sigmoid saturates): one Newton step in x
    from the root, its slope held constant, carries dx/dθ = −(∂g/∂θ)/g′ and leaves the value at the root."""
    x_root = jax.lax.stop_gradient(span * jax.nn.sigmoid(z))
    g_root, slope = jax.jvp(lambda x: excess(x) - x, (x_root,), (jnp.ones_like(x_root),))
    return x_root - (g_root - jax.lax.stop_gradient(g_root)) / jax.lax.stop_gradient(jnp.minimum(slope, -1.0))
