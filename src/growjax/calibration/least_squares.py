"""The one least-squares engine: a forward-mode linearisation and a bounded Levenberg–Marquardt loop.

Every workflow that minimises a sum of squares goes through :func:`levenberg_marquardt`: the fit and
discovery's nested fits, the control profile (residuals linearised by :func:`linearise`) and the MPC (a
forward-difference Jacobian from one batched solve). The posterior's Laplace step does not: its potential is
not a sum of squares (:func:`growjax.posterior.laplace_unconstrained`).

The loop is driven from Python around one compiled linearisation, not by ``optimistix.least_squares``;
``python benchmarks/least_squares.py`` compares the two on the fit's and the control profile's problems (the
Benchmarks page). On the fits, optimistix's Levenberg–Marquardt and Dogleg, bare or wrapped in
``BestSoFarLeastSquares``, end where the engine does (within the cost's own noise: the adaptive solver's steps
move with the parameters) but take tens of steps at that noise where the engine's gain test stops after a
few, and are several times slower warm. On the profile they are slower still, and their optimum leaves the
demand's range, which optimistix cannot bound and the engine keeps. Dogleg also needs the model's tangents
transposed, which the fast solver's are not (the benchmark gives it J·v from :func:`linearise`).
"""

from __future__ import annotations

from collections import OrderedDict

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["levenberg_marquardt", "linearise", "memoised"]


def linearise(residuals, z):
    """(r (m,), J (m, p)) of ``residuals`` at z (p,) in one forward-mode pass: ``jax.jvp`` along the p unit
    directions under ``vmap``, which the fast configuration merges into one solve carrying p sensitivities."""
    p = z.shape[0]
    r, jac_t = jax.vmap(lambda v: jax.jvp(residuals, (z,), (v,)), out_axes=(None, 0))(jnp.eye(p, dtype=z.dtype))
    return r, jac_t.T


def memoised(model, size: int = 4):
    """``model(z, *args)`` (args the same at every call) keeping its last ``size`` results by the value of z (p,): a fit
    asks for the same point again (a solver starts where the last one accepted, the hyperparameters are estimated there)
    and the model is deterministic, so the repeat costs nothing."""
    kept = OrderedDict()

    def call(z, *args):
        key = (np.asarray(z, float).tobytes(), *map(id, args))
        if key not in kept:
            kept[key] = model(z, *args)
            if len(kept) > size:
                kept.popitem(last=False)
        kept.move_to_end(key)
        return kept[key]

    return call


