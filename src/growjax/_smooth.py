"""Smooth (C¹) replacements for thresholds, plus a bracketed scalar root solver.

diffrax needs a smooth vector field: every switch of the reference model (valve
cracking, spool reversal, end stops) is written with the C¹ primitives below.
Each is exact outside a transition band of stated width, so the reference model
is reproduced wherever the state is more than one band-width from a switch.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp


def smooth_ramp(x, width):
    """C¹ version of max(x, 0): 0 for x ≤ 0, x²/(2w) on (0, w), x − w/2 beyond."""
    xc = jnp.clip(x, 0.0, width)
    return jnp.where(x >= width, x - 0.5 * width, 0.5 * xc * xc / width)


def smooth_step(x, width):
    """C¹ step from 0 (x ≤ 0) to 1 (x ≥ w), cubic in between."""
    s = jnp.clip(x / width, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def smooth_abs_power(x, exponent, eps):
    """Signed power sign(x)|x|^a, regularised so the slope at 0 is finite: x (x² + ε²)^((a−1)/2)."""
    return x * (x * x + eps * eps) ** (0.5 * (exponent - 1.0))


def _safeguarded_newton_step(f, x, lo, hi):
    """One step for a decreasing f: shrink [lo, hi] around the root, then Newton if it stays inside, else bisect."""
    fx, dfx = jax.jvp(f, (x,), (jnp.ones_like(x),))
    lo = jnp.where(fx > 0, x, lo)
    hi = jnp.where(fx > 0, hi, x)
    newton = x - fx / jnp.where(dfx < 0, dfx, -1.0)
    ok = (dfx < 0) & (newton > lo) & (newton < hi)
    x_new = jnp.where(fx == 0, x, jnp.where(ok, newton, 0.5 * (lo + hi)))
    return x_new, lo, hi


def bracketed_root(
    residual: Callable, lower, upper, *, max_iter: int = 60, xtol: float = 1e-13
):
    """Root of a scalar, monotonically decreasing ``residual`` on ``[lower, upper]``.

    The caller guarantees ``residual(lower) ≥ 0 ≥ residual(upper)``. Newton steps
    are taken while they stay inside the shrinking bracket, bisection otherwise,
    so the iteration cannot diverge. Differentiation uses the implicit function
    theorem (``jax.lax.custom_root``), not the iterations.
    """

    def solve(f, x0):
        def cond(carry):
            _, lo, hi, step, it = carry
            scale = jnp.maximum(jnp.abs(hi) + jnp.abs(lo), 1e-300)
            return (it < max_iter) & (jnp.abs(step) > xtol * scale) & (hi - lo > xtol * scale)

        def body(carry):
            x, lo, hi, _, it = carry
            x_new, lo, hi = _safeguarded_newton_step(f, x, lo, hi)
            return x_new, lo, hi, x_new - x, it + 1

        lo, hi = jnp.minimum(lower, upper), jnp.maximum(lower, upper)
        init = (x0, lo, hi, jnp.asarray(jnp.inf, x0.dtype), 0)
        return jax.lax.while_loop(cond, body, init)[0]

    def tangent_solve(g, y):
        return y / g(jnp.ones_like(y))

    x0 = 0.5 * (lower + upper)
    return jax.lax.custom_root(residual, x0, solve, tangent_solve)


def unrolled_root(residual: Callable, lower, upper, *, iterations: int = 12):
    """Root of a scalar, monotonically decreasing ``residual`` on ``[lower, upper]``, in a fixed number of steps.

    Like :func:`bracketed_root` (Newton inside a shrinking bracket, bisection otherwise,
    implicit differentiation), but with ``iterations`` steps unrolled: no data-dependent
    loop, so under ``vmap`` and inside a fixed-step scan it fuses into straight-line code.
    Use it where the residual is well conditioned enough to converge in that many steps.
    """

    def solve(f, x0):
        lo, hi = jnp.minimum(lower, upper), jnp.maximum(lower, upper)
        x = x0
        for _ in range(iterations):
            x, lo, hi = _safeguarded_newton_step(f, x, lo, hi)
        return x

    def tangent_solve(g, y):
        return y / g(jnp.ones_like(y))

    return jax.lax.custom_root(residual, 0.5 * (lower + upper), solve, tangent_solve)
