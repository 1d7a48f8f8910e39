"""Every catalogue effect: absent at zero, acting in its physical direction, the same in both configurations,
differentiable; and the synthetic-experiment generator built on them (growjax.data.synthetic).

All runs are 0–3 s of the forward drive under the published pulse with the shipped synthetic inputs
(catheter 0.004 + 0.004 t m), available everywhere. The effects are simulated in the *superset* model
(every known effect present, all at zero but one: :func:`growjax.data.synthetic.hidden_effect_parameters`),
which is the same model as the effect alone and shares one compiled solver between all effects.

The fast configuration is checked against noise-free traces made by the reference configuration
(rtol 1e-7) and shipped in growjax/data/datasets/discovery/reference/ (``python data/make_discovery_examples.py reference``):
the reference cannot be cached on disk (its solve uses host callbacks) and costs about a minute to
compile per process, so the live comparison runs under ``-m slow``.
"""

import dataclasses
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import REPO

import growjax as gj
from growjax.data import experiment as ex
from growjax.data import synthetic as sy
from growjax.data.synthetic import solve as synthetic_solve
from growjax.model import effects as fx

sys.path.insert(0, str(REPO / "data"))
import make_discovery_examples as mde  # the shipped reference traces, made and read there

NAMES = list(fx.CATALOGUE)
T1 = 3.0
FAST = gj.Config(t1=T1, adjoint="forward")  # forward mode along the tangent (jvp)
TIME = np.round(np.arange(1, 301) * 0.01, 10)  # s: the save grid of the shipped reference traces
TS = np.concatenate([[FAST.t0], TIME])
NOISE = 2e-4  # m: the rig's length noise
RISES = (0.26, 1.56, 2.86)  # s: edges of the published pulse inside the window
FALLS = (1.43, 2.73)


def _field(name):
    return sy.magnitude_field(name)


def _effect(name, value):
    return sy.effect_class(name)(**{_field(name): value})


@pytest.fixture(scope="module")
def inputs():
    return sy.resolve_inputs("synthetic", "forward", gj.reference(), T1)[0]


def _run(params, inputs, config=FAST):
    traj = gj.simulate(params, inputs, config, ts=TS)
    assert int(traj.status) == gj.OK, gj.status_name(traj.status)
    return {
        "length": np.asarray(traj.length),
        "pressure": np.asarray(traj.pressure),
        "syringe": np.asarray(traj.syringe_displacement),
    }


@pytest.fixture(scope="module")
def traces(inputs):
    """Fast-configuration traces on TS: ``base`` (no effects), ``zero`` (superset, all zero), each effect at its
    moderate magnitude (superset)."""
    out = {"base": _run(gj.reference(), inputs), "zero": _run(sy.hidden_effect_parameters(None), inputs)}
    for name in NAMES:
        out[name] = _run(sy.hidden_effect_parameters(sy.make_effect(name)), inputs)
    return out


# -- (a) zero means absent ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(sy.known_effects()))
def test_an_effect_at_zero_contributes_nothing(name):
    """Each hook of an effect at its default (zero) parameters contributes exactly nothing, at random instants."""
    effect = sy.effect_class(name)()
    assert float(getattr(effect, _field(name))) == 0.0
    params = gj.reference()
    state = effect.initial_state(params, "forward")
    np.testing.assert_array_equal(np.asarray(state), 0.0)
    assert float(effect.length_offset(state)) == 0.0
    rng = np.random.default_rng(7)
    for _ in range(20):
        t, p, v = rng.uniform(0, 10), rng.uniform(-5e3, 3e5), rng.normal(0.0, 0.02)
        rod = fx.Rod(
            t=t,
            pressure=p,
            velocity=v,
            length=rng.uniform(0, 0.08),
            catheter_length=rng.uniform(0, 0.05),
            inner_radius=params.robot.inner_radius,
            area=params.robot.area,
        )
        assert float(effect.rod_force(rod, state)) == 0.0
        assert float(effect.chamber_outflow(t, p, state)) == 0.0
        commanded = rng.normal(0.0, 50.0)
        assert float(effect.drive(commanded, state)) == commanded
        instant = fx.Instant(
            t=t,
            pressure=p,
            robot_pressure=p - 100.0,
            robot_flow=v * params.robot.area,
            velocity=v,
            length=0.02,
            drive=commanded,
        )
        np.testing.assert_array_equal(np.asarray(effect.rates(instant, state)), 0.0)
    same = jax.tree_util.tree_map(
        lambda a, b: bool(np.all(np.asarray(a) == np.asarray(b))), effect.apply(params), params
    )
    assert all(jax.tree_util.tree_leaves(same))


