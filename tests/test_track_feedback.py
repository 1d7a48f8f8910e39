"""Output feedback: the length PID (growjax.control) acting on the filter's estimate (growjax.track), the pump's
sensors (pressure 0.5 kPa, syringe 5 µm) the only readings, on a rig the filter does not know (drawn from the
default tolerance budget). Small and on the fast configuration; the reference configuration over 10 rigs is the
change benchmark's (``benchmarks/track_change.py --feedback``)."""

import jax.numpy as jnp
import numpy as np
import pytest

import growjax as gj
from growjax import control as gc
from growjax import track as tk
from growjax.calibration import tolerance as tl

T = 1.5


@pytest.fixture(scope="module")
def loops():
    """(the loop on the estimate over 1.5 s, the filter's steps and the plant's ticks it compiled)."""
    target = gc.ramp_with_pauses(t_end=T, start=0.010, speed=4e-3, move=0.5, pause=0.25)
    nominal = gj.reference("forward")  # the tracking tests' model: one compiled filter
    draws = tl.rig_draws(1, nominal, tl.default_budget(nominal), seed=7)
    rig = gj.replace(nominal, **{k: float(v[0]) for k, v in draws.items()})
    pid = gc.LengthPID(jnp.asarray((7.7, 7.9, 4.5)), jnp.asarray([0.0, T + 0.1]), jnp.asarray([110e3, 110e3]))
    plant = gc.Plant.make(rig, gj.Config(t1=T))
    model = tk.state_space(nominal, sensors=tk.sensor_set("pressure,syringe"), estimate=("Y",))
    estimator = tk.Filter(model)
    before = estimator.traces(), gc.estimated.advance_tick._cached._cache_size()
    loop = gc.run_on_estimate(plant, pid, target, T, estimator, seed=3)
    after = estimator.traces(), gc.estimated.advance_tick._cached._cache_size()
    return loop, after[0] - before[0], after[1] - before[1]


def test_the_loop_compiles_its_tick_and_the_filters_step_once(loops):
    """Each tick's demand ramp is a new two-sample series whose step differs in its last bits: nothing of it may key
    a compiled program, or the loop compiles its tick and the filter's step again at every tick."""
    _, steps, ticks = loops
    assert steps <= 1 and ticks == 1


def test_the_length_loop_on_the_estimate_tracks_the_target(loops):
    r = loops[0].result
    assert not r.pressure_limit_crossed and r.status == 0
    assert r.rmse_m < 1e-3
    assert np.ptp(r.length) > 1e-3  # it grew: the target is followed, not held at the start
    assert r.command[0] == 0 and r.command[1] > 0  # the pump idle over the first tick, the PID acting from the second


def test_the_estimate_the_loop_acted_on_holds_the_true_length_in_its_band(loops):
    estimated = loops[0]
    error = estimated.estimate - estimated.result.length
    inside = np.abs(error) <= 1.6448536 * estimated.sd
    assert np.mean(inside) > 0.8 and np.sqrt(np.mean(error**2)) < 5e-4


def test_output_feedback_reads_only_the_pump():
    model = tk.state_space(sensors=tk.sensor_set("pressure,length"))
    target = gc.ramp_with_pauses(t_end=0.1)
    plant = gc.Plant.make(gj.reference("forward"), gj.Config(t1=0.1))
    with pytest.raises(ValueError, match="reads the pump's sensors"):
        gc.run_on_estimate(plant, gc.LengthPID(jnp.zeros(3), jnp.zeros(2), jnp.zeros(2)), target, 0.1, tk.Filter(model))
