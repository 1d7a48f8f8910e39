"""Output feedback: the length PID run on an estimate of the length, the plant's pump sensors (pressure, syringe
displacement) the only readings, with their noise.

Any estimator that follows `LengthEstimator` serves (``growjax.track.Filter`` does: the calibrated model as
a filter). Each tick the plant is advanced under the demand the PID chose, its sensors are read with seeded
Gaussian noise, the estimator takes the readings, and the PID acts on the target less the estimated length.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple, Protocol

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from growjax.control.controllers import ClosedLoopResult, LengthPID, score
from growjax.control.plant import Plant, catheter_signal, segment_inputs
from growjax.control.targets import Target
from growjax.model.limits import Limits, limits

PUMP_NOISE = {"pressure_Pa": 500.0, "syringe_displacement_m": 5e-6}  # the rig's sensors' noise sd, SI
PLANT_READINGS = {"pressure_Pa": 1, "syringe_displacement_m": 2}  # column → index in a plant's outputs


class LengthEstimator(Protocol):
    """What output feedback needs of an estimator.

    Attributes:
        columns: the readings it takes, in order (``pressure_Pa``, ``syringe_displacement_m``).
    """

    columns: tuple[str, ...]

    def start(self, time: float) -> Any:
        """Its belief at rest at ``time`` s."""

    def update(self, belief: Any, time: float, readings, inputs) -> tuple[Any, float, float]:
        """(the belief at ``time`` s given ``readings`` (m,) SI there, under ``inputs`` since the belief's time; the
        length's estimate m; its sd m)."""


class EstimatedLoop(NamedTuple):
    """An output-feedback run: the closed loop's ``result`` (the true length scored), the ``estimate`` (T,) m the
    PID acted on and its ``sd`` (T,) m, and each tick's estimator ``step_s`` (T,) s."""

    result: ClosedLoopResult
    estimate: np.ndarray
    sd: np.ndarray
    step_s: np.ndarray


@eqx.filter_jit
def advance_tick(plant: Plant, y, inputs, ta, tb):
    """``plant.advance`` over one tick [ta, tb] s, read at tb (one compiled program per plant)."""
    return plant.advance(y, inputs, ta, tb, tb[None])


def run_on_estimate(
    plant: Plant,
    pid: LengthPID,
    target: Target,
    t1: float,
    estimator: LengthEstimator,
    *,
    noise: dict | None = None,
    seed: int = 0,
    lim: Limits | None = None,
) -> EstimatedLoop:
    """The length PID around ``plant`` from rest over [0, t1] s, acting on ``estimator``'s length.

    The pump is held idle (demand 0) over the first tick while the robot settles from its initial state, and the
    PID acts from the second: the fast configuration, which an estimator built on it runs, follows a demand that
    rises within the robot's first milliseconds about 0.5 mm off the reference configuration, an offset the
    pump's sensors do not show (``benchmarks/start_transient.py``); after the first tick the two agree.

    Args:
        plant: the plant (e.g. the reference configuration on a drawn rig).
        pid: the length PID (its feed-forward and gains; tick ``pid.dt``).
        target: the desired length.
        t1: the run's end, s.
        estimator: the length estimator (`LengthEstimator`).
        noise: {column: sd SI} of the readings (default `PUMP_NOISE`).
        seed: seed of the readings' noise.
        lim: the limits (default those of the plant's parameters).

    Returns:
        `EstimatedLoop`.

    Raises:
        ValueError: the estimator reads a column the plant does not give (only pressure and syringe), a noise
            missing.
    """
    noise = PUMP_NOISE if noise is None else noise
    for column in estimator.columns:
        if column not in PLANT_READINGS:
            raise ValueError(f"output feedback reads the pump's sensors ({sorted(PLANT_READINGS)}), not {column}")
        if column not in noise:
            raise ValueError(f"no noise given for the reading {column}")
    lim = lim or limits(plant.params)
    rng = np.random.default_rng(seed)
    cath = catheter_signal(target)
    dt, n = pid.dt, round(t1 / pid.dt)
    y = plant.initial_state()
    u_prev = 0.0  # the pump idle at the start
    belief = estimator.start(0.0)
    estimate, e_prev, c = float(target.at(0.0)), 0.0, pid.init()
    rows = np.zeros((n, 7))  # t, length, pressure, demand, estimate, sd, step s
    status = 0
    for k in range(n):
        ta, tb = jnp.asarray(k * dt), jnp.asarray((k + 1) * dt)
        e = float(target.at(k * dt)) - estimate
        c = c.at[1].set(0.7 * c[1] + 0.3 * (e - e_prev) / dt)
        u, c = pid(c, k * dt, e, lim)
        u = float(u) if k > 0 else 0.0  # idle over the first tick (see above)
        inputs = segment_inputs(cath, ta, tb, u_prev, u, 0.0)
        y, outputs, st = advance_tick(plant, y, inputs, ta, tb)
        status = max(status, int(st))
        truth = [float(o[0]) for o in outputs]
        readings = [truth[PLANT_READINGS[col]] + noise[col] * rng.standard_normal() for col in estimator.columns]
        clock = time.perf_counter()
        belief, estimate, sd = estimator.update(belief, float(tb), np.asarray(readings), inputs)
        rows[k] = (float(tb), truth[0], truth[1], u, estimate, sd, time.perf_counter() - clock)
        u_prev, e_prev = u, e
    ts = rows[:, 0]
    result = score(ts, rows[:, 1], rows[:, 2], rows[:, 3], ts - dt, target, lim, status)
    return EstimatedLoop(result, rows[:, 4], rows[:, 5], rows[:, 6])


__all__ = ["PLANT_READINGS", "advance_tick", "PUMP_NOISE", "EstimatedLoop", "LengthEstimator", "run_on_estimate"]
