"""The population of robots built alike: the hierarchical layer's coverage, the rig shared by its robots, the
new robot's predictive band, and the command line."""

from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

import growjax as gj
from growjax import cli
from growjax.calibration import Coordinate, FitResult
from growjax.data import experiment as ex
from growjax.data import sets as xs
from growjax.posterior import population as pop

Y = "robot.yield_pressure"
SET = Path(str(files("growjax.data") / "datasets" / "set"))
MEDIAN, SPREAD, ROBOTS = 8e3, 0.1, 8
SIGMA = 0.015  # each robot's own sd of ln Y from its data
G = np.array([0.4, 0.2])  # every robot's ln Y per unit rig error: the rig moves all robots alike
U = np.array([0.2, 0.1])  # the rig's tolerances


def _set_fit(z_hat, robots, runs=None):
    """A joint fit's Gaussian: data ln Ŷ = ln Y + G b + e (e ~ N(0, σ²)), b ~ N(0, U²), ln Y flat."""
    r = z_hat.size
    gu = np.outer(np.ones(r), G * U**2)  # (R, Q): cov(ẑ, b) = −G U² with b̂ = 0, sign immaterial here
    joint = np.block([[SIGMA**2 * np.eye(r) + (G * U**2) @ G * np.ones((r, r)), -gu], [-gu.T, np.diag(U**2)]])
    labels = tuple(f"{Y}@{k}" for k in robots)
    est = dict(zip(labels, np.exp(z_hat)))
    return FitResult(
        labels,
        est,
        {},
        {},
        joint[:r, :r],
        coordinates=tuple(Coordinate(f"{Y}@{k}", Y, "robot", k) for k in robots),
        runs=runs or [],
        rig="inferred",
        rig_labels=(("rig", "pump.screw_viscous_friction"), ("rig", "robot.catheter_friction")),
        rig_vector=np.zeros(2),
        joint_covariance=joint,
    )


def _coverage(populations: int, shared_rig: bool):
    hits = {"mu": [], "s": []}
    robots = tuple(f"r{i}" for i in range(ROBOTS))
    for k in range(populations):
        rng = np.random.default_rng(k)
        z = np.log(MEDIAN) + SPREAD * rng.standard_normal(ROBOTS)
        z_hat = z + G @ (U * rng.standard_normal(2)) + SIGMA * rng.standard_normal(ROBOTS)
        fit = _set_fit(z_hat, robots)
        if not shared_rig:  # each robot's error taken as its own: the rig's part of the covariance made diagonal
            j = fit.joint_covariance.copy()
            j[:ROBOTS, :ROBOTS] = np.diag(np.diag(j[:ROBOTS, :ROBOTS]))
            j[:ROBOTS, ROBOTS:] = j[ROBOTS:, :ROBOTS] = 0.0
            fit.joint_covariance = j
        post = pop.sample_population(fit, "Y", chains=1, warmup=200, samples=300, seed=k)
        lo, _, hi = post.interval(post.mu)
        hits["mu"].append(lo <= np.log(MEDIAN) <= hi)
        lo, _, hi = post.interval(post.s)
        hits["s"].append(lo <= SPREAD <= hi)
    return {k: float(np.mean(v)) for k, v in hits.items()}


@pytest.mark.parametrize("populations", [20, pytest.param(30, marks=pytest.mark.slow)])
def test_the_population_covers_its_median_and_spread_and_an_unshared_rig_does_not(populations):
    shared = _coverage(populations, shared_rig=True)
    assert 0.8 <= shared["mu"] <= 1.0 and 0.8 <= shared["s"] <= 1.0, shared
    independent = _coverage(populations, shared_rig=False)
    assert independent["mu"] <= shared["mu"] - 0.1, (shared, independent)


def test_the_likelihood_keeps_the_robots_and_the_rig_and_refuses_a_fit_without_them():
    fit = _set_fit(np.log([7e3, 8e3, 9e3]), ("a", "b", "c"))
    robots, labels, z_hat, b_hat, cov = pop.linearised_likelihood(fit, Y)
    assert robots == ("a", "b", "c") and np.allclose(np.exp(z_hat), [7e3, 8e3, 9e3]) and cov.shape == (5, 5)
    fit.joint_covariance = None
    with pytest.raises(ValueError, match="rig inferred"):
        pop.linearised_likelihood(fit, Y)
    with pytest.raises(ValueError, match="free it as robot.extensibility@robot"):
        pop.linearised_likelihood(_set_fit(np.log([7e3, 8e3]), ("a", "b")), "robot.extensibility")


