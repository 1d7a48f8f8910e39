"""One design end to end: the random admissible batch, the search from its best (a descent for the forward drive's
demand, a local search over the stepper's schedule), the check of the result over every draw, and the table that
sets the design beside the baseline (the published pulse train; for the stepper, the recorded length as its
demand) and the best random input."""

from __future__ import annotations

import dataclasses
import time
from concurrent.futures import ThreadPoolExecutor

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
    sensors=("length",),
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

    ``criterion``: what the design minimises, a `growjax.design.Criterion` of the predicted covariance of the
    parameters of interest (None: `growjax.design.AOptimal`; any subclass serves).
    ``random`` random admissible inputs are drawn and scored (`growjax.design.optimise.random_admissible`);
    the optimiser descends from the ``starts`` best of them (``iterations`` Adam steps each; for a
    `growjax.design.StepperSpace`, ``iterations`` moves of `growjax.design.optimise.local_search`);
    the best result that passes the check over ``n_draws`` draws of the rig and θ (scaled down a little where it
    does not) is the design.
    ``points``: the points of (θ, rig) the criterion is averaged over (1: the local design at the estimate; the
    criterion's cost grows with each point);
    ``nonlinear_draws``: draws of the rig on which what its linearisation misses is measured (0: none);
    ``gradient``: the descent's slope, ``"differences"`` over a step of the demand or ``"jax"``, exact
    (`growjax.design.optimise.multistart`). The
    table reports the design, the best random input and the space's baseline under ``sensors`` and, where
    the pressure is recorded, under the length alone. DesignError where nothing admissible is found.
    """
    clock, wall = time.perf_counter(), {}
    sensors = tuple(sensors)
    problem = dprob.make(
        knowledge, space, criterion, sensors, pressure_noise, limits, points, seed, nonlinear_draws=nonlinear_draws
    )
    lim = problem.limits
    if space.drive == "forward":
        check_p_max(space.p_max, lim)
    sets = [sensors] if sensors == ("length",) else [("length",), sensors]
    rows, batch, descents, x, scaled, checks, wall = _search(
        problem,
        knowledge,
        space,
        random,
        starts,
        iterations,
        n_draws,
        seed,
        learning_rate,
        gradient,
        progress,
        lambda inputs, breaks: _row(problem, knowledge, space.baseline_label, inputs, breaks, sets),
    )
    best_random = batch.designs[batch.best]
    for label, inputs, breaks in (
        ("best random input", space.inputs(best_random), problem.breaks),
        ("design", space.inputs(x), problem.breaks),
    ):
        rows += _row(problem, knowledge, label, inputs, breaks, sets)
    wall["total_s"] = time.perf_counter() - clock
    knots = space.edges if space.drive == "inverse" else space.knots
    return DesignResult(
        tuple(knowledge.names),
        knowledge.estimate,
        space,
        x,
        knots,
        np.asarray(space.demand(x)),
        rows,
        checks,
        batch,
        descents,
        lim,
        problem.criterion.name,
        sensors,
        knowledge.summary(),
        wall,
        scaled,
    )


def discriminate(
    knowledge: Knowledge,
    space: DesignSpace,
    effects,
    sizes=None,
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
    """Design the next experiment's input to tell two rival catalogue ``effects`` (A, B) apart: the input that
    maximises min(T_AB, T_BA) (`growjax.design.discrimination`), with ``knowledge``'s parameters refitted
    beside the rival's effect; ``sizes`` (a, b) SI: the effects' assumed sizes (default their moderate
    magnitudes). The search, the limits and the check are those of `design` (the objective −ln min T).

    The table (``rows``): per input ("published pulse train", "best random input", "design") T_AB, T_BA, min T and
    whether min T exceeds the discovery's single-experiment threshold (``false_positive_rate`` over the
    catalogue, `growjax.calibration.likelihood_ratio.boundary_threshold`): expected to separate. ValueError on a
    bad pair of effects; DesignError where nothing admissible is found."""
    effects, sizes = ddis.checked_pair(effects, sizes, space.drive)
    clock = time.perf_counter()
    problem = ddis.make(knowledge, space, effects, sizes, limits)
    lim = problem.limits
    check_p_max(space.p_max, lim)
    threshold = boundary_threshold(false_positive_rate / len(fx.CATALOGUE))
    base_t, batch, descents, x, scaled, checks, wall = _search(
        problem,
        knowledge,
        space,
        random,
        starts,
        iterations,
        n_draws,
        seed,
        learning_rate,
        gradient,
        progress,
        lambda inputs, breaks: ddis.statistics(problem, inputs, breaks),
    )
    a, b = problem.effects
    rows = []
    for label, t in (
        ("published pulse train", base_t),
        ("best random input", ddis.statistics(problem, space.inputs(batch.designs[batch.best]), problem.breaks)),
        ("design", ddis.statistics(problem, space.inputs(x), problem.breaks)),
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
    wall["total_s"] = time.perf_counter() - clock
    sizes = np.diag(np.asarray(problem.sizes))
    record = {
        "effects": [a, b],
        "parameters": list(problem.fields),
        "sizes": [float(v) for v in sizes],
        "refitted": list(knowledge.names),
        "threshold": threshold,
        "false_positive_rate": false_positive_rate,
    }
    return DesignResult(
        (a, b),
        knowledge.estimate,
        space,
        x,
        space.knots,
        np.asarray(space.demand(x)),
        rows,
        checks,
        batch,
        descents,
        lim,
        "discrimination",
        ("length",),
        knowledge.summary(),
        wall,
        scaled,
        record,
    )


def _search(
    problem, knowledge, space, random, starts, iterations, n_draws, seed, learning_rate, gradient, progress, baseline
):
    """The random batch, the search from its best, the check of the result and of the two baselines over the
    draws; beside them (its programs compile while the search runs) ``baseline(inputs, breaks)`` of the space's
    baseline, the table's row: (that row, batch, descents, design, the share of its demand kept, checks, wall
    times)."""
    wall = {}
    lim = problem.limits
    drawn = dcon.draws(knowledge, n_draws, seed)
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
        prog.note(f"design: {random} random admissible inputs, each checked over {n_draws} draws", progress)
        batch = dopt.random_admissible(problem, space, knowledge, random, seed, drawn, progress=progress)
        wall["random_s"] = batch.wall_s
        t = time.perf_counter()
        order = batch.order()[: max(starts, 1)]
        if space.drive == "inverse":
            descents = dopt.local_search(problem, space, batch.designs[order], iterations, seed, progress=progress)
        else:
            descents = dopt.multistart(problem, batch.designs[order], iterations, learning_rate, gradient, progress)
        wall["descent_s"] = time.perf_counter() - t
        t = time.perf_counter()
        x, scaled, check = _admissible(
            problem, space, knowledge, _by_reported(problem, space, descents, batch, starts), drawn, lim
        )
        wall["check_s"] = time.perf_counter() - t
        checks = {"design": check, "best random input": _one(space, knowledge, batch.designs[batch.best], drawn, lim)}
        row, checks[space.baseline_label] = published.result()
    return row, batch, descents, x, scaled, checks, wall


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
