"""Generalised least squares of a set of runs: the set's residuals and Jacobian weighted (independent noise) or
whitened (each run under its own discrepancy and noise, the rig's prior rows after them), and the alternation of
the hyperparameters' mode with Gauss–Newton on the whitened residuals."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from growjax.calibration.layout import Layout
from growjax.calibration.least_squares import levenberg_marquardt

LM_TOLERANCE = 1e-6  # rtol = atol of the Levenberg–Marquardt stop, on the coordinates and the cost
# The smallest change of the whitened cost (nats) that matters: a 90 % interval spans 1.35 nats, and the
# adaptive solver's own noise moves the cost by ~1e-3.
COST_RESOLUTION = 1e-2
OUTER_STEPS = 4  # alternations of the hyperparameters' mode and the GLS fit
OUTER_TOLERANCE = 0.05  # stop once a GLS fit moves the coordinates by less than this share of their sd


def alternate_gls(whitened, hyper_at, w, bounds, max_steps: int, hyper=None):
    """Alternate the hyperparameters' mode at w (``hyper_at(w, hyper) → hyper``) and Gauss–Newton on the whitened
    residuals (``whitened(w, hyper) → (r, J)``) from w, until a fit moves every coordinate by less than
    `OUTER_TOLERANCE` of its sd (at most `OUTER_STEPS` fits). Returns (w, hyper, cost, converged)."""
    w, cost, converged = np.asarray(w, float), np.nan, False
    for _ in range(OUTER_STEPS):
        hyper = hyper_at(w, hyper)
        w_new, cost, converged, _, jac_w = levenberg_marquardt(
            lambda v, h=hyper: whitened(v, h),
            w,
            max_steps,
            LM_TOLERANCE,
            bounds=bounds,
            cost_resolution=COST_RESOLUTION,
        )
        sd = np.sqrt(np.diag(np.linalg.pinv(jac_w.T @ jac_w, rcond=1e-10, hermitian=True)))
        moved, w = np.abs(w_new - w), np.asarray(w_new)
        if np.all(moved <= OUTER_TOLERANCE * sd):
            break
    return w, hyper, cost, converged


def with_rig_bounds(bounds, q: int):
    """The box (lower, upper) on w = (z, b): ``bounds`` on z, none on the q rig errors b after it."""
    return tuple(np.concatenate([np.asarray(x, float), np.full(q, v)]) for x, v in zip(bounds, (-np.inf, np.inf)))


def rig_stage_starts(z, box=None) -> list:
    """The starts of the least squares that fits the rig's errors beside z: the nominal-rig stage's best z, and
    where z left the sampling ``box`` (2, p), z brought back into it too (the lower cost is kept). With the rig
    held nominal, a misfit that is the rig's can run θ to where it stops acting (Y to ~0 Pa on a stepper run from
    a rig far off nominal), and from there the rig's errors cannot pull it back; from the box's edge they can."""
    z = np.asarray(z, float)
    if box is None or np.all((z >= box[0]) & (z <= box[1])):
        return [z]
    return [z, np.clip(z, box[0], box[1])]


def weighted(outs, scores, layout: Layout, q_all: int = 0):
    """The set's residuals and Jacobian under independent noise, unscored samples zeroed: P columns, or with
    ``q_all`` the P + Q columns of w = (z, b) (each run's Jacobian then has its rig's errors after its θ)."""
    p_all, p = len(layout.labels), layout.index.shape[1]
    rs, js = [], []
    for e, ((r, jac), score) in enumerate(zip(outs, scores)):
        wr, wj = (np.asarray(a) for a in score.weighted(jnp.asarray(r), jnp.asarray(jac)))
        full = np.zeros((wr.size, p_all + q_all))
        np.add.at(full.T, layout.index[e], wj[:, :p].T)
        if q_all:
            np.add.at(full.T, p_all + layout.rig_index[e], wj[:, p:].T)
        rs.append(wr)
        js.append(full)
    return np.concatenate(rs), np.concatenate(js)


def whitened_rows(outs, scores, layout: Layout, hypers, b, centre=None) -> tuple[list, list, tuple]:
    """The set's whitened rows in its coordinates w = (z (P,), b (Q,)): per run its length rows (residuals
    (n_used,), Jacobian (n_used, P + Q)), per run its pressure rows (m_p,), (m_p, P + Q), and the rig's prior rows
    (centre + b)/u ((Q,), (Q, P + Q); empty without rig errors), b (Q,) counted from ``centre`` (Q,), the point the
    runs are linearised at. Each run is whitened under its own hyperparameters ``hypers``."""
    p_all, q_all = len(layout.labels), np.asarray(b).size
    lengths, pressures = [], []
    for e, ((r, jac), score, h) in enumerate(zip(outs, scores, hypers)):
        b_e = np.asarray(b)[layout.rig_index[e]] if score.inferred else np.zeros(0)
        wr, wj = (np.asarray(a) for a in score.augmented(jnp.asarray(r), jnp.asarray(jac), h, b_e))
        columns = np.concatenate([layout.index[e], p_all + layout.rig_index[e] if score.inferred else []])
        full = np.zeros((wr.size, p_all + q_all))
        np.add.at(full.T, columns.astype(int), wj.T)
        n, q_e = int(np.size(score.index)), b_e.size  # the run's own prior rows (q_e) sit between its two kinds
        lengths.append((wr[:n], full[:n]))
        pressures.append((wr[n + q_e :], full[n + q_e :]))
    prior = (np.zeros(0), np.zeros((0, p_all + q_all)))
    if q_all:
        u = rig_sd(scores, layout)
        rows = np.concatenate([np.zeros((q_all, p_all)), np.diag(1.0 / u)], axis=1)
        prior = ((np.asarray(b) + (0.0 if centre is None else np.asarray(centre))) / u, rows)
    return lengths, pressures, prior


def whitened(outs, scores, layout: Layout, hypers, b, centre=None):
    """The set's whitened residuals and Jacobian of w = (z (P,), b (Q,)) (`whitened_rows`): every run's length
    rows, the rig's prior rows, every run's pressure rows."""
    lengths, pressures, prior = whitened_rows(outs, scores, layout, hypers, b, centre)
    rows = [*lengths, prior, *pressures]
    return np.concatenate([r for r, _ in rows]), np.concatenate([j for _, j in rows])


def rig_sd(scores, layout: Layout) -> np.ndarray:
    """(Q,) the relative sd of each rig error of the layout."""
    tol = dict(zip(scores[0].tolerance_names, np.asarray(scores[0].tolerance)))
    return np.array([tol[name] for _, name in layout.rig_labels])


def estimates(scores, outs, discrepancy: str, hypers) -> tuple:
    """Each run's hyperparameters at their mode given its residuals in ``outs``, from ``hypers``."""
    return tuple(score.estimate(r, discrepancy, h) for score, (r, _), h in zip(scores, outs, hypers))


__all__ = [
    "COST_RESOLUTION",
    "LM_TOLERANCE",
    "OUTER_STEPS",
    "OUTER_TOLERANCE",
    "alternate_gls",
    "estimates",
    "rig_sd",
    "rig_stage_starts",
    "weighted",
    "whitened",
    "whitened_rows",
    "with_rig_bounds",
]
