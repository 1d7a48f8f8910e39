"""Design for model discrimination: T against a dense computation, T for one effect against itself and against its
size, the gradient against finite differences, the design against its baselines, the command's refusals."""

import json

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import objective_differences

import growjax as gj
from growjax import cli
from growjax import design as gd
from growjax.calibration import discrepancy as dc
from growjax.data import synthetic as syn
from growjax.design import discrimination as ddis

Y = "robot.yield_pressure"
DATA = "src/growjax/data/datasets/synthetic_forward.csv"
PAIR = ("retraction_folding", "trapped_air")
RISE_FALL = np.array([0.0, 150e3, 40e3, 150e3, 40e3])  # Pa at the knots: growth, then retraction, twice


def _catheter():
    t = np.round(np.arange(0, 1001) * 0.01, 10)
    return gj.Sampled(jnp.asarray(t), jnp.asarray(0.004 + 0.004 * t))


@pytest.fixture(scope="module")
def short():
    """The short case of tests/test_design.py (2 s, knots every 0.5 s, two toleranced rig parameters)."""
    base = gj.replace(gj.reference("forward"), Y=9000.0)
    known = gd.Knowledge(
        base,
        (Y,),
        np.array([[0.03**2]]),
        {"robot.catheter_friction": 0.2, "pid.proportional": 0.05},
        dc.Hyper.of(1e-4, 0.8, 2e-4, 0.01),
        "test",
    )
    space = gd.DesignSpace(2.0, 336e3, _catheter(), knot_spacing=0.5)
    return known, space, ddis.make(known, space, PAIR, config=gj.Config(rtol=1e-7, atol=1e-7))


def test_the_statistic_is_the_dense_generalised_least_squares_projection():
    """T from the Kalman whitening with the rig in its state equals rᵀΣ⁻¹r − rᵀΣ⁻¹J(JᵀΣ⁻¹J)⁻¹JᵀΣ⁻¹r with
    Σ = K + G U Gᵀ built densely; it is the minimum over the rival's parameters of the whitened misfit."""
    rng = np.random.default_rng(1)
    n = 60
    t = np.sort(rng.uniform(0.0, 3.0, n))
    hyper = dc.Hyper.of(3e-4, 0.6, 2e-4, 0.03)
    r = rng.normal(0, 1e-3, n)
    jac = rng.normal(0, 1e-3, (n, 2))
    rig = rng.normal(0, 2e-3, (n, 3))
    u = np.array([0.2, 0.05, 0.1])
    value = float(ddis.statistic(jnp.asarray(r), jnp.asarray(jac), jnp.asarray(rig), jnp.asarray(u), t, hyper))
    sigma = dc.kernel(t, hyper) + dc.noise_kernel(t, hyper) + rig @ np.diag(u**2) @ rig.T
    si_r, si_j = np.linalg.solve(sigma, r), np.linalg.solve(sigma, jac)
    dense = r @ si_r - (jac.T @ si_r) @ np.linalg.solve(jac.T @ si_j, jac.T @ si_r)
    assert value == pytest.approx(dense, rel=1e-7)
    beta = np.linalg.solve(jac.T @ si_j, jac.T @ si_r)
    assert value == pytest.approx((r - jac @ beta) @ np.linalg.solve(sigma, r - jac @ beta), rel=1e-7)
    # r in the span of J: the rival imitates it exactly
    assert (
        abs(
            float(
                ddis.statistic(
                    jnp.asarray(jac @ [0.3, -2.0]), jnp.asarray(jac), jnp.asarray(rig), jnp.asarray(u), t, hyper
                )
            )
        )
        < 1e-9 * dense
    )


def test_rivals_must_be_two_distinct_catalogue_effects():
    assert ddis.rivals(["trapped_air", "fluid_leak"]) == ("trapped_air", "fluid_leak")
    for bad, message in (
        (["trapped_air"], "exactly two"),
        (["trapped_air"] * 2, "twice"),
        (["trapped_air", "no_such_effect"], "unknown effect 'no_such_effect'"),
        (["a", "b", "c"], "exactly two"),
    ):
        with pytest.raises(ValueError, match=message):
            ddis.rivals(bad)


def test_discriminate_command_refuses_bad_input_with_exit_2(capsys, tmp_path):
    for argv, message in (
        (["--discriminate", "trapped_air,no_such_effect"], "unknown effect 'no_such_effect'"),
        (["--discriminate", "trapped_air"], "exactly two"),
        (["--discriminate", "trapped_air,trapped_air"], "trapped_air twice"),
        (["--discriminate", ",".join(PAIR), "--for", "Y"], "give one of them"),
        (["--discriminate", ",".join(PAIR), "--size", "0.3"], "--size takes one size per effect"),
        (["--discriminate", *PAIR[:1], "--discriminate", *PAIR[1:], "--size", "0.3,0.9"], "outside its range"),
        (["--size", "0.3,0.005"], "--size gives"),
        (["--discriminate", ",".join(PAIR), "--sensors", "length,pressure"], "length alone"),
    ):
        try:
            status = cli.main(["design", DATA, "--out", str(tmp_path / "never"), *argv])
        except SystemExit as stop:
            status = stop.code
        assert status == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err, (argv, err)
    assert not (tmp_path / "never").exists()


@eqx.filter_jit
def _solve(problem, inputs, sizes):
    return problem.solve(inputs, sizes)


