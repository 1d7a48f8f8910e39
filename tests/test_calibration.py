"""Calibration: recovery of known parameters by the fit, NUTS diagnostics and posterior coverage on a test problem."""

import sys

import numpy as np
import pytest
from conftest import REPO, one_experiment

import growjax as gj
from growjax import calibration as cal
from growjax import posterior as gpost
from growjax.data import experiment as ex
from growjax.model import params as gp

TRUTH_Y = 9000.0
NOISE = 2e-4  # m

sys.path.insert(0, str(REPO / "data"))
import make_synthetic as mk


def _synthetic(t1, seed):
    """Length data made by the fast configuration itself (Y = 9 kPa, σ = 0.2 mm): any bias is the estimator's.

    For the sampler's own checks only; fits are judged on reference-made data below."""
    cfg = gj.Config(t1=t1)
    inputs = mk.reference_inputs("published")
    traj = gj.simulate(gj.replace(gj.reference(), Y=TRUTH_Y), inputs, cfg)
    times = np.arange(0.01, t1 + 1e-9, 0.01)
    clean = np.interp(times, np.asarray(traj.time), np.asarray(traj.length))
    return cfg, inputs, times, clean + np.random.default_rng(seed).normal(0.0, NOISE, times.size)


GRID = ["published_Y6000", "published_Y7920", "published_Y10000", "published_Y12000", "published_Y14000"]


@pytest.mark.parametrize(
    "grid, least", [((0, 2, 4), 2), pytest.param(range(5), 4, marks=pytest.mark.slow)], ids=["three", "five"]
)
def test_fit_intervals_cover_the_truth_on_data_made_by_the_reference(grid, least):
    """Y across the paper's box (three of the five by default), 10 s, noise 0.2 mm: the fast model's 90 % intervals
    (noise and its measured model error) cover at least ``least`` of them. Each fit starts at the published Y
    (sweep_n=0), up to 0.6 in ln Y away."""
    time, lengths, cases = mk.read_reference_lengths()
    inputs = mk.reference_inputs("published")
    covered, errors = 0, []
    for k in grid:
        name = GRID[k]
        truth = cases[name]["parameters"]["Y"]
        data = lengths[name] + np.random.default_rng(100 + k).normal(0.0, NOISE, time.size)
        res = cal.fit(
            one_experiment(time, data, inputs),
            ["Y"],
            likelihood=cal.Likelihood(sigma_length=NOISE),
            config=gj.Config(t1=10.0),
            starts=1,
            scout=0,
        )
        lo, hi = res.interval_90["robot.yield_pressure"]
        covered += lo < truth < hi
        errors.append((res.estimate["robot.yield_pressure"] - truth) / res.standard_error["robot.yield_pressure"])
        assert res.status == "converged"
        assert res.rmse_length_m == pytest.approx(NOISE, rel=0.1)  # the fit reaches the noise, no further
    assert covered >= least, errors
    assert np.max(np.abs(errors)) < 3.5, errors  # no estimate far outside its interval


def test_a_direction_the_data_do_not_inform_is_undetermined_even_alone():
    """Relative to the best-informed direction, and in absolute terms: a single free parameter whose information on
    ln θ is ~0 (Y run to ~0 Pa, where it no longer acts) gets no interval, rather than the pseudo-inverse's zero."""
    names = ("robot.yield_pressure", "robot.extensibility")
    assert cal.undetermined_directions(np.array([[3e-13]]), names[:1])[1].tolist() == [True]
    assert cal.undetermined_directions(np.array([[2e3]]), names[:1])[1].tolist() == [False]  # ±2.2 % of Y
    assert cal.undetermined_directions(np.array([[2 * cal.INFORMATION_FLOOR]]), names[:1])[1].tolist() == [False]
    rotated, blind = cal.undetermined_directions(np.array([[4e4, 0.0], [0.0, 1e-8]]), names)
    assert blind.tolist() == [False, True] and len(rotated) == 1
    assert abs(rotated[0]["direction"]["robot.extensibility"]) == pytest.approx(1.0)


