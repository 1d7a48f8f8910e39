"""What a set's fit knows: the covariance of its coordinates and its budget by source, the information the data
hold, the spread over each run's hyperparameters, and the set's log-likelihood."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import growjax.calibration.discrepancy as dc
from growjax.calibration.gls import rig_sd, whitened, whitened_rows
from growjax.calibration.layout import Layout
from growjax.calibration.scoring import hyperparameter_spread, normal_sums, schur


def set_covariance(outs, scores, layout: Layout, hypers, b, model_error: float, rig: str, centre=None):
    """(covariance (P, P) of z, its parts {source: (P, P)}, the information on z (P, P), the joint covariance
    (P + Q, P + Q) of (z, b) with its z block the covariance (None unless the rig is inferred), the estimator's
    gain (P, Q) on the rig's errors, z per unit ln ψ).

    As `growjax.calibration.scoring.RunScore.covariance`, summed over the runs, a shared rig error counted once:
    Gauss–Newton's joint covariance C of w = (z, b) at the runs' hyperparameters ``hypers``, b (Q,) the rig's
    errors from ``centre``; the estimator is linear in the data, w = A·r, and each run's noise, discrepancy, the
    configuration's own error (sd ``model_error`` m) and its pressure noise put A K Aᵀ on z; each tolerance,
    inferred (``rig``), what of its prior the data left, fixed, propagated through the gain."""
    _, jac_w = whitened(outs, scores, layout, hypers, b, centre)
    info_all = jac_w.T @ jac_w
    full = np.linalg.pinv(info_all, rcond=1e-10, hermitian=True)
    p_all, size = len(layout.labels), full.shape[0]
    parts: dict = {}
    gain = np.zeros((p_all, len(layout.rig_labels)))

    def add(name, part):
        parts[name] = parts.get(name, 0.0) + part

    for e, ((_, jac), score, hyper) in enumerate(zip(outs, scores, hypers)):
        jac, n = np.asarray(jac), score.n_len
        used = np.asarray(score.used)
        h = np.zeros((int(used.sum()), size))
        np.add.at(h.T, layout.index[e], (jac[:n][used] * score.sigma_length).T)
        g = None if score.sensitivity is None else np.asarray(score.sensitivity)[used]
        if score.inferred:
            np.add.at(h.T, p_all + layout.rig_index[e], g.T)
        a, run_parts = score.length_parts(full, h, hyper, model_error)
        for k, part in run_parts.items():
            add(k, part[:p_all, :p_all])
        if jac.shape[0] > n:
            hp = np.zeros((jac.shape[0] - n, size))
            np.add.at(hp.T, layout.index[e], jac[n:].T)
            a_p = full @ hp.T
            add("pressure_noise", (a_p @ a_p.T)[:p_all, :p_all])
        if g is not None:
            np.add.at(gain.T, layout.rig_index[e], (a[:p_all] @ g).T)
    if scores[0].tolerance is not None:
        u = rig_sd(scores, layout)
        for j, (_, name) in enumerate(layout.rig_labels):
            c = full[:p_all, p_all + j] / u[j] if rig == "inferred" else gain[:, j] * u[j]
            add(name, np.outer(c, c))
    cov = sum(parts.values())
    joint = None
    if size > p_all:
        joint = full.copy()
        joint[:p_all, :p_all] = cov
    return cov, parts, schur(info_all, p_all), joint, gain


def set_spread(outs, scores, layout: Layout, hypers, b, cov, centre=None) -> np.ndarray:
    """The covariance (P, P) of z that the runs' hyperparameters' own uncertainty adds: the sum over the runs of
    each run's spread (`growjax.calibration.scoring.hyperparameter_spread`) with the other runs held at their
    mode; a set of one is the run's own spread."""
    lengths, pressures, prior = whitened_rows(outs, scores, layout, hypers, b, centre)
    runs = len(outs)
    own = [normal_sums(*rows) for rows in lengths]
    held = [normal_sums(*rows) for rows in [prior, *pressures]]
    add = lambda terms: tuple(sum(x) for x in zip(*terms))  # noqa: E731
    p_all = len(layout.labels)
    total = np.zeros((p_all, p_all))
    for e, ((r, jac), score, hyper) in enumerate(zip(outs, scores, hypers)):
        rest = add(held + [own[k] for k in range(runs) if k != e])
        b_e = np.asarray(b)[layout.rig_index[e]] if score.inferred else np.zeros(0)
        columns = np.concatenate([layout.index[e], p_all + layout.rig_index[e] if score.inferred else []])
        total = total + hyperparameter_spread(score, (r, jac), hyper, cov, b_e, rest, columns.astype(int), p_all)
    return total


def set_log_likelihood(outs, scores, layout: Layout, hypers, centre, rig: str) -> float:
    """The set's total log-likelihood (nats) at the runs' residuals ``outs``: each run's length under its own
    discrepancy and noise (hyperparameters ``hypers``, at their mode), the rig's errors marginalised under their
    priors (``rig="inferred"``: one error vector per rig shared by its runs, `growjax.calibration.discrepancy.
    log_likelihood_runs`, the runs linearised at the rig's errors ``centre``; ``"fixed"``: each run's own), the
    pressure rows independent normal. What the fit maximises, up to a constant, profiled over the rig's errors;
    the score of a nested comparison of two fits of one set."""
    total, rows = 0.0, []
    for e, ((r, _), score, h) in enumerate(zip(outs, scores, hypers)):
        r = np.asarray(r)
        n, idx = score.n_len, np.asarray(score.index)
        r_len = r[:n] * score.sigma_length
        g = None if score.sensitivity is None else np.asarray(score.sensitivity)
        if score.inferred:
            r_len = r_len - g @ np.asarray(centre)[layout.rig_index[e]]  # the errors' prior is centred on nominal
        rows.append((r_len[idx], np.asarray(score.times)[idx], None if g is None else g[idx], h))
        r_p = r[n:]  # pressure, in units of its sd
        if r_p.size:
            total += float(-0.5 * np.sum(r_p**2) - r_p.size * 0.5 * np.log(2.0 * np.pi))
    if rig == "inferred":
        return total + _shared_rig_log_likelihood(rows, scores, layout)
    for (r_e, t_e, g_e, h), score in zip(rows, scores):
        marginal = rig == "fixed" and g_e is not None
        total += float(
            _log_likelihood(
                jnp.asarray(r_e),
                jnp.asarray(t_e),
                h,
                jnp.asarray(g_e) if marginal else None,
                jnp.asarray(score.tolerance) if marginal else None,
            )
        )
    return total


def _shared_rig_log_likelihood(rows, scores, layout: Layout) -> float:
    """The runs' length log-likelihood with each rig's errors shared by its runs and marginalised."""
    q = len(scores[0].tolerance_names)
    size = max(x[0].size for x in rows)
    pad = lambda a, fill: np.concatenate([a, np.full((size - a.shape[0], *a.shape[1:]), fill)])  # noqa: E731
    times = [np.concatenate([t, t[-1] + 1e-3 * np.arange(1, size - t.size + 1)]) for _, t, _, _ in rows]
    rig_of = layout.rig_index[:, 0] // q
    hyper = jax.tree_util.tree_map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *[x[3] for x in rows])
    return float(
        _log_likelihood_runs(
            jnp.asarray(np.stack([pad(x[0], 0.0) for x in rows])),
            jnp.asarray(np.stack(times)),
            hyper,
            jnp.asarray(np.stack([pad(x[2], 0.0) for x in rows])),
            jnp.asarray(scores[0].tolerance),
            jnp.asarray(np.stack([np.arange(size) < x[0].size for x in rows])),
            jnp.asarray(rig_of),
            int(rig_of.max()) + 1,
        )
    )


_log_likelihood = jax.jit(dc.log_likelihood)
_log_likelihood_runs = jax.jit(dc.log_likelihood_runs, static_argnums=7)


__all__ = ["set_covariance", "set_log_likelihood", "set_spread"]
