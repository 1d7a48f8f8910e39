"""The driver: `integrate` steps a Rosenbrock method from t0 to t1, one run or a batch in one loop, composing
its stage solves (`_method`), the field's slopes (`_slopes`), W⁻¹ and the variation check
(`_linear`), step control (`_step_control`), saving (`_saving`) and the stop event (`_events`).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

import growjax.simulation.rosenbrock._linear as linear
import growjax.simulation.rosenbrock._method as method
import growjax.simulation.rosenbrock._saving as saving
import growjax.simulation.rosenbrock._slopes as slopes
from growjax.simulation.rosenbrock._events import locate_event
from growjax.simulation.rosenbrock._method import ROS34PW2, RosenbrockTableau
from growjax.simulation.rosenbrock._step_control import error_norm, land, next_size

OK = 0
"""Status: the integration reached its end."""
EVENT = 1
"""Status: the stop event ended the integration."""
FAILED = 2
"""Status: the step budget ran out or a step failed."""


class Result(NamedTuple):
    """What `integrate` returns. ``status``: 0 reached t1, 1 the event stopped it, 2 failed.

    ``y_final``: (B, n) the state block at ``t_final``.  ``saved``: (T, B, n) the dense solution at ``save_ts``
    (None without them; then ``steps`` holds every accepted step, else only the last).
    """

    steps: saving.Steps
    t_final: jax.Array
    y_final: jax.Array
    status: jax.Array
    rejected: jax.Array
    saved: jax.Array | None = None


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
    steps: saving.Steps
    status: jax.Array  # −1 running
    rejected: jax.Array
    saved: jax.Array | None  # (T + SAVE_WINDOW, B, n) the solution at the save times passed, padded
    next_save: jax.Array  # index of the first save time not yet passed


@dataclasses.dataclass(frozen=True)
class _Setup:
    """What every attempt of one `integrate` call shares (its arguments of the same names)."""

    block: Callable  # (t, z, args) → the block field (B, n)
    slopes: Callable  # (t, z, args, t_left=None) → (F, ∂F/∂t, J, F_left): slopes.block_slopes
    coef: method.Coefficients
    t_start: jax.Array  # s
    t_end: jax.Array  # s
    rtol: float
    atol: float
    s_rtol: float | None
    sensitivities: bool  # a tangent field is given
    max_steps: int
    dt0: float
    dtmax: float
    event: Callable | None
    batched: bool
    saving: bool  # save times are given
    small_loops: bool
    dtype: jnp.dtype

    @property
    def opening(self) -> bool:
        """A batch takes f, ∂f/∂t and J at t0 from an opening attempt of zero length, the first of its loop: one
        copy of their evaluation in the compiled program instead of two (500-set sweep: 1.4 s less compile).
        A single run computes them before its loop: the opening's extra selects cost it 5 % (measured)."""
        return self.batched


