"""Syringe pump: two syringes on one platform driven by two lead screws.

The platform position x_p (m) is positive when it pushes the plungers in; each
syringe then delivers q = A_s ẋ_p into its hose. The syringes start on their
full-volume end stop (x_p = 0).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from growjax.model.smooth import smooth_ramp

__all__ = [
    "SyringePump",
    "cylinder_stop_force",
    "platform_force",
    "platform_velocity",
    "syringe_load_force",
    "syringe_stop_force",
    "syringe_volume_delivered",
]


class SyringePump(eqx.Module):
    """Syringe pump.

    Attributes:
        syringe_area: plunger area A_s of each syringe, m².
        syringe_stroke: plunger stroke, m (the syringe starts full, at its extend stop).
        n_syringes: N_s, syringes on the platform (static).
        lead: lead-screw lead, m/rev.
        screw_viscous_friction: viscous friction μ_S on each screw, N·m/(rad/s).
        platform_mass: carrier platform mass m_p, kg.
        penetration_coefficient: end-stop penetration coefficient K_pen, N·s/m² (Simscape 'Simple' cylinder).
    """

    syringe_area: float = 2.5e-4
    syringe_stroke: float = 0.05
    lead: float = 0.008
    screw_viscous_friction: float = 0.1
    platform_mass: float = 1e-3
    penetration_coefficient: float = 1e12
    n_syringes: int = eqx.field(static=True, default=2)

    @property
    def screw_ratio(self) -> Float[ArrayLike, ""]:
        """R_NS = 2π/lead, rad/m: screw angle per nut travel."""
        return 2.0 * math.pi / self.lead

    @property
    def screw_damping(self) -> Float[ArrayLike, ""]:
        """Viscous damping of all screws seen at the platform, b_p = N_s μ_S R_NS², N·s/m."""
        return self.n_syringes * self.screw_viscous_friction * self.screw_ratio**2


def cylinder_stop_force(
    penetration_coefficient: Float[ArrayLike, "*b"],
    displacement: Float[ArrayLike, "*b"],
    velocity: Float[ArrayLike, "*b"],
    extend_limit: Float[ArrayLike, "*b"],
    retract_limit: Float[ArrayLike, "*b"],
    width: float,
) -> Float[Array, "*b"]:
    """End-stop force F_c of a Simscape single-acting 'Simple' cylinder, regularised.

    F_c = K_pen |ξ − ξ_E| ξ̇ beyond the extend limit while extending, K_pen |ξ − ξ_R| ξ̇ beyond the retract limit while
    retracting, zero otherwise (fully inelastic stop).

    Args:
        penetration_coefficient: K_pen, N·s/m².
        displacement: ξ, m.
        velocity: ξ̇, m/s.
        extend_limit: ξ_E, m.
        retract_limit: ξ_R, m.
        width: the C¹ ramps of the penetration (m) and of the velocity gate (m/s).

    Returns:
        F_c, N.
    """
    pen_e = smooth_ramp(displacement - extend_limit, width)
    pen_r = smooth_ramp(retract_limit - displacement, width)
    v_out = smooth_ramp(velocity, width)
    v_in = smooth_ramp(-velocity, width)
    return penetration_coefficient * (pen_e * v_out - pen_r * v_in)


def syringe_stop_force(
    pump: SyringePump, x_platform: Float[ArrayLike, "*b"], v_platform: Float[ArrayLike, "*b"], width: float
) -> Float[Array, "*b"]:
    """End-stop force of one syringe on the platform.

    Syringe displacement ξ = −x_p (orientation −1); extend limit ξ_E = 0 (full), retract limit −stroke (empty).

    Args:
        pump: the pump.
        x_platform: x_p, m.
        v_platform: ẋ_p, m/s.
        width: the stop's transition band, m.

    Returns:
        The force, N (+x pushes the plunger in).
    """
    f_c = cylinder_stop_force(pump.penetration_coefficient, -x_platform, -v_platform, 0.0, -pump.syringe_stroke, width)
    return f_c


def syringe_load_force(
    pump: SyringePump,
    syringe_pressure: Float[ArrayLike, "*b"],
    x_platform: Float[ArrayLike, "*b"],
    v_platform: Float[ArrayLike, "*b"],
    width: float,
) -> Float[Array, "*b"]:
    """Force of all syringes on the platform: −N_s (A_s p_s − F_c).

    Args:
        pump: the pump.
        syringe_pressure: p_s, Pa.
        x_platform: x_p, m.
        v_platform: ẋ_p, m/s.
        width: the stops' transition band, m.

    Returns:
        The force, N (+x pushes the plungers in).
    """
    stop = syringe_stop_force(pump, x_platform, v_platform, width)
    return -pump.n_syringes * (pump.syringe_area * syringe_pressure - stop)


def platform_force(
    pump: SyringePump,
    drive_force: Float[ArrayLike, "*b"],
    syringe_pressure: Float[ArrayLike, "*b"],
    x_platform: Float[ArrayLike, "*b"],
    v_platform: Float[ArrayLike, "*b"],
    width: float,
) -> Float[Array, "*b"]:
    """Net force on the platform: drive − screw damping + syringe load.

    Args:
        pump: the pump.
        drive_force: the drive's force, N.
        syringe_pressure: p_s, Pa.
        x_platform: x_p, m.
        v_platform: ẋ_p, m/s.
        width: the stops' transition band, m.

    Returns:
        The force, N.
    """
    load = syringe_load_force(pump, syringe_pressure, x_platform, v_platform, width)
    return drive_force - pump.screw_damping * v_platform + load


def syringe_volume_delivered(pump: SyringePump, x_platform: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Liquid volume pushed out of all syringes.

    Args:
        pump: the pump.
        x_platform: x_p, m.

    Returns:
        The volume, m³.
    """
    return pump.n_syringes * pump.syringe_area * x_platform