def _less_air(amplitude: float, seed: int, truth: float):
    """A 2 s run of the fast model under a pulse train of ``amplitude`` Pa with the trapped-air effect's extra air
    fraction at ``truth`` (less air than nominal for a negative one): its length (0.2 mm noise) and pressure
    (500 Pa noise), a `growjax.data.sets.Run` with the inputs it ran."""
    from growjax.data import sets as xs

    cfg = gj.Config(t1=2.0)
    inputs = gj.Inputs(catheter_length=gj.Constant(0.004), pressure_demand=gj.PulseTrain(amplitude=amplitude))
    made = gj.with_effects(gj.reference(), gj.effects.TrappedAir(extra_fraction=truth))
    times = np.arange(0.01, 2.0 + 1e-9, 0.01)
    traj = gj.simulate(made, inputs, cfg, ts=times)
    rng = np.random.default_rng(seed)
    exp = ex.from_arrays(
        times,
        np.asarray(traj.length) + rng.normal(0.0, NOISE, times.size),
        np.asarray(traj.pressure) + rng.normal(0.0, 500.0, times.size),
    )
    return xs.Run(f"pulse {amplitude / 1e3:.0f} kPa", exp, sensors=("length", "pressure"), inputs=inputs)


def test_a_signed_parameter_is_drawn_linearly_about_its_nominal_value():
    """The trapped-air effect's extra air fraction may be negative: its range straddles zero and a scout draws it
    linearly about its nominal value (the fits themselves: the slow test below, and `tests/test_discover_set.py`,
    which names less air than nominal from one experiment and from two)."""
    name = "trapped_air.extra_fraction"
    base = gj.with_effects(gj.reference(), gj.effects.TrappedAir())
    assert cal.default_range(base, name) == (-0.005, 0.05)
    np.testing.assert_allclose(cal.sampling_box(base, [name], [0.0]), [[-0.1], [1.0]])


@pytest.mark.slow  # a companion of the discovery test of less air than nominal: ~70 s of compiling
def test_a_signed_parameter_is_fitted_below_its_nominal_value_alone_and_in_a_set():
    """The trapped-air effect's extra air fraction may be negative (less air than the base model's): it is fitted in
    a linear coordinate, not in ln θ, and on data made with less air than nominal its estimate is negative with a
    90 % interval (symmetric about it) that covers the truth, from one experiment and, narrower, from two."""
    from growjax.data import sets as xs

    truth, name = -0.003, "trapped_air.extra_fraction"
    runs = (_less_air(150e3, 1, truth), _less_air(100e3, 2, truth))
    options = dict(
        likelihood=cal.Likelihood(discrepancy="none", tolerances={}),
        config=gj.Config(t1=2.0),
        effects=(gj.effects.TrappedAir(),),  # at its nominal value, no extra air: the start
        scout=0,
    )
    base = gj.with_effects(gj.reference(), gj.effects.TrappedAir())
    assert cal.default_range(base, name) == (-0.005, 0.05)  # a scout draws over its range, linearly
    np.testing.assert_allclose(cal.sampling_box(base, [name], [0.0]), [[-0.1], [1.0]])
    widths = []
    for exps in (xs.ExperimentSet(runs[:1]), xs.ExperimentSet(runs)):
        res = cal.fit(exps, [name], **options)
        lo, hi = res.interval_90[name]
        assert res.coordinate(name).scale == 0.05 and res.summary()["parameters"][name]["coordinate"] == "linear"
        assert res.status == "converged" and res.estimate[name] < 0.0
        assert lo < truth < hi and hi - res.estimate[name] == pytest.approx(res.estimate[name] - lo)
        widths.append(hi - lo)
    assert widths[1] < widths[0]


@pytest.mark.slow
def test_fit_names_ext_and_n_as_undetermined():
    cfg, inputs, times, length = _synthetic(2.0, seed=12)
    res = cal.fit(one_experiment(times, length, inputs), ["Y", "ext", "n"], config=cfg, starts=2, scout=16)
    assert abs(res.estimate["robot.yield_pressure"] - TRUTH_Y) < 0.01 * TRUTH_Y
    assert len(res.undetermined) == 2
    assert res.interval_90["robot.extensibility"] is None and res.interval_90["robot.growth_exponent"] is None
    assert res.interval_90["robot.yield_pressure"] is not None
    ranges = gp.physical_ranges(gj.reference())
    for name in ("robot.extensibility", "robot.growth_exponent"):  # undetermined, yet inside its physical range
        assert ranges[name][0] <= res.estimate[name] <= ranges[name][1]


