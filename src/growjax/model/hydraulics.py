"""Hydraulic components between the syringes and the robot.

Sign convention (Simscape): pressures are gauge, Pa; a flow q (m³/s) is positive
from port A to port B. Each component is a small pytree of parameters plus pure
functions of pressures and flows; no component has a state except the pipeline
chambers, whose derivatives are computed here and integrated by the assemblies (`growjax.simulation.reference`,
`growjax.simulation.fast`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from growjax.model.fluid import P_ATM, Fluid, bulk_modulus
from growjax.model.smooth import smooth_ramp, smooth_step

__all__ = [
    "CheckValve",
    "DirectionalValve",
    "Nozzle",
    "Orifice",
    "Pipeline",
    "ValveNetwork",
    "chamber_pressure_rate",
    "check_valve_flow",
    "circular_pipeline",
    "critical_pressure",
    "line_pressure_drop",
    "nozzle_pressure_drop",
    "orifice_conductance",
    "orifice_flow",
    "orifice_pressure_drop",
    "pipeline_half_pressure_drop",
    "strained_volume",
    "valve_network",
    "valve_network_flow",
    "wall_strain_rate",
]


def critical_pressure(p_avg: Float[ArrayLike, "*b"], b_lam: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Laminar–turbulent transition pressure p_cr = (p_avg + p_atm)(1 − B_lam) ('pressure ratio' spec).

    Args:
        p_avg: the mean gauge pressure of the ports, Pa.
        b_lam: the laminar transition pressure ratio B_lam (–).

    Returns:
        p_cr, Pa.
    """
    return jnp.maximum(p_avg + P_ATM, 0.05 * P_ATM) * (1.0 - b_lam)


def orifice_flow(
    conductance: Float[ArrayLike, "*b"], dp: Float[ArrayLike, "*b"], p_cr: Float[ArrayLike, "*b"]
) -> Float[Array, "*b"]:
    """Regularised square-root law q = k Δp / (Δp² + p_cr²)^¼.

    Args:
        conductance: k = C_D A √(2/ρ), m³/s/√Pa.
        dp: the pressure drop Δp, Pa.
        p_cr: the laminar transition pressure, Pa.

    Returns:
        The flow q, m³/s.
    """
    return conductance * dp * jax.lax.rsqrt(jnp.sqrt(dp * dp + p_cr * p_cr))


def orifice_pressure_drop(
    conductance: Float[ArrayLike, "*b"], q: Float[ArrayLike, "*b"], p_cr: Float[ArrayLike, "*b"]
) -> Float[Array, "*b"]:
    """Exact inverse of `orifice_flow`: the pressure drop that passes a flow.

    Args:
        conductance: k = C_D A √(2/ρ), m³/s/√Pa.
        q: the flow, m³/s.
        p_cr: the laminar transition pressure, Pa.

    Returns:
        Δp, Pa.
    """
    a = (q / conductance) ** 2
    return (q / conductance) * jnp.sqrt(0.5 * (a + jnp.sqrt(a * a + 4.0 * p_cr * p_cr)))


class Pipeline(eqx.Module):
    """Hydraulic pipeline: resistive half – chamber – resistive half (no fluid inertia).

    Attributes:
        area: flow cross-section A_c, m².
        hydraulic_diameter: D_h, m.
        length: L, m (chamber volume A_c·L).
        length_additional: aggregate equivalent length of local resistances, m.
        roughness: internal surface roughness, m.
        shape_factor: laminar friction constant s (64 for a circle) (–).
        re_laminar: Reynolds number where the laminar–turbulent transition region starts (–).
        re_turbulent: Reynolds number where it ends (–).
        diameter_compliance: static pressure–diameter coefficient k_p, m/Pa (0 = rigid wall).
        wall_time_constant: viscoelastic time constant τ of the wall, s.
        initial_pressure: gauge pressure at t0, Pa.
    """

    area: float
    hydraulic_diameter: float
    length: float
    length_additional: float = 1.0
    roughness: float = 15e-6
    shape_factor: float = 64.0
    re_laminar: float = 2000.0
    re_turbulent: float = 4000.0
    diameter_compliance: float = 0.0
    wall_time_constant: float = 0.01
    initial_pressure: float = 0.0

    @property
    def volume(self) -> Float[ArrayLike, ""]:
        """Chamber volume at zero wall strain, m³."""
        return self.area * self.length


def circular_pipeline(diameter: float, length: float, **kw: float) -> Pipeline:
    """A circular `Pipeline`.

    Args:
        diameter: the inner diameter, m.
        length: the length, m.
        **kw: the other fields of `Pipeline`.

    Returns:
        The pipeline.
    """
    return Pipeline(area=math.pi * diameter**2 / 4.0, hydraulic_diameter=diameter, length=length, **kw)


