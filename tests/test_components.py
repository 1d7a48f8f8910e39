"""Component laws checked against the published model's values and against their own definitions (no ODE solve)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import growjax as gj
from growjax.model import hydraulics as hy
from growjax.model.fluid import (
    Fluid,
    bulk_modulus,
    pressure_at_stored_fraction,
    stored_volume_fraction,
    water,
)
from growjax.model.robot import catheter_friction_gain, rod_balance, rod_pressure
from growjax.model.smooth import bracketed_root, smooth_ramp, smooth_step


def test_water_properties_match_the_stock_table():
    w = water(22.0)
    assert w.density == pytest.approx(997.41, abs=0.01)
    assert w.kinematic_viscosity == pytest.approx(9.5838e-7, rel=1e-3)
    assert w.bulk_modulus_liquid == pytest.approx(2.18895e9, rel=1e-4)


@pytest.mark.parametrize("p, expected", [(0.0, 2.815e7), (8e3, 3.200e7), (150e3, 1.272e8), (373.3e3, 3.391e8)])
def test_mixture_bulk_modulus_table(p, expected):
    assert float(bulk_modulus(Fluid(), p)) == pytest.approx(expected, rel=2e-3)


@pytest.mark.parametrize("air", [0.0, 0.005, 0.02])
def test_stored_volume_law_is_the_integral_of_the_compressibility_and_inverts(air):
    """The fast configuration's closed-form storage ∫₀ᵖ dp'/E(p') against quadrature, and its inverse."""
    from scipy.integrate import quad

    fluid = gj.replace(gj.reference(), **{"fluid.air_fraction": air}).fluid
    p0 = float(gj.reference().tube.initial_pressure)
    for p in (-50e3, 1e3, 150e3, 373e3, 2e6):
        exact = quad(lambda q: 1.0 / float(bulk_modulus(fluid, q)), p0, p, limit=200, epsabs=0, epsrel=1e-12)[0]
        closed = float(stored_volume_fraction(fluid, p) - stored_volume_fraction(fluid, p0))
        assert closed == pytest.approx(exact, rel=1e-6, abs=1e-15)
        s = stored_volume_fraction(fluid, p)
        assert float(pressure_at_stored_fraction(fluid, s)) == pytest.approx(p, rel=1e-9, abs=1e-3)


def test_pressure_limit_is_373_kpa():
    assert float(gj.pressure_limit(gj.reference().robot)) == pytest.approx(373.333e3, rel=1e-5)
    thicker = gj.replace(gj.reference(), t=7e-5)
    assert float(gj.pressure_limit(thicker.robot)) == pytest.approx(2 * 373.333e3, rel=1e-5)


def test_the_rigs_limits_are_margins_under_the_membrane_limit_and_the_strokes():
    """One set of limits for every workflow: the ceiling 90 % of the membrane's 373.3 kPa, the length 95 % of each
    drive's stroke, the syringes' 50 mm travel, the stepper's 100 steps/s; the platform's speed unchecked unless
    given."""
    forward = gj.limits(gj.reference("forward"))
    assert forward.membrane_limit == pytest.approx(373.333e3, rel=1e-5)
    assert forward.pressure_ceiling == pytest.approx(336e3, rel=1e-5)
    assert forward.length_ceiling == pytest.approx(0.076, rel=1e-12) and forward.syringe_stroke == 0.05
    assert forward.max_pump_speed is None and forward.max_step_rate == 100.0
    stepper = gj.limits(gj.reference("inverse"), max_pump_speed=5e-3)
    assert stepper.length_ceiling == pytest.approx(0.095, rel=1e-12) and stepper.max_pump_speed == 5e-3
    assert stepper.summary()["pressure_ceiling_Pa"] == forward.pressure_ceiling  # the same membrane
    for bad in ({"margin": 1.2}, {"stroke_margin": 0.0}, {"max_pump_speed": 0.0}, {"max_step_rate": -1.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            gj.limits(gj.reference("forward"), **bad)


def test_orifice_inverse_is_exact():
    k, p_cr = 1e-7, 150.0
    q = jnp.array([-3e-5, -1e-8, 0.0, 2e-9, 4e-6])
    dp = hy.orifice_pressure_drop(k, q, p_cr)
    np.testing.assert_allclose(hy.orifice_flow(k, dp, p_cr), q, rtol=1e-12, atol=1e-20)


def test_check_valve_blocks_reverse_flow_unless_bypass_opens():
    p = gj.reference()
    fl, cv, dv = p.fluid, p.check_valve, p.valve
    y = p.robot.yield_pressure
    args = {"crack_pressure": y, "crack_width": 50.0}
    reverse = hy.check_valve_flow(cv, fl, -50e3, 50e3, **args)
    assert -1e-10 < float(reverse) < 0  # only the 1e-12 m² leak
    net = hy.valve_network(cv, dv, fl, y, 50.0, 10.0)
    through_network = hy.valve_network_flow(net, -50e3, 50e3)
    assert float(through_network) < -1e-4  # the 3-way valve bypasses the check valve
    # Below cracking, forward flow is leak-only, through the check valve and the network alike.
    below = hy.valve_network_flow(net, 0.5 * y, 0.5 * y)
    assert 0 < float(below) < 1e-10
    # Above cracking the valve passes the published model's growth flow (168 kPa → 6.7 mm/s).
    q = hy.valve_network_flow(net, 168e3, 60e3)
    assert float(q) / p.robot.area == pytest.approx(6.7e-3, rel=0.05)


def test_network_flow_never_bypasses_forward():
    p = gj.reference()
    net = hy.valve_network(p.check_valve, p.valve, p.fluid, 7920.0, 50.0, 10.0)
    dps = jnp.linspace(0.0, 7e3, 50)
    q = jax.vmap(lambda d: hy.valve_network_flow(net, d, 5e3))(dps)
    assert float(jnp.max(q)) < 1e-10


def test_catheter_friction_assists_growth_as_shipped():
    r = gj.reference().robot
    assert float(catheter_friction_gain(r, 0.04)) == pytest.approx(0.1758, rel=1e-3)
    p_r = rod_pressure(rod_balance(r, (1e-6, 1e-6)), 150e3, 0.0, 0.03, 0.04, 0.0)
    assert float(p_r) == pytest.approx(-18.45e3, rel=2e-3)  # the rod pressure of the published model at rest


def test_velocity_term_is_negligible_in_the_shipped_model():
    r = gj.reference().robot
    lo = rod_pressure(rod_balance(r, (1e-6, 1e-6)), 150e3, 0.0, 0.03, 0.04, 0.0)
    hi = rod_pressure(rod_balance(r, (1e-6, 1e-6)), 150e3, 0.01, 0.03, 0.04, 0.0)
    assert 0 < float(hi - lo) * r.area < 1e-10  # N, the ~1e-11 N velocity term


def test_smooth_primitives_are_exact_outside_their_band():
    x = jnp.array([-1.0, 0.0, 2.0, 5.0])
    np.testing.assert_allclose(smooth_ramp(x, 1.0), [0.0, 0.0, 1.5, 4.5])
    np.testing.assert_allclose(smooth_step(x, 1.0), [0.0, 0.0, 1.0, 1.0])
    g = jax.grad(lambda v: smooth_ramp(v, 1.0))
    assert float(g(1.0 - 1e-12)) == pytest.approx(float(g(1.0 + 1e-12)), abs=1e-9)  # C¹ at the band edge


def test_bracketed_root_value_and_implicit_gradient():
    def root(a):
        return bracketed_root(lambda x: a - x**3 - x, 0.0, a)

    a = 3.0
    x = float(root(a))
    assert x**3 + x == pytest.approx(a, rel=1e-12)
    assert float(jax.grad(root)(a)) == pytest.approx(1.0 / (3 * x**2 + 1), rel=1e-10)


def test_parameters_override_by_symbol_block_and_field():
    p = gj.replace(gj.reference(), Y=8000.0, **{"tank.length": 0.2, "catheter_friction": 0.02})
    assert gj.get(p, "robot.yield_pressure") == 8000.0
    assert p.tank.length == 0.2 and p.robot.catheter_friction == 0.02
    with pytest.raises(ValueError, match="ambiguous"):
        gj.replace(p, length=0.1)
    with pytest.raises(ValueError, match="unknown parameter"):
        gj.replace(p, yeild=1.0)


@pytest.mark.parametrize(
    "name, value, message",
    [("Y", float("nan"), "not finite"), ("n", -1.0, "physical range"), ("ri", 2e-3, "smaller than")],
)
def test_validate_names_the_bad_parameter(name, value, message):
    with pytest.raises(ValueError, match=message):
        gj.validate(gj.replace(gj.reference(), **{name: value}))


def test_reference_drives_differ_as_shipped():
    fwd, inv = gj.reference("forward"), gj.reference("inverse")
    assert fwd.tube.length == 0.3 and inv.tube.length == 0.1
    assert fwd.robot.stroke == 0.08 and inv.robot.stroke == 0.1
    with pytest.raises(ValueError):
        gj.reference("sideways")


def test_a_sampled_series_interpolates_alike_with_its_grid_found_or_searched():
    """A uniform grid of three samples or more is found (its step keys the compiled program); two samples are one
    segment, found alike whatever their step's last bits, so a new ramp per control tick does not recompile."""
    t, v = np.linspace(0.0, 1.0, 11), np.sin(np.linspace(0.0, 3.0, 11))
    uneven = t + 1e-3 * np.sin(7 * t) * (t > 0) * (t < 1)
    uniform, searched = gj.Sampled(t, v), gj.Sampled(uneven, v)
    assert uniform.spacing == pytest.approx(0.1) and searched.spacing is None
    at = np.linspace(0.0, 1.0, 57)
    np.testing.assert_allclose(uniform(jnp.asarray(at)), np.interp(at, t, v), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(searched(jnp.asarray(at)), np.interp(at, uneven, v), rtol=1e-12, atol=1e-15)
    ramps = [gj.Sampled(jnp.stack([k * 0.01, (k + 1) * 0.01]), jnp.asarray([1.0, 2.0])) for k in range(1, 40)]
    assert len({jax.tree_util.tree_structure(r) for r in ramps}) == 1
    np.testing.assert_allclose(ramps[6](0.075), 1.5, rtol=1e-12)
