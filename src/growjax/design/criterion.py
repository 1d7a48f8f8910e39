"""Criteria of a design: the expected posterior covariance of the parameters of interest under the full residual
model, linearised, and the precision criteria on it.

For the next experiment's data y = L(w) + δ + ε (length; and the pressure when it is recorded), linearised in
w = (ln θ, b) at the estimate with J̃ = [J_θ, G_b] the length's sensitivities (`.sensitivity`), the
posterior covariance of w is

    Σ_post = (Σ_prior⁻¹ + J̃ᵀ K⁻¹ J̃ + J_Pᵀ J_P / σ_P²)⁻¹,

K the covariance of the discrepancy and the sensor noise on the sample times (`growjax.calibration.discrepancy`; K⁻¹J̃
by the Kalman filter's whitening, exact for the Matérn-3/2 and Ornstein–Uhlenbeck processes) and the pressure
rows with independent noise of sd σ_P. The rig's errors b are nuisance parameters (their tolerances the
prior): the block of Σ_post on θ has them integrated out. The covariance does not depend on the data, only on
the input: it is what a fit of the designed experiment will report, to the linearisation.

A criterion (`Criterion`) maps that block, the covariance of the parameters of interest in ln θ (relative
variances), to a number to minimise: `AOptimal` (the log of its trace) or `DOptimal` (its log determinant),
Bayesian because the covariance has the prior in it. A new criterion is one subclass of `Criterion` with a
``name`` and a ``__call__``; the design (`growjax.design.design`) takes any. The discrimination design
(`growjax.design.discrimination`) minimises a criterion of another kind, −ln min(T_AB, T_BA), in the same search.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from growjax.calibration import discrepancy as dc
from growjax.design.sensitivity import Sensitivities

__all__ = [
    "PRESSURE_NOISE",
    "SENSORS",
    "AOptimal",
    "Criterion",
    "DOptimal",
    "Prediction",
    "check_sensors",
    "information",
    "posterior",
    "standard_deviations",
]

SENSORS = ("length", "pressure")
PRESSURE_NOISE = 1e3  # Pa, sd of the pressure sensor's noise (independent samples)


class Prediction(NamedTuple):
    """What an input gives.

    Attributes:
        sensitivities: the `Sensitivities` on the sample times.
        covariance: (m, m) the covariance of the estimate of w with what is known, with the rig's nonlinearity
            where it was given.
        covariance_alone: (m, m) the same from the next experiment alone (no prior on θ, the rig under its
            tolerances).
        covariance_linear: (m, m) with what is known, the rig linearised (the posterior covariance alone).
    """

    sensitivities: Sensitivities
    covariance: jax.Array
    covariance_alone: jax.Array
    covariance_linear: jax.Array


def check_sensors(sensors: Sequence[str]) -> tuple[str, ...]:
    """``sensors`` as a tuple; ValueError unless it is ('length',) or ('length', 'pressure')."""
    sensors = tuple(sensors)
    if set(sensors) - set(SENSORS) or "length" not in sensors:
        raise ValueError(f"sensors must be 'length' or 'length,pressure', got {','.join(sensors)}")
    return sensors


def information(
    s: Sensitivities,
    times: Float[ArrayLike, " n"],
    hyper: dc.Hyper,
    sensors: Sequence[str] = ("length",),
    pressure_noise: float = PRESSURE_NOISE,
) -> Float[Array, "m m"]:
    """The information J̃ᵀK⁻¹J̃ (+ J_PᵀJ_P/σ_P² with ``"pressure"`` in ``sensors``) (m, m) on w of the samples at
    ``times`` (n,) s, under the discrepancy's hyperparameters ``hyper`` and the pressure noise σ_P (Pa)."""
    check_sensors(sensors)
    w = dc.whiten(s.jac_length, times, hyper)
    info = w.T @ w
    if "pressure" in sensors:
        jp = s.jac_pressure / pressure_noise
        info = info + jp.T @ jp
    return info