@pytest.mark.slow
def test_nuts_on_reference_made_data_is_converged_and_covers_the_reference_estimate(synthetic_experiment):
    """Direct NUTS through the fast model on the shipped reference-made experiment (Y = 9 kPa), first 0.8 s.

    Over 0.8 s the length says little about Y, and this seed's noise puts the
    reference configuration's own maximum-likelihood Y more than 2 standard errors above the truth: no model can cover
    9000 Pa from these data. What the fast model must do is infer what the reference would: its interval must
    cover the reference configuration's estimate (found here on a grid of Y)."""
    exp = synthetic_experiment.window(0.8)
    cfg = gj.Config(t1=0.8)
    inputs = ex.to_inputs(exp, "forward", gj.reference(), cfg.t0, cfg.t1)
    times, length = exp.time, exp["robot_length_m"]
    ref_cfg = gj.Config(t1=0.8, fidelity="reference", rtol=1e-7)
    grid = np.linspace(8800.0, 9800.0, 11)
    sse = [
        float(
            np.sum(
                (np.asarray(gj.simulate(gj.replace(gj.reference(), Y=y), inputs, ref_cfg, ts=times).length) - length)
                ** 2
            )
        )
        for y in grid
    ]
    a, b, _ = np.polyfit(grid, sse, 2)
    y_reference, se_reference = -b / (2 * a), NOISE / np.sqrt(a)
    assert (y_reference - TRUTH_Y) / se_reference > 2.0  # the noise draw, not the model, moves Y off the truth
    priors = gpost.paper_priors()[:1]
    res = gpost.sample(
        one_experiment(times, length, inputs),
        config=cfg,
        priors=priors,
        chains=2,
        warmup=80,
        samples=80,
        seed=3,
        progress=False,
    )
    s = res.summary
    assert s["divergences"] == 0
    assert s["rhat_max"] < 1.05
    assert s["ess_bulk_min"] > 40
    lo, hi = s["parameters"]["Y"]["interval_90"]
    print(f"reference estimate {y_reference:.0f} ± {se_reference:.0f} Pa; NUTS (fast) 90 % {lo:.0f}–{hi:.0f} Pa")
    assert lo < y_reference < hi
    assert abs(s["parameters"]["Y"]["mean"] - y_reference) < 0.5 * se_reference
    assert s["parameters"]["sigma"]["mean"] == pytest.approx(NOISE, rel=0.2)
    assert 0.8 < s["coverage_90"] < 0.98
    # A new input: a 100 kPa pulse grows the robot less than the 150 kPa one, with a band that is not degenerate.
    weak = gj.Inputs(catheter_length=inputs.catheter_length, pressure_demand=gj.PulseTrain(amplitude=100e3))
    draws = gpost.predict(res.idata, priors, gj.reference(), weak, cfg, times, max_draws=50)
    lo_b, hi_b = gpost.predictive_band(draws)
    assert np.all(hi_b[-10:] > lo_b[-10:])
    assert np.median(draws[:, -1]) < np.median(length[-5:])


def test_simulation_based_calibration_of_nuts_covers_at_the_nominal_rate():
    from scipy import stats

    from growjax.posterior import emulator as em

    cfg, inputs, times, _ = _synthetic(0.8, seed=14)
    emu = em.build([em.Axis("Y", 5e3, 15e3, 41)], gj.reference(), inputs, cfg, times)
    res = gpost.sbc(emu, gpost.paper_priors()[:1], replicates=100, warmup=150, samples=150, seed=0)
    assert res["divergences"] == 0
    for site in ("Y", "sigma"):
        assert 0.8 <= res["coverage"][site] <= 0.97, (site, res["coverage"][site])
        hist = np.histogram(res["ranks"][site], bins=5, range=(0, res["draws"] + 1))[0]
        assert stats.chisquare(hist).pvalue > 1e-3, (site, hist)  # ranks of the truth are uniform


