"""The tensor-grid emulator: exact where it must be, smooth, bounded, and close to the model it stands for."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import growjax as gj
from growjax.posterior import emulator as em


def _table(f, axes):
    grids = np.meshgrid(*[a.points() for a in axes], indexing="ij")
    values = f(*grids)[..., None] * np.array([1.0, -2.0])  # two "output times"
    lows = [np.log(a.low) if a.log else a.low for a in axes]
    highs = [np.log(a.high) if a.log else a.high for a in axes]
    return em.Emulator(
        values=jnp.asarray(em.pad_linear(values, len(axes))),
        times=jnp.zeros(2),
        lows=jnp.asarray(lows),
        highs=jnp.asarray(highs),
        error_rms=jnp.asarray(0.0),
        error_max=jnp.asarray(0.0),
        base=None,
        inputs=None,
        names=("a", "b"),
        log=tuple(a.log for a in axes),
        nodes=tuple(a.nodes for a in axes),
        config=None,
    )


def test_interpolation_is_exact_for_quadratics_inside_and_linear_at_the_edges():
    axes = (em.Axis("a", 1.0, 3.0, 9), em.Axis("b", -1.0, 1.0, 5))
    quad = lambda a, b: 1.0 + 2.0 * a - 0.5 * a * a + 3.0 * a * b * b
    emu = _table(quad, axes)
    rng = np.random.default_rng(0)
    inner = np.column_stack([rng.uniform(1.25, 2.75, 50), rng.uniform(-0.5, 0.5, 50)])  # cells away from the ends
    got = np.asarray(jax.vmap(emu)(jnp.asarray(inner)))
    want = quad(inner[:, 0], inner[:, 1])[:, None] * np.array([1.0, -2.0])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    lin = _table(lambda a, b: 4.0 - a + 2.0 * b, axes)  # linear: exact everywhere, end cells included
    pts = np.column_stack([rng.uniform(1.0, 3.0, 50), rng.uniform(-1.0, 1.0, 50)])
    np.testing.assert_allclose(
        np.asarray(jax.vmap(lin)(jnp.asarray(pts)))[:, 0], 4.0 - pts[:, 0] + 2.0 * pts[:, 1], atol=1e-12
    )
    assert np.all(np.isnan(np.asarray(emu(jnp.array([3.5, 0.0])))))  # outside the box: NaN, never extrapolated


def test_interpolant_is_continuously_differentiable_across_nodes():
    axes = (em.Axis("a", 1.0, 3.0, 5, log=True), em.Axis("b", 0.0, 1.0, 4))
    emu = _table(lambda a, b: np.sin(3 * a) * np.exp(b), axes)
    node = float(axes[0].points()[2])
    g = jax.grad(lambda a: emu(jnp.array([a, 0.3]))[0])
    left, right = float(g(node * (1 - 1e-9))), float(g(node * (1 + 1e-9)))
    assert left == pytest.approx(right, rel=1e-6)


def test_axis_rejects_bad_boxes():
    with pytest.raises(ValueError, match="low < high"):
        em.Axis("Y", 2.0, 1.0, 5)
    with pytest.raises(ValueError, match="2 nodes"):
        em.Axis("Y", 1.0, 2.0, 1)
    with pytest.raises(ValueError, match="log axis"):
        em.Axis("Y", 0.0, 2.0, 5, log=True)


@pytest.mark.slow
def test_emulator_of_the_model_is_within_its_measured_error():
    cfg = gj.Config(t1=0.8)
    t = np.array([0.0, 100.0])
    inputs = gj.Inputs(catheter_length=gj.Sampled(t, 0.004 + 0.004 * t), pressure_demand=gj.published_pulse())
    times = np.arange(0.01, 0.8, 0.01)
    emu = em.validate(em.build([em.Axis("Y", 5e3, 15e3, 41)], gj.reference(), inputs, cfg, times), n_points=16)
    assert 0 < float(emu.error_rms) <= float(emu.error_max) < 5e-5  # 0.05 mm, against σ ≈ 1 mm on the data
    y = 8123.0  # off the grid: the emulator matches a fresh model run
    traj = gj.simulate(gj.replace(gj.reference(), Y=y), inputs, cfg)
    model = np.interp(times, np.asarray(traj.time), np.asarray(traj.length))
    assert np.max(np.abs(np.asarray(emu(jnp.array([y]))) - model)) <= float(emu.error_max) * 2 + 1e-9
