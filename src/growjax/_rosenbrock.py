"""An adaptive Rosenbrock integrator for the fast configuration, with dense output and a stop event.

A Rosenbrock method replaces the Newton iterations of an implicit Runge–Kutta method by one
linear solve per stage with W = I − hγJ, J = ∂f/∂y (Hairer & Wanner, IV.7)::

    W k_i = h f(t0 + α_i h, y0 + Σ_j α_ij k_j) + h J Σ_j γ_ij k_j + γ_i h² ∂f/∂t
    y1 = y0 + Σ b_i k_i,   error estimate Σ (b_i − b̂_i) k_i.

ROS34PW2 (Rang & Angermann 2005) is L-stable and stiffly accurate, so the stiff modes of the
hydraulics (opened bypass, ~1e5 s⁻¹; stepper rotor, ~3e5 s⁻¹) are damped at steps set by the
slow dynamics; it keeps every linear invariant of the field (the volume balance) to rounding.

Why not ``diffrax.diffeqsolve``: diffrax ships no Rosenbrock method, and a forward-mode
derivative through its loop is not under any step control. Here J is the exact Jacobian at the
step's start, held constant under differentiation (a W-method: order 3 for any matrix in place
of J, so the tangents are the same method applied to the sensitivity equations). A tangent step
is stable only while J stays close to the true Jacobian over the step, which fails where a stiff
mode switches on inside a step (the bypass opening). So every step also compares J at its end
with J at its start and is rejected unless ``h γ ‖J₁ − J₀‖∞ ≤ 1``: the step sequence depends only
on the primal solution, and the tangents it carries are stable and consistent. The end's J is the
next step's start's, so the check costs nothing extra.

In a batch (``batched``: a sweep) four choices differ, each measured a gain there (the first three a loss
in a single run; the fourth has no single-run form): the Jacobian and ∂f/∂t are taken in forward mode (the
primal once, then one tangent per state and for time) instead of by forward differences; the stages are a loop (one copy of the field
in the compiled program: a shorter compile); f, ∂f/∂t and J at t0 come from an opening attempt of
zero length, the loop's first, instead of a second copy of that code before the loop; and W⁻¹ and the
variation check are written with the batch axis last, in elementwise operations (``custom_vmap`` rules;
for 250 6 × 6 matrices in a loop, measured: an inverse ~70 µs against LAPACK's ~120 µs, a product ~12 µs
against a batched ``dot``'s ~45 µs; 500-set sweep 1.04 → 0.83 s). A run may also
interpolate its save times inside the loop (``save_ts``, used by batches) instead of recording every
step: a sweep member then carries (T, n) values, not the (max_steps, n) records whose per-member writes
and memory cost a 500-set sweep a fifth of its time.

Other choices: steps land on every declared input break (a jump is approached from the left and
left from the right, one ulp either side; a slope break is landed on); the accepted steps are
recorded, and the solution on the save grid is their cubic Hermite interpolant, evaluated after
the loop; a stop event (the pressure limit) is located by bisection on that interpolant.
Derivatives: forward mode (``jax.jvp``, ``jax.jacfwd``) through the loop; reverse mode is not
supported (the loop's length is not static).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

OK, EVENT, FAILED = 0, 1, 2


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


def hermite(t0, t1, y0, y1, f0, f1, t):
    """Cubic Hermite interpolant of one step at time ``t`` (exact values and slopes at both ends)."""
    h = t1 - t0
    s = jnp.clip((t - t0) / jnp.where(h > 0, h, 1.0), 0.0, 1.0)
    h00 = (1.0 + 2.0 * s) * (1.0 - s) ** 2
    h10 = s * (1.0 - s) ** 2
    h01 = s * s * (3.0 - 2.0 * s)
    h11 = s * s * (s - 1.0)
    return h00 * y0 + h10 * h * f0 + h01 * y1 + h11 * h * f1


def evaluate(steps: Steps, ts) -> jax.Array:
    """The dense solution at sorted times ``ts`` (T,) → (T, B, n); times beyond the last step get its end."""
    last = jnp.maximum(steps.count - 1, 0)
    i = jnp.clip(jnp.searchsorted(steps.t1, ts, side="left"), 0, last)

    def at(i, t):
        return hermite(steps.t0[i], steps.t1[i], steps.y0[i], steps.y1[i], steps.f0[i], steps.f1[i], t)

    return jax.vmap(at)(i, ts)


class Result(NamedTuple):
    """What :func:`integrate` returns. ``status``: 0 reached t1, 1 the event stopped it, 2 failed.

    ``y_final``: (B, n) the state block at ``t_final``.  ``saved``: (T, B, n) the dense solution at ``save_ts``
    (None without them; then ``steps`` holds every accepted step, else only the last).
    """

    steps: Steps
    t_final: jax.Array
    y_final: jax.Array
    status: jax.Array
    rejected: jax.Array
    saved: jax.Array | None = None


SAVE_WINDOW = 16  # most save times one step may cover when they are taken in the loop (``save_ts``)


class _Carry(NamedTuple):
    t: jax.Array
    y: jax.Array  # (B, n)
    f: jax.Array  # (B, n), the block field at (t⁺, y)
    jac: jax.Array  # (n, n), J(t⁺, y[0])
    f_t: jax.Array  # (B, n), ∂/∂t of the block field
    err: jax.Array  # error norm of the last accepted step (PI control)
    h: jax.Array  # proposed step, s
    rejected_last: jax.Array  # was the last attempt rejected?
    opened: jax.Array  # has the opening attempt (zero length) evaluated f, ∂f/∂t and J at t0?
    brk: jax.Array  # index of the next break
    steps: Steps
    status: jax.Array  # −1 running
    rejected: jax.Array
    saved: jax.Array | None  # (T + SAVE_WINDOW, B, n) the solution at the save times passed, padded
    next_save: jax.Array  # index of the first save time not yet passed


def _jacobian(field, t, y, f0, forward: bool = False):
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
    dy = _jacobian_steps(y)
    cols = jax.vmap(lambda d: field(t, y + d), out_axes=1)(jnp.diag(dy))
    return jax.lax.stop_gradient((cols - f0[:, None]) / dy[None, :])


def _forward_slopes(field, t, y, t_left=None):
    """(F, ∂F/∂t, J, F_left) of a plain run's field at (t, y) in forward mode: one ``jax.jvp`` along each state
    direction and along time, the primal evaluated once; F_left = F(t_left, y) (default F). ∂F/∂t is the
    derivative of the input's piece that starts at t. Shapes as the state block: (1, n), (1, n), (n, n), (1, n).

    Used for batches: there it costs less than the difference columns (500-set sweep 1.35 → 1.06 s), in a
    single run more (a 10 s simulation 18.5 → 28 ms, with the stage loop), at a longer compile (+1.6–2.1 s for the sweep).
    """
    t, y = jax.lax.stop_gradient((t, y))
    units = jnp.eye(y.shape[0] + 1, dtype=y.dtype)
    f, cols = jax.vmap(lambda e: jax.jvp(field, (t, y), (e[0], e[1:])), out_axes=(None, 1))(units)
    f_left = f if t_left is None else field(t_left, y)
    f_t, jac = jax.lax.stop_gradient((cols[:, 0], cols[:, 1:]))
    return f[None], f_t[None], jac, f_left[None]


def _jacobian_steps(y):
    """Forward-difference steps of the Jacobian's columns: √ε · max(|y|, 1)."""
    return jnp.sqrt(jnp.finfo(y.dtype).eps) * jnp.maximum(jnp.abs(jax.lax.stop_gradient(y)), 1.0)


