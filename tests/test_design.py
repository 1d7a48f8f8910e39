"""Design of the next experiment: the criterion against a dense posterior, the design space's CSV, the limits
checked on simulation, the gradient against finite differences, the design against its baselines, the command."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import objective_differences

import growjax as gj
from growjax import cli
from growjax import design as gd
from growjax.calibration import default_range
from growjax.calibration import discrepancy as dc
from growjax.calibration import tolerance as tl
from growjax.data import experiment as ex

Y = "robot.yield_pressure"
DATA = "src/growjax/data/datasets/synthetic_forward.csv"


def _catheter():
    t = np.round(np.arange(0, 1001) * 0.01, 10)
    return gj.Sampled(jnp.asarray(t), jnp.asarray(0.004 + 0.004 * t))


HYPER = dc.Hyper.of(0.0, 1.0, 2e-4)  # white length noise of 0.2 mm, no discrepancy


def _knowledge(sd=0.03, tolerances=None):
    base = gj.replace(gj.reference("forward"), Y=9000.0)
    tol = tl.default_budget(base) if tolerances is None else tolerances
    hyper = dc.Hyper.of(1e-4, 0.8, 2e-4, 0.01)
    return gd.Knowledge(base, (Y,), np.array([[sd**2]]), tol, hyper, "test")


def test_criterion_is_the_dense_gaussian_posterior():
    """The information form (Kalman whitening, pressure rows, prior) equals the data-space conditioning of the joint
    Gaussian of (w, y) built from dense covariances."""
    rng = np.random.default_rng(0)
    n, m = 40, 4
    t = np.sort(rng.uniform(0.0, 4.0, n))
    hyper = dc.Hyper.of(3e-4, 0.7, 2e-4, 0.05)
    s = gd.Sensitivities(
        jnp.zeros(n),
        jnp.zeros(n),
        jnp.asarray(rng.normal(0, 1e-3, (n, m))),
        jnp.asarray(rng.normal(0, 2e3, (n, m))),
        jnp.asarray(True),
    )
    prior = np.diag([0.05, 0.2, 0.05, 0.02]) ** 2
    rem = rng.normal(0, 1e-4, (n, 3))
    for sensors, sigma_p in ((("length",), 1e3), (("length", "pressure"), 1.5e3)):
        pred = gd.posterior(
            s,
            t,
            hyper,
            np.linalg.inv(prior),
            np.diag([0.0, *np.diag(np.linalg.inv(prior))[1:]]),
            sensors,
            sigma_p,
            jnp.asarray(rem),
        )
        h = np.asarray(s.jac_length)
        r = dc.kernel(t, hyper) + dc.noise_kernel(t, hyper)
        v = rem
        if "pressure" in sensors:
            h = np.concatenate([h, np.asarray(s.jac_pressure)])
            r = np.block([[r, np.zeros((n, n))], [np.zeros((n, n)), sigma_p**2 * np.eye(n)]])
            v = np.concatenate([rem, np.zeros((n, 3))])
        dense = prior - prior @ h.T @ np.linalg.solve(h @ prior @ h.T + r, h @ prior)
        np.testing.assert_allclose(np.asarray(pred.covariance_linear), dense, rtol=1e-6, atol=1e-14)
        # the rig's nonlinearity: the estimator's gain (a linear map of the data) applied to the remainder
        gain = dense @ h.T @ np.linalg.inv(r)
        sandwich = dense + gain @ (v @ v.T / 3) @ gain.T
        np.testing.assert_allclose(np.asarray(pred.covariance), sandwich, rtol=1e-6, atol=1e-14)
    # Alone: no prior on θ, so Y's variance is that of the data with the rig integrated out.
    assert float(pred.covariance_alone[0, 0]) > float(pred.covariance[0, 0])
    cov = jnp.asarray([[4.0, 1.0], [1.0, 9.0]])
    assert float(gd.AOptimal()(cov)) == pytest.approx(np.log(13.0))
    assert float(gd.DOptimal()(cov)) == pytest.approx(np.log(35.0))
    with pytest.raises(ValueError, match="sensors"):
        gd.information(s, t, hyper, ("pressure",))


def test_knowledge_from_a_saved_fit(tmp_path):
    base = gj.reference("forward")
    saved = tmp_path / "fit.json"
    saved.write_text(
        json.dumps(
            {
                "parameters": {
                    Y: {"estimate": 8000.0, "standard_error": 160.0},
                    "robot.extensibility": {"estimate": 0.03, "standard_error": None},
                    "robot.growth_exponent": {"estimate": 0.64, "standard_error": 25.0},
                },
                "discrepancy": {
                    "kind": "matern32",
                    "amplitude_m": 5e-4,
                    "time_scale_s": 1.0,
                    "noise_m": 2e-4,
                    "noise_time_s": 0.0,
                },
                "tolerances": {"pid.proportional": 0.05},
            }
        )
    )
    known = gd.from_summary(saved, base, ["Y", "ext"])
    assert known.estimate[0] == 8000.0 and known.rig == ("pid.proportional",)
    assert np.sqrt(known.covariance[0, 0]) == pytest.approx(0.02)
    lo, hi = default_range(base, "robot.extensibility")
    assert known.covariance[1, 1] == pytest.approx(np.log(hi / lo) ** 2 / 12)  # undetermined: its box,
    assert known.estimate[1] == pytest.approx(np.sqrt(lo * hi))  # centred there, not at the fit's arbitrary value
    lo, hi = default_range(base, "robot.growth_exponent")
    wide = gd.from_summary(saved, base, ["Y", "n"])  # an interval wider than the box says less than the box
    assert wide.estimate[1] == pytest.approx(np.sqrt(lo * hi)) and wide.covariance[1, 1] == pytest.approx(
        np.log(hi / lo) ** 2 / 12
    )
    assert float(known.hyper.amplitude) == 5e-4
    assert known.prior_precision(False)[0, 0] == 0.0 and known.prior_precision(True)[0, 0] == pytest.approx(1 / 0.02**2)
    with pytest.raises(ValueError, match="did not fit pid.proportional"):
        gd.from_summary(saved, base, ["pid.proportional"])
    with pytest.raises(ValueError, match="unknown"):
        gd.from_summary(saved, base, ["no_such_parameter"])


def test_a_design_is_written_in_the_rigs_terms(tmp_path):
    exp = ex.read(DATA)
    space = gd.DesignSpace(12.0, 300e3, gd.catheter_of(exp, 12.0), knot_spacing=0.5)
    assert space.size == 24 and space.knots.size == 25 and space.times[0] == 0.01 and space.times[-1] == 12.0
    demand = np.linspace(0.0, 300e3, space.size + 1)
    x = space.unconstrained(demand)
    np.testing.assert_allclose(np.asarray(space.demand(x)), [0.0, *np.clip(demand[1:], 0.3, 300e3 - 0.3)], rtol=1e-9)
    path = space.write_csv(tmp_path / "design.csv", x)
    back = ex.read(path)
    assert "robot_length_m" not in back and back.time[0] == 0.0 and back.time[-1] == 12.0
    inputs = ex.to_inputs(back, "forward", gj.reference("forward"), t1=12.0)
    ts = jnp.asarray(space.times)
    np.testing.assert_allclose(
        np.asarray(jax.vmap(inputs.pressure_demand)(ts)),
        np.asarray(jax.vmap(space.inputs(x).pressure_demand)(ts)),
        rtol=1e-9,
        atol=1e-6,
    )
    # The catheter follows the experiment already run, held at its last value after its end (10 s).
    cath = np.asarray(jax.vmap(inputs.catheter_length)(jnp.asarray([5.0, 10.0, 11.5])))
    np.testing.assert_allclose(cath, [0.024, 0.044, 0.044], atol=1e-12)
    for bad in ({"duration": 0.0}, {"duration": -1.0}, {"p_max": 0.0}, {"knot_spacing": 20.0}):
        with pytest.raises(ValueError):
            gd.DesignSpace(**{"duration": 3.0, "p_max": 1e5, "catheter": gj.Constant(0.0), **bad})


def test_the_random_batchs_summary_counts_apart_the_inputs_without_a_criterion():
    """A random input without a criterion (inf or NaN: the model failed, or the input informs nothing where the
    prior is flat) is counted apart, and is never the best; the quantiles are those of the others."""
    from types import SimpleNamespace

    from growjax.design import optimise as dopt
    from growjax.design.workflow import DesignResult

    batch = dopt.RandomBatch(np.zeros((5, 2)), np.array([np.nan, -3.0, np.inf, -1.0, -2.0]), drawn=9, wall_s=1.0)
    result = DesignResult(
        ("robot.yield_pressure",),
        np.ones(1),
        gd.DesignSpace(1.0, 1e5, gj.Constant(0.0)),
        np.zeros(2),
        np.zeros(3),
        np.zeros(3),
        rows=[],
        checks={},
        random=batch,
        descents=[],
        limits=SimpleNamespace(summary=dict),
        criterion="A",
        sensors=("length",),
        knowledge={},
        wall_s={},
    )
    r = result.summary()["random"]
    assert r["criterion_undefined"] == 2 and r["criterion_best"] == -3.0 and batch.best == 1
    assert r["criterion_quantiles"] == {"0.1": pytest.approx(-2.8), "0.5": -2.0, "0.9": pytest.approx(-1.2)}


def test_a_singular_precision_gives_no_covariance_instead_of_an_error():
    """Information on one direction only, and a flat prior on the other: the precision cannot be inverted, and the
    covariances are NaN (the criterion then NaN, the input flagged), not a LinAlgError that sinks the batch."""
    from types import SimpleNamespace

    from growjax.design import problem as dprob

    info = np.zeros((3, 2, 2))
    info[:, 0, 0] = 1.0
    none = np.zeros((2, 0))
    flat = SimpleNamespace(precision_known=np.zeros((2, 2)), precision_alone=np.zeros((2, 2)))
    out = dprob.covariances(flat, info, info, none, ("length",))
    assert all(np.all(np.isnan(c)) for c in out.values())
    prior = SimpleNamespace(precision_known=np.eye(2), precision_alone=np.eye(2))
    np.testing.assert_allclose(dprob.covariances(prior, info, info, none, ("length",))["known"], np.diag([0.5, 1.0]))


class EOptimal(gd.Criterion):
    """E-optimality, defined here and nowhere in the package: the log of the covariance's largest eigenvalue (the
    relative variance of the worst-determined combination of ln θ)."""

    name = "E"

    def __call__(self, covariance):
        return jnp.log(jnp.linalg.eigvalsh(covariance)[-1])


def test_a_criterion_defined_outside_the_package_runs_through_the_design():
    """A new criterion is one subclass of gd.Criterion: the design minimises it and its table reports it, the log
    of the largest eigenvalue of the predicted covariance of the two parameters of interest; its summary names it."""
    from growjax.design import problem as dprob

    base = gj.replace(gj.reference("forward"), Y=9000.0)
    names = (Y, "robot.catheter_friction")  # the data inform both, Y's relative variance the smaller by ~20×
    known = gd.Knowledge(base, names, np.diag([0.03, 0.05]) ** 2, {"pid.proportional": 0.05}, HYPER, "test")
    space = gd.DesignSpace(1.0, 336e3, _catheter(), knot_spacing=0.5)
    res = gd.design(known, space, EOptimal(), random=2, iterations=1, n_draws=2, points=1, nonlinear_draws=0)
    assert res.summary()["criterion"] == "E"
    problem = gd.make(known, space, EOptimal(), points=1, nonlinear_draws=0)
    crit = {r["input"]: r["criterion"] for r in res.rows}
    best_random = res.random.designs[res.random.best]
    for label, inputs in (("design", space.inputs(res.x)), ("best random input", space.inputs(best_random))):
        info_l, info_p, cross = dprob.information(problem, inputs, problem.breaks)[:3]
        cov = dprob.covariances(problem, info_l, info_p, cross, ("length",))["known"][:2, :2]
        largest = np.linalg.eigvalsh(cov)[-1]
        assert crit[label] == pytest.approx(np.log(largest), rel=1e-9, abs=1e-12)
        assert np.log(np.trace(cov)) > crit[label] + 0.01  # not the A-criterion (there Y's variance adds ~5 %)
        sd = [r["parameters"] for r in res.rows if r["input"] == label][0]
        np.testing.assert_allclose([sd[n]["sd_log"] for n in names], np.sqrt(np.diag(cov)), rtol=1e-9)
    assert crit["design"] <= crit["best random input"]  # the search minimised it
    with pytest.raises(TypeError, match="criterion must be a growjax.design.Criterion"):
        gd.make(known, space, "E")


def test_the_check_flags_exactly_the_inputs_that_cross_a_limit_on_simulation():
    known = _knowledge()
    space = gd.DesignSpace(2.0, 336e3, _catheter(), knot_spacing=1.0)
    membrane = float(gj.pressure_limit(known.base.robot))
    lim = gj.Limits(membrane_limit=membrane, pressure_ceiling=200e3, length_ceiling=0.015, syringe_stroke=0.05)
    drawn = gd.draws(known, 3, seed=1)
    assert set(drawn) == {Y, *known.tolerances} and all(v.shape == (3,) for v in drawn.values())
    designs = [space.unconstrained(np.full(space.size + 1, v)) for v in (60e3, 150e3, 250e3)]
    res = gd.check(
        gd.stack([space.inputs(x) for x in designs]),
        known,
        space.config(),
        space.times,
        space.breaks(),
        lim,
        drawn,
        keep_runs=True,
    )
    # on its own simulation of every draw: the peaks the check reports, and the verdict they imply
    config = space.config()
    for i, x in enumerate(designs):
        peaks_p, peaks_l = [], []
        for d in range(3):
            p = gj.replace(known.base, **{k: float(v[d]) for k, v in drawn.items()})
            tr = gj.simulate(p, space.inputs(x), config, ts=space.times)
            assert int(tr.status) == gj.OK
            peaks_p.append(float(jnp.max(tr.pressure)))
            peaks_l.append(float(jnp.max(tr.length)))
        assert res.peak_pressure[i] == pytest.approx(max(peaks_p), rel=1e-4)  # a batch steps its runs together
        assert res.peak_length[i] == pytest.approx(max(peaks_l), rel=1e-4)
        assert bool(res.admissible[i]) == (max(peaks_p) <= lim.pressure_ceiling and max(peaks_l) <= lim.length_ceiling)
    assert res.admissible.tolist() == [True, False, False]  # 150 kPa grows past 15 mm; 250 kPa crosses 200 kPa too
    assert res.peak_pressure[2] > lim.pressure_ceiling > res.peak_pressure[1]
    assert res.length.shape == (3, 3, space.times.size)


def test_design_command_refuses_bad_input_with_exit_2(capsys, tmp_path):
    for argv, message in (
        (["--for", "Y", "no_such_parameter"], "no_such_parameter"),
        (["--duration", "0"], "--duration"),
        (["--p-max", "400e3"], "above the sensed-pressure ceiling"),
        (["--next-drive", "inverse", "--p-max", "200e3"], "the stepper's schedule has neither"),
        (
            ["--next-drive", "inverse", "--discriminate", "retraction_folding", "trapped_air"],
            "drop --next-drive inverse",
        ),
        (["--knot-spacing", "20", "--duration", "5"], "knot spacing"),
        (["--fit-from", "/nonexistent/fit.json"], "cannot read the saved fit"),
    ):
        try:
            status = cli.main(["design", DATA, "--out", str(tmp_path / "never"), *argv])
        except SystemExit as stop:  # argparse's own checks
            status = stop.code
        assert status == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err, (argv, err)
    assert not (tmp_path / "never").exists()  # refused before any work


def test_a_stepper_schedule_is_written_as_the_desired_length_the_controller_turns_back_into_it(tmp_path):
    """The stepper's design space: every schedule steps at most once per controller period, never below a count of
    0; its CSV, read back and run through the shipped position controller, issues exactly the designed steps; the
    baseline is the controller's own schedule for the recorded length."""
    base = gj.reference("inverse")
    exp = ex.read(DATA, catheter=True)
    space = gd.stepper_space(base, 4.0, exp)
    assert space.size == 12 and np.allclose(np.diff(space.edges)[1:], 1 / 3)  # 3 Hz, the first edge after t0
    rng = np.random.default_rng(0)
    xs = space.random(6, rng)
    baseline = space.baseline()
    scaled = space.scaled(xs[0], 0.7)
    moved = gd.neighbours(space, baseline)
    for x in [baseline, *xs, scaled, *moved[:5]]:
        assert set(np.unique(x)) <= {-1.0, 0.0, 1.0} and np.all(np.cumsum(x) >= 0)
        space.write_csv(tmp_path / "s.csv", x)
        inputs = ex.to_inputs(ex.read(tmp_path / "s.csv", catheter=True), "inverse", base, 0.001, 4.0)
        after = jnp.asarray(np.append(space.edges + 1e-6, 3.999))
        issued, designed = (np.asarray(jax.vmap(i.steps)(after)) for i in (inputs, space.inputs(x)))
        np.testing.assert_array_equal(issued, designed)
    # the recorded length as the desired length: what the shipped model's stepper does with it
    shipped = ex.to_inputs(exp, "inverse", base, 0.001, 4.0).steps
    np.testing.assert_array_equal(
        np.asarray(jax.vmap(shipped)(after)), np.asarray(jax.vmap(space.inputs(baseline).steps)(after))
    )
    assert np.sum(baseline) > 0 and np.all(np.cumsum(scaled) <= np.cumsum(xs[0]))
    assert len(moved) == len({m.tobytes() for m in moved}) and np.all(np.sum(moved != baseline, axis=1) <= 2)


