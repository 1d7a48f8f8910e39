"""Working fluid: water with entrained air (Simscape 'Hydraulic Fluid' block, PHYSICS.md §3.1, §4)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

P_ATM = 101325.0  # Pa, Simscape reference atmosphere


class Fluid(eqx.Module):
    """Loop-wide liquid properties.

    Attributes:
        density: ρ, kg/m³.
        kinematic_viscosity: ν, m²/s.
        bulk_modulus_liquid: E_l of the pure liquid, Pa.
        air_fraction: α, relative volume of entrained air at atmospheric pressure (–).
        polytropic_index: gas index n of the air (1.4 adiabatic, as modelled).
    """

    density: float = 997.41
    kinematic_viscosity: float = 9.5838e-7
    bulk_modulus_liquid: float = 2.18895e9
    air_fraction: float = 0.005
    polytropic_index: float = 1.4


def water(temperature_c: float = 22.0, air_fraction: float = 0.005, polytropic_index: float = 1.4) -> Fluid:
    """Water from Simscape's stock correlation at ``temperature_c`` (°C)."""
    dt = temperature_c - 1.0
    nu_cst = 0.0374 * np.exp(443.5170 / (temperature_c + 273.15 - 158.4127))
    e_bar = 20424 + 87.31 * dt - 0.87045 * dt**2 + 1.7143e-3 * dt**3
    rho = 1000 - 4.4627e-2 * dt - 3.7459e-3 * dt**2
    return Fluid(float(rho), float(nu_cst * 1e-6), float(e_bar * 1e5), air_fraction, polytropic_index)


def bulk_modulus(fluid: Fluid, p):
    """Effective bulk modulus E(p) of the liquid–air mixture, Pa, at gauge pressure ``p`` (Pa)."""
    pa = P_ATM
    n = fluid.polytropic_index
    pabs = jnp.maximum(pa + p, 0.05 * pa)
    el, a = fluid.bulk_modulus_liquid, fluid.air_fraction
    num = 1.0 + a * (pa / pabs) ** (1.0 / n)
    den = 1.0 + a * el * pa ** (1.0 / n) / (n * pabs ** ((n + 1.0) / n))
    return el * num / den
