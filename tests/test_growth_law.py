"""Lockhart's growth law beside the reference: the rod balance it solves, and what it makes identifiable."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import growjax as gj
from growjax.model import hydraulics as hy
from growjax.model.robot import LOCKHART_PRESSURE_SCALE, inflow, rod_balance, rod_pressure

WIDTHS = (1e-12, 1e-6)  # velocity_eps m/s (regularisation negligible here), stop width m


def _lockhart(**kw):
    return gj.replace(gj.reference(growth_law="lockhart"), **kw)


def _inflow(p, pressure, length=0.02, catheter=0.005):
    rod = rod_balance(p.robot, WIDTHS)
    valves = hy.valve_network(p.check_valve, p.valve, p.fluid, p.robot.yield_pressure, 50.0, 10.0)
    return inflow(rod, valves, pressure, length, catheter, lambda v: 0.0), rod, valves


@pytest.mark.parametrize("n_l", [0.25, 1.0, 2.0])
@pytest.mark.parametrize("pressure", [20e3, 80e3, 150e3])
def test_lockhart_flow_satisfies_both_the_valve_and_the_growth_law(n_l, pressure):
    p = _lockhart(n_L=n_l, phi_L=1e-3)
    length, catheter = 0.02, 0.005
    (q, p_r), rod, valves = _inflow(p, pressure, length, catheter)
    p_0 = rod_pressure(rod, pressure, 0.0, length, catheter, 0.0)
    dp = pressure - p_r
    valve = hy.valve_network_flow(valves, dp, pressure - 0.5 * dp)
    growth = p.robot.area * 1e-3 * max(float(p_r - p_0) / LOCKHART_PRESSURE_SCALE, 0.0) ** n_l
    assert float(q) > 0
    assert float(q) == pytest.approx(float(valve), rel=1e-9)
    assert float(q) == pytest.approx(growth, rel=1e-6)


def test_lockhart_flow_gradient_matches_finite_differences():
    def q(log_phi, n_l):
        return _inflow(_lockhart(phi_L=jnp.exp(log_phi), n_L=n_l), 100e3)[0][0]

    x = (jnp.log(1e-3), 0.8)
    grad = jax.grad(q, argnums=(0, 1))(*x)
    h = 1e-6
    fd = ((q(x[0] + h, x[1]) - q(x[0] - h, x[1])) / (2 * h), (q(x[0], x[1] + h) - q(x[0], x[1] - h)) / (2 * h))
    for g, f in zip(grad, fd):
        assert float(g) == pytest.approx(float(f), rel=1e-5)


def test_lockhart_law_makes_phi_and_n_matter_where_ext_and_n_do_not():
    cfg = gj.Config(t1=2.0)
    t = np.array([0.0, 100.0])
    inputs = gj.Inputs(catheter_length=gj.Sampled(t, 0.004 + 0.004 * t), pressure_demand=gj.published_pulse())

    def final(params):
        tr = gj.simulate(params, inputs, cfg)
        assert int(tr.status) == 0
        return float(tr.length[-1])

    ref = [final(gj.replace(gj.reference(), ext=e, n=n)) for e, n in [(4000.0, 0.9), (10000.0, 1.1)]]
    assert abs(ref[0] - ref[1]) < 1e-6  # the published velocity term: no effect beyond the solver tolerance (0.1 µm)
    slow, fast = final(_lockhart(phi_L=3e-4)), final(_lockhart(phi_L=3e-3))
    soft, stiff = final(_lockhart(phi_L=1e-3, n_L=0.5)), final(_lockhart(phi_L=1e-3, n_L=1.5))
    base = final(gj.reference())
    assert fast - slow > 8e-4  # faster membrane, longer robot: a mm-scale effect (1.2 mm measured)
    assert abs(soft - stiff) > 8e-4  # 1.4 mm measured
    assert max(slow, fast, soft, stiff) <= base + 1e-4  # a resistance in series never speeds growth


def test_growth_law_is_validated():
    with pytest.raises(ValueError, match="growth_law"):
        gj.reference(growth_law="plant")
    with pytest.raises(ValueError, match="lockhart_rate"):
        gj.validate(_lockhart(phi_L=-1.0))


@pytest.mark.slow
def test_forward_mode_and_difference_tangents_give_the_same_jacobian():
    """The fast configuration's sensitivities with their field in forward mode (``jax.jvp``: the Lockhart law's
    default, the rod balance's Newton solve evaluated once) and by central differences of the field (whose match
    with differences of whole solves tests/test_model.py checks) agree, for d(length)/d(Y, φ_L, n_L) over 1.5 s,
    both through ``length_jacobian`` (NUTS's path: one solve gives the length and its Jacobian)."""
    from growjax.simulation.simulate import length_jacobian

    t = np.array([0.0, 100.0])
    inputs = gj.Inputs(catheter_length=gj.Sampled(t, 0.004 + 0.004 * t), pressure_demand=gj.published_pulse())
    names = ("Y", "phi_L", "n_L")
    theta0 = jnp.array([6000.0, 2e-3, 0.5])
    ts = jnp.array([0.5, 1.0, 1.5])

    def params_of(theta):
        return _lockhart(**dict(zip(names, theta)))

    forward = gj.Config(t1=1.5, adjoint="forward", tangents="forward")
    runs = {
        mode: length_jacobian(params_of, theta0, inputs, forward.replace(tangents=mode), ts)
        for mode in ("forward", "differences")
    }
    (traj_f, jf), (traj_d, jd) = ((r[0], np.asarray(r[1])) for r in runs.values())
    assert int(traj_f.status) == int(traj_d.status) == gj.OK
    assert np.all(np.abs(jd[-1] * np.asarray(theta0)) > 1e-4)  # each matters (> 0.1 mm over its whole value)
    assert np.all(np.abs(jf - jd) <= 1e-3 * np.abs(jd).max(axis=0)), (jf, jd)
    np.testing.assert_allclose(np.asarray(traj_f.length), np.asarray(traj_d.length), rtol=0, atol=2e-6)  # 2 µm
