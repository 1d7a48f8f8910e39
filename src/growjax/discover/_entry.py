"""The entry of a discovery: a set of one experiment takes the single-experiment workflow, a larger set the set's
joint fits."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from growjax.calibration import Likelihood
from growjax.data.sets import ExperimentSet, Scope
from growjax.simulation.config import Config

from ._candidates import candidate_parameter
from ._report import DiscoveryResult
from ._scoring import MATERIAL_MISFIT
from ._set import SetDiscoveryResult, discover_set
from ._workflow import discover_one

SINGLE_MAX_STEPS = 40  # Levenberg–Marquardt steps of each fit of one experiment
SET_MAX_STEPS = 100  # of each joint fit of a set


def discover(
    experiments: ExperimentSet,
    *,
    config: Config | None = None,
    base_free: Sequence[str] = ("Y",),
    candidates: Sequence[str] | None = None,
    false_positive_rate: float = 0.05,
    confounding_correlation: float = 0.99,
    likelihood: Likelihood = Likelihood(),
    material_misfit: float = MATERIAL_MISFIT,
    max_steps: int | None = None,
    max_effects: int = 2,
    multistart: bool = True,
    progress: bool = False,
    workers: int | None = None,
    effect_scope: str = "robot",
    scout: int = 16,
    seed: int = 0,
) -> DiscoveryResult | SetDiscoveryResult:
    """Which catalogue effect the measured lengths of ``experiments`` need beyond the base model, and how sure: a
    set of one alone (effects added in rounds), a larger set by its joint fits (one round, one copy per scope).

    Args:
        experiments: the runs; a run's parameters are the base model (and the reference of a confounding shift),
            its inputs its own or its columns', its ``window`` the samples scored.
        config: the simulation's settings (default: the first run's drive, the fast configuration).
        base_free: base parameters refitted with every candidate, ``NAME`` or ``NAME@SCOPE`` (default scope: one
            per robot).
        candidates: catalogue effects tested (default the whole catalogue, registered effects included).
        false_positive_rate: the family's false-alarm rate, Bonferroni over the candidates.
        confounding_correlation: the correlation with a base parameter beyond which a candidate may be confounded.
        likelihood: the likelihood of every score (`growjax.calibration.Likelihood`).
        material_misfit: m: a smooth misfit below it is left to the discrepancy.
        max_steps: Levenberg–Marquardt steps of each fit (default 40 for one experiment, 100 for a set).
        max_effects, multistart, progress, workers: one experiment's: the most effects added, every candidate
            fitted from every start, the fits reported on stderr, fits run at a time (the result does not
            depend on it).
        effect_scope, scout, seed: a set's: the copies of each effect's parameter (``"robot"``, ``"rig"``,
            ``"experiment"`` or ``"shared"``), points and seed of each joint fit's Latin-hypercube scout.

    Returns:
        `DiscoveryResult` for a set of one, `SetDiscoveryResult` for more.

    Raises:
        TypeError: not an `ExperimentSet`. ValueError: an unknown candidate, parameter or scope, another drive
            than the configuration's, or a run without samples in its window.
    """
    config = _checked(experiments, candidates, config)
    shared = dict(
        candidates=candidates,
        false_positive_rate=false_positive_rate,
        confounding_correlation=confounding_correlation,
        likelihood=likelihood,
        material_misfit=material_misfit,
    )
    if len(experiments) > 1:
        steps = SET_MAX_STEPS if max_steps is None else max_steps
        return discover_set(
            experiments, config=config, base_free=base_free, effect_scope=effect_scope, scout=scout, seed=seed,
            max_steps=steps, **shared,
        )  # fmt: skip
    run, base = experiments.runs[0], experiments.runs[0].base()
    t0, t1 = run.window if run.window is not None else (config.t0, config.t1)
    keep = (run.times >= t0) & (run.times <= t1)
    if not np.any(keep):
        raise ValueError(f"the run {run.name!r} has no samples in its window [{t0}, {t1}] s")
    return discover_one(
        run.times[keep],
        np.asarray(run.length)[keep],
        run.model_inputs(base, config.t0, config.t1),
        base=base,
        config=config,
        base_names=[Scope.parse(s, base, default="robot").name for s in base_free],
        max_effects=max_effects,
        max_steps=SINGLE_MAX_STEPS if max_steps is None else max_steps,
        multistart=multistart,
        progress=progress,
        workers=workers,
        **shared,
    )


def _checked(experiments, candidates, config: Config | None) -> Config:
    """The configuration (default the first run's drive), after refusing a bad set, candidate or drive."""
    if not isinstance(experiments, ExperimentSet):
        raise TypeError(
            f"discover takes a growjax.data.sets.ExperimentSet (ExperimentSet.single for one), got {type(experiments)}"
        )
    for name in candidates or ():
        candidate_parameter(name)  # an unknown effect is refused before any fit
    if candidates is not None and len(set(candidates)) != len(tuple(candidates)):
        raise ValueError(f"a candidate is named twice: {list(candidates)}")
    config = config if config is not None else Config(drive=experiments.runs[0].drive)
    if len(experiments) == 1 and experiments.runs[0].drive != config.drive:
        run = experiments.runs[0]
        raise ValueError(
            f"the run {run.name!r} is on the {run.drive} drive, the configuration on the {config.drive} drive"
        )
    return config
