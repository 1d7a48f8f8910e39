"""The Rosenbrock method: its coefficients as data, and one step's stage solves with its error estimate.

A step of an s-stage Rosenbrock (W-)method with W⁻¹ = (I − hγJ)⁻¹ given (Hairer & Wanner, IV.7)::

    W k_i = h f(t0 + α_i h, y0 + Σ_j α_ij k_j) + h J Σ_j γ_ij k_j + γ_i h² ∂f/∂t
    y1 = y0 + Σ b_i k_i,   error estimate Σ (b_i − b̂_i) k_i.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


@dataclasses.dataclass(frozen=True)
class RosenbrockTableau:
    """Coefficients of an s-stage Rosenbrock method (lower-triangular ``alpha``, ``gamma``; diagonal ``gamma_diag``)."""

    gamma_diag: float
    alpha: np.ndarray  # (s, s), strictly lower
    gamma: np.ndarray  # (s, s), strictly lower
    b: np.ndarray  # (s,) solution weights
    b_hat: np.ndarray  # (s,) embedded weights
    order: int

    @property
    def stages(self) -> int:
        return self.b.size

    @property
    def c(self) -> np.ndarray:
        """Stage times α_i = Σ_j α_ij (fractions of the step)."""
        return self.alpha.sum(axis=1)

    @property
    def gamma_sum(self) -> np.ndarray:
        """γ_i = γ + Σ_j γ_ij, the weights of the time derivative."""
        return self.gamma_diag + self.gamma.sum(axis=1)

    def coefficients(self, dtype: jnp.dtype) -> Coefficients:
        """The coefficients a step uses, as arrays of ``dtype``."""
        return Coefficients(
            jnp.asarray(self.alpha, dtype),
            jnp.asarray(self.gamma, dtype),
            jnp.asarray(self.c, dtype),
            jnp.asarray(self.gamma_sum, dtype),
            jnp.asarray(self.b, dtype),
            jnp.asarray(self.b - self.b_hat, dtype),
            self.gamma_diag,
            self.order,
            self.stages,
        )


class Coefficients(NamedTuple):
    """A tableau's coefficients as arrays: ``alpha``, ``gamma`` (s, s); ``c``, ``gamma_sum``, ``b`` and the error
    weights ``b_err`` = b − b̂ (s,); the diagonal γ, the order and the number of stages s."""

    alpha: jax.Array
    gamma: jax.Array
    c: jax.Array
    gamma_sum: jax.Array
    b: jax.Array
    b_err: jax.Array
    gamma_diag: float
    order: int
    stages: int


def _ros34pw2() -> RosenbrockTableau:
    # Rang & Angermann (2005), BIT 45: order 3 (embedded 2), L-stable, stiffly accurate W-method.
    g = 0.435866521508459
    alpha = np.zeros((4, 4))
    alpha[1, 0] = 0.87173304301691801
    alpha[2, 0], alpha[2, 1] = 0.84457060015369423, -0.11299064236484185
    alpha[3, 2] = 1.0
    gamma = np.zeros((4, 4))
    gamma[1, 0] = -0.87173304301691801
    gamma[2, 0], gamma[2, 1] = -0.90338057013044082, 0.054180672388095326
    gamma[3, 0], gamma[3, 1], gamma[3, 2] = 0.24212380706095346, -1.2232505839045147, 0.54526025533510214
    b = np.array([0.24212380706095346, -1.2232505839045147, 1.5452602553351020, g])
    b_hat = np.array([0.37810903145819369, -0.096042292212423178, 0.5, 0.2179332607542295])
    return RosenbrockTableau(g, alpha, gamma, b, b_hat, 3)


ROS34PW2 = _ros34pw2()


def step(
    coef: Coefficients,
    block: Callable,
    t: Float[Array, ""],
    y: Float[Array, "B n"],
    f0: Float[Array, "B n"],
    f_t: Float[Array, "B n"],
    jac: Float[Array, "n n"],
    w_inv: Float[Array, "n n"],
    h: Float[Array, ""],
    args: Any,
    looped: bool,
) -> tuple[Float[Array, "B n"], Float[Array, "B n"]]:
    """(y1, error estimate) of one step of size ``h`` s from (t, y), both shaped as the block y (B, n).

    ``block(t, z, args)`` is the block field; ``f0`` (B, n) its value at (t⁺, y), ``f_t`` (B, n) its time
    derivative, ``jac`` (n, n) the state's Jacobian and ``w_inv`` (n, n) = (I − hγJ)⁻¹. ``looped``: the stages
    after the first are a ``fori_loop`` (one copy of the field in the compiled program: a shorter compile, as fast
    in a batch) instead of unrolled (faster in a single run: a 10 s simulation 15.6 instead of 18.5 ms).
    """

    def stage(i, ks, fi):
        rhs = h * fi + (coef.gamma_sum[i] * h * h) * f_t + h * (jnp.tensordot(coef.gamma[i], ks, 1) @ jac.T)
        return ks.at[i].set(rhs @ w_inv.T)

    def next_stage(i, ks):
        return stage(i, ks, block(t + coef.c[i] * h, y + jnp.tensordot(coef.alpha[i], ks, 1), args))

    ks = stage(0, jnp.zeros((coef.stages,) + y.shape, y.dtype), f0)
    if looped:
        ks = jax.lax.fori_loop(1, coef.stages, next_stage, ks)
    else:
        for i in range(1, coef.stages):
            ks = next_stage(i, ks)
    return y + jnp.tensordot(coef.b, ks, 1), jnp.tensordot(coef.b_err, ks, 1)
