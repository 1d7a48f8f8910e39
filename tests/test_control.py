"""Control design on the model: linearisation, profile limits, tuning, disturbance rejection (short windows)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import growjax as gj
from growjax import control as gc
from growjax.calibration.tolerance import rig_draws
from growjax.control import workflow as cw

T = 1.5


@pytest.fixture(scope="module")
def target():
    return gc.ramp_with_pauses(t_end=T, start=0.010, speed=4e-3, move=0.5, pause=0.25)


def test_linearisation_matches_finite_differences_and_small_step():
    pytest.importorskip("control")
    p = gj.reference("forward")
    sys = gc.linearize(p, "forward", pressure=150e3, settle=1.0)
    op = sys.operating_point
    assert op["growing"] and 3e-3 < op["growth_speed_m_s"] < 8e-3  # ~5 mm/s at 150 kPa
    plant, y, inputs = gc.operating_point(p, "forward", 150e3, settle=1.0)

    def f(y, u):
        return plant.field(1.0, y, eqx.tree_at(lambda i: i.pressure_demand, inputs, gj.Constant(u)))

    h = 1e-6
    for j in range(y.size):  # A column by column against central differences of the nonlinear field
        e = jnp.zeros_like(y).at[j].set(h)
        fd = (f(y + e, 150e3) - f(y - e, 150e3)) / (2 * h)
        np.testing.assert_allclose(sys.A[:, j], fd, rtol=1e-4, atol=1e-6 * np.max(np.abs(sys.A)))
    fd_b = (f(y, 150e3 + 10.0) - f(y, 150e3 - 10.0)) / 20.0
    np.testing.assert_allclose(sys.B[:, 0], fd_b, rtol=1e-4, atol=1e-12)

    # small step of the demand: nonlinear response minus the unstepped run, against the linear step response
    dt, du = 0.4, 2e3
    ts = 1.0 + jnp.linspace(0.02, dt, 20)

    @jax.jit
    def run(u):
        i = eqx.tree_at(lambda i: i.pressure_demand, inputs, gj.Constant(u))
        return plant.advance(y, i, 1.0, 1.0 + dt, ts)[1][0]

    delta = np.asarray(run(150e3 + du) - run(150e3))
    import control

    tl = np.concatenate([[0.0], np.asarray(ts) - 1.0])
    lin = control.forced_response(sys, T=tl, U=np.full(tl.size, du), X0=0).outputs[1:]
    assert delta[-1] > 1e-5  # the step speeds growth: the length gains ~tens of µm in 0.4 s
    np.testing.assert_allclose(delta, lin, rtol=0.05, atol=0.02 * np.max(np.abs(delta)))


@pytest.mark.slow
def test_optimised_profile_respects_limits_and_improves(target):
    p = gc.plant_params("forward", target)
    lim = gj.Limits(
        membrane_limit=float(gj.pressure_limit(p.robot)),
        pressure_ceiling=200e3,
        length_ceiling=float(p.robot.stroke),
        syringe_stroke=0.05,
        max_pump_speed=5e-3,
    )
    prof = gc.optimize_profile(p, target, T, knot_dt=0.3, iterations=3, lim=lim)
    assert prof.cost_history[-1] < prof.cost_history[0]
    assert np.all(prof.demand >= 0.0) and np.all(prof.demand <= lim.pressure_ceiling + 1e-6)
    tr = gc.simulate_profile(p, target, prof, gj.Config(t1=T))
    assert int(tr.status) == 0 and float(np.nanmax(tr.pressure)) < lim.membrane_limit
    disp = np.asarray(tr.syringe_displacement)
    assert np.all(np.abs(disp) < lim.syringe_stroke)
    assert np.max(np.abs(np.diff(disp) / np.diff(np.asarray(tr.time)))) < lim.max_pump_speed
    assert prof.rmse_m < 1e-3


def _pid(log_gains=gc.DEFAULT_LOG_GAINS):
    knots = jnp.asarray([0.0, T + 0.1])
    return gc.LengthPID(jnp.asarray(log_gains), knots, jnp.asarray([110e3, 110e3]))


def test_feedback_rejects_a_disturbance_the_open_loop_does_not(target):
    """An active-channel pull of 0.05 N (≈ 8 kPa on the membrane) slows the open-loop robot; the length loop holds."""
    base = gc.plant_params("forward", target)
    pid = _pid((7.7, 7.9, 4.5))
    out = {}
    for force in (0.0, 0.05):
        p = gj.with_effects(base, gj.effects.ActiveChannelForce(force=force))
        closed = gc.run_closed_loop(gc.Plant.make(p, gj.Config(t1=T)), pid, target, T)
        inputs = gj.Inputs(
            catheter_length=gc.catheter_signal(target),
            pressure_demand=gj.Sampled(
                np.concatenate([[0.0], closed.tick_time + pid.dt]), np.concatenate([[110e3], closed.command])
            ),
        )
        ts = target.time[target.time <= T]
        # the open loop replays the undisturbed closed loop's demand
        if force == 0.0:
            replay = inputs
        tr = gj.simulate(p, replay, gj.Config(t1=T), ts=ts)
        out[force] = (closed.rmse_m, gc.rmse(ts, np.asarray(tr.length), target), closed.pressure_limit_crossed)
    (c0, o0, x0), (c1, o1, x1) = out[0.0], out[0.05]
    assert not (x0 or x1)
    assert abs(o0 - c0) < 2e-4  # the replay reproduces the closed loop when nothing changes
    assert o1 > o0 + 3e-4  # the pull costs the open loop > 0.3 mm
    assert c1 < c0 + 0.5 * (o1 - o0)  # the loop removes more than half of that


@pytest.mark.slow
def test_tuning_reduces_the_cost_it_optimises(target):
    p = gc.plant_params("forward", target)
    cost = gc.pid_cost_fn(p, target, T, _pid())
    res = gc.tune_pid(cost, jnp.asarray([6.3, 6.0, 4.0]), iterations=2)
    assert res.cost_history[-1] < 0.9 * res.cost_history[0]
    assert res.cost_history[-1] == pytest.approx(float(cost(jnp.asarray(res.log_gains))), rel=1e-9)


def test_step_controller_steps_back_and_respects_the_step_rate():
    tg = gc.Target(
        np.arange(0.01, 2.0, 0.01), 0.010 + 6e-3 * np.sin(np.pi * np.arange(0.01, 2.0, 0.01) / 2.0) ** 2, np.zeros(199)
    )
    p = gc.plant_params("inverse", tg)
    ctrl = gc.StepController(rate=20.0, lead=0.05)
    res = gc.run_closed_loop(gc.Plant.make(p, gj.Config(drive="inverse", t1=2.0)), ctrl, tg, 2.0)
    steps = np.diff(np.concatenate([[0.0], res.command]))
    assert np.max(steps) >= 1 and np.min(steps) <= -1  # it steps forward and back
    assert np.max(np.abs(steps)) <= 1  # one step per tick, ticks at ≤ the motor's step rate
    # full steps place the robot on a 3.1 mm grid: the error is quantisation-bound (step/√12 ≈ 0.9 mm at best)
    assert res.rmse_m < 0.6 * gc.step_length(p) and not res.pressure_limit_crossed


def test_planned_step_schedule_replays_the_controller_on_the_model_and_respects_the_step_rate():
    """plan_steps' schedule, run blind on the model it was planned on, reproduces the closed loop there (the same
    steps at the same ticks), and it keeps one step per tick at most at the motor's step rate."""
    tg = _sine_target()
    p = gc.plant_params("inverse", tg)
    ctrl = gc.StepController(rate=20.0, lead=0.2)
    _, model_rmse, ticks, counts = gc.plan_steps(p, tg, 2.0, controller=ctrl)
    steps = np.diff(np.concatenate([[0.0], counts]))
    assert np.max(steps) >= 1 and np.min(steps) <= -1 and np.max(np.abs(steps)) <= 1
    assert np.all(np.diff(ticks) >= 1.0 / gj.limits(p).max_step_rate - 1e-12)
    ts = tg.time[tg.time <= 2.0]
    replay = gc.simulate_steps(p, tg, ticks, counts, gj.Config(drive="inverse", t1=2.0), ts)
    assert int(replay.status) == 0
    assert gc.rmse(ts, np.asarray(replay.length), tg) == pytest.approx(model_rmse, rel=0.02)


