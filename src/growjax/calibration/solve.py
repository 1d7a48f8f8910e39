"""The fit's stages from its starts to the estimate: least squares from every start with the rig nominal, then
generalised least squares with the rig's errors inferred in the model's own tangents (the default) or through its
secants, relinearised where the data put the rig."""

from __future__ import annotations

import dataclasses

import numpy as np

from growjax.calibration.batch import Batch
from growjax.calibration.gls import (
    LM_TOLERANCE,
    alternate_gls,
    estimates,
    rig_sd,
    rig_stage_starts,
    weighted,
    whitened,
    with_rig_bounds,
)
from growjax.calibration.layout import Layout
from growjax.calibration.least_squares import levenberg_marquardt
from growjax.calibration.problem import problem_at_rig

# The rig's sensitivities are secants taken at one point: where the data pull the rig's errors a good part of a
# tolerance from nominal (with three or more runs on one rig, say), secants at nominal bias θ by several standard
# errors. With ``relinearise`` the fit takes them again where it put the rig, as central secants (the slope there:
# a one-sided secant's slope belongs half a tolerance away, and the rig would drift past its optimum step after
# step), at most this many linearisations, until the errors move by less than this share of their tolerance.
RELINEARISE_STEPS = 8
RELINEARISE_TOLERANCE = 0.02


@dataclasses.dataclass
class Solution:
    """Where the fit ended.

    Attributes:
        z: (P,) the coordinates.
        b: (Q,) the rig's errors ln(ψ/ψ₀) (empty unless inferred).
        centre: (Q,) the rig's errors where the runs are linearised (b − centre is what the scores add).
        outs: per run (r (m_e,), J (m_e, p)) at z with the rig at ``centre``.
        scores: per run its `growjax.calibration.scoring.RunScore` with the rig's tolerances.
        hypers: per run its hyperparameters at their mode.
        cost: the whitened cost, nats.
        converged: whether the last fit converged.
        batch: the batch the runs were last solved in.
        linearisations: points at which the rig's sensitivities were taken.
        rig_last_move: the rig's largest move in the last linearisation, in tolerances.
    """

    z: np.ndarray
    b: np.ndarray
    centre: np.ndarray
    outs: list
    scores: list
    hypers: list
    cost: float
    converged: bool
    batch: Batch
    linearisations: int = 1
    rig_last_move: float = 0.0


def from_starts(batch: Batch, layout: Layout, scores, z0s, bounds, max_steps: int):
    """Least squares of z (independent noise, the rig nominal) from every start z0 (P,) of ``z0s``, one after
    another through the batch's compiled program: consistent under any correlation of the residuals, and a start
    that a discrepancy absorbing the misfit cannot trap. Returns (z (K, P), cost (K,), converged (K,))."""
    solved = [
        levenberg_marquardt(
            lambda z: weighted(batch.linearised(z, layout), scores, layout), z0, max_steps, LM_TOLERANCE, bounds=bounds
        )
        for z0 in z0s
    ]
    return tuple(np.asarray([s[k] for s in solved]) for k in range(3))


def solve_tangents(
    batch: Batch, layout: Layout, plain, tol: dict, z, bounds, discrepancy: str, max_steps: int, box=None
) -> Solution:
    """From z (P,) (least squares with the rig nominal), with the rig's errors b (Q,) among the runs' model
    parameters: least squares of w = (z, b) with b's prior rows b/u (before any discrepancy is estimated: a misfit
    is then the model's to remove, not the discrepancy's to absorb), from `rig_stage_starts` in the sampling
    ``box`` (2, P); then generalised least squares of w alternating with each run's hyperparameters, every run
    linearised at w with its rig's exact tangents there."""
    p, p_all, q_all = layout.index.shape[1], len(layout.labels), len(layout.rig_labels)
    u = np.array([tol[name] for _, name in layout.rig_labels])
    prior = np.concatenate([np.zeros((q_all, p_all)), np.diag(1.0 / u)], axis=1)
    w_bounds = with_rig_bounds(bounds, q_all)

    def independent(w):
        r, jac = weighted(batch.linearised(w, layout), plain, layout, q_all)
        return np.concatenate([r, np.asarray(w)[p_all:] / u]), np.concatenate([jac, prior])

    w, _, converged, _, _ = min(
        (
            levenberg_marquardt(
                independent, np.concatenate([z0, np.zeros(q_all)]), max_steps, LM_TOLERANCE, bounds=w_bounds
            )
            for z0 in rig_stage_starts(z, box)
        ),
        key=lambda run: run[1],
    )

    def at(w):  # each run linearised at w: its score with the rig's tangents there, and (r, J_θ)
        outs = batch.linearised(w, layout)
        b = np.asarray(w)[p_all:]
        scores = [
            score.with_tolerances(
                np.asarray(jac)[: score.n_len, p:] * score.sigma_length,
                tol,
                inferred=True,
                centre=b[layout.rig_index[e]],
            )
            for e, (score, (_, jac)) in enumerate(zip(plain, outs))
        ]
        return scores, [(r, jac[:, :p]) for r, jac in outs], b

    def whitened_at(w, hs):
        scores, outs, b = at(w)
        return whitened(outs, scores, layout, hs, np.zeros(q_all), b)

    def hyper_at(w, hs):
        scores, outs, _ = at(w)
        return estimates(scores, outs, discrepancy, hs)

    w, hypers, cost, converged = alternate_gls(whitened_at, hyper_at, w, w_bounds, max_steps, (None,) * len(plain))
    scores, outs, b = at(w)
    return Solution(np.asarray(w)[:p_all], b, b, outs, scores, list(hypers), cost, converged, batch)