@pytest.mark.slow
def test_emulated_and_direct_posteriors_agree_on_the_test_problem():
    cfg, inputs, times, length = _synthetic(0.8, seed=13)
    priors = gpost.paper_priors()[:1]
    kw = {"config": cfg, "priors": priors, "chains": 2, "warmup": 150, "samples": 150, "seed": 3, "progress": False}
    emulated = gpost.sample(one_experiment(times, length, inputs), **kw).summary["parameters"]["Y"]
    direct = gpost.sample(one_experiment(times, length, inputs), emulate=False, **kw).summary["parameters"]["Y"]
    assert emulated["mean"] == pytest.approx(direct["mean"], abs=0.3 * direct["sd"])
    assert emulated["sd"] == pytest.approx(direct["sd"], rel=0.2)


def _numeric(residuals):
    """``linearised`` for `growjax.calibration.levenberg_marquardt` from NumPy residuals (forward differences)."""

    def linearised(z):
        z = np.asarray(z, float)
        r = residuals(z)
        h = 1e-7 * (1.0 + np.abs(z))
        jac = np.stack([(residuals(z + h[i] * np.eye(z.size)[i]) - r) / h[i] for i in range(z.size)], axis=1)
        return r, jac

    return linearised


def test_levenberg_marquardt_solves_rosenbrock_and_stops_on_a_parameter_running_off_its_range():
    rosenbrock = _numeric(lambda z: np.array([10.0 * (z[1] - z[0] ** 2), 1.0 - z[0]]))
    z, cost, ok, _, _ = cal.levenberg_marquardt(rosenbrock, np.array([-1.2, 1.0]), max_steps=100)
    assert ok and np.allclose(z, [1.0, 1.0], atol=1e-5) and cost < 1e-10
    # η = softplus(u) best at 0 (u → −∞): stops, converged, with the other coordinate fitted.
    drift = _numeric(lambda z: np.array([np.logaddexp(0.0, z[0]), z[1] - 2.0, 0.1]))
    z, _, ok, _, _ = cal.levenberg_marquardt(drift, np.array([1.0, 0.0]), max_steps=40)
    assert ok and z[0] < -3.0 and z[1] == pytest.approx(2.0, abs=1e-6)


def test_levenberg_marquardt_keeps_a_flat_direction_inside_its_bounds():
    # z1 is pulled weakly towards 10 but bounded above by 2; z0 is determined.
    pulled = _numeric(lambda z: np.array([z[0] - 1.0, 1e-3 * (z[1] - 10.0)]))
    bounds = (np.array([-np.inf, -5.0]), np.array([np.inf, 2.0]))
    z, _, ok, _, _ = cal.levenberg_marquardt(pulled, np.array([0.0, 0.0]), max_steps=60, bounds=bounds)
    assert ok and z[0] == pytest.approx(1.0, abs=1e-6) and z[1] == pytest.approx(2.0, abs=1e-12)
    z, _, _, _, _ = cal.levenberg_marquardt(pulled, np.array([0.0, 0.0]), max_steps=60)
    assert z[1] > 2.5  # without bounds it runs past them


def test_levenberg_marquardt_holds_a_coordinate_on_its_bound_and_solves_for_the_others():
    # r = (z0 − 5, z1 − z0) with z0 ≤ 2: the constrained optimum is z = (2, 2). The free step aims at (5, 5);
    # clipped, z1 would chase z0's unreachable target. Held on its bound, z0 stays and z1 follows it.
    calls = []

    def linearised(z):
        calls.append(1)
        return np.array([z[0] - 5.0, z[1] - z[0]]), np.array([[1.0, 0.0], [-1.0, 1.0]])

    bounds = (np.array([-np.inf, -np.inf]), np.array([2.0, np.inf]))
    z, cost, ok, _, _ = cal.levenberg_marquardt(linearised, np.zeros(2), max_steps=60, bounds=bounds)
    assert ok and z == pytest.approx([2.0, 2.0], abs=1e-3) and cost == pytest.approx(4.5, rel=1e-6)
    assert len(calls) <= 5


def _noisy_line(calls, noise, phase_shift=0.0):
    """A line fit whose residuals and Jacobian carry a deterministic noise, irregular in z and across samples, as
    an adaptive solver's do (its steps move with the parameters); an irreducible misfit of 1 per sample.
    ``phase_shift`` (rad) draws another realisation of the noise."""
    m = 400
    t = np.linspace(0.0, 1.0, m)
    a = np.stack([np.ones_like(t), t], axis=1)
    floor = np.where(np.arange(m) % 2, 1.0, -1.0)

    def linearised(z):
        calls.append(np.array(z))
        phase = np.sin(1e6 * (z @ np.array([1.0, np.sqrt(2.0)])) + 1e3 * np.arange(m) ** 1.5 + phase_shift)
        return a @ z - 1.0 - 2.0 * t + floor + noise * phase, a * (1.0 + 30.0 * noise * phase[:, None])

    return linearised


