"""Scoring a model against the data: the noise, the misfit test, and the likelihood-ratio and Bayes-factor
scores of a round's candidates."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

from growjax.calibration import RunScore
from growjax.calibration import discrepancy as dc
from growjax.data import experiment

from ._candidates import Z90, CandidateFit, candidate_parameter

PINNED_FACTOR = 2.0  # a correlated effect whose 90 % interval lies within [η/2, 2η] is determined, not confounded
MATERIAL_MISFIT = 5e-4  # m: a smooth misfit below this amplitude is left to the discrepancy term
STRUCTURE_THRESHOLD = float(stats.chi2.isf(0.01, df=2))
_log_likelihood = jax.jit(dc.log_likelihood)


def shared_intervals(fit: CandidateFit, scorer: Scorer, model_error: float) -> dict:
    """{name: (low, high)} SI: the 90 % intervals of ``fit``'s parameters under the scorer's likelihood, treated as
    `growjax.calibration.fit` treats them: the generalised least-squares covariance under the discrepancy and
    noise at their mode, the rig's tolerances inferred (marginalised under their priors), the fitted
    configuration's own error ``model_error`` (m) propagated, and the spread over the hyperparameters. A
    parameter fitted in ln θ gets θ·exp(±z σ), an effect's θ ± z σ within its range."""
    if fit.jacobian is None or (scorer.kind == "none" and scorer.sensitivity is None):
        return dict(fit.interval_90)
    hyper = scorer.profile(fit.residual_m)[1]
    n = len(scorer.times)
    used = np.ones(n, bool) if scorer.observed is None else np.asarray(scorer.observed, bool)
    likelihood = RunScore.of(scorer.times, used, 1e-3)
    q = 0
    if scorer.sensitivity is not None:
        q = len(scorer.tolerance)
        likelihood = likelihood.with_tolerances(
            scorer.sensitivity, {f"rig_{j}": u for j, u in enumerate(scorer.tolerance)}, inferred=True
        )
    raw = (jnp.asarray(np.asarray(fit.residual_m) / 1e-3), jnp.asarray(fit.jacobian))
    b = np.zeros(q)
    cov, _, _ = likelihood.covariance(raw, hyper, b, model_error)
    if scorer.kind != "none":
        cov = cov + likelihood.hyperparameter_spread(raw, hyper, cov, b)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out = {}
    for i, (name, value) in enumerate(fit.estimate.items()):
        if fit.log_coordinate[i]:
            out[name] = (float(value * math.exp(-Z90 * sd[i])), float(value * math.exp(Z90 * sd[i])))
        else:
            lo, hi = fit.ranges[i]
            half = Z90 * sd[i] * abs(float(fit.slopes[i]))
            out[name] = (float(max(value - half, lo)), float(min(value + half, hi)))
    return out


def noise_from_differences(residual) -> float:
    """White-noise σ (m) of a residual series from its successive differences: var(Δr)/2 (von Neumann)."""
    d = np.diff(np.asarray(residual, float))
    return float(np.sqrt(np.mean(d**2) / 2.0))


def misfit_test(residual, sigma: float, z_limit: float = 4.0, ratio_limit: float = 1.2) -> dict:
    """Whether the residuals (m) carry structure beyond white noise of scale ``sigma`` (m).

    Two statistics: the lag-1 autocorrelation ρ̂ (its z-score ρ̂·√m is N(0, 1) for white noise) and
    the ratio RMSE/σ (≈ 1 for white noise). Structured if z > ``z_limit`` or the ratio > ``ratio_limit``.
    """
    r = np.asarray(residual, float)
    m = r.size
    c = r - r.mean()
    rho = float(np.sum(c[1:] * c[:-1]) / max(np.sum(c * c), 1e-300))
    z = rho * math.sqrt(m)
    rmse = float(np.sqrt(np.mean(r**2)))
    ratio = rmse / sigma if sigma > 0 else math.inf
    return {
        "rmse_m": rmse,
        "noise_sigma_m": float(sigma),
        "rmse_over_noise": ratio,
        "lag1_autocorrelation": rho,
        "autocorrelation_z": z,
        "structured": bool(z > z_limit or ratio > ratio_limit),
    }


