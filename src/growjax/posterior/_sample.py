"""NUTS over the priors: the likelihood's terms, the start, the run and its record."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import time
import types
from collections.abc import Sequence
from unittest import mock

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
from jaxtyping import Float

from growjax import _progress
from growjax.calibration import Likelihood
from growjax.calibration import discrepancy as dc
from growjax.calibration import tolerance as tl
from growjax.data import experiment
from growjax.data.sets import ExperimentSet
from growjax.posterior import emulator as em
from growjax.simulation.config import Config

from ._checks import diagnostics
from ._laplace import _scout, bound_start, precondition
from ._model import (
    Residuals,
    build_emulator,
    direct_mean,
    emulated_mean,
    growth_model,
    with_model_tangents,
)
from ._priors import Prior, coordinate, paper_priors
from ._record import inference_data


@dataclasses.dataclass
class PosteriorResult:
    """NUTS output: ``idata``, the run as an xarray DataTree (ArviZ 1.x, :func:`inference_data`), plus the headline
    diagnostics."""

    idata: object
    summary: dict
    wall_s: float
    residuals: Residuals | None = None  # the likelihood's discrepancy, samples and tolerances (None: independent)
    data: tuple[Float[np.ndarray, " n"], Float[np.ndarray, " n"]] = ()  # (times s, length m) it was fitted on


def _window(times, length, config, window):
    t0, t1 = window if window is not None else (config.t0, config.t1)
    keep = (np.asarray(times) >= t0) & (np.asarray(times) <= t1)
    return np.asarray(times)[keep], np.asarray(length)[keep]


def sample(
    experiments: ExperimentSet,
    *,
    config: Config | None = None,
    priors: Sequence[Prior] | None = None,
    likelihood: Likelihood = Likelihood(),
    chains: int = 4,
    warmup: int = 500,
    samples: int = 500,
    seed: int = 0,
    dense_mass: bool = True,
    target_accept: float = 0.9,
    progress: bool = True,
    emulate: bool | em.Emulator = False,
    max_tree_depth: int = 10,
    chain_method: str | None = None,
    rig_centre: dict | None = None,
) -> PosteriorResult:
    """NUTS over the priors and σ given one experiment's measured length.

    Args:
        experiments: the set of one experiment (`growjax.data.sets.ExperimentSet.single`): its length (m) at its
            times (s) inside its window, its parameters and inputs (a set's population is
            `growjax.posterior.population`'s).
        config: the simulation's settings (its drive is the run's).
        priors: the sampled parameters' priors (default `paper_priors`).
        likelihood: the likelihood's options, as the fit takes them (`growjax.calibration.Likelihood`): the
            discrepancy's amplitude and time scale are sampled with the parameters; the rig's tolerances enter
            through the length's sensitivities (linearised), marginalised exactly (``rig`` must be
            ``"inferred"``); the configuration's own error (``model_error``, default the configuration's) enters
            as the slow drift the fit carries, marginalised too.
        emulate: True samples through an `growjax.posterior.emulator.Emulator` of the model built over the prior
            box (its validated RMS error joins the noise); an ``Emulator`` is used as given; False (default) runs
            the model in every gradient (forward mode).
        max_tree_depth: NUTS's cap on the tree (at most 2^depth − 1 leapfrog steps per draw).
        chain_method: NumPyro's; None runs the chains ``"vectorized"`` through an emulator, and through the model
            ``"parallel"`` (one chain per JAX device, each on its own thread: expose CPU cores as devices before
            JAX starts, as ``growjax posterior`` does) when there are as many devices as chains, else
            ``"sequential"``: the vmapped forward-mode solve (members stepped together) costs what the chains
            cost one after another, and the chains' trees, built in lockstep, would wait for the deepest
            (`benchmarks/nuts_direct.py` measures both).
        progress: a line per phase (emulator, likelihood, start point, NUTS's start and end) and NumPyro's bars on
            stderr where it is a terminal; elsewhere (a log) the bars' progress as a plain line every ~10 % of
            each chain's draws. The draws do not depend on where stderr goes.
        rig_centre: {tolerance: ln(ψ/ψ₀)} where the rig is linearised, or None to take it from
            `growjax.calibration.fit` on the same data and likelihood (its ``rig_offset``), so that the fit and
            the posterior linearise the rig alike. The model runs with the rig there, and the rig's errors keep
            their prior about nominal.
        chains, warmup, samples, seed, dense_mass, target_accept: NUTS's.

    Returns:
        A DataTree (`inference_data`: the sampled sites in the posterior, the replicated and the model's length in
        the posterior predictive, the pointwise log-likelihood for LOO, the measured length as observed data,
        NUTS's sample stats) and a summary: per-parameter mean and 90 % interval, ``rhat_max``, ``ess_bulk_min``,
        ``ess_tail_min``, ``divergences``, ``bfmi_min``, ``coverage_90`` (share of measured points inside the
        90 % predictive band), ``emulator`` (its error and build time), ``chain_method``, ``coordinates`` (each
        prior's: ``"numpyro"``, ``"softplus"`` or ``"ridge"``, `bound_start`), ``laplace_s`` (the start and mass
        matrix through the model, `laplace_unconstrained`, compilation included), ``configuration_error_m`` (the
        drift's sd) and ``wall_s`` (everything).

    Raises:
        ValueError: a set of more than one experiment, a fixed rig, or a ``rig_centre`` naming an untoleranced
            parameter.
    """
    if len(experiments) != 1:
        raise ValueError(
            f"a posterior takes one experiment, got {len(experiments)}: several robots' experiments are the "
            "population's (growjax.posterior.population)"
        )
    if likelihood.rig != "inferred":
        raise ValueError("the posterior marginalises the rig's errors under their tolerances: give rig='inferred'")
    run = experiments.runs[0]
    config = (config if config is not None else Config()).replace(adjoint="forward", drive=run.drive)
    base = run.base()
    inputs = run.model_inputs(base, config.t0, config.t1)
    priors = tuple(priors) if priors is not None else paper_priors()
    discrepancy, window = likelihood.discrepancy, run.window
    t, y = _window(run.times, run.length, config, window)
    start = time.perf_counter()
    if emulate is True:
        _progress.note("posterior: building the emulator", progress)
    tol = likelihood.budget(base, [p.name for p in priors])
    centre, linearisations = _rig_centre(rig_centre, tol, experiments, priors, config, likelihood, seed, progress)
    base = tl.rig_at(base, tol, centre)
    mean, model_error, emu_info = _mean_length(emulate, priors, base, inputs, config, t, seed, start)
    _progress.note(f"posterior: the likelihood ({discrepancy} discrepancy)", progress)
    drift = likelihood.model_error_for(config)
    residuals, extra_init = _likelihood_terms(
        discrepancy, tol, t, y, mean, priors, (base, inputs, config), seed, centre, drift
    )

    def make_model(mean_length, priors=priors):
        return functools.partial(
            growth_model, mean_length=mean_length, priors=priors, model_error=model_error, residuals=residuals
        )

    start_precondition = time.perf_counter()
    _progress.note("posterior: start point and mass matrix", progress)
    sampled, init_values, inverse_mass = _nuts_start(make_model, priors, mean, y, seed, emulate, extra_init)
    precondition_s = time.perf_counter() - start_precondition
    nuts = {
        "dense_mass": dense_mass,
        "target_accept": target_accept,
        "max_tree_depth": max_tree_depth,
        "chains": chains,
        "warmup": warmup,
        "samples": samples,
        "progress": progress,
        "chain_method": chain_method or _chain_method(chains, emulate is not False),
    }
    _progress.note(
        f"posterior: NUTS, {chains} chains of {warmup} warm-up and {samples} kept draws ({nuts['chain_method']})",
        progress,
    )
    start_nuts = time.perf_counter()
    with _numpyro_progress(progress):
        mcmc = _run_nuts(make_model(mean, sampled), init_values, inverse_mass, y, seed, emulate is False, **nuts)
    _progress.note(f"posterior: NUTS done in {time.perf_counter() - start_nuts:.1f} s", progress)
    post = mcmc.get_samples(group_by_chain=True)
    loglik, predicted, new = observation_draws(
        post["length_model"],
        post["sigma"],
        model_error,
        y,
        seed + 1,
        residuals,
        post.get("delta_amplitude"),
        post.get("delta_time_scale"),
        post.get("noise_time"),
    )
    scored = residuals.observed if residuals is not None else np.ones(len(y), bool)
    idata = inference_data(post, mcmc.get_extra_fields(group_by_chain=True), t, y, scored, loglik, predicted, new)
    wall = time.perf_counter() - start
    summary = diagnostics(idata, priors, y, mcmc, residuals)
    summary.update(
        {
            "wall_s": wall,
            "emulator": emu_info,
            "laplace_s": precondition_s if emulate is False else None,
            "chain_method": mcmc.chain_method,
            "coordinates": {p.site: coordinate(p) for p in sampled},
            "chains": chains,
            "warmup": warmup,
            "samples": samples,
            "discrepancy": discrepancy,
            "rig_centre": dict(zip(tol, map(float, centre))) if centre is not None else {},
            "linearisations": linearisations,
            "configuration_error_m": drift,
            **_likelihood_record(residuals, y),
        }
    )
    return PosteriorResult(idata, summary, wall, residuals, (t, y))


def _mean_length(emulate, priors, base, inputs, config, t, seed: int, start: float):
    """(``mean_length`` at the times ``t``, the emulator's RMS error (m, 0 through the model), the emulator's record
    or None) for :func:`sample`: the model with its own tangents, or an emulator (given, or built over the priors'
    box, its build time counted from ``start``)."""
    if emulate is False:
        mean = with_model_tangents(direct_mean(base, inputs, config, t), [p.name for p in priors])
        return mean, 0.0, None
    emu = emulate if isinstance(emulate, em.Emulator) else build_emulator(priors, base, inputs, config, t, seed)
    if emu.times.shape != t.shape or not np.allclose(np.asarray(emu.times), t):
        raise ValueError("the emulator was built for other measurement times than these data")
    emu_info = {
        "error_rms_m": float(emu.error_rms),
        "error_max_m": float(emu.error_max),
        "nodes": dict(zip(emu.names, emu.nodes)),
        "build_s": time.perf_counter() - start,
    }
    return emulated_mean(emu), float(emu.error_rms), emu_info


def _likelihood_terms(
    discrepancy: str, tol: dict, t, y, mean, priors, model, seed: int, centre=None, model_error: float = 0.0
):
    """(:class:`Residuals` or None for independent noise, start values of σ and the discrepancy's sites);
    ``model`` = (base, inputs, config)."""
    if discrepancy == "none" and not tol and model_error == 0:
        return None, {}
    residuals, hyper = build_residuals(discrepancy, t, y, mean, priors, *model, tol, seed, centre, model_error)
    return residuals, {**residuals.hyper_sites(hyper), "sigma": float(hyper.noise)}


def _rig_centre(given, tol: dict, experiments, priors, config, likelihood, seed: int, progress: bool):
    """(the rig's errors (q,) ln(ψ/ψ₀) where the posterior linearises it, or None at nominal; the fit's number of
    linearisations, 0 when given or without tolerances): ``given`` {tolerance: value}, or the fit's of the
    experiment's length (its pressure is not scored)."""
    if not tol:
        return None, 0
    if given is not None:
        unknown = sorted(set(given) - set(tol))
        if unknown:
            raise ValueError(f"rig_centre names {unknown}, which carry no tolerance here (tolerances: {sorted(tol)})")
        centre = np.array([float(given.get(name, 0.0)) for name in tol])
        return (centre if np.any(centre != 0) else None), 0
    from growjax.calibration import fit

    _progress.note("posterior: the fit, for where the data put the rig", progress)
    length_only = ExperimentSet(tuple(dataclasses.replace(r, sensors=("length",)) for r in experiments))
    fitted = fit(length_only, [p.name for p in priors], likelihood=likelihood, config=config, seed=seed)
    offsets = next(iter(fitted.rig_offset.values()), {})
    centre = np.array([offsets.get(name, 0.0) for name in tol])
    if not np.all(np.isfinite(centre)) or not np.any(centre):  # the rig stayed at nominal
        return None, fitted.linearisations
    return centre, fitted.linearisations


def _nuts_start(make_model, priors, mean, y, seed: int, emulate, extra_init: dict):
    """(priors as sampled, start, inverse mass matrix): :func:`precondition`, then through the model
    :func:`bound_start`."""
    init_values, inverse_mass = precondition(
        make_model(mean),
        priors,
        mean,
        y,
        seed,
        optimise=emulate is not False,
        make_model=make_model if emulate is False else None,
        extra_init=extra_init,
    )
    if emulate is not False:
        return priors, init_values, inverse_mass
    return bound_start(make_model, priors, mean, y, init_values, inverse_mass)


@contextlib.contextmanager
def _numpyro_progress(progress: bool):
    """NumPyro's progress bars where stderr is a terminal; elsewhere its bars' updates as plain lines every ~10 %
    (:class:`growjax._progress.Lines`, standing in for tqdm in ``numpyro.util``). Either way NumPyro runs the
    loop it runs with ``progress_bar=True``, so the draws do not depend on where stderr goes."""
    import numpyro.util as nu

    if not progress or _progress.terminal() or not (hasattr(nu, "tqdm") and hasattr(nu, "tqdm_auto")):
        yield
        return

    def trange(n, **_):
        return _progress.Lines(n, "posterior: NUTS", "draw", iterable=range(n))

    def auto(iterable, position=0, **_):
        return _progress.Lines(
            len(iterable), f"posterior: NUTS chain {position}", "draw", iterable=iterable, phases=False
        )  # NumPyro's descriptions there name the chain again

    with mock.patch.object(nu, "tqdm", types.SimpleNamespace(trange=trange)), mock.patch.object(nu, "tqdm_auto", auto):
        yield


def _run_nuts(
    model,
    init_values,
    inverse_mass,
    y,
    seed: int,
    forward_mode: bool,
    *,
    dense_mass: bool,
    target_accept: float,
    max_tree_depth: int,
    chains: int,
    warmup: int,
    samples: int,
    progress: bool,
    chain_method: str,
):
    """NumPyro's MCMC run of NUTS on ``model`` from ``init_values`` with ``inverse_mass`` (dense, or its diagonal)."""
    from numpyro.infer import MCMC, NUTS

    kernel = NUTS(
        model,
        dense_mass=dense_mass,
        target_accept_prob=target_accept,
        max_tree_depth=max_tree_depth,
        inverse_mass_matrix=inverse_mass if dense_mass else jnp.diag(inverse_mass),
        init_strategy=numpyro.infer.init_to_value(values=init_values),
        # through the ODE, forward mode is 5× cheaper than reverse mode through the scan
        forward_mode_differentiation=forward_mode,
    )
    mcmc = MCMC(
        kernel,
        num_warmup=warmup,
        num_samples=samples,
        num_chains=chains,
        chain_method=chain_method,
        progress_bar=progress,
    )
    mcmc.run(jax.random.PRNGKey(seed), jnp.asarray(y), extra_fields=("diverging", "energy", "num_steps"))
    return mcmc


def _likelihood_record(residuals: Residuals | None, y) -> dict:
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


def _chain_method(chains: int, emulated: bool) -> str:
    if emulated:
        return "vectorized"
    return "parallel" if chains > 1 and jax.local_device_count() >= chains else "sequential"