def _sine_target():
    t = np.arange(0.01, 2.0, 0.01)
    return gc.Target(t, 0.010 + 6e-3 * np.sin(np.pi * t / 2.0) ** 2, np.zeros(t.size))


def test_step_controller_holds_forward_steps_above_its_pressure_gate():
    tg = _sine_target()
    p = gc.plant_params("inverse", tg)
    gate = 60e3
    ctrl = gc.StepController(rate=20.0, lead=0.2, pressure_gate=gate)
    res = gc.run_closed_loop(gc.Plant.make(p, gj.Config(drive="inverse", t1=2.0)), ctrl, tg, 2.0)
    sub = res.time.size // res.tick_time.size  # samples per tick; the last one is the tick's end
    sensed = np.concatenate([[0.0], res.pressure[sub - 1 :: sub][:-1]])  # what each tick saw
    forward = np.diff(np.concatenate([[0.0], res.command])) > 0
    assert forward.any() and np.all(sensed[forward] < gate)
    held = (sensed >= gate) & (
        np.interp(res.tick_time + ctrl.lead, tg.time, tg.length)
        > np.interp(res.tick_time, res.time, res.length) + 0.5 * gc.step_length(p)
    )
    assert held.any()  # the gate did bind: it held steps the error asked for


def _step_runner(fidelity):
    tg = _sine_target()
    p = gc.plant_params("inverse", tg)
    cfg = gj.Config(fidelity=fidelity, drive="inverse", t1=1.2)
    ts, ticks = np.arange(0.05, 1.2, 0.05), np.array([0.0, 0.2, 0.4, 0.6])

    def run(params, counts):
        return np.asarray(gc.simulate_steps(params, tg, ticks, np.asarray(counts, float), cfg, ts).length)

    return p, run