class Scorer:
    """Likelihood-ratio scores and the misfit test under the fit's likelihood (`growjax.calibration.discrepancy`).

    ``discrepancy="matern32"``: a model's score is its log-likelihood with the residual model's
    hyperparameters at their mode for that model's residuals, and the rig's tolerances marginalised (after
    `with_tolerances`: every model is then scored against what the fixed parameters' errors could do);
    the misfit is structured where the discrepancy is significant against white noise (2ΔlogL above the 1 %
    point of χ²₂) and larger than the noise, and material where its amplitude also exceeds ``material`` (m):
    only a material misfit that no candidate removes is reported ``unexplained``; a smaller one is left to the
    discrepancy term. ``"none"``: independent noise of sd ``sigma`` (m) and `misfit_test`.
    A record interpolated between keyframes is scored at its keyframes.
    """

    def __init__(self, times, length, sigma: float, discrepancy: str, material: float = MATERIAL_MISFIT):
        self.times, self.sigma, self.kind, self.material = np.asarray(times, float), sigma, discrepancy, material
        self.observed = experiment.informative_samples(length) if discrepancy != "none" else None
        self.scored = int(np.sum(self.observed)) if self.observed is not None else len(self.times)
        self.sensitivity = self.tolerance = None
        self._cache, self._start = {}, None

    def with_tolerances(self, sensitivity, tolerance) -> None:
        """Marginalise the rig's tolerances in every score from now on: ``sensitivity`` (n, q) m per unit ln ψ
        (the length's, at the base fit), ``tolerance`` (q,) relative sds."""
        self.sensitivity, self.tolerance = np.asarray(sensitivity, float), np.asarray(tolerance, float)
        self._cache, self._start = {}, None

    def anchor(self, residual) -> None:
        """Start every later model's hyperparameter search at the mode for ``residual`` (m; the base model's), from
        one start instead of a spread: a nested model's residuals differ from the base's by one effect, and its
        mode lies near the base's (on the discovery benchmarks' data the scores agree with a search from the
        spread of starts to 0.1 nats)."""
        self._start = self.profile(residual)[1]

    @property
    def _seen(self):
        """The rows scored: a boolean mask, or every row."""
        return slice(None) if self.observed is None else self.observed

    def profile(self, residual, kind: str | None = None) -> tuple[float, dc.Hyper]:
        """(log-likelihood, nats, at the hyperparameters' mode for ``residual``; that mode)."""
        kind = kind or self.kind
        r = np.asarray(residual, float)
        key = (kind, r.tobytes())
        if key not in self._cache:
            seen = self._seen  # the filter over the scored rows: exact
            t, g = self.times[seen], None if self.sensitivity is None else self.sensitivity[seen]
            hyper = dc.estimate(r[seen], t, kind, g, self.tolerance, start=self._start if kind == self.kind else None)
            value = _log_likelihood(jnp.asarray(r[seen]), jnp.asarray(t), hyper, g, self.tolerance)
            self._cache[key] = (float(value), hyper)
        return self._cache[key]

    def allowance(self, residual, error: float, time_scale: float) -> float:
        """The expected 2ΔlogL that a slow drift of RMS ``error`` (m; squared-exponential over ``time_scale`` s, the
        fitted configuration's own error against the reference) buys a model that can follow it, under this
        scorer's likelihood at the mode for ``residual``: tr(K⁻¹ K_e), K the residuals' covariance, K_e the drift's.
        Under independent noise it is m·e²/σ²; a discrepancy that already takes slow structure leaves less."""
        if error <= 0.0:
            return 0.0
        if self.kind == "none" and self.sensitivity is None:
            return self.scored * error**2 / self.sigma**2
        hyper = self.profile(residual)[1]
        seen = self._seen
        t = self.times[seen]
        cov = dc.kernel(t, hyper) + dc.noise_kernel(t, hyper)
        if self.sensitivity is not None:
            g = self.sensitivity[seen]
            cov = cov + (g * self.tolerance**2) @ g.T
        return float(np.trace(np.linalg.solve(cov, dc.drift_kernel(t, error, time_scale))))

    def noise(self, residual) -> float:
        return float(self.profile(residual)[1].noise)

    def lr(self, worse, better, signed: bool = False) -> float:
        """2ΔlogL of the model with residuals ``better`` (m) over the one with ``worse`` (≥ 0 unless ``signed``)."""
        if self.kind == "none" and self.sensitivity is None:
            value = (float(np.sum(np.asarray(worse) ** 2)) - float(np.sum(np.asarray(better) ** 2))) / self.sigma**2
        else:
            value = 2.0 * (self.profile(better)[0] - self.profile(worse)[0])
        return value if signed else max(value, 0.0)

    def misfit(self, residual) -> dict:
        """:func:`misfit_test`'s statistics, and under the discrepancy its amplitude, time scale and noise, the
        2ΔlogL of the discrepancy against white noise, and ``structured`` by the rule above."""
        if self.kind == "none":
            return misfit_test(residual, self.sigma)
        smooth, hyper = self.profile(residual)
        white = self.profile(residual, "none")[0]
        out = misfit_test(residual, float(hyper.noise))
        lr = 2.0 * (smooth - white)
        out.update(
            {
                "discrepancy": hyper.as_dict(),
                "discrepancy_lr": lr,
                "noise_sigma_m": float(hyper.noise),
                "rmse_over_noise": out["rmse_m"] / float(hyper.noise),
                "structured": bool(lr > STRUCTURE_THRESHOLD and float(hyper.amplitude) > float(hyper.noise)),
                "material": bool(float(hyper.amplitude) > self.material),
            }
        )
        return out


