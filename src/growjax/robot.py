"""The growing element: force balance of the everting robot (paper eq. 7; PHYSICS.md eq. 1, §3.7).

The robot is a massless single-acting cylinder of annular area A_r = π(r_o² − r_i²).
The Simulink force S_F (eq. 1) acts on its rod, so the rod balance A_r p_r + S_F − F_c = 0
gives the robot pressure p_r needed to move at velocity v:

    p_r = Y + F_AC/A_r − P·2π r_i μ_c L_c/A_r + sgn(v)|v/ext|^n + (F_c + F_hs − F_extra)/A_r

Note the catheter-friction term enters with the sign that *assists* growth, as in the
shipped model (PHYSICS.md §8.4). ``extra_force`` is where candidate effects plug in.

Two growth laws set the velocity term (``GrowingRobot.growth_law``):

* ``"reference"`` — the shipped diagram's sgn(v)|v/ext|^n (Pa). With the published ext it is
  ~1e-10 of the other forces (PHYSICS.md §9), so ext and n cannot be identified.
* ``"lockhart"`` — Lockhart's law v = φ_L·((p_r − p_0)/p_ref)^(n_L) above yield, with φ_L a
  velocity (m/s) at the reference excess p_ref = 1 kPa; p_0 is the rest pressure above
  (Y and the other rod forces). Its inverse, p_ref·sgn(v)|v/φ_L|^(1/n_L), replaces the
  velocity term, so the everting membrane adds a physically sized resistance in series
  with the check valve and φ_L, n_L shape the growth rate. This is a deviation from the
  reference added beside it, not in place of it (PHYSICS.md: "add better-posed variants").
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from growjax._smooth import smooth_abs_power, smooth_ramp
from growjax.pump import cylinder_stop_force

GROWTH_LAWS = ("reference", "lockhart")
LOCKHART_PRESSURE_SCALE = 1e3  # Pa: p_ref of the Lockhart law


class GrowingRobot(eqx.Module):
    """Everting membrane robot.

    Attributes:
        yield_pressure: Y, Pa; growth needs the pressure to exceed it.
        extensibility: ext (φ), the velocity-term divisor, (m/s)·Pa^(−1/n) in the paper's reading.
        growth_exponent: n (–).
        inner_radius: r_i, m.  outer_radius: r_o, m.
        membrane_thickness: t, m.  membrane_yield_stress: σ_y, Pa.
        safety_factor: on the membrane hoop-stress limit (–).
        catheter_friction: μ_c (–), friction coefficient between catheter and membrane.
        active_channel_force: F_AC, N, pull of the active channel (0 in the shipped model).
        stroke: maximum elongation from zero length, m.  initial_length: L(t0), m.
        hard_stop_bound: ±bound of the rod hard stop, m (never reached in normal use).
        hard_stop_stiffness: N/m.  hard_stop_damping: N·s/m.
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
    def area(self):
        """Annular piston area A_r, m²."""
        return jnp.pi * (self.outer_radius**2 - self.inner_radius**2)


def pressure_limit(robot: GrowingRobot):
    """Safe pressure of the membrane, Pa: 2 t σ_y / (r_o · safety factor) (paper eq. 8)."""
    return 2.0 * robot.membrane_thickness * robot.membrane_yield_stress / (robot.outer_radius * robot.safety_factor)


def catheter_friction_gain(robot: GrowingRobot, catheter_length):
    """k = 2π r_i μ_c L_c / A_r (–): the friction force per unit pressure P, per unit area."""
    return 2.0 * jnp.pi * robot.inner_radius * robot.catheter_friction * catheter_length / robot.area


def velocity_pressure(robot: GrowingRobot, velocity, velocity_eps):
    """Velocity term of the rod balance, Pa (regularised at v = 0 over ``velocity_eps`` m/s).

    Reference: sgn(v)|v/ext|^n (eq. 1). Lockhart: p_ref·sgn(v)|v/φ_L|^(1/n_L), the inverse of
    v = φ_L((p_r − p_0)/p_ref)^(n_L).
    """
    if robot.growth_law == "lockhart":
        phi = robot.lockhart_rate
        return LOCKHART_PRESSURE_SCALE * smooth_abs_power(velocity / phi, 1.0 / robot.lockhart_exponent, velocity_eps / phi)
    return smooth_abs_power(velocity / robot.extensibility, robot.growth_exponent, velocity_eps / robot.extensibility)


def hard_stop_force(robot: GrowingRobot, length, velocity, width):
    """Rod hard-stop force (N, opposing motion beyond ±bound; reference 'smooth' model over ``width`` m)."""
    x = length - robot.initial_length
    pen_up = smooth_ramp(x - robot.hard_stop_bound, width)
    pen_lo = smooth_ramp(-robot.hard_stop_bound - x, width)
    k, d = robot.hard_stop_stiffness, robot.hard_stop_damping
    gate_up = jnp.clip(pen_up / width, 0.0, 1.0)
    gate_lo = jnp.clip(pen_lo / width, 0.0, 1.0)
    return k * (pen_up - pen_lo) + d * velocity * (gate_up + gate_lo)


def robot_pressure(robot: GrowingRobot, sensor_pressure, velocity, length, catheter_length, extra_force, widths):
    """Robot chamber pressure p_r (Pa) satisfying the massless rod balance at velocity ``velocity`` (m/s).

    ``widths`` = (velocity_eps m/s, stop_width m). ``extra_force`` (N) pushes the rod outward.
    """
    velocity_eps, stop_width = widths
    displacement = length - robot.initial_length
    stop = cylinder_stop_force(
        robot.penetration_coefficient,
        displacement,
        velocity,
        robot.stroke - robot.initial_length,
        -robot.initial_length,
        stop_width,
    )
    static = (
        robot.yield_pressure
        + robot.active_channel_force / robot.area
        - catheter_friction_gain(robot, catheter_length) * sensor_pressure
    )
    dynamic = velocity_pressure(robot, velocity, velocity_eps) + (
        stop + hard_stop_force(robot, length, velocity, stop_width) - extra_force
    ) / robot.area
    return static + dynamic
