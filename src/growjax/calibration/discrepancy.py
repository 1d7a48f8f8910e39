"""The residual model shared by every likelihood: a smooth model discrepancy, sensor noise and rig tolerances.

The measured length is written

    y(tᵢ) = L(tᵢ; θ) + δ(tᵢ) + Σⱼ gⱼ(tᵢ) bⱼ + εᵢ,

with L the simulated length, δ a zero-mean Gaussian process in time (Matérn ν = 3/2, amplitude ``a`` m,
time scale ``ℓ`` s), ε sensor noise (sd ``σ`` m, correlation time ``τ`` s: an Ornstein–Uhlenbeck process,
corr(εᵢ, εⱼ) = exp(−|tᵢ − tⱼ|/τ); τ = 0 is independent noise), and the last sum the linearised effect of
the fixed rig parameters held at their nominal values: bⱼ ~ N(0, uⱼ²) is parameter j's relative error
(its tolerance uⱼ) and gⱼ(t) = ∂L/∂ln ψⱼ the length's sensitivity to it.

A Matérn-3/2 process is the output of a two-state linear SDE and the noise of a one-state one, so this
covariance is that of a linear Gaussian state-space model: a Kalman filter (`kalman_filter`, a ``lax.scan``)
gives the exact likelihood in O(n) for any (also irregular) sampling, the whitened residuals for Gauss–Newton,
forecasts and draws. The tolerance terms are static states of the same filter (for the total log-likelihood, a q × q
correction after the three-state filter instead).

Shapes: ``times`` (n,) s, sorted; residuals (n,) or (n, k) m (k columns share one filter: a residual and its
Jacobian's columns are whitened together); ``sensitivity`` (n, q) m, or None.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np
import numpyro.distributions as _dist
from jaxtyping import ArrayLike, Float

from growjax.calibration.hyperparameters import (
    AMPLITUDE_SCALE,
    KINDS,
    NOISE_SCALE,
    NOISE_TIME_BOUNDS,
    NOISE_TIME_LOG_SD,
    NOISE_TIME_MEDIAN,
    TIME_SCALE_LOG_SD,
    TIME_SCALE_MEDIAN,
    Hyper,
    log_prior,
)
from growjax.calibration.kernels import DRIFT_GRID, DRIFT_SHARE, drift_columns, drift_kernel, kernel, noise_kernel

__all__ = [
    "AMPLITUDE_SCALE",
    "DRIFT_GRID",
    "DRIFT_SHARE",
    "KINDS",
    "NOISE_SCALE",
    "NOISE_TIME_BOUNDS",
    "NOISE_TIME_LOG_SD",
    "NOISE_TIME_MEDIAN",
    "TIME_SCALE_LOG_SD",
    "TIME_SCALE_MEDIAN",
    "Hyper",
    "MeasuredLength",
    "distribution",
    "draw",
    "drift_columns",
    "drift_kernel",
    "estimate",
    "forecast",
    "kalman_filter",
    "kernel",
    "matern_transition",
    "log_likelihood",
    "log_likelihood_runs",
    "log_prior",
    "noise_kernel",
    "smooth",
    "whiten",
]

_JITTER = 1e-24  # m², keeps an innovation variance positive where two samples coincide


def matern_transition(dt, amplitude, time_scale):
    """(A (2, 2), Q (2, 2), stationary covariance (2, 2)) of a Matérn-3/2 process's state (δ, δ') over ``dt``
    s: amplitude ``amplitude`` (δ's unit), time scale ``time_scale`` (s). The exact discretisation of its
    two-state linear SDE (Hartikainen & Särkkä 2010): δ(t + dt) = A (δ, δ')(t) + N(0, Q)."""
    lam = jnp.sqrt(3.0) / time_scale
    a2 = jnp.asarray(amplitude, float) ** 2
    stationary = jnp.diag(jnp.stack([a2, lam**2 * a2]))
    e = jnp.exp(-lam * dt)
    trans = e * jnp.array([[1.0 + lam * dt, dt], [-(lam**2) * dt, 1.0 - lam * dt]])
    return trans, stationary - trans @ stationary @ trans.T, stationary


def _transition(dt, hyper: Hyper):
    """(A (3, 3), Q (3, 3), stationary covariance (3, 3)) of the state (δ, δ', ε) over dt (s): the Matérn-3/2
    pair and the noise's Ornstein–Uhlenbeck state (for τ = 0 it forgets itself at every sample)."""
    smooth, _, pair = matern_transition(dt, hyper.amplitude, hyper.time_scale)
    s2 = hyper.noise**2
    stationary = jax.scipy.linalg.block_diag(pair, s2[None, None])
    tau = hyper.noise_time
    rho = jnp.where(tau > 0, jnp.exp(-dt / jnp.where(tau > 0, tau, 1.0)), 0.0)
    trans = jax.scipy.linalg.block_diag(smooth, rho[None, None])
    return trans, stationary - trans @ stationary @ trans.T, stationary


def kalman_filter(residuals, times, hyper: Hyper, sensitivity=None, tolerance=None, observed=None, hoist: bool = True):
    """Kalman filter of the residual model over ``residuals`` (n,) or (n, k).

    ``sensitivity`` (n, q) and ``tolerance`` (q,) add the rig terms Σⱼ gⱼ(t) bⱼ, bⱼ ~ N(0, uⱼ²); ``observed``
    (n,) bool marks the samples that update the filter (default all): at the others the filter only
    predicts. ``hoist``: compute every step's transition before the loop (quicker for one filter; under ``vmap``
    over many hyperparameters, False keeps them inside the loop and the memory small). Returns (innovations
    (n,) or (n, k) m, their variances (n,) m², the predicted residual
    δ + rig term + ε (n,) or (n, k) m and its variance (n,) m² before each update; the innovation is the
    residual less that prediction, so the two variances are one).
    """
    r = jnp.asarray(residuals, float)
    vector = r.ndim == 1
    r = r[:, None] if vector else r
    n, k = r.shape
    t = jnp.asarray(times, float)
    q = 0 if sensitivity is None else sensitivity.shape[1]
    g = jnp.zeros((n, 0)) if q == 0 else jnp.asarray(sensitivity, float)
    u2 = jnp.zeros((0,)) if q == 0 else jnp.asarray(tolerance, float) ** 2
    obs = jnp.ones(n, bool) if observed is None else jnp.asarray(observed, bool)
    _, _, stationary = _transition(0.0, hyper)
    p0 = jax.scipy.linalg.block_diag(stationary, jnp.diag(u2)) if q else stationary
    dts = jnp.diff(t, prepend=t[0])

    if hoist:  # every step's transition at once, outside the loop: the loop's body stays small
        a_all, q_all, _ = jax.vmap(lambda dt: _transition(dt, hyper))(dts)
        steps = (a_all, q_all)
    else:
        steps = (dts,)

    def step(carry, inp):
        m, p = carry
        *how, y, gk, ok = inp
        a_d, q_d = how if hoist else _transition(how[0], hyper)[:2]
        a = jax.scipy.linalg.block_diag(a_d, jnp.eye(q)) if q else a_d
        qn = jax.scipy.linalg.block_diag(q_d, jnp.zeros((q, q))) if q else q_d
        m = a @ m
        p = a @ p @ a.T + qn
        h = jnp.concatenate([jnp.array([1.0, 0.0, 1.0]), gk])
        ph = p @ h
        s = h @ ph + _JITTER
        pred = h @ m
        pred_var = s
        v = y - pred
        gain = jnp.where(ok, ph / s, 0.0)
        m = m + gain[:, None] * v[None, :]
        p = p - jnp.outer(gain, ph)
        p = 0.5 * (p + p.T)
        return (m, p), (v, s, pred, pred_var)

    init = (jnp.zeros((3 + q, k)), p0)
    _, (v, s, pred, pred_var) = jax.lax.scan(step, init, (*steps, r, g, obs))
    if vector:
        v, pred = v[:, 0], pred[:, 0]
    return v, s, pred, pred_var


def log_likelihood(
    residuals: Float[ArrayLike, " n"],
    times: Float[ArrayLike, " n"],
    hyper: Hyper,
    sensitivity=None,
    tolerance=None,
    observed=None,
    pointwise: bool = False,
):
    """Exact log-likelihood (nats) of ``residuals`` (n,) m at the ``observed`` samples (default all) under the
    residual model; ``pointwise``: the (n,) one-step-ahead terms log p(yᵢ | earlier observed y), whose sum is
    the total (0 where not observed)."""
    if sensitivity is not None and not pointwise:
        return _log_likelihood_static(residuals, times, hyper, sensitivity, tolerance, observed)
    v, s, _, _ = kalman_filter(residuals, times, hyper, sensitivity, tolerance, observed)
    terms = -0.5 * (jnp.log(2.0 * jnp.pi * s) + v**2 / s)
    if observed is not None:
        terms = jnp.where(jnp.asarray(observed, bool), terms, 0.0)
    return terms if pointwise else jnp.sum(terms)


def _log_likelihood_static(residuals, times, hyper: Hyper, sensitivity, tolerance, observed):
    """The total of :func:`log_likelihood` with the rig terms, by the three-state filter and a q × q correction
    instead of the (3 + q)-state filter: the same number to rounding, and several times cheaper (the loop carries
    3 × 3 matrices, not (3 + q) × (3 + q)).

    With K the covariance of δ + ε and W = K^{-1/2} G U (the filter's whitened sensitivity columns, each scaled by
    its tolerance), Woodbury's identity and the determinant lemma give
    rᵀC⁻¹r = |w|² − bᵀM⁻¹b and log det C = log det K + log det M, with w = K^{-1/2} r, b = Wᵀw, M = I + WᵀW.
    """
    r = jnp.asarray(residuals, float)
    g = jnp.asarray(sensitivity, float) * jnp.asarray(tolerance, float)
    v, s, _, _ = kalman_filter(jnp.concatenate([r[:, None], g], axis=1), times, hyper, observed=observed)
    w = v / jnp.sqrt(s)[:, None]
    log_s = jnp.log(2.0 * jnp.pi * s)
    if observed is not None:
        ok = jnp.asarray(observed, bool)
        w, log_s = jnp.where(ok[:, None], w, 0.0), jnp.where(ok, log_s, 0.0)
    wr, wg = w[:, 0], w[:, 1:]
    chol = jnp.linalg.cholesky(jnp.eye(g.shape[1]) + wg.T @ wg)
    c = jax.scipy.linalg.solve_triangular(chol, wg.T @ wr, lower=True)
    return -0.5 * (jnp.sum(log_s) + wr @ wr - c @ c) - jnp.sum(jnp.log(jnp.diag(chol)))


def log_likelihood_runs(residuals, times, hyper: Hyper, sensitivity, tolerance, observed, rig_index, n_rigs: int = 1):
    """Exact log-likelihood (nats) of several runs' residuals whose rig terms are shared: run e's residual is its
    own discrepancy and noise (hyperparameters ``hyper``, batched over runs) plus Σⱼ g_ej b_kj with b_k ~ N(0, U)
    one vector per rig k = ``rig_index[e]``, the same for every run on that rig.

    Shapes: ``residuals``, ``times``, ``observed`` (E, n) (pad short runs with unobserved samples);
    ``sensitivity`` (E, n, q) m; ``tolerance`` (q,); ``rig_index`` (E,) int in [0, ``n_rigs``). Each run is
    whitened by its own three-state filter; the rig's q × q correction (Woodbury's identity, the determinant
    lemma) sums the runs of each rig, so a shared error counts once however many runs see it.
    """
    r = jnp.asarray(residuals, float)
    g = jnp.asarray(sensitivity, float) * jnp.asarray(tolerance, float)
    obs = jnp.asarray(observed, bool)

    def run(r_e, g_e, t_e, h_e, o_e):
        v, s, _, _ = kalman_filter(jnp.concatenate([r_e[:, None], g_e], axis=1), t_e, h_e, observed=o_e)
        w = jnp.where(o_e[:, None], v / jnp.sqrt(s)[:, None], 0.0)
        return w[:, 0], w[:, 1:], jnp.sum(jnp.where(o_e, jnp.log(2.0 * jnp.pi * s), 0.0))

    wr, wg, log_s = jax.vmap(run)(r, g, jnp.asarray(times, float), hyper, obs)
    q = g.shape[-1]
    gram = jax.ops.segment_sum(jnp.einsum("eni,enj->eij", wg, wg), rig_index, n_rigs) + jnp.eye(q)
    cross = jax.ops.segment_sum(jnp.einsum("eni,en->ei", wg, wr), rig_index, n_rigs)
    chol = jnp.linalg.cholesky(gram)
    c = jax.vmap(lambda l_k, b_k: jax.scipy.linalg.solve_triangular(l_k, b_k, lower=True))(chol, cross)
    logdet = jnp.sum(jnp.log(jnp.diagonal(chol, axis1=-2, axis2=-1)))
    return -0.5 * (jnp.sum(log_s) + jnp.sum(wr**2) - jnp.sum(c**2)) - logdet


def whiten(
    residuals: Float[ArrayLike, " n"] | Float[ArrayLike, " n k"],
    times: Float[ArrayLike, " n"],
    hyper: Hyper,
    sensitivity=None,
    tolerance=None,
    observed=None,
):
    """Whitened residuals (n,) or (n, k): v/√S, independent N(0, 1) under the model (0 at samples not
    ``observed``). Linear in the residuals, so Gauss–Newton on the whitened residuals and whitened Jacobian
    is generalised least squares."""
    v, s, _, _ = kalman_filter(residuals, times, hyper, sensitivity, tolerance, observed)
    w = v / jnp.sqrt(s if v.ndim == 1 else s[:, None])
    if observed is not None:
        ok = jnp.asarray(observed, bool)
        w = jnp.where(ok if w.ndim == 1 else ok[:, None], w, 0.0)
    return w


def forecast(residuals, times, observed, hyper: Hyper, sensitivity=None, tolerance=None):
    """Predictive mean (n,) m and variance (n,) m² of a measurement's residual (δ + rig term + noise) at every
    sample, conditioned on the residuals at the ``observed`` (n,) samples before it (the filter's prediction;
    beyond the last observed sample, the forecast)."""
    _, _, pred, pred_var = kalman_filter(residuals, times, hyper, sensitivity, tolerance, observed)
    return pred, pred_var


def smooth(
    residuals: Float[ArrayLike, " n"],
    times: Float[ArrayLike, " n"],
    hyper: Hyper,
    sensitivity=None,
    tolerance=None,
    observed=None,
):
    """Mean (n,) m and variance (n,) m² of the model's error δ(tᵢ) + Σⱼ gⱼ(tᵢ) bⱼ at every sample, given the
    residuals (n,) m at the ``observed`` (n,) samples (default all), before and after each one: the
    Rauch–Tung–Striebel smoother over the filter's states, the sensor noise left out. What a replication of the
    same experiment (same discrepancy, same rig, fresh noise) keeps of the error.
    """
    r = jnp.asarray(residuals, float)
    n, t = r.shape[0], jnp.asarray(times, float)
    q = 0 if sensitivity is None else sensitivity.shape[1]
    g = jnp.zeros((n, 0)) if q == 0 else jnp.asarray(sensitivity, float)
    u2 = jnp.zeros((0,)) if q == 0 else jnp.asarray(tolerance, float) ** 2
    obs = jnp.ones(n, bool) if observed is None else jnp.asarray(observed, bool)
    _, _, stationary = _transition(0.0, hyper)
    a_d, q_d, _ = jax.vmap(lambda dt: _transition(dt, hyper))(jnp.diff(t, prepend=t[0]))
    eye, zero = jnp.eye(q), jnp.zeros((q, q))
    a_all = jax.vmap(lambda a: jax.scipy.linalg.block_diag(a, eye))(a_d)
    q_all = jax.vmap(lambda x: jax.scipy.linalg.block_diag(x, zero))(q_d)

    def forward(carry, inp):
        m, p = carry
        a, qn, y, gk, ok = inp
        m_pred, p_pred = a @ m, a @ p @ a.T + qn
        h = jnp.concatenate([jnp.array([1.0, 0.0, 1.0]), gk])
        ph = p_pred @ h
        gain = jnp.where(ok, ph / (h @ ph + _JITTER), 0.0)
        m = m_pred + gain * (y - h @ m_pred)
        p = p_pred - jnp.outer(gain, ph)
        return (m, 0.5 * (p + p.T)), (m_pred, p_pred, m, 0.5 * (p + p.T))

    p0 = jax.scipy.linalg.block_diag(stationary, jnp.diag(u2))
    _, (m_pred, p_pred, m_f, p_f) = jax.lax.scan(forward, (jnp.zeros(3 + q), p0), (a_all, q_all, r, g, obs))

    def backward(carry, inp):
        m_s, p_s = carry
        m_fk, p_fk, a_next, m_pred_next, p_pred_next = inp
        c = jnp.linalg.solve(p_pred_next, a_next @ p_fk).T  # P_f Aᵀ P_pred⁻¹ (P_pred symmetric)
        m_s = m_fk + c @ (m_s - m_pred_next)
        p_s = p_fk + c @ (p_s - p_pred_next) @ c.T
        return (m_s, 0.5 * (p_s + p_s.T)), (m_s, p_s)

    last = (m_f[-1], p_f[-1])
    _, (m_s, p_s) = jax.lax.scan(backward, last, (m_f[:-1], p_f[:-1], a_all[1:], m_pred[1:], p_pred[1:]), reverse=True)
    m_s, p_s = jnp.concatenate([m_s, last[0][None]]), jnp.concatenate([p_s, last[1][None]])
    h = jnp.concatenate([jnp.broadcast_to(jnp.array([1.0, 0.0, 0.0]), (n, 3)), g], axis=1)
    return jnp.einsum("ni,ni->n", h, m_s), jnp.einsum("ni,nij,nj->n", h, p_s, h)


def draw(key, times, hyper: Hyper, shape=(), noise: bool = False):
    """Draws of δ at ``times`` (n,) from the Matérn-3/2 prior, plus the sensor noise ε if ``noise``: shape
    ``shape + (n,)`` m."""
    t = jnp.asarray(times, float)
    dts = jnp.diff(t, prepend=t[0])
    _, _, stationary = _transition(0.0, hyper)
    k0, k1 = jax.random.split(key)
    x0 = jax.random.normal(k0, shape + (3,)) * jnp.sqrt(jnp.diag(stationary))
    xi = jax.random.normal(k1, (t.size,) + shape + (3,))
    h = jnp.array([1.0, 0.0, 1.0 if noise else 0.0])

    def step(x, inp):
        dt, e = inp
        a, q, _ = _transition(dt, hyper)
        chol = jnp.linalg.cholesky(q + 1e-30 * jnp.eye(3))
        x = x @ a.T + e @ chol.T
        return x, x @ h

    _, d = jax.lax.scan(step, x0, (dts, xi))
    return jnp.moveaxis(d, 0, -1)


def _negative_log_posterior(log_hyper, residuals, times, sensitivity, tolerance, observed, kind):
    if kind == "none":
        hyper = Hyper.of(0.0, 1.0, jnp.exp(log_hyper[2]), 0.0)
        return -(
            log_likelihood(residuals, times, hyper, sensitivity, tolerance, observed)
            - 0.5 * (hyper.noise / NOISE_SCALE) ** 2
            + jnp.log(hyper.noise)
        )
    hyper = Hyper(*jnp.exp(log_hyper))
    return -(log_likelihood(residuals, times, hyper, sensitivity, tolerance, observed) + log_prior(hyper))


_objective = jax.jit(jax.value_and_grad(_negative_log_posterior), static_argnames="kind")


def estimate(
    residuals,
    times,
    kind: str = "matern32",
    sensitivity=None,
    tolerance=None,
    observed=None,
    start: Hyper | None = None,
) -> Hyper:
    """Hyperparameters at the mode of their posterior given ``residuals`` (n,) m (the model's θ held fixed).

    ``kind="none"``: σ alone (a = 0, τ = 0). Quasi-Newton (L-BFGS-B) in the log coordinates, from ``start`` or
    from a spread of starts (the likelihood can have one mode with δ absorbing the residual and one with the
    noise doing so).
    """
    from scipy.optimize import minimize

    if kind not in KINDS:
        raise ValueError(f"discrepancy must be one of {KINDS}, got {kind!r}")
    r = jnp.asarray(residuals, float)
    t = jnp.asarray(times, float)
    g = None if sensitivity is None else jnp.asarray(sensitivity, float)
    u = None if tolerance is None else jnp.asarray(tolerance, float)
    obs = jnp.ones(r.shape[0], bool) if observed is None else jnp.asarray(observed, bool)
    rms = max(float(np.sqrt(np.mean(np.asarray(r)[np.asarray(obs)] ** 2))), 1e-7)
    if start is not None:
        starts = [
            np.log(
                [
                    float(start.amplitude) if kind != "none" else 1.0,
                    float(start.time_scale),
                    float(start.noise),
                    max(float(start.noise_time), NOISE_TIME_BOUNDS[0]),
                ]
            )
        ]
    elif kind == "none":
        starts = [np.log([1.0, 1.0, rms, NOISE_TIME_MEDIAN])]
    else:
        starts = [
            np.log([rms, TIME_SCALE_MEDIAN, 0.3 * rms, NOISE_TIME_MEDIAN]),
            np.log([0.3 * rms, 0.2, rms, NOISE_TIME_MEDIAN]),
        ]

    def fun(x):
        f, grad = _objective(jnp.asarray(x), r, t, g, u, obs, kind)
        f, grad = float(f), np.asarray(grad, float)
        return (f, grad) if np.isfinite(f) and np.all(np.isfinite(grad)) else (1e300, np.zeros(4))

    bounds = [
        (np.log(1e-9), np.log(1.0)),
        (np.log(1e-3), np.log(1e3)),
        (np.log(1e-9), np.log(1.0)),
        tuple(np.log(NOISE_TIME_BOUNDS)),
    ]

    def search(x0):  # stop at a projected gradient of 1e-3 nats per unit of ln h: well within the mode's spread
        return minimize(fun, x0, jac=True, method="L-BFGS-B", bounds=bounds, options={"gtol": 1e-3})

    if len(starts) == 1:
        best = search(starts[0])
    else:  # independent starts: one thread each (a compiled evaluation releases the GIL; the result is the same)
        with ThreadPoolExecutor(max_workers=len(starts)) as pool:
            best = min(pool.map(search, starts), key=lambda res: res.fun)
    a, ell, s, tau = np.exp(best.x)
    return Hyper.of(0.0, ell, s, 0.0) if kind == "none" else Hyper.of(a, ell, s, tau)


def distribution(mean, times, hyper: Hyper, sensitivity=None, tolerance=None, observed=None):
    """The measured length as a NumPyro distribution: event shape (n,), mean ``mean`` (n,) m plus the residual
    model (:class:`MeasuredLength`)."""
    return MeasuredLength(mean, times, hyper, sensitivity, tolerance, observed)


class MeasuredLength(_dist.Distribution):
    """y = model + δ + Σ g b + ε over ``times`` (n,): log-density by :func:`log_likelihood` (at the ``observed``
    samples), draws by `draw` plus the rig terms and the noise."""

    support = _dist.constraints.real_vector

    def __init__(self, model, times, hyper: Hyper, sensitivity=None, tolerance=None, observed=None, validate_args=None):
        self.model, self.times, self.hyper = jnp.asarray(model), jnp.asarray(times), hyper
        self.sensitivity, self.tolerance, self.observed = sensitivity, tolerance, observed
        super().__init__(batch_shape=(), event_shape=self.model.shape[-1:], validate_args=validate_args)

    def log_prob(self, value):
        return log_likelihood(
            value - self.model, self.times, self.hyper, self.sensitivity, self.tolerance, self.observed
        )

    def pointwise(self, value):
        """(n,) one-step-ahead log-densities (0 where not observed)."""
        return log_likelihood(
            value - self.model, self.times, self.hyper, self.sensitivity, self.tolerance, self.observed, pointwise=True
        )

    def sample(self, key, sample_shape=()):
        k_delta, k_rig = jax.random.split(key)
        shape = tuple(sample_shape)
        y = self.model + draw(k_delta, self.times, self.hyper, shape, noise=True)
        if self.sensitivity is not None:
            b = jax.random.normal(k_rig, shape + (self.sensitivity.shape[1],)) * self.tolerance
            y = y + b @ self.sensitivity.T
        return y