def _time_step(t):
    return jnp.sqrt(jnp.finfo(jnp.result_type(t)).eps) * jnp.maximum(jnp.abs(t), 1.0)


def _inverse(m):
    """Inverse of a small square matrix (n, n) by Gauss–Jordan elimination with partial pivoting, unrolled over
    its n columns in elementwise operations (no LAPACK call: XLA:CPU can then compile the solver's whole loop
    into one kernel, :mod:`growjax.xla_flags`; without that option LAPACK is faster)."""
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


def _product_last(a, b):
    """Products of two batches of matrices with the batch axis last: (n, m, B) @ (m, k, B) → (n, k, B)."""
    return sum(a[:, j, None, :] * b[None, j, :, :] for j in range(b.shape[0]))


def _row_sums_max(m):
    """‖m‖∞ of a batch of matrices with the batch axis last (n, n, B) → (B,)."""
    return jnp.max(jnp.sum(jnp.abs(m), axis=1), axis=0)


def _inverse_batch(m):
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


def _variation(w_inv, dw):
    """Spectral radius of W₀⁻¹ (W₀ − W₁) for W₀⁻¹ = ``w_inv`` and W₀ − W₁ = ``dw`` (n, n): its ∞-norm, refined by
    :func:`_spectral_radius` where that bound exceeds 1 (a step is rejected above 1)."""
    change = w_inv @ dw
    bound = _norm_inf(change)
    return jax.lax.cond(bound > 1.0, _spectral_radius, lambda m: bound, change)