def test_every_effect_at_zero_is_the_base_model(traces):
    """The superset model with every effect at zero against the model with none (fast configuration).

    Not bit-equal: the zero effects add states (lag, folding, hose) whose zero rates still enter the step-size
    control, and the velocity-dependent ones switch the rod balance from one fixed-point pass to Newton
    iterations; both move the solution at the solver's tolerance (rtol 1e-4 on scaled states), measured 0.3 µm
    over 3 s. The bound is 5 µm, 40× under the length noise; each hook is exactly zero (test above).
    """
    diff = traces["zero"]["length"] - traces["base"]["length"]
    assert np.max(np.abs(diff)) < 5e-6
    assert np.max(np.abs(traces["zero"]["pressure"] - traces["base"]["pressure"])) < 50.0  # Pa, of 150 kPa


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_an_effect_alone_at_zero_is_the_base_model(inputs, name):
    """The effect alone (its own compiled solver), at zero, against the base model.

    Not bit-equal even for the effects that add only zeros (no state, no velocity dependence): a different
    compiled program rounds differently in the last bit, and the adaptive step control amplifies that to the
    solver's tolerance. Measured over 3 s: active_channel_force and trapped_air ≤ 1e-12 m, fluid_leak 0.22 µm.
    """
    cls = fx.CATALOGUE[name]
    base = _run(gj.reference(), inputs)["length"]
    alone = _run(gj.with_effects(gj.reference(), cls()), inputs)["length"]
    assert np.max(np.abs(alone - base)) <= 5e-6


# -- (b) the physically expected direction ---------------------------------------------------------------


def _at(t):
    """Index in TS of time t (s)."""
    return int(np.argmin(np.abs(TS - t)))


def _growth(length):
    """Length gained over each full on-phase of the pulse (rise → fall), m."""
    return np.array([length[_at(f)] - length[_at(r)] for r, f in zip(RISES, FALLS)])


def _retraction(length):
    """Length lost while the demand is off (start → first rise, each fall → next rise), m (positive)."""
    starts, ends = (0.001, *FALLS), RISES
    return np.array([length[_at(a)] - length[_at(b)] for a, b in zip(starts, ends)])


def _pressure_after(trace, edges, delay):
    return np.array([trace["pressure"][_at(e + delay)] for e in edges])


def _check_pull(base, eff, name):
    # A constant pull only ever opposes growth: the robot is never longer, and ends clearly shorter.
    d = eff["length"] - base["length"]
    assert np.max(d) < 1e-6 and d[-1] < -1e-3
    assert np.all(_growth(eff["length"]) < _growth(base["length"]))


def _check_leak(base, eff, name):
    # The leak loses volume: the syringes deliver more than reaches the robot, by G·∫p dt (within 3 %),
    # and the pressure-controlled chamber runs lower while the demand is on.
    p = gj.reference()
    syringes, robot = p.pump.n_syringes * float(p.pump.syringe_area), float(p.robot.area)
    lost = lambda tr: syringes * tr["syringe"] - robot * tr["length"]
    extra = lost(eff) - lost(base)
    g = sy.moderate_magnitude(name)
    leaked = g * np.concatenate([[0.0], np.cumsum(0.5 * (eff["pressure"][1:] + eff["pressure"][:-1]) * np.diff(TS))])
    assert leaked[-1] > 5e-8  # m³: 50 mm³, 8 mm of robot
    np.testing.assert_allclose(extra[_at(1.0) :], leaked[_at(1.0) :], rtol=0.03)
    on = (TS > RISES[0] + 0.05) & (TS < FALLS[0])
    assert np.mean(eff["pressure"][on] - base["pressure"][on]) < 0.0


def _check_slow_pressure(base, eff, name):
    # A lagging drive, or a more compliant fluid, delays the pressure's response to the demand: lower just
    # after each rising edge, higher just after each falling edge.
    assert np.all(_pressure_after(eff, RISES, 0.011) < _pressure_after(base, RISES, 0.011) - 5e3)
    assert np.all(_pressure_after(eff, FALLS, 0.011) > _pressure_after(base, FALLS, 0.011) + 5e3)