@pytest.mark.parametrize("noise", [0.01, 0.03])
def test_levenberg_marquardt_stops_at_the_costs_resolution_instead_of_wandering_in_its_noise(noise):
    # the cost's noise is ~√m·noise ≈ 1e-3 of it (0.2–0.6 in 200): a resolution of that size ends the wander.
    # Whether one realisation of the noise makes the plain loop wander is chance (its path hangs on the last bits
    # of z): sixteen realisations; the resolved loop never runs longer, and in all about half as long (0.4–0.5).
    plain_counts, resolved_counts = [], []
    for shift in range(16):
        plain, resolved = [], []
        _, cost_plain, _, _, _ = cal.levenberg_marquardt(_noisy_line(plain, noise, shift), np.zeros(2), max_steps=60)
        z, cost, ok, _, _ = cal.levenberg_marquardt(
            _noisy_line(resolved, noise, shift), np.zeros(2), max_steps=60, relative_resolution=1e-3
        )
        assert ok and len(resolved) <= min(len(plain), 15)
        assert abs(cost - cost_plain) < 10 * 1e-3 * cost_plain  # the same minimum, within ten resolutions
        assert z == pytest.approx([1.0, 2.0], abs=0.1)
        plain_counts.append(len(plain))
        resolved_counts.append(len(resolved))
    assert sum(resolved_counts) <= 0.7 * sum(plain_counts), (plain_counts, resolved_counts)
    # without noise the resolution changes nothing: a clean fit ends as before
    clean, clean_resolved = [], []
    out = cal.levenberg_marquardt(_noisy_line(clean, 0.0), np.zeros(2), max_steps=60)
    out_resolved = cal.levenberg_marquardt(
        _noisy_line(clean_resolved, 0.0), np.zeros(2), max_steps=60, relative_resolution=1e-3
    )
    assert np.array_equal(out[0], out_resolved[0]) and len(clean) == len(clean_resolved)


def test_levenberg_marquardt_never_evaluates_a_rejected_point_twice():
    # r = e^{3z} − 1.5 from z = −1: the Gauss–Newton step (~10) is clipped to max_move = 3 and lands on z = 2,
    # far worse; while the damping grows the clipped step lands there again. It is evaluated once.
    steep = _numeric(lambda z: np.array([np.exp(3.0 * z[0]) - 1.5]))
    points = []

    def linearised(z):
        points.append(np.asarray(z, float).tobytes())
        return steep(z)

    z, _, ok, _, _ = cal.levenberg_marquardt(linearised, np.array([-1.0]), max_steps=40, max_move=3.0)
    assert ok and z[0] == pytest.approx(np.log(1.5) / 3.0, abs=1e-6)
    assert len(points) == len(set(points))


def test_levenberg_marquardt_linearises_only_the_points_it_accepts():
    """With ``residuals`` a trial point is scored by the residuals alone and linearised once accepted: the same
    minimum as without, one linearisation at the start and per accepted step, ``max_steps`` accepted steps."""
    f = lambda z: np.array([np.exp(3.0 * z[0]) - 1.5, 0.1 * z[0]])
    steep, linearised_at, scored = _numeric(f), [], []

    def linearised(z):
        linearised_at.append(float(np.asarray(z)[0]))
        return steep(z)

    def residuals(z):
        scored.append(float(np.asarray(z)[0]))
        return f(np.asarray(z, float))

    plain = cal.levenberg_marquardt(steep, np.array([-1.0]), max_steps=40, max_move=3.0)
    z, cost, ok, _, _ = cal.levenberg_marquardt(
        linearised, np.array([-1.0]), max_steps=40, max_move=3.0, residuals=residuals
    )
    assert ok and z[0] == pytest.approx(plain[0][0], abs=1e-6) and cost == pytest.approx(plain[1], rel=1e-6)
    assert set(linearised_at[1:]) <= set(scored) and len(scored) > len(linearised_at) - 1  # some were rejected
    costs = [0.5 * float(f(np.array([x])) @ f(np.array([x]))) for x in linearised_at]
    assert np.all(np.diff(costs) <= 0.0)  # every point linearised after the start was accepted
    linearised_at.clear()
    cal.levenberg_marquardt(linearised, np.array([-1.0]), max_steps=2, max_move=3.0, residuals=residuals)
    assert len(linearised_at) == 3


