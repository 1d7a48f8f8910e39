"""Checks and uses of a posterior: diagnostics, predictive bands and forecasts, SBC, LOO, Laplace."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from growjax.calibration import discrepancy as dc
from growjax.calibration import tolerance as tl
from growjax.posterior import emulator as em
from growjax.posterior.emulator import predicted_length
from growjax.simulation import xla_flags

from ._model import Residuals, emulated_mean, growth_model
from ._priors import Prior
from ._record import recorded_name, site_draws


def predictive_band(draws, level: float = 0.9):
    """(lower, upper) pointwise quantiles of predictive draws (S, T) at ``level``."""
    a = 0.5 * (1.0 - level)
    return np.nanquantile(draws, a, axis=0), np.nanquantile(draws, 1.0 - a, axis=0)


def diagnostics(idata, priors, observed, mcmc=None, residuals: Residuals | None = None) -> dict:
    """Posterior means and 90 % intervals, R-hat, ESS, divergences, BFMI and predictive coverage: the share of
    the measured samples inside the pointwise 90 % band of this experiment replicated (``coverage_90``) and of a
    new experiment (``coverage_90_new_experiment``, a fresh discrepancy and rig error: wider). ``idata``: the run's
    DataTree (:func:`inference_data`); R-hat, ESS and BFMI are arviz-stats'. ``parameters`` is keyed by NumPyro's
    site names, in SI units (σ in m, where the DataTree records ``sigma_mm``)."""
    import arviz_stats as azs

    post = idata.posterior
    sites = [p.site for p in priors] + ["sigma"]
    sites += [s for s in ("delta_amplitude", "delta_time_scale", "noise_time") if recorded_name(s) in post]
    names = [recorded_name(s) for s in sites]
    rhat = azs.rhat(idata, var_names=names)
    ess_bulk = azs.ess(idata, var_names=names, method="bulk")
    ess_tail = azs.ess(idata, var_names=names, method="tail")
    params = {}
    for s, name in zip(sites, names):
        x = site_draws(post, s).ravel()
        params[s] = {
            "mean": float(x.mean()),
            "sd": float(x.std()),
            "interval_90": [float(np.quantile(x, 0.05)), float(np.quantile(x, 0.95))],
            "rhat": float(rhat[name]),
            "ess_bulk": float(ess_bulk[name]),
            "ess_tail": float(ess_tail[name]),
        }
    div = int(np.asarray(idata.sample_stats["diverging"]).sum()) if "diverging" in idata.sample_stats else 0
    observed = np.asarray(observed)

    def coverage_of(name):
        pp = np.asarray(idata.posterior_predictive[name])
        lo, hi = predictive_band(pp.reshape(-1, pp.shape[-1]))
        return float(np.mean((observed >= lo) & (observed <= hi)))

    coverage = coverage_of("length")
    coverage_new = (
        coverage_of("length_new_experiment") if "length_new_experiment" in idata.posterior_predictive else coverage
    )
    return {
        "parameters": params,
        "rhat_max": float(max(p["rhat"] for p in params.values())),
        "ess_bulk_min": float(min(p["ess_bulk"] for p in params.values())),
        "ess_tail_min": float(min(p["ess_tail"] for p in params.values())),
        "divergences": div,
        "bfmi_min": float(np.min(np.asarray(azs.bfmi(idata)["energy"]))),
        "coverage_90": coverage,
        "coverage_90_new_experiment": coverage_new,
    }


def predict(idata, priors, base, inputs, config, times, seed: int = 0, max_draws: int = 400):
    """Posterior predictive length draws (S, T) for new ``inputs`` (e.g. another pressure profile), noise included."""
    post = idata.posterior
    flat = {p.site: np.asarray(post[p.site]).ravel() for p in priors}
    sigma = site_draws(post, "sigma").ravel()
    take = np.random.default_rng(seed).choice(sigma.size, size=min(max_draws, sigma.size), replace=False)
    thetas = {p.name: jnp.asarray(flat[p.site][take]) for p in priors}
    mu = jax.jit(jax.vmap(lambda th: predicted_length(th, base, inputs, config, jnp.asarray(times))))(thetas)
    noise = np.random.default_rng(seed + 1).normal(size=mu.shape) * sigma[take][:, None]
    return np.asarray(mu) + noise


def forecast(
    result, priors, base, inputs, config, times: Float[ArrayLike, " T"], seed: int = 0, max_draws: int = 400
) -> Float[np.ndarray, "S T"]:
    """Posterior predictive length draws (S, T), m, at ``times`` (s) beyond or between the data the posterior was
    fitted on, conditioned on them: each draw's model run over the fitted and the new times, its discrepancy
    (and rig terms) at the new times given its residuals at the fitted samples (the Kalman forecast), and fresh
    noise. Without a discrepancy (``result.residuals`` None) the draws are the model plus noise."""
    post = result.idata.posterior
    t_fit, y_fit = (np.asarray(a, float) for a in result.data)
    t_new = np.asarray(times, float)
    union = np.unique(np.concatenate([t_fit, t_new]))
    sigma = site_draws(post, "sigma").ravel()
    take = np.random.default_rng(seed).choice(sigma.size, size=min(max_draws, sigma.size), replace=False)
    thetas = {p.name: jnp.asarray(np.asarray(post[p.site]).ravel()[take]) for p in priors}
    res = result.residuals
    if res is not None:  # the model runs where the posterior linearised the rig
        base = tl.rig_at(base, res.tolerance_names, res.centre)
    mu = np.asarray(
        jax.jit(jax.vmap(lambda th: predicted_length(th, base, inputs, config, jnp.asarray(union))))(thetas)
    )
    at_fit, at_new = np.searchsorted(union, t_fit), np.searchsorted(union, t_new)
    rng = np.random.default_rng(seed + 1)
    if res is None:
        return mu[:, at_new] + sigma[take][:, None] * rng.standard_normal((take.size, at_new.size))
    observed = np.zeros(union.size, bool)
    observed[at_fit[res.observed]] = True
    g_np = None
    if res.sensitivity is not None:
        mean_theta = {n: float(np.mean(v)) for n, v in thetas.items()}
        g_np = tl.length_sensitivity(
            mean_theta,
            base,
            inputs,
            config,
            union,
            dict(zip(res.tolerance_names, map(float, res.tolerance))),
            central=res.centre is not None,
        )
        offset = np.asarray(res.rig_mean(g_np))  # the rig term's prior mean where the rig is not nominal
        mu = mu + offset
    g, u = res.columns(union, g_np)  # the rig's terms and the configuration's drift at every time
    g, u = (None, None) if g is None else (jnp.asarray(g), jnp.asarray(u))
    flat = lambda site: jnp.asarray(site_draws(post, site).ravel()[take]) if recorded_name(site) in post else None
    amp, ell, tau = flat("delta_amplitude"), flat("delta_time_scale"), flat("noise_time")
    hyper = dc.Hyper(
        jnp.zeros(take.size) if amp is None else amp,
        jnp.ones(take.size) if ell is None else ell,
        jnp.asarray(np.sqrt(sigma[take] ** 2 + result.summary.get("model_error_m", 0.0) ** 2)),
        jnp.zeros(take.size) if tau is None else tau,
    )
    r = np.zeros_like(mu)
    r[:, at_fit] = y_fit[None, :] - mu[:, at_fit]
    mean, var = jax.jit(jax.vmap(lambda ri, h: dc.forecast(ri, jnp.asarray(union), jnp.asarray(observed), h, g, u)))(
        jnp.asarray(r), hyper
    )
    scale = np.sqrt(np.asarray(var)[:, at_new])  # the filter's predictive variance includes the noise
    return mu[:, at_new] + np.asarray(mean)[:, at_new] + scale * rng.standard_normal(scale.shape)


def nuts_chain(info, warmup: int, samples: int, target_accept_prob: float):
    """One NUTS chain of a model set up by ``numpyro.infer.util.initialize_model(..., dynamic_args=True)`` as a pure
    function ``(start {site: unconstrained value}, key, model arguments) → ({site: (samples, …)} constrained,
    divergences)``: NumPyro's functional kernel in a ``lax.scan``, for ``jax.vmap`` over chains or data sets and one
    ``jit`` by the caller (``numpyro.infer.MCMC`` compiles its sampling loop again on every run)."""
    from numpyro.infer.hmc import hmc

    init_kernel, sample_kernel = hmc(potential_fn_gen=info.potential_fn, algo="NUTS")

    def chain(start, key, args):
        state = init_kernel(start, warmup, model_args=args, rng_key=key, target_accept_prob=target_accept_prob)

        def step(state, _):
            state = sample_kernel(state, model_args=args)
            return state, (state.z, state.diverging)

        _, (zs, diverging) = jax.lax.scan(step, state, None, length=warmup + samples)
        kept = jax.tree_util.tree_map(lambda a: a[warmup:], zs)
        return jax.vmap(info.postprocess_fn(*args))(kept), jnp.sum(diverging[warmup:])

    return chain


def sbc(
    emulator: em.Emulator,
    priors: Sequence[Prior],
    replicates: int = 100,
    warmup: int = 200,
    samples: int = 200,
    seed: int = 0,
    noise_scale: float = 1e-3,
    level: float = 0.9,
    truth_model=None,
    model_error: float = 0.0,
) -> dict:
    """Simulation-based calibration (Talts et al. 2018) of NUTS on :func:`growth_model`, all replicates at once.

    Each replicate draws θ and σ from the prior and a data set from the model (here its
    emulator, which is then exact by construction), and samples the posterior with NUTS
    (diagonal mass adapted in warm-up). All replicates run in one ``vmap``ped program
    (NumPyro's functional NUTS). A calibrated sampler ranks the truth uniformly among the
    draws and covers it with the central ``level`` interval in a share ``level`` of replicates.

    ``truth_model({qualified name: (replicates,) values}) → (replicates, m)`` clean lengths (m) at the emulator's
    times: data from another configuration (the reference), plus σ-noise, so the check also sees the
    emulated configuration's error against it; the likelihood then carries the emulator's RMS error and
    ``model_error`` (m, e.g. `growjax.calibration.FAST_MODEL_ERROR`, the fast configuration's against the
    reference), both as independent noise.

    Returns ``ranks`` {site: (replicates,) ints in [0, samples]}, ``coverage`` {site: share},
    ``divergences`` (total) and ``draws`` (samples per replicate).
    """
    from numpyro.infer import Predictive
    from numpyro.infer.util import initialize_model

    if truth_model is not None:
        model_error = float(np.hypot(float(emulator.error_rms), model_error))
        if not np.isfinite(model_error):
            raise ValueError(
                "sbc with a truth_model needs a validated emulator (growjax.posterior.emulator.validate): its "
                "error joins the noise"
            )
    model = functools.partial(
        growth_model,
        mean_length=emulated_mean(emulator),
        priors=priors,
        noise_scale=noise_scale,
        model_error=model_error,
    )
    k_prior, k_init, k_run, k_noise = jax.random.split(jax.random.PRNGKey(seed), 4)
    truth = Predictive(model, num_samples=replicates)(k_prior)
    if truth_model is not None:
        clean = jnp.asarray(truth_model({p.name: np.asarray(truth[p.site]) for p in priors}))
        noise = jax.random.normal(k_noise, clean.shape, clean.dtype) * truth["sigma"][:, None]
        truth = {**truth, "length": clean + noise}
    sites = [p.site for p in priors] + ["sigma"]
    info = initialize_model(k_init, model, model_args=(truth["length"][0],), dynamic_args=True)
    chain = nuts_chain(info, warmup, samples, target_accept_prob=0.9)

    def run(key, data):
        values, div = chain(info.param_info.z, key, (data,))
        return {s: values[s] for s in sites}, div

    # a long loop of a small model: XLA's full backend optimisation whatever the process's level
    program = jax.jit(jax.vmap(run), compiler_options=xla_flags.FULL_BACKEND)
    draws, div = program(jax.random.split(k_run, replicates), truth["length"])
    a = 0.5 * (1.0 - level)
    ranks, coverage = {}, {}
    for s in sites:
        d, t = np.asarray(draws[s]), np.asarray(truth[s])[:, None]
        ranks[s] = np.sum(d < t, axis=1)
        lo, hi = np.quantile(d, a, axis=1), np.quantile(d, 1.0 - a, axis=1)
        coverage[s] = float(np.mean((t[:, 0] >= lo) & (t[:, 0] <= hi)))
    return {"ranks": ranks, "coverage": coverage, "divergences": int(np.sum(np.asarray(div))), "draws": samples}


def compare_loo(results: dict) -> dict:
    """PSIS-LOO of several posteriors of the same data ({label: PosteriorResult}) via arviz-stats.

    Returns per model ``elpd_loo``, its standard error, ``p_loo``, the largest Pareto k̂, and
    the ArviZ ranking (``rank``, 0 the best; ``elpd_diff``, ``dse``, and the stacking ``weight``). The likelihood
    treats residuals as independent; when they are autocorrelated (model discrepancy) the standard errors are
    optimistic.
    """
    import arviz_stats as azs

    loos = {k: azs.loo(r.idata, pointwise=True, var_name="length") for k, r in results.items()}
    table = azs.compare(loos, method="stacking")
    out = {}
    for label, loo in loos.items():
        out[label] = {
            "elpd_loo": float(loo.elpd),
            "se": float(loo.se),
            "p_loo": float(loo.p),
            "pareto_k_max": float(np.max(np.asarray(loo.pareto_k))),
            "rank": int(table.loc[label, "rank"]),
            "elpd_diff": float(table.loc[label, "elpd_diff"]),
            "dse": float(table.loc[label, "dse"]),
            "weight": float(table.loc[label, "weight"]),
        }
    return out


def laplace(fit_result, sigma: float | None = None) -> dict:
    """Laplace (Gauss–Newton) approximation at a fit (`growjax.calibration.FitResult`): per coordinate its mean, sd
    and 90 % interval (log-normal in θ, or normal for a parameter fitted in a linear coordinate)."""
    out = {}
    for i, c in enumerate(fit_result.coordinates):
        sd_z = float(np.sqrt(max(fit_result.covariance[i, i], 0.0)))
        est = fit_result.estimate[c.label]
        slope = est if c.scale is None else c.scale
        out[c.label] = {"mean": est, "sd": slope * sd_z, "interval_90": fit_result.interval_90[c.label]}
    return out