@pytest.fixture(scope="module")
def short_problem():
    known = _knowledge(sd=0.03, tolerances={"robot.catheter_friction": 0.2, "pid.proportional": 0.05})
    space = gd.DesignSpace(2.0, 336e3, _catheter(), knot_spacing=0.5)
    return known, space


@pytest.mark.slow
@pytest.mark.parametrize("nonlinear_draws", [0, 2])
def test_the_criterions_gradient_through_the_model_matches_finite_differences(short_problem, nonlinear_draws):
    """Through the linearised covariances alone and with the remainder's solves at drawn rigs (the objective the
    search and the table share)."""
    known, space = short_problem
    problem = gd.make(
        known, space, points=2, nonlinear_draws=nonlinear_draws, seed=0, config=gj.Config(rtol=1e-7, atol=1e-7)
    )
    x = space.unconstrained(np.array([0.0, 90e3, 60e3, 120e3, 80e3]))
    value, grad = (np.asarray(a) for a in gd.value_and_gradient(problem, x))
    assert value == pytest.approx(float(sum(gd.evaluate(problem, x))), rel=1e-5)  # two programs: rounding
    fd = objective_differences(lambda y: sum(gd.evaluate(problem, y)), x)
    # The knots after the first: the exact derivative is the difference quotient's. The first (0.5 s) sets when the
    # pressure crosses the growth threshold, a switch the model smooths over a band far narrower than 1e-3 of a
    # logit: there the exact derivative is the band's, and the descent follows differences over a step of the
    # demand instead (smoothed_gradient).
    np.testing.assert_allclose(grad[1:], fd[1:], rtol=0.02)
    assert np.min(np.abs(fd[1:])) > 1e-3  # the criterion does move with the input
    _, smooth = gd.smoothed_gradient(problem, x, workers=1)
    assert np.all(np.sign(smooth) == np.sign(fd))


