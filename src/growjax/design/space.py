"""The design space of the forward drive: a piecewise-linear pressure demand on fixed knots over the run.

A design is a vector x (K − 1,) of unconstrained numbers, one per knot after the first; the demand at knot k is
p_max·σ(x_k) (σ the logistic function), so every x is a demand inside (0, p_max) and the map is smooth for the
optimiser. The run starts at rest: the demand is 0 at t = 0 (the first knot), as in the shipped experiments (a
demand already high when the run starts sends the fast configuration through a start-up transient the
reference does not have). Between knots the demand is linear (:class:`growjax.control.KnotProfile`: every interior knot is a
declared slope break, so the solver's breaks do not depend on the values). The catheter is an input the rig
gives, not a design variable: its length is the one of the experiment already run (held after its end).
SI units: s, Pa, m.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from growjax import experiment as ex
from growjax.config import Config
from growjax.control.profile import KnotProfile
from growjax.signals import Constant, Inputs, Sampled
from growjax.simulate import input_breaks

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

    def __post_init__(self):
        if not np.isfinite(self.duration) or self.duration <= 0:
            raise ValueError(f"the duration must be a positive number of seconds, got {self.duration}")
        if not np.isfinite(self.p_max) or self.p_max <= 0:
            raise ValueError(f"p_max must be a positive pressure (Pa), got {self.p_max}")
        if not 0 < self.knot_spacing <= self.duration:
            raise ValueError(f"the knot spacing must lie in (0, duration = {self.duration} s], got {self.knot_spacing}")
        if not 0 < self.sample_interval <= self.duration:
            raise ValueError(f"the sample interval must lie in (0, duration = {self.duration} s], got {self.sample_interval}")

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
        n = int(np.floor(self.duration / self.sample_interval + 1e-9))
        return np.round(self.sample_interval * np.arange(1, n + 1), 12)

    def config(self, **changes) -> Config:
        """The fast configuration over the design's run, forward-mode derivatives (``changes``: other fields)."""
        return Config(t1=float(self.duration), adjoint="forward", **changes)

    def demand(self, x):
        """Demand at the knots (K,) Pa of a design x (K − 1,): 0 at the first (traceable)."""
        return demand_at_knots(x, self.p_max)

    def unconstrained(self, demand) -> np.ndarray:
        """The design x (K − 1,) whose demand at the knots after the first is ``demand`` (K,) Pa's (clipped a
        hair inside (0, p_max); the first knot's value is ignored: it is 0)."""
        u = np.clip(np.asarray(demand, float)[..., 1:] / self.p_max, _EDGE, 1.0 - _EDGE)
        return np.log(u) - np.log1p(-u)

    def inputs(self, x) -> Inputs:
        """The model's inputs under design x (K − 1,) (traceable)."""
        return Inputs(catheter_length=self.catheter, pressure_demand=KnotProfile(jnp.asarray(self.knots), self.demand(x)))

    def breaks(self):
        """The inputs' (jump, slope-break) times the solver steps onto: the same for every design."""
        return input_breaks(self.inputs(np.zeros(self.size)), self.config())

    def random(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """n random designs (n, K): each knot uniform on [0, c·p_max], c uniform on (0, 1] per design (so that
        low, moderate and high demands are all drawn)."""
        scale = rng.uniform(0.0, 1.0, (n, 1))
        scale = np.where(scale > 0, scale, 1.0)
        return self.unconstrained(self.p_max * scale * rng.uniform(0.0, 1.0, (n, self.size + 1)))

    def table(self, x) -> tuple[np.ndarray, dict]:
        """(time (T,) s, {column: (T,)}) of design x in the experiment CSV's columns: the demand and the catheter
        length every sample interval from 0 to the end."""
        n = int(np.floor(self.duration / self.sample_interval + 1e-9))
        t = np.round(self.sample_interval * np.arange(0, n + 1), 12)
        if t[-1] < self.duration - 1e-9:
            t = np.append(t, self.duration)
        demand = np.interp(t, self.knots, np.asarray(self.demand(x)))
        catheter = np.asarray(jax.vmap(self.catheter)(jnp.asarray(t)), float)
        return t, {"pressure_demand_Pa": demand, "catheter_length_m": catheter}

    def write_csv(self, path, x) -> Path:
        """Write design x as an experiment CSV (time_s, pressure_demand_Pa, catheter_length_m), which
        ``growjax simulate`` and ``growjax fit`` (once the length is measured) take."""
        t, series = self.table(x)
        ex.write_csv(path, t, series)
        return Path(path)


def demand_at_knots(x, p_max):
    """(K,) Pa: 0, then p_max·σ(x) for design x (K − 1,) (traceable)."""
    x = jnp.asarray(x)
    return jnp.concatenate([jnp.zeros(x.shape[:-1] + (1,)), p_max * jax.nn.sigmoid(x)], axis=-1)


def catheter_of(experiment: ex.Experiment | None, duration: float):
    """The catheter length (m) of an experiment already run, as a signal over [0, ``duration``] s: its samples,
    held at their last value after its end (a constant 0 where it had no catheter, or none is given)."""
    if experiment is None or "catheter_length_m" not in experiment:
        return Constant(0.0)
    t = np.asarray(experiment.time, float)
    c = np.asarray(experiment["catheter_length_m"], float)
    if t[-1] < duration:  # held after the record ends
        t, c = np.append(t, duration + 1.0), np.append(c, c[-1])
    return Sampled(jnp.asarray(t), jnp.asarray(c))