def _check_growth_friction(base, eff, name):
    # Friction on the catheter (∝ pressure, so mostly while growing) slows every growth phase.
    assert np.all(_growth(eff["length"]) < _growth(base["length"]) - 1e-4)
    assert eff["length"][-1] < base["length"][-1] - 5e-4


def _check_lumen_friction(base, eff, name):
    # Wall friction resists the motion both ways: less growth while on (by ~0.1 mm: the force, ~0.015 N, is
    # small against the ~140 kPa that drives growth), much less retraction while off (by ~1 mm).
    assert np.all(_growth(eff["length"]) < _growth(base["length"]) - 2e-5)
    assert np.all(_retraction(eff["length"]) < _retraction(base["length"]) - 1e-4)


def _check_rate_limit(base, eff, name):
    # Limits growth only: the robot falls behind while growing, never catches up, and retracts as before.
    d = eff["length"] - base["length"]
    assert np.all(np.diff(d) < 1e-6)
    assert d[-1] < -5e-4
    np.testing.assert_allclose(_retraction(eff["length"]), _retraction(base["length"]), rtol=0.02, atol=2e-5)


def _check_folding(base, eff, name):
    # A fraction f of each retraction folds inside: the robot retracts (1 − f) as far, grows as before,
    # and so is left longer after every retraction.
    f = sy.moderate_magnitude(name)
    d = eff["length"] - base["length"]
    assert np.all(np.diff(d) > -1e-6)
    np.testing.assert_allclose(_retraction(eff["length"]), (1.0 - f) * _retraction(base["length"]), rtol=0.02)
    np.testing.assert_allclose(_growth(eff["length"]), _growth(base["length"]), rtol=0.01, atol=2e-5)


DIRECTION = {
    "active_channel_force": _check_pull,
    "fluid_leak": _check_leak,
    "actuation_lag": _check_slow_pressure,
    "trapped_air": _check_slow_pressure,
    "catheter_friction": _check_growth_friction,
    "lumen_friction": _check_lumen_friction,
    "growth_rate_limit": _check_rate_limit,
    "retraction_folding": _check_folding,
}


@pytest.mark.parametrize("name", NAMES)
def test_a_moderate_effect_acts_in_its_physical_direction(traces, name):
    """At its moderate magnitude each effect moves the length by clearly more than the noise, as its physics says."""
    lo, hi = fx.CATALOGUE[name].ranges[_field(name)]
    assert lo <= sy.moderate_magnitude(name) <= hi
    base, eff = traces["base"], traces[name]
    assert np.max(np.abs(eff["length"] - base["length"])) > 2.5 * NOISE
    DIRECTION[name](base, eff, name)


# -- (c) fast against reference ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def reference_traces():
    time, lengths, meta = mde.read_reference(mde.REFERENCE)
    np.testing.assert_allclose(time, TIME)
    return lengths, meta


def test_shipped_reference_traces_are_current(reference_traces):
    """They were made at the moderate magnitudes in use, on these inputs and window (else: rerun the script)."""
    lengths, meta = reference_traces
    assert set(lengths) == {"none", *NAMES}
    assert meta["t_end_s"] == T1 and meta["configuration"]["fidelity"] == "reference"
    for name in NAMES:
        assert meta["cases"][name]["magnitude"] == sy.moderate_magnitude(name), name


@pytest.mark.parametrize("name", ["none", *NAMES])
def test_fast_agrees_with_the_reference_with_the_effect_on(traces, reference_traces, name):
    """0–3 s: within 0.05 mm RMSE and 0.15 mm max of the reference-made trace (noise 0.2 mm)."""
    lengths, _ = reference_traces
    fast = traces["zero" if name == "none" else name]["length"][1:]
    diff = fast - lengths[name]
    assert np.sqrt(np.mean(diff**2)) < 0.05e-3
    assert np.max(np.abs(diff)) < 0.15e-3


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_fast_agrees_with_a_live_reference_run(traces, inputs, name):
    """The same comparison against the reference configuration run here (about a minute to compile, then
    tens of seconds per effect on two cores)."""
    params = sy.hidden_effect_parameters(sy.make_effect(name))
    ref = _run(params, inputs, FAST.replace(fidelity="reference", rtol=1e-7, atol=1e-7))["length"]
    diff = traces[name]["length"] - ref
    assert np.sqrt(np.mean(diff**2)) < 0.05e-3
    assert np.max(np.abs(diff)) < 0.15e-3


# -- differentiability ----------------------------------------------------------------------------------------

