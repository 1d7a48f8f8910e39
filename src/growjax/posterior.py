"""Bayesian calibration: a NumPyro model of the measured length, NUTS, ArviZ diagnostics, predictive bands.

The statistical model reads like its maths::

    Y ~ Uniform(5, 15) kPa,  ext ~ Uniform(4000, 10000),  n ~ Uniform(0.9, 1.1)   (the paper's box)
    σ ~ HalfNormal(1 mm)
    L_obs(t_i) ~ Normal(L_model(t_i; Y, ext, n), σ)

NumPyro samples the bounded priors in unconstrained (logit) coordinates, which are O(1).
The model runs in the quasi-static configuration by default (fixed grid, no data-dependent
loops, exact reverse-mode gradients). A failed solve gives zero likelihood (−∞ log
density, rejected by NUTS), never an exception.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from growjax import params as gp
from growjax.model import Config, simulate
from growjax.quasistatic import QuasiStaticConfig


@dataclasses.dataclass(frozen=True)
class Prior:
    """Uniform prior of one parameter (qualified name, SI bounds) and its site name in the NumPyro model."""

    site: str
    name: str
    low: float
    high: float


def paper_priors() -> tuple[Prior, ...]:
    """Uniform priors over the paper's investigation box."""
    return (
        Prior("Y", "robot.yield_pressure", 5e3, 15e3),
        Prior("ext", "robot.extensibility", 4000.0, 10000.0),
        Prior("n", "robot.growth_exponent", 0.9, 1.1),
    )


def predicted_length(theta: dict, base, inputs, config, times):
    """Model length (m) at ``times`` for parameter values ``theta`` {qualified name: value}; NaN if the run failed."""
    p = gp.replace(base, **theta)
    traj = simulate(p, inputs, config)
    ok = traj.status == 0
    return jnp.where(ok, jnp.interp(times, traj.time, traj.length), jnp.nan)


def growth_model(times, length=None, *, base, inputs, config, priors: Sequence[Prior], noise_scale=1e-3):
    """NumPyro model: priors → simulated length → Normal likelihood of the measured length (m)."""
    theta = {p.name: numpyro.sample(p.site, dist.Uniform(p.low, p.high)) for p in priors}
    sigma = numpyro.sample("sigma", dist.HalfNormal(noise_scale))
    mu = predicted_length(theta, base, inputs, config, times)
    ok = jnp.all(jnp.isfinite(mu))
    numpyro.factor("solver_ok", jnp.where(ok, 0.0, -jnp.inf))
    numpyro.deterministic("length_model", mu)
    numpyro.sample("length", dist.Normal(jnp.where(jnp.isfinite(mu), mu, 0.0), sigma), obs=length)


@dataclasses.dataclass
class PosteriorResult:
    """NUTS output: ArviZ InferenceData plus the headline diagnostics."""

    idata: object
    summary: dict
    wall_s: float


def _window(times, length, config, window):
    t0, t1 = window if window is not None else (config.t0, config.t1)
    keep = (np.asarray(times) >= t0) & (np.asarray(times) <= t1)
    return np.asarray(times)[keep], np.asarray(length)[keep]


