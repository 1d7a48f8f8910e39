"""A stop event's location: the root of g(t, y) inside the step that crossed it, on that step's interpolant."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from growjax.simulation.rosenbrock._saving import Steps, hermite


def locate_event(
    event: Callable[[Float[Array, ""], Float[Array, " n"]], Float[Array, ""]],
    steps: Steps,
    occurred: Bool[ArrayLike, ""],
    y_final: Float[Array, "B n"],
    iterations: int = 60,
) -> tuple[Float[Array, ""], Float[Array, "B n"]]:
    """(time s, state block (B, n)) where ``event(t, y)`` (decreasing through zero) has its root inside the last
    recorded step, by bisection on its cubic Hermite interpolant of the state (row 0); where not ``occurred``, that
    step's end and ``y_final``."""
    last = jnp.maximum(steps.count - 1, 0)
    t0, t1 = steps.t0[last], steps.t1[last]
    y0, y1, f0, f1 = steps.y0[last], steps.y1[last], steps.f0[last], steps.f1[last]

    def g(t):
        return event(t, hermite(t0, t1, y0[0], y1[0], f0[0], f1[0], t))

    def bisect(_, bracket):
        lo, hi = bracket
        mid = 0.5 * (lo + hi)
        above = g(mid) >= 0.0
        return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

    _lo, hi = jax.lax.fori_loop(0, iterations, bisect, jax.lax.stop_gradient((t0, t1)))
    t_cross = jnp.where(occurred, hi, t1)
    return t_cross, jnp.where(occurred, hermite(t0, t1, y0, y1, f0, f1, t_cross), y_final)
