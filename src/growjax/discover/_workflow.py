"""The discovery workflow: the base fit, the first round's fits with the base refitted and held, the rounds of
scoring and adding effects, and the result."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import numpy as np
from jaxtyping import ArrayLike, Float
from scipy import stats

from growjax.calibration import MODEL_ERROR_TIME, Likelihood
from growjax.calibration import tolerance as tl
from growjax.model import effects as fx
from growjax.model import params as gp
from growjax.simulation.config import Config

from ._candidates import CandidateFit, _held_start, candidate_parameter, make_candidates
from ._decision import choose, confounded_with_base, final_effect, separated_by
from ._fitting import Fitter, _cores
from ._report import DiscoveryResult, _unit, locate
from ._scoring import MATERIAL_MISFIT, Scorer, noise_from_differences, score_round, shared_intervals


def discover_one(
    times: Float[ArrayLike, " m"],
    length: Float[ArrayLike, " m"],
    inputs,
    *,
    base: gp.Parameters | None = None,
    config: Config | None = None,
    base_names: Sequence[str] = ("Y",),
    candidates: Sequence[str] | None = None,
    false_positive_rate: float = 0.05,
    confounding_correlation: float = 0.99,
    max_effects: int = 2,
    max_steps: int = 40,
    multistart: bool = True,
    progress: bool = False,
    workers: int | None = None,
    likelihood: Likelihood = Likelihood(),
    material_misfit: float = MATERIAL_MISFIT,
) -> DiscoveryResult:
    """Find which catalogue effect the measured ``length`` (m) at ``times`` (s) needs beyond the base model.

    ``inputs``: the experiment's `growjax.Inputs`; ``base``: the base parameters (default the published set of
    ``config.drive``), also the reference of a confounding shift; ``base_names``: refitted with every candidate;
    ``multistart``: every new candidate fitted from every start in ``START_FRACTIONS``; ``workers``: fits run at
    a time (the result does not depend on it); ``likelihood``: of every test, the rig inferred in every score.
    The module docstring gives the procedure and its thresholds; `growjax.discover.discover` the options.
    """
    discrepancy = likelihood.discrepancy
    start = time.perf_counter()
    workers = workers if workers is not None else _cores()
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    config = config if config is not None else Config()
    base = base if base is not None else gp.reference(config.drive)
    candidates = tuple(candidates) if candidates else tuple(fx.CATALOGUE)
    times, length = np.asarray(times, float), np.asarray(length, float)
    problem = make_candidates(times, length, inputs, candidates, base, base_names, config)
    fitter = Fitter(problem, length, multistart, workers, progress, max_steps)
    threshold = float(stats.chi2.isf(2.0 * false_positive_rate / len(candidates), df=1))  # ½χ²₀ + ½χ²₁, Bonferroni
    model_error = likelihood.model_error_for(config)
    tol = likelihood.budget(base, base_names)
    first = _first_round(fitter, candidates, times, length, discrepancy, material_misfit, (base, inputs, config, tol))
    held_lr, held_trades = _held_round(fitter, first, candidates, threshold)
    allowance = first.scorer.allowance(first.base_fit.residual_m, model_error, MODEL_ERROR_TIME)
    misfit_before = first.scorer.misfit(first.base_fit.residual_m)
    misfit_open = discrepancy == "none" or (misfit_before["structured"] and misfit_before["material"])
    held = {name: (h, h > threshold + allowance and held_trades[name] and misfit_open) for name, h in held_lr.items()}
    current, added, evidence, confounded = _rounds(
        fitter, first, candidates, held, threshold, confounding_correlation, max_effects, allowance
    )
    misfit_after = first.scorer.misfit(current.residual_m)
    before_trace, after_trace = length + first.base_fit.residual_m, length + current.residual_m
    parameters = _parameters(current, candidates, first.scorer, model_error)
    return DiscoveryResult(
        effect=final_effect(added, misfit_after, confounded),
        effects=added,
        parameters=parameters,
        rmse_before_m=misfit_before["rmse_m"],
        rmse_after_m=misfit_after["rmse_m"],
        noise_sigma_m=first.sigma,
        threshold=threshold,
        evidence=evidence,
        confounded_with=confounded,
        where={
            "before": locate(times, first.base_fit.residual_m, before_trace, first.pressure),
            "after": locate(times, current.residual_m, after_trace, first.pressure),
        },
        misfit_before=misfit_before,
        misfit_after=misfit_after,
        separating_measurement={n: separated_by(n) for n in confounded},
        wall_s=time.perf_counter() - start,
        trade_allowance=allowance,
        fits=fitter.fits,
        linearisations=fitter.linearisations,
        times=times,
        measured=length,
        before=before_trace,
        after=after_trace,
    )


@dataclasses.dataclass
class _FirstRound:
    """The base fit and the first round's joint fits: the raw fits (base first, as :meth:`Fitter.batch` returns
    them), their summaries, the noise σ (m) the later rounds use, the scorer, and the base model's pressure (m,) Pa."""

    outs: list
    base_fit: CandidateFit
    fits: dict
    sigma: float
    scorer: Scorer
    pressure: np.ndarray


