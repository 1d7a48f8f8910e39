"""Inputs of the model as data: pulse trains, sampled series and step schedules.

Every signal is a pytree with a ``__call__(t)`` that is pure in ``t``, a
``jump_times(t0, t1)`` listing its discontinuities and a ``kink_times(t0, t1)`` listing
its significant slope breaks: the solvers step onto both, so no step straddles an edge.
Sampled series are interpolated linearly and extrapolated linearly from the two
end samples, as Simulink's From Workspace block does.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

__all__ = ["Constant", "Inputs", "KnotProfile", "PulseTrain", "Sampled", "StepSchedule", "published_pulse"]


class Constant(eqx.Module):
    """A constant signal."""

    value: float = 0.0

    def __call__(self, t: Float[ArrayLike, "*t"]) -> Float[Array, "*t"]:
        """The value at times ``t`` (s)."""
        return jnp.asarray(self.value, float) + 0.0 * t

    def jump_times(self, t0: float, t1: float) -> Float[np.ndarray, " J"]:
        """The signal's discontinuities in (t0, t1), s: none."""
        return np.zeros(0)

    def kink_times(self, t0: float, t1: float) -> Float[np.ndarray, " J"]:
        """The signal's slope breaks in (t0, t1), s: none."""
        return np.zeros(0)


class PulseTrain(eqx.Module):
    """Time-based pulse: ``amplitude`` for a fraction ``width`` of each ``period`` after ``delay``, else 0.

    Attributes:
        amplitude: the pulse's value (Pa for a pressure demand).
        period: s.
        width: the share of each period the pulse is on (–).
        delay: the first pulse's start, s.
    """

    amplitude: float = 150e3
    period: float = 1.3
    width: float = 0.9
    delay: float = 0.26

    def __call__(self, t: Float[ArrayLike, "*t"]) -> Float[Array, "*t"]:
        """The value at times ``t`` (s)."""
        phase = jnp.mod(t - self.delay, self.period)
        on = (t >= self.delay) & (phase < self.width * self.period)
        return jnp.where(on, self.amplitude, 0.0)

    def jump_times(self, t0: float, t1: float) -> Float[np.ndarray, " J"]:
        """The pulses' rising and falling edges in (t0, t1), s, sorted."""
        period, delay, width = float(self.period), float(self.delay), float(self.width)
        k = np.arange(max(int(np.ceil((t1 - delay) / period)), 0) + 1)
        rise = delay + k * period
        fall = rise + width * period
        edges = np.concatenate([rise, fall])
        return np.sort(edges[(edges > t0) & (edges < t1)])

    def kink_times(self, t0: float, t1: float) -> Float[np.ndarray, " J"]:
        """The signal's slope breaks in (t0, t1), s: none."""
        return np.zeros(0)


class Sampled(eqx.Module):
    """Piecewise-linear series through (``times``, ``values``) with linear extrapolation.

    On a uniform time grid (detected at construction) the segment is found by division,
    otherwise by binary search.

    Attributes:
        times: (N,) sample times, s, increasing.
        values: (N,) the samples.
        spacing: the uniform grid's step, s; None: not uniform (found by search), or two samples (one segment:
            nothing to find, and no value of the step, which rounding varies, to key a compiled program on).
    """

    times: jax.Array
    values: jax.Array
    spacing: float | None = eqx.field(static=True, default=None)

    def __init__(self, times: Float[ArrayLike, " N"], values: Float[ArrayLike, " N"], spacing: float | None = None):
        """A series through the samples.

        Args:
            times: (N,) sample times, s, increasing.
            values: (N,) the samples.
            spacing: the grid's step, s; None: detected (a uniform grid of three samples or more, to 1e-9
                relative), else searched.
        """
        self.times = jnp.asarray(times, float)
        self.values = jnp.asarray(values, float)
        if spacing is None and not isinstance(times, jax.core.Tracer):
            t = np.asarray(times, float)
            d = np.diff(t)
            if d.size > 1 and d[0] > 0 and np.allclose(d, d[0], rtol=1e-9, atol=0.0):
                spacing = float((t[-1] - t[0]) / (t.size - 1))
        self.spacing = spacing

    def __call__(self, t: Float[ArrayLike, "*t"]) -> Float[Array, "*t"]:
        """The interpolated value at times ``t`` (s)."""
        ts, vs = self.times, self.values
        n = ts.shape[-1]
        if self.spacing is not None:
            i = jnp.floor((t - ts[0]) / self.spacing).astype(int)
        else:
            i = jnp.searchsorted(ts, t, side="right") - 1
        i = jnp.clip(i, 0, n - 2)
        t_a, t_b = ts[i], ts[i + 1]
        w = (t - t_a) / (t_b - t_a)
        return vs[i] + w * (vs[i + 1] - vs[i])

    def jump_times(self, t0: float, t1: float) -> Float[np.ndarray, " J"]:
        """The signal's discontinuities in (t0, t1), s: none."""
        return np.zeros(0)

    def kink_times(self, t0: float, t1: float, threshold: float = 0.01) -> Float[np.ndarray, " J"]:
        """The samples in (t0, t1) where the slope changes by more than ``threshold`` of the series' range per sample
        step, s."""
        t, v = np.asarray(self.times, float), np.asarray(self.values, float)
        if t.size < 3:
            return np.zeros(0)
        slope = np.diff(v) / np.diff(t)
        change = np.abs(np.diff(slope)) * np.minimum(np.diff(t)[1:], np.diff(t)[:-1])
        span = float(np.ptp(v))
        keep = change > threshold * span if span > 0 else np.zeros(change.size, bool)
        times = t[1:-1][keep]
        return times[(times > t0) & (times < t1)]


