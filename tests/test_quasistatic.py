"""The quasi-static reduction against the reference model, and its own physics."""

import jax
import numpy as np
import pytest
from conftest import SHORT
from scipy.integrate import quad

import growjax as gj
from growjax import experiment as ex
from growjax import quasistatic as qs
from growjax.fluid import bulk_modulus
from growjax.metrics import length_rmse

QS_SHORT = gj.QuasiStaticConfig(t1=3.0)


@pytest.fixture(scope="module")
def synthetic_inputs(synthetic_experiment):
    return ex.to_inputs(synthetic_experiment, "forward", gj.reference())


@pytest.mark.parametrize("yield_pressure, tolerance_mm", [
    (5e3, 0.15), (7920.46, 0.25),
    pytest.param(15e3, 0.6, marks=pytest.mark.slow),  # the box's far corner; CI keeps the two nearer ones
])
def test_quasistatic_length_agrees_with_the_reference(synthetic_experiment, synthetic_inputs, yield_pressure, tolerance_mm):
    params = gj.replace(gj.reference(), Y=yield_pressure)
    fast = gj.simulate(params, synthetic_inputs, QS_SHORT)
    ref = gj.simulate(params, synthetic_inputs, SHORT, ts=QS_SHORT.save_grid())
    assert int(fast.status) == gj.OK and int(ref.status) == gj.OK
    # The reference drains the robot into the lines over the first ~20 ms; the reduction does it at once.
    late = np.asarray(fast.time) > 0.05
    diff_mm = 1e3 * np.abs(np.asarray(fast.length - ref.length))[late]
    assert diff_mm.max() < tolerance_mm
    exp = synthetic_experiment
    rmse = [float(length_rmse(t, exp.time, exp["robot_length_m"], 0.001, 3.0)) for t in (fast, ref)]
    assert abs(rmse[0] - rmse[1]) < 0.15e-3


def test_quasistatic_volume_balance_converges_with_the_step(synthetic_inputs):
    rigid = gj.replace(gj.reference(), **{"tube.diameter_compliance": 0.0})
    defects = []
    for substeps in (10, 40):
        cfg = gj.QuasiStaticConfig(t1=1.0, substeps=substeps)
        traj = gj.simulate(rigid, synthetic_inputs, cfg)
        p, x_p, _, _, _, xi = np.asarray(traj.final_state) * np.asarray(qs.SCALES)
        delivered = rigid.pump.n_syringes * rigid.pump.syringe_area * x_p
        volume = float(qs._chamber_volume(rigid, 0.0))
        p0 = float(qs.initial_state(gj.replace(rigid, Y=0.0), synthetic_inputs, cfg)[0]) * qs.SCALES[0]
        stored = quad(lambda q, v=volume: v / float(bulk_modulus(rigid.fluid, q)), p0, p, limit=200)[0]
        defects.append(abs(delivered - rigid.robot.area * xi - stored) / delivered)
    # The step over each pulse rise is where volume is lost; it shrinks at least as h².
    assert defects[0] < 0.1
    assert defects[1] < defects[0] / 16


def test_quasistatic_gradient_matches_central_difference(synthetic_inputs):
    cfg = gj.QuasiStaticConfig(t1=1.5)

    def length_at_end(y):
        return gj.simulate(gj.replace(gj.reference(), Y=y), synthetic_inputs, cfg).length[-1]

    grad = float(jax.grad(length_at_end)(8000.0))
    fd = (float(length_at_end(8010.0)) - float(length_at_end(7990.0))) / 20.0
    assert grad < 0
    assert grad == pytest.approx(fd, rel=1e-4)


def test_quasistatic_flags_the_pressure_limit(synthetic_inputs):
    thin = gj.replace(gj.reference(), t=1e-5)  # limit 107 kPa < the 150 kPa demand
    traj = gj.simulate(thin, synthetic_inputs, QS_SHORT)
    assert int(traj.status) == gj.PRESSURE_LIMIT
    assert 0.26 < float(traj.limit_time) < 0.5
    assert np.all(np.isnan(np.asarray(traj.length)[np.asarray(traj.time) > float(traj.limit_time)]))


def test_quasistatic_rejects_a_save_grid():
    with pytest.raises(ValueError, match="save_grid"):
        gj.simulate(gj.reference(), gj.Inputs(catheter_length=gj.Constant(0.0)), QS_SHORT, ts=np.linspace(0, 1, 5))
