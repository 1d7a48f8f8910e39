"""The fit: gradient fits of the measured length (and pressure) of one experiment or a set of them through the
differentiable model.

One code path for any number of runs. A free parameter has one value for all the runs, or one per robot, rig or
run (its `growjax.data.sets.Scope`); each run's length is its model plus its own smooth discrepancy plus sensor
noise (hyperparameters per run), and the rig's relative errors b (one vector per rig, or per run) enter every run
on that rig. The free parameters move in z = ln(θ/θ_ref), or linearly for a parameter whose range allows negative
values (`growjax.calibration.problem`). Levenberg–Marquardt (`growjax.calibration.least_squares`, forward-mode
Jacobian, the runs batched: `growjax.calibration.batch`) starts from the best points of one Latin-hypercube scout
(`growjax.calibration.starts`); least squares from every start, then generalised least squares under the residual
model (`growjax.calibration.solve`). The intervals are Gauss–Newton's under that model, plus the spread over each
run's hyperparameters, the configuration's own error and the rig's tolerances, reported term by term
(`growjax.calibration.covariance`); the directions the information leaves open have no interval.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from growjax.calibration.batch import Batch
from growjax.calibration.covariance import set_covariance, set_log_likelihood, set_spread
from growjax.calibration.layout import Layout, make_layout
from growjax.calibration.likelihood import Likelihood
from growjax.calibration.problem import check_window, make_problem
from growjax.calibration.result import FitResult, intervals, slopes
from growjax.calibration.scoring import RunScore
from growjax.calibration.solve import RELINEARISE_STEPS, Solution, from_starts, solve_secants, solve_tangents
from growjax.calibration.starts import sampling_box, scout_starts
from growjax.data import experiment as ex
from growjax.data.sets import ExperimentSet, Scope
from growjax.model import params as gp
from growjax.simulation.config import Config


def fit(
    experiments: ExperimentSet,
    free: Sequence[str | Scope] = ("Y",),
    *,
    likelihood: Likelihood = Likelihood(),
    config: Config | None = None,
    effects: Sequence = (),
    starts: int = 3,
    scout: int = 64,
    seed: int = 0,
    max_steps: int = 100,
    rig_tangents: bool = True,
    relinearise: bool = True,
) -> FitResult:
    """Fit the ``free`` parameters to every run of ``experiments`` at once.

    Args:
        experiments: the runs (one experiment is a set of one: `growjax.data.sets.ExperimentSet.single`); each
            scores its length (and pressure, with that sensor) inside its window.
        free: ``NAME`` (one value for all runs) or ``NAME@robot|rig|experiment`` (one per robot, rig or run), or
            `growjax.data.sets.Scope` s.
        likelihood: the likelihood's options (`growjax.calibration.Likelihood`): the discrepancy, the noise
            scales, the configuration's own error, the rig's tolerances and how they enter (``rig``: inferred
            beside θ, or fixed and propagated; ``rig_errors``: shared per rig or one per run).
        config: the simulation's settings (its drive is taken from each run).
        effects: `growjax.Effect` instances added to every run's parameters at their given values (an effect's
            parameter can then be freed by name, e.g. ``fluid_leak.conductance@robot``, and starts there).
        starts: least-squares fits from the best points of the scout.
        scout: points of the Latin-hypercube scout over each free parameter's
            `growjax.calibration.starts.default_range` (every copy at the same value), ranked by the length RMSE
            over all runs; 0: one start, at the runs' own values.
        seed, max_steps: the scout's seed; Levenberg–Marquardt's accepted steps per fit.
        rig_tangents: with the rig inferred, its errors are parameters of every run's model beside θ, their
            sensitivities the solver's exact tangents: least squares of z with the rig nominal, then of (z, b)
            with b's prior rows (a misfit is then the model's to remove, not the discrepancy's to absorb), then
            generalised least squares of (z, b). False: the rig's secants, taken apart from the solve.
        relinearise: with the secants, take them again where the data put the rig until it settles (at most
            `growjax.calibration.solve.RELINEARISE_STEPS` linearisations); False: once, at nominal (cheaper;
            over-confident where the rig is off by a tolerance or more).

    Returns:
        The `growjax.calibration.FitResult`: each coordinate's estimate, 90 % interval, standard error and budget
        by source, the runs, the rig's fitted errors, and ``parameters(run)``.

    Raises:
        ValueError: a bad option, scope, window or parameter, naming it.
        RuntimeError: no start of the scout simulated.
    """
    if not isinstance(likelihood, Likelihood):
        raise ValueError(f"likelihood must be a growjax.calibration.Likelihood, got {type(likelihood).__name__}")
    clock = time.perf_counter()
    config = (config if config is not None else Config()).replace(adjoint="forward")  # Jacobians by jvp
    runs = list(experiments)
    bases = [gp.with_effects(r.base(), *effects) if effects else r.base() for r in runs]
    scopes = [s if isinstance(s, Scope) else Scope.parse(s, bases[0]) for s in free]
    names = tuple(s.name for s in scopes)
    if len(set(names)) != len(names):
        raise ValueError(f"a parameter is freed twice: {list(free)}")
    tol = likelihood.budget(bases[0], names)
    tangents = rig_tangents and likelihood.rig == "inferred" and bool(tol)
    problems = _problems(runs, bases, names + tuple(tol) if tangents else names, config, likelihood)
    scores = [_score(pr, likelihood) for pr in problems]
    layout = make_layout(experiments, scopes, bases, problems, tol, likelihood.rig_errors)
    batch = Batch(problems, rig_in_model=tangents)
    bounds = layout.bounds(bases[0])
    values, order = scout_starts(batch, layout, bases[0], starts, scout, seed)
    zs, costs, oks = from_starts(batch, layout, scores, layout.coordinates_of(values[order]), bounds, max_steps)
    z = np.asarray(zs[int(np.argmin(costs))])
    if tangents:
        box = sampling_box(bases[0], layout.names, layout.refs, layout.scales)
        solution = solve_tangents(batch, layout, scores, tol, z, bounds, likelihood.discrepancy, max_steps, box)
    else:
        options = (likelihood.rig, likelihood.discrepancy, max_steps, RELINEARISE_STEPS if relinearise else 1)
        solution = solve_secants(batch, problems, layout, scores, tol, z, bounds, options)
    result = _result(solution, layout, likelihood, likelihood.model_error_for(config), tol, bounds)
    _describe(result, solution, layout, runs, bases)
    result.starts = _start_records(layout, values, order, (zs, costs, oks))
    result.wall_s = time.perf_counter() - clock
    return result


def _start_records(layout: Layout, values, order, solved) -> list:
    """[{"start", "estimate", "cost", "converged"}] of the least squares from each start: ``values`` (K, P) SI the
    points scouted, ``order`` the starts among them, ``solved`` = (z, cost, converged) per start."""
    zs, costs, oks = solved
    return [
        {
            "start": dict(zip(layout.labels, map(float, values[i]))),
            "estimate": dict(zip(layout.labels, map(float, layout.values(zs[k])))),
            "cost": float(costs[k]),
            "converged": bool(oks[k]),
        }
        for k, i in enumerate(order)
    ]


def _problems(runs, bases, modelled, config: Config, likelihood: Likelihood) -> list:
    """Each run's `growjax.calibration.problem.Problem` in the parameters ``modelled``.

    Raises:
        ValueError: a window outside the simulated span, or fewer than two samples inside it.
    """
    problems = []
    for run, base in zip(runs, bases):
        cfg = config.replace(drive=run.drive)
        window = check_window(run.window, cfg)
        inputs = run.model_inputs(base, cfg.t0, cfg.t1)
        pr = make_problem(
            base,
            modelled,
            inputs,
            cfg,
            run.times,
            run.length,
            run.pressure,
            window,
            likelihood.sigma_length,
            likelihood.sigma_pressure,
            thin_pressure=likelihood.discrepancy != "none",
        )
        if pr.times.size < 2:
            raise ValueError(f"experiment {run.name!r}: fewer than two samples inside the window")
        problems.append(pr)
    return problems


def _score(problem, likelihood: Likelihood) -> RunScore:
    """A run's score: every sample, or with a discrepancy the informative ones (a record interpolated between
    keyframes is scored at its keyframes: `growjax.data.experiment.informative_samples`)."""
    n = int(problem.times.size)
    used = ex.informative_samples(np.asarray(problem.length)) if likelihood.discrepancy != "none" else np.ones(n, bool)
    return RunScore.of(problem.times, used, likelihood.sigma_length)


def _result(solution: Solution, layout: Layout, likelihood: Likelihood, model_error: float, tol, bounds) -> FitResult:
    """The result at the solution: the covariance with its budget (the hyperparameters' spread added with a
    discrepancy), the intervals, the rig's fitted errors."""
    s = solution
    rig = likelihood.rig if tol else "none"
    b_rel = s.b - s.centre
    cov, parts, info, joint, gain = set_covariance(
        s.outs, s.scores, layout, s.hypers, b_rel, model_error, rig, s.centre
    )
    if likelihood.discrepancy != "none":  # the hyperparameters are estimated, not known: average over them
        spread = set_spread(s.outs, s.scores, layout, s.hypers, b_rel, cov, s.centre)
        parts["hyperparameters"], cov = spread, cov + spread
    theta = layout.values(s.z)
    slope = slopes(layout.coordinates, theta)
    interval, se, undetermined = intervals(layout.coordinates, theta, cov, info)
    labels = layout.labels
    lo, hi = bounds
    result = FitResult(
        labels,
        dict(zip(labels, map(float, theta))),
        interval,
        se,
        cov,
        budget={
            k: {src: float(slope[i] * np.sqrt(max(part[i, i], 0.0))) for src, part in parts.items()}
            for i, k in enumerate(labels)
        },
        coordinates=layout.coordinates,
        information=info,
        undetermined=undetermined,
        rig=rig,
        rig_errors=likelihood.rig_errors,
        tolerances=dict(tol),
        cost=float(s.cost),
        status="converged" if s.converged else "max_steps",
        simulate_s=s.batch.simulate_s,
        programs=len(s.batch.groups),
        linearisations=s.linearisations,
        rig_last_move=s.rig_last_move,
        log_likelihood=set_log_likelihood(s.outs, s.scores, layout, s.hypers, s.centre, rig),
        likelihood=likelihood,
        model_error_m=model_error,
        at_bound=tuple(k for k, zi, a, b in zip(labels, s.z, lo, hi) if min(zi - a, b - zi) < 1e-9),
        tolerance_gain=_gains(layout, slope, gain),
    )
    if rig == "inferred":
        result.rig_labels, result.rig_vector, result.joint_covariance = layout.rig_labels, np.asarray(s.b), joint
        for j, (key, name) in enumerate(layout.rig_labels):
            result.rig_offset.setdefault(key, {})[name] = float(s.b[j])
    return result


