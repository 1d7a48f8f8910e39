"""The unscented (cubature) Kalman filter: sigma points pushed through the solver.

The 2N points m ± √N·Lᵢ (L the covariance's Cholesky factor, equal weights 1/2N: the third-degree spherical
cubature rule of Arasaratnam & Haykin 2009, which never gives a negative weight) are each integrated over the
sample interval by the configuration's solver (``jax.vmap``: each its own adaptive loop); the predicted mean and
covariance are theirs, plus Q. The sensors are read at 2N points redrawn from the prediction. No derivative of
the model is taken, so the filter sees the transition's curvature to second order; each point pays a solve.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from growjax.track.belief import Belief, Step, symmetric, update
from growjax.track.model import StateSpace

JITTER = (1e-12, 1e-18)  # relative to the covariance's diagonal and absolute (states of order one): a factor of a
# singular covariance (a state at rest that no parameter moves)


@dataclasses.dataclass(frozen=True)
class Unscented:
    """The unscented Kalman filter on the cubature rule (2N sigma points, equal weights)."""

    name: str = "unscented Kalman"

    def start(self, model: StateSpace, time) -> Belief:
        """The belief at rest at ``time`` (s): `growjax.track.model.StateSpace.initial`."""
        mean, cov = model.initial()
        return Belief(jnp.asarray(time, float), mean, cov)

    def step(self, model: StateSpace, belief: Belief, time, readings, inputs, breaks) -> tuple[Belief, Step]:
        """The belief at ``time`` (s) given the ``readings`` (m,) SI taken there (NaN: missing); and the step's
        record."""
        points = sigma_points(belief.mean, belief.cov)
        moved, status = jax.vmap(lambda x: model.advance(x, inputs, belief.time, time, breaks))(points)
        mean = jnp.mean(moved, axis=0)
        cov = symmetric(_covariance(moved, moved, mean, mean) + model.process_noise(time - belief.time))
        cross = _covariance(points, moved, belief.mean, mean)
        sd = model.noise_sd()
        redrawn = sigma_points(mean, cov)
        read = jax.vmap(lambda x: model.measure(x, time, inputs))(redrawn) / sd
        predicted = jnp.mean(read, axis=0)
        spread = _covariance(read, read, predicted, predicted)
        post = update(mean, cov, predicted * sd, spread, _covariance(redrawn, read, mean, predicted), readings, sd)
        record = Step(
            mean,
            cov,
            cross,
            post.innovation,
            post.innovation_cov,
            jnp.isfinite(readings),
            post.nis,
            post.log_likelihood,
            jnp.max(status),
        )
        return Belief(jnp.asarray(time, float), post.mean, post.cov), record


def sigma_points(mean, cov):
    """The cubature rule's 2N points (2N, N) of N(mean, cov)."""
    n = mean.shape[0]
    jitter = JITTER[0] * jnp.diag(cov) + JITTER[1]
    chol = jnp.linalg.cholesky(symmetric(cov) + jnp.diag(jitter))
    offsets = jnp.sqrt(n) * chol.T  # rows: √N Lᵢ
    return jnp.concatenate([mean + offsets, mean - offsets])


def _covariance(a, b, mean_a, mean_b):
    """Equal-weight cross-covariance of paired points a (2N, p) and b (2N, q) about their means."""
    return (a - mean_a).T @ (b - mean_b) / a.shape[0]


__all__ = ["Unscented", "sigma_points"]