def spread(args, in_batched, axis_size: int):
    """``custom_vmap`` arguments (a tuple of pytrees) with the unbatched leaves broadcast to the batch's leading axis."""
    def one(x, batched):
        return x if batched else jnp.broadcast_to(x, (axis_size,) + jnp.shape(x))

    return jax.tree_util.tree_map(one, tuple(args), tuple(in_batched))


@jax.custom_batching.custom_vmap
def _batchable_inverse(m):
    """W⁻¹ of one (n, n) matrix by LAPACK; of a batch (under ``vmap``) by :func:`_inverse_batch`."""
    return jnp.linalg.inv(m)


@_batchable_inverse.def_vmap
def _inverse_rule(axis_size, in_batched, m):
    return _inverse_batch(*spread((m,), in_batched, axis_size)), True


_batchable_variation = jax.custom_batching.custom_vmap(_variation)


@_batchable_variation.def_vmap
def _variation_rule(axis_size, in_batched, w_inv, dw):
    """:func:`_variation` of a batch, its matrices with the batch axis last: elementwise operations instead of
    batched 6 × 6 products, and the refinement computed for every member (as a vmapped ``cond`` would)."""
    w_inv, dw = spread((w_inv, dw), in_batched, axis_size)
    change = _product_last(jnp.moveaxis(w_inv, 0, -1), jnp.moveaxis(dw, 0, -1))
    bound = _row_sums_max(change)
    return jnp.where(bound > 1.0, _spectral_radius(change, norm=_row_sums_max, product=_product_last), bound), True


def _norm_inf(m):
    """‖m‖∞ of a square matrix (n, n)."""
    return jnp.max(jnp.sum(jnp.abs(m), axis=1))


def _spectral_radius(m, squarings: int = 3, norm=_norm_inf, product=jnp.matmul):
    """Upper estimate of the spectral radius of a square matrix: ‖m^(2^k)‖∞^(1/2^k) (k squarings, rescaled).
    ``norm`` and ``product`` fit the layout: a batch with its axis last passes :func:`_row_sums_max` and
    :func:`_product_last` and gets (B,)."""
    log_scale = 0.0
    for _ in range(squarings):
        size = jnp.maximum(norm(m), 1e-300)
        m = m / size
        log_scale = 2.0 * (log_scale + jnp.log(size))
        m = product(m, m)
    return jnp.exp((log_scale + jnp.log(jnp.maximum(norm(m), 1e-300))) / 2**squarings)


