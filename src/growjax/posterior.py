"""Bayesian calibration: a NumPyro model of the measured length, NUTS, ArviZ diagnostics, predictive bands.

The statistical model reads like its maths::

    Y ~ Uniform(5, 15) kPa,  ext ~ Uniform(4000, 10000),  n ~ Uniform(0.9, 1.1)   (the paper's box)
    σ ~ HalfNormal(1 mm)
    L_obs(t_i) ~ Normal(L_model(t_i; Y, ext, n), σ)

NumPyro samples the bounded priors in unconstrained (logit) coordinates, which are O(1).
The model runs in the fast configuration by default, with forward-mode gradients (or through an
emulator, opt-in); through the model, NUTS starts at the mode found in those coordinates, with the
Hessian there as its mass matrix (:func:`laplace_unconstrained`), and a prior whose mode lies
against a bound is sampled in a softplus coordinate instead (:class:`SoftplusPrior`, :func:`bound_start`), the
others across the ridge they form with it (:class:`RidgePrior`). A failed solve gives zero likelihood
(−∞ log density, rejected by NUTS), never an exception.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
import optimistix as optx

from growjax import discrepancy as dc
from growjax import emulator as em
from growjax import experiment
from growjax import params as gp
from growjax import tolerance as tl
from growjax.config import Config
from growjax.emulator import predicted_length, sample_times
from growjax.simulate import as_arrays, input_breaks, length_jacobian
from growjax.trajectory import OK


@dataclasses.dataclass(frozen=True)
class Prior:
    """Prior of one parameter: site name in the NumPyro model, qualified name, SI bounds.

    Uniform on [low, high], or log-uniform when ``log``. ``nodes`` is the emulator's node
    count along this parameter (see :mod:`growjax.emulator`).
    """

    site: str
    name: str
    low: float
    high: float
    log: bool = False
    nodes: int = 33

    def distribution(self):
        return dist.LogUniform(self.low, self.high) if self.log else dist.Uniform(self.low, self.high)

    def sample(self, given: dict | None = None):
        """θ from this prior inside a NumPyro model (NumPyro's own unconstrained coordinate for it). ``given``:
        the parameters sampled before it, {name: value} (used by :class:`RidgePrior`)."""
        return numpyro.sample(self.site, self.distribution())

    def value_at(self, f):
        """θ at fraction ``f`` of the range (log scale for a log prior); :func:`fraction` inverted."""
        return self.low * (self.high / self.low) ** f if self.log else self.low + (self.high - self.low) * f

    def axis(self) -> em.Axis:
        return em.Axis(self.name, self.low, self.high, self.nodes, self.log)


BOUND_FRACTION = 0.05  # a mode closer to a bound than this share of the prior's range is "pressed" against it


@dataclasses.dataclass(frozen=True)
class SoftplusPrior(Prior):
    """The same prior, sampled in a coordinate u that suits a posterior pressed against a bound.

    NumPyro's logit coordinate puts a double-exponential wall at a bound; where the likelihood presses
    the posterior against it, NUTS's steps there diverge or shrink. Here the prior's fraction f
    (of [low, high], on a log scale when ``log``), measured from the pressed bound, is
    f = 1 − exp(−s·softplus(u)), s its value at the mode: a bijection of ℝ onto (0, 1) with
    exponential tails on both sides, f ≈ s near the mode (u ≈ 0.5), and the prior's density kept by the
    factor |df/du|. θ is recorded as the deterministic site ``site``; u is sampled as ``u_<site>``.
    """

    scale: float = 1.0  # s, the fraction at the mode
    upper: bool = False  # pressed against ``high`` (f measured from it) instead of ``low``

    def sample(self, given: dict | None = None):
        u = numpyro.sample("u_" + self.site, dist.ImproperUniform(dist.constraints.real, (), ()))
        s = self.scale
        numpyro.factor("du_" + self.site, jnp.log(s) + jax.nn.log_sigmoid(u) - s * jax.nn.softplus(u))
        return numpyro.deterministic(self.site, self.value_at(self.fraction_at(u)))

    def fraction_at(self, u):
        """The prior's fraction from ``low`` (:func:`fraction`) at coordinate u."""
        f = -jnp.expm1(-self.scale * jax.nn.softplus(u))
        return 1.0 - f if self.upper else f

    def start(self) -> float:
        """u where f = s (the mode this coordinate was centred on)."""
        s = self.scale
        return float(np.log(np.expm1(-np.log1p(-s) / s)))


@dataclasses.dataclass(frozen=True)
class RidgePrior(Prior):
    """The same prior, sampled across the ridge it forms with priors pressed against a bound.

    Where the likelihood ties this parameter to pressed ones (φ_L ≈ a + b·n_L under the Lockhart law on the
    public experiment), the tie is linear in their values but curved in their softplus coordinates, and no
    mass matrix follows a curved ridge: NUTS's trees stay long and its draws correlated. Here NumPyro's
    own coordinate z of this prior is z = v + ``offset`` + Σ_k b_k·f_k(θ_k), f_k the pressed prior's
    :func:`fraction` and ``along`` = ((pressed prior, b_k), ...); v, sampled as ``v_<site>``, measures the
    distance from the ridge. The map (v, u) → (z, u) has unit Jacobian, so the prior's density in z is kept
    as NumPyro keeps it. The pressed priors must be sampled first (``given``). θ is the deterministic ``site``.
    """

    along: tuple = ()  # ((pressed Prior, slope b_k), ...)
    offset: float = 0.0

    def sample(self, given: dict | None = None):
        v = numpyro.sample("v_" + self.site, dist.ImproperUniform(dist.constraints.real, (), ()))
        z = v + self.offset + sum(b * _fraction(p, given[p.name]) for p, b in self.along)
        prior = self.distribution()
        to_theta = dist.transforms.biject_to(prior.support)
        theta = to_theta(z)
        numpyro.factor("dv_" + self.site, prior.log_prob(theta) + to_theta.log_abs_det_jacobian(z, theta))
        return numpyro.deterministic(self.site, theta)


def coordinate(prior: Prior) -> str:
    """The coordinate NUTS samples a prior in: ``"softplus"``, ``"ridge"`` or ``"numpyro"`` (NumPyro's own)."""
    return "softplus" if isinstance(prior, SoftplusPrior) else "ridge" if isinstance(prior, RidgePrior) else "numpyro"


def _recast(kind: type, prior: Prior, **coordinate_fields):
    """``prior``'s range and names as a ``kind`` (a :class:`Prior` subclass) with its own coordinate's fields."""
    return kind(**{f.name: getattr(prior, f.name) for f in dataclasses.fields(Prior)}, **coordinate_fields)


def _fraction(prior: Prior, value):
    if prior.log:
        return jnp.log(value / prior.low) / np.log(prior.high / prior.low)
    return (value - prior.low) / (prior.high - prior.low)


def fraction(prior: Prior, value) -> float:
    """Where ``value`` lies in the prior's range: 0 at ``low``, 1 at ``high`` (log scale for a log prior)."""
    return float(_fraction(prior, value))


def bound_coordinates(priors: Sequence[Prior], mode: dict, within: float = BOUND_FRACTION) -> tuple[Prior, ...]:
    """``priors`` with each one whose ``mode`` {site: value} lies within ``within`` of a bound (share of its range)
    as a :class:`SoftplusPrior` centred there; the others unchanged."""
    out = []
    for p in priors:
        f = fraction(p, mode[p.site]) if p.site in mode and not isinstance(p, SoftplusPrior) else 0.5
        if min(f, 1.0 - f) < within:
            upper = f > 0.5
            scale = min(max(1.0 - f if upper else f, 1e-6), within)
            p = _recast(SoftplusPrior, p, scale=scale, upper=upper)
        out.append(p)
    return tuple(out)


def paper_priors() -> tuple[Prior, ...]:
    """Uniform priors over the paper's investigation box (reference growth law).

    Emulator nodes: 101 along Y; 3 along ext and n, whose effect is ~1e-10 (validated, not assumed).
    """
    return (
        Prior("Y", "robot.yield_pressure", 5e3, 15e3, nodes=101),
        Prior("ext", "robot.extensibility", 4000.0, 10000.0, nodes=3),
        Prior("n", "robot.growth_exponent", 0.9, 1.1, nodes=3),
    )


def lockhart_priors() -> tuple[Prior, ...]:
    """Priors of the Lockhart growth law (:mod:`growjax.robot`): Y on the paper's box, φ_L and n_L log-uniform.

    φ_L, the growth speed 1 kPa above the rest pressure, spans 0.1–10 mm/s: from a robot
    that barely moves within the experiment to one whose speed the check valve alone sets.
    n_L spans 0.25–2, from a nearly rate-capped membrane to a stiffening one (Lockhart's plant
    cells have n ≈ 1); below 0.25 the quasi-static rod balance needs more than its 16 Newton
    steps. Emulator nodes: 21 × 25 × 15 (log-spaced in φ_L and n_L).
    """
    return (
        Prior("Y", "robot.yield_pressure", 5e3, 15e3, nodes=21),
        Prior("phi_L", "robot.lockhart_rate", 1e-4, 1e-2, log=True, nodes=25),
        Prior("n_L", "robot.lockhart_exponent", 0.25, 2.0, log=True, nodes=15),
    )


def growth_model(length=None, *, mean_length, priors: Sequence[Prior], noise_scale=1e-3, model_error=0.0,
                 residuals: Residuals | None = None):
    """NumPyro model of the measured length (m)::

        θ_j ~ prior_j,   σ ~ HalfNormal(noise_scale),
        a ~ HalfNormal(2 mm),   ℓ ~ LogNormal(ln 1 s, 1)                       (with a discrepancy)
        L_obs = L_model(t; θ) + δ(t) + Σ_k g_k(t) b_k + ε,   δ ~ GP(0, Matérn-3/2(a, ℓ)),
        b_k ~ N(0, u_k²),   ε_i ~ N(0, σ² + e²)

    ``mean_length(theta)`` is the model (or its emulator) at the measured times; ``e`` (m) is the
    emulator's RMS error (0 for the model itself). ``residuals`` (:class:`Residuals`) sets the discrepancy,
    the rig's tolerances and the samples scored; None: independent noise, every sample (δ and b absent).
    δ and b are marginalised exactly (:mod:`growjax.discrepancy`). A failed solve has zero likelihood.
    """
    theta = {}
    for p in priors:
        theta[p.name] = p.sample(theta)
    sigma = numpyro.sample("sigma", dist.HalfNormal(noise_scale))
    mu = mean_length(theta)
    ok = jnp.all(jnp.isfinite(mu))
    numpyro.factor("solver_ok", jnp.where(ok, 0.0, -jnp.inf))
    numpyro.deterministic("length_model", mu)
    scale = jnp.sqrt(sigma**2 + model_error**2)
    mu = jnp.where(jnp.isfinite(mu), mu, 0.0)
    if residuals is None:
        numpyro.sample("length", dist.Normal(mu, scale), obs=length)
        return
    if residuals.discrepancy == "matern32":
        amplitude = numpyro.sample("delta_amplitude", dist.HalfNormal(dc.AMPLITUDE_SCALE))
        time_scale = numpyro.sample("delta_time_scale",
                                    dist.LogNormal(np.log(dc.TIME_SCALE_MEDIAN), dc.TIME_SCALE_LOG_SD))
    else:
        amplitude, time_scale = jnp.zeros(()), jnp.ones(())
    hyper = dc.Hyper(amplitude, time_scale, scale)
    if length is None:  # replicated data at every sample
        numpyro.sample("length", residuals.replicate(mu, hyper))
    else:  # the scored samples
        numpyro.sample("length", residuals.distribution(mu, hyper), obs=jnp.asarray(length)[residuals.index])


@dataclasses.dataclass(frozen=True, eq=False)
class Residuals:
    """What the likelihood of :func:`growth_model` holds besides the model: the discrepancy (``"matern32"`` or
    ``"none"``), the sample times (n,) s, the samples scored (n,) bool, and the rig's tolerances: sensitivities
    (n, q) m per unit ln ψ, relative sds (q,), names. The filter runs over the scored samples alone (the
    likelihood of an interpolated record is that of its keyframes)."""

    discrepancy: str
    times: np.ndarray
    observed: np.ndarray
    sensitivity: np.ndarray | None = None
    tolerance: np.ndarray | None = None
    tolerance_names: tuple = ()

    @property
    def index(self) -> np.ndarray:
        return np.flatnonzero(self.observed)

    def _terms(self, index):
        g = None if self.sensitivity is None else jnp.asarray(np.asarray(self.sensitivity)[index])
        u = None if self.tolerance is None else jnp.asarray(self.tolerance)
        return jnp.asarray(np.asarray(self.times)[index]), g, u

    def distribution(self, mu, hyper):
        """The scored samples' distribution (event shape: the number scored) around the model ``mu`` (n,)."""
        index = self.index
        t, g, u = self._terms(index)
        return dc.distribution(mu[index], t, hyper, g, u)

    def replicate(self, mu, hyper):
        """Replicated data at every sample (event shape (n,)) around ``mu`` (n,)."""
        t, g, u = self._terms(np.arange(len(self.times)))
        return dc.distribution(mu, t, hyper, g, u)

    def pointwise(self, y, mu, hyper):
        """(n,) one-step-ahead log-densities of ``y`` at the scored samples, 0 elsewhere."""
        index = self.index
        terms = self.distribution(mu, hyper).pointwise(jnp.asarray(y)[index])
        return jnp.zeros(len(self.times)).at[index].set(terms)

    def hyper_sites(self, hyper: dc.Hyper) -> dict:
        """Start values {site: value} of the hyperparameters' sites."""
        if self.discrepancy != "matern32":
            return {}
        return {"delta_amplitude": max(float(hyper.amplitude), 1e-7), "delta_time_scale": float(hyper.time_scale)}


class DirectMean:
    """``mean_length`` that runs the model: θ {name: value} → length (m) at ``times`` (NaN where the run failed),
    with :meth:`value_and_jacobian` from one solve that carries the sensitivities."""

    def __init__(self, base, inputs, config, times):
        self.base, self.inputs, self.config, self.times = base, inputs, config, jnp.asarray(times)

    def __call__(self, theta):
        return predicted_length(theta, self.base, self.inputs, self.config, self.times)

    def value_and_jacobian(self, names):
        """``v (d,) → (μ (m,), ∂μ/∂v (m, d))`` over θ = ``dict(zip(names, v))`` (:func:`growjax.simulate.length_jacobian`:
        a solve fewer than a forward-mode derivative of :meth:`__call__`; NaN where the run failed)."""
        names, base = tuple(names), self.base
        breaks = input_breaks(self.inputs, self.config)
        ts = sample_times(self.times, self.config)

        def params_of(v):
            return gp.replace(base, **dict(zip(names, v)))

        def value_and_jacobian(v):
            traj, jac = length_jacobian(params_of, v, self.inputs, self.config, ts, breaks)
            ok = traj.status == OK
            return jnp.where(ok, traj.length, jnp.nan), jnp.where(ok, jac, jnp.nan)

        return value_and_jacobian


def direct_mean(base, inputs, config, times) -> DirectMean:
    """``mean_length`` that runs the model: θ {name: value} → length (m) at ``times`` (:class:`DirectMean`)."""
    return DirectMean(base, inputs, config, times)


def emulated_mean(emulator: em.Emulator):
    """``mean_length`` from an emulator (θ {name: value} → length at the emulator's times)."""
    return lambda theta: emulator(jnp.stack([jnp.asarray(theta[n], float) for n in emulator.names]))


def build_emulator(priors: Sequence[Prior], base, inputs, config, times, seed: int = 0) -> em.Emulator:
    """Emulator over the prior box, validated at 64 seeded points."""
    emu = em.build([p.axis() for p in priors], base, inputs, config, times)
    return em.validate(emu, 64, seed)


@dataclasses.dataclass
class PosteriorResult:
    """NUTS output: ArviZ InferenceData plus the headline diagnostics."""

    idata: object
    summary: dict
    wall_s: float
    residuals: Residuals | None = None  # the likelihood's discrepancy, samples and tolerances (None: independent)
    data: tuple = ()  # (times (n,) s, length (n,) m) the posterior was fitted on


def _window(times, length, config, window):
    t0, t1 = window if window is not None else (config.t0, config.t1)
    keep = (np.asarray(times) >= t0) & (np.asarray(times) <= t1)
    return np.asarray(times)[keep], np.asarray(length)[keep]


def sample(
    times,
    length,
    inputs,
    base: gp.Parameters | None = None,
    config: Config | None = None,
    priors: Sequence[Prior] | None = None,
    chains: int = 4,
    warmup: int = 500,
    samples: int = 500,
    seed: int = 0,
    dense_mass: bool = True,
    target_accept: float = 0.9,
    window=None,
    progress: bool = True,
    emulate: bool | em.Emulator = False,
    max_tree_depth: int = 10,
    chain_method: str | None = None,
    discrepancy: str = "matern32",
    tolerances: dict | None = None,
) -> PosteriorResult:
    """NUTS over the priors and σ given a measured length (m) at ``times`` (s).

    ``emulate``: True samples through an :class:`~growjax.emulator.Emulator` of the model built over
    the prior box (its validated RMS error joins the noise); an ``Emulator`` is used as given; False
    (default) runs the model in every gradient (forward mode). ``max_tree_depth``: NUTS's cap on the
    tree (at most 2^depth − 1 leapfrog steps per draw). ``chain_method``: NumPyro's; None runs the chains
    ``"vectorized"`` through an emulator, and through the model ``"parallel"`` (one chain per JAX device,
    each on its own thread: expose CPU cores as devices before JAX starts, as ``growjax posterior`` does)
    when there are as many devices as chains, else ``"sequential"``: the vmapped forward-mode solve
    (members stepped together) costs what the chains cost one after another, and the chains' trees, built
    in lockstep, would wait for the deepest (`benchmarks/nuts_direct.py` measures both).

    ``discrepancy`` and ``tolerances``: the likelihood, as in :func:`growjax.fit.fit` (:func:`growth_model`): the
    discrepancy's amplitude and time scale are sampled with the parameters; the rig's tolerances enter through
    the length's sensitivities at the start point (linearised), marginalised exactly.

    Returns InferenceData with posterior, pointwise log-likelihood (for LOO), posterior
    predictive of the length, observed data and sample stats, and a summary: per-parameter
    mean and 90 % interval, ``rhat_max``, ``ess_bulk_min``, ``ess_tail_min``,
    ``divergences``, ``bfmi_min``, ``coverage_90`` (share of measured points inside the 90 %
    predictive band), ``emulator`` (its error and build time), ``chain_method``, ``coordinates`` (each prior's:
    ``"numpyro"``, ``"softplus"`` or ``"ridge"``, :func:`bound_start`), ``laplace_s`` (the start and
    mass matrix through the model, :func:`laplace_unconstrained`, compilation included) and ``wall_s`` (everything).
    """
    import arviz as az
    from numpyro.infer import MCMC, NUTS

    base = base if base is not None else gp.reference()
    config = (config if config is not None else Config()).replace(adjoint="forward")
    priors = tuple(priors) if priors is not None else paper_priors()
    t, y = _window(times, length, config, window)
    start = time.perf_counter()
    emu_info = None
    if emulate is False:
        mean, model_error = direct_mean(base, inputs, config, t), 0.0
        mean = with_model_tangents(mean, [p.name for p in priors])
    else:
        emu = emulate if isinstance(emulate, em.Emulator) else build_emulator(priors, base, inputs, config, t, seed)
        if emu.times.shape != t.shape or not np.allclose(np.asarray(emu.times), t):
            raise ValueError("the emulator was built for other measurement times than these data")
        mean, model_error = emulated_mean(emu), float(emu.error_rms)
        emu_info = {"error_rms_m": float(emu.error_rms), "error_max_m": float(emu.error_max),
                    "nodes": dict(zip(emu.names, emu.nodes)), "build_s": time.perf_counter() - start}
    if discrepancy not in dc.KINDS:
        raise ValueError(f"discrepancy must be one of {dc.KINDS}, got {discrepancy!r}")
    residuals, extra_init = None, {}
    tol = tl.budget(base, tolerances, [p.name for p in priors], use_default=tolerances is None and discrepancy != "none")
    if discrepancy != "none" or tol:
        residuals, hyper = build_residuals(discrepancy, t, y, mean, priors, base, inputs, config, tol, seed)
        extra_init = {**residuals.hyper_sites(hyper), "sigma": float(hyper.noise)}

    def make_model(mean_length, priors=priors):
        return functools.partial(growth_model, mean_length=mean_length, priors=priors, model_error=model_error,
                                 residuals=residuals)

    start_precondition = time.perf_counter()
    init_values, inverse_mass = precondition(make_model(mean), priors, mean, y, seed, optimise=emulate is not False,
                                             make_model=make_model if emulate is False else None,
                                             extra_init=extra_init)
    sampled = priors
    if emulate is False:
        sampled, init_values, inverse_mass = bound_start(make_model, priors, mean, y, init_values, inverse_mass)
    precondition_s = time.perf_counter() - start_precondition
    model = make_model(mean, sampled)
    kernel = NUTS(model, dense_mass=dense_mass, target_accept_prob=target_accept, max_tree_depth=max_tree_depth,
                  inverse_mass_matrix=inverse_mass if dense_mass else jnp.diag(inverse_mass),
                  init_strategy=numpyro.infer.init_to_value(values=init_values),
                  # through the ODE, forward mode is 5× cheaper than reverse mode through the scan
                  forward_mode_differentiation=emulate is False)
    mcmc = MCMC(kernel, num_warmup=warmup, num_samples=samples, num_chains=chains,
                chain_method=chain_method or _chain_method(chains, emulate is not False),
                progress_bar=progress)
    mcmc.run(jax.random.PRNGKey(seed), jnp.asarray(y), extra_fields=("diverging", "energy", "num_steps"))
    post = mcmc.get_samples(group_by_chain=True)
    loglik, predicted = observation_draws(post["length_model"], post["sigma"], model_error, y, seed + 1, residuals,
                                          post.get("delta_amplitude"), post.get("delta_time_scale"))
    idata = az.from_numpyro(mcmc, log_likelihood=False, posterior_predictive={"length": predicted})
    idata.add_groups(log_likelihood={"length": loglik})
    wall = time.perf_counter() - start
    summary = diagnostics(idata, priors, y, mcmc, residuals)
    summary["wall_s"] = wall
    summary["emulator"] = emu_info
    summary["laplace_s"] = precondition_s if emulate is False else None
    summary["chain_method"] = mcmc.chain_method
    summary["coordinates"] = {p.site: coordinate(p) for p in sampled}
    summary["chains"], summary["warmup"], summary["samples"] = chains, warmup, samples
    summary["discrepancy"] = discrepancy
    summary["tolerances"] = dict(zip(residuals.tolerance_names, map(float, residuals.tolerance))) if (
        residuals is not None and residuals.tolerance is not None) else {}
    summary["samples_used"] = int(np.sum(residuals.observed)) if residuals is not None else int(y.size)
    return PosteriorResult(idata, summary, wall, residuals, (t, y))


def _scout(priors, mean_length, length, seed: int, n_scout: int = 64):
    """The best θ {name: value} of a seeded Latin hypercube over the priors, and its RMSE (m)."""
    from scipy.stats import qmc

    unit = qmc.LatinHypercube(d=len(priors), seed=seed).random(n_scout)
    cols = {}
    for k, p in enumerate(priors):
        u = unit[:, k]
        cols[p.name] = np.exp(np.log(p.low) + u * np.log(p.high / p.low)) if p.log else p.low + u * (p.high - p.low)
    mu = np.asarray(jax.jit(jax.vmap(mean_length))({n: jnp.asarray(v) for n, v in cols.items()}))
    rmse = np.sqrt(np.nanmean((mu - np.asarray(length)) ** 2, axis=1))
    rmse = np.where(np.all(np.isfinite(mu), axis=1), rmse, np.inf)
    best = int(np.argmin(rmse))
    if not np.isfinite(rmse[best]):
        raise RuntimeError("no point of the preconditioning scout simulated successfully")
    return {p.name: float(cols[p.name][best]) for p in priors}, float(rmse[best]), best, cols


def tolerance_sensitivity(theta: dict, base, inputs, config, times, tol: dict) -> np.ndarray:
    """g (n, q): the model's length change (m) at ``times`` per unit ln ψ of each toleranced parameter, the secant
    from ψ to ψ·e^u at θ (one compiled run of the model, the rig as its argument)."""
    times = jnp.asarray(times)
    run = jax.jit(lambda b: predicted_length(theta, b, inputs, config, times))
    base = as_arrays(base)
    l0 = np.asarray(run(base))
    cols = [(np.asarray(run(gp.replace(base, **{n: gp.get(base, n) * np.exp(u)}))) - l0) / u for n, u in tol.items()]
    g = np.stack(cols, axis=1)
    if not np.all(np.isfinite(g)):
        raise RuntimeError("the model failed while measuring the rig's tolerance sensitivities")
    return g


def build_residuals(discrepancy: str, times, length, mean_length, priors, base, inputs, config, tol: dict,
                    seed: int = 0) -> tuple[Residuals, dc.Hyper]:
    """The :class:`Residuals` of a posterior and its hyperparameters' start: the samples scored
    (:func:`growjax.experiment.informative_samples` with a discrepancy), the rig's sensitivities at the scout's
    best θ, and the hyperparameters' mode given the residuals there."""
    theta, _, _, _ = _scout(priors, mean_length, length, seed)
    observed = experiment.informative_samples(length) if discrepancy != "none" else np.ones(len(length), bool)
    g = u = None
    if tol:
        g = tolerance_sensitivity(theta, base, inputs, config, times, tol)
        u = np.asarray(list(tol.values()))
    r = np.asarray(length) - np.asarray(jax.jit(mean_length)({k: jnp.asarray(v) for k, v in theta.items()}))
    hyper = dc.estimate(r, times, discrepancy, g, u, observed)
    return Residuals(discrepancy, np.asarray(times), observed, g, u, tuple(tol)), hyper


def observation_draws(mean_length, sigma, model_error: float, observed, seed: int, residuals: Residuals | None = None,
                      amplitude=None, time_scale=None):
    """Pointwise log-likelihood and posterior predictive length (m), both (C, S, T), of every draw.

    ``mean_length`` (C, S, T): the model's length (m) at each draw, which :func:`growth_model` records as
    ``length_model`` while NUTS samples; ``sigma`` (C, S): the noise scale (m); ``model_error`` (m) joins it as in
    the model; ``residuals``, ``amplitude`` and ``time_scale`` (C, S): the discrepancy and tolerances, if any. The
    pointwise terms are then the one-step-ahead log-densities log p(yᵢ | earlier y) (0 at samples not scored),
    and a predictive draw carries a fresh discrepancy and rig error. Nothing is simulated again: NumPyro's
    ``Predictive`` and ArviZ's log-likelihood would each run the model once more per draw. Seeded by ``seed``.
    """
    from scipy.stats import norm

    mean_length = np.asarray(mean_length, float)
    scale = np.sqrt(np.asarray(sigma, float) ** 2 + model_error**2)
    finite = np.isfinite(mean_length)
    if residuals is None:
        loglik = np.where(finite, norm.logpdf(np.asarray(observed, float), np.where(finite, mean_length, 0.0),
                                              scale[..., None]), -np.inf)
        noise = np.random.default_rng(seed).standard_normal(mean_length.shape)
        return loglik, mean_length + scale[..., None] * noise
    shape = mean_length.shape
    mu = np.where(finite, mean_length, 0.0).reshape(-1, shape[-1])
    ones = np.ones(shape[:-1])
    amp = np.zeros(shape[:-1]) if amplitude is None else np.asarray(amplitude, float)
    ell = ones if time_scale is None else np.asarray(time_scale, float)
    hyper = dc.Hyper(jnp.asarray(amp.ravel()), jnp.asarray(ell.ravel()), jnp.asarray(scale.ravel()))
    y = jnp.asarray(observed, float)

    def one(m, h, key):
        return residuals.pointwise(y, m, h), residuals.replicate(m, h).sample(key)

    keys = jax.random.split(jax.random.PRNGKey(seed), mu.shape[0])
    loglik, predicted = jax.jit(jax.vmap(one))(jnp.asarray(mu), hyper, keys)
    loglik = np.where(np.all(finite, axis=-1, keepdims=True), np.asarray(loglik).reshape(shape), -np.inf)
    return loglik, np.asarray(predicted).reshape(shape)


def bound_start(make_model, priors, mean_length, length, mode: dict, inverse_mass):
    """(priors as sampled, start, inverse mass matrix) for NUTS through the model.

    ``mode`` is the posterior mode in NumPyro's coordinates ({site: value}, σ included). Priors whose mode
    lies against a bound are sampled in softplus coordinates instead (:func:`bound_coordinates`), and
    the start and mass matrix are found again in them (:func:`laplace_unconstrained`); then the other
    priors are sampled across the ridge they form with the pressed ones (:func:`ridge_coordinates`), and the
    start and mass matrix found once more. Where none is pressed, ``priors``, ``mode`` and ``inverse_mass``
    come back unchanged. ``make_model(mean, priors)``:
    the NumPyro model. On the public experiment under the Lockhart law (Y and n_L at their bounds),
    ``python benchmarks/nuts_direct.py --geometry`` measures what this changes (README, "Benchmarks").
    """
    sampled = bound_coordinates(priors, mode)
    if sampled == tuple(priors):
        return tuple(priors), mode, inverse_mass
    start = {("u_" + p.site if isinstance(p, SoftplusPrior) else p.site):
             (p.start() if isinstance(p, SoftplusPrior) else mode[p.site]) for p in sampled}
    start.update({k: v for k, v in mode.items() if k not in {p.site for p in priors}})  # σ and the discrepancy's
    start, hess = laplace_unconstrained(lambda m: make_model(m, sampled), sampled, mean_length, length, start)
    ridged = ridge_coordinates(sampled, start, hess)
    if ridged == sampled:
        return sampled, start, jnp.asarray(_inverse_floored(hess))
    start = {**{"u_" + p.site: start["u_" + p.site] for p in ridged if isinstance(p, SoftplusPrior)},
             **{"v_" + p.site: 0.0 for p in ridged if isinstance(p, RidgePrior)},
             **{k: v for k, v in start.items() if not k.startswith("u_") and k not in {p.site for p in sampled}}}
    start, hess = laplace_unconstrained(lambda m: make_model(m, ridged), ridged, mean_length, length, start)
    return ridged, start, jnp.asarray(_inverse_floored(hess))


def ridge_coordinates(sampled: Sequence[Prior], start: dict, hess) -> tuple[Prior, ...]:
    """``sampled`` with every prior that is not pressed as a :class:`RidgePrior` across its ridge with the pressed
    (:class:`SoftplusPrior`) ones, the pressed ones first; unchanged where none is pressed or none is free.

    ``start`` {site: value} and ``hess`` (the potential's Hessian over the flattened sites, keys sorted as
    ``jax.flatten_util.ravel_pytree`` sorts them) come from :func:`laplace_unconstrained` in ``sampled``'s
    coordinates. The ridge is the Gaussian's conditional mean there, E[z_free | u] = z₀ − H_ff⁻¹ H_fu (u − u₀),
    each u-slope divided by ∂f_k/∂u_k at the mode to become a slope in the pressed prior's fraction f_k."""
    pressed = [p for p in sampled if isinstance(p, SoftplusPrior)]
    free = [p for p in sampled if not isinstance(p, (SoftplusPrior, RidgePrior))]
    if not pressed or not free:
        return tuple(sampled)
    index = {k: i for i, k in enumerate(sorted(start))}
    u_idx = [index["u_" + p.site] for p in pressed]
    f_idx = [index[p.site] for p in free]
    hess = np.asarray(hess)
    slopes_u = -np.linalg.solve(hess[np.ix_(f_idx, f_idx)], hess[np.ix_(f_idx, u_idx)])  # (free, pressed)
    u0 = [float(start["u_" + p.site]) for p in pressed]
    df_du = [float(jax.grad(p.fraction_at)(u)) for p, u in zip(pressed, u0)]
    f0 = [float(p.fraction_at(u)) for p, u in zip(pressed, u0)]
    out = list(pressed)
    for i, p in enumerate(free):
        z0 = float(dist.transforms.biject_to(p.distribution().support).inv(start[p.site]))
        along = tuple((q, float(slopes_u[i, k] / df_du[k])) for k, q in enumerate(pressed))
        offset = z0 - sum(b * f for (_, b), f in zip(along, f0))
        out.append(_recast(RidgePrior, p, along=along, offset=offset))
    return tuple(out)


def _chain_method(chains: int, emulated: bool) -> str:
    if emulated:
        return "vectorized"
    return "parallel" if chains > 1 and jax.local_device_count() >= chains else "sequential"


def precondition(model, priors, mean_length, length, seed=0, n_scout: int = 64, optimise: bool = True,
                 make_model=None, extra_init: dict | None = None):
    """Start point and inverse mass matrix for NUTS.

    The data fix Y to ~0.2 % of its prior width while ext and n stay at their priors, a
    scale ratio of ~200 in the unconstrained space: without preconditioning NUTS builds
    trees of hundreds of leapfrog steps. The start is the best of a seeded Latin hypercube
    over the priors (σ at its RMS residual). Then, if ``make_model`` is given (``mean → model``,
    the same statistical model around another ``mean_length``), the posterior mode and the Hessian
    of the potential there in NumPyro's unconstrained coordinates (:func:`laplace_unconstrained`:
    Gauss–Newton in θ, the transforms and priors exact; one forward-mode Jacobian of the model per
    step); else, if ``optimise``, the mode by BFGS (cheap on an emulator) and a central-difference
    Hessian. The inverse mass matrix is the inverse Hessian, eigenvalues floored at the logistic
    prior's curvature so that flat directions get the prior's scale.
    """
    from jax.flatten_util import ravel_pytree
    from numpyro.infer.util import initialize_model

    best_theta, rmse, _, _ = _scout(priors, mean_length, length, seed, n_scout)
    init = {p.site: best_theta[p.name] for p in priors}
    init["sigma"] = max(rmse, 1e-6)
    init.update(extra_init or {})
    if make_model is not None:
        init, hess = laplace_unconstrained(make_model, priors, mean_length, length, init)
        return init, jnp.asarray(_inverse_floored(hess))
    info = initialize_model(jax.random.PRNGKey(seed), model, model_args=(jnp.asarray(length),),
                            init_strategy=numpyro.infer.init_to_value(values=init),
                            forward_mode_differentiation=not optimise, validate_grad=False)
    z0, unravel = ravel_pytree(info.param_info.z)
    potential = jax.jit(lambda z: info.potential_fn(unravel(z)))
    if optimise:
        sol = optx.minimise(lambda z, _: potential(z), optx.BFGS(rtol=1e-8, atol=1e-8), z0, max_steps=500, throw=False)
        if np.isfinite(float(potential(sol.value))) and float(potential(sol.value)) < float(potential(z0)):
            z0 = sol.value
            init = {k: float(v) for k, v in info.postprocess_fn(unravel(z0)).items() if k in init}
    return init, jnp.asarray(_inverse_floored(_fd_hessian(jax.jit(jax.vmap(potential)), np.asarray(z0))))


PRIOR_CURVATURE_FLOOR = 0.3  # logistic prior's curvature ≈ 0.5 at its centre


def _inverse_floored(hess):
    """Inverse of a symmetric Hessian (d, d) with its eigenvalues floored at :data:`PRIOR_CURVATURE_FLOOR`."""
    evals, evecs = np.linalg.eigh(np.asarray(hess))
    return (evecs / np.maximum(evals, PRIOR_CURVATURE_FLOOR)) @ evecs.T


def value_and_jacobian(mean_length, names):
    """``v (d,) → (μ (m,), ∂μ/∂v (m, d))`` for ``mean_length`` over θ = ``dict(zip(names, v))``: the model's own
    (:meth:`DirectMean.value_and_jacobian`, one solve) where it has one, else one forward-mode pass carrying d
    tangent directions (:func:`growjax.fit.linearise`)."""
    from growjax.fit import linearise

    names = tuple(names)
    if hasattr(mean_length, "value_and_jacobian"):
        return mean_length.value_and_jacobian(names)
    return lambda v: linearise(lambda w: mean_length(dict(zip(names, w))), v)


@functools.lru_cache(maxsize=8)
def _jitted_jacobian(mean_length, names):
    """``jax.jit`` of :func:`value_and_jacobian`, one per model: a second Laplace start (:func:`bound_start`)
    reuses the compiled Jacobian."""
    return jax.jit(value_and_jacobian(mean_length, names))


def with_model_tangents(mean_length, names):
    """``mean_length`` whose forward-mode derivative runs one tangent solve in θ's own d directions.

    ``jacfwd`` of NumPyro's potential pushes one tangent per unconstrained site through the model,
    the noise scale's (zero) included; here the model's Jacobian ∂μ/∂θ (d directions) is computed once
    and every tangent of θ is mapped through it.
    """
    names = tuple(names)
    jacobian = value_and_jacobian(mean_length, names)

    @jax.custom_jvp
    def mean_vector(v):
        return mean_length(dict(zip(names, v)))

    @mean_vector.defjvp
    def _tangent(primals, tangents):
        (v,), (dv,) = primals, tangents
        mu, jac = jacobian(v)
        return mu, jac @ dv

    return lambda theta: mean_vector(jnp.stack([jnp.asarray(theta[n], float) for n in names]))


LAPLACE_MAX_STEPS = 40
LAPLACE_DECREMENT = 1e-2  # nats: stop once Newton predicts less (~0.1 posterior sd from the mode)
LAPLACE_STALL = 3  # or once this many steps in a row fail to lower it: the model's own noise is reached


def laplace_unconstrained(make_model, priors, mean_length, length, init: dict):
    """Posterior mode and Hessian of the potential in NumPyro's unconstrained coordinates.

    NUTS samples z = T⁻¹(θ) (logit of each bounded prior, log σ). Near a prior's bound (the public
    experiment's Y and n_L under the Lockhart law lie at theirs) the posterior in z is not the
    Gaussian of a fit in θ: the transform's Jacobian shapes it. Each step linearises the model in θ
    around the current point, μ(θ) ≈ μ₀ + J(θ − θ₀) (one forward-mode Jacobian), and takes a
    Levenberg–Marquardt step on the resulting potential, exact in everything else (priors, transforms,
    σ); a step the true potential does not confirm raises the damping. At the fixed point the gradient
    is the true one and the Hessian is Gauss–Newton in θ, exact in the transforms. ``make_model(mean_length)``: the NumPyro
    model around a given mean. ``init``: {site: constrained value}.

    Returns the mode as {site: constrained value} and the Hessian (d, d) over the flattened sites.
    """
    from jax.flatten_util import ravel_pytree
    from numpyro.infer.util import constrain_fn, potential_energy, unconstrain_fn

    names = tuple(p.name for p in priors)
    sites = tuple(p.site for p in priors)
    y = jnp.asarray(length)

    def linear_model(data, mu0, jac, v0):
        make_model(lambda th: mu0 + jac @ (jnp.stack([jnp.asarray(th[n], float) for n in names]) - v0))(data)

    d = len(names)
    placeholder = (y, jnp.zeros_like(y), jnp.zeros((y.size, d)), jnp.zeros(d))  # the transforms alone
    zf, unravel = ravel_pytree(unconstrain_fn(linear_model, placeholder, {}, init))

    def potential(z, mu0, jac, v0):
        return potential_energy(linear_model, (y, mu0, jac, v0), {}, unravel(z))

    def constrained(z):  # deterministic sites included: a prior may record θ as one (Prior.sample)
        return constrain_fn(linear_model, placeholder, {}, unravel(z), return_deterministic=True)

    def theta_of(z):
        values = constrained(z)
        return jnp.stack([values[s] for s in sites])

    value = jax.jit(potential)
    grad_hess = jax.jit(lambda *a: (jax.grad(potential)(*a), jax.hessian(potential)(*a)))
    jacobian = _jitted_jacobian(mean_length, names)
    theta = jax.jit(theta_of)

    def linearised_at(z):
        v = theta(jnp.asarray(z))
        mu0, jac = jacobian(v)
        return mu0, jac, v

    z = np.asarray(zf)
    args = linearised_at(z)
    f = float(value(jnp.asarray(z), *args))
    if not np.isfinite(f):
        raise RuntimeError("the model failed at the start of the Laplace approximation")
    damping, rejected = 1e-3, 0
    for _ in range(LAPLACE_MAX_STEPS):
        g, h = (np.asarray(a) for a in grad_hess(jnp.asarray(z), *args))
        evals, evecs = np.linalg.eigh(h)
        h_pos = (evecs * np.maximum(evals, 1e-8 * max(evals[-1], 1e-300))) @ evecs.T
        if 0.5 * g @ np.linalg.solve(h_pos, g) < LAPLACE_DECREMENT:  # Newton decrement: at the mode
            break
        step = -np.linalg.solve(h_pos + damping * np.diag(np.diag(h_pos)), g)
        predicted = f - float(value(jnp.asarray(z + step), *args))
        if not predicted > 0.0:  # too far even for the linearised model: shorten without running the model
            damping = 4.0 * max(damping, 1e-3)
            continue
        args_new = linearised_at(z + step)
        f_new = float(value(jnp.asarray(z + step), *args_new))
        ratio = (f - f_new) / predicted
        if np.isfinite(f_new) and ratio > 0.1:
            z, args, f, rejected = z + step, args_new, f_new, 0
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
        else:
            damping, rejected = 4.0 * max(damping, 1e-3), rejected + 1
            if rejected == LAPLACE_STALL:
                break
    hess = np.asarray(grad_hess(jnp.asarray(z), *args)[1])
    mode = {k: float(x) for k, x in jax.jit(constrained)(jnp.asarray(z)).items() if k in init}
    return mode, hess


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


def diagnostics(idata, priors, observed, mcmc=None, residuals: Residuals | None = None) -> dict:
    """Posterior means and 90 % intervals, R-hat, ESS, divergences, BFMI and predictive coverage (the share of
    the measured samples inside the pointwise 90 % band of replicated data)."""
    import arviz as az

    sites = [p.site for p in priors] + ["sigma"]
    sites += [s for s in ("delta_amplitude", "delta_time_scale") if s in idata.posterior]
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


def forecast(result: PosteriorResult, priors, base, inputs, config, times, seed: int = 0, max_draws: int = 400):
    """Posterior predictive length draws (S, T), m, at ``times`` (s) beyond or between the data the posterior was
    fitted on, conditioned on them: each draw's model run over the fitted and the new times, its discrepancy
    (and rig terms) at the new times given its residuals at the fitted samples (the Kalman forecast), and fresh
    noise. Without a discrepancy (``result.residuals`` None) the draws are the model plus noise."""
    post = result.idata.posterior
    t_fit, y_fit = (np.asarray(a, float) for a in result.data)
    t_new = np.asarray(times, float)
    union = np.unique(np.concatenate([t_fit, t_new]))
    sigma = np.asarray(post["sigma"]).ravel()
    take = np.random.default_rng(seed).choice(sigma.size, size=min(max_draws, sigma.size), replace=False)
    thetas = {p.name: jnp.asarray(np.asarray(post[p.site]).ravel()[take]) for p in priors}
    mu = np.asarray(jax.jit(jax.vmap(lambda th: predicted_length(th, base, inputs, config, jnp.asarray(union))))(thetas))
    at_fit, at_new = np.searchsorted(union, t_fit), np.searchsorted(union, t_new)
    res = result.residuals
    rng = np.random.default_rng(seed + 1)
    if res is None:
        return mu[:, at_new] + sigma[take][:, None] * rng.standard_normal((take.size, at_new.size))
    observed = np.zeros(union.size, bool)
    observed[at_fit[res.observed]] = True
    g = u = None
    if res.sensitivity is not None:
        mean_theta = {n: float(np.mean(v)) for n, v in thetas.items()}
        g = jnp.asarray(tolerance_sensitivity(mean_theta, base, inputs, config, union,
                                              dict(zip(res.tolerance_names, map(float, res.tolerance)))))
        u = jnp.asarray(res.tolerance)
    flat = lambda site: jnp.asarray(np.asarray(post[site]).ravel()[take]) if site in post else None
    amp, ell = flat("delta_amplitude"), flat("delta_time_scale")
    hyper = dc.Hyper(jnp.zeros(take.size) if amp is None else amp, jnp.ones(take.size) if ell is None else ell,
                     jnp.asarray(np.sqrt(sigma[take] ** 2 + result.summary.get("model_error_m", 0.0) ** 2)))
    r = np.zeros_like(mu)
    r[:, at_fit] = y_fit[None, :] - mu[:, at_fit]
    mean, var = jax.jit(jax.vmap(lambda ri, h: dc.forecast(ri, jnp.asarray(union), jnp.asarray(observed), h, g, u)))(
        jnp.asarray(r), hyper)
    scale = np.sqrt(np.asarray(var)[:, at_new] + np.asarray(hyper.noise)[:, None] ** 2)
    return mu[:, at_new] + np.asarray(mean)[:, at_new] + scale * rng.standard_normal(scale.shape)


def sbc(emulator: em.Emulator, priors: Sequence[Prior], replicates: int = 100, warmup: int = 200,
        samples: int = 200, seed: int = 0, noise_scale: float = 1e-3, level: float = 0.9,
        truth_model=None, model_error: float = 0.0) -> dict:
    """Simulation-based calibration (Talts et al. 2018) of NUTS on :func:`growth_model`, all replicates at once.

    Each replicate draws θ and σ from the prior and a data set from the model (here its
    emulator, which is then exact by construction), and samples the posterior with NUTS
    (diagonal mass adapted in warm-up). All replicates run in one ``vmap``ped program
    (NumPyro's functional NUTS). A calibrated sampler ranks the truth uniformly among the
    draws and covers it with the central ``level`` interval in a share ``level`` of replicates.

    ``truth_model({qualified name: (replicates,) values}) → (replicates, m)`` clean lengths (m) at the emulator's
    times: data from another configuration (the reference), plus σ-noise, so the check also sees the
    emulated configuration's error against it; the likelihood then carries the emulator's RMS error and
    ``model_error`` (m, e.g. :data:`growjax.fit.FAST_MODEL_ERROR`, the fast configuration's against the
    reference), both as independent noise.

    Returns ``ranks`` {site: (replicates,) ints in [0, samples]}, ``coverage`` {site: share},
    ``divergences`` (total) and ``draws`` (samples per replicate).
    """
    from numpyro.infer import Predictive
    from numpyro.infer.hmc import hmc
    from numpyro.infer.util import initialize_model

    if truth_model is not None:
        model_error = float(np.hypot(float(emulator.error_rms), model_error))
        if not np.isfinite(model_error):
            raise ValueError("sbc with a truth_model needs a validated emulator (growjax.emulator.validate): its "
                             "error joins the noise")
    model = functools.partial(growth_model, mean_length=emulated_mean(emulator), priors=priors,
                              noise_scale=noise_scale, model_error=model_error)
    k_prior, k_init, k_run, k_noise = jax.random.split(jax.random.PRNGKey(seed), 4)
    truth = Predictive(model, num_samples=replicates)(k_prior)
    if truth_model is not None:
        clean = jnp.asarray(truth_model({p.name: np.asarray(truth[p.site]) for p in priors}))
        noise = jax.random.normal(k_noise, clean.shape, clean.dtype) * truth["sigma"][:, None]
        truth = {**truth, "length": clean + noise}
    sites = [p.site for p in priors] + ["sigma"]
    info = initialize_model(k_init, model, model_args=(truth["length"][0],), dynamic_args=True)
    init_kernel, sample_kernel = hmc(potential_fn_gen=info.potential_fn, algo="NUTS")

    def run(key, data):
        state = init_kernel(info.param_info.z, warmup, model_args=(data,), rng_key=key, target_accept_prob=0.9)

        def step(state, _):
            state = sample_kernel(state, model_args=(data,))
            return state, (state.z, state.diverging)

        _, (zs, div) = jax.lax.scan(step, state, None, length=warmup + samples)
        kept = jax.tree_util.tree_map(lambda a: a[warmup:], zs)
        values = jax.vmap(info.postprocess_fn(data))(kept)
        return {s: values[s] for s in sites}, jnp.sum(div[warmup:])

    draws, div = jax.jit(jax.vmap(run))(jax.random.split(k_run, replicates), truth["length"])
    a = 0.5 * (1.0 - level)
    ranks, coverage = {}, {}
    for s in sites:
        d, t = np.asarray(draws[s]), np.asarray(truth[s])[:, None]
        ranks[s] = np.sum(d < t, axis=1)
        lo, hi = np.quantile(d, a, axis=1), np.quantile(d, 1.0 - a, axis=1)
        coverage[s] = float(np.mean((t[:, 0] >= lo) & (t[:, 0] <= hi)))
    return {"ranks": ranks, "coverage": coverage, "divergences": int(np.sum(np.asarray(div))), "draws": samples}


def compare_loo(results: dict) -> dict:
    """PSIS-LOO of several posteriors of the same data ({label: PosteriorResult}) via ArviZ.

    Returns per model ``elpd_loo``, its standard error, ``p_loo``, the largest Pareto k̂, and
    the ArviZ ranking (``elpd_diff``, ``dse``, ``weight``). The likelihood treats residuals as
    independent; when they are autocorrelated (model discrepancy) the standard errors are optimistic.
    """
    import arviz as az

    table = az.compare({k: r.idata for k, r in results.items()}, ic="loo", var_name="length")
    out = {}
    for label, r in results.items():
        loo = az.loo(r.idata, pointwise=True, var_name="length")
        out[label] = {"elpd_loo": float(loo.elpd_loo), "se": float(loo.se), "p_loo": float(loo.p_loo),
                      "pareto_k_max": float(np.max(np.asarray(loo.pareto_k))),
                      "rank": int(table.loc[label, "rank"]), "elpd_diff": float(table.loc[label, "elpd_diff"]),
                      "dse": float(table.loc[label, "dse"]), "weight": float(table.loc[label, "weight"])}
    return out


def laplace(fit_result, sigma: float | None = None) -> dict:
    """Laplace (Gauss–Newton) approximation at a fit: per-parameter mean, sd and 90 % interval (log-normal in θ)."""
    out = {}
    for i, n in enumerate(fit_result.names):
        sd_z = float(np.sqrt(max(fit_result.covariance_log[i, i], 0.0)))
        est = fit_result.estimate[n]
        out[n] = {"mean": est, "sd": est * sd_z, "interval_90": fit_result.interval_90[n]}
    return out