def test_microstepping_driver_matches_full_steps_at_integers_and_resolves_between():
    p, run = _step_runner("fast")

    full = run(p, [1, 2, 3, 2])
    micro = run(gc.with_microstepping(p), [1, 2, 3, 2])
    assert np.max(np.abs(micro - full)) < 2e-5  # the same driver at every integer command
    quarter = run(gc.with_microstepping(p), [0.25, 0.5, 0.75, 0.5])
    half = run(gc.with_microstepping(p), [0.5, 1.0, 1.5, 1.0])
    # a fraction of a step moves the robot by less than the step, and more for a larger fraction
    assert quarter[-1] > quarter[0] + 3e-5
    assert quarter[-1] + 2e-4 < half[-1] and half[-1] + 5e-4 < full[-1]


@pytest.mark.slow
def test_microstepping_driver_is_the_same_in_both_configurations():
    """The reference configuration runs the same driver (slow: compiles the reference stepper, ~1 min)."""
    p, fast = _step_runner("fast")
    _, reference = _step_runner("reference")
    micro = gc.with_microstepping(p)
    a, b = fast(micro, [0.5, 1.0, 1.5, 1.0]), reference(micro, [0.5, 1.0, 1.5, 1.0])
    assert np.all(np.isfinite(b)) and np.max(np.abs(a - b)) < 5e-5  # the fast/reference agreement of full steps
    assert np.max(np.abs(b - reference(p, [0, 1, 1, 1]))) > 1e-4  # the reference did microstep (not round)


def test_posterior_draws_are_joint_seeded_and_only_model_parameters(tmp_path):
    import arviz_base as azb

    rng = np.random.default_rng(0)
    y = 8000.0 + 50.0 * rng.standard_normal((2, 40))
    post = {"Y": y, "ext": 10.0 * y, "sigma": np.full((2, 40), 1e-3), "length_model": rng.random((2, 40, 3))}
    path = tmp_path / "posterior.nc"
    azb.from_dict({"posterior": post}).to_netcdf(str(path))
    draws = gc.parameter_draws(16, 3, str(path))
    assert set(draws) == {"Y", "ext"}  # σ and derived sites are not model parameters
    np.testing.assert_array_equal(draws["ext"], 10.0 * draws["Y"])  # one draw index for every variable
    assert set(draws["Y"]) <= set(y.ravel())
    np.testing.assert_array_equal(gc.parameter_draws(16, 3, str(path))["Y"], draws["Y"])
    assert not np.array_equal(gc.parameter_draws(16, 4, str(path))["Y"], draws["Y"])
    assert set(gc.parameter_draws(4, 0, str(path), names=["Y"])) == {"Y"}
    with pytest.raises(ValueError, match="model parameters"):
        gc.parameter_draws(4, 0, str(path), names=["tip_speed"])


