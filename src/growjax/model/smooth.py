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
from jaxtyping import Array, ArrayLike, Float

__all__ = ["bracketed_root", "newton_root", "smooth_abs_power", "smooth_ramp", "smooth_step"]


def smooth_ramp(x: Float[ArrayLike, "*b"], width: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """C¹ version of max(x, 0): 0 for x ≤ 0, x²/(2w) on (0, w), x − w/2 beyond.

    Args:
        x: the argument, in any unit.
        width: w > 0, the transition band, in the unit of ``x``.

    Returns:
        The ramp, in the unit of ``x``.
    """
    xc = jnp.clip(x, 0.0, width)
    return jnp.where(x >= width, x - 0.5 * width, 0.5 * xc * xc / width)


def smooth_step(x: Float[ArrayLike, "*b"], width: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """C¹ step from 0 (x ≤ 0) to 1 (x ≥ w), cubic in between.

    Args:
        x: the argument, in any unit.
        width: w > 0, the transition band, in the unit of ``x``.

    Returns:
        The step, in [0, 1].
    """
    s = jnp.clip(x / width, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def smooth_abs_power(
    x: Float[ArrayLike, "*b"], exponent: Float[ArrayLike, "*b"], eps: Float[ArrayLike, "*b"]
) -> Float[Array, "*b"]:
    """Signed power sign(x)|x|^a, regularised so the slope at 0 is finite: x (x² + ε²)^((a−1)/2).

    Args:
        x: the argument.
        exponent: a.
        eps: ε > 0, the regularisation, in the unit of ``x``.

    Returns:
        The regularised power.
    """
    return x * (x * x + eps * eps) ** (0.5 * (exponent - 1.0))


def _implicit_tangent(g, y):
    return y / g(jnp.ones_like(y))


def newton_root(
    residual: Callable[[Float[Array, "*b"]], Float[Array, "*b"]], x0: Float[ArrayLike, "*b"], iterations: int
) -> Float[Array, "*b"]:
    """Root of a smooth scalar residual by unrolled Newton steps, for well-conditioned residuals with a close start
    (an inverse law, a nearly linear balance).

    Derivatives are implicit (``jax.lax.custom_root``), never through the iterations.

    Args:
        residual: the function whose root is sought, elementwise.
        x0: the start.
        iterations: the Newton steps taken.

    Returns:
        The root.
    """

    def solve(f, x):
        for _ in range(iterations):
            fx, dfx = jax.jvp(f, (x,), (jnp.ones_like(x),))
            x = x - fx / dfx
        return x

    return jax.lax.custom_root(residual, x0, solve, _implicit_tangent)


def _safeguarded_newton_step(f, x, lo, hi):
    """One step for a decreasing f: shrink [lo, hi] around the root, then Newton if it stays inside, else bisect."""
    fx, dfx = jax.jvp(f, (x,), (jnp.ones_like(x),))
    lo = jnp.where(fx > 0, x, lo)
    hi = jnp.where(fx > 0, hi, x)
    newton = x - fx / jnp.where(dfx < 0, dfx, -1.0)
    ok = (dfx < 0) & (newton >= lo) & (newton <= hi)
    x_new = jnp.where(fx == 0, x, jnp.where(ok, newton, 0.5 * (lo + hi)))
    return x_new, lo, hi


def bracketed_root(
    residual: Callable[[Float[Array, "*b"]], Float[Array, "*b"]],
    lower: Float[ArrayLike, "*b"],
    upper: Float[ArrayLike, "*b"],
    *,
    x0: Float[ArrayLike, "*b"] | None = None,
    max_iter: int = 60,
    xtol: float = 1e-13,
    atol: float = 0.0,
) -> Float[Array, "*b"]:
    """Root of a scalar, monotonically decreasing residual on a bracket.

    Newton steps are taken while they stay inside the shrinking bracket, bisection otherwise, so the iteration
    cannot diverge. Differentiation uses the implicit function theorem (``jax.lax.custom_root``), not the
    iterations.

    Args:
        residual: the function whose root is sought; the caller guarantees
            ``residual(lower) ≥ 0 ≥ residual(upper)``.
        lower: one end of the bracket.
        upper: the other end.
        x0: the start; default the midpoint.
        max_iter: the most steps.
        xtol: stop when a step or the bracket falls below ``xtol`` × the bracket's magnitude + ``atol``.
        atol: in the unit of x; needed where the bracket can shrink to nothing (e.g. at an equilibrium).

    Returns:
        The root.
    """

    def solve(f, x0):
        def cond(carry):
            _, lo, hi, step, it = carry
            tol = xtol * (jnp.abs(hi) + jnp.abs(lo)) + atol
            return (it < max_iter) & (jnp.abs(step) > tol) & (hi - lo > tol)

        def body(carry):
            x, lo, hi, _, it = carry
            x_new, lo, hi = _safeguarded_newton_step(f, x, lo, hi)
            return x_new, lo, hi, x_new - x, it + 1

        lo, hi = jnp.minimum(lower, upper), jnp.maximum(lower, upper)
        init = (x0, lo, hi, jnp.asarray(jnp.inf, x0.dtype), 0)
        return jax.lax.while_loop(cond, body, init)[0]

    start = 0.5 * (lower + upper) if x0 is None else jnp.clip(x0, jnp.minimum(lower, upper), jnp.maximum(lower, upper))
    return jax.lax.custom_root(residual, jax.lax.stop_gradient(start), solve, _implicit_tangent)