def _ramp_balance(damping, stop, drive, width):
    """u ≥ 0 with damping·u + stop·smooth_ramp(u, width) = drive ≥ 0 (exact: quadratic inside the band, linear
    beyond)."""
    quadratic = 2.0 * drive / (damping + jnp.sqrt(damping * damping + 2.0 * stop * drive / width))
    linear = (drive + 0.5 * stop * width) / (damping + stop)
    return jnp.where(drive <= (damping + 0.5 * stop) * width, quadratic, linear)


def platform_velocity(
    pump: SyringePump,
    drive_force: Float[ArrayLike, "*b"],
    line_pressure: Float[ArrayLike, "*b"],
    line_resistance: Float[ArrayLike, "*b"],
    x_platform: Float[ArrayLike, "*b"],
    width: float,
) -> Float[Array, "*b"]:
    """Velocity of a massless platform: the exact root of `platform_force` = 0.

    The syringes see the line pressure plus a linear line drop, p_s = P + R·N_s·A_s·v. The balance
    F₀ − B v + N_s K_pen (pen_E·ramp(−v) − pen_R·ramp(v)) = 0, with F₀ = drive − N_s A_s P and
    B = b_p + N_s² A_s² R, is linear outside the end stops' velocity band and quadratic inside
    it, so the root has a closed form on each side of v = 0.

    Args:
        pump: the pump.
        drive_force: the drive's force, N.
        line_pressure: P, Pa.
        line_resistance: R, Pa·s/m³ of total flow.
        x_platform: x_p, m.
        width: the stops' transition band, m.

    Returns:
        v, m/s.
    """
    n, a_s = pump.n_syringes, pump.syringe_area
    damping = pump.screw_damping + n * n * a_s * a_s * line_resistance
    f0 = drive_force - n * a_s * line_pressure
    pen_full = smooth_ramp(-x_platform, width)  # beyond the full mark: resists withdrawal
    pen_empty = smooth_ramp(x_platform - pump.syringe_stroke, width)  # beyond the empty mark: resists pushing
    push = _ramp_balance(damping, n * pump.penetration_coefficient * pen_empty, jnp.maximum(f0, 0.0), width)
    pull = _ramp_balance(damping, n * pump.penetration_coefficient * pen_full, jnp.maximum(-f0, 0.0), width)
    return jnp.where(f0 >= 0.0, push, -pull)
