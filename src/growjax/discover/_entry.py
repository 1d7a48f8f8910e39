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
    """Which catalogue effect the measured lengths of ``experiments`` need beyond the base model, and how sure.

    A set of one experiment is discovered on its own (`DiscoveryResult`): the base fit, every candidate fitted
    with the base refitted and held, rounds that add effects (up to ``max_effects``). A larger set is discovered
    by its joint fits (`SetDiscoveryResult`): one round, each effect's parameter one value per ``effect_scope``.
    The module docstring and `discover_set` give each procedure.

    Args:
        experiments: the runs (`growjax.data.sets.ExperimentSet`; `ExperimentSet.single` makes a set of one). A
            run's parameters (`growjax.data.sets.Run.base`) are the base model, and also the values against which
            a base parameter's shift counts as confounding; its inputs are its own or made from its columns; its
            ``window`` (else the configuration's span), s, selects the samples scored.
        config: the simulation's settings (default: the first run's drive, the fast configuration).
        base_free: base parameters refitted with every candidate, ``NAME`` or ``NAME@SCOPE`` (default scope: one
            per robot).
        candidates: catalogue effects tested (default the whole catalogue, registered effects included).
        false_positive_rate: the family's false-alarm rate, Bonferroni over the candidates.
        confounding_correlation: the correlation with a base parameter beyond which a candidate may be confounded.
        likelihood: the likelihood of every score (`growjax.calibration.Likelihood`).
        material_misfit: m: a smooth misfit below it is left to the discrepancy.
        max_steps: Levenberg–Marquardt steps of each fit (default 40 for one experiment, 100 for a set).
        max_effects: one experiment: the most effects added.
        multistart: one experiment: fit each candidate from every start (False: the first only).
        progress: one experiment: report the fits on stderr.
        workers: one experiment: fits run at a time (default one per CPU core; the result does not depend on it).
        effect_scope: a set: the copies of each effect's parameter (``"robot"``, ``"rig"``, ``"experiment"`` or
            ``"shared"``).
        scout: a set: points of each joint fit's Latin-hypercube scout.
        seed: a set: seed of the scout.

    Returns:
        `DiscoveryResult` for a set of one, `SetDiscoveryResult` for more.

    Raises:
        TypeError: ``experiments`` is not an `ExperimentSet`.
        ValueError: an unknown candidate, parameter or scope, a drive other than the configuration's, or a run
            without samples in its window.
    """
    if not isinstance(experiments, ExperimentSet):
        raise TypeError(
            f"discover takes a growjax.data.sets.ExperimentSet (ExperimentSet.single for one), got {type(experiments)}"
        )
    for name in candidates or ():
        candidate_parameter(name)  # an unknown effect is refused before any fit
    if candidates is not None and len(set(candidates)) != len(tuple(candidates)):
        raise ValueError(f"a candidate is named twice: {list(candidates)}")
    config = config if config is not None else Config(drive=experiments.runs[0].drive)
    if len(experiments) > 1:
        return discover_set(
            experiments,
            config=config,
            base_free=base_free,
            candidates=candidates,
            effect_scope=effect_scope,
            false_positive_rate=false_positive_rate,
            confounding_correlation=confounding_correlation,
            likelihood=likelihood,
            material_misfit=material_misfit,
            scout=scout,
            seed=seed,
            max_steps=SET_MAX_STEPS if max_steps is None else max_steps,
        )
    (run,) = experiments.runs
    if run.drive != config.drive:
        raise ValueError(
            f"the run {run.name!r} is on the {run.drive} drive, the configuration on the {config.drive} drive"
        )
    base = run.base()
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
        candidates=candidates,
        false_positive_rate=false_positive_rate,
        confounding_correlation=confounding_correlation,
        max_effects=max_effects,
        max_steps=SINGLE_MAX_STEPS if max_steps is None else max_steps,
        multistart=multistart,
        progress=progress,
        workers=workers,
        likelihood=likelihood,
        material_misfit=material_misfit,
    )
