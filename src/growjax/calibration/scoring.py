"""One run's side of the likelihood (`growjax.calibration.discrepancy`): its residuals and Jacobian weighted or
whitened under the discrepancy and noise, its rig's linearised errors, and its covariance with the budget.

The spread over the discrepancy's hyperparameters (`hyperparameter_spread`) is written for a run inside a set of
runs: the run's hyperparameters move over a grid about their mode while the rest of the set's rows (the other
runs at their mode, the pressure rows, the rig's prior rows) are held; a run alone is the set of one.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import growjax.calibration.discrepancy as dc
from growjax.calibration.likelihood import MODEL_ERROR_TIME


class RunScore(eqx.Module):
    """How one run's residuals are scored: its samples (length rows in units of ``sigma_length``, pressure rows
    after them), which of them the likelihood sees, and its rig's linearised errors.

    Attributes:
        times: (n,) s, the run's length samples.
        used: (n,) bool, the samples the likelihood sees.
        index: (n_used,) int, their rows (the filter runs over them alone: exact, the process is Markov).
        sigma_length: the length rows' unit, m.
        n_len: n, the number of length rows.
        sensitivity: (n, q) m per unit ln ψ, the length's sensitivity to the rig's relative errors, or None.
        tolerance: (q,) their relative sds, or None.
        tolerance_names: (q,) the toleranced parameters.
        inferred: whether the rig's errors b are fitted beside z (prior N(0, u²)).
        centre: (q,) the rig's errors ln(ψ/ψ₀) where the model is linearised; b is counted from here.
    """

    times: jax.Array
    used: jax.Array
    index: jax.Array
    sigma_length: float = eqx.field(static=True)
    n_len: int = eqx.field(static=True)
    sensitivity: jax.Array | None = None
    tolerance: jax.Array | None = None
    tolerance_names: tuple = eqx.field(static=True, default=())
    inferred: bool = eqx.field(static=True, default=False)
    centre: jax.Array | None = None

    @classmethod
    def of(cls, times, used, sigma_length: float) -> RunScore:
        """The score of a run with length samples at ``times`` (n,) s of which ``used`` (n,) bool are scored."""
        used = np.asarray(used, bool)
        return cls(jnp.asarray(times), jnp.asarray(used), jnp.asarray(np.flatnonzero(used)), sigma_length, used.size)

    def with_tolerances(self, sensitivity, tol: dict, inferred: bool = False, centre=None) -> RunScore:
        """This score with the rig's sensitivities ``sensitivity`` (n, q) m per unit ln ψ and tolerances ``tol``
        {name: relative sd}, fitted beside z (``inferred``) from ``centre`` (q,) or propagated."""
        centre = jnp.zeros(len(tol)) if centre is None else jnp.asarray(centre, float)
        return RunScore(
            self.times,
            self.used,
            self.index,
            self.sigma_length,
            self.n_len,
            jnp.asarray(sensitivity),
            jnp.asarray(list(tol.values())),
            tuple(tol),
            inferred,
            centre,
        )

    def augmented(self, r, jac, hyper, b):
        """Whitened residuals and Jacobian of w = (z, b) under the discrepancy and noise: z alone with the rig at
        its nominal values, or, when the rig is inferred, with its linearised effect g·b on the length and
        its prior residuals b/u as q more rows."""
        return _augmented(self, r, jac, hyper, jnp.asarray(b if self.inferred else np.zeros(0)))

    def length_columns(self, r, jac, b):
        """The scored length rows, m: [residual (with the rig's g·b when inferred), Jacobian, (g when inferred)]
        (n_used, 1 + p (+ q)), and their times (n_used,) s: the columns one filter whitens together."""
        scale = self.sigma_length
        cols = [r[: self.n_len, None] * scale, jac[: self.n_len] * scale]
        if self.inferred:
            g = self.sensitivity
            cols = [cols[0] + g @ b[:, None], cols[1], g]
        return jnp.concatenate(cols, axis=1)[self.index], self.times[self.index]

    def weighted(self, r, jac):
        """Residuals and Jacobian with the unused length samples zeroed (independent noise of sd σ_L)."""
        keep = jnp.concatenate([self.used, jnp.ones(r.shape[0] - self.n_len, bool)])
        return jnp.where(keep, r, 0.0), jnp.where(keep[:, None], jac, 0.0)

    def estimate(self, r, kind, start=None) -> dc.Hyper:
        """The hyperparameters' mode for the residuals ``r`` (units of σ_L), the rig marginalised when inferred."""
        index = np.asarray(self.index)
        r_len = np.asarray(r)[: self.n_len] * self.sigma_length
        g, u = (np.asarray(self.sensitivity)[index], np.asarray(self.tolerance)) if self.inferred else (None, None)
        if self.inferred:  # the errors' prior is centred on nominal, not on the point of linearisation
            r_len = r_len - np.asarray(self.sensitivity) @ np.asarray(self.centre)
        return dc.estimate(r_len[index], np.asarray(self.times)[index], kind, g, u, start=start)

    def information(self, raw, hyper, b) -> np.ndarray:
        """The information (p, p) the data hold on z: J̃ᵀJ̃, or with the rig inferred its Schur complement
        (the inverse of the z block of the joint covariance)."""
        _, jac_w = (np.asarray(a) for a in self.augmented(*raw, hyper, b))
        p = np.asarray(raw[1]).shape[1]
        return schur(jac_w.T @ jac_w, p)

    def covariance(self, raw, hyper, b, model_error: float = 0.0):
        """Covariance (p, p) of z, its parts {source: (p, p)}, which add up to it, and the estimator's gain (p, q)
        on the rig's errors (z per unit ln ψ).

        The joint covariance C of w = (z, b) is Gauss–Newton's, (J̃ᵀJ̃)⁻¹ (b only when the rig is inferred);
        the estimator is linear in the data, w = A·r, and its covariance splits by the residual's sources: the
        noise and the discrepancy, A K_k Aᵀ; each tolerance, inferred, through its prior residual
        (C_{z,b_j} C_{z,b_j}ᵀ / u_j²: what of its prior the data left), fixed, propagated through the estimator
        (the GUM's sensitivity coefficients), u² (A g)(A g)ᵀ with g the length's sensitivity; the fitted
        configuration's own error against the reference (sd ``model_error`` m, squared-exponential over
        `MODEL_ERROR_TIME`: too small for the data to measure, known from the agreement benchmark) through the
        same gain; the pressure noise."""
        jac = np.asarray(raw[1])
        p = jac.shape[1]
        _, jac_w = (np.asarray(a) for a in self.augmented(*raw, hyper, b))
        full = np.linalg.pinv(jac_w.T @ jac_w, rcond=1e-10, hermitian=True)
        used = np.asarray(self.used)
        h = jac[: self.n_len][used] * self.sigma_length  # m per unit z
        g = None if self.sensitivity is None else np.asarray(self.sensitivity)[used]  # m per unit ln ψ
        if self.inferred:
            h = np.concatenate([h, g], axis=1)
        a, parts = self.length_parts(full, h, hyper, model_error)
        parts = {k: v[:p, :p] for k, v in parts.items()}
        if jac.shape[0] > self.n_len:
            j_p = jac[self.n_len :]
            j_p = np.concatenate([j_p, np.zeros((j_p.shape[0], full.shape[0] - p))], axis=1)
            a_p = full @ j_p.T
            parts["pressure_noise"] = (a_p @ a_p.T)[:p, :p]
        gain = np.zeros((p, 0))
        if g is not None:
            gain = a[:p] @ g  # (p, q): the estimate's response to a rig error
            for j, name in enumerate(self.tolerance_names):
                u = float(self.tolerance[j])
                c = full[:p, p + j] / u if self.inferred else gain[:, j] * u
                parts[name] = np.outer(c, c)
        return sum(parts.values()), parts, gain

    def length_parts(self, full, h, hyper, model_error: float) -> tuple[np.ndarray, dict]:
        """(A (S, n_used), {source: A K Aᵀ (S, S)}): the estimator's gain on the scored length samples, A =
        ``full`` (S, S) · (K⁻¹ ``h``)ᵀ with ``h`` (n_used, S) m per unit coordinate, and the covariance each
        source of the length residual (noise, discrepancy, the configuration's own error) puts on the
        coordinates through it."""
        t = np.asarray(self.times)[np.asarray(self.used)]
        kernels = {"noise": dc.noise_kernel(t, hyper)}
        if float(hyper.amplitude) > 0:
            kernels["discrepancy"] = dc.kernel(t, hyper)
        a = full @ np.linalg.solve(sum(kernels.values()), h).T
        parts = {k: a @ kern @ a.T for k, kern in kernels.items()}
        if model_error > 0:
            parts["fast_model_error"] = a @ dc.drift_kernel(t, model_error, MODEL_ERROR_TIME) @ a.T
        return a, parts

    def hyperparameter_spread(self, raw, hyper, cov, b) -> np.ndarray:
        """The covariance (p, p) of z that the hyperparameters' own uncertainty adds, the run alone
        (`hyperparameter_spread` with the run's pressure and rig-prior rows as the rest)."""
        r, jac = (np.asarray(a) for a in raw)
        p, n = jac.shape[1], self.n_len
        b = np.asarray(b if self.inferred else np.zeros(0), float)
        q = b.size
        rest = normal_sums(r[n:], np.concatenate([jac[n:], np.zeros((r.size - n, q))], axis=1))
        if self.inferred:  # its rig's prior rows
            u = np.asarray(self.tolerance)
            prior = normal_sums(
                (np.asarray(self.centre) + b) / u, np.concatenate([np.zeros((q, p)), np.diag(1 / u)], 1)
            )
            rest = tuple(x + y for x, y in zip(prior, rest))
        return hyperparameter_spread(self, raw, hyper, cov, b, rest, np.arange(p + q), p)


def schur(info, p: int) -> np.ndarray:
    """The information (p, p) on the first p coordinates of ``info`` (S, S), the others marginalised: its Schur
    complement (``info`` itself where S = p)."""
    info = np.asarray(info, float)
    if info.shape[0] == p:
        return info
    return info[:p, :p] - info[:p, p:] @ np.linalg.solve(info[p:, p:], info[p:, :p])


def normal_sums(r, jac) -> tuple:
    """(JᵀJ (S, S), Jᵀr (S,), rᵀr ()) of whitened rows r (m,), J (m, S): what those rows add to a Gauss–Newton
    system."""
    r, jac = np.asarray(r, float), np.asarray(jac, float)
    return jac.T @ jac, jac.T @ r, float(r @ r)


HYPER_GRID = (
    np.geomspace(1e-3, 10.0, 13),
    np.geomspace(0.1, 10.0, 7),
    np.geomspace(0.5, 2.0, 3),
)  # × the mode (each holds it)


def hyperparameter_spread(score: RunScore, raw, hyper, cov, b, rest, columns, p_all: int) -> np.ndarray:
    """The covariance (P, P) of the set's z that one run's hyperparameters' own uncertainty adds.

    On a grid about the run's mode (amplitude, time scale and noise, log-spaced; the noise's correlation time
    held at its mode, a nuisance the data pin down where it matters), each point h is weighted by its posterior
    given the data, the coordinates integrated out by Laplace at the linearisation ``raw`` = (r, J) of the run:
    the log-likelihood at the Gauss–Newton optimum ẑ(h), −½ log det of the information and the hyperparameters'
    prior. The rest of the system (``rest`` = (JᵀJ, Jᵀr, rᵀr) over the S = P + Q coordinates: the other runs at
    their mode, the pressure rows, the rig's prior rows) is held. The spread is the weighted
    Σ_h [C(h) + (ẑ(h) − z̄)(ẑ(h) − z̄)ᵀ], z̄ the weighted mean, minus the covariance ``cov`` (P, P) at the mode
    (floored at zero): a discrepancy whose amplitude the data leave open widens the interval as sampling over it
    would. ``columns`` (p + q,): the coordinate of each of the run's columns (its z, then its rig's errors when
    inferred, ``b`` (q,) those errors from the run's centre); ``p_all``: P.
    """
    a, ell, s = (np.ravel(x) for x in np.meshgrid(*HYPER_GRID, indexing="ij"))
    amp = np.maximum(float(hyper.amplitude), 1e-3 * float(hyper.noise)) * a
    grid = dc.Hyper(
        jnp.asarray(amp),
        jnp.asarray(float(hyper.time_scale) * ell),
        jnp.asarray(float(hyper.noise) * s),
        jnp.full(amp.shape, float(hyper.noise_time)),
    )
    select = np.zeros((len(columns), rest[0].shape[0]))
    select[np.arange(len(columns)), np.asarray(columns)] = 1.0
    r, jac = raw
    rest = tuple(jnp.asarray(x) for x in rest)
    logw, shift, c_h = (
        np.asarray(x)
        for x in _hyper_scan(score, jnp.asarray(r), jnp.asarray(jac), grid, jnp.asarray(b), rest, select, p_all)
    )
    logw = np.where(np.isfinite(logw), logw, -np.inf)
    w = np.exp(logw - np.max(logw))
    w /= w.sum()
    shift = shift - w @ shift  # about the mixture's mean: the point linearised at need not be the mode's optimum
    total = np.einsum("g,gij->ij", w, c_h + shift[:, :, None] * shift[:, None, :])
    spread = total - cov
    evals, evecs = np.linalg.eigh(0.5 * (spread + spread.T))
    return (evecs * np.clip(evals, 0.0, None)) @ evecs.T


@eqx.filter_jit
def _hyper_scan(score: RunScore, r, jac, grid: dc.Hyper, b, rest, select, p_all: int):
    """Per grid point: log weight, the Gauss–Newton shift of the set's z (P,), its covariance (P, P).

    The filter runs over the grid in one batch; the (S, S) solves run one grid point at a time (`jax.lax.map`),
    each one eigendecomposition: XLA:CPU's batched LAPACK kernels wait on its thread pool for their batch's
    parts, and two of them side by side on a 2-thread pool wait for each other for ever.
    """
    cols, t = score.length_columns(r, jac, b)
    info_rest, grad_rest, rr_rest = rest
    select = jnp.asarray(select)

    def whitened(h):
        v, s, _, _ = dc.kalman_filter(cols, t, h, hoist=False)
        w = v / jnp.sqrt(s)[:, None]
        return w[:, 0], w[:, 1:] @ select, -0.5 * jnp.sum(jnp.log(2.0 * jnp.pi * s)) + dc.log_prior(h)

    def solved(point):
        wr, wj, constant = point
        info = info_rest + wj.T @ wj
        grad = grad_rest + wj.T @ wr
        c, logdet = _pinv_logdet(info)
        cost = 0.5 * (rr_rest + wr @ wr) - 0.5 * grad @ c @ grad
        # the rig's prior normalisation is the same at every h
        return constant - cost - 0.5 * logdet, (-c @ grad)[:p_all], c[:p_all, :p_all]

    return jax.lax.map(solved, jax.vmap(whitened)(grid))


def _pinv_logdet(info):
    """The pseudo-inverse of the symmetric ``info`` (S, S), as `jnp.linalg.pinv` with ``hermitian=True``
    gives it, and log |det info|, from one eigendecomposition."""
    w, v = jnp.linalg.eigh(info)
    cutoff = 10.0 * info.shape[0] * jnp.finfo(info.dtype).eps * jnp.max(jnp.abs(w))
    inverse = jnp.where(jnp.abs(w) > cutoff, 1.0 / w, 0.0)
    return (v * inverse) @ v.T, jnp.sum(jnp.log(jnp.abs(w)))


def _stacked(score: RunScore, w, r, jac, b):
    """Whitened residuals and Jacobian of w = (z[, b]) from the whitened length columns ``w``, the rig's prior
    rows (centre + b)/u when inferred, then the pressure rows."""
    n, p = score.n_len, jac.shape[1]
    if not score.inferred:
        return jnp.concatenate([w[:, 0], r[n:]]), jnp.concatenate([w[:, 1:], jac[n:]], axis=0)
    u = score.tolerance
    q = u.shape[0]
    prior = jnp.concatenate([jnp.zeros((q, p)), jnp.diag(1.0 / u)], axis=1)
    pressure = jnp.concatenate([jac[n:], jnp.zeros((jac.shape[0] - n, q))], axis=1)
    return (
        jnp.concatenate([w[:, 0], (score.centre + b) / u, r[n:]]),
        jnp.concatenate([w[:, 1:], prior, pressure], axis=0),
    )


@eqx.filter_jit
def _augmented(score: RunScore, r, jac, hyper, b):
    cols, t = score.length_columns(r, jac, b)
    return _stacked(score, dc.whiten(cols, t, hyper), r, jac, b)


__all__ = ["HYPER_GRID", "RunScore", "hyperparameter_spread", "normal_sums", "schur"]