def solve_secants(
    batch: Batch,
    problems,
    layout: Layout,
    plain,
    tol: dict,
    z,
    bounds,
    options: tuple,
) -> Solution:
    """From z (P,), generalised least squares alternating with each run's hyperparameters, the rig's sensitivities
    secants taken apart from the solve: its errors fitted beside z (``rig="inferred"``) or the rig held nominal
    (``"fixed"``: its tolerances propagated afterwards). When inferred, the runs and the rig's sensitivities are
    taken again where the fit put the rig, until its errors move by less than `RELINEARISE_TOLERANCE` of their
    tolerance (at most ``steps`` linearisations). ``options`` = (rig, discrepancy, max_steps, steps)."""
    rig, discrepancy, max_steps, steps = options
    inferred = bool(tol) and rig == "inferred"
    centre = np.zeros(len(layout.rig_labels) if inferred else 0)
    b, hypers, scores, sensitivities, move, linearisations = centre.copy(), [None] * len(plain), plain, None, 0.0, 0
    for step in range(steps):
        linearisations += 1
        sensitivities = batch.sensitivities(z, layout, tol, central=step > 0) if tol else None
        if inferred:
            scores = [
                score.with_tolerances(g, tol, inferred=True, centre=centre[layout.rig_index[e]])
                for e, (score, g) in enumerate(zip(plain, sensitivities))
            ]
        z, b_step, hypers, cost, converged = _gls(
            batch, layout, scores, hypers, z, b - centre, centre, bounds, discrepancy, max_steps
        )
        b = centre + b_step
        move = float(np.max(np.abs(b - centre) / rig_sd(scores, layout))) if centre.size else 0.0
        if centre.size == 0 or step == steps - 1 or move <= RELINEARISE_TOLERANCE:
            break
        centre = b.copy()  # the rig's errors moved: take the sensitivities again where the data put the rig
        spent = batch.simulate_s
        batch = Batch([problem_at_rig(pr, tol, centre[layout.rig_index[e]]) for e, pr in enumerate(problems)])
        batch.simulate_s = spent
    if tol and not inferred:  # fixed: propagated after the fit
        scores = [score.with_tolerances(g, tol) for score, g in zip(scores, sensitivities)]
    outs = batch.linearised(z, layout)
    return Solution(z, b, centre, outs, scores, hypers, cost, converged, batch, linearisations, move)


def _gls(batch, layout: Layout, scores, hypers, z, b, centre, bounds, discrepancy: str, max_steps: int):
    """Alternate each run's hyperparameter mode and the whitened Gauss–Newton fit of (z, b), b the rig's errors
    from ``centre``. Returns (z, b, hypers, cost, converged)."""
    p_all = z.size

    def hyper_at(w, hs):
        return estimates(scores, batch.linearised(w[:p_all], layout), discrepancy, hs)

    w, hypers, cost, converged = alternate_gls(
        lambda w, hs: whitened(batch.linearised(w[:p_all], layout), scores, layout, hs, w[p_all:], centre),
        hyper_at,
        np.concatenate([z, b]),
        with_rig_bounds(bounds, b.size),
        max_steps,
        tuple(hypers),
    )
    return w[:p_all], w[p_all:], list(hypers), cost, converged


__all__ = [
    "RELINEARISE_STEPS",
    "RELINEARISE_TOLERANCE",
    "Solution",
    "from_starts",
    "solve_secants",
    "solve_tangents",
]
