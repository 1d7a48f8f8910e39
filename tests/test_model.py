"""Whole-model behaviour of the fast configuration: volume, yield, the pressure limit, gradients, batches, the paper."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import SHORT, forward_inputs
from scipy.integrate import quad

import growjax as gj
from growjax.data import experiment as ex
from growjax.model.fluid import bulk_modulus
from growjax.simulation.metrics import length_rmse


def _stored(params, p0, p1):
    """Liquid volume (m³) the rigid lumped lines (hoses and tank) store from p0 to p1 Pa: ∫ V/E(p) dp by quadrature."""
    volume = params.pump.n_syringes * params.tube.volume + params.tank.volume
    return quad(lambda p: volume / float(bulk_modulus(params.fluid, p)), p0, p1, limit=200, epsrel=1e-10)[0]


EDGE_TIMES = np.unique(
    np.concatenate(
        [np.linspace(0.001, 3.0, 61)]
        + [e + np.array([-1e-3, -1e-4, 0.0, 1e-4, 1e-3, 1e-2]) for e in (0.26, 1.43, 1.56, 2.73)]
    )
)  # rises and falls


@pytest.mark.parametrize(
    "demand", [gj.published_pulse(), gj.PulseTrain(300e3, 0.7, 0.5, 0.05)], ids=["published", "300kPa"]
)
def test_volume_balance_holds_through_every_demand_edge(demand):
    """Delivered = grown + stored at every save time, the stored volume from the sensed pressure by quadrature."""
    rigid = gj.replace(gj.reference(), **{"tube.diameter_compliance": 0.0})
    inputs = gj.Inputs(catheter_length=gj.Constant(0.02), pressure_demand=demand)
    traj = gj.simulate(rigid, inputs, SHORT, ts=EDGE_TIMES)
    assert int(traj.status) == gj.OK
    delivered = rigid.pump.n_syringes * rigid.pump.syringe_area * np.asarray(traj.syringe_displacement)
    grown = rigid.robot.area * (np.asarray(traj.length) - rigid.robot.initial_length)
    pressure = np.asarray(traj.pressure)  # from the first sample (t0), where the lumped lines start equalised
    stored = np.array([_stored(rigid, pressure[0], p) for p in pressure])
    defect = delivered - grown - stored
    scale = np.max(np.abs(delivered))
    assert scale > 5e-8
    assert np.max(np.abs(defect)) < 1e-3 * scale  # 0.1 % of the delivered volume


def test_zero_demand_never_grows_the_robot():
    traj = gj.simulate(gj.reference(), forward_inputs(amplitude=0.0), SHORT)
    assert int(traj.status) == gj.OK
    assert float(jnp.max(traj.length)) <= gj.reference().robot.initial_length + 1e-9


def test_growth_only_above_the_yield_pressure():
    params = gj.reference()
    y = params.robot.yield_pressure
    below = gj.simulate(params, forward_inputs(amplitude=0.9 * y, catheter=0.0), SHORT)
    assert float(jnp.max(below.length)) <= params.robot.initial_length + 1e-9
    traj = gj.simulate(params, forward_inputs(amplitude=150e3), SHORT)
    growing = np.asarray(traj.robot_flow) > 1e-10
    assert growing.sum() > 100
    drop = np.asarray(traj.pressure - traj.robot_pressure)[growing]
    assert drop.min() > y  # the check valve is open only above cracking (= Y as shipped)


def _assert_stopped_at_the_limit(traj, latest, limit=373.333e3):
    assert int(traj.status) == gj.PRESSURE_LIMIT, gj.status_name(traj.status)
    t_cross = float(traj.limit_time)
    assert 0.0 < t_cross < latest and float(traj.t_final) == pytest.approx(t_cross)
    t = np.asarray(traj.time)
    assert np.all(np.isnan(np.asarray(traj.pressure)[t > t_cross + 1e-9]))
    assert np.nanmax(np.asarray(traj.pressure)[t <= t_cross]) <= limit * 1.001
    return t_cross


@pytest.mark.parametrize("amplitude", [400e3, 600e3, 2e6])
def test_forward_demands_beyond_the_membrane_limit_stop_with_status_1(amplitude):
    """Pulses and a step at 400 kPa–2 MPa: the run stops at the crossing, never with a solver failure."""
    pulse = gj.simulate(gj.reference(), forward_inputs(amplitude=amplitude), SHORT)
    t_pulse = _assert_stopped_at_the_limit(pulse, 0.6)
    assert t_pulse > 0.26  # after the first rise
    step = gj.Inputs(
        catheter_length=gj.Constant(0.02),
        pressure_demand=gj.Sampled(np.array([0.0, 0.1, 0.1 + 1e-9, 100.0]), np.array([0.0, 0.0, amplitude, amplitude])),
    )
    _assert_stopped_at_the_limit(gj.simulate(gj.reference(), step, SHORT), 0.6)


@pytest.mark.parametrize("rate", [500.0, 2000.0])
def test_inverse_drive_pushing_a_blocked_robot_stops_with_status_1(rate):
    """The stepper feeding a robot that cannot grow (Y = 1 MPa) compresses the lines past the limit.

    A thinner membrane (10 µm: limit 107 kPa) puts the limit below the ~190 kPa at which the shipped
    stepper stalls against the syringes."""
    params = gj.replace(gj.reference("inverse"), Y=1e6, t=1e-5)
    times = 0.05 + np.arange(1000) / rate  # the same number of edges: one compiled solver
    inputs = gj.Inputs(catheter_length=gj.Constant(0.0), steps=gj.StepSchedule(times, np.arange(1, 1001, dtype=float)))
    traj = gj.simulate(params, inputs, gj.Config(drive="inverse", t1=3.0))
    _assert_stopped_at_the_limit(traj, 3.0, float(gj.pressure_limit(params.robot)))


GRAD_NAMES = ("Y", "check_valve.max_open_pressure", "fluid.air_fraction")


def _final_length_and_rmse(exp, adjoint):
    """(θ (3,) ↦ [final length m, length RMSE m] over 1.5 s at rtol 1e-8, θ at the reference) for GRAD_NAMES."""
    cfg = gj.Config(t1=1.5, rtol=1e-8, adjoint=adjoint)
    p0 = gj.reference()
    inputs = ex.to_inputs(exp, "forward", p0, cfg.t0, cfg.t1)
    breaks = gj.input_breaks(inputs, cfg)

    def outputs(theta):
        traj = gj.simulate(gj.replace(p0, **dict(zip(GRAD_NAMES, theta))), inputs, cfg, breaks=breaks)
        return jnp.stack([traj.length[-1], length_rmse(traj, exp.time, exp["robot_length_m"], cfg.t0, cfg.t1)])

    return outputs, jnp.array([float(gj.get(p0, name)) for name in GRAD_NAMES])


@pytest.mark.slow
@pytest.mark.parametrize("adjoint", ["forward", "reverse"])
def test_gradients_match_central_differences(synthetic_experiment, adjoint):
    """d(final length, RMSE)/dθ through the solver (jacfwd or grad) against central differences (by default
    test_api checks the final length's gradient both ways against differences)."""
    outputs, theta0 = _final_length_and_rmse(synthetic_experiment, adjoint)
    jac_fn = jax.jacfwd(outputs) if adjoint == "forward" else jax.jacrev(outputs)
    jac = np.asarray(jax.jit(jac_fn)(theta0))
    run = jax.jit(outputs)
    for i, name in enumerate(GRAD_NAMES):
        h = 1e-3 * float(theta0[i])
        fd = np.asarray(run(theta0.at[i].add(h)) - run(theta0.at[i].add(-h))) / (2 * h)
        # 1 % plus the differences' own floor: adaptive steps move the length by ~rtol·L between the ±h runs.
        atol = np.array([1e-6, 1e-7]) / float(theta0[i])
        assert np.all(np.abs(jac[:, i] - fd) <= 1e-2 * np.abs(fd) + atol), (name, jac[:, i], fd)
        assert abs(jac[0, i]) * float(theta0[i]) > 1e-5  # each matters (> 10 µm over its whole value)


@pytest.mark.slow
def test_a_batch_of_jacobians_equals_the_single_ones(synthetic_experiment):
    """At a batch of points (NUTS's vectorised chains) the members step together in one solve and give each
    member's own Jacobian."""
    outputs, theta0 = _final_length_and_rmse(synthetic_experiment, "forward")
    jac_fn = jax.jit(jax.jacfwd(outputs))
    other = theta0 * jnp.array([1.2, 0.9, 1.5])
    batched = np.asarray(jax.jit(jax.vmap(jax.jacfwd(outputs)))(jnp.stack([theta0, other])))
    for k, point in enumerate((theta0, other)):
        np.testing.assert_allclose(batched[k], np.asarray(jac_fn(point)), rtol=1e-4, atol=1e-9)


def test_paper_box_corners_run_bad_member_is_isolated_and_paper_rmse_is_reproduced(shared_experiment):
    """One batched call: the 8 corners of the paper's LHS box, the published set, and a broken member."""
    corners = [(n, y, e) for n in (0.9, 1.1) for y in (5e3, 15e3) for e in (4000.0, 10000.0)]
    p0 = gj.reference()
    published = (p0.robot.growth_exponent, p0.robot.yield_pressure, p0.robot.extensibility)
    members = corners + [published, (1.0, float("nan"), 5000.0)]
    ns, ys, es = (jnp.array([m[i] for m in members]) for i in range(3))
    cfg = gj.Config(t1=10.0)
    inputs = ex.to_inputs(shared_experiment, "forward", p0)
    breaks = gj.input_breaks(inputs, cfg)

    def run(n, y, e):
        traj = gj.simulate(gj.replace(p0, n=n, Y=y, ext=e), inputs, cfg, breaks=breaks)
        exp = shared_experiment
        return traj, length_rmse(traj, exp.time, exp["robot_length_m"], cfg.t0, cfg.t1)

    trajs, rmse = jax.vmap(run)(ns, ys, es)
    status = np.asarray(trajs.status)
    assert np.all(status[:-1] == gj.OK), status
    assert status[-1] == gj.SOLVER_FAILED  # flagged, and the other members are untouched
    assert np.all(np.isfinite(np.asarray(trajs.length)[:-1]))
    final = np.asarray(trajs.length)[:8, -1]
    assert np.all(final > p0.robot.initial_length)  # every corner grows over 10 s (Y = 15 kPa: to ~13 mm)
    low_y = final[[c[1] == 5e3 for c in corners]]
    high_y = final[[c[1] == 15e3 for c in corners]]
    assert low_y.min() > high_y.max()  # lower yield pressure, faster growth
    assert 1.4e-3 < float(rmse[8]) < 2.0e-3  # published parameters: paper 1.7 mm


def test_inverse_model_tracks_and_steps_the_syringe(shared_experiment):
    params = gj.reference("inverse")
    cfg = gj.Config(drive="inverse")
    inputs = ex.to_inputs(shared_experiment, "inverse", params)
    traj = gj.simulate(params, inputs, cfg)
    assert int(traj.status) == gj.OK
    steps = float(inputs.steps.counts[-1])
    per_step = params.pump.lead / 200.0  # 1.8° full steps
    # The rotor lags its detent under load by a fraction of a step (holding stiffness ≈ 6.7 N·m/rad).
    assert abs(float(traj.syringe_displacement[-1]) - steps * per_step) < 0.3 * per_step
    rmse = float(length_rmse(traj, shared_experiment.time, shared_experiment["robot_length_m"], 0.001, 10.0))
    assert rmse < 5e-3  # paper: 2.5 mm; growjax: ~3.5 mm (README)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="drive"):
        gj.Config(drive="sideways")
    with pytest.raises(ValueError, match="fidelity"):
        gj.Config(fidelity="quick")
    with pytest.raises(ValueError, match="t1"):
        gj.Config(t0=1.0, t1=0.5)
    inputs = forward_inputs()
    with pytest.raises(ValueError, match="sorted"):
        gj.simulate(gj.reference(), inputs, SHORT, ts=np.array([0.5, 0.2]))
    with pytest.raises(ValueError, match="finite"):
        gj.simulate(gj.reference(), inputs, SHORT, ts=np.array([0.1, np.nan]))
    with pytest.raises(ValueError, match=r"within \[t0, t1\]"):
        gj.simulate(gj.reference(), inputs, SHORT, ts=np.array([0.1, 5.0]))


def test_input_breaks_are_remembered_only_while_valid():
    from growjax.simulation.simulate import input_breaks

    cfg = gj.Config()
    inputs = gj.Inputs(catheter_length=gj.Constant(0.0), pressure_demand=gj.PulseTrain(150e3, 1.3, 0.9, 0.26))
    first = input_breaks(inputs, cfg)
    assert input_breaks(inputs, cfg)[0] is first[0]  # same object, same window: remembered
    short = input_breaks(inputs, cfg.replace(t1=2.0))  # another window: found again
    assert np.sum(np.asarray(short[0]) < 2.0) == 3 and np.sum(np.asarray(first[0]) < 10.0) == 15  # 0.26, 1.43, 1.56 s
    edges = np.array([0.5, 1.5])  # a writable NumPy leaf could change in place: never remembered
    stepped = gj.Inputs(catheter_length=gj.Constant(0.0), steps=gj.StepSchedule(edges, np.array([1.0, 2.0])))
    before = np.asarray(input_breaks(stepped, cfg.replace(drive="inverse"))[0])
    edges[1] = 2.5
    after = np.asarray(input_breaks(stepped, cfg.replace(drive="inverse"))[0])
    assert 1.5 in before and 2.5 in after and 1.5 not in after


def test_input_breaks_found_under_a_trace_are_not_remembered():
    """JAX makes even a constant array a tracer under ``jit``: breaks found there must not be reused outside."""
    from growjax.simulation.simulate import input_breaks

    cfg = gj.Config(t1=1.0)
    inputs = gj.Inputs(catheter_length=gj.Constant(0.0), pressure_demand=gj.PulseTrain(150e3, 1.3, 0.9, 0.26))
    jax.jit(lambda x: x + input_breaks(inputs, cfg)[0][0])(0.0)  # found first inside a trace
    jumps, _ = input_breaks(inputs, cfg)
    assert not isinstance(jumps, jax.core.Tracer)
    assert np.asarray(jumps)[0] == pytest.approx(0.26)


def test_fits_and_the_emulator_score_the_model_at_the_samples():
    """Samples at whole hundredths fall between the default save grid's points (every 10 ms from t0 = 1 ms):
    fit residuals and the emulator's prediction use the solution at the samples themselves (a sweep's RMSE:
    tests/test_sweep.py)."""
    from growjax.calibration import fit as gf
    from growjax.posterior import emulator as em

    cfg = gj.Config(t1=1.0)
    inputs = gj.Inputs(catheter_length=gj.Constant(0.0), pressure_demand=gj.PulseTrain(150e3, 1.3, 0.9, 0.26))
    times = np.arange(0.01, 1.0 + 1e-9, 0.01)
    base = gj.reference()
    exact = np.asarray(gj.simulate(base, inputs, cfg, ts=times).length)
    grid = gj.simulate(base, inputs, cfg)
    interpolated = np.interp(times, np.asarray(grid.time), np.asarray(grid.length))
    assert np.max(np.abs(interpolated - exact)) > 1e-6  # the grid would be off by more than a micrometre
    data = exact + 1e-4
    problem = gf.make_problem(base, ["Y"], inputs, cfg, times, data, sigma_length=1e-4)
    np.testing.assert_allclose(np.asarray(problem.residuals(jnp.zeros(1))), -1.0, atol=1e-4)  # 1e-8 m
    predicted = em.predicted_length(
        {"robot.yield_pressure": base.robot.yield_pressure}, base, inputs, cfg, jnp.asarray(times)
    )
    np.testing.assert_allclose(np.asarray(predicted), exact, atol=1e-9)


def test_a_batch_saves_in_its_loop_what_single_runs_interpolate_afterwards():
    """A vmapped ``simulate`` steps its members in one loop, takes the state's Jacobian in forward mode and
    interpolates each save time as its step is taken (``rosenbrock.integrate(save_ts=…)``, no step records);
    a single run keeps every step and interpolates after the loop. The two agree at the solver's tolerance on
    a grid through every demand edge and denser than one step may cover (1 ms: ``SAVE_WINDOW`` then
    shortens the batch's steps), at a stop on the pressure limit (a 10 µm membrane: limit 107 kPa), and for a
    member whose field is not finite at t0 (it fails at once, beside the others)."""
    members = [
        gj.reference(),
        gj.replace(gj.reference(), Y=12e3, n=1.05),
        gj.replace(gj.reference(), t=1e-5),
        gj.replace(gj.reference(), Y=float("nan")),
    ]
    expected = [gj.OK, gj.OK, gj.PRESSURE_LIMIT, gj.SOLVER_FAILED]
    stacked = jax.tree_util.tree_map(lambda *leaves: jnp.stack([jnp.asarray(x) for x in leaves]), *members)
    inputs = forward_inputs()
    dense = np.arange(1, 3001) * 1e-3
    edges = EDGE_TIMES[np.min(np.abs(EDGE_TIMES[:, None] - dense[None, :]), axis=1) > 1e-9]
    ts = np.sort(np.concatenate([dense, edges]))  # one grid: one compiled program
    batch = jax.vmap(lambda p: gj.simulate(p, inputs, SHORT, ts=ts))(stacked)
    for i, params in enumerate(members):
        single = gj.simulate(params, inputs, SHORT, ts=ts)
        assert int(batch.status[i]) == int(single.status) == expected[i]
        assert float(batch.t_final[i]) == pytest.approx(float(single.t_final), abs=1e-4)
        if expected[i] == gj.SOLVER_FAILED:  # every sample after t0 NaN (at t0 the batch reports y0)
            assert np.all(np.isnan(batch.length[i][1:])) and np.all(np.isnan(single.length[1:]))
            continue
        np.testing.assert_array_equal(np.isnan(batch.length[i]), np.isnan(single.length))
        np.testing.assert_allclose(
            batch.length[i], single.length, rtol=0, atol=5e-6, equal_nan=True
        )  # measured ≤ 0.6 µm
        np.testing.assert_allclose(batch.pressure[i], single.pressure, rtol=2e-3, atol=500.0, equal_nan=True)  # ≤ 83 Pa
    assert float(batch.limit_time[2]) < 1.0 and np.all(np.isfinite(batch.length[:2]))


@pytest.mark.parametrize("batched", [False, True], ids=["single", "batch"])
def test_the_integrator_saves_in_its_loop_the_solution_it_would_record(batched):
    """``rosenbrock.integrate(save_ts=…)`` on y' = −k y with an input jump (k doubles at t = 0.5 s): the values
    saved in the loop equal those interpolated from the recorded steps of the same run without ``save_ts`` (to
    rounding, 4e-16 measured), and
    the exact solution to the tolerance (measured 1.0e-6 relative at k = 3, 1.1e-8 at k = 1), on a 2 ms grid and
    through the jump, with and without a leading batch axis."""
    from growjax.simulation import rosenbrock as rb

    def field(t, y, k):
        return -k * jnp.where(t < 0.5, 1.0, 2.0) * y

    ts = np.arange(0, 1001) * 2e-3
    ks = np.array([1.0, 3.0])
    kw = {"rtol": 1e-8, "atol": 1e-10, "max_steps": 4000, "breaks": jnp.array([0.5]), "jumps": jnp.array([True])}
    if batched:
        kw.update(breaks=jnp.full((2, 1), 0.5), jumps=jnp.ones((2, 1), bool))
        run = rb.integrate(
            field, jnp.ones((2, 1)), 0.0, 2.0, args=jnp.asarray(ks), batched=True, save_ts=jnp.tile(ts, (2, 1)), **kw
        )
        kept = rb.integrate(field, jnp.ones((2, 1)), 0.0, 2.0, args=jnp.asarray(ks), batched=True, **kw)
        recorded = np.stack(
            [np.asarray(rb.evaluate(jax.tree_util.tree_map(lambda x, i=i: x[i], kept.steps), ts)) for i in range(2)]
        )[:, :, 0, 0]
        saved = np.asarray(run.saved)[:, :, 0, 0]
    else:
        ks = ks[:1]
        run = rb.integrate(field, jnp.ones(1), 0.0, 2.0, args=jnp.asarray(ks[0]), save_ts=jnp.asarray(ts), **kw)
        kept = rb.integrate(field, jnp.ones(1), 0.0, 2.0, args=jnp.asarray(ks[0]), **kw)
        recorded = np.asarray(rb.evaluate(kept.steps, ts))[None, :, 0, 0]
        saved = np.asarray(run.saved)[None, :, 0, 0]
    exact = np.exp(-ks[:, None] * (np.minimum(ts, 0.5) + 2.0 * np.maximum(ts - 0.5, 0.0)))
    assert np.all(np.asarray(run.status) == rb.OK) and np.all(np.asarray(kept.status) == rb.OK)
    np.testing.assert_allclose(saved, recorded, rtol=1e-9, atol=0)
    np.testing.assert_allclose(saved, exact, rtol=1e-5, atol=0)


def test_a_batch_inverts_and_measures_the_variation_as_single_members_do():
    """The batch's elementwise W⁻¹ (Gauss–Jordan with partial pivoting, batch axis last) and variation check
    (‖W₀⁻¹ΔW‖∞, refined by the spectral radius above 1) against the single-member LAPACK inverse and
    ``_variation``: members that need row exchanges (zero leading entries), one ill-conditioned, and changes on both
    sides of the bound (a non-normal one whose ∞-norm exceeds 1 while its spectral radius does not)."""
    from growjax.simulation import rosenbrock as rb

    rng = np.random.default_rng(7)
    n = 6
    swap = np.eye(n)[[1, 0, 3, 2, 5, 4]]  # every diagonal entry zero: no step without a row exchange
    mats = np.stack(
        [
            np.eye(n) + 0.3 * rng.normal(size=(n, n)),
            swap,
            swap + 1e-3 * rng.normal(size=(n, n)),
            np.diag([1.0, 1e-7, 1.0, 1.0, 1e3, 1.0]) + 1e-4 * rng.normal(size=(n, n)),
            np.eye(n) - 50.0 * rng.normal(size=(n, n)),
        ]
    )
    inverse = np.asarray(jax.vmap(rb.batchable_inverse)(jnp.asarray(mats)))
    expected = np.stack([np.linalg.inv(m) for m in mats])
    np.testing.assert_allclose(inverse, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())

    nilpotent = np.diag(np.full(n - 1, 3.0), 1)  # ‖·‖∞ = 3, spectral radius 0
    changes = np.stack(
        [
            0.01 * rng.normal(size=(n, n)),
            nilpotent,
            2.0 * np.eye(n),
            0.5 * rng.normal(size=(n, n)),
            nilpotent + 0.9 * np.eye(n),
        ]
    )
    w_inv = np.broadcast_to(np.eye(n), changes.shape)
    batch = np.asarray(jax.vmap(rb.batchable_variation)(jnp.asarray(w_inv), jnp.asarray(changes)))
    single = np.array([float(rb.variation(jnp.asarray(w), jnp.asarray(c))) for w, c in zip(w_inv, changes)])
    np.testing.assert_allclose(batch, single, rtol=1e-12)
    assert single[0] < 1.0 and single[1] < 1.0 < np.abs(changes[1]).sum(axis=1).max() and single[2] > 1.0


# The reference case compiles the reference model twice (40 s): a slow study.
@pytest.mark.parametrize("fidelity", ["fast", pytest.param("reference", marks=pytest.mark.slow)])
def test_simulate_members_equals_the_vmapped_simulate(fidelity):
    """``simulate_members`` (one batched solve, the one-member program never traced) gives what
    ``jax.vmap(simulate)`` gives, field by field, for members that finish, stop at the pressure limit (a 10 µm
    membrane) and fail (Y NaN); it refuses to be differentiated. Both run the same batched solve (bitwise equal
    here); the bounds are the solver's (1e-3 relative, 1e-4 of each field's scale, 2 % of the steps), so that two
    compiles that round differently, and so take a step differently, cannot fail it."""
    # the members of the batch test above (its vmapped program, compiled once)
    members = [
        gj.reference(),
        gj.replace(gj.reference(), Y=12e3, n=1.05),
        gj.replace(gj.reference(), t=1e-5),
        gj.replace(gj.reference(), Y=float("nan")),
    ]
    stacked = jax.tree_util.tree_map(lambda *leaves: jnp.stack([jnp.asarray(x) for x in leaves]), *members)
    inputs = forward_inputs()
    config = SHORT.replace(fidelity=fidelity, t1=1.0) if fidelity == "reference" else SHORT
    ts = EDGE_TIMES[EDGE_TIMES <= config.t1]
    together = gj.simulate_members(stacked, inputs, config, ts=ts)
    vmapped = jax.vmap(lambda p: gj.simulate(p, inputs, config, ts=ts))(stacked)
    assert [int(s) for s in together.status] == [gj.OK, gj.OK, gj.PRESSURE_LIMIT, gj.SOLVER_FAILED]
    leaves = jax.tree_util.tree_leaves_with_path(together)
    assert len(leaves) == len(jax.tree_util.tree_leaves(vmapped)) > 5
    for (path, a), b in zip(leaves, jax.tree_util.tree_leaves(vmapped)):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape and a.dtype == b.dtype, jax.tree_util.keystr(path)
        name = jax.tree_util.keystr(path)
        if np.issubdtype(a.dtype, np.floating):  # NaN where the other is NaN (past a stop, the failed member)
            scale = np.nanmax(np.abs(b)) if np.any(np.isfinite(b)) else 0.0
            np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-4 * scale, equal_nan=True, err_msg=name)
        elif "n_steps" in name:
            assert np.all(np.abs(a - b) <= 0.02 * b + 2), name
        else:
            np.testing.assert_array_equal(a, b, err_msg=name)
    if fidelity == "fast":
        with pytest.raises(TypeError, match="not differentiable"):
            jax.jvp(
                lambda y: gj.simulate_members(gj.replace(stacked, Y=y), inputs, config, ts=ts).length,
                (stacked.robot.yield_pressure,),
                (jnp.ones(len(members)),),
            )