def levenberg_marquardt(
    linearised,
    z0,
    max_steps: int = 100,
    tol: float = 1e-6,
    gain_tol: float = 1e-5,
    max_move: float = 3.0,
    bounds=None,
    cost_resolution: float = 0.0,
    relative_resolution: float = 0.0,
    stall_steps: int = 3,
    residuals=None,
):
    """Minimise ½‖r(z)‖² from z0 by Levenberg–Marquardt (Marquardt's scaling diag(JᵀJ), Nielsen's damping
    update), driven from Python.

    ``linearised(z) → (r (m,), J (m, p))``. Stops when an accepted step moves z by < tol·(1 + |z|) and the
    cost by < tol of itself, or when a full Gauss–Newton step, ½gᵀ(JᵀJ)⁺g, would gain < ``gain_tol`` of the
    cost (at the solver's noise floor, or a parameter drifting to the edge of its range). A step moves each
    coordinate by at most ``max_move`` (clipped one by one); a point whose residuals or Jacobian are not
    finite is rejected (at z0 it ends the fit, not converged). ``bounds`` = (lower (p,), upper (p,)) on z:
    each trial point is projected into the box (a direction the data do not determine then stops at the
    parameter's physical range instead of drifting), and a coordinate on its bound that the gradient pushes
    outwards is held there while the others are solved for (so a fit pressed against its range converges as
    fast as a free one). A trial point equal to the last one rejected (a step
    clipped to ``max_move`` or to the box while the damping grows) is rejected again without evaluating it.
    Resolution (on when ``cost_resolution`` or ``relative_resolution`` > 0): the smallest change of the cost
    that matters, the larger of ``cost_resolution`` and ``relative_resolution`` × the cost. An adaptive
    solver's cost carries noise (its steps move with the parameters; ~1e-4 of the cost for growjax's fast
    configuration), and near a minimum, or along a valley the data hardly determine, trial points then
    wander at that noise: the fit stops, converged, once ``stall_steps`` trial points in a row near the best
    (within ten resolutions of its cost) have not lowered it by more than one resolution. A trial point far
    above the best (a step too long, far from the minimum) neither counts nor resets the count.
    ``residuals(z) → r (m,)``, where given: trial points are scored by it alone and linearised once accepted
    (r from ``residuals``, J from ``linearised``), for residuals whose Jacobian costs many evaluations of them;
    ``max_steps`` then counts accepted steps (a rejected one costs one evaluation of the residuals).
    Returns (z, cost, converged, r, J at z).
    """
    z = np.asarray(z0, float)
    r, jac = (np.asarray(a) for a in linearised(jnp.asarray(z)))
    cost = 0.5 * float(r @ r)
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(jac))):  # the model fails at the start: no descent
        return z, np.inf, False, r, np.nan_to_num(jac, nan=0.0, posinf=0.0, neginf=0.0)
    damping, growth = 1e-3, 2.0
    stalled = 0  # trial points in a row near the best that did not lower it by a resolution
    rejected = None  # the last trial point rejected
    resolving = cost_resolution > 0.0 or relative_resolution > 0.0
    steps = 0
    while steps < max_steps:
        step, predicted = _damped_step(jac, r, z, cost, damping, max_move, bounds, gain_tol)
        if step is None:
            return z, cost, True, r, jac  # a full Gauss–Newton step would gain < gain_tol of the cost
        trial = z + step
        if rejected is not None and np.array_equal(trial, rejected):
            cost_new = np.inf  # evaluated already, and rejected: the model is deterministic
        else:
            r_new, jac_new, cost_new = _scored(linearised, residuals, trial, cost)
            resolution = max(cost_resolution, relative_resolution * cost)
            if cost_new < cost - resolution:
                stalled = 0
            elif cost_new < cost + 10.0 * resolution:
                stalled += 1
        at_noise = resolving and stalled >= stall_steps
        steps += 1 if residuals is None or cost_new <= cost else 0
        if cost_new <= cost:
            done = np.all(np.abs(step) < tol * (1.0 + np.abs(z))) and cost - cost_new <= tol * cost
            gain = (cost - cost_new) / max(predicted, 1e-300)
            z, r, jac, cost = z + step, r_new, jac_new, cost_new
            # Nielsen's update: keep the damping where the linear model predicted well, relax it slowly
            damping = max(damping * max(1.0 / 3.0, 1.0 - (2.0 * min(gain, 1.0) - 1.0) ** 3), 1e-9)
            growth = 2.0
            if done or at_noise:
                return z, cost, True, r, jac
        else:
            rejected = trial
            damping *= growth
            growth *= 2.0
            if damping > 1e12 or at_noise:  # no descent left at the solver's resolution: a minimum
                return z, cost, True, r, jac
    return z, cost, False, r, jac


def _damped_step(jac, r, z, cost, damping, max_move, bounds, gain_tol):
    """(step (p,), the decrease of ½‖r‖² the linear model promises for it) at ``damping``; (None, 0) where a full
    Gauss–Newton step would gain < ``gain_tol`` of ``cost``. A coordinate on its bound that the gradient pushes
    outwards is held there (the active set): the gain test and the step are those of the others."""
    jtj, g = jac.T @ jac, jac.T @ r
    free = np.ones(z.size, bool) if bounds is None else ~(((z <= bounds[0]) & (g > 0)) | ((z >= bounds[1]) & (g < 0)))
    jtj_f, g_f = jtj[np.ix_(free, free)], g[free]
    if 0.5 * float(g_f @ np.linalg.pinv(jtj_f, rcond=1e-12, hermitian=True) @ g_f) <= gain_tol * cost:
        return None, 0.0
    scale = np.maximum(np.diag(jtj_f), 1e-12 * max(float(np.max(np.diag(jtj), initial=0.0)), 1e-300))
    step = np.zeros_like(z)
    step[free] = np.linalg.solve(jtj_f + damping * np.diag(scale), -g_f)
    step = np.clip(step, -max_move, max_move)  # a coordinate running to its range's edge moves no others less
    if bounds is not None:
        step = np.clip(z + step, *bounds) - z
    return step, 0.5 * float(step[free] @ (damping * scale * step[free] - g_f))


def _scored(linearised, residuals, trial, cost):
    """(r, J, ½‖r‖²) at ``trial``, the cost ∞ where r or J is not finite; with ``residuals``, r from it and J
    (else None) only where the trial's cost is no more than ``cost``."""
    if residuals is None:
        r, jac = (np.asarray(a) for a in linearised(jnp.asarray(trial)))
    else:
        r, jac = np.asarray(residuals(jnp.asarray(trial))), None
        if np.all(np.isfinite(r)) and 0.5 * float(r @ r) <= cost:
            jac = np.asarray(linearised(jnp.asarray(trial))[1])
    ok = np.all(np.isfinite(r)) and (jac is None or np.all(np.isfinite(jac)))
    return r, jac, 0.5 * float(r @ r) if ok else np.inf