def _describe(result: FitResult, solution: Solution, layout: Layout, runs, bases) -> None:
    """Add to ``result`` the runs' records and residuals, the pooled length RMSE and samples, the runs' median
    hyperparameters, the rig's fitted values and what ``parameters(run)`` needs."""
    residuals = _length_residuals(solution, layout)
    result.runs = _run_records(solution, residuals, runs)
    result.residuals = [(np.asarray(s.times), r) for s, r in zip(solution.scores, residuals)]
    result.rmse_length_m = float(np.sqrt(np.mean(np.concatenate(residuals) ** 2)))
    result.samples_used = int(sum(r["samples_used"] for r in result.runs))
    hypers = [r["discrepancy"] for r in result.runs]
    median = {k: float(np.median([h[k] for h in hypers])) for k in hypers[0]}
    result.discrepancy = {"kind": result.likelihood.discrepancy, **median}
    result.bases, result.run_keys = tuple(bases), tuple((r.name, r.robot, r.rig) for r in runs)
    keys = [r.rig if result.rig_errors == "shared" else r.name for r in runs]
    for key, offsets in result.rig_offset.items():
        base = bases[keys.index(key)]
        result.rig_estimate[key] = {t: float(gp.get(base, t)) * float(np.exp(b)) for t, b in offsets.items()}