def test_physical_bounds_are_the_ranges_in_log_coordinates():
    base = gj.reference()
    names = ("robot.yield_pressure", "robot.growth_exponent", "robot.extensibility")
    refs = np.array([8000.0, 1.0, 5000.0])
    lo, hi = cal.physical_bounds(base, names, refs)
    assert lo[0] == -np.inf and hi[0] == pytest.approx(np.log(1e6 / 8000.0))  # Y in [0, 1 MPa]
    assert (lo[1], hi[1]) == pytest.approx((np.log(0.05), np.log(5.0)))  # n in [0.05, 5]
    assert hi[2] == np.inf


def test_levenberg_marquardt_rejects_points_where_the_model_fails():
    # ln z is NaN for z < 0; the first Gauss–Newton step from z = 20 lands there (20 − 32 = −12).
    calls = []

    def residuals(z):
        calls.append(float(z[0]))
        with np.errstate(invalid="ignore"):
            return np.array([np.log(z[0]) - np.log(4.0)])

    z, _, ok, _, jac = cal.levenberg_marquardt(_numeric(residuals), np.array([20.0]), max_steps=60, max_move=100.0)
    assert min(calls) < 0.0  # a failed point was tried...
    assert ok and z[0] == pytest.approx(4.0, rel=1e-6) and np.all(np.isfinite(jac))  # ...and not taken


def test_levenberg_marquardt_reports_a_start_where_the_model_fails():
    failing = _numeric(lambda z: np.array([np.nan, z[0]]))
    z, cost, ok, _, jac = cal.levenberg_marquardt(failing, np.array([1.0]))
    assert not ok and cost == np.inf and z[0] == 1.0 and np.all(np.isfinite(jac))


def _saturating_problem(seed=0):
    """A cheap model L(t) = a·(1 − exp(−b t)) whose data put a's maximum likelihood below its prior's bound."""
    import functools

    import jax.numpy as jnp

    t = np.linspace(0.0, 5.0, 200)
    truth = {"a": 0.0195, "b": 1.3}
    noise = 2e-4
    rng = np.random.default_rng(seed)
    y = truth["a"] * (1.0 - np.exp(-truth["b"] * t)) + noise * rng.normal(size=t.size)
    priors = (gpost.Prior("a", "a", 0.02, 0.05), gpost.Prior("b", "b", 0.1, 10.0, log=True))

    def mean(theta):
        return theta["a"] * (1.0 - jnp.exp(-theta["b"] * jnp.asarray(t)))

    def make_model(m, priors=priors):
        return functools.partial(gpost.growth_model, mean_length=m, priors=priors)

    return y, priors, mean, make_model


def test_laplace_in_unconstrained_coordinates_finds_the_mode_against_a_prior_bound():
    """The start and mass matrix of direct NUTS: the mode of the potential in NumPyro's coordinates, with the
    Hessian there. The data's best a (0.0195) lies below its prior (0.02–0.05): the mode in the logit
    coordinate sits where the likelihood's pull balances the transform's Jacobian, not at a fit in θ."""
    import jax
    from jax.flatten_util import ravel_pytree
    from numpyro.infer.util import potential_energy, unconstrain_fn

    y, priors, mean, make_model = _saturating_problem()
    init = {"a": 0.035, "b": 3.0, "sigma": 1e-3}
    mode, hess = gpost.laplace_unconstrained(make_model, priors, mean, y, init)
    model = make_model(mean)
    z, unravel = ravel_pytree(unconstrain_fn(model, (y,), {}, mode))
    potential = jax.jit(lambda z: potential_energy(model, (y,), {}, unravel(z)))
    grad = np.asarray(jax.grad(potential)(z))
    exact = np.asarray(jax.hessian(potential)(z))
    assert 0.02 < mode["a"] < 0.0202  # pressed against the bound, inside it
    # Newton's predicted gain from the returned point is below the stop (0.01 nats): at the mode.
    assert 0.5 * grad @ np.linalg.solve(exact, grad) < gpost.LAPLACE_DECREMENT
    # Gauss–Newton in θ, exact in the transforms: the Hessian to a few per cent of the exact one.
    np.testing.assert_allclose(hess, exact, rtol=0.05, atol=0.05 * np.abs(exact).max())
    rms = np.sqrt(np.mean((np.asarray(mean({"a": mode["a"], "b": mode["b"]})) - y) ** 2))
    assert rms > 1.5 * 2e-4  # the bound leaves a misfit on top of the noise, and σ takes it
    assert mode["sigma"] == pytest.approx(rms, rel=0.02)