class _Designed(Exception):
    """Raised by a stand-in to stop a design once it has shown what it was given."""


def test_design_builds_its_plant_and_limits_from_base(target, monkeypatch):
    seen = {}

    def stop(params, target_, t1, **kw):
        seen["params"], seen["lim"] = params, kw["lim"]
        raise _Designed

    monkeypatch.setattr(cw, "optimize_profile", stop)
    reference = gj.reference("forward")
    changed = gj.replace(
        reference,
        Y=2.5 * float(gj.get(reference, "Y")),
        membrane_yield_stress=0.5 * float(gj.get(reference, "robot.membrane_yield_stress")),
    )
    for base, want in ((None, reference), (changed, changed)):
        with pytest.raises(_Designed):
            gc.design_controller(target, "forward", "open-loop", T, evaluate_on="fast", base=base)
        assert float(gj.get(seen["params"], "Y")) == float(gj.get(want, "Y"))
        assert float(gj.get(seen["params"], "initial_length")) == target.length[0]  # started on the target
        assert seen["lim"].membrane_limit == pytest.approx(float(gj.pressure_limit(want.robot)), rel=1e-12)
    assert seen["lim"].membrane_limit == pytest.approx(0.5 * float(gj.pressure_limit(reference.robot)), rel=1e-12)


def test_design_tunes_feedback_on_draws_of_the_rig_within_its_tolerances(target, monkeypatch):
    import types

    seen = {}

    def profile(params, target_, t1, **kw):
        return types.SimpleNamespace(wall_s=0.0, knots=np.array([0.0, T]), demand=np.array([110e3, 110e3]))

    def stop(base, target_, t1, pid, draws=None, lim=None):
        seen["base"], seen["draws"] = base, draws
        raise _Designed

    monkeypatch.setattr(cw, "optimize_profile", profile)
    monkeypatch.setattr(cw, "pid_cost_fn", stop)
    with pytest.raises(_Designed):
        gc.design_controller(
            target, "forward", "feedback", T, n_draws=64, seed=2, tolerances={"Kp": 0.1, "tank.length": 0.0}
        )
    draws = seen["draws"]
    assert set(draws) == {"pid.proportional"}  # the alias resolved, the zero tolerance dropped
    kp = float(gj.get(seen["base"], "pid.proportional"))
    spread = np.log(draws["pid.proportional"] / kp)
    assert spread.shape == (64,) and 0.07 < np.std(spread) < 0.13 and abs(np.mean(spread)) < 0.04
    with pytest.raises(_Designed):
        gc.design_controller(target, "forward", "feedback", T, n_draws=64, seed=2)
    assert seen["draws"] is None  # no tolerances: the rig as it is
    np.testing.assert_array_equal(
        rig_draws(64, seen["base"], {"Kp": 0.1}, seed=2)["pid.proportional"], draws["pid.proportional"]
    )  # seeded
    with pytest.raises(ValueError, match="feedback design only"):
        gc.design_controller(target, "forward", "mpc", T, tolerances={"Kp": 0.1})


@pytest.mark.slow
def test_design_on_a_changed_base_tracks_differently(target):
    """End to end (slow: two profile optimisations, ~1 min each on 2 cores): a stiffer robot needs another profile."""
    short = gc.Target(*(np.asarray(a)[target.time <= 0.6] for a in target))
    reference = gj.reference("forward")
    runs = [
        gc.design_controller(short, "forward", "open-loop", 0.6, iterations=1, evaluate_on="fast", base=base)
        for base in (None, gj.replace(reference, Y=30e3))
    ]
    assert runs[0]["profile"]["demand_Pa"] != runs[1]["profile"]["demand_Pa"]
    assert runs[1]["tracking_rmse_m"] > runs[0]["tracking_rmse_m"]
