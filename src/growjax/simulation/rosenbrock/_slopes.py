"""The field a step needs at one point: the block field F (state and sensitivities), ∂F/∂t and the state's
Jacobian J, all held constant under differentiation except F (a W-method: see `growjax.simulation.rosenbrock`).

The state block z is (1 + p, n): row 0 the state, rows 1… its sensitivities (p = 0 without them).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float


def block(
    field: Callable, tangent_field: Callable | None, t: Float[ArrayLike, ""], z: Float[Array, "1+p n"], args: Any
) -> Float[Array, "1+p n"]:
    """The block field at (t, z) (1 + p, n): ``field(t, y, args)`` (n,) alone, or with the sensitivities' slopes
    from ``tangent_field(t, y, S, args)`` → (f, S')."""
    if tangent_field is None:
        return field(t, z[0], args)[None]
    f, ds = tangent_field(t, z[0], z[1:], args)
    return jnp.concatenate([f[None], ds])


def jacobian(
    field: Callable, t: Float[ArrayLike, ""], y: Float[Array, " n"], f0: Float[Array, " n"], forward: bool = False
) -> Float[Array, "n n"]:
    """J = ∂f/∂y at (t, y), held constant under differentiation: by forward differences from f0 = f(t, y),
    or in forward mode (``forward``: one ``jax.jvp`` per column, the primal evaluated once).

    A W-method needs no exact Jacobian, only one that holds the stiff modes. Differences of the primal
    field (one batched evaluation) cost a third of a forward-mode Jacobian when this solver was written
    (published growth law); where the field solves the rod balance by Newton (the Lockhart law), each
    difference column repeats that solve, and forward mode, whose tangents are implicit, is cheaper.
    """
    t, y, f0 = jax.lax.stop_gradient((t, y, f0))
    if forward:
        units = jnp.eye(y.shape[0], dtype=y.dtype)
        cols = jax.vmap(lambda e: jax.jvp(lambda x: field(t, x), (y,), (e,))[1], out_axes=1)(units)
        return jax.lax.stop_gradient(cols)
    dy = jacobian_steps(y)
    cols = jax.vmap(lambda d: field(t, y + d), out_axes=1)(jnp.diag(dy))
    return jax.lax.stop_gradient((cols - f0[:, None]) / dy[None, :])


def forward_slopes(
    field: Callable, t: Float[ArrayLike, ""], y: Float[Array, " n"], t_left: Float[ArrayLike, ""] | None = None
) -> tuple[Float[Array, "1 n"], Float[Array, "1 n"], Float[Array, "n n"], Float[Array, "1 n"]]:
    """(F, ∂F/∂t, J, F_left) of a plain run's field at (t, y) in forward mode: one ``jax.jvp`` along each state
    direction and along time, the primal evaluated once; F_left = F(t_left, y) (default F). ∂F/∂t is the
    derivative of the input's piece that starts at t. Shapes as the state block: (1, n), (1, n), (n, n), (1, n).

    Used for batches, where it costs less than the difference columns; in a single run it costs more, and it
    compiles longer (``benchmarks/simulate.py``).
    """
    t, y = jax.lax.stop_gradient((t, y))
    units = jnp.eye(y.shape[0] + 1, dtype=y.dtype)
    f, cols = jax.vmap(lambda e: jax.jvp(field, (t, y), (e[0], e[1:])), out_axes=(None, 1))(units)
    f_left = f if t_left is None else field(t_left, y)
    f_t, jac = jax.lax.stop_gradient((cols[:, 0], cols[:, 1:]))
    return f[None], f_t[None], jac, f_left[None]


def jacobian_steps(y: Float[Array, " n"]) -> Float[Array, " n"]:
    """Forward-difference steps of the Jacobian's columns: √ε · max(|y|, 1)."""
    return jnp.sqrt(jnp.finfo(y.dtype).eps) * jnp.maximum(jnp.abs(jax.lax.stop_gradient(y)), 1.0)


def time_step(t: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """Forward-difference step of ∂F/∂t, s: √ε · max(|t|, 1)."""
    return jnp.sqrt(jnp.finfo(jnp.result_type(t)).eps) * jnp.maximum(jnp.abs(t), 1.0)


def block_slopes(
    field: Callable,
    tangent_field: Callable | None,
    t: Float[ArrayLike, ""],
    z: Float[Array, "1+p n"],
    args: Any,
    t_left: Float[ArrayLike, ""] | None = None,
    *,
    batched: bool,
    forward_jacobian: bool,
) -> tuple[Float[Array, "1+p n"], Float[Array, "1+p n"], Float[Array, "n n"], Float[Array, "1+p n"]]:
    """(F, ∂F/∂t, J, F_left) at (t, z): the block field (1 + p, n), its time derivative (forward difference,
    (1 + p, n)), the state's Jacobian (n, n) and the block field at ``t_left`` (default t). The block's evaluations
    are one vmapped call (each copy of the field in the program costs compile time), F_left apart in one run.
    A batch (``batched``) without sensitivities takes them in forward mode instead (`forward_slopes`);
    ``forward_jacobian``: with sensitivities, J in forward mode (`jacobian`)."""
    if tangent_field is None and batched:
        return forward_slopes(lambda t, y: field(t, y, args), t, z[0], t_left)
    n = z.shape[-1]
    dt = time_step(t)
    # The left limit differs from F only across a jump. One run evaluates it there alone (a branch);
    # a batch, whose members' branches would all be taken, in the same call.
    left_in_call = batched and t_left is not None
    times = jnp.stack([t, t + dt, t_left] if left_in_call else [t, t + dt])
    m = times.shape[0]
    if tangent_field is None:  # the Jacobian's columns join the same call
        y = z[0]
        dy = jacobian_steps(y)
        points = jnp.concatenate([jnp.broadcast_to(y, (m, n)), jax.lax.stop_gradient(y) + jnp.diag(dy)])
        values = jax.vmap(field, in_axes=(0, 0, None))(jnp.concatenate([times, jnp.full((n,), t)]), points, args)
        fs = values[:m, None]
        jac = jax.lax.stop_gradient((values[m:].T - jax.lax.stop_gradient(values[0])[:, None]) / dy[None, :])
    else:
        fs = jax.vmap(functools.partial(block, field, tangent_field), in_axes=(0, None, None))(times, z, args)
        jac = jacobian(lambda t, y: field(t, y, args), t, z[0], fs[0, 0], forward_jacobian)
    f = fs[0]
    f_t = jax.lax.stop_gradient((fs[1] - jax.lax.stop_gradient(f)) / dt)
    if left_in_call:
        f_left = fs[2]
    elif t_left is None:
        f_left = f
    else:
        f_left = jax.lax.cond(t_left == t, lambda: f, lambda: block(field, tangent_field, t_left, z, args))
    return f, f_t, jac, f_left
