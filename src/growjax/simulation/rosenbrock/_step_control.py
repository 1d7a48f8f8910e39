"""Step control: where a step ends (on the input's breaks), its error norm, and the next step's size.

Steps land on every declared input break: a jump is approached from the left and left from the right, one ulp
either side (the input at a step's end is its left limit there); a slope break is landed on.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float


def land(
    t: Float[Array, ""],
    h: Float[Array, ""],
    t_end: Float[ArrayLike, ""],
    t_break: Float[Array, ""],
    is_jump: Bool[Array, ""],
) -> tuple[Float[Array, ""], Float[Array, ""], Bool[Array, ""], Bool[Array, ""]]:
    """Where a step of proposed size ``h`` s from ``t`` s ends, with the next break at ``t_break`` s (a jump if
    ``is_jump``) and the run's end at ``t_end`` s. Returns (t_next, t_after, on_break, is_jump): the step's end,
    the time the next step starts from (one ulp past a jump landed on, else t_next), whether it lands on the break
    and whether that is a jump."""
    on_break = (t + h >= t_break - 1e-12 * jnp.maximum(1.0, jnp.abs(t_break))) & (t_break < t_end)
    is_jump = on_break & is_jump
    inf = jnp.asarray(jnp.inf, jnp.result_type(t_break))
    # Land on a slope break; stop one ulp short of a jump (the input there is its left limit).
    t_next = jnp.where(on_break, jnp.where(is_jump, jnp.nextafter(t_break, -inf), t_break), t + h)
    t_next = jnp.where(t + h >= t_end, t_end, t_next)
    t_after = jnp.where(is_jump, jnp.nextafter(t_break, inf), t_next)
    return t_next, t_after, on_break, is_jump


def error_norm(
    err: Float[Array, "B n"],
    y: Float[Array, "B n"],
    y1: Float[Array, "B n"],
    tol_abs: Float[ArrayLike, "B 1"],
    tol_rel: Float[ArrayLike, "B 1"],
) -> Float[Array, ""]:
    """The step's error norm: the largest of the block's rows' weighted RMS norms of ``err`` (B, n), weights
    ``tol_abs + tol_rel · max(|y|, |y1|)`` (tolerances (B, 1)); accepted at ≤ 1."""
    scale = tol_abs + tol_rel * jnp.maximum(jnp.abs(y), jnp.abs(y1))
    return jax.lax.stop_gradient(jnp.max(jnp.sqrt(jnp.mean((err / scale) ** 2, axis=1))))


def next_size(
    h: Float[Array, ""],
    err_norm: Float[Array, ""],
    *,
    err_prev: Float[Array, ""],
    order: int,
    accept: Bool[Array, ""],
    rejected_last: Bool[Array, ""],
    variation: Float[Array, ""],
    finite: Bool[Array, ""],
    shortened: Bool[Array, ""],
    h_proposed: Float[Array, ""],
    dtmax: float,
) -> Float[Array, ""]:
    """The size (s) of the next attempt after one of size ``h`` s with error norm ``err_norm``.

    PI control (Gustafsson; gains 0.6/k, 0.2/k for a method of order k, measured best here) on ``err_prev``, the
    last accepted step's norm; no growth right after a rejection (``rejected_last``); a shrink below 0.7 /
    ``variation`` where the Jacobian varied too much over the step; a quarter where the step was not ``finite``;
    at most ``dtmax``. After an accepted step ``shortened`` onto a break (or a save window's end), the size
    the controller had proposed, ``h_proposed``, is kept.
    """
    safe_err = jnp.maximum(err_norm, 1e-10)
    factor = 0.9 * safe_err ** (-0.6 / order) * err_prev ** (0.2 / order)
    factor = jnp.clip(factor, 0.2, 5.0)
    factor = jnp.where(accept & rejected_last, jnp.minimum(factor, 1.0), factor)
    factor = jnp.where(variation > 1.0, jnp.minimum(factor, jnp.maximum(0.7 / variation, 0.1)), factor)
    factor = jnp.where(finite, factor, 0.25)
    h_new = jnp.minimum(jax.lax.stop_gradient(h * factor), dtmax)
    return jnp.where(accept & shortened, jnp.maximum(h_new, jnp.minimum(h_proposed, dtmax)), h_new)