@pytest.mark.slow
def test_the_design_beats_the_published_pulse_and_the_best_random_input_and_is_admissible():
    known = gd.Knowledge(
        gj.replace(gj.reference("forward"), Y=9000.0),
        (Y,),
        np.array([[0.02**2]]),
        {"robot.catheter_friction": 0.2, "pid.proportional": 0.05},
        dc.Hyper.of(0.0, 1.0, 2e-4),
        "test",
    )
    space = gd.DesignSpace(3.0, 336e3, _catheter(), knot_spacing=0.5)
    res = gd.design(known, space, random=6, starts=1, iterations=6, n_draws=4, seed=0, points=2, nonlinear_draws=2)
    crit = {r["input"]: r["criterion"] for r in res.rows}
    assert crit["design"] < crit["best random input"] and crit["design"] < crit["published pulse train"], crit
    # one criterion: what the search minimised is what the table reports, the rig's nonlinearity included
    problem = gd.make(known, space, points=2, seed=0, nonlinear_draws=2)
    assert float(gd.evaluate(problem, res.x)[0]) == pytest.approx(crit["design"], rel=1e-4)  # two programs: rounding
    linear = gd.make(known, space, points=2, seed=0, nonlinear_draws=0)
    assert float(gd.evaluate(linear, res.x)[0]) < crit["design"] - 1e-3, float(gd.evaluate(linear, res.x)[0])
    assert res.descents[0].value <= res.descents[0].history[0]  # never worse than its start, the best random input
    sd = {r["input"]: r["parameters"][Y]["sd_log"] for r in res.rows}
    assert sd["design"] < sd["best random input"] and sd["design"] < sd["published pulse train"]
    # every admissible input, the design's included, stays inside the limits on simulation over fresh draws
    drawn = gd.draws(known, 4, seed=7)
    lim = res.limits
    for x in [res.x, *res.random.designs]:
        for d in range(4):
            p = gj.replace(known.base, **{k: float(v[d]) for k, v in drawn.items()})
            tr = gj.simulate(p, space.inputs(x), space.config(), ts=space.times)
            assert int(tr.status) == gj.OK
            assert (
                float(jnp.max(tr.pressure)) <= lim.pressure_ceiling and float(jnp.max(tr.length)) <= lim.length_ceiling
            )