def test_the_robots_are_drawn_from_their_exact_gaussian_given_the_population():
    """ln θ | μ, s, data: the dense Gaussian's mean (s²I + C)⁻¹ weighting and covariance (I/s² + C⁻¹)⁻¹,
    matched by 200 000 draws; at s = 0 every robot sits at μ."""
    rng = np.random.default_rng(1)
    a = rng.normal(size=(3, 3))
    cov = 0.01 * (a @ a.T + 0.5 * np.eye(3))
    z_hat, mu, s = np.log([7e3, 8e3, 9.5e3]), np.log(8e3), 0.1
    draws = pop.robots_given(np.full(200_000, mu), np.full(200_000, s), z_hat, cov, np.random.default_rng(2))
    precision = np.eye(3) / s**2 + np.linalg.inv(cov)
    exact_cov = np.linalg.inv(precision)
    exact_mean = exact_cov @ (mu / s**2 + np.linalg.solve(cov, z_hat))
    assert np.max(np.abs(draws.mean(axis=0) - exact_mean)) < 5 * np.sqrt(np.max(np.diag(exact_cov)) / 200_000)
    np.testing.assert_allclose(np.cov(draws.T), exact_cov, rtol=0.02, atol=0.02 * np.max(np.diag(exact_cov)))
    at_zero = pop.robots_given(np.array([mu, mu + 0.1]), np.zeros(2), z_hat, cov, np.random.default_rng(3))
    np.testing.assert_allclose(at_zero, [[mu] * 3, [mu + 0.1] * 3], atol=1e-15)


def test_a_new_robot_band_centres_on_the_population_and_widens_with_its_spread():
    exps = xs.read([SET / "set.toml"])
    run = exps.runs[1]
    hyper = {"amplitude_m": 2e-5, "time_scale_s": 1.0, "noise_m": 2e-4, "noise_time_s": 0.0}
    fit = _set_fit(np.log([7.5e3, 8e3, 8.5e3]), ("a", "b", "c"), runs=[{"discrepancy": hyper}] * 3)
    post = pop.sample_population(fit, "Y", chains=2, warmup=200, samples=100, seed=0)
    # two chains from their own starts sample one posterior, without a divergence (the robots are integrated out)
    assert post.mu.size == 200 and post.diagnostics["mu"]["r_hat"] < 1.2 and post.diagnostics["divergences"] == 0
    with pytest.raises(ValueError, match="chains"):
        pop.sample_population(fit, "Y", chains=0)
    config = gj.Config(t1=3.0)
    band = pop.predict_new_robot(post, run, config, draws=64, seed=0)
    wide = pop.PopulationResult(**{**post.__dict__, "s": post.s + 0.3})
    wider = pop.predict_new_robot(wide, run, config, draws=64, seed=0)
    at_median = gj.simulate(
        gj.replace(run.base(), Y=float(np.exp(np.median(post.mu)))),
        ex.to_inputs(run.experiment, run.drive, run.base(), config.t0, config.t1),
        config,
        ts=np.concatenate([[config.t0], band["times"]]),
    )
    assert band["failed"] == 0 and band["draws"].shape == (64, band["times"].size)
    assert np.all(band["lower"] < band["upper"])
    assert np.median(np.abs(band["median"] - np.asarray(at_median.length)[1:])) < 0.3e-3
    assert np.median(wider["upper"] - wider["lower"]) > 1.2 * np.median(band["upper"] - band["lower"])


def test_the_command_line_wants_several_robots_for_a_population(tmp_path, capsys):
    code = cli.main(["posterior", str(SET / "set.toml"), "--hierarchical", "Y", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "two or more robots" in err[0]
    code = cli.main(["posterior", str(SET / "set.toml"), "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "--hierarchical" in err[0]


@pytest.mark.slow
def test_the_command_line_samples_a_population_of_three_robots(tmp_path):
    manifest = tmp_path / "pop.toml"
    rows = "\n".join(
        f'[[experiment]]\nfile = "{SET / f}"\nrobot = "{r}"\n'
        for f, r in (("pulse_published.csv", "a"), ("pulse_slow.csv", "b"), ("pulse_100kPa.csv", "c"))
    )
    manifest.write_text('[defaults]\ndrive = "forward"\nrig = "bench"\n' + rows)
    out = tmp_path / "out"
    code = cli.main(
        [
            "posterior",
            str(manifest),
            "--hierarchical",
            "Y",
            "--t-end",
            "4",
            "--chains",
            "2",
            "--warmup",
            "200",
            "--samples",
            "200",
            "--out",
            str(out),
            "--json",
            str(tmp_path / "s.json"),
            "--quiet",
        ]
    )
    import json

    s = json.loads((tmp_path / "s.json").read_text())
    assert code == 0 and (out / "population.nc").exists() and (out / "population.png").exists()
    lo, hi = s["population_median"]["interval_90"]
    assert lo <= 9e3 <= hi  # the shipped set's one membrane, Y = 9 kPa, run as three "robots"