def posterior(
    s: Sensitivities,
    times: Float[ArrayLike, " n"],
    hyper: dc.Hyper,
    precision_known: Float[Array, "m m"],
    precision_alone: Float[Array, "m m"],
    sensors: Sequence[str] = ("length",),
    pressure_noise: float = PRESSURE_NOISE,
    remainder: Float[Array, "n D"] | None = None,
) -> Prediction:
    """The `Prediction` of sensitivities ``s``: Σ = (Λ₀ + information)⁻¹ for the prior precisions Λ₀
    ``precision_known`` and ``precision_alone`` (m, m) (`growjax.design.knowledge.Knowledge.prior_precision`).

    ``remainder`` (n, D) m: what the rig's linearised effect misses at D draws of the rig
    (`growjax.design.sensitivity.remainder`). A fit that linearises the rig (`growjax.calibration.fit.fit`) takes
    it for data: its estimate moves by Σ J̃ᵀK⁻¹ r for a remainder r, so the covariance gains
    Σ J̃ᵀK⁻¹ V VᵀK⁻¹J̃ Σ with V Vᵀ = the remainder's second moment over the draws (the sandwich of the estimator
    the fit is, with the remainder as an error it does not model)."""
    check_sensors(sensors)
    m = s.jac_length.shape[1]
    if remainder is None:
        remainder = jnp.zeros((s.jac_length.shape[0], 0))
    d = remainder.shape[1]
    cols = jnp.concatenate([s.jac_length, remainder / jnp.sqrt(max(d, 1))], axis=1)
    w = dc.whiten(cols, times, hyper)
    info = w[:, :m].T @ w[:, :m]
    if "pressure" in sensors:
        jp = s.jac_pressure / pressure_noise
        info = info + jp.T @ jp
    cross = w[:, :m].T @ w[:, m:]  # (m, D)
    inv = lambda a: jnp.linalg.inv(0.5 * (a + a.T))
    known, alone = inv(precision_known + info), inv(precision_alone + info)
    spread = lambda c: c + c @ cross @ cross.T @ c
    return Prediction(s, spread(known), spread(alone), known)


class Criterion(eqx.Module):
    """A criterion of precision: the number a design minimises, from the covariance of the parameters of interest.

    Subclass it with a ``name`` (how summaries and figures label it: ``"A"`` for "A-optimal") and a ``__call__``.
    Instances are compared and hashed by their fields (a criterion is a static part of a compiled problem).
    """

    name: ClassVar[str]

    @abc.abstractmethod
    def __call__(self, covariance: Float[Array, "p p"]) -> Float[Array, ""]:
        """The criterion of a covariance.

        Args:
            covariance: (p, p) the posterior covariance of ln θ of the p parameters of interest (relative: a
                diagonal entry is a relative variance). Traceable: the criterion is differentiated through it.

        Returns:
            A scalar, smaller for a more precise estimate; NaN or inf where it is undefined.
        """


class AOptimal(Criterion):
    """Bayesian A-optimality: the log of the trace of the covariance, the log of the sum of the parameters'
    relative variances."""

    name = "A"

    def __call__(self, covariance: Float[Array, "p p"]) -> Float[Array, ""]:
        return jnp.log(jnp.trace(covariance))


class DOptimal(Criterion):
    """Bayesian D-optimality: the log determinant of the covariance, the log of the squared volume of the
    parameters' joint uncertainty."""

    name = "D"

    def __call__(self, covariance: Float[Array, "p p"]) -> Float[Array, ""]:
        return jnp.linalg.slogdet(covariance)[1]


def standard_deviations(cov: Float[Array, "m m"], size: int) -> Float[Array, " size"]:
    """sd (size,) of ln θ, the first ``size`` coordinates of the covariance ``cov``: each parameter's relative
    standard uncertainty."""
    return jnp.sqrt(jnp.clip(jnp.diag(cov)[:size], 0.0, None))