def sample(
    times,
    length,
    inputs,
    base: gp.Parameters | None = None,
    config: Config | QuasiStaticConfig | None = None,
    priors: Sequence[Prior] | None = None,
    chains: int = 4,
    warmup: int = 500,
    samples: int = 500,
    seed: int = 0,
    dense_mass: bool = True,
    target_accept: float = 0.9,
    window=None,
    progress: bool = True,
) -> PosteriorResult:
    """NUTS over the priors and σ given a measured length (m) at ``times`` (s); chains vectorised.

    Returns InferenceData with posterior, posterior predictive of the length, observed
    data and sample stats, and a summary: per-parameter mean and 90 % interval,
    ``rhat_max``, ``ess_bulk_min``, ``ess_tail_min``, ``divergences``, ``bfmi_min``,
    ``coverage_90`` (share of measured points inside the 90 % predictive band).
    """
    import arviz as az
    from numpyro.infer import MCMC, NUTS, Predictive

    base = base if base is not None else gp.reference()
    config = config if config is not None else QuasiStaticConfig()
    priors = tuple(priors) if priors is not None else paper_priors()
    t, y = _window(times, length, config, window)
    kwargs = {"base": base, "inputs": inputs, "config": config, "priors": priors}

    def model(times, length=None):
        growth_model(times, length, **kwargs)

    init_values, inverse_mass = precondition(model, priors, base, inputs, config, t, y, seed)
    kernel = NUTS(model, dense_mass=dense_mass, target_accept_prob=target_accept,
                  inverse_mass_matrix=inverse_mass if dense_mass else jnp.diag(inverse_mass),
                  init_strategy=numpyro.infer.init_to_value(values=init_values),
                  forward_mode_differentiation=True)  # 5× cheaper than reverse mode through the scan here
    mcmc = MCMC(kernel, num_warmup=warmup, num_samples=samples, num_chains=chains,
                chain_method="vectorized", progress_bar=progress)
    start = time.perf_counter()
    mcmc.run(jax.random.PRNGKey(seed), jnp.asarray(t), jnp.asarray(y), extra_fields=("diverging", "energy"))
    wall = time.perf_counter() - start
    post = mcmc.get_samples(group_by_chain=False)
    predictive = Predictive(lambda times: growth_model(times, None, **kwargs), posterior_samples=post)
    pp = predictive(jax.random.PRNGKey(seed + 1), jnp.asarray(t))
    idata = az.from_numpyro(mcmc, posterior_predictive={"length": np.asarray(pp["length"]).reshape(chains, samples, -1)})
    summary = diagnostics(idata, priors, y, mcmc)
    summary["wall_s"] = wall
    summary["chains"], summary["warmup"], summary["samples"] = chains, warmup, samples
    return PosteriorResult(idata, summary, wall)


def precondition(model, priors, base, inputs, config, times, length, seed=0, grid: int = 33):
    """Start point and inverse mass matrix for NUTS.

    The data fix Y to ~0.2 % of its prior width while ext and n stay at their priors, a
    scale ratio of ~200 in the unconstrained space. Without preconditioning, NUTS builds
    trees of hundreds of leapfrog steps. The start is the best Y of a grid (ext and n at
    their prior centres, σ at that fit's RMS residual). The inverse mass matrix is the
    inverse Hessian of the potential there, with eigenvalues floored at the logistic
    prior's curvature so that flat directions get the prior's scale.
    """
    from jax.flatten_util import ravel_pytree
    from numpyro.infer.util import initialize_model

    from growjax import sweep as sw

    centre = {p.name: 0.5 * (p.low + p.high) for p in priors}
    y_prior = next((p for p in priors if p.name == "robot.yield_pressure"), None)
    init = {p.site: centre[p.name] for p in priors}
    b = gp.replace(base, **centre)
    if y_prior is not None:
        vals = np.linspace(y_prior.low, y_prior.high, grid)[1:-1, None]
        res = sw.evaluate(vals, [y_prior.name], b, inputs, config, measured=(times, length))
        best = int(np.nanargmin(res.rmse))
        init["Y"] = float(vals[best, 0])
        sigma0 = float(res.rmse[best])
    else:
        mu = predicted_length(centre, base, inputs, config, jnp.asarray(times))
        sigma0 = float(np.sqrt(np.nanmean((np.asarray(mu) - length) ** 2)))
    init["sigma"] = max(sigma0, 1e-6)
    info = initialize_model(jax.random.PRNGKey(seed), model, model_args=(jnp.asarray(times), jnp.asarray(length)),
                            init_strategy=numpyro.infer.init_to_value(values=init),
                            forward_mode_differentiation=True, validate_grad=False)
    z0, unravel = ravel_pytree(info.param_info.z)
    hess = _fd_hessian(jax.jit(jax.vmap(lambda z: info.potential_fn(unravel(z)))), np.asarray(z0))
    evals, evecs = np.linalg.eigh(np.asarray(hess))
    evals = np.maximum(evals, 0.3)  # logistic prior curvature ≈ 0.5 at its centre
    inverse_mass = (evecs / evals) @ evecs.T
    return init, jnp.asarray(inverse_mass)


