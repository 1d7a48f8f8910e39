"""Targets of length control: desired lengths, the plant's parameters started on them, the stepper's length per step,
and the tracking error (SI units: m, Pa, s). The limits a design respects are the model's (`growjax.model.limits`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from jaxtyping import ArrayLike, Float

import growjax as gj

if TYPE_CHECKING:
    from growjax.data.experiment import Experiment

__all__ = [
    "Target",
    "plant_params",
    "ramp_with_pauses",
    "rmse",
    "step_length",
    "step_sequence",
    "target_from_experiment",
]


class Target(NamedTuple):
    """A desired length.

    Attributes:
        time: (T,) s.
        length: (T,) the desired length, m.
        catheter: (T,) the catheter length in contact, m (0 if unknown).
    """

    time: Float[np.ndarray, " T"]
    length: Float[np.ndarray, " T"]
    catheter: Float[np.ndarray, " T"]

    def at(self, t: Float[ArrayLike, "*t"]) -> Float[np.ndarray, "*t"]:
        """Desired length (m) at times ``t`` (s), held at the ends."""
        return np.interp(t, self.time, self.length)


def target_from_experiment(exp: Experiment, t_end: float = 10.0) -> Target:
    """The target of an experiment up to ``t_end`` (s): its ``desired_length_m`` column, else the measured
    ``robot_length_m``; ValueError where it has neither."""
    exp = exp.window(t_end + 1e-9)
    col = "desired_length_m" if "desired_length_m" in exp else "robot_length_m"
    if col not in exp:
        raise ValueError("the data need a desired_length_m or robot_length_m column to serve as the target")
    cath = exp["catheter_length_m"] if "catheter_length_m" in exp else np.zeros_like(exp.time)
    return Target(np.asarray(exp.time, float), np.asarray(exp[col], float), np.asarray(cath, float))


def ramp_with_pauses(
    t_end: float = 3.0,
    dt: float = 0.01,
    start: float = 0.010,
    speed: float = 5e-3,
    move: float = 0.5,
    pause: float = 0.5,
) -> Target:
    """A ramp at ``speed`` (m/s) for ``move`` s, then a pause of ``pause`` s, repeated; from ``start`` m, sampled
    every ``dt`` s over (0, ``t_end``] s."""
    t = np.arange(dt, t_end + 1e-9, dt)
    period = move + pause
    moving = np.minimum(np.mod(t, period), move) + move * np.floor(t / period)
    return Target(t, start + speed * moving, np.zeros_like(t))


def step_sequence(
    t_end: float = 3.0,
    dt: float = 0.01,
    start: float = 0.010,
    height: float = 2e-3,
    every: float = 1.0,
    rise: float = 0.3,
) -> Target:
    """Steps of ``height`` m every ``every`` s, each a ``rise`` s ramp (a physical robot cannot jump), from
    ``start`` m, sampled every ``dt`` s over (0, ``t_end``] s."""
    t = np.arange(dt, t_end + 1e-9, dt)
    k = np.floor(t / every)
    frac = np.clip((t - k * every) / rise, 0.0, 1.0)
    return Target(t, start + height * (k + frac), np.zeros_like(t))


def plant_params(drive: str, target: Target | None = None, base: gj.Parameters | None = None) -> gj.Parameters:
    """``base`` (default: the reference parameters of ``drive``) with the robot starting at the target's first
    length (m)."""
    p = base if base is not None else gj.reference(drive)
    if target is not None:
        p = gj.replace(p, initial_length=float(target.length[0]))
    return p


def step_length(params: gj.Parameters) -> float:
    """Robot length per full motor step, m: lead·(step angle/2π)·n A_s / A_r (3.1 mm for the published rig)."""
    pump, motor = params.pump, params.motor
    syringe = float(pump.lead) * float(motor.step_angle) / (2 * math.pi)
    return syringe * pump.n_syringes * float(pump.syringe_area) / float(params.robot.area)


def rmse(t: Float[ArrayLike, " T"], length: Float[ArrayLike, " T"], target: Target, t_start: float = 0.0) -> float:
    """RMS of (length − target) over the samples at t ≥ ``t_start``, m (NaN if a sample is not finite)."""
    t, length = np.asarray(t), np.asarray(length)
    keep = t >= t_start - 1e-12
    return float(np.sqrt(np.mean((length[keep] - target.at(t[keep])) ** 2)))
