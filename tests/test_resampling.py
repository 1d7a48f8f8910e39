"""A record's information does not depend on the rate it is stored at: each sensor's record is scored at the
samples that carry it, so a record interpolated to a higher rate gives the fit the same answer."""

from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

import growjax as gj
from growjax import calibration as cal
from growjax.data import experiment as ex
from growjax.data import sets as xs

SHIPPED = Path(str(files("growjax.data") / "datasets" / "synthetic_forward.csv"))
Y = "robot.yield_pressure"
T_END = 2.0  # s


def _resampled(exp, rate_hz: float) -> ex.Experiment:
    """The record linearly interpolated to ``rate_hz`` (what a logger resampling a 100 Hz record writes)."""
    t = exp.time[exp.time <= T_END]
    fine = np.arange(t[0], t[-1] + 0.5 / rate_hz, 1.0 / rate_hz)
    columns = {k: np.interp(fine, exp.time, exp[k]) for k in ("robot_length_m", "pressure_Pa", "catheter_length_m")}
    return ex.Experiment(fine, columns)


def _fit(exp):
    runs = xs.ExperimentSet.single(exp, sensors=("length", "pressure"))
    return cal.fit(runs, ["Y"], config=gj.Config(t1=T_END), starts=1, scout=0)


def test_length_and_pressure_resampled_from_100_hz_to_1_khz_give_the_same_interval():
    shipped = ex.read(SHIPPED)
    coarse = _resampled(shipped, 100.0)
    fine = _resampled(shipped, 1000.0)
    assert fine.time.size > 9 * coarse.time.size
    a, b = _fit(coarse), _fit(fine)
    assert a.status == b.status == "converged"
    (lo_a, hi_a), (lo_b, hi_b) = a.interval_90[Y], b.interval_90[Y]
    width = hi_a - lo_a
    assert abs(lo_b - lo_a) < 0.1 * width and abs(hi_b - hi_a) < 0.1 * width, (a.interval_90[Y], b.interval_90[Y])
    assert b.estimate[Y] == pytest.approx(a.estimate[Y], abs=0.1 * width)