ALL_CLASSES = tuple(sy.known_effects().values())  # the superset's effects, in its order
# The default run's model: a force, a flow and an effect with a state of its own (the whole superset compiles
# for ~40 s more: the slow test below takes every effect through it).
FEW = ("active_channel_force", "fluid_leak", "retraction_folding")
FEW_CLASSES = tuple(sy.known_effects()[n] for n in FEW)


@eqx.filter_jit
def _length_and_tangent(values, tangent, inputs, breaks, classes=FEW_CLASSES):
    """(length on TS, its jvp) of the model carrying the effects ``classes`` with magnitudes ``values`` (one per
    class), along ``tangent``: one compiled program for every effect and every value."""

    def length(v):
        effects = tuple(cls(**{sy.magnitude_field(cls): v[i]}) for i, cls in enumerate(classes))
        params = dataclasses.replace(gj.reference(), effects=effects)
        return gj.simulate(params, inputs, FAST, ts=TS, breaks=breaks).length

    return jax.jvp(length, (values,), (tangent,))


def _unit(k, scale=1.0, size=None):
    size = len(FEW) if size is None else size
    e = np.zeros(size)
    e[k] = scale
    return jnp.asarray(e)


def _leaf_against_differences(inputs, name, classes):
    """d(final length)/dθ by forward mode along a unit tangent on θ in SI units (one column of ``jax.jacfwd``)
    against central differences (±5 % of θ), at the moderate magnitude θ = m."""
    k = list(classes).index(sy.effect_class(name))
    m = sy.moderate_magnitude(name)
    breaks = gj.input_breaks(inputs, FAST)
    at = _unit(k, m, len(classes))
    run = lambda v: _length_and_tangent(v, _unit(k, 1.0, len(classes)), inputs, breaks, classes)
    grad = float(run(at)[1][-1])
    fd = (float(run(at * 1.05)[0][-1]) - float(run(at * 0.95)[0][-1])) / (0.1 * m)
    assert abs(fd * m) > 1e-5  # the final length depends on it (> 10 µm per 100 %)
    assert grad == pytest.approx(fd, rel=3e-2)


@pytest.mark.parametrize("name", FEW)
def test_the_effect_parameter_is_a_differentiable_leaf(inputs, name):
    """d(final length)/dθ by forward mode through the fast configuration matches central differences within 3 %,
    at the moderate magnitude (SI sizes from 3e-13 to 0.3), for a force, a flow and an effect with a state."""
    _leaf_against_differences(inputs, name, FEW_CLASSES)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(sy.known_effects()))
def test_every_effect_parameter_is_a_differentiable_leaf_of_the_superset(inputs, name):
    """The same for every effect, through the superset model (SI sizes from 3e-18 to 350)."""
    _leaf_against_differences(inputs, name, ALL_CLASSES)


@pytest.mark.parametrize("name", ["fluid_leak", "active_channel_force"])
def test_the_derivative_at_an_absent_effect_is_finite_and_right(inputs, name):
    """At θ = 0 (the effect absent) a unit tangent in SI units has no size of its own to scale the difference
    step: the effect's range sets it (a leak's 1e-12 m³/(s·Pa), not 1); a step of ε^⅓ in SI would make the
    shifted solve fail and every derivative NaN. d(final length)/dθ matches the forward
    difference to 10 % of the moderate magnitude within 5 % (both effects are nearly linear there)."""
    k = FEW.index(name)
    m = sy.moderate_magnitude(name)
    breaks = gj.input_breaks(inputs, FAST)
    zero = jnp.zeros(len(FEW))
    length0, tangent = _length_and_tangent(zero, _unit(k), inputs, breaks)
    grad = float(tangent[-1])
    assert np.isfinite(grad)
    fd = (float(_length_and_tangent(_unit(k, 0.1 * m), _unit(k), inputs, breaks)[0][-1]) - float(length0[-1])) / (
        0.1 * m
    )
    assert grad == pytest.approx(fd, rel=5e-2)


# -- the synthetic-experiment generator --------------------------------------------------------------------


def test_moderate_magnitudes_lie_inside_the_ranges_and_out_of_range_is_refused():
    for name, cls in sy.known_effects().items():
        effect = sy.make_effect(name)
        lo, hi = cls.ranges[_field(name)]
        assert lo <= getattr(effect, _field(name)) == sy.moderate_magnitude(name) <= hi
        with pytest.raises(ValueError, match="outside"):
            sy.make_effect(name, 2 * hi + 1.0)
    for cls in fx.CATALOGUE.values():  # what discovery reports and a discriminating design sizes
        assert cls.moderate > 0.0 and len(cls.separated_by) > 20, cls.name
    assert not set(sy.OUTSIDE) & set(fx.CATALOGUE)
    with pytest.raises(ValueError, match="unknown effect"):
        sy.make_effect("gravity")


