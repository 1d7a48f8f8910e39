"""NUTS over the priors: the likelihood's terms, the start, the run and its record."""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
from jaxtyping import Float

from growjax import progress as prog
from growjax.calibration import Likelihood
from growjax.calibration import tolerance as tl
from growjax.data.sets import ExperimentSet
from growjax.posterior import emulator as em
from growjax.simulation.config import Config

from ._checks import diagnostics
from ._laplace import bound_start, precondition
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
from ._residuals import likelihood_record, likelihood_terms, observation_draws


@dataclasses.dataclass
class PosteriorResult:
    """NUTS output.

    Attributes:
        idata: the run as an xarray DataTree (ArviZ 1.x, `inference_data`): the sampled sites in the posterior, the
            replicated and the model's length in the posterior predictive, the pointwise log-likelihood for LOO,
            the measured length as observed data, NUTS's sample stats.
        summary: per-parameter mean and 90 % interval, ``rhat_max``, ``ess_bulk_min``, ``ess_tail_min``,
            ``divergences``, ``bfmi_min``, ``coverage_90`` (share of measured points inside the 90 % predictive
            band), ``emulator`` (its error and build time), ``chain_method``, ``coordinates`` (each prior's:
            ``"numpyro"``, ``"softplus"`` or ``"ridge"``, `bound_start`), ``laplace_s`` (the start and mass matrix
            through the model, `laplace_unconstrained`, compilation included), ``configuration_error_m`` (the
            configuration's drift, sd m) and ``wall_s`` (everything).
        wall_s: s, everything.
        residuals: the likelihood's discrepancy, samples, tolerances and drift (None: independent noise).
        data: (times (n,) s, length (n,) m) the posterior was fitted on.
    """

    idata: object
    summary: dict
    wall_s: float
    residuals: Residuals | None = None
    data: tuple[Float[np.ndarray, " n"], Float[np.ndarray, " n"]] = ()


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
            times (s) inside its window, its parameters and inputs.
        config, priors: the simulation's settings (its drive is the run's); the priors (default `paper_priors`).
        likelihood: the likelihood's options, as the fit takes them (`growjax.calibration.Likelihood`): the
            discrepancy's amplitude and time scale are sampled with the parameters; the rig's tolerances enter
            through the length's sensitivities (linearised), marginalised exactly (``rig`` must be
            ``"inferred"``); the configuration's own error (``model_error``, default the configuration's) enters
            as the slow drift the fit carries, marginalised too.
        emulate: True samples through an `growjax.posterior.emulator.Emulator` of the model built over the prior
            box (its validated RMS error joins the noise); an ``Emulator`` is used as given; False (default) runs
            the model in every gradient (forward mode).
        max_tree_depth: NUTS's cap on the tree (at most 2^depth − 1 leapfrog steps per draw).
        chain_method: NumPyro's; None: vectorized (emulator), parallel (a device per chain) or sequential.
        progress: a line per phase on stderr, and NumPyro's bars where stderr is a terminal (the draws agree to
            rounding, below 1e-11 relative).
        rig_centre: {tolerance: ln(ψ/ψ₀)} where the rig is linearised (the model runs with the rig there, its
            errors' prior stays about nominal), or None: where `growjax.calibration.fit` puts it on the same data.
        chains, warmup, samples, seed, dense_mass, target_accept: NUTS's.

    Returns:
        The `PosteriorResult`: the draws as a DataTree and the summary.

    Raises:
        ValueError: more than one experiment, a fixed rig, or a ``rig_centre`` naming an untoleranced parameter.
    """
    run, config = _one_run(experiments, config, likelihood)
    priors = tuple(priors) if priors is not None else paper_priors()
    t, y = _window(run.times, run.length, config, run.window)
    start = time.perf_counter()
    prog.note("posterior: building the emulator", progress and emulate is True)
    terms = _terms(experiments, config, priors, likelihood, (t, y), rig_centre, emulate, seed, start, progress)
    mean, model_error, residuals = terms["mean"], terms["model_error"], terms["residuals"]

    def make_model(mean_length, priors=priors):
        return functools.partial(
            growth_model, mean_length=mean_length, priors=priors, model_error=model_error, residuals=residuals
        )

    nuts = dict(dense_mass=dense_mass, target_accept=target_accept, max_tree_depth=max_tree_depth, chains=chains)
    nuts.update(warmup=warmup, samples=samples, progress=progress)
    nuts["chain_method"] = chain_method or _chain_method(chains, emulate is not False)
    mcmc, sampled, precondition_s = _nuts(make_model, priors, mean, y, seed, emulate, terms["extra_init"], nuts)
    idata = _inference_data(mcmc, model_error, t, y, seed, residuals)
    wall = time.perf_counter() - start
    summary = diagnostics(idata, priors, y, mcmc, residuals)
    summary.update(
        {
            "wall_s": wall,
            "emulator": terms["emulator"],
            "laplace_s": precondition_s if emulate is False else None,
            "chain_method": mcmc.chain_method,
            "coordinates": {p.site: coordinate(p) for p in sampled},
            **{k: nuts[k] for k in ("chains", "warmup", "samples")},
            "discrepancy": likelihood.discrepancy,
            **{k: terms[k] for k in ("rig_centre", "linearisations", "configuration_error_m")},
            **likelihood_record(residuals, y),
        }
    )
    return PosteriorResult(idata, summary, wall, residuals, (t, y))


def _terms(experiments, config, priors, likelihood: Likelihood, data, given, emulate, seed: int, start, progress):
    """The likelihood's terms of the set's one run: {mean (its ``mean_length``), model_error (the emulator's RMS
    error, m), emulator (its record), residuals (`Residuals` or None), extra_init (start values), rig_centre
    {tolerance: ln(ψ/ψ₀)}, linearisations (the fit's), configuration_error_m (the drift's sd, m)}. The rig is
    linearised at ``given`` or where the fit puts it (`_rig_centre`); ``data`` = (t (n,) s, y (n,) m)."""
    run = experiments.runs[0]
    base = run.base()
    inputs = run.model_inputs(base, config.t0, config.t1)
    tol = likelihood.budget(base, [p.name for p in priors])
    centre, linearisations = _rig_centre(given, tol, experiments, priors, config, likelihood, seed, progress)
    base = tl.rig_at(base, tol, centre)
    t, y = data
    mean, model_error, emu_info = _mean_length(emulate, priors, base, inputs, config, t, seed, start)
    prog.note(f"posterior: the likelihood ({likelihood.discrepancy} discrepancy)", progress)
    drift = likelihood.model_error_for(config)
    residuals, extra_init = likelihood_terms(
        likelihood.discrepancy, tol, t, y, mean, priors, (base, inputs, config), seed, centre, drift
    )
    return {
        "mean": mean,
        "model_error": model_error,
        "emulator": emu_info,
        "residuals": residuals,
        "extra_init": extra_init,
        "rig_centre": dict(zip(tol, map(float, centre))) if centre is not None else {},
        "linearisations": linearisations,
        "configuration_error_m": drift,
    }


def _one_run(experiments: ExperimentSet, config: Config | None, likelihood: Likelihood):
    """(the set's one run, the configuration on its drive with forward-mode derivatives).

    Raises:
        ValueError: a set of more than one experiment, or the rig fixed.
    """
    if len(experiments) != 1:
        raise ValueError(
            f"a posterior takes one experiment, got {len(experiments)}: several robots' experiments are the "
            "population's (growjax.posterior.population)"
        )
    if likelihood.rig != "inferred":
        raise ValueError("the posterior marginalises the rig's errors under their tolerances: give rig='inferred'")
    run = experiments.runs[0]
    return run, (config if config is not None else Config()).replace(adjoint="forward", drive=run.drive)


def _nuts(make_model, priors, mean, y, seed: int, emulate, extra_init: dict, nuts: dict):
    """(NumPyro's MCMC run, the priors as sampled, the start's and mass matrix's time s): NUTS's start
    (`_nuts_start`), then its chains with the options ``nuts``."""
    start_precondition = time.perf_counter()
    progress = nuts["progress"]
    prog.note("posterior: start point and mass matrix", progress)
    sampled, init_values, inverse_mass = _nuts_start(make_model, priors, mean, y, seed, emulate, extra_init)
    precondition_s = time.perf_counter() - start_precondition
    prog.note(
        f"posterior: NUTS, {nuts['chains']} chains of {nuts['warmup']} warm-up and {nuts['samples']} kept draws "
        f"({nuts['chain_method']})",
        progress,
    )
    start_nuts = time.perf_counter()
    mcmc = _run_nuts(make_model(mean, sampled), init_values, inverse_mass, y, seed, emulate is False, **nuts)
    jax.block_until_ready(mcmc.get_samples())  # the chains run asynchronously: their time, not the dispatch's
    prog.note(f"posterior: NUTS done in {time.perf_counter() - start_nuts:.1f} s", progress)
    return mcmc, sampled, precondition_s


def _inference_data(mcmc, model_error: float, t, y, seed: int, residuals):
    """The run's DataTree (`inference_data`) with the pointwise log-likelihood and the replicated lengths of every
    draw (`observation_draws`)."""
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
    return inference_data(post, mcmc.get_extra_fields(group_by_chain=True), t, y, scored, loglik, predicted, new)


def _mean_length(emulate, priors, base, inputs, config, t, seed: int, start: float):
    """(``mean_length`` at the times ``t``, the emulator's RMS error (m, 0 through the model), the emulator's record
    or None) for `sample`: the model with its own tangents, or an emulator (given, or built over the priors'
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

    prog.note("posterior: the fit, for where the data put the rig", progress)
    length_only = ExperimentSet(tuple(dataclasses.replace(r, sensors=("length",)) for r in experiments))
    fitted = fit(length_only, [p.name for p in priors], likelihood=likelihood, config=config, seed=seed)
    offsets = next(iter(fitted.rig_offset.values()), {})
    centre = np.array([offsets.get(name, 0.0) for name in tol])
    if not np.all(np.isfinite(centre)) or not np.any(centre):  # the rig stayed at nominal
        return None, fitted.linearisations
    return centre, fitted.linearisations


def _nuts_start(make_model, priors, mean, y, seed: int, emulate, extra_init: dict):
    """(priors as sampled, start, inverse mass matrix): `precondition`, then through the model
    `bound_start`."""
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
    """NumPyro's MCMC run of NUTS on ``model`` from ``init_values`` with ``inverse_mass`` (dense, or its diagonal);
    NumPyro's bars only where ``progress`` goes to a terminal (in a log they would be a line per update)."""
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
        progress_bar=progress and prog.terminal(),
    )
    mcmc.run(jax.random.PRNGKey(seed), jnp.asarray(y), extra_fields=("diverging", "energy", "num_steps"))
    return mcmc


def _chain_method(chains: int, emulated: bool) -> str:
    """``"vectorized"`` through an emulator; through the model ``"parallel"`` (one chain per JAX device, each on its
    own thread: expose CPU cores as devices before JAX starts, as ``growjax posterior`` does) when there are as many
    devices as chains, else ``"sequential"``: the vmapped forward-mode solve (members stepped together) costs what
    the chains cost one after another, and the chains' trees, built in lockstep, would wait for the deepest
    (`benchmarks/nuts_direct.py` measures both)."""
    if emulated:
        return "vectorized"
    return "parallel" if chains > 1 and jax.local_device_count() >= chains else "sequential"