def integrate(
    field: Callable,
    y0: jax.Array,
    t0: float,
    t1: float,
    *,
    args: Any = None,
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
    """Integrate y' = f(t, y) from t0 to t1 (s), and optionally its forward sensitivities S' = ∂f/∂y S + ∂f/∂θ d
    (one row per direction d) under the same error control.

    The state block is (1 + p, n): row 0 the state, rows 1… the sensitivities, every row sharing W = I − hγJ, J
    the state's Jacobian (the block-diagonal W a W-method allows). The error norm is the largest of the rows'
    weighted RMS norms, so a sensitivity the step cannot follow (a stiff mode switched on inside it) rejects it.

    Args:
        field: f(t, y, args) → (n,), y a flat (n,) array of states scaled to O(1).
        y0: (n,) the state at t0.
        t0: the start, s.
        t1: the end, s.
        args: the field's parameters (a pytree), passed to every callback.
        breaks: sorted, distinct times (s) the steps land on (input jumps and slope breaks); any beyond t1 ignored.
        jumps: bool flags, the shape of ``breaks``: a jump (approached from the left, left from the right).
        rtol: relative tolerance on the scaled states (weighted RMS norm).
        atol: absolute tolerance on the scaled states.
        max_steps: budget of accepted steps (the size of the recorded dense solution).
        tangent_field: ``(t, y, S, args) → (f(t, y), S')`` with S of shape (p, n); None: no sensitivities.
        s0: (p, n) sensitivities at t0.
        s_atol: (p,) absolute tolerance of each sensitivity row.
        s_rtol: their relative tolerance (default ``rtol``).
        forward_jacobian: with ``tangent_field``, the state's Jacobian in forward mode, not by forward differences.
        dt0: the first step, s.
        dtmax: the largest step, s.
        event: ``g(t, y, args)``, decreasing through zero where the run must stop (e.g. 1 − p/p_limit).
        tableau: the Rosenbrock method.
        batched: ``y0``, ``args``, ``breaks``, ``jumps`` (and ``s0``, ``s_atol``) carry a leading batch axis B
            of independent problems, stepped together in one loop while any member runs (each member's attempt a
            no-op once it has stopped, its steps written in place). Every output gains the leading axis.
        save_ts: (T,) sorted times, s ((B, T) with ``batched``), at which to return the solution (``Result.saved``),
            interpolated as each step is taken, so that no step record is kept (only the last step, for the
            event). A step then covers at most ``SAVE_WINDOW`` of them (binding only where they lie closer than
            about dtmax / (SAVE_WINDOW − 1)); times beyond the end get its state.
        small_loops: a single run writes W⁻¹ in elementwise operations (`inverse`) instead of a LAPACK call, so
            that XLA:CPU can compile its whole loop into one kernel (`growjax.simulation.xla_flags`).

    Returns:
        The `Result`.
    """
    y0 = jnp.asarray(y0)
    settings = dict(rtol=rtol, atol=atol, s_rtol=s_rtol, max_steps=max_steps, dt0=dt0, dtmax=dtmax, event=event)
    flags = dict(forward_jacobian=forward_jacobian, tableau=tableau, batched=batched, small_loops=small_loops)
    s = _setup(field, tangent_field, y0.dtype, t0, t1, saving=save_ts is not None, **flags, **settings)
    if not batched:
        return _run_one(s, y0, args, breaks, jumps, s0, s_atol, save_ts)
    return _run_batch(s, y0, args, breaks, jumps, s0, s_atol, save_ts)


def _setup(field, tangent_field, dtype, t0, t1, *, forward_jacobian, tableau, batched, **settings) -> _Setup:
    """The `_Setup` of one `integrate` call (``settings``: its fields of the same names)."""
    return _Setup(
        block=functools.partial(slopes.block, field, tangent_field),
        slopes=functools.partial(
            slopes.block_slopes, field, tangent_field, batched=batched, forward_jacobian=forward_jacobian
        ),
        coef=tableau.coefficients(dtype),
        t_start=jnp.asarray(t0, dtype),
        t_end=jnp.asarray(t1, dtype),
        sensitivities=tangent_field is not None,
        batched=batched,
        dtype=dtype,
        **settings,
    )


def _run_one(s: _Setup, y0, args, breaks, jumps, s0, s_atol, save_ts) -> Result:
    """One run's loop of attempts, and its result."""
    prob = (*_problem(s, y0, breaks, jumps, s0, s_atol), saving.padded(save_ts, s.dtype), args)
    final = jax.lax.while_loop(
        lambda c: c.status < 0, functools.partial(_attempt, s, prob), _init(s, prob[0], args, prob[3], prob[5])
    )
    return _finish(s, prob, final)


def _run_batch(s: _Setup, y0, args, breaks, jumps, s0, s_atol, save_ts) -> Result:
    """A batch's one loop of attempts while any member runs, and the members' results."""
    probs = jax.vmap(functools.partial(_problem, s))(y0, breaks, jumps, s0, s_atol)
    probs = (
        *probs,
        None if save_ts is None else jax.vmap(functools.partial(saving.padded, dtype=s.dtype))(save_ts),
        args,
    )
    carry0 = jax.vmap(functools.partial(_init, s))(probs[0], args, probs[3], probs[5])
    final = jax.lax.while_loop(
        lambda c: jnp.any(c.status < 0), lambda c: jax.vmap(functools.partial(_attempt, s))(probs, c), carry0
    )
    return jax.vmap(functools.partial(_finish, s))(probs, final)


def _problem(s: _Setup, y0, breaks, jumps, s0, s_atol):
    """One member's block start z0 (1 + p, n), absolute and relative tolerances (1 + p, 1), and its breaks and
    jump flags closed by one more at +∞."""
    dtype = s.dtype
    if not s.sensitivities:
        z0 = y0[None]
        tol_abs = jnp.full((1, 1), s.atol, dtype)
        tol_rel = jnp.full((1, 1), s.rtol, dtype)
    else:
        z0 = jnp.concatenate([y0[None], jnp.asarray(s0, dtype)])
        tol_abs = jnp.concatenate([jnp.full((1,), s.atol, dtype), jnp.asarray(s_atol, dtype)])[:, None]
        s_rel = s.rtol if s.s_rtol is None else s.s_rtol
        tol_rel = jnp.concatenate([jnp.full((1,), s.rtol, dtype), jnp.full((z0.shape[0] - 1,), s_rel, dtype)])[:, None]
    breaks = jnp.concatenate([jnp.asarray(breaks, dtype).ravel(), jnp.full((1,), jnp.inf, dtype)])
    jumps = jnp.concatenate([jnp.asarray(jumps, bool).ravel(), jnp.zeros((1,), bool)])
    return z0, tol_abs, tol_rel, breaks, jumps


def _init(s: _Setup, z0, args, breaks, ts) -> _Carry:
    """The loop's carry at t0 for block start ``z0``, ``breaks`` (closed at +∞) and padded save times ``ts``."""
    n, dtype = z0.shape[-1], s.dtype
    if s.opening:
        f_first, f_t0, jac0 = jnp.zeros_like(z0), jnp.zeros_like(z0), jnp.zeros((n, n), dtype)
    else:
        f_first, f_t0, jac0, _ = s.slopes(s.t_start, z0, args)
    steps0 = saving.no_steps(1 if s.saving else s.max_steps, z0.shape, dtype)  # one row kept when saving: the last step
    first_break = jnp.searchsorted(breaks, s.t_start, side="right")
    saved = None if ts is None else jnp.zeros((ts.shape[0],) + z0.shape, dtype)
    return _Carry(
        s.t_start,
        z0,
        f_first,
        jac0,
        f_t0,
        jnp.asarray(1.0, dtype),
        jnp.asarray(s.dt0, dtype),
        jnp.asarray(False),
        jnp.asarray(not s.opening),
        first_break,
        steps0,
        jnp.asarray(-1),
        jnp.asarray(0),
        saved,
        jnp.asarray(0),
    )


def _attempt(s: _Setup, prob, carry: _Carry) -> _Carry:
    """The carry after one attempted step of one member, accepted or rejected (unchanged once it has stopped)."""
    _, tol_abs, tol_rel, breaks, jumps, ts, args = prob
    live = carry.status < 0  # False only for a finished member of a batch
    t, y, f0, jac, f_t = carry.t, carry.y, carry.f, carry.jac, carry.f_t
    h = jnp.minimum(carry.h, s.t_end - t)
    if s.saving:  # the step may cover SAVE_WINDOW save times at most
        h, capped = saving.window_cap(ts, carry.next_save, t, h)
    if s.opening:
        h = jnp.where(carry.opened, h, 0.0)
    t_next, t_after, on_break, is_jump = land(t, h, s.t_end, breaks[carry.brk], jumps[carry.brk])
    h = jax.lax.stop_gradient(t_next - t)

    g = s.coef.gamma_diag
    invert = linear.batchable_inverse if s.batched else linear.inverse if s.small_loops else jnp.linalg.inv
    w_inv = invert(jnp.eye(y.shape[-1], dtype=s.dtype) - (h * g) * jac)
    y1, err = method.step(s.coef, s.block, t, y, f0, f_t, jac, w_inv, h, args, looped=s.batched)
    err_norm = error_norm(err, y, y1, tol_abs, tol_rel)

    # The field after the step: its right limit starts the next step; across a jump, the left limit
    # closes this step's interpolant.
    f1, f_t1, jac1, f1_left = s.slopes(t_after, y1, args, t_next)
    # J must describe the field over the whole step (see the package docstring).
    vary = linear.batchable_variation if s.batched else linear.variation
    variation = jax.lax.stop_gradient(vary(w_inv, (h * g) * (jac1 - jac)))
    variation = jnp.where(is_jump, 0.0, variation)  # across a jump J may change: the step ends there
    finite = jnp.all(jnp.isfinite(y1)) & jnp.isfinite(err_norm) & jnp.all(jnp.isfinite(jac1))
    accept = live & finite & (err_norm <= 1.0) & (variation <= 1.0)

    h_new = next_size(
        h,
        err_norm,
        err_prev=carry.err,
        order=s.coef.order,
        accept=accept,
        rejected_last=carry.rejected_last,
        variation=variation,
        finite=finite,
        shortened=(on_break | capped) if s.saving else on_break,
        h_proposed=carry.h,
        dtmax=s.dtmax,
    )
    taken = accept  # a step of the solution (not the opening attempt)
    if s.opening:
        h_new = jnp.where(carry.opened, h_new, carry.h)  # the opening attempt leaves the first step's size
        taken = accept & carry.opened

    # The row after the last accepted step is scratch: written by every live attempt, kept by an accepted one;
    # when saving, the one row is the last step taken.
    row = 0 if s.saving else jnp.minimum(carry.steps.count, s.max_steps - 1)
    written = (taken & live) if s.saving else live
    steps = saving.record(carry.steps, row, written, taken, t, t_next, y, y1, f0, f1_left)
    saved, next_save = carry.saved, carry.next_save
    if s.saving:  # the save times this step covers, from its cubic Hermite interpolant
        saved, next_save = saving.save_covered(saved, next_save, ts, taken & live, t, t_next, y, y1, f0, f1_left)
    status, err_kept = _outcome(s, carry, args, live, accept, taken, t_next, y1, h_new, err_norm)
    keep = jax.tree_util.tree_map(
        lambda new, old: jnp.where(accept, new, old),
        (t_after, y1, f1, jac1, f_t1, err_kept),
        (t, y, f0, jac, f_t, carry.err),
    )
    return _Carry(
        *keep,
        h=jnp.where(live, h_new, carry.h),
        rejected_last=jnp.where(live, ~accept, carry.rejected_last),
        opened=(carry.opened | live) if s.opening else carry.opened,
        brk=carry.brk + jnp.where(accept & on_break, 1, 0),
        steps=steps,
        status=status,
        rejected=carry.rejected + jnp.where(live & ~accept, 1, 0),
        saved=saved,
        next_save=next_save,
    )


def _outcome(s: _Setup, carry: _Carry, args, live, accept, taken, t_next, y1, h_new, err_norm):
    """(status, error norm kept for the PI control) after an attempt: the event, t1 reached, a step too small or
    the step budget spent end a member's run; so does an opening attempt where f or J is not finite at t0."""
    status = carry.status
    if s.event is not None:
        status = jnp.where(taken & (s.event(t_next, y1[0], args) < 0.0), EVENT, status)
    status = jnp.where(taken & (t_next >= s.t_end) & (status < 0), OK, status)
    too_small = live & ~accept & (h_new < 1e-14 * jnp.maximum(1.0, jnp.abs(carry.t)))
    out_of_budget = taken & (carry.steps.count + 1 >= s.max_steps) & (status < 0)
    status = jnp.where(too_small | out_of_budget, FAILED, status)
    err_kept = jnp.maximum(err_norm, 1e-4)
    if s.opening:
        status = jnp.where(live & ~accept & ~carry.opened, FAILED, status)
        err_kept = jnp.where(carry.opened, err_kept, carry.err)
    return status, err_kept


def _finish(s: _Setup, prob, final: _Carry) -> Result:
    """One member's `Result` from its last carry: the event located inside its last step, the save times
    after that step given its end state."""
    t_final, y_final = final.t, final.y
    if s.event is not None:
        args = prob[-1]
        last = final.steps._replace(count=jnp.minimum(final.steps.count, 1)) if s.saving else final.steps
        t_final, y_final = locate_event(lambda t, y: s.event(t, y, args), last, final.status == EVENT, y_final)
        if s.saving:  # the one record kept is the last step taken: none if the run failed at once
            t_final = jnp.where(final.status == EVENT, t_final, final.t)
    saved = saving.saved_after(final.saved, final.next_save, final.y) if s.saving else None
    return Result(final.steps, t_final, y_final, final.status, final.rejected, saved)
