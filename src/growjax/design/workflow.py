"""One design end to end: the random admissible batch, the search from its best (a descent for the forward drive's
demand, a local search over the stepper's schedule), the check of the result over every draw, and the table that
sets the design beside the baseline (the published pulse train; for the stepper, the recorded length as its
demand) and the best random input."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import jax
import numpy as np

import growjax.design.constraints as dcon
import growjax.design.criterion as dcrit
import growjax.design.discrimination as ddis
import growjax.design.optimise as dopt
import growjax.design.problem as dprob
from growjax import progress as prog
from growjax.calibration import Z90
from growjax.calibration.likelihood_ratio import boundary_threshold
from growjax.design.knowledge import Knowledge
from growjax.design.space import DesignSpace, StepperSpace, check_p_max
from growjax.model import effects as fx
from growjax.model.limits import Limits
from growjax.model.signals import Inputs
from growjax.simulation.simulate import input_breaks

__all__ = ["SHRINK", "DesignError", "DesignResult", "design", "discriminate", "published_inputs"]

SHRINK = (0.97, 0.93, 0.88, 0.8, 0.7)  # demand scalings tried on a design that fails its check


class DesignError(ValueError):
    """No admissible design: the message says which limit every candidate crossed."""


@dataclasses.dataclass
class DesignResult:
    """A designed input and what it is predicted to give.

    ``x`` the design, ``knots`` (K,) s and ``demand`` (K,) its demand there (Pa at the knots; for the stepper, the
    commanded length, m, after each edge); ``rows``: the table, one row per input (the space's baseline, "best
    random input", "design") and sensor set, each parameter's predicted sd
    of ln θ with what is known (``sd_log``: averaged over the points, with what the fit's linearised rig misses),
    from the next experiment alone (``sd_log_alone``), the classical local prediction at the estimate
    (``sd_log_local``) and its 90 % interval (SI); ``checks``: {input: `growjax.design.constraints.Check`
    over the draws}; ``random``: the random batch; ``descents``: the optimiser's starts, best first."""

    names: tuple
    estimate: np.ndarray
    space: DesignSpace | StepperSpace
    x: np.ndarray
    knots: np.ndarray
    demand: np.ndarray
    rows: list
    checks: dict
    random: dopt.RandomBatch
    descents: list
    limits: Limits
    criterion: str  # the criterion's name: "A", "D" (`Criterion.name`) or "discrimination"
    sensors: tuple
    knowledge: dict
    wall_s: dict
    scaled: float = 1.0  # the share of the optimiser's demand kept to pass the check (1: as optimised)
    discrimination: dict | None = None  # the rivals, their sizes and the threshold (a design by `discriminate`)

    def summary(self) -> dict:
        random = self.random
        defined = np.asarray(random.criterion)[
            np.isfinite(random.criterion)
        ]  # inf or NaN: the model failed, or no information
        return {
            "parameters": list(self.names),
            "criterion": self.criterion,
            "sensors": list(self.sensors),
            **self.space.settings(),
            "design": {**self.space.describe(self.x), "demand_scaled": self.scaled},
            "table": self.rows,
            "checks": {k: c.row(0) for k, c in self.checks.items()},
            "limits": self.limits.summary(),
            "random": {
                "admissible": int(len(random.designs)),
                "drawn": random.drawn,
                "criterion_best": float(random.criterion[random.best]),
                "criterion_quantiles": {
                    q: float(np.quantile(defined, float(q))) if defined.size else None for q in ("0.1", "0.5", "0.9")
                },
                "criterion_undefined": int(np.sum(~np.isfinite(random.criterion))),
            },
            "descents": [
                {"start_criterion": float(d.history[0]), "best": float(d.value), "history": d.history}
                for d in self.descents
            ],
            "knowledge": self.knowledge,
            "wall_s": self.wall_s,
            **({"discrimination": self.discrimination} if self.discrimination else {}),
        }


def published_inputs(space: DesignSpace | StepperSpace) -> Inputs:
    """The baseline: the published pulse train with the design's catheter (for the stepper: the recorded length
    as its demand)."""
    return space.baseline_inputs()


def design(
    knowledge: Knowledge,
    space: DesignSpace | StepperSpace,
    criterion: dcrit.Criterion | None = None,
    *,
    sensors: Sequence[str] = ("length",),
    random: int = 64,
    starts: int = 1,
    iterations: int = dopt.ITERATIONS,
    n_draws: int = dcon.DRAWS,
    seed: int = 0,
    points: int = dprob.POINTS,
    pressure_noise: float = dcrit.PRESSURE_NOISE,
    limits: Limits | None = None,
    learning_rate: float = dopt.LEARNING_RATE,
    nonlinear_draws: int = dprob.NONLINEAR_DRAWS,
    gradient: str = "differences",
    progress: bool = False,
) -> DesignResult:
    """Design the next experiment's input for the precision of ``knowledge``'s parameters.

    Random admissible inputs are drawn and scored; the optimiser descends from the best of them; the best result
    that passes the check over draws of the rig and θ (scaled down a little where it does not) is the design. The
    table reports the design, the best random input and the space's baseline under ``sensors`` and, where the
    pressure is recorded, under the length alone.

    Args:
        knowledge: what is known (the parameters of interest, their covariance, the rig's tolerances).
        space: the inputs a design may take: the forward drive's demand or the stepper's schedule.
        criterion: what the design minimises, a `growjax.design.Criterion` of the predicted covariance of the
            parameters of interest (None: `growjax.design.AOptimal`; any subclass serves).
        sensors: the sensors recorded, ``"length"`` and optionally ``"pressure"``.
        random: random admissible inputs drawn and scored (`growjax.design.optimise.random_admissible`).
        starts: the best random inputs the optimiser starts from.
        iterations: Adam steps per start (for a `growjax.design.StepperSpace`, moves of
            `growjax.design.optimise.local_search`).
        n_draws: draws of the rig and θ the check runs over.
        seed: the draws' and the random inputs' seed.
        points: the points of (θ, rig) the criterion is averaged over (1: the local design at the estimate).
        pressure_noise: the pressure sensor's noise sd, Pa.
        limits: the rig's limits; default those of ``knowledge``'s parameters.
        learning_rate: Adam's step, in the design variables.
        nonlinear_draws: draws of the rig on which what its linearisation misses is measured (0: none).
        gradient: the descent's slope, ``"differences"`` over a step of the demand or ``"jax"``, exact
            (`growjax.design.optimise.multistart`).
        progress: progress lines on stderr.

    Returns:
        The design, its table, checks, random batch and descents.

    Raises:
        DesignError: where nothing admissible is found.
        ValueError: for a demand ceiling above the rig's limit.
    """
    clock = time.perf_counter()
    sensors = tuple(sensors)
    problem = dprob.make(
        knowledge, space, criterion, sensors, pressure_noise, limits, points, seed, nonlinear_draws=nonlinear_draws
    )
    if space.drive == "forward":
        check_p_max(space.p_max, problem.limits)
    sets = [sensors] if sensors == ("length",) else [("length",), sensors]
    settings = _Search(random, starts, iterations, n_draws, seed, learning_rate, gradient, progress)
    found = _search(
        problem,
        knowledge,
        space,
        settings,
        lambda inputs, breaks: _row(problem, knowledge, space.baseline_label, inputs, breaks, sets),
    )
    rows = found.row
    for label, x in (("best random input", found.batch.designs[found.batch.best]), ("design", found.x)):
        rows += _row(problem, knowledge, label, space.inputs(x), problem.breaks, sets)
    found.wall["total_s"] = time.perf_counter() - clock
    knots = space.edges if space.drive == "inverse" else space.knots
    return _result(knowledge, space, found, rows, knots, problem, problem.criterion.name, sensors)


def discriminate(
    knowledge: Knowledge,
    space: DesignSpace,
    effects: Sequence[str],
    *,
    sizes: Sequence[float] | None = None,
    random: int = 64,
    starts: int = 1,
    iterations: int = dopt.ITERATIONS,
    n_draws: int = dcon.DRAWS,
    seed: int = 0,
    limits: Limits | None = None,
    learning_rate: float = dopt.LEARNING_RATE,
    gradient: str = "differences",
    false_positive_rate: float = 0.05,
    progress: bool = False,
) -> DesignResult:
    """Design the next experiment's input to tell two rival catalogue effects (A, B) apart.

    The input maximises min(T_AB, T_BA) (`growjax.design.discrimination`), with ``knowledge``'s parameters
    refitted beside the rival's effect. The search, the limits and the check are those of `design` (the objective
    −ln min T). The table (``rows``) holds, per input ("published pulse train", "best random input", "design"),
    T_AB, T_BA, min T and whether min T exceeds the discovery's single-experiment threshold: expected to separate.

    Args:
        knowledge: what is known (the parameters refitted beside each rival).
        space: the forward drive's demand a design may take.
        effects: the two rival catalogue effects' names (A, B).
        sizes: (a, b), the effects' assumed sizes, SI; default their moderate magnitudes.
        random: random admissible inputs drawn and scored (as `design`).
        starts: the best random inputs the optimiser starts from.
        iterations: Adam steps per start.
        n_draws: draws of the rig and θ the check runs over.
        seed: the draws' and the random inputs' seed.
        limits: the rig's limits; default those of ``knowledge``'s parameters.
        learning_rate: Adam's step, in the design variables.
        gradient: the descent's slope, ``"differences"`` or ``"jax"`` (as `design`).
        progress: progress lines on stderr.
        false_positive_rate: the discovery's false-positive rate over the catalogue, from which the threshold
            follows (`growjax.calibration.likelihood_ratio.boundary_threshold`).

    Returns:
        The design, its table, checks, random batch and descents, and the rivals' record (``discrimination``).

    Raises:
        ValueError: for a bad pair of effects.
        DesignError: where nothing admissible is found.
    """
    effects, sizes = ddis.checked_pair(effects, sizes, space.drive)
    clock = time.perf_counter()
    problem = ddis.make(knowledge, space, effects, sizes, limits)
    check_p_max(space.p_max, problem.limits)
    threshold = boundary_threshold(false_positive_rate / len(fx.CATALOGUE))
    settings = _Search(random, starts, iterations, n_draws, seed, learning_rate, gradient, progress)
    found = _search(
        problem, knowledge, space, settings, lambda inputs, breaks: ddis.statistics(problem, inputs, breaks)
    )
    rows = _discrimination_rows(problem, space, found, threshold)
    found.wall["total_s"] = time.perf_counter() - clock
    a, b = problem.effects
    record = {
        "effects": [a, b],
        "parameters": list(problem.fields),
        "sizes": [float(v) for v in np.diag(np.asarray(problem.sizes))],
        "refitted": list(knowledge.names),
        "threshold": threshold,
        "false_positive_rate": false_positive_rate,
    }
    return _result(knowledge, space, found, rows, space.knots, problem, "discrimination", ("length",), (a, b), record)


def _discrimination_rows(problem: ddis.Discrimination, space: DesignSpace, found: _Found, threshold: float) -> list:
    """The table's rows of a discrimination design: T_AB, T_BA and min T of the baseline, the best random input
    and the design."""
    a, b = problem.effects
    rows = []
    for label, t in (
        ("published pulse train", found.row),
        (
            "best random input",
            ddis.statistics(problem, space.inputs(found.batch.designs[found.batch.best]), problem.breaks),
        ),
        ("design", ddis.statistics(problem, space.inputs(found.x), problem.breaks)),
    ):
        t_ab, t_ba = (max(float(v), 0.0) for v in t)
        rows.append(
            {
                "input": label,
                "sensors": ["length"],
                "criterion": -float(np.log(max(min(t_ab, t_ba), ddis.FLOOR))),
                "T": {f"{a} real, {b} fitted": t_ab, f"{b} real, {a} fitted": t_ba},
                "T_min": min(t_ab, t_ba),
                "expected_to_separate": bool(min(t_ab, t_ba) > threshold),
            }
        )
    return rows


def _result(knowledge, space, found, rows, knots, problem, criterion, sensors, names=None, record=None):
    """The `DesignResult` of a search (``names``: the result's parameters, default ``knowledge``'s)."""
    return DesignResult(
        tuple(knowledge.names) if names is None else names,
        knowledge.estimate,
        space,
        found.x,
        knots,
        np.asarray(space.demand(found.x)),
        rows,
        found.checks,
        found.batch,
        found.descents,
        problem.limits,
        criterion,
        sensors,
        knowledge.summary(),
        found.wall,
        found.scaled,
        record,
    )


@dataclasses.dataclass(frozen=True)
class _Search:
    """The search's settings (the arguments of `design` of the same names)."""

    random: int
    starts: int
    iterations: int
    n_draws: int
    seed: int
    learning_rate: float
    gradient: str
    progress: bool


class _Found(NamedTuple):
    """What `_search` finds: the baseline's row, the random batch, the descents, the design, the share of its
    demand kept, the checks and the wall times (s)."""

    row: Any
    batch: dopt.RandomBatch
    descents: list
    x: np.ndarray
    scaled: float
    checks: dict
    wall: dict


def _search(problem, knowledge: Knowledge, space, settings: _Search, baseline: Callable) -> _Found:
    """The random batch, the search from its best, the check of the result and of the two baselines over the
    draws; beside them (its programs compile while the search runs) ``baseline(inputs, breaks)`` of the space's
    baseline, the table's row."""
    wall = {}
    lim = problem.limits
    drawn = dcon.draws(knowledge, settings.n_draws, settings.seed)
    base_inputs = space.baseline_inputs()
    base_breaks = input_breaks(base_inputs, space.config())
    with ThreadPoolExecutor(max_workers=1) as pool:
        published = pool.submit(
            lambda: (
                baseline(base_inputs, base_breaks),
                dcon.check(
                    dcon.stack([base_inputs]),
                    knowledge,
                    space.config(),
                    space.times,
                    base_breaks,
                    lim,
                    drawn,
                    keep_runs=True,
                ),
            )
        )
        batch, descents = _descend(problem, knowledge, space, settings, drawn, wall)
        t = time.perf_counter()
        ranked = _by_reported(problem, space, descents, batch, settings.starts)
        x, scaled, check = _admissible(problem, space, knowledge, ranked, drawn, lim)
        wall["check_s"] = time.perf_counter() - t
        checks = {"design": check, "best random input": _one(space, knowledge, batch.designs[batch.best], drawn, lim)}
        row, checks[space.baseline_label] = published.result()
    return _Found(row, batch, descents, x, scaled, checks, wall)


def _descend(problem, knowledge: Knowledge, space, settings: _Search, drawn, wall: dict):
    """(the random batch, the descents from its best): the optimiser's part of the search, its times in ``wall``."""
    s = settings
    prog.note(f"design: {s.random} random admissible inputs, each checked over {s.n_draws} draws", s.progress)
    batch = dopt.random_admissible(problem, space, knowledge, s.random, s.seed, drawn, progress=s.progress)
    wall["random_s"] = batch.wall_s
    t = time.perf_counter()
    order = batch.order()[: max(s.starts, 1)]
    if space.drive == "inverse":
        descents = dopt.local_search(problem, space, batch.designs[order], s.iterations, s.seed, progress=s.progress)
    else:
        descents = dopt.multistart(problem, batch.designs[order], s.iterations, s.learning_rate, s.gradient, s.progress)
    wall["descent_s"] = time.perf_counter() - t
    return batch, descents


def _by_reported(problem, space, descents, batch, starts: int) -> np.ndarray:
    """The descents' results and the best random inputs (S, K − 1), ordered by the criterion the table reports
    (the objective's, less the limits' penalty, which the check over the draws replaces): never a design the table
    ranks below the best random input."""
    xs = np.stack([d.x for d in descents] + [batch.designs[i] for i in batch.order()[: max(starts, 1)]])
    if isinstance(problem, ddis.Discrimination):
        return xs
    return xs[np.argsort(dprob.evaluate_many(problem, xs)[:, 0], kind="stable")]


def _covariances(problem, inputs, breaks, sets) -> list[dict]:
    """The predicted covariances (`growjax.design.problem.covariances`) of ``inputs``, one per sensor set."""
    info_l, info_p, cross = dprob.information(problem, inputs, breaks)[:3]
    return [dprob.covariances(problem, info_l, info_p, cross, sensors) for sensors in sets]


def _admissible(problem, space, knowledge, xs, drawn, lim):
    """(design, the share of its demand kept, its check): the first of ``xs`` (S, K − 1) that passes the check
    over the draws, else the first scaled down until it does."""
    check = dcon.check(
        dcon.stack([space.inputs(x) for x in xs]), knowledge, space.config(), space.times, space.breaks(), lim, drawn
    )
    for i in np.flatnonzero(check.admissible):
        return xs[i], 1.0, _one(space, knowledge, xs[i], drawn, lim)
    scaled = [space.scaled(xs[0], f) for f in SHRINK]
    check = dcon.check(
        dcon.stack([space.inputs(x) for x in scaled]),
        knowledge,
        space.config(),
        space.times,
        space.breaks(),
        lim,
        drawn,
    )
    for i in np.flatnonzero(check.admissible):
        return scaled[i], SHRINK[i], _one(space, knowledge, scaled[i], drawn, lim)
    raise DesignError(
        f"no admissible design: over the draws the best one reaches {check.peak_pressure[0] / 1e3:.1f} kPa "
        f"(ceiling {lim.pressure_ceiling / 1e3:.1f}) and {check.peak_length[0] * 1e3:.1f} mm "
        f"(ceiling {lim.length_ceiling * 1e3:.1f}); lower p_max or shorten the run"
    )


def _one(space, knowledge, x, drawn, lim):
    return dcon.check(
        dcon.stack([space.inputs(x)]),
        knowledge,
        space.config(),
        space.times,
        space.breaks(),
        lim,
        drawn,
        keep_runs=True,
    )


def _row(problem, knowledge: Knowledge, label: str, inputs, breaks, sets) -> list[dict]:
    """The table's rows of one input, one per sensor set of ``sets``."""
    p = len(knowledge.names)
    theta = knowledge.estimate
    rows = []
    for sensors, covs in zip(sets, _covariances(problem, inputs, breaks, sets)):
        sd, sd_alone, sd_linear = (
            np.sqrt(np.clip(np.diag(covs[k])[:p], 0, None)) for k in ("known", "alone", "known_local")
        )
        cov = covs["known"]
        params = {}
        for i, n in enumerate(knowledge.names):
            lo, hi = theta[i] * np.exp(-Z90 * sd[i]), theta[i] * np.exp(Z90 * sd[i])
            params[n] = {
                "estimate": float(theta[i]),
                "sd_log": float(sd[i]),
                "sd_log_alone": float(sd_alone[i]),
                "sd_log_local": float(sd_linear[i]),
                "interval_90": [float(lo), float(hi)],
                "width_90": float(hi - lo),
            }
        crit = float(problem.criterion_of(jax.numpy.asarray(cov)))
        rows.append({"input": label, "sensors": list(sensors), "criterion": crit, "parameters": params})
    return rows
