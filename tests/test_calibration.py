"""Calibration: recovery of known parameters by the fit, NUTS diagnostics and posterior coverage on a test problem."""

import numpy as np
import pytest

import growjax as gj
from growjax import fit as gf
from growjax import posterior as gpost

TRUTH_Y = 9000.0
NOISE = 2e-4  # m


def _synthetic(t1, seed):
    """Length data made by the quasi-static model itself (Y = 9 kPa, σ = 0.2 mm), so any bias is the estimator's."""
    cfg = gj.QuasiStaticConfig(t1=t1)
    t = np.array([0.0, 100.0])
    inputs = gj.Inputs(catheter_length=gj.Sampled(t, 0.004 + 0.004 * t), pressure_demand=gj.published_pulse())
    traj = gj.simulate(gj.replace(gj.reference(), Y=TRUTH_Y), inputs, cfg)
    times = np.arange(0.01, t1 + 1e-9, 0.01)
    clean = np.interp(times, np.asarray(traj.time), np.asarray(traj.length))
    return cfg, inputs, times, clean + np.random.default_rng(seed).normal(0.0, NOISE, times.size)


def test_fit_recovers_the_yield_pressure_from_every_start():
    cfg, inputs, times, length = _synthetic(2.0, seed=11)
    res = gf.fit(times, length, inputs, free=["Y"], config=cfg, n_starts=3, sweep_n=16, seed=1)
    est = res.estimate["robot.yield_pressure"]
    lo, hi = res.interval_90["robot.yield_pressure"]
    assert res.status == "converged"
    assert abs(est - TRUTH_Y) < 0.01 * TRUTH_Y
    assert lo < TRUTH_Y < hi
    assert res.rmse_length_m == pytest.approx(NOISE, rel=0.15)
    starts = [s["estimate"]["robot.yield_pressure"] for s in res.starts]
    assert len(starts) == 3 and np.ptp(starts) < 1e-6 * est  # every start reaches the same optimum


@pytest.mark.slow
def test_fit_names_ext_and_n_as_undetermined():
    cfg, inputs, times, length = _synthetic(2.0, seed=12)
    res = gf.fit(times, length, inputs, free=["Y", "ext", "n"], config=cfg, n_starts=2, sweep_n=16)
    assert abs(res.estimate["robot.yield_pressure"] - TRUTH_Y) < 0.01 * TRUTH_Y
    assert len(res.undetermined) == 2
    assert res.interval_90["robot.extensibility"] is None and res.interval_90["robot.growth_exponent"] is None
    assert res.interval_90["robot.yield_pressure"] is not None


def test_nuts_on_the_test_problem_is_converged_and_covers_the_truth():
    cfg, inputs, times, length = _synthetic(0.8, seed=13)
    priors = gpost.paper_priors()[:1]
    res = gpost.sample(times, length, inputs, config=cfg, priors=priors, chains=2, warmup=80, samples=80,
                       seed=3, progress=False)
    s = res.summary
    assert s["divergences"] == 0
    assert s["rhat_max"] < 1.05
    assert s["ess_bulk_min"] > 40
    lo, hi = s["parameters"]["Y"]["interval_90"]
    assert lo < TRUTH_Y < hi
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

    from growjax import emulator as em

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
    emulated = gpost.sample(times, length, inputs, **kw).summary["parameters"]["Y"]
    direct = gpost.sample(times, length, inputs, emulate=False, **kw).summary["parameters"]["Y"]
    assert emulated["mean"] == pytest.approx(direct["mean"], abs=0.3 * direct["sd"])
    assert emulated["sd"] == pytest.approx(direct["sd"], rel=0.2)