def _t(problem, truth, rival, k):
    """T of data from the run ``truth`` fitted by the run ``rival`` with effect ``k``'s parameter (0: A, 1: B) free."""
    p = len(problem.names)
    jac = rival[2]
    return float(
        ddis.statistic(
            truth[0] - rival[0],
            jac[:, [*range(p), p + k]],
            jac[:, p + 2 :],
            problem.tolerance,
            problem.times,
            problem.hyper,
        )
    )


@pytest.mark.slow
def test_t_vanishes_for_one_effect_against_itself_and_grows_with_the_true_effects_size(short):
    known, space, problem = short
    inputs = space.inputs(space.unconstrained(RISE_FALL))
    a, b = (syn.moderate_magnitude(e) for e in PAIR)
    run = lambda sa, sb: _solve(problem, inputs, jnp.asarray([sa, sb]))
    # B's model at its moderate size fitting data from A's model at 0.5, 1, 2 times A's moderate size
    rival = run(0.0, b)
    t_ab = [_t(problem, run(f * a, 0.0), rival, 1) for f in (0.5, 1.0, 2.0)]
    assert 0 < t_ab[0] < t_ab[1] < t_ab[2], t_ab
    t_ab_problem, t_ba_problem = (float(v) for v in ddis.statistics(problem, inputs, problem.breaks))
    assert t_ab_problem == pytest.approx(t_ab[1], rel=1e-6)
    assert t_ba_problem == pytest.approx(_t(problem, rival, run(a, 0.0), 0), rel=1e-6)
    # A's model fitting its own data: 0 at the same size; off it only the linearisation's remainder
    own = run(a, 0.0)
    assert _t(problem, own, own, 0) == 0.0
    near = _t(problem, run(1.2 * a, 0.0), own, 0)
    assert near < 1e-6 * t_ab[0], (near, t_ab)


@pytest.mark.slow
def test_the_discrimination_gradient_through_the_model_matches_finite_differences(short):
    known, space, problem = short
    x = space.unconstrained(RISE_FALL)
    value, grad = (np.asarray(v) for v in ddis.value_and_gradient(problem, x))
    assert value == pytest.approx(float(sum(gd.evaluate(problem, x))), rel=1e-4)
    fd = objective_differences(lambda y: sum(gd.evaluate(problem, y)), x)
    # the first knot sets when the growth threshold is crossed (a switch; see tests/test_design.py)
    np.testing.assert_allclose(grad[1:], fd[1:], rtol=0.05, atol=1e-3 * np.max(np.abs(fd)))
    assert np.max(np.abs(fd[1:])) > 1e-2


@pytest.mark.slow
def test_the_discriminating_design_beats_the_published_pulse_and_the_best_random_input(short):
    known, _, _ = short
    # knots every 0.1 s: the published pulse train's short drops to 0 kPa, which both effects answer, are within reach
    space = gd.DesignSpace(2.0, 336e3, _catheter(), knot_spacing=0.1)
    res = gd.discriminate(known, space, PAIR, random=8, starts=1, iterations=8, n_draws=4, seed=0)
    t = {r["input"]: r["T_min"] for r in res.rows}
    assert t["design"] >= t["best random input"] and t["design"] >= t["published pulse train"], t
    assert res.checks["design"].admissible[0]
    s = res.summary()
    assert s["discrimination"]["effects"] == list(PAIR) and s["discrimination"]["threshold"] > 5
    row = next(r for r in s["table"] if r["input"] == "design")
    assert row["T_min"] == min(row["T"].values())
    assert row["expected_to_separate"] == (row["T_min"] > s["discrimination"]["threshold"])
    json.dumps(s)


@pytest.mark.slow
def test_discriminate_command_prints_the_table_and_writes_the_files(tmp_path, capsys):
    saved = tmp_path / "fit.json"
    saved.write_text(
        json.dumps(
            {
                "parameters": {Y: {"estimate": 9000.0, "standard_error": 270.0}},
                "discrepancy": {"amplitude_m": 1e-4, "time_scale_s": 0.8, "noise_m": 2e-4},
                "tolerances": {"robot.catheter_friction": 0.2, "pid.proportional": 0.05},
            }
        )
    )
    out = tmp_path / "discriminate"
    argv = [
        "design",
        DATA,
        "--fit-from",
        str(saved),
        "--discriminate",
        ",".join(PAIR),
        "--duration",
        "2",
        "--knot-spacing",
        "0.5",
        "--scout",
        "3",
        "--starts",
        "1",
        "--descent-steps",
        "2",
        "--check-draws",
        "3",
        "--out",
        str(out),
        "--quiet",
    ]
    assert cli.main(argv) == 0
    text = capsys.readouterr().out
    assert "to tell retraction_folding from trapped_air" in text and "expected to separate" in text
    summary = json.loads((out / "summary.json").read_text())
    rows = {r["input"]: r for r in summary["table"]}
    assert set(rows) == {"published pulse train", "best random input", "design"}
    for label, row in rows.items():
        line = next(ln for ln in text.splitlines() if ln.strip().startswith(label + "  "))
        assert line.split()[-1] == ("yes" if row["expected_to_separate"] else "no")
        assert f"{row['T_min']:.2f}" in line
    assert summary["discrimination"]["sizes"] == [0.3, 0.005]
    assert (out / "design.csv").exists() and (out / "design.png").stat().st_size > 10_000
