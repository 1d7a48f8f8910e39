"""Discovery over an experiment set: each catalogue effect tested by the set's joint fit, its parameter one value
per robot.

The procedure, one round (at most one effect is added):

1. **Base fit.** `growjax.calibration.fit` of ``base_free`` (default one yield pressure per robot) under
   ``likelihood`` (`growjax.calibration.Likelihood`: the rig's errors shared per rig and inferred under their
   tolerances by default, each run with its own discrepancy). Its score is the set's total log-likelihood
   (`growjax.calibration.FitResult.log_likelihood`): every run's under its discrepancy and noise at their mode,
   the rig's errors marginalised.
2. **Each candidate** (default the whole catalogue) is one more joint fit, one batched program over the runs:
   the base parameters and the effect's parameter freed together, fitted from the best of the fit's
   Latin-hypercube scout (``scout`` points, ``seed``; the effect's box a factor two either side of
   `EFFECT_START` of its range's top, or, for an effect whose range also allows negative values (trapped air),
   its physical range, fitted in a linear coordinate).
3. **Score.** 2ΔlogL = 2 (logL_k − logL_base), floored at 0. The threshold: 2ΔlogL distributed as the mixture of
   χ² over the effect's copies on their boundary (½χ²₀ + ½χ²₁ for one robot, `boundary_threshold`) at
   ``false_positive_rate`` Bonferroni-divided over the candidates, as in `growjax.discover.discover`.
4. **Confounding.** A candidate that clears the threshold while one of its copies correlates with a base
   parameter beyond ``confounding_correlation`` in the joint covariance is ``confounded`` with that parameter,
   unless its size is pinned (every copy's 90 % interval within a factor two of its estimate). Two candidates
   that both clear it within the threshold of each other are both ``confounded`` (rivals), and neither is added.
   (Single-experiment discovery's base-held fits and its allowance for the fitted configuration's own error are
   not run.)
5. **Verdict.** The best clean candidate is added. Each run's residuals get the misfit test of
   `growjax.discover.Scorer` (the discrepancy's significance against white noise; ``material_misfit``,
   m, its material amplitude; the rig at its fitted errors): the set is structured where any run is. The
   verdict follows `growjax.discover.discover`'s: the effect where one was added and no structure
   remains; ``"unexplained"`` where structure remains (or is material with none added); ``"confounded"``;
   else ``"none"``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence

import numpy as np

from growjax.calibration import FitResult, Likelihood, fit
from growjax.calibration.likelihood_ratio import boundary_p_value, boundary_threshold
from growjax.data.sets import SCOPES, ExperimentSet, Scope
from growjax.model import effects as fx
from growjax.simulation.config import Config

from ._candidates import START_FRACTIONS, candidate_parameter
from ._decision import choose, confounded_with_base, final_effect, separated_by
from ._report import _unit, confounded_lines
from ._scoring import MATERIAL_MISFIT, Scorer, is_pinned, noise_from_differences

EFFECT_START = START_FRACTIONS[1]  # an effect's joint fit starts at this fraction of its range's top


@dataclasses.dataclass
class SetDiscoveryResult:
    """What `growjax.discover.discover` found on a set of several experiments (see `report` for the JSON form). ``parameters``: the final model's
    {label: {"estimate", "interval_90", "unit"}}, a label ``NAME@KEY`` per robot (or per the scope's key);
    ``evidence``: one round, {candidate: its score}; ``misfit_before``/``misfit_after``: per run the misfit test
    (as :meth:`growjax.discover.Scorer.misfit`), with ``structured``/``material`` of the set (any run)."""

    effect: str  # a catalogue name, "none", "unexplained" or "confounded"
    effects: list
    parameters: dict
    threshold: float
    evidence: list
    confounded_with: dict
    misfit_before: dict
    misfit_after: dict
    separating_measurement: dict
    log_likelihood_base: float
    runs: list  # per run: name, robot, rig, rmse before and after (m)
    fits: int  # joint fits run (one batched program each)
    wall_s: float

    def report(self) -> dict:
        return dataclasses.asdict(self)


def discover_set(
    experiments: ExperimentSet,
    *,
    config: Config | None = None,
    base_free: Sequence[str] = ("Y@robot",),
    candidates: Sequence[str] | None = None,
    effect_scope: str = "robot",
    false_positive_rate: float = 0.05,
    confounding_correlation: float = 0.99,
    likelihood: Likelihood = Likelihood(),
    material_misfit: float = MATERIAL_MISFIT,
    scout: int = 16,
    seed: int = 0,
    max_steps: int = 100,
) -> SetDiscoveryResult:
    """Which catalogue effect the runs of ``experiments`` need beyond the base model, each effect's parameter one
    value per robot (``effect_scope``: or one per rig, per run, or one for all): `growjax.discover.discover` of a
    set of several experiments.

    The procedure is the module's docstring.

    Sizes and intervals are the joint fit's; ``config``'s ``t1`` ends every run's window; ValueError for an unknown
    candidate or scope.
    """
    started = time.perf_counter()
    candidates = _checked(candidates, effect_scope, false_positive_rate)
    config = config if config is not None else Config()
    base_params = experiments.runs[0].base()
    base_scopes = [s if isinstance(s, Scope) else Scope.parse(s, base_params, default="robot") for s in base_free]
    copies = len(dict.fromkeys(experiments.group_of(effect_scope)))
    threshold = boundary_threshold(false_positive_rate / len(candidates), copies)
    options = dict(config=config, likelihood=likelihood, starts=1, scout=scout, seed=seed, max_steps=max_steps)
    base = fit(experiments, base_scopes, **options)
    fits = {}
    for name in candidates:
        qname, _, (_, top) = candidate_parameter(name)
        effect = fx.CATALOGUE[name](**{qname.split(".")[1]: EFFECT_START * top})
        fits[name] = fit(experiments, [*base_scopes, Scope(qname, effect_scope)], effects=(effect,), **options)
    scores = {name: _score(name, f, base, threshold, confounding_correlation, copies) for name, f in fits.items()}
    confounded = confounded_with_base(scores)
    best = choose(scores, threshold, confounded)
    final = fits[best] if best is not None else base
    windows = _measured(experiments, config)
    misfit_before = _misfit(base, windows, likelihood.discrepancy, material_misfit)
    misfit_after = _misfit(final, windows, likelihood.discrepancy, material_misfit)
    added = [best] if best is not None else []
    units = {candidate_parameter(n)[0]: candidate_parameter(n)[1] for n in candidates}
    parameters = {
        lab: {
            "estimate": final.estimate[lab],
            "interval_90": final.interval_90[lab],
            "unit": units.get(c.name, _unit(c.name)),
        }
        for lab, c in zip(final.labels, final.coordinates)
    }
    runs = [
        {
            "name": a["name"],
            "robot": a["robot"],
            "rig": a["rig"],
            "rmse_before_m": a["rmse_length_m"],
            "rmse_after_m": b["rmse_length_m"],
        }
        for a, b in zip(base.runs, final.runs)
    ]
    return SetDiscoveryResult(
        effect=final_effect(added, misfit_after, confounded),
        effects=added,
        parameters=parameters,
        threshold=threshold,
        evidence=[scores],
        confounded_with=confounded,
        misfit_before=misfit_before,
        misfit_after=misfit_after,
        separating_measurement={n: separated_by(n) for n in confounded},
        log_likelihood_base=base.log_likelihood,
        runs=runs,
        fits=1 + len(fits),
        wall_s=time.perf_counter() - started,
    )


def _checked(candidates, effect_scope: str, false_positive_rate: float) -> tuple:
    """The candidates (default the whole catalogue), after refusing an unknown or repeated one, a bad scope or
    rate."""
    candidates = tuple(candidates) if candidates else tuple(fx.CATALOGUE)
    for name in candidates:
        candidate_parameter(name)  # an unknown effect is refused before any fit
    if len(set(candidates)) != len(candidates):
        raise ValueError(f"a candidate is named twice: {list(candidates)}")
    if effect_scope not in SCOPES:
        raise ValueError(f"effect_scope must be one of {SCOPES}, got {effect_scope!r}")
    if not 0.0 < false_positive_rate < 1.0:
        raise ValueError(f"false_positive_rate must lie in (0, 1), got {false_positive_rate}")
    return candidates


def _score(
    name: str,
    fit: FitResult,
    base: FitResult,
    threshold: float,
    confounding_correlation: float,
    copies: int,
) -> dict:
    """A candidate's evidence from its joint fit ``fit`` against the base fit: the keys of
    :func:`growjax.discover.score_candidate` (its estimate and interval per copy)."""
    qname, unit, (lo, hi) = candidate_parameter(name)
    mine = [k for k, c in enumerate(fit.coordinates) if c.name == qname]
    others = [k for k in range(len(fit.labels)) if k not in mine]
    lr = max(2.0 * (fit.log_likelihood - base.log_likelihood), 0.0)
    if not math.isfinite(lr):
        lr = 0.0
    cov = fit.covariance
    sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    corr = {}
    for j in others:  # each base parameter: its largest correlation with a copy of the effect
        c = [float(cov[k, j] / (sd[k] * sd[j])) for k in mine]
        corr[fit.labels[j]] = max(c, key=abs)
    c_max = max(corr.values(), key=abs, default=0.0)
    estimate = {fit.labels[k]: fit.estimate[fit.labels[k]] for k in mine}
    interval = {fit.labels[k]: fit.interval_90[fit.labels[k]] for k in mine}
    pinned = lr > threshold and all(iv is not None and is_pinned(estimate[lab], iv) for lab, iv in interval.items())
    return {
        "parameter": qname,
        "unit": unit,
        "estimate": estimate,
        "interval_90": interval,
        "lr_statistic": lr,
        "p_value": boundary_p_value(lr, copies),
        "log_likelihood": fit.log_likelihood,
        "rmse_m": [r["rmse_length_m"] for r in fit.runs],
        "lr_statistic_base_held": None,
        "correlation_with_base": corr,
        "clears_threshold": bool(lr > threshold),
        "pinned": bool(pinned),
        "at_range_edge": bool(any(v >= hi * (1 - 1e-6) for v in estimate.values())),
        "confounded": bool(abs(c_max) > confounding_correlation and lr > threshold and not pinned),
        "status": fit.status,
    }


def _measured(experiments: ExperimentSet, config: Config) -> list:
    """Per run its measured length (n,) m in its scored window (as the joint fit scores it)."""
    out = []
    for run in experiments:
        t0, t1 = run.window if run.window is not None else (config.t0, config.t1)
        keep = (run.times >= t0) & (run.times <= t1)
        out.append(np.asarray(run.length)[keep])
    return out


def _misfit(fit: FitResult, measured: list, discrepancy: str, material: float) -> dict:
    """The misfit test of each run's residuals of ``fit``, and the set's: structured (material) where any run is."""
    per_run = []
    for (t, r), length, run in zip(fit.residuals, measured, fit.runs):
        scorer = Scorer(t, length, noise_from_differences(r), discrepancy, material)
        per_run.append({"name": run["name"], **scorer.misfit(r)})
    return {
        "structured": any(m["structured"] for m in per_run),
        "material": any(m["structured"] and m.get("material", True) for m in per_run),
        "runs": per_run,
    }


def set_summary_text(result: SetDiscoveryResult) -> str:
    """A readable summary of a :class:`SetDiscoveryResult` for the terminal."""
    lines = [
        f"effect: {result.effect}" + (f" (added: {', '.join(result.effects)})" if result.effects else ""),
        f"threshold 2ΔlogL > {result.threshold:.2f} (the set's joint fits, one round)",
    ]
    for name, p in result.parameters.items():
        iv = p["interval_90"]
        shown = "undetermined" if iv is None else f"90 %: {iv[0]:.4g} – {iv[1]:.4g}"
        lines.append(f"  {name} = {p['estimate']:.4g} {p['unit']} ({shown})")
    for r in result.runs:
        lines.append(
            f"  {r['name']}: length RMSE {1e3 * r['rmse_before_m']:.3f} mm before, "
            f"{1e3 * r['rmse_after_m']:.3f} mm after"
        )
    lines.append("round 1:")
    for name, s in sorted(result.evidence[0].items(), key=lambda kv: -kv[1]["lr_statistic"]):
        flag = "confounded" if s["confounded"] else ("clears" if s["clears_threshold"] else "")
        sizes = ", ".join(f"{v:.3g}" for v in s["estimate"].values())
        lines.append(f"  {name:22s} 2ΔlogL {s['lr_statistic']:8.2f}  {s['parameter']} = {sizes} {s['unit']}  {flag}")
    lines += confounded_lines(result.confounded_with)
    lines.append(f"{result.wall_s:.1f} s: {result.fits} joint fits")
    return "\n".join(lines)