class KnotProfile(Sampled):
    """A piecewise-linear profile through (``times`` (K,) s, ``values`` (K,)) whose every interior knot is a declared
    slope break, so the solvers' breaks depend on the knots alone, never on the values (which may be traced:
    optimised, or differentiated). Extrapolated linearly as `Sampled`."""

    def kink_times(self, t0: float, t1: float, threshold: float = 0.0) -> Float[np.ndarray, " J"]:
        """The interior knots in (t0, t1), s (``threshold`` is not used: every knot is a break)."""
        t = np.asarray(self.times, float)
        return t[(t > t0) & (t < t1)]


class StepSchedule(eqx.Module):
    """Integer step count of a stepper driver: ``counts[j]`` from ``times[j]`` on, 0 before the first edge.

    Attributes:
        times: (K,) the step edges, s, sorted.
        counts: (K,) the step count after each edge (integers, as float).
    """

    times: jnp.ndarray
    counts: jnp.ndarray

    def __call__(self, t: Float[ArrayLike, "*t"]) -> Float[Array, "*t"]:
        """The step count at times ``t`` (s)."""
        if self.times.shape[-1] == 0:
            return jnp.zeros_like(t)
        j = jnp.searchsorted(jnp.asarray(self.times), t, side="right") - 1
        return jnp.where(j >= 0, jnp.asarray(self.counts)[jnp.maximum(j, 0)], 0.0)

    def jump_times(self, t0: float, t1: float) -> Float[np.ndarray, " J"]:
        """The step edges in (t0, t1), s."""
        t = np.asarray(self.times)
        return t[(t > t0) & (t < t1)]

    def kink_times(self, t0: float, t1: float) -> Float[np.ndarray, " J"]:
        """The signal's slope breaks in (t0, t1), s: none."""
        return np.zeros(0)


def published_pulse() -> PulseTrain:
    """The shipped demand: 0/150 kPa, period 1.3 s, width 90 %, delay 0.26 s (a `PulseTrain`)."""
    return PulseTrain()


class Inputs(eqx.Module):
    """Everything that drives a simulation from outside.

    Attributes:
        catheter_length: L_c(t), m (catheter in contact with the robot).
        pressure_demand: P_ref(t), Pa (forward drive).
        steps: driver step count k(t) (inverse drive; from `growjax.model.motor.step_schedule`).
        desired_length: desired robot length, m (inverse drive; kept for plotting and metrics).
    """

    catheter_length: eqx.Module
    pressure_demand: eqx.Module = Constant(0.0)
    steps: eqx.Module = StepSchedule(np.zeros(0), np.zeros(0))
    desired_length: eqx.Module | None = None

    def jump_times(self, t0: float, t1: float) -> Float[np.ndarray, " J"]:
        """All input discontinuities in (t0, t1), s, sorted."""
        ts = np.concatenate(
            [
                self.pressure_demand.jump_times(t0, t1),
                self.steps.jump_times(t0, t1),
                self.catheter_length.jump_times(t0, t1),
            ]
        )
        return np.unique(ts)

    def kink_times(self, t0: float, t1: float) -> Float[np.ndarray, " K"]:
        """Significant slope breaks of the inputs in (t0, t1), s, sorted."""
        ts = np.concatenate([self.pressure_demand.kink_times(t0, t1), self.catheter_length.kink_times(t0, t1)])
        return np.unique(ts)