def _friction_times_reynolds(pipe: Pipeline, re):
    """f(Re)·Re: laminar s below Re_lam, Haaland above Re_turb, C¹ blend between."""
    re_safe = jnp.maximum(re, 1.0)
    rel = pipe.roughness / pipe.hydraulic_diameter / 3.7
    f_turb = 1.0 / (-1.8 * jnp.log10(6.9 / re_safe + rel**1.11)) ** 2
    w = smooth_step(re - pipe.re_laminar, pipe.re_turbulent - pipe.re_laminar)
    return (1.0 - w) * pipe.shape_factor + w * re_safe * f_turb


def pipeline_half_pressure_drop(pipe: Pipeline, fluid: Fluid, q: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Pressure drop across one resistive half of a pipeline.

    Args:
        pipe: the pipeline.
        fluid: the fluid.
        q: the flow, m³/s.

    Returns:
        The drop, Pa.
    """
    d, a = pipe.hydraulic_diameter, pipe.area
    l_eff = 0.5 * (pipe.length + pipe.length_additional)
    re = jnp.abs(q) * d / (a * fluid.kinematic_viscosity)
    laminar_coeff = fluid.kinematic_viscosity * fluid.density * l_eff / (2.0 * d * d * a)
    return laminar_coeff * _friction_times_reynolds(pipe, re) * q


def chamber_pressure_rate(
    pipe: Pipeline,
    fluid: Fluid,
    p: Float[ArrayLike, "*b"],
    wall_strain: Float[ArrayLike, "*b"],
    net_inflow: Float[ArrayLike, "*b"],
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    """The rates of a pipeline chamber's pressure and wall.

    Rigid wall: (V/E) ṗ = q. Flexible wall: τ δ̇ = k_p p − δ and
    q = (V(δ)/E) ṗ + (π(d+δ)/2) L (1 + p/E) δ̇, V(δ) = π(d+δ)²L/4.

    Args:
        pipe: the pipeline.
        fluid: the fluid.
        p: the chamber's gauge pressure, Pa.
        wall_strain: δ, the diameter increase, m.
        net_inflow: q, the net flow into the chamber, m³/s.

    Returns:
        (dp/dt, Pa/s; dδ/dt, m/s).
    """
    e = bulk_modulus(fluid, p)
    rigid = pipe.diameter_compliance == 0.0
    dd = wall_strain_rate(pipe, p, wall_strain)
    volume = jnp.where(rigid, pipe.volume, strained_volume(pipe, wall_strain))
    wall_flow = jnp.pi * (pipe.hydraulic_diameter + wall_strain) / 2.0 * pipe.length * (1.0 + p / e) * dd
    return (net_inflow - wall_flow) * e / volume, dd


def strained_volume(
    pipe: Pipeline, wall_strain: Float[ArrayLike, "*b"], count: int | Float[ArrayLike, "*b"] = 1
) -> Float[Array, "*b"]:
    """Chamber volume n·π(d + δ)²L/4 of n pipes at a diameter increase.

    Args:
        pipe: the pipeline.
        wall_strain: δ, m.
        count: n, the number of pipes like ``pipe``.

    Returns:
        The volume, m³.
    """
    return count * jnp.pi * (pipe.hydraulic_diameter + wall_strain) ** 2 / 4.0 * pipe.length


def wall_strain_rate(
    pipe: Pipeline, p: Float[ArrayLike, "*b"], wall_strain: Float[ArrayLike, "*b"]
) -> Float[Array, "*b"]:
    """dδ/dt of the viscoelastic wall: τ δ̇ = k_p p − δ (0 for a rigid wall).

    Args:
        pipe: the pipeline.
        p: gauge pressure, Pa.
        wall_strain: δ, m.

    Returns:
        dδ/dt, m/s.
    """
    rate = (pipe.diameter_compliance * p - wall_strain) / pipe.wall_time_constant
    return jnp.where(pipe.diameter_compliance == 0.0, 0.0, rate)


class Orifice(eqx.Module):
    """Fixed orifice.

    Attributes:
        area: opening area A, m².
        discharge_coefficient: C_D (–).
        b_lam: laminar transition pressure ratio B_lam (–).
    """

    area: float = 1.2566e-5
    discharge_coefficient: float = 0.7
    b_lam: float = 0.999


def orifice_conductance(area: Float[ArrayLike, "*b"], cd: Float[ArrayLike, "*b"], fluid: Fluid) -> Float[Array, "*b"]:
    """The conductance k = C_D A √(2/ρ) of an orifice.

    Args:
        area: A, m².
        cd: C_D (–).
        fluid: the fluid.

    Returns:
        k, m³/s/√Pa.
    """
    return cd * area * jnp.sqrt(2.0 / fluid.density)


class Nozzle(eqx.Module):
    """Gradual area change (semi-empirical Gibson losses). Port A small, B large.

    Attributes:
        small_diameter: diameter at port A, m.
        large_diameter: diameter at port B, m.
        angle: included angle of the transition, rad.
        correction: factor on the loss coefficients (–).
        b_lam: laminar transition pressure ratio B_lam (–).
    """

    small_diameter: float = 2e-3
    large_diameter: float = 15e-3
    angle: float = math.radians(30.0)
    correction: float = 1.0
    b_lam: float = 0.999

    def loss_coefficients(self) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
        """(K_expansion A→B, K_contraction B→A), referenced to the small area (α ≤ 45°)."""
        ar = (self.small_diameter / self.large_diameter) ** 2
        s = jnp.sin(self.angle / 2.0)
        k_exp = self.correction * (1.0 - ar) ** 2 * 2.6 * s
        k_con = self.correction * 0.5 * (1.0 - ar) ** 0.75 * 1.6 * s
        return k_exp, k_con


def nozzle_pressure_drop(
    noz: Nozzle, fluid: Fluid, q_ab: Float[ArrayLike, "*b"], p_avg: Float[ArrayLike, "*b"], flow_width: float
) -> Float[Array, "*b"]:
    """The pressure drop of a nozzle for a flow from its small to its large side.

    The loss coefficient switches between expansion and contraction with the flow sign; the switch is blended to
    keep the law C¹.

    Args:
        noz: the nozzle.
        fluid: the fluid.
        q_ab: the flow A → B, m³/s.
        p_avg: the ports' mean gauge pressure, Pa.
        flow_width: the blend's half-width, m³/s.

    Returns:
        Δp = p_A − p_B, Pa.
    """
    k_exp, k_con = noz.loss_coefficients()
    k = k_con + (k_exp - k_con) * smooth_step(q_ab + flow_width, 2.0 * flow_width)
    a_s = jnp.pi * noz.small_diameter**2 / 4.0
    conductance = a_s * jnp.sqrt(2.0 / (k * fluid.density))
    p_cr = critical_pressure(p_avg, noz.b_lam)
    return orifice_pressure_drop(conductance, q_ab, p_cr)


class CheckValve(eqx.Module):
    """Check valve with linear opening between cracking and max-opening pressure.

    ``crack_pressure`` is None in the shipped model: it is tied to the robot's yield pressure Y.

    Attributes:
        area_max: fully open area, m².
        max_open_pressure: pressure drop at which the valve is fully open, Pa.
        discharge_coefficient: C_D (–).
        leak_area: area when closed, m².
        b_lam: laminar transition pressure ratio B_lam (–).
        crack_pressure: cracking pressure, Pa (None: the robot's yield pressure Y).
    """

    area_max: float = 2.5e-4
    max_open_pressure: float = 1.2e10
    discharge_coefficient: float = 0.7
    leak_area: float = 1e-12
    b_lam: float = 0.999
    crack_pressure: float | None = None


def check_valve_flow(
    cv: CheckValve,
    fluid: Fluid,
    dp: Float[ArrayLike, "*b"],
    p_avg: Float[ArrayLike, "*b"],
    crack_pressure: Float[ArrayLike, "*b"],
    crack_width: float,
) -> Float[Array, "*b"]:
    """The flow through a check valve, its opening started smoothly (C¹).

    Args:
        cv: the valve.
        fluid: the fluid.
        dp: Δp = p_A − p_B, Pa.
        p_avg: the ports' mean gauge pressure, Pa.
        crack_pressure: the cracking pressure, Pa.
        crack_width: the band over which the opening starts, Pa.

    Returns:
        The flow A → B, m³/s.
    """
    net = valve_network(cv, DirectionalValve(), fluid, crack_pressure, crack_width, 1.0)
    return _check_flow(net, dp, critical_pressure(p_avg, net.check_laminar_ratio))


class DirectionalValve(eqx.Module):
    """3-way directional valve whose spool follows the robot-flow sign (PS Switch).

    Spool +1 (robot flow ≥ 0): P–A open, A–T closed; −1: A–T open (check valve bypassed).

    Attributes:
        area_max: fully open area of a path, m².
        discharge_coefficient: C_D (–).
        leak_area: area of a closed path, m².
        b_lam: laminar transition pressure ratio B_lam (–).
    """

    area_max: float = 5e-5
    discharge_coefficient: float = 0.7
    leak_area: float = 1e-12
    b_lam: float = 0.999


class ValveNetwork(NamedTuple):
    """Constants of the check valve ∥ 3-way bypass network, computed once per solve (`valve_network`)."""

    crack: jax.Array  # Pa, cracking pressure of the check valve
    crack_width: float  # Pa
    switch_width: float  # Pa
    check_leak: jax.Array  # m²
    check_gain: jax.Array  # m²/Pa, opening per Pa above cracking
    check_area_max: jax.Array  # m²
    check_k: jax.Array  # C_D √(2/ρ), per m² of opening
    check_laminar_ratio: jax.Array  # B_lam
    bypass_leak: jax.Array  # m²
    bypass_span: jax.Array  # m², full minus leak area
    bypass_k: jax.Array  # C_D √(2/ρ)
    bypass_laminar_ratio: jax.Array  # B_lam


def valve_network(
    cv: CheckValve,
    dv: DirectionalValve,
    fluid: Fluid,
    crack_pressure: Float[ArrayLike, "*b"],
    crack_width: float,
    switch_width: float,
) -> ValveNetwork:
    """The `ValveNetwork` constants.

    Args:
        cv: the check valve.
        dv: the directional valve.
        fluid: the fluid.
        crack_pressure: the check valve's cracking pressure, Pa.
        crack_width: the band over which the check valve's opening starts, Pa.
        switch_width: the band over which the bypass opens, Pa.

    Returns:
        The constants.
    """
    root = jnp.sqrt(2.0 / fluid.density)
    gain = (cv.area_max - cv.leak_area) / (cv.max_open_pressure - crack_pressure)
    return ValveNetwork(
        crack_pressure,
        crack_width,
        switch_width,
        cv.leak_area,
        gain,
        cv.area_max,
        cv.discharge_coefficient * root,
        cv.b_lam,
        dv.leak_area,
        dv.area_max - dv.leak_area,
        dv.discharge_coefficient * root,
        dv.b_lam,
    )


def _check_flow(net: ValveNetwork, dp, p_cr):
    area = jnp.minimum(
        net.check_leak + net.check_gain * smooth_ramp(dp - net.crack, net.crack_width), net.check_area_max
    )
    return orifice_flow(net.check_k * area, dp, p_cr)


def valve_network_flow(
    net: ValveNetwork, dp: Float[ArrayLike, "*b"], p_avg: Float[ArrayLike, "*b"]
) -> Float[Array, "*b"]:
    """Flow into the robot from node P through the check valve and the 3-way valve.

    The spool is +1 exactly when flow enters the robot, i.e. when Δp ≥ 0. The bypass
    (A–T) area is therefore opened for Δp < 0 only, ramping from leak to full over
    ``switch_width`` Pa, so no forward flow ever bypasses the check valve. The open P–A
    orifice in series with the check valve is omitted: its resistance is < 1e-5 of the
    check valve's, a relative flow error below 1e-5.

    Args:
        net: the network's constants.
        dp: Δp = P − p_robot, Pa.
        p_avg: the mean gauge pressure, Pa.

    Returns:
        The flow, m³/s.
    """
    q_check = _check_flow(net, dp, critical_pressure(p_avg, net.check_laminar_ratio))
    bypass_open = 1.0 - smooth_step(dp + net.switch_width, net.switch_width)
    area_at = net.bypass_leak + net.bypass_span * bypass_open
    q_bypass = orifice_flow(net.bypass_k * area_at, dp, critical_pressure(p_avg, net.bypass_laminar_ratio))
    return q_check + q_bypass


def line_pressure_drop(
    tube: Pipeline,
    orifice: Orifice,
    tank: Pipeline,
    fluid: Fluid,
    flow: Float[ArrayLike, "*b"],
    n_syringes: int | Float[ArrayLike, "*b"],
    p_avg: Float[ArrayLike, "*b"],
) -> Float[Array, "*b"]:
    """Pressure drop from the syringe outlets to the tank chamber, where the hoses and tank are lumped into one
    chamber.

    Series path of the lines at quasi-steady flow: each hose (both resistive halves) at flow/n, the orifice and
    one resistive half of the tank at the whole flow.

    Args:
        tube: each syringe's hose.
        orifice: the orifice.
        tank: the tank.
        fluid: the fluid.
        flow: the total pump flow, m³/s.
        n_syringes: n, the hoses in parallel.
        p_avg: the mean gauge pressure, Pa, that sets the orifice's laminar transition.

    Returns:
        The drop, Pa.
    """
    k_or = orifice_conductance(orifice.area, orifice.discharge_coefficient, fluid)
    hoses = 2.0 * pipeline_half_pressure_drop(tube, fluid, flow / n_syringes)
    orifice_drop = orifice_pressure_drop(k_or, flow, critical_pressure(p_avg, orifice.b_lam))
    return hoses + orifice_drop + pipeline_half_pressure_drop(tank, fluid, flow)