def _first_round(
    fitter: Fitter, candidates, times, length, discrepancy: str, material_misfit: float, rig
) -> _FirstRound:
    """The base model, then every candidate on it with the base parameters refitted jointly, each starting from the
    base fit (the extended model then starts within its new term of the base optimum, not in a side minimum of the
    base parameters that the given values may lie nearer to). ``rig`` = (base, inputs, config, tolerances): the
    rig's sensitivities are taken at the base fit and marginalised by the scorer."""
    p, k_all = fitter.p, fitter.k_all
    z0 = np.concatenate([np.zeros(p), np.zeros(k_all)])
    base_out = fitter.batch([((), True, z0)], "base")[0]
    z_base = np.concatenate([base_out[0][:p], np.zeros(k_all)])
    outs = [base_out] + fitter.batch([((k,), True, z_base) for k in range(k_all)], "round 1")
    sigma = noise_from_differences(outs[0][1] * 1e-3)
    base_fit = fitter.summarise(outs[0], sigma, ())
    fits = {candidates[k]: fitter.summarise(outs[k + 1], sigma, (candidates[k],)) for k in range(k_all)}
    scorer = Scorer(times, length, sigma, discrepancy, material_misfit)
    base, inputs, config, tol = rig
    if tol:
        theta = {n: base_fit.estimate[n] for n in fitter.problem.base_names}
        scorer.with_tolerances(tl.length_sensitivity(theta, base, inputs, config, times, tol), list(tol.values()))
    if discrepancy != "none":
        scorer.anchor(base_fit.residual_m)
        sigma = scorer.noise(base_fit.residual_m)
    return _FirstRound(outs, base_fit, fits, sigma, scorer, outs[0][5])


def _held_round(fitter: Fitter, first: _FirstRound, candidates, threshold: float) -> tuple[dict, dict]:
    """({candidate: 2ΔlogL over the base model, both with the base held}, {candidate: whether with the base held it
    explains the data as well as refitting the base does}). The same candidates with the base parameters held at
    their given values (deciding confounding for a candidate correlated with a base parameter, reported for the
    others), each from one start: where its joint fit's linearisation puts it with the base at the given values."""
    p, k_all, outs = fitter.p, fitter.k_all, first.outs
    z0 = np.concatenate([np.zeros(p), np.zeros(k_all)])
    u_held = [_held_start(fitter.problem, outs[k + 1], k, fitter.u_starts[k, 0]) for k in range(k_all)]
    held = fitter.batch(
        [((), False, z0)]
        + [((k,), False, np.where(np.arange(p + k_all) == p + k, u_held[k], z0)) for k in range(k_all)],
        "base held",
        warm=set(range(1, k_all + 1)),
    )
    held_res = [h[1] * 1e-3 for h in held]
    scorer = first.scorer
    held_lr = {candidates[k]: scorer.lr(held_res[0], held_res[k + 1]) for k in range(k_all)}
    held_trades = {
        candidates[k]: scorer.lr(held_res[k + 1], first.base_fit.residual_m, signed=True) < threshold
        for k in range(k_all)
    }
    return held_lr, held_trades


def _rounds(
    fitter: Fitter,
    first: _FirstRound,
    candidates,
    held: dict,
    threshold: float,
    confounding_correlation: float,
    max_effects: int,
    allowance: float = 0.0,
):
    """(the final model's fit, the effects added, the evidence per round, {candidate: confounding record}): each
    round scores the remaining candidates on top of the current model (the first round's with ``held``, its
    base-held evidence), records the confounded ones and adds the best clean one, until none clears the threshold,
    a rival ties, the misfit test passes or ``max_effects`` are added."""
    current, fits, scorer = first.base_fit, first.fits, first.scorer
    added, evidence, confounded = [], [], {}
    for round_no in range(max_effects):
        if round_no > 0:
            if not scorer.misfit(current.residual_m)["structured"]:
                break
            others = [k for k in range(fitter.k_all) if k not in fitter.added_index]
            outs = fitter.batch(
                [(tuple(fitter.added_index) + (k,), True, current.z) for k in others], f"round {round_no + 1}"
            )
            fits = {
                candidates[k]: fitter.summarise(o, first.sigma, tuple(added) + (candidates[k],))
                for k, o in zip(others, outs)
            }
        scores = score_round(
            fits,
            current.residual_m,
            scorer,
            threshold,
            confounding_correlation,
            held if round_no == 0 else None,
            allowance,
        )
        confounded.update(confounded_with_base(scores))
        evidence.append(scores)
        best = choose(scores, threshold, confounded)
        if best is None:
            break
        added.append(best)
        fitter.added_index.append(candidates.index(best))
        current = fits[best]
    return current, added, evidence, confounded


def _parameters(current, candidates, scorer, model_error: float) -> dict:
    """{name: {"estimate", "interval_90", "unit"}} of the final model's parameters."""
    units = {candidate_parameter(n)[0]: candidate_parameter(n)[1] for n in candidates}
    intervals = shared_intervals(current, scorer, model_error)
    return {
        n: {"estimate": v, "interval_90": intervals[n], "unit": units.get(n, _unit(n))}
        for n, v in current.estimate.items()
    }