@pytest.mark.slow
def test_design_command_writes_a_csv_that_simulate_reads(tmp_path, capsys):
    saved = tmp_path / "fit.json"
    saved.write_text(
        json.dumps(
            {
                "parameters": {Y: {"estimate": 9000.0, "standard_error": 200.0}},
                "discrepancy": {"amplitude_m": 3e-5, "time_scale_s": 2.0, "noise_m": 2e-4},
                "tolerances": {"robot.catheter_friction": 0.2},
            }
        )
    )
    out = tmp_path / "design"
    argv = [
        "design",
        DATA,
        "--fit-from",
        str(saved),
        "--duration",
        "2",
        "--knot-spacing",
        "1",
        "--random",
        "3",
        "--starts",
        "1",
        "--iterations",
        "2",
        "--draws",
        "3",
        "--points",
        "1",
        "--nonlinear-draws",
        "2",
        "--sensors",
        "length,pressure",
        "--out",
        str(out),
        "--quiet",
    ]
    assert cli.main(argv) == 0
    text = capsys.readouterr().out
    assert "published pulse train" in text and "best random input" in text and "length+pressure" in text
    summary = json.loads((out / "summary.json").read_text())
    assert {(r["input"], tuple(r["sensors"])) for r in summary["table"]} == {
        (i, s)
        for i in ("published pulse train", "best random input", "design")
        for s in (("length",), ("length", "pressure"))
    }
    assert (out / "design.png").stat().st_size > 10_000
    assert cli.main(["simulate", str(out / "design.csv"), "--t-end", "2", "--out", str(tmp_path / "sim")]) == 0
    traj = ex.read(tmp_path / "sim" / "trajectory.csv")
    assert np.max(traj["pressure_Pa"]) <= summary["limits"]["pressure_ceiling_Pa"]