def integrate(
    field: Callable,
    y0: jax.Array,
    t0: float,
    t1: float,
    *,
    args=None,
    breaks: jax.Array,
    jumps: jax.Array,
    rtol: float,
    atol: float,
    max_steps: int,
    tangent_field: Callable | None = None,
    s0: jax.Array | None = None,
    s_atol: jax.Array | None = None,
    s_rtol: float | None = None,
    forward_jacobian: bool = False,
    dt0: float = 1e-5,
    dtmax: float = 0.1,
    event: Callable | None = None,
    tableau: RosenbrockTableau = ROS34PW2,
    batched: bool = False,
    save_ts: jax.Array | None = None,
    small_loops: bool = False,
) -> Result:
    """Integrate y' = f(t, y) from t0 to t1 (y: flat (n,) array of states scaled to O(1)), and optionally
    its forward sensitivities S' = ∂f/∂y S + ∂f/∂θ d (one row per direction d) under the same error control.

    Args:
        field: f(t, y, args) → (n,).
        args: the field's parameters (a pytree), passed to every callback.
        breaks: sorted, distinct times (s) the steps land on (input jumps and slope breaks); any beyond t1 are ignored.
        jumps: bool flags, same shape: a jump (approached from the left, left from the right).
        rtol, atol: error control on the scaled states (weighted RMS norm).
        max_steps: budget of accepted steps (the size of the recorded dense solution).
        tangent_field: ``(t, y, S, args) → (f(t, y), S')`` with S of shape (p, n); None: no sensitivities.
        s0: (p, n) sensitivities at t0.  s_atol: (p,) absolute tolerance of each sensitivity row;
            s_rtol: their relative tolerance (default ``rtol``).
        forward_jacobian: with ``tangent_field``, the state's Jacobian in forward mode instead of by forward
            differences (:func:`_jacobian`).
        event: ``g(t, y, args)``, decreasing through zero where the run must stop (e.g. 1 − p/p_limit).
        batched: ``y0``, ``args``, ``breaks``, ``jumps`` (and ``s0``, ``s_atol``) carry a leading batch axis B
            of independent problems, stepped together: one loop while any member runs, each member's
            attempt a no-op once it has stopped, its steps written in place. (``jax.vmap`` of the
            unbatched loop would instead select between the old and new step records of every member
            at every attempt: O(B · max_steps) per attempt.) Every output gains the leading axis.
        save_ts: sorted times (T,) s (with ``batched``, (B, T)) at which to return the solution
            (``Result.saved``), interpolated in the loop as each step is taken, so that no step record is
            kept (only the last step, for the event). A step then covers at most ``SAVE_WINDOW`` of them
            (binding only where they lie closer than about dtmax / (SAVE_WINDOW − 1)); times beyond the end get its state.
        small_loops: a single run writes W⁻¹ in elementwise operations (:func:`_inverse`) instead of a LAPACK
            call, so that XLA:CPU can compile its whole loop into one kernel (:mod:`growjax.xla_flags`).

    The state block is (1 + p, n): row 0 the state, rows 1… the sensitivities. Every row shares
    W = I − hγJ, J the state's Jacobian (the block-diagonal W a W-method allows). The error norm
    is the largest of the rows' weighted RMS norms, so a sensitivity that the step cannot follow
    (a stiff mode switched on inside it) rejects the step.
    """
    y0 = jnp.asarray(y0)
    n = y0.shape[-1]
    dtype = y0.dtype
    alpha, gamma = jnp.asarray(tableau.alpha, dtype), jnp.asarray(tableau.gamma, dtype)
    c, gamma_sum = jnp.asarray(tableau.c, dtype), jnp.asarray(tableau.gamma_sum, dtype)
    b, b_err = jnp.asarray(tableau.b, dtype), jnp.asarray(tableau.b - tableau.b_hat, dtype)
    g = tableau.gamma_diag
    k_order = tableau.order
    inf = jnp.asarray(jnp.inf, dtype)
    eye = jnp.eye(n, dtype=dtype)
    t_start, t_end = jnp.asarray(t0, dtype), jnp.asarray(t1, dtype)

    saving = save_ts is not None
    # A batch takes f, ∂f/∂t and J at t0 from an opening attempt of zero length, the first of its loop: one
    # copy of their evaluation in the compiled program instead of two (500-set sweep: 1.4 s less compile).
    # A single run computes them before its loop: the opening's extra selects cost it 5 % (measured).
    opening = batched
    window = jnp.arange(SAVE_WINDOW)
    max_rows = 1 if saving else max_steps  # step records kept

    def problem(y0, args, breaks, jumps, s0, s_atol):
        """One member's (block start z0, absolute and relative tolerances, breaks, jump flags)."""
        if tangent_field is None:
            z0 = y0[None]
            tol_abs = jnp.full((1, 1), atol, dtype)
            tol_rel = jnp.full((1, 1), rtol, dtype)
        else:
            z0 = jnp.concatenate([y0[None], jnp.asarray(s0, dtype)])
            tol_abs = jnp.concatenate([jnp.full((1,), atol, dtype), jnp.asarray(s_atol, dtype)])[:, None]
            s_rel = rtol if s_rtol is None else s_rtol
            tol_rel = jnp.concatenate([jnp.full((1,), rtol, dtype), jnp.full((z0.shape[0] - 1,), s_rel, dtype)])[:, None]
        breaks = jnp.concatenate([jnp.asarray(breaks, dtype).ravel(), jnp.full((1,), jnp.inf, dtype)])
        jumps = jnp.concatenate([jnp.asarray(jumps, bool).ravel(), jnp.zeros((1,), bool)])
        return z0, tol_abs, tol_rel, breaks, jumps

    def block(t, z, args):
        if tangent_field is None:
            return field(t, z[0], args)[None]
        f, ds = tangent_field(t, z[0], z[1:], args)
        return jnp.concatenate([f[None], ds])

    def block_slopes(t, z, args, t_left=None):
        """(F, ∂F/∂t, J, F_left) at (t, z): the block field, its time derivative (forward difference), the
        state's Jacobian and the block field at ``t_left`` (default t). The block's evaluations are one
        vmapped call (each copy of the field in the program costs compile time), F_left apart in one run.
        A batch without sensitivities takes them in forward mode instead (:func:`_forward_slopes`)."""
        if tangent_field is None and batched:
            return _forward_slopes(lambda t, y: field(t, y, args), t, z[0], t_left)
        dt = _time_step(t)
        # The left limit differs from F only across a jump. One run evaluates it there alone (a branch);
        # a batch, whose members' branches would all be taken, in the same call.
        left_in_call = batched and t_left is not None
        times = jnp.stack([t, t + dt, t_left] if left_in_call else [t, t + dt])
        m = times.shape[0]
        if tangent_field is None:  # the Jacobian's columns join the same call
            y = z[0]
            dy = _jacobian_steps(y)
            points = jnp.concatenate([jnp.broadcast_to(y, (m, n)), jax.lax.stop_gradient(y) + jnp.diag(dy)])
            values = jax.vmap(field, in_axes=(0, 0, None))(jnp.concatenate([times, jnp.full((n,), t)]), points, args)
            fs = values[:m, None]
            jac = jax.lax.stop_gradient((values[m:].T - jax.lax.stop_gradient(values[0])[:, None]) / dy[None, :])
        else:
            fs = jax.vmap(block, in_axes=(0, None, None))(times, z, args)
            jac = _jacobian(lambda t, y: field(t, y, args), t, z[0], fs[0, 0], forward_jacobian)
        f = fs[0]
        f_t = jax.lax.stop_gradient((fs[1] - jax.lax.stop_gradient(f)) / dt)
        if left_in_call:
            f_left = fs[2]
        elif t_left is None:
            f_left = f
        else:
            f_left = jax.lax.cond(t_left == t, lambda: f, lambda: block(t_left, z, args))
        return f, f_t, jac, f_left

    def init(z0, args, breaks, ts):
        if opening:
            f_first, f_t0, jac0 = jnp.zeros_like(z0), jnp.zeros_like(z0), jnp.zeros((n, n), dtype)
        else:
            f_first, f_t0, jac0, _ = block_slopes(t_start, z0, args)
        zeros_m = jnp.zeros((max_rows,) + z0.shape, dtype)
        steps0 = Steps(jnp.full((max_rows,), inf), jnp.full((max_rows,), inf), zeros_m, zeros_m, zeros_m, zeros_m,
                       jnp.asarray(0))
        first_break = jnp.searchsorted(breaks, t_start, side="right")
        saved = None if ts is None else jnp.zeros((ts.shape[0],) + z0.shape, dtype)
        return _Carry(t_start, z0, f_first, jac0, f_t0, jnp.asarray(1.0, dtype), jnp.asarray(dt0, dtype),
                      jnp.asarray(False), jnp.asarray(not opening), first_break, steps0, jnp.asarray(-1), jnp.asarray(0), saved,
                      jnp.asarray(0))

    def attempt(prob, carry: _Carry):
        _, tol_abs, tol_rel, breaks, jumps, ts, args = prob
        live = carry.status < 0  # False only for a finished member of a batch
        t, y, f0, jac, f_t = carry.t, carry.y, carry.f, carry.jac, carry.f_t
        h = jnp.minimum(carry.h, t_end - t)
        if saving:  # the step may cover SAVE_WINDOW save times at most
            reach = ts[carry.next_save + SAVE_WINDOW - 1] - t
            capped = reach < h
            h = jnp.where(capped, jnp.maximum(reach, 0.0), h)
        if opening:
            h = jnp.where(carry.opened, h, 0.0)
        t_break, is_jump = breaks[carry.brk], jumps[carry.brk]
        on_break = (t + h >= t_break - 1e-12 * jnp.maximum(1.0, jnp.abs(t_break))) & (t_break < t_end)
        is_jump = on_break & is_jump
        # Land on a slope break; stop one ulp short of a jump (the input there is its left limit).
        t_next = jnp.where(on_break, jnp.where(is_jump, jnp.nextafter(t_break, -inf), t_break), t + h)
        t_next = jnp.where(t + h >= t_end, t_end, t_next)
        h = jax.lax.stop_gradient(t_next - t)

        w_inv = (_batchable_inverse if batched else _inverse if small_loops else jnp.linalg.inv)(eye - (h * g) * jac)

        def stage(i, ks, fi):
            rhs = h * fi + (gamma_sum[i] * h * h) * f_t + h * (jnp.tensordot(gamma[i], ks, 1) @ jac.T)
            return ks.at[i].set(rhs @ w_inv.T)

        def next_stage(i, ks):
            return stage(i, ks, block(t + c[i] * h, y + jnp.tensordot(alpha[i], ks, 1), args))

        ks = stage(0, jnp.zeros((tableau.stages,) + y.shape, dtype), f0)
        if batched:  # one copy of the field in the program for all stages: a shorter compile, as fast a batch
            ks = jax.lax.fori_loop(1, tableau.stages, next_stage, ks)
        else:  # unrolled: faster in a single run (10 s simulation 15.6 instead of 18.5 ms)
            for i in range(1, tableau.stages):
                ks = next_stage(i, ks)
        y1 = y + jnp.tensordot(b, ks, 1)
        err = jnp.tensordot(b_err, ks, 1)
        scale = tol_abs + tol_rel * jnp.maximum(jnp.abs(y), jnp.abs(y1))
        err_norm = jax.lax.stop_gradient(jnp.max(jnp.sqrt(jnp.mean((err / scale) ** 2, axis=1))))

        # The field after the step: its right limit starts the next step; across a jump, the left limit
        # closes this step's interpolant.
        t_after = jnp.where(is_jump, jnp.nextafter(t_break, inf), t_next)
        f1, f_t1, jac1, f1_left = block_slopes(t_after, y1, args, t_next)
        # J must describe the field over the whole step (see the module docstring).
        variation = jax.lax.stop_gradient((_batchable_variation if batched else _variation)(w_inv, (h * g) * (jac1 - jac)))
        variation = jnp.where(is_jump, 0.0, variation)  # across a jump J may change: the step ends there
        finite = jnp.all(jnp.isfinite(y1)) & jnp.isfinite(err_norm) & jnp.all(jnp.isfinite(jac1))
        accept = live & finite & (err_norm <= 1.0) & (variation <= 1.0)

        # PI step-size control (Gustafsson; gains 0.6/k, 0.2/k measured best here), no growth right after a rejection.
        safe_err = jnp.maximum(err_norm, 1e-10)
        factor = 0.9 * safe_err ** (-0.6 / k_order) * carry.err ** (0.2 / k_order)
        factor = jnp.clip(factor, 0.2, 5.0)
        factor = jnp.where(accept & carry.rejected_last, jnp.minimum(factor, 1.0), factor)
        factor = jnp.where(variation > 1.0, jnp.minimum(factor, jnp.maximum(0.7 / variation, 0.1)), factor)
        factor = jnp.where(finite, factor, 0.25)
        h_new = jnp.minimum(jax.lax.stop_gradient(h * factor), dtmax)
        # After a step shortened onto a break, keep the size the controller had proposed.
        shortened = (on_break | capped) if saving else on_break
        h_new = jnp.where(accept & shortened, jnp.maximum(h_new, jnp.minimum(carry.h, dtmax)), h_new)
        taken = accept  # a step of the solution (not the opening attempt)
        if opening:
            h_new = jnp.where(carry.opened, h_new, carry.h)  # the opening attempt leaves the first step's size
            taken = accept & carry.opened

        # The row after the last accepted step is scratch: written by every live attempt, kept by an accepted one.
        k = carry.steps.count
        row = 0 if saving else jnp.minimum(k, max_steps - 1)
        st = carry.steps
        written = (taken & live) if saving else live  # one row kept when saving: the last step

        def put(buffer, value):  # a stopped member rewrites its row unchanged
            return buffer.at[row].set(jnp.where(written, value, buffer[row]))

        saved, next_save = carry.saved, carry.next_save
        if saving:  # the save times this step covers, from its cubic Hermite interpolant
            t_save = ts[next_save + window]
            covered = taken & live & (t_save <= t_next)
            values = jax.vmap(lambda ti: hermite(t, t_next, y, y1, f0, f1_left, ti))(t_save)
            # The whole window is written: the rows past those covered are rewritten by the next step taken
            # (its window starts at or before them), or by ``finish`` after the last.
            saved = jax.lax.dynamic_update_slice_in_dim(saved, values, next_save, 0)
            next_save = next_save + jnp.sum(covered)

        new_steps = Steps(put(st.t0, t), put(st.t1, t_next), put(st.y0, y), put(st.y1, y1), put(st.f0, f0),
                          put(st.f1, f1_left), k + jnp.where(taken, 1, 0))
        status = carry.status
        if event is not None:
            status = jnp.where(taken & (event(t_next, y1[0], args) < 0.0), EVENT, status)
        status = jnp.where(taken & (t_next >= t_end) & (status < 0), OK, status)
        too_small = live & ~accept & (h_new < 1e-14 * jnp.maximum(1.0, jnp.abs(t)))
        out_of_budget = taken & (k + 1 >= max_steps) & (status < 0)
        status = jnp.where(too_small | out_of_budget, FAILED, status)
        err_kept = jnp.maximum(err_norm, 1e-4)
        if opening:
            status = jnp.where(live & ~accept & ~carry.opened, FAILED, status)  # f or J not finite at t0
            err_kept = jnp.where(carry.opened, err_kept, carry.err)
        keep = jax.tree_util.tree_map(lambda new, old: jnp.where(accept, new, old),
                                      (t_after, y1, f1, jac1, f_t1, err_kept),
                                      (t, y, f0, jac, f_t, carry.err))
        return _Carry(*keep, h=jnp.where(live, h_new, carry.h), rejected_last=jnp.where(live, ~accept, carry.rejected_last),
                      opened=(carry.opened | live) if opening else carry.opened,
                      brk=carry.brk + jnp.where(accept & on_break, 1, 0), steps=new_steps, status=status,
                      rejected=carry.rejected + jnp.where(live & ~accept, 1, 0), saved=saved, next_save=next_save)

    def finish(prob, final: _Carry):
        t_final, y_final = final.t, final.y
        if event is not None:
            args = prob[-1]
            last = final.steps._replace(count=jnp.minimum(final.steps.count, 1)) if saving else final.steps
            t_final, y_final = _locate_event(lambda t, y: event(t, y, args), last, final.status == EVENT, y_final)
            if saving:  # the one record kept is the last step taken: none if the run failed at once
                t_final = jnp.where(final.status == EVENT, t_final, final.t)
        saved = None
        if saving:  # save times after the last step taken get its end state
            n_save = final.saved.shape[0] - SAVE_WINDOW
            passed = (jnp.arange(n_save) < final.next_save).reshape((-1,) + (1,) * final.y.ndim)
            saved = jnp.where(passed, final.saved[:n_save], final.y)
        return Result(final.steps, t_final, y_final, final.status, final.rejected, saved)

    def padded(ts):  # SAVE_WINDOW times after the last, so that every window of them lies inside
        return None if ts is None else jnp.concatenate([jnp.asarray(ts, dtype), jnp.full((SAVE_WINDOW,), inf, dtype)])

    if not batched:
        prob = (*problem(y0, args, breaks, jumps, s0, s_atol), padded(save_ts), args)
        final = jax.lax.while_loop(lambda c: c.status < 0, functools.partial(attempt, prob),
                                   init(prob[0], args, prob[3], prob[5]))
        return finish(prob, final)
    probs = jax.vmap(problem)(y0, args, breaks, jumps, s0, s_atol)
    probs = (*probs, None if save_ts is None else jax.vmap(padded)(save_ts), args)
    carry0 = jax.vmap(init)(probs[0], args, probs[3], probs[5])
    final = jax.lax.while_loop(lambda c: jnp.any(c.status < 0), lambda c: jax.vmap(attempt)(probs, c), carry0)
    return jax.vmap(finish)(probs, final)


def _locate_event(event, steps: Steps, occurred, y_final, iterations: int = 60):
    """(time, state block) where the event's root lies inside the last step, by bisection on its interpolant."""
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
