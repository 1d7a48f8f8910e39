"""Working fluid: water with entrained air (Simscape 'Hydraulic Fluid' block)."""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "P_ATM",
    "Fluid",
    "StorageLaw",
    "bulk_modulus",
    "pressure_at_stored_fraction",
    "storage_law",
    "stored_volume_fraction",
    "water",
]

P_ATM = 101325.0  # Pa, Simscape reference atmosphere


class Fluid(eqx.Module):
    """Loop-wide liquid properties.

    Attributes:
        density: ρ, kg/m³.
        kinematic_viscosity: ν, m²/s.
        bulk_modulus_liquid: E_l of the pure liquid, Pa.
        air_fraction: α, relative volume of entrained air at atmospheric pressure (–).
        polytropic_index: polytropic index γ of the air (1.4 adiabatic, as modelled).
    """

    density: float = 997.41
    kinematic_viscosity: float = 9.5838e-7
    bulk_modulus_liquid: float = 2.18895e9
    air_fraction: float = 0.005
    polytropic_index: float = 1.4


def water(temperature_c: float = 22.0, air_fraction: float = 0.005, polytropic_index: float = 1.4) -> Fluid:
    """Water from Simscape's stock correlation.

    Args:
        temperature_c: the temperature, °C.
        air_fraction: α, relative volume of entrained air at atmospheric pressure (–).
        polytropic_index: the air's gas index n.

    Returns:
        The fluid: density, viscosity and bulk modulus of water at ``temperature_c``.
    """
    dt = temperature_c - 1.0
    nu_cst = 0.0374 * np.exp(443.5170 / (temperature_c + 273.15 - 158.4127))
    e_bar = 20424 + 87.31 * dt - 0.87045 * dt**2 + 1.7143e-3 * dt**3
    rho = 1000 - 4.4627e-2 * dt - 3.7459e-3 * dt**2
    return Fluid(float(rho), float(nu_cst * 1e-6), float(e_bar * 1e5), air_fraction, polytropic_index)