@pytest.mark.slow
def test_a_stepper_design_beats_the_recorded_length_and_the_best_random_schedule_and_is_admissible(tmp_path):
    """The stepper's schedule designed for Y (what is known carried over from a forward fit); its CSV runs through
    ``growjax simulate --drive inverse`` inside the limits."""
    base = gj.reference("inverse")
    tolerances = {"robot.catheter_friction": 0.2, "pump.screw_viscous_friction": 0.2}
    known = _knowledge(sd=0.02, tolerances=tolerances).on(base)
    assert float(gj.get(known.base, Y)) == 9000.0 and known.base.motor.controller_rate == base.motor.controller_rate
    space = gd.stepper_space(base, 3.0, ex.read(DATA, catheter=True))
    res = gd.design(known, space, random=6, iterations=3, n_draws=4, seed=0, points=2, nonlinear_draws=2)
    crit = {r["input"]: r["criterion"] for r in res.rows}
    assert crit["design"] < crit["best random input"] and crit["design"] < crit["recorded length as demand"], crit
    assert res.descents[0].value < res.descents[0].history[0]  # the local search moved off its start
    assert set(np.unique(res.x)) <= {-1.0, 0.0, 1.0} and res.checks["design"].row(0)["admissible"]
    summary = res.summary()
    assert summary["drive"] == "inverse" and len(summary["design"]["steps"]) == space.size
    space.write_csv(tmp_path / "design.csv", res.x)
    assert (
        cli.main(
            [
                "simulate",
                str(tmp_path / "design.csv"),
                "--drive",
                "inverse",
                "--t-end",
                "3",
                "--out",
                str(tmp_path / "sim"),
            ]
        )
        == 0
    )
    traj = ex.read(tmp_path / "sim" / "trajectory.csv")
    assert (
        np.max(traj["pressure_Pa"]) <= res.limits.pressure_ceiling
        and np.max(traj["robot_length_m"]) <= res.limits.length_ceiling
    )
