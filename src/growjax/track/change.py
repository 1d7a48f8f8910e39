"""Change detection: the filter's innovations watched for a sudden change, which is flagged with its time and named
among the catalogue's effects by a quick likelihood comparison from the flag on.

The model a watch runs (`watch_model`) carries every candidate effect (a leak, a load on the tip, folding,
trapped air) in its parameters at 0 and its parameter in the state (a linear coordinate in units of the
candidate's scale, no random walk), conditioned on being absent: until a change, the filter is the model without
the effects, and every hypothesis below runs on the same compiled program.

* **Detection**: each sensor's innovation, normalised by its predicted sd (standard normal while the model holds),
  feeds a two-sided CUSUM g⁺ₖ = max(0, g⁺ₖ₋₁ + eₖ − κ), g⁻ₖ = max(0, g⁻ₖ₋₁ − eₖ − κ) (`Cusum`); a
  statistic above h flags a change, its onset estimated at the statistic's last zero.
* **Naming**: from the belief at the onset, a bank of filters, one per candidate (its parameter's variance opened
  to its scale²) and one with none, runs over the samples up to ``confirm`` s after the flag; of the candidates
  whose estimate stays in its parameter's physical range, the one whose readings' log-likelihood is highest names
  the change. The watch then carries on with that hypothesis's belief
  (the effect estimated from then on) and the statistics restart.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from growjax.data.experiment import Experiment
from growjax.model import effects as fx
from growjax.model import params as gp
from growjax.track.belief import Belief
from growjax.track.filter import Filter
from growjax.track.model import StateSpace
from growjax.track.noise import StateParameter
from growjax.track.result import TrackResult
from growjax.track.run import assemble, checked_step, prepare


@dataclasses.dataclass(frozen=True)
class Candidate:
    """An effect a sudden change may be: its ``name`` in reports, the catalogue ``effect`` (at 0: absent), the
    ``parameter`` that switches it on (qualified name) and that parameter's ``scale`` once on (its prior sd, in
    its unit)."""

    name: str
    effect: fx.Effect
    parameter: str
    scale: float

    def __post_init__(self):
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"the scale of the candidate {self.name!r} must be a positive number, got {self.scale}")


CANDIDATES = (
    Candidate("leak", fx.FluidLeak(), "fluid_leak.conductance", 3e-13),
    Candidate("tip load", fx.ActiveChannelForce(), "active_channel_force.force", 0.2),
    Candidate("fold", fx.RetractionFolding(), "retraction_folding.folding_fraction", 0.3),
    Candidate("trapped air", fx.TrappedAir(), "trapped_air.extra_fraction", 0.01),
)


@dataclasses.dataclass(frozen=True)
class Cusum:
    """The two-sided CUSUM on each sensor's normalised innovation.

    Attributes:
        drift: κ, in sd: the shift it is tuned to half of (a mean shift of 2κ sd is found fastest).
        threshold: h, in sd: higher, fewer false flags and later ones.
    """

    drift: float = 0.5
    threshold: float = 15.0

    def __post_init__(self):
        if not (self.drift >= 0 and self.threshold > 0):
            raise ValueError(f"the CUSUM needs drift >= 0 and threshold > 0, got {self.drift}, {self.threshold}")


@dataclasses.dataclass(frozen=True)
class Change:
    """A change flagged and named.

    Attributes:
        onset_s: when it began (the statistic's last zero before the flag), s.
        flagged_s: when the statistic crossed the threshold, s.
        named_s: when it was named (``confirm`` s after the flag, or the record's end), s.
        sensor: the column whose statistic crossed.
        effect: the candidate named (`Candidate.name`).
        parameter: its parameter.
        estimate: the parameter's estimate when named (its unit), and ``sd`` its sd.
        evidence: log-likelihood of the readings over the naming window under each hypothesis (nats; −∞ where
            the solver failed under it):
            {candidate name: value, "none": value}.
    """

    onset_s: float
    flagged_s: float
    named_s: float
    sensor: str
    effect: str
    parameter: str
    estimate: float
    sd: float
    evidence: dict

    def as_dict(self) -> dict:
        """The fields as plain values (JSON's: a hypothesis under which the solver failed has evidence None)."""
        out = dataclasses.asdict(self)
        out["evidence"] = {k: v if np.isfinite(v) else None for k, v in self.evidence.items()}
        return out


@dataclasses.dataclass(frozen=True)
class Watch:
    """A record watched: the ``track`` (`growjax.track.TrackResult`, the belief carried through the changes),
    the ``model`` it ran (`watch_model`: the state's layout), the CUSUM ``statistic`` (T,) (the largest of
    every sensor's two, in sd), the ``changes`` found and the flags ``dismissed``: those whose named effect was
    smaller than the watch's ``smallest`` share of its candidate's scale (`material`)."""

    track: TrackResult
    model: StateSpace
    statistic: np.ndarray
    changes: tuple[Change, ...]
    dismissed: tuple[Change, ...] = ()

    def flags(self) -> np.ndarray:
        """(T,) 1 at the samples where a change was flagged, else 0."""
        out = np.zeros(self.track.time.size, int)
        for c in self.changes:
            out[np.searchsorted(self.track.time, c.flagged_s)] = 1
        return out

    def summary(self) -> list[dict]:
        """The changes found, as plain values (`Change.as_dict`)."""
        return [c.as_dict() for c in self.changes]


def watch_model(model: StateSpace, candidates=CANDIDATES) -> StateSpace:
    """``model`` with every candidate effect in its parameters (at 0) and its parameter in the state.

    Raises:
        ValueError: a candidate's effect already present and on, or a candidate named twice.
    """
    names = [c.name for c in candidates]
    if len(set(names)) != len(names) or not candidates:
        raise ValueError(f"the candidates must be distinct and at least one, got {names}")
    present = {e.name: e for e in model.params.effects}
    for c in candidates:
        if c.effect.name in present and bool(present[c.effect.name].present()):
            raise ValueError(f"the candidate {c.name!r} is on in the model already ({c.effect.name})")
    params = gp.with_effects(model.params, *(c.effect for c in candidates))
    extra = tuple(StateParameter(gp.resolve_name(params, c.parameter), c.scale, 0.0, log=False) for c in candidates)
    return dataclasses.replace(model, params=params, parameters=extra + model.parameters)


def candidate_index(model: StateSpace, candidate: Candidate) -> int:
    """The index in the state of ``candidate``'s coordinate in a `watch_model` model."""
    names = [p.name for p in model.parameters]
    return model.model_size + names.index(gp.resolve_name(model.params, candidate.parameter))


def absent(belief: Belief, index) -> Belief:
    """``belief`` conditioned on the coordinates ``index`` being 0 (the effects absent)."""
    index = np.asarray(index)
    mean, cov = np.asarray(belief.mean), np.asarray(belief.cov)
    keep = np.setdiff1d(np.arange(mean.size), index)
    gain = cov[np.ix_(keep, index)] @ np.linalg.pinv(cov[np.ix_(index, index)])
    new_mean, new_cov = mean.copy(), np.zeros_like(cov)
    new_mean[keep] -= gain @ mean[index]
    new_mean[index] = 0.0
    new_cov[np.ix_(keep, keep)] = cov[np.ix_(keep, keep)] - gain @ cov[np.ix_(index, keep)]
    return Belief(belief.time, np.asarray(new_mean), 0.5 * (new_cov + new_cov.T))


def opened(belief: Belief, index: int) -> Belief:
    """``belief`` with the coordinate ``index`` given a unit variance (an effect that may have appeared)."""
    cov = np.array(belief.cov)
    cov[index, index] += 1.0
    return Belief(belief.time, belief.mean, cov)


def watch(
    experiment: Experiment,
    model: StateSpace,
    *,
    candidates=CANDIDATES,
    cusum: Cusum = Cusum(),
    confirm: float = 0.3,
    smallest: float = 0.1,
    method=None,
    t_end: float | None = None,
    inputs=None,
) -> Watch:
    """Track ``experiment`` with ``model`` and watch for a sudden change.

    Args:
        experiment: the record (the chosen sensors' columns and the inputs').
        model: the tracking model (`growjax.track.state_space`); the candidates join it (`watch_model`).
        candidates: the effects a change may be (`CANDIDATES`).
        cusum: the detector (`Cusum`).
        confirm: how long after a flag the naming reads on, s (≥ 0).
        smallest: the smallest change reported, as a share of its candidate's scale (≥ 0): a flag whose named
            effect is smaller (`material`) is dismissed (the model's own error over a long record, not a change);
            the filter carries on as after a change.
        method: the filter (default extended Kalman).
        t_end: the last sample used, s.
        inputs: the known inputs (default from the experiment).

    Returns:
        `Watch`.

    Raises:
        ValueError: a bad ``confirm`` or ``smallest``, a candidate already on, a chosen sensor's column missing.
        RuntimeError: the solver failed inside an interval.
    """
    if not (np.isfinite(confirm) and confirm >= 0):
        raise ValueError(f"confirm must be a non-negative time (s), got {confirm}")
    if not (np.isfinite(smallest) and smallest >= 0):
        raise ValueError(f"smallest must be a non-negative share of a candidate's scale, got {smallest}")
    wmodel = watch_model(model, candidates)
    index = [candidate_index(wmodel, c) for c in candidates]
    times, readings, t0, inputs, breaks = prepare(experiment, wmodel, t_end, inputs)
    run = Filter(wmodel, method)
    belief = absent(run.start(t0), index)
    stats = Statistics(len(wmodel.sensors), cusum)
    beliefs, records, seconds, statistic = [], [], np.zeros(times.size), np.zeros(times.size)
    changes, dismissed = [], []
    by_name = {c.name: c for c in candidates}
    k = 0
    while k < times.size:
        clock = time.perf_counter()
        belief, step = checked_step(run, belief, times[k], readings[k], inputs, breaks, times[k - 1] if k else t0)
        seconds[k] = time.perf_counter() - clock
        beliefs.append(belief)
        records.append(step)
        statistic[k] = stats.add(np.asarray(step.innovation), np.asarray(step.innovation_cov), k)
        if statistic[k] > cusum.threshold:
            onset, channel = stats.onset()
            end = min(int(np.searchsorted(times, times[k] + confirm - 1e-9)), times.size - 1)
            run_args = (run, times, readings, inputs, breaks, onset, end)
            change, path = name_change(beliefs[onset], candidates, index, run_args)
            found = Change(times[onset], times[k], times[end], wmodel.sensors[channel].column, **change)
            (changes if material(found, by_name[found.effect], smallest) else dismissed).append(found)
            beliefs[onset + 1 :] = [b for b, _ in path]
            records[onset + 1 :] = [r for _, r in path]
            statistic[k + 1 : end + 1] = 0.0
            belief, k = beliefs[-1], end
            stats = Statistics(len(wmodel.sensors), cusum)
        k += 1
    result = assemble(wmodel, run.method, times, beliefs, records, inputs, smooth=False, seconds=seconds)
    return Watch(result, wmodel, statistic, tuple(changes), tuple(dismissed))


class Statistics:
    """The running two-sided CUSUMs of every sensor's normalised innovation and their last zeros."""

    def __init__(self, m: int, cusum: Cusum):
        self.cusum = cusum
        self.g = np.zeros((2, m))
        self.zero = np.full((2, m), -1)

    def add(self, innovation, innovation_cov, k: int) -> float:
        """Take step ``k``'s whitened innovation (m,) and its covariance (m, m); the largest statistic."""
        e = innovation / np.sqrt(np.diag(innovation_cov))
        self.g = np.maximum(0.0, self.g + np.stack([e, -e]) - self.cusum.drift)
        self.zero = np.where(self.g == 0.0, k, self.zero)
        return float(self.g.max())

    def onset(self) -> tuple[int, int]:
        """(the sample index of the largest statistic's last zero (its change's onset estimate), its sensor)."""
        side, channel = np.unravel_index(np.argmax(self.g), self.g.shape)
        return max(int(self.zero[side, channel]), 0), int(channel)


def name_change(start: Belief, candidates, index, run_args) -> tuple[dict, list]:
    """Run the bank from ``start`` (the belief at the onset) over the naming window; (the named candidate's fields
    of `Change`, its path [(belief, step)] over the window). A candidate whose estimate leaves its
    parameter's physical range (a leak that pumps in, a tip that pulls) is named only where every one does; one
    under which the solver fails is not named (its evidence −∞).

    Raises:
        RuntimeError: the solver failed under every candidate.
    """
    run, times, readings, inputs, breaks, onset, end = run_args
    evidence, paths = {}, {}
    for label, belief in [("none", start)] + [(c.name, opened(start, i)) for c, i in zip(candidates, index)]:
        path = []
        try:
            for j in range(onset + 1, end + 1):
                belief, step = checked_step(run, belief, times[j], readings[j], inputs, breaks, times[j - 1])
                path.append((belief, step))
        except RuntimeError:  # the solver failed under this hypothesis: it cannot explain the readings
            evidence[label], paths[label] = float("-inf"), None
            continue
        evidence[label] = float(sum(float(s.log_likelihood) for _, s in path))
        paths[label] = path
    ran = [k for k, c in enumerate(candidates) if paths[c.name] is not None]
    if not ran:
        raise RuntimeError(f"the solver failed under every candidate from {times[onset]:.3f} s to {times[end]:.3f} s")
    estimates = [
        float(paths[c.name][-1][0].mean[i]) * c.scale if paths[c.name] is not None else float("nan")
        for c, i in zip(candidates, index)
    ]
    physical = [in_range(c, v) for c, v in zip(candidates, estimates)]
    allowed = [k for k in ran if physical[k]] or ran
    best = max(allowed, key=lambda k: evidence[candidates[k].name])
    c, i = candidates[best], index[best]
    last = paths[c.name][-1][0]
    fields = dict(
        effect=c.name,
        parameter=c.parameter,
        estimate=estimates[best],
        sd=float(np.sqrt(last.cov[i, i])) * c.scale,
        evidence=evidence,
    )
    return fields, paths[c.name]


def material(change: Change, candidate: Candidate, smallest: float) -> bool:
    """Whether ``change``'s estimated effect is at least ``smallest`` times ``candidate``'s scale (its typical size)
    in size: a change worth reporting, not the model's own error read as a faint effect."""
    return bool(abs(change.estimate) >= smallest * candidate.scale)


def in_range(candidate: Candidate, value: float) -> bool:
    """Whether ``value`` lies in the physical range of ``candidate``'s parameter (its effect's ``ranges``; any
    finite value where it has none)."""
    low, high = candidate.effect.ranges.get(candidate.parameter.split(".")[-1], (-np.inf, np.inf))
    return bool(np.isfinite(value) and low <= value <= high)


__all__ = [
    "CANDIDATES",
    "Candidate",
    "Change",
    "Cusum",
    "Statistics",
    "Watch",
    "absent",
    "candidate_index",
    "in_range",
    "material",
    "name_change",
    "opened",
    "watch",
    "watch_model",
]
