"""What a Gaussian filter carries and returns: the belief (mean and covariance of the state at a time), one
step's record (what the smoother and the change detectors read), and the measurement update every method
shares.

Measurements are whitened by the sensors' noise sd before the update (a pressure in Pa beside a displacement in m
would leave the innovation covariance with a condition number of 1e20), so the innovation covariance is
S = H P Hᵀ + I and every reading's innovation is in units of its noise. A sensor whose sample is missing (NaN)
drops out of the update: its row of H and its innovation are zeroed and its row of S is the identity's.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

LOG_2PI = float(jnp.log(2.0 * jnp.pi))


class Belief(eqx.Module):
    """The filter's Gaussian belief about the state: ``time`` (s), ``mean`` (N,), ``cov`` (N, N)."""

    time: Float[Array, ""]
    mean: Float[Array, " N"]
    cov: Float[Array, "N N"]


class Step(eqx.Module):
    """One filter step's record, from the belief at t_k to the one at t_{k+1}.

    Attributes:
        predicted_mean: (N,) the state at t_{k+1} given the readings up to t_k.
        predicted_cov: (N, N) its covariance.
        cross: (N, N) covariance of the state at t_k (given the readings up to t_k) with the predicted one
            (the smoother's gain is cross · predicted_cov⁻¹).
        innovation: (m,) the readings less their prediction, in units of each sensor's noise sd (0 where missing).
        innovation_cov: (m, m) its covariance S (whitened: the identity's row where missing).
        observed: (m,) which readings were present.
        nis: the normalised innovation squared vᵀS⁻¹v (χ² with ``observed.sum()`` degrees of freedom).
        log_likelihood: log p(readings at t_{k+1} | readings up to t_k), nats (readings in SI units).
        status: the solver's: 0 ok, 2 failed (the belief is then not finite).
    """

    predicted_mean: Float[Array, " N"]
    predicted_cov: Float[Array, "N N"]
    cross: Float[Array, "N N"]
    innovation: Float[Array, " m"]
    innovation_cov: Float[Array, "m m"]
    observed: Bool[Array, " m"]
    nis: Float[Array, ""]
    log_likelihood: Float[Array, ""]
    status: Int[Array, ""]


def symmetric(p: Float[Array, "N N"]) -> Float[Array, "N N"]:
    return 0.5 * (p + p.T)


def square_root(p: Float[Array, "N N"]) -> Float[Array, "N N"]:
    """A factor r (N, N) of the positive semi-definite part of the covariance ``p``: r rᵀ is ``p`` with its
    negative eigenvalues set to 0, and a coordinate with no variance keeps a zero row.

    A transition's Jacobian F carries the covariance as (F r)(F r)ᵀ, positive semi-definite whatever F's size:
    as F P Fᵀ it would multiply rounding's negative eigenvalues of P, which near a sharp switch of the model
    (F up to 1e14) turn into negative variances."""
    values, vectors = jnp.linalg.eigh(symmetric(p))
    root = vectors * jnp.sqrt(jnp.maximum(values, 0.0))
    return jnp.where(jnp.diag(p)[:, None] > 0.0, root, 0.0)


class Update(eqx.Module):
    """The measurement update of a Gaussian filter: (posterior mean (N,), posterior covariance (N, N),
    whitened innovation (m,), its covariance S (m, m), NIS, log-likelihood nats)."""

    mean: Float[Array, " N"]
    cov: Float[Array, "N N"]
    innovation: Float[Array, " m"]
    innovation_cov: Float[Array, "m m"]
    nis: Float[Array, ""]
    log_likelihood: Float[Array, ""]


def update(
    mean: Float[Array, " N"],
    cov: Float[Array, "N N"],
    predicted: Float[Array, " m"],
    spread: Float[Array, "m m"],
    cross: Float[Array, "N m"],
    readings: Float[Array, " m"],
    noise_sd: Float[Array, " m"],
    jacobian: Float[Array, "m N"] | None = None,
) -> Update:
    """Condition the prior (``mean``, ``cov``) on ``readings`` (m,) SI (NaN: missing).

    Args:
        mean, cov: the predicted state (N,) and covariance (N, N).
        predicted: the readings' predicted mean (m,) SI.
        spread: their predicted covariance without the noise (m, m), whitened (divided by σᵢσⱼ).
        cross: covariance of the state with the whitened readings (N, m).
        readings: (m,) SI; NaN where a sample is missing.
        noise_sd: the sensors' noise sd (m,) SI.
        jacobian: the whitened measurement Jacobian (m, N) where the method has one (the extended filter): the
            covariance is then updated in Joseph's form, which stays positive definite under rounding.

    Returns:
        `Update`.
    """
    observed = jnp.isfinite(readings)
    mask = observed.astype(mean.dtype)
    v = jnp.where(observed, (jnp.where(observed, readings, 0.0) - predicted) / noise_sd, 0.0)
    s = spread * mask[:, None] * mask[None, :] + jnp.eye(v.shape[0])
    c = cross * mask[None, :]
    chol = jnp.linalg.cholesky(s)
    gain = jax.scipy.linalg.cho_solve((chol, True), c.T).T  # (N, m)
    white = jax.scipy.linalg.solve_triangular(chol, v, lower=True)
    if jacobian is None:
        cov_post = cov - gain @ s @ gain.T
    else:
        a = jnp.eye(mean.shape[0]) - gain @ (jacobian * mask[:, None])
        cov_post = a @ cov @ a.T + gain @ jnp.diag(mask) @ gain.T
    nis = white @ white
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diag(chol)))
    log_like = -0.5 * (nis + log_det + jnp.sum(mask) * LOG_2PI) - jnp.sum(mask * jnp.log(noise_sd))
    return Update(mean + gain @ v, symmetric(cov_post), v, s, nis, log_like)


__all__ = ["Belief", "Step", "Update", "square_root", "symmetric", "update"]