def is_pinned(estimate: float, interval) -> bool:
    """Whether the data fix an effect's size: its 90 % interval excludes zero and lies within a factor
    `PINNED_FACTOR` of the estimate. An interval of (near) zero width is not pinned: the effect's Jacobian column
    vanished (η deep in softplus's flat end) and the pseudo-inverse dropped its variance instead of making it
    infinite.

    Args:
        estimate: the effect parameter's estimate (its units).
        interval: (low, high), its 90 % interval (the same units).

    Returns:
        True where pinned.
    """
    lo, hi = interval
    size = abs(estimate)
    return (
        lo * hi > 0
        and hi - lo > 1e-6 * size
        and min(abs(lo), abs(hi)) >= size / PINNED_FACTOR
        and max(abs(lo), abs(hi)) <= PINNED_FACTOR * size
    )


def score_candidate(
    name: str,
    fitted: CandidateFit,
    residual,
    scorer: Scorer,
    threshold: float,
    confounding_correlation: float,
    held_lr: float = 0.0,
    trades: bool = False,
    allowance: float = 0.0,
) -> dict:
    """The evidence for candidate ``name`` from its fit ``fitted`` on top of the current model (residuals ``residual``,
    m): 2ΔlogL and its p-value, the Laplace log Bayes factor against a uniform prior on the effect's range, the
    estimate and interval, the correlation with the base parameters, and whether it clears ``threshold``, is pinned,
    lies at its range's edge or is confounded. ``held_lr``: its 2ΔlogL with the base held (first round);
    ``trades``: whether with the base held it trades with a base parameter (first round); ``allowance``: the
    2ΔlogL the fitted configuration's own error can buy through a candidate correlated with a base parameter
    (such a candidate clears, or is confounded, only above ``threshold + allowance``)."""
    qname, unit, rng = candidate_parameter(name)
    lr = scorer.lr(residual, fitted.residual_m)
    sd = max((fitted.interval_90[qname][1] - fitted.interval_90[qname][0]) / (2 * Z90), 1e-300)
    corr = fitted.correlation.get(qname, {})
    _, c = max(corr.items(), key=lambda kv: abs(kv[1]), default=(None, 0.0))
    bar = threshold + (allowance if abs(c) > confounding_correlation else 0.0)
    pinned = lr > bar and is_pinned(fitted.estimate[qname], fitted.interval_90[qname])
    return {
        "parameter": qname,
        "unit": unit,
        "estimate": fitted.estimate[qname],
        "interval_90": fitted.interval_90[qname],
        "lr_statistic": lr,
        "p_value": float(0.5 * stats.chi2.sf(lr, df=1)) if lr > 0 else 1.0,
        "log_bayes_factor": 0.5 * lr + math.log(math.sqrt(2 * math.pi) * sd / (rng[1] - max(rng[0], 0.0))),
        "rmse_m": float(np.sqrt(np.mean(fitted.residual_m**2))),
        "lr_statistic_base_held": held_lr,
        "correlation_with_base": corr,
        "clears_threshold": bool(lr > bar),
        "pinned": bool(pinned),
        # the fit pressed against its range's top (or a signed effect's bottom): the data ask for more
        "at_range_edge": bool(
            fitted.estimate[qname] >= rng[1] * (1 - 1e-6)
            or (rng[0] < 0 and fitted.estimate[qname] <= rng[0] * (1 - 1e-6))
        ),
        "confounded": bool(abs(c) > confounding_correlation and (lr > bar or trades) and not pinned),
    }


def score_round(
    fits: dict,
    residual,
    scorer: Scorer,
    threshold: float,
    confounding_correlation: float,
    held: dict | None = None,
    allowance: float = 0.0,
) -> dict:
    """{candidate: :func:`score_candidate`} of a round's ``fits`` {candidate: CandidateFit} on top of the current
    model (residuals ``residual``, m). ``held`` {candidate: (2ΔlogL with the base held, trades)}: the first round's
    base-held evidence (None in later rounds)."""
    return {
        name: score_candidate(
            name,
            fitted,
            residual,
            scorer,
            threshold,
            confounding_correlation,
            *(held[name] if held is not None else (0.0, False)),
            allowance,
        )
        for name, fitted in fits.items()
    }