def _fd_hessian(batched_potential, z0, step: float = 1e-3):
    """Central-difference Hessian (d, d) from one batched call of the potential on the stencil (cheap to compile)."""
    d = z0.size
    eye = np.eye(d) * step
    points = [z0]
    for i in range(d):
        points += [z0 + eye[i], z0 - eye[i]]
        for j in range(i + 1, d):
            points += [z0 + eye[i] + eye[j], z0 + eye[i] - eye[j], z0 - eye[i] + eye[j], z0 - eye[i] - eye[j]]
    u = np.asarray(batched_potential(jnp.asarray(np.stack(points))))
    hess = np.zeros((d, d))
    k = 1
    for i in range(d):
        hess[i, i] = (u[k] - 2.0 * u[0] + u[k + 1]) / step**2
        k += 2
        for j in range(i + 1, d):
            hess[i, j] = hess[j, i] = (u[k] - u[k + 1] - u[k + 2] + u[k + 3]) / (4.0 * step**2)
            k += 4
    return hess


def predictive_band(draws, level: float = 0.9):
    """(lower, upper) pointwise quantiles of predictive draws (S, T) at ``level``."""
    a = 0.5 * (1.0 - level)
    return np.nanquantile(draws, a, axis=0), np.nanquantile(draws, 1.0 - a, axis=0)


def diagnostics(idata, priors, observed, mcmc=None) -> dict:
    """Posterior means and 90 % intervals, R-hat, ESS, divergences, BFMI and predictive coverage."""
    import arviz as az

    sites = [p.site for p in priors] + ["sigma"]
    rhat = az.rhat(idata, var_names=sites)
    ess_bulk = az.ess(idata, var_names=sites, method="bulk")
    ess_tail = az.ess(idata, var_names=sites, method="tail")
    post = idata.posterior
    params = {}
    for s in sites:
        x = np.asarray(post[s]).ravel()
        params[s] = {"mean": float(x.mean()), "sd": float(x.std()),
                     "interval_90": [float(np.quantile(x, 0.05)), float(np.quantile(x, 0.95))],
                     "rhat": float(rhat[s]), "ess_bulk": float(ess_bulk[s]), "ess_tail": float(ess_tail[s])}
    div = int(np.asarray(idata.sample_stats["diverging"]).sum()) if "diverging" in idata.sample_stats else 0
    pp = np.asarray(idata.posterior_predictive["length"])
    lo, hi = predictive_band(pp.reshape(-1, pp.shape[-1]))
    observed = np.asarray(observed)
    coverage = float(np.mean((observed >= lo) & (observed <= hi)))
    return {
        "parameters": params,
        "rhat_max": float(max(p["rhat"] for p in params.values())),
        "ess_bulk_min": float(min(p["ess_bulk"] for p in params.values())),
        "ess_tail_min": float(min(p["ess_tail"] for p in params.values())),
        "divergences": div,
        "bfmi_min": float(np.min(az.bfmi(idata))),
        "coverage_90": coverage,
    }


def predict(idata, priors, base, inputs, config, times, seed: int = 0, max_draws: int = 400):
    """Posterior predictive length draws (S, T) for new ``inputs`` (e.g. another pressure profile), noise included."""
    post = idata.posterior
    flat = {p.site: np.asarray(post[p.site]).ravel() for p in priors}
    sigma = np.asarray(post["sigma"]).ravel()
    take = np.random.default_rng(seed).choice(sigma.size, size=min(max_draws, sigma.size), replace=False)
    thetas = {p.name: jnp.asarray(flat[p.site][take]) for p in priors}
    mu = jax.jit(jax.vmap(lambda th: predicted_length(th, base, inputs, config, jnp.asarray(times))))(thetas)
    noise = np.random.default_rng(seed + 1).normal(size=mu.shape) * sigma[take][:, None]
    return np.asarray(mu) + noise


def laplace(fit_result, sigma: float | None = None) -> dict:
    """Laplace (Gauss–Newton) approximation at a fit: per-parameter mean, sd and 90 % interval (log-normal in θ)."""
    out = {}
    for i, n in enumerate(fit_result.names):
        sd_z = float(np.sqrt(max(fit_result.covariance_log[i, i], 0.0)))
        est = fit_result.estimate[n]
        out[n] = {"mean": est, "sd": est * sd_z, "interval_90": fit_result.interval_90[n]}
    return out
