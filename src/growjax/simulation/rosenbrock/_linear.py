"""The small dense linear algebra of a step: W⁻¹ and the Jacobian's variation check, for one run and for a batch.

One run inverts W by LAPACK, or in elementwise operations (`inverse`) where XLA:CPU is to compile the whole
loop into one kernel (`growjax.simulation.xla_flags`). A batch (under ``vmap``) writes both with the batch axis last, in
elementwise operations (``custom_vmap`` rules; for 250 6 × 6 matrices in a loop, measured: an inverse ~70 µs
against LAPACK's ~120 µs, a product ~12 µs against a batched ``dot``'s ~45 µs).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float


def inverse(m: Float[Array, "n n"]) -> Float[Array, "n n"]:
    """Inverse of a small square matrix (n, n) by Gauss–Jordan elimination with partial pivoting, unrolled over
    its n columns in elementwise operations (no LAPACK call: XLA:CPU can then compile the solver's whole loop
    into one kernel, `growjax.simulation.xla_flags`; without that option LAPACK is faster)."""
    n = m.shape[-1]
    rows = jnp.arange(n)[:, None]
    a = jnp.concatenate([m, jnp.eye(n, dtype=m.dtype)], axis=1)
    for k in range(n):
        size = jnp.where(rows[:, 0] >= k, jnp.abs(a[:, k]), -1.0)
        p = jnp.argmax(size)
        row_p = jnp.sum(jnp.where(rows == p, a, 0.0), axis=0)
        a = jnp.where(rows == p, a[k][None, :], a)  # swap rows k and p
        pivot = row_p / row_p[k]
        a = a - a[:, k : k + 1] * pivot[None, :]
        a = jnp.where(rows == k, pivot[None, :], a)
    return a[:, n:]


def product_last(a: Float[Array, "n m B"], b: Float[Array, "m k B"]) -> Float[Array, "n k B"]:
    """Products of two batches of matrices with the batch axis last: (n, m, B) @ (m, k, B) → (n, k, B)."""
    return sum(a[:, j, None, :] * b[None, j, :, :] for j in range(b.shape[0]))


def row_sums_max(m: Float[Array, "n n B"]) -> Float[Array, " B"]:
    """‖m‖∞ of a batch of matrices with the batch axis last (n, n, B) → (B,)."""
    return jnp.max(jnp.sum(jnp.abs(m), axis=1), axis=0)


def inverse_batch(m: Float[Array, "B n n"]) -> Float[Array, "B n n"]:
    """Inverses of a batch of small matrices (B, n, n) by Gauss–Jordan elimination with partial pivoting,
    with the batch axis last inside: every operation is elementwise over the batch. For 250 6 × 6 matrices in
    a loop: ~70 µs against ~120 µs for ``jnp.linalg.inv`` (LAPACK) on the same batch."""
    n = m.shape[-1]
    a = jnp.moveaxis(m, 0, -1)  # (n, n, B)
    unit = jnp.broadcast_to(jnp.eye(n, dtype=m.dtype)[:, :, None], a.shape)
    rows = [jnp.concatenate([a[i], unit[i]]) for i in range(n)]  # each (2n, B)
    for k in range(n):
        p = k + jnp.argmax(jnp.stack([jnp.abs(rows[r][k]) for r in range(k, n)]), axis=0)  # (B,)
        row_p = sum(jnp.where(p == r, rows[r], 0.0) for r in range(k, n))
        pivot = row_p / row_p[k]
        new = []
        for r in range(n):
            if r == k:
                new.append(pivot)
                continue
            src = rows[r] if r < k else jnp.where(p == r, rows[k], rows[r])  # row p takes row k's place
            new.append(src - src[k] * pivot)
        rows = new
    return jnp.moveaxis(jnp.stack([r[n:] for r in rows]), -1, 0)


def variation(w_inv: Float[Array, "n n"], dw: Float[Array, "n n"]) -> Float[Array, ""]:
    """Spectral radius of W₀⁻¹ (W₀ − W₁) for W₀⁻¹ = ``w_inv`` and W₀ − W₁ = ``dw`` (n, n): its ∞-norm, refined by
    `spectral_radius` where that bound exceeds 1 (a step is rejected above 1)."""
    change = w_inv @ dw
    bound = norm_inf(change)
    return jax.lax.cond(bound > 1.0, spectral_radius, lambda m: bound, change)


def spread(args: tuple[Any, ...], in_batched: tuple[Any, ...], axis_size: int) -> tuple[Any, ...]:
    """``custom_vmap`` arguments (a tuple of pytrees) with the unbatched leaves broadcast to the leading batch
    axis of size ``axis_size``; ``in_batched`` tells, per leaf, which are batched."""

    def one(x, batched):
        return x if batched else jnp.broadcast_to(x, (axis_size,) + jnp.shape(x))

    return jax.tree_util.tree_map(one, tuple(args), tuple(in_batched))


@jax.custom_batching.custom_vmap
def batchable_inverse(m: Float[Array, "n n"]) -> Float[Array, "n n"]:
    """W⁻¹ of one (n, n) matrix by LAPACK; of a batch (under ``vmap``) by `inverse_batch`."""
    return jnp.linalg.inv(m)


@batchable_inverse.def_vmap
def _inverse_rule(axis_size, in_batched, m):
    return inverse_batch(*spread((m,), in_batched, axis_size)), True


batchable_variation = jax.custom_batching.custom_vmap(variation)


@batchable_variation.def_vmap
def _variation_rule(axis_size, in_batched, w_inv, dw):
    """`variation` of a batch, its matrices with the batch axis last: elementwise operations instead of
    batched 6 × 6 products, and the refinement computed for every member (as a vmapped ``cond`` would)."""
    w_inv, dw = spread((w_inv, dw), in_batched, axis_size)
    change = product_last(jnp.moveaxis(w_inv, 0, -1), jnp.moveaxis(dw, 0, -1))
    bound = row_sums_max(change)
    return jnp.where(bound > 1.0, spectral_radius(change, norm=row_sums_max, product=product_last), bound), True


def norm_inf(m: Float[Array, "n n"]) -> Float[Array, ""]:
    """‖m‖∞ of a square matrix (n, n)."""
    return jnp.max(jnp.sum(jnp.abs(m), axis=1))


def spectral_radius(
    m: Float[Array, "n n *B"],
    squarings: int = 3,
    norm: Callable[[Array], Array] = norm_inf,
    product: Callable[[Array, Array], Array] = jnp.matmul,
) -> Float[Array, "*B"]:
    """Upper estimate of the spectral radius of a square matrix: ‖m^(2^k)‖∞^(1/2^k) (k squarings, rescaled).
    ``norm`` and ``product`` fit the layout: a batch with its axis last passes `row_sums_max` and
    `product_last` and gets (B,)."""
    log_scale = 0.0
    for _ in range(squarings):
        size = jnp.maximum(norm(m), 1e-300)
        m = m / size
        log_scale = 2.0 * (log_scale + jnp.log(size))
        m = product(m, m)
    return jnp.exp((log_scale + jnp.log(jnp.maximum(norm(m), 1e-300))) / 2**squarings)
