"""The design spaces: the forward drive's pressure demand (`DesignSpace`, made by `demand_space`) and the
stepper's step schedule (`StepperSpace`, made by `stepper_space`).

The forward drive's demand is a piecewise-linear profile on fixed knots over the run.

A design is a vector x (K − 1,) of unconstrained numbers, one per knot after the first; the demand at knot k is
p_max·σ(x_k) (σ the logistic function), so every x is a demand inside (0, p_max) and the map is smooth for the
optimiser. The run starts at rest: the demand is 0 at t = 0 (the first knot), as in the shipped experiments (a
demand already high when the run starts sends the fast configuration through a start-up transient the
reference does not have). Between knots the demand is linear (`growjax.model.signals.KnotProfile`: every
interior knot is a declared slope break, so the solver's breaks do not depend on the values). The catheter is
an input the rig gives, not a design variable: its length is the one of the experiment already run (held after
its end).

The stepper's input is discrete. Its position controller samples the desired length every 1/f s and issues at
most one step per period, half a period later (`growjax.model.motor.step_schedule`), so every schedule it can
issue is a choice of −1, 0 or +1 step at each of the same edge times. A design is that vector of choices; the
schedule's count is its running sum, never below 0 (the robot starts at rest). All schedules share their edges,
hence the solver's breaks and one compiled program; the criterion is piecewise constant in them, so the search
is over the choices themselves (`growjax.design.optimise.local_search`), not along a gradient.
SI units: s, Pa, m.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from growjax.data import experiment as ex
from growjax.model.limits import Limits
from growjax.model.motor import step_schedule
from growjax.model.params import Parameters
from growjax.model.signals import Constant, Inputs, KnotProfile, Sampled, StepSchedule, published_pulse
from growjax.simulation.config import Config
from growjax.simulation.simulate import Breaks, input_breaks

__all__ = [
    "KNOT_SPACING",
    "SAMPLE_INTERVAL",
    "DesignSpace",
    "StepperSpace",
    "catheter_of",
    "demand_space",
    "demand_at_knots",
    "held",
    "sample_times",
    "stepper_inputs",
    "stepper_space",
]

KNOT_SPACING = 0.5  # s between the demand's knots
SAMPLE_INTERVAL = 0.01  # s between the sensors' samples (100 Hz, as the shipped experiments)
_EDGE = 1e-6  # share of p_max kept from the open interval's ends when a demand is mapped back to x


@dataclasses.dataclass(frozen=True)
class DesignSpace:
    """The forward drive's demand over ``duration`` s: knots every ``knot_spacing`` s from 0 to the end, values in
    (0, ``p_max``) Pa; the catheter length ``catheter`` (a signal, m); the sensors sampled every
    ``sample_interval`` s from the first interval to the end."""

    duration: float
    p_max: float
    catheter: object
    knot_spacing: float = KNOT_SPACING
    sample_interval: float = SAMPLE_INTERVAL

    drive = "forward"
    baseline_label = "published pulse train"

    def __post_init__(self) -> None:
        if not np.isfinite(self.duration) or self.duration <= 0:
            raise ValueError(f"the duration must be a positive number of seconds, got {self.duration}")
        if not np.isfinite(self.p_max) or self.p_max <= 0:
            raise ValueError(f"p_max must be a positive pressure (Pa), got {self.p_max}")
        if not 0 < self.knot_spacing <= self.duration:
            raise ValueError(f"the knot spacing must lie in (0, duration = {self.duration} s], got {self.knot_spacing}")
        if not 0 < self.sample_interval <= self.duration:
            raise ValueError(
                f"the sample interval must lie in (0, duration = {self.duration} s], got {self.sample_interval}"
            )

    @property
    def knots(self) -> np.ndarray:
        """(K,) s: 0, the spacing, …, the duration (the last interval shortened to end there)."""
        k = np.arange(0.0, self.duration - 1e-9, self.knot_spacing)
        return np.append(k, self.duration)

    @property
    def size(self) -> int:
        """K − 1, the number of design variables (the knots after the first)."""
        return int(self.knots.size) - 1

    @property
    def times(self) -> np.ndarray:
        """(n,) s: the sensors' sample times."""
        return sample_times(self.duration, self.sample_interval)

    def config(self, **changes: Any) -> Config:
        """The fast configuration over the design's run, forward-mode derivatives (``changes``: other fields)."""
        return Config(t1=float(self.duration), adjoint="forward", **changes)

    def demand(self, x: Float[ArrayLike, "*S k"]) -> Float[Array, "*S K"]:
        """Demand at the knots (K,) Pa of a design x (K − 1,): 0 at the first (traceable)."""
        return demand_at_knots(x, self.p_max)

    def unconstrained(self, demand: Float[ArrayLike, "*S K"]) -> Float[np.ndarray, "*S k"]:
        """The design x (K − 1,) whose demand at the knots after the first is ``demand`` (K,) Pa's (clipped a
        hair inside (0, p_max); the first knot's value is ignored: it is 0)."""
        u = np.clip(np.asarray(demand, float)[..., 1:] / self.p_max, _EDGE, 1.0 - _EDGE)
        return np.log(u) - np.log1p(-u)

    def inputs(self, x: Float[ArrayLike, " k"]) -> Inputs:
        """The model's inputs under design x (K − 1,) (traceable)."""
        return Inputs(
            catheter_length=self.catheter, pressure_demand=KnotProfile(jnp.asarray(self.knots), self.demand(x))
        )

    def breaks(self) -> Breaks:
        """The inputs' (jump, slope-break) times the solver steps onto: the same for every design."""
        return input_breaks(self.inputs(np.zeros(self.size)), self.config())

    def random(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """n random designs (n, K): each knot uniform on [0, c·p_max], c uniform on (0, 1] per design (so that
        low, moderate and high demands are all drawn)."""
        scale = rng.uniform(0.0, 1.0, (n, 1))
        scale = np.where(scale > 0, scale, 1.0)
        return self.unconstrained(self.p_max * scale * rng.uniform(0.0, 1.0, (n, self.size + 1)))

    def table(self, x: Float[ArrayLike, " k"]) -> tuple[Float[np.ndarray, " T"], dict[str, Float[np.ndarray, " T"]]]:
        """(time (T,) s, {column: (T,)}) of design x in the experiment CSV's columns: the demand and the catheter
        length every sample interval from 0 to the end."""
        n = int(np.floor(self.duration / self.sample_interval + 1e-9))
        t = np.round(self.sample_interval * np.arange(0, n + 1), 12)
        if t[-1] < self.duration - 1e-9:
            t = np.append(t, self.duration)
        demand = np.interp(t, self.knots, np.asarray(self.demand(x)))
        catheter = np.asarray(jax.vmap(self.catheter)(jnp.asarray(t)), float)
        return t, {"pressure_demand_Pa": demand, "catheter_length_m": catheter}

    def write_csv(self, path: str | Path, x: Float[ArrayLike, " k"]) -> Path:
        """Write design x as an experiment CSV (time_s, pressure_demand_Pa, catheter_length_m), which
        ``growjax simulate`` and ``growjax fit`` (once the length is measured) take."""
        t, series = self.table(x)
        ex.write_csv(path, t, series)
        return Path(path)

    def baseline_inputs(self) -> Inputs:
        """The baseline: the published pulse train with the design's catheter."""
        return Inputs(catheter_length=self.catheter, pressure_demand=published_pulse())

    def scaled(self, x: Float[ArrayLike, " k"], share: float) -> Float[np.ndarray, " k"]:
        """Design x with its demand scaled by ``share`` (a design that fails its check, turned down)."""
        return self.unconstrained(share * np.asarray(self.demand(x)))

    def command(self, x: Float[ArrayLike, " k"], t: Float[ArrayLike, " T"]) -> Float[np.ndarray, " T"]:
        """The demand (Pa) of design x at times ``t`` (T,) s, for figures."""
        return np.interp(t, self.knots, np.asarray(self.demand(x)))

    def baseline_command(self, t: Float[ArrayLike, " T"]) -> Float[np.ndarray, " T"]:
        """The baseline's demand (Pa) at times ``t`` (T,) s, for figures."""
        return np.asarray(jax.vmap(self.baseline_inputs().pressure_demand)(jnp.asarray(t)))

    def describe(self, x: Float[ArrayLike, " k"]) -> dict[str, list[float]]:
        """Design x in the summary's terms."""
        return {"knots_s": self.knots.tolist(), "demand_Pa": np.asarray(self.demand(x)).tolist()}

    def settings(self) -> dict[str, Any]:
        """The space's settings, JSON-ready (SI, units in the keys)."""
        return {
            "drive": self.drive,
            "duration_s": self.duration,
            "knot_spacing_s": self.knot_spacing,
            "p_max_Pa": self.p_max,
            "sample_interval_s": self.sample_interval,
        }


def demand_at_knots(x: Float[ArrayLike, "*S k"], p_max: Float[ArrayLike, ""]) -> Float[Array, "*S K"]:
    """(K,) Pa: 0, then p_max·σ(x) for design x (K − 1,) (traceable)."""
    x = jnp.asarray(x)
    return jnp.concatenate([jnp.zeros(x.shape[:-1] + (1,)), p_max * jax.nn.sigmoid(x)], axis=-1)


def sample_times(duration: float, interval: float) -> np.ndarray:
    """(n,) s: every ``interval`` s from the first interval to ``duration``."""
    n = int(np.floor(duration / interval + 1e-9))
    return np.round(interval * np.arange(1, n + 1), 12)


def held(experiment: ex.Experiment, column: str, duration: float) -> Sampled:
    """An experiment's ``column`` as a signal over [0, ``duration``] s: its samples, held at their last value after
    the record ends."""
    t = np.asarray(experiment.time, float)
    v = np.asarray(experiment[column], float)
    if t[-1] < duration:
        t, v = np.append(t, duration + 1.0), np.append(v, v[-1])
    return Sampled(jnp.asarray(t), jnp.asarray(v))


def catheter_of(experiment: ex.Experiment | None, duration: float) -> Sampled | Constant:
    """The catheter length (m) of an experiment already run, as a signal over [0, ``duration``] s: its samples,
    held at their last value after its end (a constant 0 where it had no catheter, or none is given)."""
    if experiment is None or "catheter_length_m" not in experiment:
        return Constant(0.0)
    return held(experiment, "catheter_length_m", duration)


def stepper_inputs(catheter: Sampled | Constant, edges: Float[ArrayLike, " N"], x: Float[ArrayLike, " N"]) -> Inputs:
    """The stepper's inputs under design x (N,): the count after each edge (N,) s its running sum (traceable)."""
    return Inputs(catheter_length=catheter, steps=StepSchedule(jnp.asarray(edges), jnp.cumsum(jnp.asarray(x), axis=-1)))


@dataclasses.dataclass(frozen=True)
class StepperSpace:
    """The stepper (inverse) drive's schedule over ``duration`` s: at each of the position controller's edges
    (`edges`, every 1/``rate`` s) −1, 0 or +1 step, each step ``metres_per_step`` m of commanded robot length
    (`growjax.data.experiment.demand_steps`); the catheter length ``catheter`` (a signal, m); the baseline
    ``recorded`` (a desired length, m, as a signal: the length the experiment already run recorded, which is what the
    shipped stepper model is driven by); the sensors sampled every ``sample_interval`` s. Build it with
    `stepper_space`."""

    duration: float
    metres_per_step: float
    rate: float
    catheter: object
    recorded: object = None
    t0: float = 0.001
    sample_interval: float = SAMPLE_INTERVAL

    drive = "inverse"
    baseline_label = "recorded length as demand"

    def __post_init__(self) -> None:
        for name in ("duration", "metres_per_step", "rate"):
            v = getattr(self, name)
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"the stepper space's {name} must be positive, got {v}")
        if self.edges.size == 0:
            raise ValueError(f"a {self.duration} s run holds no edge of the {self.rate} Hz step controller")

    @functools.cached_property
    def edges(self) -> np.ndarray:
        """(N,) s: the times at which the controller can issue a step (those inside the run)."""
        ramp = np.array([0.0, self.duration + 1.0])
        t, _ = step_schedule(2.0 * self.rate * ramp + 2.0, ramp, self.rate, self.t0, self.duration)
        return t

    @property
    def size(self) -> int:
        """N, the number of design variables (one per edge)."""
        return int(self.edges.size)

    @property
    def times(self) -> np.ndarray:
        """(n,) s: the sensors' sample times."""
        return sample_times(self.duration, self.sample_interval)

    def config(self, **changes: Any) -> Config:
        """The fast configuration of the stepper drive over the run, forward-mode derivatives."""
        return Config(drive="inverse", t1=float(self.duration), adjoint="forward", **changes)

    def counts(self, x: Float[ArrayLike, "*S N"]) -> Float[Array, "*S N"]:
        """(N,) the driver's step count after each edge of design x (N,) (traceable)."""
        return jnp.cumsum(jnp.asarray(x), axis=-1)

    def demand(self, x: Float[ArrayLike, "*S N"]) -> Float[Array, "*S N"]:
        """(N,) m: the commanded length after each edge of design x."""
        return self.metres_per_step * self.counts(x)

    def inputs(self, x: Float[ArrayLike, " N"]) -> Inputs:
        """The model's inputs under design x (N,) (traceable)."""
        return stepper_inputs(self.catheter, self.edges, x)

    def breaks(self) -> Breaks:
        """The inputs' jump times (every edge) the solver steps onto: the same for every design."""
        return input_breaks(self.inputs(np.zeros(self.size)), self.config())

    def admissible_counts(self, x: Float[ArrayLike, " N"]) -> Float[np.ndarray, " N"]:
        """Design x with every step that would take the count below 0 dropped."""
        x = np.asarray(np.rint(x), float).copy()
        c = 0.0
        for k, e in enumerate(x):
            if c + e < 0:
                x[k] = 0.0
            c += x[k]
        return x

    def random(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """n random schedules (n, N): per schedule a share a ~ U(0, 1) of edges stepping forward and
        r ~ U(0, ½)(1 − a) stepping back (so slow, fast and retracting schedules are all drawn), the count kept ≥ 0."""
        a = rng.uniform(0.0, 1.0, (n, 1))
        r = rng.uniform(0.0, 0.5, (n, 1)) * (1.0 - a)
        u = rng.uniform(0.0, 1.0, (n, self.size))
        x = np.where(u < a, 1.0, np.where(u < a + r, -1.0, 0.0))
        return np.stack([self.admissible_counts(row) for row in x])

    def from_length(self, desired: Sampled) -> Float[np.ndarray, " N"]:
        """The design (N,) the shipped position controller issues for a desired length ``desired`` (a signal, m)."""
        grid = np.arange(0.0, self.duration + 1.0 / self.rate, 0.25 / self.rate)
        d = np.asarray(jax.vmap(desired)(jnp.asarray(grid)), float) / self.metres_per_step
        t, counts = step_schedule(d, grid, self.rate, self.t0, self.duration)
        x = np.zeros(self.size)
        idx = np.searchsorted(self.edges, t - 1e-9)
        x[idx] = np.diff(np.concatenate([[0.0], counts]))
        return x

    def baseline(self) -> np.ndarray:
        """The baseline design: the recorded length as the desired length (0 steps where none is given)."""
        return np.zeros(self.size) if self.recorded is None else self.from_length(self.recorded)

    def baseline_inputs(self) -> Inputs:
        """The inputs of the `baseline` design."""
        return self.inputs(self.baseline())

    def scaled(self, x: Float[ArrayLike, " k"], share: float) -> Float[np.ndarray, " k"]:
        """Design x with its count scaled by ``share`` ≤ 1 (rounded down): still at most one step per edge."""
        counts = np.floor(share * np.asarray(self.counts(x), float) + 1e-9)
        return np.diff(np.concatenate([[0.0], counts]))

    def command(self, x: Float[ArrayLike, " k"], t: Float[ArrayLike, " T"]) -> Float[np.ndarray, " T"]:
        """The commanded length (m) of design x at times ``t`` (T,) s (held between edges), for figures."""
        c = np.asarray(self.demand(x), float)
        j = np.searchsorted(self.edges, np.asarray(t), side="right") - 1
        return np.where(j >= 0, c[np.maximum(j, 0)], 0.0)

    def baseline_command(self, t: Float[ArrayLike, " T"]) -> Float[np.ndarray, " T"]:
        """The baseline's commanded length (m) at times ``t`` (T,) s, for figures."""
        return self.command(self.baseline(), t)

    def table(self, x: Float[ArrayLike, " k"]) -> tuple[Float[np.ndarray, " T"], dict[str, Float[np.ndarray, " T"]]]:
        """(time (T,) s, {column: (T,)}) of design x in the experiment CSV's columns: the desired length the shipped
        controller turns back into exactly this schedule (the count after each edge, reached at the controller's
        sample before it, linear between samples) and the catheter length, every sample interval and at each of
        the controller's samples."""
        n = int(np.floor(self.duration / self.sample_interval + 1e-9))
        grid = np.round(self.sample_interval * np.arange(0, n + 1), 12)
        samples = np.round(self.edges - 0.5 / self.rate, 12)  # the controller's samples (the first at t0)
        t = np.unique(np.concatenate([grid, samples, [self.duration]]))
        counts = np.asarray(self.counts(x), float)
        desired = self.metres_per_step * np.interp(t, samples, counts)
        catheter = np.asarray(jax.vmap(self.catheter)(jnp.asarray(t)), float)
        return t, {"desired_length_m": desired, "catheter_length_m": catheter}

    def write_csv(self, path: str | Path, x: Float[ArrayLike, " k"]) -> Path:
        """Write design x as an experiment CSV (time_s, desired_length_m, catheter_length_m), which ``growjax
        simulate --drive inverse`` and ``growjax fit --drive inverse`` (once the length is measured) take."""
        t, series = self.table(x)
        ex.write_csv(path, t, series)
        return Path(path)

    def describe(self, x: Float[ArrayLike, " N"]) -> dict[str, list[float]]:
        """Design x in the summary's terms."""
        return {
            "edges_s": self.edges.tolist(),
            "steps": np.asarray(x, float).tolist(),
            "commanded_length_m": np.asarray(self.demand(x)).tolist(),
        }

    def settings(self) -> dict[str, Any]:
        """The space's settings, JSON-ready (SI, units in the keys)."""
        return {
            "drive": self.drive,
            "duration_s": self.duration,
            "controller_rate_Hz": self.rate,
            "metres_per_step": self.metres_per_step,
            "sample_interval_s": self.sample_interval,
        }


def stepper_space(base: Parameters, duration: float, experiment: ex.Experiment | None = None) -> StepperSpace:
    """The `StepperSpace` of the stepper drive's parameters ``base`` over ``duration`` s, with the catheter
    and the baseline (its recorded length as the desired length) of an experiment already run, if given."""
    recorded = None
    if experiment is not None and "robot_length_m" in experiment:
        recorded = held(experiment, "robot_length_m", duration)
    per_metre = float(ex.demand_steps(base, 1.0))
    return StepperSpace(
        float(duration),
        1.0 / per_metre,
        float(base.motor.controller_rate),
        catheter_of(experiment, duration),
        recorded,
        t0=Config().t0,
    )


def check_p_max(p_max: float, limits: Limits) -> None:
    """Refuse a demand whose top ``p_max`` (Pa) is above the sensed-pressure ceiling of ``limits``.

    Raises:
        ValueError: naming both pressures, kPa.
    """
    if p_max > limits.pressure_ceiling + 1e-9:
        raise ValueError(
            f"--p-max {p_max / 1e3:.1f} kPa is above the sensed-pressure ceiling "
            f"{limits.pressure_ceiling / 1e3:.1f} kPa "
            f"(the membrane limit {limits.membrane_limit / 1e3:.1f} kPa × the margin)"
        )


def demand_space(
    duration: float,
    limits: Limits,
    experiment: ex.Experiment | None = None,
    *,
    p_max: float | None = None,
    knot_spacing: float | None = None,
) -> DesignSpace:
    """The forward drive's `DesignSpace` over ``duration`` s, inside ``limits``.

    Args:
        duration: length of the run, s.
        limits: the limits the design respects (`growjax.model.limits.limits`).
        experiment: an experiment already run: its catheter length, held after its end (none: 0).
        p_max: top of the demand, Pa; None: the sensed-pressure ceiling of ``limits``.
        knot_spacing: s between the demand's knots; None: `KNOT_SPACING`.

    Returns:
        The space.

    Raises:
        ValueError: ``p_max`` above the sensed-pressure ceiling (`check_p_max`), or a bad duration or knot spacing.
    """
    p_max = limits.pressure_ceiling if p_max is None else p_max
    check_p_max(p_max, limits)
    spacing = KNOT_SPACING if knot_spacing is None else knot_spacing
    return DesignSpace(duration, p_max, catheter_of(experiment, duration), spacing)
