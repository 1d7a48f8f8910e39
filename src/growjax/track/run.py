"""A whole record tracked: the filter stepped over every sample (causal), optionally smoothed (the whole record),
and the quantities read from the beliefs with their bands.

The filter starts at rest at the configuration's start t0 (or at the first sample, if that is earlier), as a
simulation does, and steps to each sample in turn, reading the chosen sensors' columns (NaN where a sample is
missing). The inputs it knows are those of the experiment (`growjax.data.experiment.to_inputs`: the
catheter's length, the pressure demand or the published pulse, the stepper's demand); an estimated input
replaces its known one.
"""

from __future__ import annotations

import time

import jax
import numpy as np

import growjax.track.smoother as smoother
from growjax.data.experiment import Experiment, informative_samples, to_inputs
from growjax.track.belief import Belief, Step
from growjax.track.filter import Filter, compiled
from growjax.track.model import StateSpace
from growjax.track.result import TrackResult, quantities, report
from growjax.track.sensors import measurements


def start_time(model: StateSpace, times) -> float:
    """When the filter starts at rest (s): the configuration's t0 (as a simulation does), or the first sample where
    that is earlier. A first sample at the start is read without a prediction before it."""
    return min(float(model.config.t0), float(np.asarray(times, float)[0]))


def read(experiment: Experiment, model: StateSpace) -> np.ndarray:
    """The readings (T, m) the filter takes from ``experiment``: the chosen sensors' columns, NaN where missing. With
    a discrepancy in the model, a length digitised at keyframes and interpolated between them is read at its
    keyframes only (`growjax.data.experiment.informative_samples`, as calibration reads it): its
    interpolated samples repeat them, and the discrepancy's correlation would count each many times."""
    readings = measurements(experiment, model.sensors)
    if model.discrepancy is not None:
        for j, s in enumerate(model.sensors):
            if s.output == "length":
                values = readings[:, j]
                finite = np.isfinite(values)
                keep = np.zeros(values.size, bool)
                keep[finite] = informative_samples(values[finite])
                readings[:, j] = np.where(keep, values, np.nan)
    return readings


def track(
    experiment: Experiment,
    model: StateSpace,
    *,
    method=None,
    smooth: bool = False,
    t_end: float | None = None,
    inputs=None,
) -> TrackResult:
    """Track ``experiment`` with ``model``'s sensors.

    Args:
        experiment: the record: the chosen sensors' columns and the inputs' (``catheter_length_m``, ...).
        model: the state-space model (`growjax.track.state_space`).
        method: the filter (default `growjax.track.ExtendedKalman`).
        smooth: the whole record's estimate (Rauch–Tung–Striebel), not the causal one.
        t_end: the last sample used, s (default: the record's end).
        inputs: the known inputs (``growjax.Inputs``); default from the experiment.

    Returns:
        `growjax.track.TrackResult`.

    Raises:
        ValueError: a chosen sensor's column missing, fewer than two samples.
        RuntimeError: the solver failed inside an interval (named by its time).
    """
    times, readings, t0, inputs, breaks = prepare(experiment, model, t_end, inputs)
    run = Filter(model, method)
    belief = run.start(t0)
    records, beliefs, seconds = [], [], np.zeros(times.size)
    for k, (t, y) in enumerate(zip(times, readings)):
        clock = time.perf_counter()
        belief, step = checked_step(run, belief, t, y, inputs, breaks, float(times[k - 1]) if k else t0)
        seconds[k] = time.perf_counter() - clock
        records.append(step)
        beliefs.append(belief)
    return assemble(model, run.method, times, beliefs, records, inputs, smooth=smooth, seconds=seconds)


def prepare(experiment: Experiment, model: StateSpace, t_end: float | None = None, inputs=None):
    """(sample times (T,) s, readings (T, m) SI, the start t0 s, the known inputs, their breaks) of a record to
    track: what `track` steps over.

    Raises:
        ValueError: a chosen sensor's column missing, fewer than two samples.
    """
    if t_end is not None:
        experiment = experiment.window(t_end)
    times = np.asarray(experiment.time, float)
    if times.size < 2:
        raise ValueError("a record to track needs at least two samples")
    readings = read(experiment, model)
    t0 = start_time(model, times)
    if inputs is None:
        inputs = to_inputs(experiment, model.config.drive, model.params, t0, float(times[-1]))
    return times, readings, t0, inputs, model.breaks(inputs, t0, float(times[-1]))


def checked_step(run: Filter, belief: Belief, t, y, inputs, breaks, previous: float) -> tuple[Belief, Step]:
    """``run.step`` to time ``t`` s, waited for.

    Raises:
        RuntimeError: the solver failed in the interval from ``previous`` s.
    """
    belief, step = jax.block_until_ready(run.step(belief, t, y, inputs, breaks))
    if int(step.status) != 0:
        raise RuntimeError(
            f"the solver failed between {previous:.3f} s and {float(t):.3f} s "
            f"(a step budget of {run.model.config.step_budget} per interval: raise config.max_steps)"
        )
    return belief, step


def assemble(model: StateSpace, method, times, beliefs, records, inputs, *, smooth: bool, seconds) -> TrackResult:
    """The `growjax.track.TrackResult` of the ``beliefs`` after each sample at ``times`` (T,) s and the
    steps' ``records`` (`growjax.track.Step`), smoothed where asked; ``seconds`` (T,) each step's wall time."""
    stack = lambda xs: np.stack([np.asarray(x) for x in xs])  # noqa: E731
    means, covs = stack([b.mean for b in beliefs]), stack([b.cov for b in beliefs])
    if smooth:
        pred_m = stack([s.predicted_mean for s in records[1:]] + [records[-1].predicted_mean])
        pred_p = stack([s.predicted_cov for s in records[1:]] + [records[-1].predicted_cov])
        cross = stack([s.cross for s in records[1:]] + [records[-1].cross])
        means, covs = (np.asarray(a) for a in smoother.smooth(means, covs, pred_m, pred_p, cross))
    return TrackResult(
        time=np.asarray(times, float),
        quantities=quantities(model),
        columns=report(model, *compiled(model, method).linearised(times, means, covs, inputs)),
        mean=means,
        cov=covs,
        state_names=model.state_names(),
        sensors=tuple(s.column for s in model.sensors),
        nis=stack([s.nis for s in records]),
        dof=stack([np.sum(s.observed) for s in records]),
        log_likelihood=float(sum(float(s.log_likelihood) for s in records)),
        method=method.name,
        smoothed=smooth,
        step_seconds=np.asarray(seconds, float),
    )


__all__ = ["assemble", "checked_step", "prepare", "read", "start_time", "track"]
