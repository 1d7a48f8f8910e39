"""Linearly implicit Rosenbrock solvers for diffrax (diffrax ships none).

A Rosenbrock method replaces the Newton iterations of an implicit Runge–Kutta method by
one linear solve per stage with W = I − hγJ, J ≈ ∂f/∂y. With an
L-stable, stiffly accurate tableau it damps the stiff modes of the hydraulics (opened
bypass, platform, motor rotor) at steps set by the slow dynamics, with no inner iteration
and no convergence failure. Each stage is (Hairer & Wanner, IV.7)::

    W k_i = h f(t0 + α_i h, y0 + Σ_j α_ij k_j) + h J Σ_j γ_ij k_j + γ_i h² ∂f/∂t
    y1 = y0 + Σ b_i k_i,   error estimate Σ (b_i − b̂_i) k_i.

Rosenbrock methods preserve every linear invariant of the vector field (a volume
balance), as exact Jacobians give c·J = 0 whenever c·f ≡ 0. Dense output is the quadratic
through the step's ends and its initial slope (no extra evaluation of the vector field).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np


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


class QuadraticInterpolation(diffrax.AbstractLocalInterpolation):
    """y(t0 + θh) = y0 + θ k0 + θ² (y1 − y0 − k0), k0 = h f(t0, y0): exact at both ends, O(h³) inside."""

    t0: jax.Array
    t1: jax.Array
    y0: jax.Array
    y1: jax.Array
    k0: jax.Array

    def evaluate(self, t0, t1=None, left=True):
        if t1 is not None:
            return self.evaluate(t1) - self.evaluate(t0)
        theta = (t0 - self.t0) / (self.t1 - self.t0)
        return self.y0 + theta * self.k0 + theta * theta * (self.y1 - self.y0 - self.k0)


def jacobian(f, t0, y0, h):
    """J ≈ ∂f/∂y and ∂f/∂t at (t0, y0) by forward differences, from one batched evaluation of ``f(t, y)``.

    A W-method needs no exact Jacobian (its order holds for any matrix), only one that
    captures the stiff modes. The increments are √ε relative to each state (states are scaled
    to O(1)) and √ε·h in time. No derivative flows through the result: under differentiation
    J is a constant, i.e. the W-method is applied to the sensitivity equations too.
    """
    t0, y0, h = jax.lax.stop_gradient((t0, y0, h))
    n = y0.shape[0]
    eps = jnp.sqrt(jnp.finfo(y0.dtype).eps)
    dy = eps * jnp.maximum(jnp.abs(y0), 1.0)
    dt = eps * jnp.maximum(jnp.abs(h), 1e-12)
    ts = jnp.concatenate([jnp.stack([t0, t0 + dt]), jnp.full((n,), t0)])
    ys = jnp.concatenate([jnp.stack([y0, y0]), y0 + jnp.diag(dy)])
    fs = jax.lax.stop_gradient(jax.vmap(f)(ts, ys))
    return ((fs[2:] - fs[0]) / dy[:, None]).T, (fs[1] - fs[0]) / dt


class Rosenbrock(diffrax.AbstractAdaptiveSolver):
    """A Rosenbrock solver for ``diffrax.ODETerm`` (state: a flat 1-D array).

    The Jacobian and ∂f/∂t come from one batched evaluation of f at the start of each step
    (:func:`jacobian`); W⁻¹ is formed once and applied to every stage. Under differentiation
    the Jacobian is a constant: ROS34PW2 is a W-method (order 3 for any matrix in place of J),
    so the derivatives are those of the same method applied to the sensitivity equations,
    consistent to third order, without the second derivatives of f that differentiating J
    would cost. (HMC stays exact with them: its leapfrog is reversible and volume-preserving for
    any position-dependent force.)
    """

    tableau: ClassVar[RosenbrockTableau] = ROS34PW2
    term_structure: ClassVar = diffrax.AbstractTerm
    interpolation_cls: ClassVar = QuadraticInterpolation

    def order(self, terms):
        return self.tableau.order

    def error_order(self, terms):
        return self.tableau.order

    def init(self, terms, t0, t1, y0, args):
        return None

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        tab = self.tableau
        h = t1 - t0
        n = y0.shape[0]

        def f(t, y):
            return terms.vf(t, y, args)

        f0 = f(t0, y0)
        frozen = jax.tree_util.tree_map(lambda a: jax.lax.stop_gradient(a) if eqx.is_array(a) else a, args)
        jac, f_t = jacobian(lambda t, y: terms.vf(t, y, frozen), t0, y0, h)
        eye = jnp.eye(n, dtype=y0.dtype)
        w_inv = jnp.linalg.inv(eye - (h * tab.gamma_diag) * jac)
        alpha, gamma = jnp.asarray(tab.alpha, y0.dtype), jnp.asarray(tab.gamma, y0.dtype)
        c, gamma_sum = jnp.asarray(tab.c, y0.dtype), jnp.asarray(tab.gamma_sum, y0.dtype)

        def stage_k(fi, i, ks):
            return w_inv @ (h * fi + (gamma_sum[i] * h * h) * f_t + h * (jac @ (gamma[i] @ ks)))

        k0 = stage_k(f0, 0, jnp.zeros((tab.stages, n), y0.dtype))
        ks0 = jnp.zeros((tab.stages, n), y0.dtype).at[0].set(k0)

        def later_stage(ks, i):
            # One traced evaluation of f serves every later stage (a smaller program to compile).
            fi = f(t0 + c[i] * h, y0 + alpha[i] @ ks)
            return ks.at[i].set(stage_k(fi, i, ks)), None

        ks, _ = jax.lax.scan(later_stage, ks0, jnp.arange(1, tab.stages))
        ks = [ks[i] for i in range(tab.stages)]
        y1 = y0 + sum(tab.b[i] * ks[i] for i in range(tab.stages))
        y_error = sum((tab.b[i] - tab.b_hat[i]) * ks[i] for i in range(tab.stages))
        dense_info = dict(y0=y0, y1=y1, k0=h * f0)
        return y1, y_error, dense_info, None, diffrax.RESULTS.successful
