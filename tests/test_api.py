"""The public API: shape/dtype annotations (jaxtyping) on the entry points, configuration checks, and
``jax.grad`` through :func:`growjax.simulation.simulate` in every configuration."""

import typing

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import growjax as gj
from growjax import calibration as cal
from growjax import control as gc
from growjax import posterior as gpost
from growjax.calibration import discrepancy as dc
from growjax.simulation.simulate import simulate_from

ANNOTATED = [
    gj.simulate,
    gj.simulate_members,
    gj.input_breaks,
    simulate_from,
    gj.Inputs.jump_times,
    gj.Inputs.kink_times,
    gc.optimize_profile,
    gc.run_closed_loop,
    gc.Plant.advance,
    cal.fit,
    gpost.sample,
    gpost.forecast,
    dc.log_likelihood,
    dc.whiten,
]
RECORDS = [
    gj.Trajectory,
    gc.Target,
    gc.ProfileResult,
    gc.ClosedLoopResult,
    gc.LengthPID,
    cal.FitResult,
    gpost.PosteriorResult,
]


def _shaped(hint) -> bool:
    """Does a resolved annotation carry a jaxtyping shape (Float[...], Int[...]), itself or in the fields of the
    record it names?"""
    text = repr(hint)
    if "jaxtyping" in text or "Float[" in text or "Int[" in text:
        return True
    return isinstance(hint, type) and hint in RECORDS and any(map(_shaped, typing.get_type_hints(hint).values()))


@pytest.mark.parametrize("fn", ANNOTATED, ids=lambda f: f.__qualname__)
def test_entry_points_resolve_their_annotations_and_carry_shapes(fn):
    hints = typing.get_type_hints(fn)
    assert "return" in hints or fn in (gj.Inputs.jump_times, dc.log_likelihood, dc.whiten)
    assert any(_shaped(h) for h in hints.values()), hints


@pytest.mark.parametrize("cls", RECORDS, ids=lambda c: c.__qualname__)
def test_records_annotate_their_arrays_with_shapes(cls):
    hints = typing.get_type_hints(cls)
    assert sum(_shaped(h) for h in hints.values()) >= 1, hints


def test_config_refuses_fields_of_the_other_fidelity():
    with pytest.raises(ValueError, match="tangents applies to the 'fast' fidelity"):
        gj.Config(fidelity="reference", tangents="forward")
    with pytest.raises(ValueError, match="small_loops"):
        gj.Config(fidelity="reference", small_loops=True)
    with pytest.raises(ValueError, match="flow_width applies to the 'reference' fidelity"):
        gj.Config(flow_width=1e-9)
    assert gj.Config(small_loops=True).resolved().small_loops is True
    assert gj.Config().resolved().small_loops in (True, False)
    assert gj.Config(fidelity="reference").resolved().small_loops is None


def test_config_records_the_emitters_its_programs_compile_with():
    """``quick_compile`` (XLA:CPU's older emitters round differently) comes from the process where a program is
    compiled under ``jax.jit``, and a value such a program cannot take is refused; within a sweep's own compile
    (``xla_flags.compiling``) the sweep's choice holds."""
    from growjax.simulation import xla_flags

    quick = xla_flags.quick_compile_applied()
    assert gj.Config().resolved().quick_compile is quick
    assert gj.Config(fidelity="reference").resolved().quick_compile is quick
    assert gj.Config(quick_compile=quick).resolved() == gj.Config().resolved()
    with pytest.raises(ValueError, match="quick_compile"):
        gj.Config(quick_compile=not quick).resolved()
    with xla_flags.compiling(not quick):
        assert gj.Config().resolved().quick_compile is (not quick)
        assert gj.Config(quick_compile=not quick).resolved().quick_compile is (not quick)


NAMES = ("Y", "check_valve.max_open_pressure")


def _final_length(experiment, fidelity):
    from growjax.data import experiment as ex

    cfg = gj.Config(fidelity=fidelity, t1=1.5, rtol=1e-8)
    base = gj.reference()
    inputs = ex.to_inputs(experiment, "forward", base, cfg.t0, cfg.t1)
    breaks = gj.input_breaks(inputs, cfg)

    def final(theta):
        return gj.simulate(gj.replace(base, **dict(zip(NAMES, theta))), inputs, cfg, breaks=breaks).length[-1]

    return final, jnp.array([float(gj.get(base, n)) for n in NAMES])


def _central(fn, theta0, rel=1e-3):
    out = []
    for i in range(theta0.size):
        h = rel * float(theta0[i])
        out.append(float(fn(theta0.at[i].add(h)) - fn(theta0.at[i].add(-h))) / (2 * h))
    return np.asarray(out)


def _grad_against_differences(experiment, fidelity):
    final, theta0 = _final_length(experiment, fidelity)
    value_and_grad = jax.jit(jax.value_and_grad(final))  # one program for the gradient and the differences
    grad = np.asarray(value_and_grad(theta0)[1])
    fd = _central(lambda theta: value_and_grad(theta)[0], theta0)
    # 1 % plus the differences' own floor (adaptive steps move the length by ~rtol·L between the ±h runs).
    assert np.all(np.abs(grad - fd) <= 1e-2 * np.abs(fd) + 1e-6 / np.asarray(theta0)), (fidelity, grad, fd)
    assert np.all(np.abs(grad * np.asarray(theta0)) > 1e-5)  # each matters (> 10 µm over its whole value)
    return grad


def test_grad_of_the_fast_configuration_matches_differences(synthetic_experiment):
    """``jax.grad`` of the final length through the fast configuration (the Jacobian in the leaves that carry
    tangents, contracted and transposed) against central differences at rtol 1e-8. (Its forward mode against
    differences: ``test_effects``; against each other: the slow test below.)"""
    _grad_against_differences(synthetic_experiment, "fast")


@pytest.mark.slow
def test_grad_of_both_configurations_agree(synthetic_experiment):
    """The reference configuration's reverse mode (diffrax) against its differences, the two configurations'
    gradients against each other to the lumped model's error (10 %), and the fast configuration's reverse mode
    against its forward mode (sensitivities along the tangent) to the sensitivities' error control."""
    fast = _grad_against_differences(synthetic_experiment, "fast")
    final, theta0 = _final_length(synthetic_experiment, "fast")
    np.testing.assert_allclose(fast, np.asarray(jax.jit(jax.jacfwd(final))(theta0)), rtol=1e-4)
    reference = _grad_against_differences(synthetic_experiment, "reference")
    np.testing.assert_allclose(fast, reference, rtol=0.1)
