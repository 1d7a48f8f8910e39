"""The extended Kalman filter on the model's forward-mode tangents.

Prediction: the mean is integrated over the sample interval by the configuration's own solver, and the
covariance carried by the transition's Jacobian F = ∂x(t_b)/∂x(t_a), which ``jax.jacfwd`` takes through the
solver: the tangents of its Rosenbrock W-method, whose Jacobian is held fixed over each step, are that same
method applied to the variational equation, so F is the exact derivative of the discrete transition that
the mean follows (one solve carries the state and its N tangents). P⁻ = F P Fᵀ + Q, formed as
(F R)(F R)ᵀ + Q from a square root R of P (`growjax.track.belief.square_root`). The update linearises the
sensors at the predicted mean (``jax.jacfwd`` of the measurement) and keeps P positive definite in Joseph's form.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from growjax.track.belief import Belief, Step, square_root, symmetric, update
from growjax.track.model import StateSpace


@dataclasses.dataclass(frozen=True)
class ExtendedKalman:
    """The extended Kalman filter (first-order linearisation of the transition and the sensors)."""

    name: str = "extended Kalman"

    def start(self, model: StateSpace, time) -> Belief:
        """The belief at rest at ``time`` (s): `growjax.track.model.StateSpace.initial`."""
        mean, cov = model.initial()
        return Belief(jnp.asarray(time, float), mean, cov)

    def step(self, model: StateSpace, belief: Belief, time, readings, inputs, breaks) -> tuple[Belief, Step]:
        """The belief at ``time`` (s) given the ``readings`` (m,) SI taken there (NaN: missing), over ``inputs``
        with their ``breaks``; and the step's record."""
        mean, jac, status = model.linearised_advance(belief.mean, inputs, belief.time, time, breaks)
        carried = jac @ square_root(belief.cov)
        cov = symmetric(carried @ carried.T + model.process_noise(time - belief.time))
        sd = model.noise_sd()
        predicted, h = _measurement(model, mean, time, inputs)
        hw = h / sd[:, None]
        post = update(mean, cov, predicted, hw @ cov @ hw.T, cov @ hw.T, readings, sd, jacobian=hw)
        record = Step(
            mean,
            cov,
            belief.cov @ jac.T,
            post.innovation,
            post.innovation_cov,
            jnp.isfinite(readings),
            post.nis,
            post.log_likelihood,
            status,
        )
        return Belief(jnp.asarray(time, float), post.mean, post.cov), record


def _measurement(model: StateSpace, mean, time, inputs):
    """(predicted readings (m,) SI, their Jacobian (m, N))."""

    def read(x):
        y = model.measure(x, time, inputs)
        return y, y

    jac, value = jax.jacfwd(read, has_aux=True)(mean)
    return value, jac


__all__ = ["ExtendedKalman"]
