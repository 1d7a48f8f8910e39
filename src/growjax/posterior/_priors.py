"""The priors of a posterior and the coordinates NUTS samples them in."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from growjax.posterior import emulator as em


@dataclasses.dataclass(frozen=True)
class Prior:
    """Prior of one parameter: site name in the NumPyro model, qualified name, SI bounds.

    Uniform on [low, high], or log-uniform when ``log``. ``nodes`` is the emulator's node
    count along this parameter (see :mod:`growjax.posterior.emulator`).
    """

    site: str
    name: str
    low: float
    high: float
    log: bool = False
    nodes: int = 33

    def distribution(self):
        return dist.LogUniform(self.low, self.high) if self.log else dist.Uniform(self.low, self.high)

    def sample(self, given: dict | None = None):
        """θ from this prior inside a NumPyro model (NumPyro's own unconstrained coordinate for it). ``given``:
        the parameters sampled before it, {name: value} (used by :class:`RidgePrior`)."""
        return numpyro.sample(self.site, self.distribution())

    def value_at(self, f):
        """θ at fraction ``f`` of the range (log scale for a log prior); :func:`fraction` inverted."""
        return self.low * (self.high / self.low) ** f if self.log else self.low + (self.high - self.low) * f

    def axis(self) -> em.Axis:
        return em.Axis(self.name, self.low, self.high, self.nodes, self.log)


BOUND_FRACTION = 0.05  # a mode closer to a bound than this share of the prior's range is "pressed" against it


@dataclasses.dataclass(frozen=True)
class SoftplusPrior(Prior):
    """The same prior, sampled in a coordinate u that suits a posterior pressed against a bound.

    NumPyro's logit coordinate puts a double-exponential wall at a bound; where the likelihood presses
    the posterior against it, NUTS's steps there diverge or shrink. Here the prior's fraction f
    (of [low, high], on a log scale when ``log``), measured from the pressed bound, is
    f = 1 − exp(−s·softplus(u)), s its value at the mode: a bijection of ℝ onto (0, 1) with
    exponential tails on both sides, f ≈ s near the mode (u ≈ 0.5), and the prior's density kept by the
    factor |df/du|. θ is recorded as the deterministic site ``site``; u is sampled as ``u_<site>``.
    """

    scale: float = 1.0  # s, the fraction at the mode
    upper: bool = False  # pressed against ``high`` (f measured from it) instead of ``low``

    def sample(self, given: dict | None = None):
        u = numpyro.sample("u_" + self.site, dist.ImproperUniform(dist.constraints.real, (), ()))
        s = self.scale
        numpyro.factor("du_" + self.site, jnp.log(s) + jax.nn.log_sigmoid(u) - s * jax.nn.softplus(u))
        return numpyro.deterministic(self.site, self.value_at(self.fraction_at(u)))

    def fraction_at(self, u):
        """The prior's fraction from ``low`` (:func:`fraction`) at coordinate u."""
        f = -jnp.expm1(-self.scale * jax.nn.softplus(u))
        return 1.0 - f if self.upper else f

    def start(self) -> float:
        """u where f = s (the mode this coordinate was centred on)."""
        s = self.scale
        return float(np.log(np.expm1(-np.log1p(-s) / s)))


@dataclasses.dataclass(frozen=True)
class RidgePrior(Prior):
    """The same prior, sampled across the ridge it forms with priors pressed against a bound.

    Where the likelihood ties this parameter to pressed ones (φ_L ≈ a + b·n_L under the Lockhart law on the
    public experiment), the tie is linear in their values but curved in their softplus coordinates, and no
    mass matrix follows a curved ridge: NUTS's trees stay long and its draws correlated. Here NumPyro's
    own coordinate z of this prior is z = v + ``offset`` + Σ_k b_k·f_k(θ_k), f_k the pressed prior's
    :func:`fraction` and ``along`` = ((pressed prior, b_k), ...); v, sampled as ``v_<site>``, measures the
    distance from the ridge. The map (v, u) → (z, u) has unit Jacobian, so the prior's density in z is kept
    as NumPyro keeps it. The pressed priors must be sampled first (``given``). θ is the deterministic ``site``.
    """

    along: tuple = ()  # ((pressed Prior, slope b_k), ...)
    offset: float = 0.0

    def sample(self, given: dict | None = None):
        v = numpyro.sample("v_" + self.site, dist.ImproperUniform(dist.constraints.real, (), ()))
        z = v + self.offset + sum(b * _fraction(p, given[p.name]) for p, b in self.along)
        prior = self.distribution()
        to_theta = dist.transforms.biject_to(prior.support)
        theta = to_theta(z)
        numpyro.factor("dv_" + self.site, prior.log_prob(theta) + to_theta.log_abs_det_jacobian(z, theta))
        return numpyro.deterministic(self.site, theta)


def coordinate(prior: Prior) -> str:
    """The coordinate NUTS samples a prior in: ``"softplus"``, ``"ridge"`` or ``"numpyro"`` (NumPyro's own)."""
    return "softplus" if isinstance(prior, SoftplusPrior) else "ridge" if isinstance(prior, RidgePrior) else "numpyro"


def _recast(kind: type, prior: Prior, **coordinate_fields):
    """``prior``'s range and names as a ``kind`` (a :class:`Prior` subclass) with its own coordinate's fields."""
    return kind(**{f.name: getattr(prior, f.name) for f in dataclasses.fields(Prior)}, **coordinate_fields)


def _fraction(prior: Prior, value):
    if prior.log:
        return jnp.log(value / prior.low) / np.log(prior.high / prior.low)
    return (value - prior.low) / (prior.high - prior.low)


def fraction(prior: Prior, value) -> float:
    """Where ``value`` lies in the prior's range: 0 at ``low``, 1 at ``high`` (log scale for a log prior)."""
    return float(_fraction(prior, value))


def bound_coordinates(priors: Sequence[Prior], mode: dict, within: float = BOUND_FRACTION) -> tuple[Prior, ...]:
    """``priors`` with each one whose ``mode`` {site: value} lies within ``within`` of a bound (share of its range)
    as a :class:`SoftplusPrior` centred there; the others unchanged."""
    out = []
    for p in priors:
        f = fraction(p, mode[p.site]) if p.site in mode and not isinstance(p, SoftplusPrior) else 0.5
        if min(f, 1.0 - f) < within:
            upper = f > 0.5
            scale = min(max(1.0 - f if upper else f, 1e-6), within)
            p = _recast(SoftplusPrior, p, scale=scale, upper=upper)
        out.append(p)
    return tuple(out)


def paper_priors() -> tuple[Prior, ...]:
    """Uniform priors over the paper's investigation box (reference growth law).

    Emulator nodes: 101 along Y; 3 along ext and n, whose effect is ~1e-10 (validated, not assumed).
    """
    return (
        Prior("Y", "robot.yield_pressure", 5e3, 15e3, nodes=101),
        Prior("ext", "robot.extensibility", 4000.0, 10000.0, nodes=3),
        Prior("n", "robot.growth_exponent", 0.9, 1.1, nodes=3),
    )


def lockhart_priors() -> tuple[Prior, ...]:
    """Priors of the Lockhart growth law (:mod:`growjax.model.robot`): Y on the paper's box, φ_L and n_L log-uniform.

    φ_L, the growth speed 1 kPa above the rest pressure, spans 0.1–10 mm/s: from a robot
    that barely moves within the experiment to one whose speed the check valve alone sets.
    n_L spans 0.25–2, from a nearly rate-capped membrane to a stiffening one (Lockhart's plant
    cells have n ≈ 1); below 0.25 the quasi-static rod balance needs more than its 16 Newton
    steps. Emulator nodes: 21 × 25 × 15 (log-spaced in φ_L and n_L).
    """
    return (
        Prior("Y", "robot.yield_pressure", 5e3, 15e3, nodes=21),
        Prior("phi_L", "robot.lockhart_rate", 1e-4, 1e-2, log=True, nodes=25),
        Prior("n_L", "robot.lockhart_exponent", 0.25, 2.0, log=True, nodes=15),
    )