def test_softplus_coordinate_keeps_the_prior_and_the_posterior():
    """A prior pressed against its bound is sampled in a softplus coordinate (``bound_start``): the same prior
    (the density it implies on θ integrates to 1 over the range, uniform in θ) and the same posterior as NumPyro's
    logit coordinate (NUTS in both on the cheap saturating model: the same quantiles of a), without divergences."""
    import jax
    import jax.numpy as jnp
    import numpyro
    from numpyro.infer import MCMC, NUTS

    prior = gpost.SoftplusPrior("a", "a", 0.02, 0.05, scale=0.01)
    u = np.linspace(-60.0, 3000.0, 400_001)
    s = prior.scale
    f = -np.expm1(-s * np.logaddexp(0.0, u))
    density = np.exp(np.log(s) - np.logaddexp(0.0, -u) - s * np.logaddexp(0.0, u))  # |df/du|
    assert np.all(np.diff(f) >= 0) and f[0] < 1e-20 and f[-1] > 1.0 - 1e-9
    assert np.trapezoid(density, u) == pytest.approx(1.0, abs=1e-6)
    inside = (f > 0.2) & (f < 0.6)  # uniform in θ: the share of u's mass mapped into a slice is its width
    assert np.trapezoid(np.where(inside, density, 0.0), u) == pytest.approx(0.4, abs=1e-4)
    assert -np.expm1(-s * np.logaddexp(0.0, prior.start())) == pytest.approx(s, rel=1e-12)

    y, priors, mean, make_model = _saturating_problem()
    mode, inverse_mass = gpost.precondition(make_model(mean), priors, mean, y, make_model=make_model)
    sampled, start, mass = gpost.bound_start(make_model, priors, mean, y, mode, inverse_mass)
    assert [type(p).__name__ for p in sampled] == ["SoftplusPrior", "RidgePrior"]  # a at its bound, b across it
    quantiles, divergences = [], []
    for ps, init, m in ((priors, mode, inverse_mass), (sampled, start, mass)):
        kernel = NUTS(
            make_model(mean, ps),
            dense_mass=True,
            inverse_mass_matrix=m,
            target_accept_prob=0.9,
            init_strategy=numpyro.infer.init_to_value(values=init),
        )
        mcmc = MCMC(
            kernel, num_warmup=500, num_samples=1000, num_chains=2, chain_method="vectorized", progress_bar=False
        )
        mcmc.run(jax.random.PRNGKey(1), jnp.asarray(y), extra_fields=("diverging",))
        draws = mcmc.get_samples()
        quantiles.append({k: np.quantile(np.asarray(draws[k]), [0.1, 0.5, 0.9]) for k in ("a", "b")})
        divergences.append(int(np.asarray(mcmc.get_extra_fields()["diverging"]).sum()))
    assert quantiles[0]["a"][0] > 0.02 and quantiles[1]["a"][0] > 0.02
    for k in ("a", "b"):
        spread = quantiles[0][k][2] - quantiles[0][k][0]
        np.testing.assert_allclose(quantiles[1][k], quantiles[0][k], atol=0.15 * spread)
    assert divergences[1] == 0