def bulk_modulus(fluid: Fluid, p: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Effective bulk modulus E(p) of the liquid–air mixture.

    Args:
        fluid: the fluid.
        p: gauge pressure, Pa.

    Returns:
        E(p), Pa.
    """
    pa = P_ATM
    n = fluid.polytropic_index
    pabs = jnp.maximum(pa + p, 0.05 * pa)
    el, a = fluid.bulk_modulus_liquid, fluid.air_fraction
    num = 1.0 + a * (pa / pabs) ** (1.0 / n)
    den = 1.0 + a * el * pa ** (1.0 / n) / (n * pabs ** ((n + 1.0) / n))
    return el * num / den


def _expm1_over(e, z):
    """(e^(e·z) − 1)/e, continuous at e = 0 (→ z)."""
    small = jnp.abs(e) < 1e-8
    e_safe = jnp.where(small, 1.0, e)
    return jnp.where(small, z, jnp.expm1(e_safe * z) / e_safe)


class StorageLaw(NamedTuple):
    """Constants of the stored-volume law of a `Fluid` (see `stored_volume_fraction`)."""

    air: jax.Array  # α
    index: jax.Array  # n
    e1: jax.Array  # 1 − 1/n
    e2: jax.Array  # 1 − 2/n
    liquid: jax.Array  # p_a / E_l
    log1p_air: jax.Array  # ln(1 + α)


def storage_law(fluid: Fluid) -> StorageLaw:
    """The constants of the stored-volume law of ``fluid``, computed once."""
    n, a = fluid.polytropic_index, fluid.air_fraction
    return StorageLaw(
        jnp.asarray(a, float),
        jnp.asarray(n, float),
        1.0 - 1.0 / n,
        1.0 - 2.0 / n,
        P_ATM / fluid.bulk_modulus_liquid,
        jnp.log1p(a),
    )


def stored_volume_fraction(fluid: Fluid | StorageLaw, p: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """s(p) = ∫₀ᵖ dp'/E(p'): liquid volume stored per unit chamber volume from gauge 0 to p.

    Closed form of the Simscape mixture law. With g = α(p_a/(p_a + p))^(1/n),
    1/E = 1/(E_l(1 + g)) − g'/(1 + g); the second term integrates exactly (−ln(1 + g)) and
    the first is expanded as 1 − g + g² (error O(α³) ≈ 1e-7 of the liquid term). In terms of
    L = ln(1 + p/p_a):

        s = ln((1 + α)/(1 + α e^(−L/n))) + (p_a/E_l)[e^L − 1 − α E₁(L) + α² E₂(L)],
        E_k(L) = (e^((1 − k/n)L) − 1)/(1 − k/n).

    Valid for p_a + p ≥ 0.05 p_a, where `bulk_modulus` stops clamping.

    Args:
        fluid: the fluid, or its `StorageLaw`.
        p: gauge pressure, Pa.

    Returns:
        s (–).
    """
    law = fluid if isinstance(fluid, StorageLaw) else storage_law(fluid)
    return _stored_and_slopes(law, jnp.log1p(p / P_ATM))[0]


def _stored_and_slopes(law: StorageLaw, lv):
    """s(L) and its first two derivatives in L = ln(1 + p/p_a), from three transcendental evaluations.

    With a = e^L − 1 and b = e^(−L/n) − 1 (both by expm1, exact near L = 0): e^(e₁L) − 1 = a + b + ab
    and e^(e₂L) − 1 = a + b(2 + b)(1 + a).
    """
    a_air, n, e1, e2, c = law.air, law.index, law.e1, law.e2, law.liquid
    a = jnp.expm1(lv)
    b = jnp.expm1(-lv / n)
    ay = a_air * (1.0 + b)
    x1m = a + b + a * b
    x2m = a + b * (2.0 + b) * (1.0 + a)
    small1, small2 = jnp.abs(e1) < 1e-8, jnp.abs(e2) < 1e-8
    over1 = jnp.where(small1, lv, x1m / jnp.where(small1, 1.0, e1))
    over2 = jnp.where(small2, lv, x2m / jnp.where(small2, 1.0, e2))
    value = law.log1p_air - jnp.log1p(ay) + c * (a - a_air * over1 + a_air * a_air * over2)
    ex, x1, x2 = 1.0 + a, 1.0 + x1m, 1.0 + x2m
    slope = ay / (n * (1.0 + ay)) + c * (ex - a_air * x1 + a_air * a_air * x2)
    curvature = -ay / (n * n * (1.0 + ay) ** 2) + c * (ex - a_air * e1 * x1 + a_air * a_air * e2 * x2)
    return value, slope, curvature


def pressure_at_stored_fraction(
    fluid: Fluid | StorageLaw, s: Float[ArrayLike, "*b"], iterations: int = 3
) -> Float[Array, "*b"]:
    """Inverse of `stored_volume_fraction`: the gauge pressure at which a unit volume stores ``s``.

    Halley iterations on L = ln(1 + p/p_a) (unrolled, cubic convergence) from the smaller of the air-only and the
    liquid-only inverses, which both bound L from above. Derivatives are implicit.

    Args:
        fluid: the fluid, or its `StorageLaw`.
        s: the stored volume per unit volume (–).
        iterations: the Halley steps.

    Returns:
        The gauge pressure, Pa.
    """
    law = fluid if isinstance(fluid, StorageLaw) else storage_law(fluid)
    a, n = law.air, law.index
    shrink = (1.0 + a) * jnp.exp(-s) - 1.0  # α e^(−L/n) if the air stored everything
    l_air = jnp.where(
        (shrink > 0.0) & (a > 0.0), -n * jnp.log(jnp.maximum(shrink, 1e-300) / jnp.maximum(a, 1e-300)), jnp.inf
    )
    arg = s / law.liquid
    l_liquid = jnp.where(arg > -0.5, jnp.log1p(jnp.maximum(arg, -0.5)), jnp.inf)
    l0 = jax.lax.stop_gradient(jnp.minimum(l_air, l_liquid))

    def solve(f, lv):
        for _ in range(iterations):
            v, d1, d2 = _stored_and_slopes(law, lv)
            r = v - s
            lv = lv - 2.0 * r * d1 / (2.0 * d1 * d1 - r * d2)
        return lv

    def tangent(g, y):
        return y / g(jnp.ones_like(y))

    log_ratio = jax.lax.custom_root(lambda lv: _stored_and_slopes(law, lv)[0] - s, l0, solve, tangent)
    return P_ATM * jnp.expm1(log_ratio)
