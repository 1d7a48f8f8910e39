"""A population of robots built alike: each robot's parameter θ_i drawn from a log-normal population, and the
population predictive for a new robot of the same build.

    μ ~ Normal(m₀, w₀)                       ln SI units; m₀, w₀ from the parameter's default box
    s ~ HalfNormal(s₀)
    ln θ_i ~ Normal(μ, s²),  i = 1..R robots
    (ln θ̂, b̂) ~ Normal((ln θ, b), F)           the set's data, through its joint fit

The data enter through the fit of the set (`growjax.calibration.fit` with ``NAME@robot``): its
estimate of the robots' ln θ and of the rig's relative errors b, with their covariance F, is the likelihood of
(ln θ, b) linearised at the estimate (rig tolerance priors included, every run's discrepancy, noise and the fast
model's error marginalised, other free parameters marginalised). That is the fit's own treatment of the rig and
the discrepancy, so the population and the fit answer alike; it is exact for a length linear in ln θ across the
robots' intervals (each is a few per cent wide) and keeps NUTS off the ODE: a few seconds instead of hours. The
rig's errors are shared by the robots on it, so the robots' estimates are correlated through F and the
population's median cannot be known better than the rig allows, however many robots are run.

The likelihood being Gaussian, the robots' ln θ are integrated out in closed form:
ln θ̂ ~ Normal(μ·1, s²I + F_θθ). NUTS samples (μ, s) alone, a smooth two-dimensional posterior, and each
draw's ln θ is then drawn exactly from its Gaussian given (μ, s) and the data (:func:`robots_given`). Neither
the centred nor the non-centred parametrisation of ln θ is needed: both put a funnel in front of NUTS as
s → 0 (the non-centred one where the data pin each robot more tightly than the population does, the centred
one where they pin it less), and a few draws diverge or a chain sticks. Given ln θ, b is Gaussian too, and is
drawn beside each draw for the predictive.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from growjax.calibration import MODEL_ERROR_TIME, FitResult, default_range
from growjax.calibration import discrepancy as dc
from growjax.data import experiment as ex
from growjax.data.sets import Run
from growjax.model import params as gp
from growjax.posterior import nuts_chain
from growjax.simulation.config import Config
from growjax.simulation.simulate import input_breaks, simulate

__all__ = [
    "SPREAD_SCALE",
    "PopulationResult",
    "linearised_likelihood",
    "model",
    "new_robot",
    "predict_new_robot",
    "robots_given",
    "sample_population",
    "save",
]

SPREAD_SCALE = 0.3  # s₀: half-normal scale of the population's sd of ln θ (robots within ~±60 % a priori)


@dataclasses.dataclass
class PopulationResult:
    """Posterior draws (D = chains × samples) of the population of ``name`` (full name) over ``robots``."""

    name: str
    robots: tuple  # (R,)
    mu: np.ndarray  # (D,) ln SI: the population's median is exp(μ)
    s: np.ndarray  # (D,) sd of ln θ across robots
    ln_theta: np.ndarray  # (D, R) each robot's ln θ (SI)
    rig: np.ndarray  # (D, Q) the rig's relative errors b, drawn given ln θ
    rig_labels: tuple  # (Q,) (rig key, tolerance name)
    diagnostics: dict  # {site: {"r_hat", "ess"}}, "divergences"
    set_fit: FitResult
    mu_prior: tuple  # (m₀, w₀)
    spread_scale: float
    chains: int = 1

    def interval(self, values, level: float = 0.9) -> tuple:
        q = np.quantile(values, [(1 - level) / 2, 0.5, (1 + level) / 2])
        return float(q[0]), float(q[1]), float(q[2])

    def summary(self) -> dict:
        med = self.interval(np.exp(self.mu))
        sd = self.interval(self.s)
        robots = {
            r: dict(zip(("lower_90", "median", "upper_90"), self.interval(np.exp(self.ln_theta[:, i]))))
            for i, r in enumerate(self.robots)
        }
        return {
            "parameter": self.name,
            "robots": list(self.robots),
            "population_median": {"median": med[1], "interval_90": [med[0], med[2]]},
            "population_sd_log": {"median": sd[1], "interval_90": [sd[0], sd[2]]},
            "robot_posterior": robots,
            "draws": int(self.mu.size),
            "diagnostics": self.diagnostics,
            "prior": {
                "mu": {"loc": self.mu_prior[0], "scale": self.mu_prior[1]},
                "s": {"half_normal_scale": self.spread_scale},
            },
        }


def linearised_likelihood(set_fit: FitResult, name: str):
    """(robots (R,), labels (R,), ln θ̂ (R,) SI, b̂ (Q,), F (R + Q, R + Q)) from a joint fit that freed
    ``name@robot`` with the rig inferred. Other free coordinates are marginalised (rows and columns dropped)."""
    if set_fit.joint_covariance is None:
        raise ValueError("a population needs the joint fit's rig inferred (rig='inferred' and a tolerance budget)")
    keep = [i for i, c in enumerate(set_fit.coordinates) if c.name == name and c.scope == "robot"]
    if not keep:
        raise ValueError(f"the joint fit has no per-robot {name}: free it as {name}@robot")
    labels = tuple(set_fit.labels[i] for i in keep)
    robots = tuple(set_fit.coordinates[i].key for i in keep)
    p = len(set_fit.labels)
    rows = np.array(keep + list(range(p, p + len(set_fit.rig_labels))))
    cov = np.asarray(set_fit.joint_covariance)[np.ix_(rows, rows)]
    z_hat = np.log([set_fit.estimate[lab] for lab in labels])
    return robots, labels, z_hat, np.asarray(set_fit.rig_vector, float), 0.5 * (cov + cov.T)


def model(z_hat, cov, mu_loc: float, mu_scale: float, spread_scale: float = SPREAD_SCALE):
    """The population model above, with the robots' ln θ and the data's rig block integrated out: ``z_hat`` (R,)
    ln SI, ``cov`` (R, R) its covariance given ln θ."""
    mu = numpyro.sample("mu", dist.Normal(mu_loc, mu_scale))
    s = numpyro.sample("s", dist.HalfNormal(spread_scale))
    marginal = cov + s**2 * jnp.eye(z_hat.shape[0])
    numpyro.sample("z_hat", dist.MultivariateNormal(mu * jnp.ones_like(z_hat), covariance_matrix=marginal), obs=z_hat)


def robots_given(mu, s, z_hat, cov, rng: np.random.Generator) -> np.ndarray:
    """Exact draws of the robots' ln θ (D, R) given each draw's (μ, s) (D,) and the data ``z_hat`` (R,) with
    covariance ``cov`` (R, R). In the eigenbasis of ``cov`` (eigenvalues λ) the prior N(μ·1, s²I) and the data
    are independent per axis: mean s²/(s² + λ) of the data's offset from μ, variance s²λ/(s² + λ); exact at
    s = 0 (every robot at μ)."""
    lam, vec = np.linalg.eigh(0.5 * (cov + cov.T))
    lam = np.maximum(lam, 0.0)
    mu, s2 = np.asarray(mu, float)[:, None], np.asarray(s, float)[:, None] ** 2
    offset = (np.asarray(z_hat, float)[None, :] - mu) @ vec  # (D, R) in the eigenbasis
    shrink = np.divide(s2, s2 + lam, out=np.zeros(offset.shape), where=s2 + lam > 0)  # 0 where s = λ = 0
    x = shrink * offset + np.sqrt(shrink * lam) * rng.standard_normal(offset.shape)
    return mu + x @ vec.T


def sample_population(
    set_fit: FitResult,
    name: str = "Y",
    *,
    chains: int = 4,
    warmup: int = 500,
    samples: int = 500,
    seed: int = 0,
    spread_scale: float = SPREAD_SCALE,
    mu_prior: tuple | None = None,
) -> PopulationResult:
    """NUTS over (μ, s) of the population of ``name`` (as freed ``name@robot`` in ``set_fit``), the robots'
    ln θ drawn exactly given each draw (:func:`robots_given`) and b given ln θ. ``mu_prior``: (m₀, w₀) of μ,
    ln SI (None: centred on the parameter's default box in log scale, half its log width as sd). The ``chains``
    run side by side in one compiled program (:func:`_sampler`), each from its own start drawn uniformly in
    (−2, 2) in unconstrained space (NumPyro's default) and with its own step size and diagonal mass adapted over
    ``warmup``."""
    base = gp.reference()
    full = gp.resolve_name(base, name)
    robots, _, z_hat, b_hat, cov = linearised_likelihood(set_fit, full)
    r = z_hat.size
    if mu_prior is None:
        lo, hi = default_range(base, full)
        mu_prior = (0.5 * math.log(lo * hi), 0.5 * math.log(hi / lo))
    czz, czb, cbb = cov[:r, :r], cov[:r, r:], cov[r:, r:]
    if chains < 1 or warmup < 1 or samples < 2:
        raise ValueError(f"need chains >= 1, warmup >= 1 and samples >= 2, got {chains}, {warmup}, {samples}")
    args = tuple(jnp.asarray(a, float) for a in (z_hat, czz, mu_prior[0], mu_prior[1], spread_scale))
    values, diverging = _sampler(r, chains, warmup, samples)(jax.random.split(jax.random.PRNGKey(seed), chains), args)
    draws = {k: np.asarray(values[k]) for k in ("mu", "s")}  # (chains, samples)
    rng = np.random.default_rng(seed)
    draws["ln_theta"] = robots_given(draws["mu"].reshape(-1), draws["s"].reshape(-1), z_hat, czz, rng).reshape(
        chains, samples, r
    )
    diagnostics = {}
    for site in ("mu", "s", "ln_theta"):
        x = draws[site]
        diagnostics[site] = {
            "r_hat": float(np.max(numpyro.diagnostics.split_gelman_rubin(x))) if chains > 1 else None,
            "ess": float(np.min(numpyro.diagnostics.effective_sample_size(x))),
        }
    diagnostics["divergences"] = int(np.sum(diverging))
    ln_theta = draws["ln_theta"].reshape(-1, r)
    gain = np.linalg.solve(czz, czb).T  # (Q, R)
    cond = cbb - czb.T @ np.linalg.solve(czz, czb)
    chol = np.linalg.cholesky(0.5 * (cond + cond.T) + 1e-14 * np.eye(cond.shape[0]))
    b = b_hat + (ln_theta - z_hat) @ gain.T + rng.standard_normal((ln_theta.shape[0], b_hat.size)) @ chol.T
    return PopulationResult(
        full,
        robots,
        draws["mu"].reshape(-1),
        draws["s"].reshape(-1),
        ln_theta,
        b,
        tuple(set_fit.rig_labels),
        diagnostics,
        set_fit,
        tuple(map(float, mu_prior)),
        float(spread_scale),
        chains,
    )


def save(population: PopulationResult, path) -> Path:
    """Write the draws as a netCDF DataTree with a ``posterior`` group (dims chain, draw, robot), the layout
    ArviZ reads. Returns the path."""
    import xarray as xr

    c = population.chains
    d = population.mu.size // c
    coords = {"chain": np.arange(c), "draw": np.arange(d), "robot": list(population.robots)}
    ds = xr.Dataset(
        {
            "mu": (("chain", "draw"), population.mu.reshape(c, d)),
            "s": (("chain", "draw"), population.s.reshape(c, d)),
            "ln_theta": (("chain", "draw", "robot"), population.ln_theta.reshape(c, d, -1)),
        },
        coords=coords,
        attrs={"parameter": population.name, "units": "mu, ln_theta: ln of SI; s: sd of ln"},
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    xr.DataTree.from_dict({"posterior": ds}).to_netcdf(path)
    return path


@functools.lru_cache(maxsize=8)
def _sampler(robots: int, chains: int, warmup: int, samples: int):
    """NUTS on :func:`model` for ``robots`` robots (NumPyro's functional kernel, target acceptance 0.95): a jitted
    ``(keys (chains, 2), model arguments) → ({site: (chains, samples, ...)}, divergences (chains,))``, compiled
    once per shape and reused across data sets (``numpyro.infer.MCMC`` compiles its sampling loop again on every
    run: ~0.6 s, more than a run of this model takes)."""
    from numpyro.infer.util import initialize_model

    shape = (jnp.zeros(robots), jnp.eye(robots), 0.0, 1.0, SPREAD_SCALE)
    info = initialize_model(jax.random.PRNGKey(0), model, model_args=shape, dynamic_args=True)
    run = nuts_chain(info, warmup, samples, target_accept_prob=0.95)

    def chain(key, args):
        k_start, k_run = jax.random.split(key)
        names = sorted(info.param_info.z)
        start = {
            n: jax.random.uniform(k, jnp.shape(info.param_info.z[n]), minval=-2.0, maxval=2.0)
            for n, k in zip(names, jax.random.split(k_start, len(names)))
        }
        return run(start, k_run, args)

    return jax.jit(jax.vmap(chain, in_axes=(0, None)))


def new_robot(population: PopulationResult, draws: int | None = None, seed: int = 0):
    """(θ (D,) SI, b (D, Q)): a new robot of the same build on the same rig, one per posterior draw (or
    ``draws`` of them, resampled)."""
    rng = np.random.default_rng(seed)
    d = population.mu.size
    pick = np.arange(d) if draws is None else rng.choice(d, size=draws, replace=draws > d)
    theta = np.exp(population.mu[pick] + population.s[pick] * rng.standard_normal(pick.size))
    return theta, population.rig[pick]


def predict_new_robot(
    population: PopulationResult,
    run: Run,
    config: Config | None = None,
    draws: int = 200,
    seed: int = 0,
    level: float = 0.9,
) -> dict:
    """The length of a new robot of the population on ``run``'s rig under ``run``'s input, at ``run.times``:
    the model for each drawn (θ, b), plus a fresh discrepancy and noise (this set's runs' median
    hyperparameters; a new experiment's) and the fast model's error. Returns times (T,), median, lower, upper
    (T,) m at ``level``, and the draws (D, T) m."""
    config = (config if config is not None else Config()).replace(drive=run.drive)
    base = _run_base(population, run)
    theta, b = new_robot(population, draws, seed)
    tol_names = [n for key, n in population.rig_labels if key == run.rig]
    cols = [j for j, (key, _) in enumerate(population.rig_labels) if key == run.rig]
    b = b[:, cols]
    nominal = np.array([float(gp.get(base, n)) for n in tol_names])
    inputs = ex.to_inputs(run.experiment, run.drive, base, config.t0, config.t1)
    times = np.asarray(run.times, float)
    inside = (times >= config.t0) & (times <= config.t1)
    times = times[inside]
    ts = jnp.asarray(np.concatenate([[config.t0], times]) if times[0] > config.t0 else times)
    breaks = input_breaks(inputs, config)

    @jax.jit
    @jax.vmap
    def length(th, bb):
        values = {population.name: th, **{n: v * jnp.exp(x) for n, v, x in zip(tol_names, nominal, bb)}}
        traj = simulate(gp.replace(base, **values), inputs, config, ts=ts, breaks=breaks)
        return traj.length[-times.size :], traj.status

    mean, status = length(jnp.asarray(theta), jnp.asarray(b))
    mean, ok = np.asarray(mean), np.asarray(status) == 0
    hyper = _median_hyper(population.set_fit.runs)
    key = jax.random.PRNGKey(seed)
    noise = np.asarray(dc.draw(key, times, hyper, shape=(theta.size,), noise=True))
    model_error = population.set_fit.likelihood.model_error_for(config)
    if model_error > 0:
        k = dc.drift_kernel(times, model_error, MODEL_ERROR_TIME) + 1e-18 * np.eye(times.size)
        noise = (
            noise + np.random.default_rng(seed + 1).standard_normal((theta.size, times.size)) @ np.linalg.cholesky(k).T
        )
    paths = (mean + noise)[ok]
    q = np.quantile(paths, [(1 - level) / 2, 0.5, (1 + level) / 2], axis=0)
    return {
        "times": times,
        "lower": q[0],
        "median": q[1],
        "upper": q[2],
        "draws": paths,
        "theta": theta[ok],
        "failed": int(np.sum(~ok)),
        "level": level,
    }


def _run_base(population: PopulationResult, run: Run) -> gp.Parameters:
    """``run``'s parameters with the set fit's other estimates that apply to it (shared, its rig's), the rig
    nominal (each draw sets its own)."""
    return population.set_fit.parameters(run, rig=False)


def _median_hyper(runs: list) -> dc.Hyper:
    keys = ("amplitude_m", "time_scale_s", "noise_m", "noise_time_s")
    med = [float(np.median([r["discrepancy"][k] for r in runs])) for k in keys]
    return dc.Hyper.of(*med)
