"""The fast configuration against the reference: the same robot, from the shipped reference-made traces and live runs."""

import sys

import jax
import numpy as np
import pytest
from conftest import REPO

import growjax as gj
from growjax.model import effects as fx

sys.path.insert(0, str(REPO / "data"))
import make_synthetic as mk

FAST = gj.Config(t1=10.0)


@pytest.fixture(scope="module")
def reference_traces():
    """Noise-free lengths made by the reference configuration (rtol 1e-7), growjax/data/datasets/reference_lengths.csv."""
    return mk.read_reference_lengths()


def _fast_length(case, times):
    params = mk.case_parameters(case["parameters"])
    traj = gj.simulate(params, mk.reference_inputs(case["demand"]), FAST, ts=np.concatenate([[FAST.t0], times]))
    assert int(traj.status) == gj.OK
    return np.asarray(traj.length)[1:]


# Every demand and both growth laws; the Latin-hypercube cases run in the benchmark (benchmarks/agreement.py).
CASES = [
    "published_Y6000",
    "published_Y10000",
    "published_Y14000",
    "sampled_Y6000",
    "sampled_Y10000",
    "pulse50_Y6000",
    "step_Y8000",
    "ramp_Y12000",
    "lockhart_published",
    "lockhart_sampled",
]


@pytest.mark.parametrize("name", CASES)
def test_fast_length_agrees_with_the_reference(reference_traces, name):
    """0–10 s: within 0.05 mm RMSE and 0.15 mm max of the reference, for inputs beyond the published pulse."""
    time, lengths, cases = reference_traces
    diff = _fast_length(cases[name], time) - lengths[name]
    assert np.sqrt(np.mean(diff**2)) < 0.05e-3
    assert np.max(np.abs(diff)) < 0.15e-3
    assert np.ptp(lengths[name]) > 5e-4  # the robot moved: the agreement is not about a robot at rest


@pytest.mark.slow
def test_effects_plug_into_both_configurations_and_they_agree():
    """A pull on the rod, a leak from the chamber and a lag with a state of its own, from one definition each."""
    effects = (fx.ActiveChannelForce(force=0.05), fx.FluidLeak(conductance=5e-14), fx.ActuationLag(time_constant=0.05))
    params = gj.with_effects(gj.replace(gj.reference(), Y=7000.0), *effects)
    inputs = mk.reference_inputs("sampled")
    short = gj.Config(t1=2.5)
    ts = short.save_grid()
    fast = gj.simulate(params, inputs, short, ts=ts)
    ref = gj.simulate(params, inputs, short.replace(fidelity="reference", rtol=1e-7), ts=ts)
    base = gj.simulate(gj.replace(gj.reference(), Y=7000.0), inputs, short, ts=ts)
    assert int(fast.status) == gj.OK and int(ref.status) == gj.OK
    diff = np.asarray(fast.length - ref.length)
    effect = np.asarray(fast.length - base.length)
    assert np.max(np.abs(effect)) > 1e-3  # the effects move the robot by millimetres
    assert np.sqrt(np.mean(diff**2)) < 0.05e-3 and np.max(np.abs(diff)) < 0.15e-3
    # With every effect at zero the extended model is the base model: the lag's extra state changes only the
    # adaptive step sequence, i.e. the length at the solver's tolerance (measured 0.25 µm).
    zero = gj.with_effects(gj.replace(gj.reference(), Y=7000.0), *(type(e)() for e in effects))
    np.testing.assert_allclose(
        np.asarray(gj.simulate(zero, inputs, short, ts=ts).length), np.asarray(base.length), rtol=0, atol=2e-6
    )


@pytest.mark.slow
def test_effect_parameters_are_differentiable_leaves():
    inputs = mk.reference_inputs("published")
    cfg = gj.Config(t1=1.5, adjoint="forward")
    breaks = gj.input_breaks(inputs, cfg)

    def final_length(force):
        params = gj.with_effects(gj.reference(), fx.ActiveChannelForce(force=force))
        return gj.simulate(params, inputs, cfg, breaks=breaks).length[-1]

    grad = float(jax.jacfwd(final_length)(0.05))
    fd = (float(final_length(0.06)) - float(final_length(0.04))) / 0.02
    assert grad < 0  # a pull shortens the robot
    assert grad == pytest.approx(fd, rel=2e-2)
