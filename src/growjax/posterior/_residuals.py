"""The likelihood's terms of a posterior: its `Residuals` (discrepancy, scored samples, the rig's tolerances, the
configuration's drift) and what the draws score under them."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from growjax.calibration import discrepancy as dc
from growjax.calibration import tolerance as tl
from growjax.data import experiment

from ._laplace import _scout
from ._model import Residuals


def likelihood_terms(
    discrepancy: str, tol: dict, t, y, mean, priors, model, seed: int, centre=None, model_error: float = 0.0
):
    """(:class:`Residuals` or None for independent noise, start values of σ and the discrepancy's sites);
    ``model`` = (base, inputs, config)."""
    if discrepancy == "none" and not tol and model_error == 0:
        return None, {}
    residuals, hyper = build_residuals(discrepancy, t, y, mean, priors, *model, tol, seed, centre, model_error)
    return residuals, {**residuals.hyper_sites(hyper), "sigma": float(hyper.noise)}


def likelihood_record(residuals: Residuals | None, y) -> dict:
    """The summary's ``tolerances`` {name: relative sd} and ``samples_used``."""
    tolerances = (
        dict(zip(residuals.tolerance_names, map(float, residuals.tolerance)))
        if (residuals is not None and residuals.tolerance is not None)
        else {}
    )
    return {
        "tolerances": tolerances,
        "samples_used": int(np.sum(residuals.observed)) if residuals is not None else int(y.size),
    }


def build_residuals(
    discrepancy: str,
    times,
    length,
    mean_length,
    priors,
    base,
    inputs,
    config,
    tol: dict,
    seed: int = 0,
    centre=None,
    model_error: float = 0.0,
) -> tuple[Residuals, dc.Hyper]:
    """The :class:`Residuals` of a posterior and its hyperparameters' start: the samples scored
    (`growjax.data.experiment.informative_samples` with a discrepancy), the rig's sensitivities at the scout's
    best θ (``base`` holds the rig where it is linearised; ``centre`` (q,) its errors ln(ψ/ψ₀) there, None at
    nominal: the slope there, as the fit takes it, rather than the secant from nominal), the configuration's own
    error ``model_error`` (m), and the hyperparameters' mode given the residuals there."""
    theta, _, _, _ = _scout(priors, mean_length, length, seed)
    observed = experiment.informative_samples(length) if discrepancy != "none" else np.ones(len(length), bool)
    g = u = None
    if tol:
        g = tl.length_sensitivity(theta, base, inputs, config, times, tol, central=centre is not None)
        u = np.asarray(list(tol.values()))
    residuals = Residuals(
        discrepancy,
        np.asarray(times),
        observed,
        g,
        u,
        tuple(tol),
        None if centre is None else np.asarray(centre, float),
        float(model_error),
    )
    r = (
        np.asarray(length)
        - np.asarray(jax.jit(mean_length)({k: jnp.asarray(v) for k, v in theta.items()}))
        - residuals.rig_mean()
    )
    g_all, u_all = residuals.columns()
    hyper = dc.estimate(r, times, discrepancy, g_all, u_all, observed)
    return residuals, hyper


def observation_draws(
    mean_length,
    sigma,
    model_error: float,
    observed,
    seed: int,
    residuals: Residuals | None = None,
    amplitude=None,
    time_scale=None,
    noise_time=None,
):
    """Pointwise log-likelihood and two posterior predictives of the length (m), all (C, S, T), of every draw.

    ``mean_length`` (C, S, T): the model's length (m) at each draw, which :func:`growth_model` records as
    ``length_model`` while NUTS samples; ``sigma`` (C, S): the noise scale (m); ``model_error`` (m) joins it as in
    the model; ``residuals``, ``amplitude``, ``time_scale`` and ``noise_time`` (C, S): the discrepancy, the noise's
    correlation time and the tolerances, if any. The
    pointwise terms are then the one-step-ahead log-densities log p(yᵢ | earlier y) (0 at samples not scored).
    Returns (log-likelihood, this experiment replicated, a new experiment): a replication keeps this experiment's
    discrepancy and rig error as the data determine them (`growjax.calibration.discrepancy.smooth`, each sample
    drawn from its marginal) with fresh sensor noise; a new experiment draws a fresh discrepancy and rig error (the
    band for running the rig again). Nothing is simulated again: NumPyro's ``Predictive`` and ArviZ's
    log-likelihood would each run the model once more per draw. Seeded by ``seed``.
    """
    from scipy.stats import norm

    mean_length = np.asarray(mean_length, float)
    scale = np.sqrt(np.asarray(sigma, float) ** 2 + model_error**2)
    finite = np.isfinite(mean_length)
    if residuals is None:
        loglik = np.where(
            finite,
            norm.logpdf(np.asarray(observed, float), np.where(finite, mean_length, 0.0), scale[..., None]),
            -np.inf,
        )
        noise = np.random.default_rng(seed).standard_normal(mean_length.shape)
        predicted = mean_length + scale[..., None] * noise
        return loglik, predicted, predicted
    shape = mean_length.shape
    mu = np.where(finite, mean_length, 0.0).reshape(-1, shape[-1])
    ones = np.ones(shape[:-1])
    amp = np.zeros(shape[:-1]) if amplitude is None else np.asarray(amplitude, float)
    ell = ones if time_scale is None else np.asarray(time_scale, float)
    tau = np.zeros(shape[:-1]) if noise_time is None else np.asarray(noise_time, float)
    hyper = dc.Hyper(
        jnp.asarray(amp.ravel()), jnp.asarray(ell.ravel()), jnp.asarray(scale.ravel()), jnp.asarray(tau.ravel())
    )
    y = jnp.asarray(observed, float)

    def one(args):
        m, h, key = args
        k_same, k_new = jax.random.split(key)
        mean, var = residuals.conditional(y, m, h)
        same = m + mean + jnp.sqrt(var + h.noise**2) * jax.random.normal(k_same, m.shape)
        return residuals.pointwise(y, m, h), same, residuals.replicate(m, h).sample(k_new)

    keys = jax.random.split(jax.random.PRNGKey(seed), mu.shape[0])
    # in batches: the smoother keeps every step's states, (T, 3 + q, 3 + q) a draw
    loglik, predicted, new = jax.jit(lambda *a: jax.lax.map(one, a, batch_size=64))(jnp.asarray(mu), hyper, keys)
    loglik = np.where(np.all(finite, axis=-1, keepdims=True), np.asarray(loglik).reshape(shape), -np.inf)
    return loglik, np.asarray(predicted).reshape(shape), np.asarray(new).reshape(shape)


__all__ = ["build_residuals", "likelihood_record", "likelihood_terms", "observation_draws"]