def test_make_experiment_noise_seeds_cache_and_format(monkeypatch, tmp_path, traces):
    """Plumbing of make_experiment (the solver faked by the fast configuration, checked to be asked for the
    reference): seeded noise of the stated size, one solve for many seeds, a CSV + JSON that read back."""
    calls = []

    def fake(params, model_inputs, config, ts):
        assert config.fidelity == "reference"  # the generator never asks for the fast configuration
        calls.append(config)
        return gj.simulate(params, model_inputs, config.replace(fidelity="fast", rtol=None, atol=None), ts=ts)

    monkeypatch.setattr(synthetic_solve, "reference_solve", fake)
    sy.clear_cache()
    kw = {"inputs": "synthetic", "t_end": T1}
    a = sy.make_experiment("active_channel_force", None, seed=1, **kw)
    b = sy.make_experiment("active_channel_force", None, seed=1, **kw)
    c = sy.make_experiment("active_channel_force", None, seed=2, **kw)
    assert len(calls) == 1  # the noise-free solve is cached across seeds
    np.testing.assert_array_equal(a["robot_length_m"], b["robot_length_m"])
    assert not np.array_equal(a["robot_length_m"], c["robot_length_m"])
    np.testing.assert_allclose(a.time, TIME)
    clean = traces["active_channel_force"]["length"][1:]
    noise = a["robot_length_m"] - clean
    assert abs(np.mean(noise)) < 4 * NOISE / np.sqrt(noise.size)
    assert np.std(noise) == pytest.approx(NOISE, rel=0.15)
    assert set(a.series) == {"robot_length_m", "pressure_Pa", "catheter_length_m"}
    meta = a.metadata
    assert meta["effect"] == "active_channel_force" and meta["in_catalogue"] is True
    assert meta["parameter"] == "active_channel_force.force" and meta["magnitude"] == 0.01 and meta["unit"] == "N"
    assert meta["seed"] == 1 and meta["noise_sd"]["robot_length_m"] == NOISE
    assert meta["solver"]["fidelity"] == "reference"
    path = a.write(tmp_path / "acf.csv")
    back = ex.read(path)
    np.testing.assert_allclose(back["robot_length_m"], a["robot_length_m"], rtol=0, atol=1e-15)
    assert sy.read_truth(path)["magnitude"] == 0.01
    rebuilt = ex.to_inputs(back, "forward", gj.reference(), t1=T1)
    assert isinstance(rebuilt.pressure_demand, gj.PulseTrain)  # the published pulse: no demand column needed
    clean_none = sy.make_experiment(None, None, seed=1, noise_pressure_Pa=None, **kw)
    assert clean_none.metadata["effect"] is None and "pressure_Pa" not in clean_none
    outside = sy.make_experiment("oscillating_force", None, seed=1, **kw)
    assert outside.metadata["in_catalogue"] is False
    sy.clear_cache()


def test_shipped_discovery_examples():
    """growjax/data/datasets/discovery/: small CSVs with a JSON truth beside each, 0.01–10 s, length noise 0.2 mm as stated."""
    folder = REPO / "src" / "growjax" / "data" / "datasets" / "discovery"
    paths = sorted(folder.glob("*.csv"))
    assert {p.stem for p in paths} >= {"clean", "active_channel_force", "retraction_folding"}
    assert any(sy.read_truth(p)["in_catalogue"] is False for p in paths)
    for path in paths:
        assert path.stat().st_size < 110e3
        exp = ex.read(path)
        truth = sy.read_truth(path)
        assert truth["drive"] == "forward" and truth["solver"]["fidelity"] == "reference"
        assert exp.time[0] == pytest.approx(0.01) and exp.time[-1] == pytest.approx(10.0)
        assert truth["noise_sd"]["robot_length_m"] == NOISE
        if truth["effect"] is not None:
            assert truth["magnitude"] == sy.moderate_magnitude(truth["effect"])
        # Robust noise estimate from second differences (the trace itself is smooth at 100 Hz but for edges).
        d2 = np.diff(exp["robot_length_m"], 2)
        sigma = 1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0)
        assert sigma == pytest.approx(NOISE, rel=0.2)