def _gains(layout: Layout, slope, gain) -> dict:
    """{label: {rig key: {tolerance: dθ/d ln ψ}}} from the gain (P, Q) on the coordinates."""
    out: dict = {}
    for i, label in enumerate(layout.labels):
        for j, (key, name) in enumerate(layout.rig_labels):
            out.setdefault(label, {}).setdefault(key, {})[name] = float(slope[i] * gain[i, j])
    return out


def _length_residuals(solution: Solution, layout: Layout) -> list:
    """Per run its length residual (n,) m with the rig at its fitted errors."""
    out = []
    for e, ((r, _), score) in enumerate(zip(solution.outs, solution.scores)):
        r_len = np.asarray(r)[: score.n_len] * score.sigma_length
        if score.inferred:
            r_len = r_len + np.asarray(score.sensitivity) @ (solution.b - solution.centre)[layout.rig_index[e]]
        out.append(r_len)
    return out


def _run_records(solution: Solution, residuals, runs) -> list:
    """Per run: name, robot, rig, drive, length RMSE (m), its hyperparameters, the samples scored."""
    return [
        {
            "name": run.name,
            "robot": run.robot,
            "rig": run.rig,
            "drive": run.drive,
            "rmse_length_m": float(np.sqrt(np.mean(r_len**2))),
            "discrepancy": hyper.as_dict(),
            "samples_used": int(np.sum(np.asarray(score.used))),
        }
        for run, r_len, hyper, score in zip(runs, residuals, solution.hypers, solution.scores)
    ]


__all__ = ["fit"]