def test_ridge_coordinate_keeps_the_prior():
    """A free prior sampled across its ridge with a pressed one (``RidgePrior``: z = v + offset + b·f_a) implies
    the same prior on θ whatever the pressed value: its density in v integrates to 1 and is log-uniform in θ."""
    import jax
    import jax.numpy as jnp
    from numpyro.infer.util import constrain_fn, log_density

    pressed = gpost.SoftplusPrior("a", "a", 0.02, 0.05, scale=0.01)
    ridge = gpost.RidgePrior("b", "b", 0.1, 10.0, log=True, along=((pressed, 3.0),), offset=0.4)
    v = jnp.linspace(-40.0, 40.0, 200_001)
    for a in (0.0201, 0.03, 0.049):

        def model(a=a):
            ridge.sample({"a": a})

        density = np.exp(np.asarray(jax.vmap(lambda x: log_density(model, (), {}, {"v_b": x})[0])(v)))
        theta = np.asarray(
            jax.vmap(lambda x: constrain_fn(model, (), {}, {"v_b": x}, return_deterministic=True)["b"])(v)
        )
        assert np.all(np.diff(theta) >= 0) and theta[0] < 0.1 + 1e-9 and theta[-1] > 10.0 - 1e-9
        assert np.trapezoid(density, np.asarray(v)) == pytest.approx(1.0, abs=1e-6)
        f = np.log(theta / 0.1) / np.log(100.0)
        inside = (f > 0.2) & (f < 0.6)  # log-uniform: a slice of the log range holds its share of the mass
        assert np.trapezoid(np.where(inside, density, 0.0), np.asarray(v)) == pytest.approx(0.4, abs=1e-3)


def test_model_tangents_give_numpyros_forward_gradient():
    """``with_model_tangents`` (the model's Jacobian in θ's own directions, mapped through every tangent)
    changes the cost of NUTS's forward-mode gradient, never its value."""
    import jax
    from jax.flatten_util import ravel_pytree
    from numpyro.infer.util import potential_energy, unconstrain_fn

    y, priors, mean, make_model = _saturating_problem()
    point = {"a": 0.021, "b": 1.2, "sigma": 3e-4}
    gradients = []
    for m in (mean, gpost.with_model_tangents(mean, [p.name for p in priors])):
        model = make_model(m)
        z, unravel = ravel_pytree(unconstrain_fn(model, (y,), {}, point))

        def potential(z, model=model, unravel=unravel):
            return potential_energy(model, (y,), {}, unravel(z))

        gradients.append(np.asarray(jax.jacfwd(potential)(z)))
    assert np.abs(gradients[0]).max() > 1.0
    np.testing.assert_allclose(gradients[1], gradients[0], rtol=1e-10)


def test_observation_draws_equal_numpyros_log_likelihood_and_predictive():
    """posterior.sample takes the pointwise log-likelihood and the predictive from each draw's recorded model
    length instead of running the model twice more per draw: the log-likelihood must be NumPyro's own (which runs
    the model again), the predictive its noise around that length, and a failed draw must have −∞."""
    import functools

    from numpyro.infer.util import log_likelihood

    t = np.linspace(0.0, 1.0, 30)
    priors = (gpost.Prior("a", "a", 0.5, 2.0),)
    model_error = 3e-4
    model = functools.partial(
        gpost.growth_model, mean_length=lambda th: th["a"] * 1e-2 * t, priors=priors, model_error=model_error
    )
    rng = np.random.default_rng(0)
    draws = {"a": rng.uniform(0.5, 2.0, (2, 40)), "sigma": rng.uniform(1e-3, 2e-3, (2, 40))}
    draws["length_model"] = draws["a"][..., None] * 1e-2 * t
    observed = 1.2e-2 * t + rng.normal(0.0, 1.5e-3, t.size)
    loglik, predicted, new = gpost.observation_draws(
        draws["length_model"], draws["sigma"], model_error, observed, seed=1
    )
    np.testing.assert_array_equal(predicted, new)  # independent noise: nothing of this experiment to keep
    flat = {k: v.reshape(80, *v.shape[2:]) for k, v in draws.items()}
    expected = np.asarray(log_likelihood(model, flat, observed)["length"]).reshape(2, 40, -1)
    np.testing.assert_allclose(loglik, expected, rtol=1e-12)
    z = (predicted - draws["length_model"]) / np.sqrt(draws["sigma"] ** 2 + model_error**2)[..., None]
    assert abs(z.mean()) < 0.15 and abs(z.std() - 1.0) < 0.1  # 2400 standard normal draws
    failed = draws["length_model"].copy()
    failed[1, 3] = np.nan
    assert np.all(gpost.observation_draws(failed, draws["sigma"], model_error, observed, seed=1)[0][1, 3] == -np.inf)
