"""Dense output: the accepted steps' records, their cubic Hermite interpolant, and the save times a run
interpolates inside its loop (``save_ts``) instead of recording every step.

Shapes: M the rows of step records, B × n the state block (row 0 the state, rows 1… its sensitivities),
T the save times.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int

SAVE_WINDOW = 16  # most save times one step may cover when they are taken in the loop (``save_ts``)


class Steps(NamedTuple):
    """The accepted steps of a run, padded to the step budget M (rows from ``count`` on are scratch).

    ``t0``, ``t1``: (M,) s.  ``y0``, ``y1``: (M, B, n) the state block at both ends (row 0 the state,
    rows 1… its sensitivities).  ``f0``, ``f1``: (M, B, n) their slopes (right limit at t0, left limit at t1).
    ``count``: accepted steps.
    """

    t0: jax.Array
    t1: jax.Array
    y0: jax.Array
    y1: jax.Array
    f0: jax.Array
    f1: jax.Array
    count: jax.Array


def hermite(
    t0: Float[ArrayLike, ""],
    t1: Float[ArrayLike, ""],
    y0: Float[Array, "*s"],
    y1: Float[Array, "*s"],
    f0: Float[Array, "*s"],
    f1: Float[Array, "*s"],
    t: Float[ArrayLike, ""],
) -> Float[Array, "*s"]:
    """Cubic Hermite interpolant of one step (t0, t1) s at time ``t`` s, exact at both ends: values y0, y1 and
    slopes f0, f1 (per s), each shaped as the state (block)."""
    h = t1 - t0
    s = jnp.clip((t - t0) / jnp.where(h > 0, h, 1.0), 0.0, 1.0)
    h00 = (1.0 + 2.0 * s) * (1.0 - s) ** 2
    h10 = s * (1.0 - s) ** 2
    h01 = s * s * (3.0 - 2.0 * s)
    h11 = s * s * (s - 1.0)
    return h00 * y0 + h10 * h * f0 + h01 * y1 + h11 * h * f1


def evaluate(steps: Steps, ts: Float[ArrayLike, " T"]) -> Float[Array, "T B n"]:
    """The dense solution at sorted times ``ts`` (T,) → (T, B, n); times beyond the last step get its end."""
    last = jnp.maximum(steps.count - 1, 0)
    i = jnp.clip(jnp.searchsorted(steps.t1, ts, side="left"), 0, last)

    def at(i, t):
        return hermite(steps.t0[i], steps.t1[i], steps.y0[i], steps.y1[i], steps.f0[i], steps.f1[i], t)

    return jax.vmap(at)(i, ts)


def no_steps(rows: int, shape: tuple[int, int], dtype: jnp.dtype) -> Steps:
    """Empty records of ``rows`` steps of a state block of ``shape`` (B, n): times +∞, states zero."""
    inf = jnp.asarray(jnp.inf, dtype)
    zeros = jnp.zeros((rows,) + tuple(shape), dtype)
    return Steps(jnp.full((rows,), inf), jnp.full((rows,), inf), zeros, zeros, zeros, zeros, jnp.asarray(0))


def record(
    steps: Steps,
    row: Int[ArrayLike, ""],
    written: Bool[ArrayLike, ""],
    taken: Bool[ArrayLike, ""],
    t: Float[Array, ""],
    t_next: Float[Array, ""],
    y: Float[Array, "B n"],
    y1: Float[Array, "B n"],
    f0: Float[Array, "B n"],
    f1: Float[Array, "B n"],
) -> Steps:
    """``steps`` with the step (t, t_next) s, its ends' blocks y, y1 and slopes f0, f1 (B, n) written to ``row``
    where ``written`` (else the row rewritten unchanged), and counted where ``taken``."""

    def put(buffer, value):
        return buffer.at[row].set(jnp.where(written, value, buffer[row]))

    return Steps(
        put(steps.t0, t),
        put(steps.t1, t_next),
        put(steps.y0, y),
        put(steps.y1, y1),
        put(steps.f0, f0),
        put(steps.f1, f1),
        steps.count + jnp.where(taken, 1, 0),
    )


def padded(ts: Float[ArrayLike, " T"] | None, dtype: jnp.dtype) -> Float[Array, " T+W"] | None:
    """Save times (T,) followed by SAVE_WINDOW times +∞, so that every window of them lies inside (None: None)."""
    return None if ts is None else jnp.concatenate([jnp.asarray(ts, dtype), jnp.full((SAVE_WINDOW,), jnp.inf, dtype)])


def window_cap(
    ts: Float[Array, " T+W"], next_save: Int[Array, ""], t: Float[Array, ""], h: Float[Array, ""]
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """(h, capped): a step of proposed size ``h`` s from ``t`` s shortened to cover SAVE_WINDOW save times at most,
    ``next_save`` the index of the first not yet passed in the padded ``ts``."""
    reach = ts[next_save + SAVE_WINDOW - 1] - t
    capped = reach < h
    return jnp.where(capped, jnp.maximum(reach, 0.0), h), capped


def save_covered(
    saved: Float[Array, "T+W B n"],
    next_save: Int[Array, ""],
    ts: Float[Array, " T+W"],
    taken: Bool[ArrayLike, ""],
    t: Float[Array, ""],
    t_next: Float[Array, ""],
    y: Float[Array, "B n"],
    y1: Float[Array, "B n"],
    f0: Float[Array, "B n"],
    f1: Float[Array, "B n"],
) -> tuple[Float[Array, "T+W B n"], Int[Array, ""]]:
    """(saved, next_save) after the step (t, t_next) s, ``taken`` or not: the save times it covers interpolated
    from its ends' blocks y, y1 and slopes f0, f1 (B, n) into ``saved`` (T + SAVE_WINDOW, B, n)."""
    t_save = ts[next_save + jnp.arange(SAVE_WINDOW)]
    covered = taken & (t_save <= t_next)
    values = jax.vmap(lambda ti: hermite(t, t_next, y, y1, f0, f1, ti))(t_save)
    # The whole window is written: the rows past those covered are rewritten by the next step taken
    # (its window starts at or before them), or by ``saved_after`` after the last.
    saved = jax.lax.dynamic_update_slice_in_dim(saved, values, next_save, 0)
    return saved, next_save + jnp.sum(covered)


def saved_after(
    saved: Float[Array, "T+W B n"], next_save: Int[Array, ""], y_end: Float[Array, "B n"]
) -> Float[Array, "T B n"]:
    """The solution at the save times (T, B, n) from a loop's ``saved`` (T + SAVE_WINDOW, B, n): the times after
    the last step taken (index ``next_save`` on) get its end state ``y_end`` (B, n)."""
    n_save = saved.shape[0] - SAVE_WINDOW
    passed = (jnp.arange(n_save) < next_save).reshape((-1,) + (1,) * y_end.ndim)
    return jnp.where(passed, saved[:n_save], y_end)
