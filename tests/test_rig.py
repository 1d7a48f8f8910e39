"""The rig's tolerances in the fit: inferred from the data (the default, the posterior's treatment) or held
nominal and propagated (``rig="fixed"``)."""

import functools
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import one_experiment

import growjax as gj
from growjax import calibration as cal
from growjax.calibration import batch as cb
from growjax.calibration import discrepancy as dc

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "data"))
import make_synthetic as mk

Y = "robot.yield_pressure"
RIG_OFF = "published_Y9000_screw_friction_low"  # reference-made, the lead screw's friction 10 % below nominal


def _likelihood(inferred: bool, n=120):
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 10.0, n))
    used = np.ones(n, bool)
    used[::7] = False  # samples the likelihood does not score
    g = rng.normal(0.0, 1e-4, (n, 3))  # m per unit ln ψ
    u = np.array([0.2, 0.05, 0.1])
    lik = cal.RunScore.of(t, used, 1e-3)
    raw = (
        jnp.asarray(rng.normal(0.0, 0.2, n)),
        jnp.asarray(rng.normal(0.0, 5.0, (n, 2))),
    )  # σ_L, σ_L per unit z
    return lik.with_tolerances(g, dict(zip(("a", "b", "c"), u)), inferred=inferred), raw, t, used, g, u


def test_inferred_rig_covariance_is_the_marginal_gls_and_its_budget_adds_up():
    """With the rig inferred the covariance of z is (Jᵀ(K + G U Gᵀ)⁻¹J)⁻¹ (the rig's errors marginalised under
    their priors, as the posterior does), its parts add up to it, and the fixed propagation (the GLS estimator
    that ignores the rig, under the same residual covariance) is nowhere narrower."""
    hyper = dc.Hyper.of(3e-4, 1.2, 2e-4, 0.02)
    lik, raw, t, used, g, u = _likelihood(inferred=True)
    cov, parts, _ = lik.covariance(raw, hyper, np.array([0.05, -0.01, 0.02]))
    k = dc.kernel(t[used], hyper) + dc.noise_kernel(t[used], hyper) + (g[used] * u**2) @ g[used].T
    j = np.asarray(raw[1])[used] * 1e-3
    np.testing.assert_allclose(cov, np.linalg.inv(j.T @ np.linalg.solve(k, j)), rtol=1e-8)
    np.testing.assert_allclose(sum(parts.values()), cov, rtol=1e-10)
    assert set(parts) == {"noise", "discrepancy", "a", "b", "c"}
    lik_fixed, raw, *_ = _likelihood(inferred=False)
    fixed, fixed_parts, _ = lik_fixed.covariance(raw, hyper, np.zeros(0))
    assert np.all(np.linalg.eigvalsh(fixed - cov) > -1e-12 * np.max(np.diag(cov)))
    assert fixed_parts["a"][0, 0] > parts["a"][0, 0]  # the data inform the rig: less is left of its prior


@pytest.fixture(scope="module")
def rig_off():
    (
        t,
        lengths,
        cases,
    ) = mk.read_reference_lengths()
    data = lengths[RIG_OFF] + np.random.default_rng(5).normal(0.0, 2e-4, t.size)
    fit = lambda rig, **kw: cal.fit(
        one_experiment(t, data, mk.reference_inputs("published")),
        ["Y"],
        likelihood=cal.Likelihood(rig=rig),
        config=gj.Config(t1=10.0),
        starts=1,
        scout=0,
        **kw,
    )
    points = {"tangents": [], "secants": []}  # (z, the rig's values) of every run of the model in a fit
    spread = cb.spread

    def counted(kind):
        def run(program, z_local, problems, stacked=True):
            rig = np.concatenate([np.ravel(np.asarray(x, float)) for x in jax.tree_util.tree_leaves(problems.base)])
            points[kind].append(np.asarray(z_local, float).tobytes() + rig.tobytes())
            return spread(program, z_local, problems, stacked)

        return run

    def counting(kind, **kw):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(cb, "spread", counted(kind))
            return fit("inferred", **kw)

    # the rig's secants (``rig_tangents=False``, not the default) and the secants linearised once: the slow tests',
    # fitted when first asked for
    secants = functools.cache(lambda: counting("secants", rig_tangents=False))
    once = functools.cache(lambda: fit("inferred", rig_tangents=False, relinearise=False))
    return (
        cases[RIG_OFF]["parameters"]["Y"],
        {"once": once, "fixed": fit("fixed"), "secants": secants, "tangents": counting("tangents")},
        points,
    )


def test_the_data_inform_the_rig_on_reference_made_data(rig_off):
    """Reference-made data with the screw friction 10 % low: with the rig inferred (by default its errors are
    parameters of the model, fitted in its exact tangents) Y's interval covers the truth and is under half as wide
    as the fixed propagation's (which also covers), and the friction's fitted error points the right way."""
    truth, fits, _ = rig_off
    inferred, fixed = fits["tangents"], fits["fixed"]
    for res in (fits["fixed"], fits["tangents"]):
        assert res.interval_90[Y][0] <= truth <= res.interval_90[Y][1], (res.rig, res.estimate, res.interval_90)
    width = lambda res: res.interval_90[Y][1] - res.interval_90[Y][0]
    assert width(inferred) < 0.5 * width(fixed)
    assert inferred.rig == "inferred" and fixed.rig == "fixed" and fixed.rig_offset == {}
    assert inferred.rig_offset["rig"]["pump.screw_viscous_friction"] < 0.0
    assert inferred.status == "converged" and inferred.linearisations == 1  # exact slopes: nothing to take again
    budget = inferred.budget[Y]
    assert sum(v**2 for v in budget.values()) == pytest.approx(inferred.standard_error[Y] ** 2, rel=1e-6)


@pytest.mark.slow
def test_the_rigs_secants_agree_with_its_tangents_where_both_reach(rig_off):
    """``rig_tangents=False``: the rig's secants. The friction's error is a quarter of its tolerance: the secants
    are taken again where the rig settled; Y agrees with the tangents' within a standard error, the two intervals'
    widths within 15 %, and the friction is read low."""
    truth, fits, points = rig_off
    secants, tangents = fits["secants"](), fits["tangents"]
    assert secants.interval_90[Y][0] <= truth <= secants.interval_90[Y][1]
    assert fits["fixed"].linearisations == 1 and secants.linearisations >= 2
    assert len(points["secants"]) > 10 and len(set(points["secants"])) == len(points["secants"])
    assert abs(tangents.estimate[Y] - secants.estimate[Y]) < secants.standard_error[Y]
    width = lambda res: res.interval_90[Y][1] - res.interval_90[Y][0]
    assert width(tangents) == pytest.approx(width(secants), rel=0.15)
    assert secants.rig_offset["rig"]["pump.screw_viscous_friction"] < 0.0


@pytest.mark.slow
def test_relinearising_the_secants_moves_the_estimate_by_less_than_a_standard_error(rig_off):
    """The secants linearised once, at nominal, cover the truth; taken again where the rig settled, the estimate
    moves by less than a standard error."""
    truth, fits, _ = rig_off
    once, secants = fits["once"](), fits["secants"]()
    assert once.linearisations == 1 and once.interval_90[Y][0] <= truth <= once.interval_90[Y][1]
    assert abs(secants.estimate[Y] - once.estimate[Y]) < once.standard_error[Y]


def test_the_fit_runs_the_model_once_per_point(rig_off):
    """The fit's solvers and its hyperparameter steps ask again for points already run (a solver starts where the
    last one ended); each point of (z, rig) is run once, the repeats served from what was kept."""
    *_, points = rig_off  # (the rig's secants: the slow test above)
    seen = points["tangents"]
    assert len(seen) > 10 and len(set(seen)) == len(seen)


def test_an_unknown_rig_treatment_is_refused():
    with pytest.raises(ValueError, match="rig must be one of"):
        cal.Likelihood(rig="known")


@pytest.mark.slow
def test_fit_and_posterior_agree_on_the_shipped_data(synthetic_experiment):
    """The shipped synthetic experiment: the fit's and the posterior's 90 % intervals of Y agree within 25 % in
    width (both infer the rig), the fixed propagation is far wider, and the posterior's band of this experiment
    replicated holds 0.85–0.95 of the measured points while a new experiment's is wider."""
    from growjax import posterior as gpost
    from growjax.data import sets as xs

    exp = synthetic_experiment
    base = gj.replace(gj.reference("forward"), Y=9000.0)
    config = gj.Config(t1=10.0)
    width = lambda iv: iv[1] - iv[0]
    one = xs.ExperimentSet.single(exp, defaults=base)
    fit = cal.fit(one, config=config)
    fixed = cal.fit(one, likelihood=cal.Likelihood(rig="fixed"), config=config)
    length_only = xs.ExperimentSet.single(exp, defaults=base, sensors=["length"])
    post = gpost.sample(length_only, config=config, emulate=True, progress=False)
    posterior_width = width(post.summary["parameters"]["Y"]["interval_90"])
    assert abs(width(fit.interval_90[Y]) / posterior_width - 1.0) < 0.25
    assert width(fixed.interval_90[Y]) > 2.0 * width(fit.interval_90[Y])
    assert 0.85 <= post.summary["coverage_90"] <= 0.95
    assert post.summary["coverage_90_new_experiment"] >= post.summary["coverage_90"]


def test_the_posterior_linearised_away_from_nominal_keeps_the_rig_prior_about_nominal():
    """The posterior's likelihood with the rig linearised at errors c (the model there, the rig's errors b' from
    there with the prior N(−c, u²)) is the likelihood of the rig's errors b = c + b' ~ N(0, u²): the same
    distribution as at nominal with the model shifted by −g·c, both for the scored data and for the smoother."""
    from growjax import posterior as gpost

    rng = np.random.default_rng(7)
    t = np.arange(1, 201) * 0.02
    g = rng.normal(0.0, 1e-3, (t.size, 2))
    u, c = np.array([0.2, 0.05]), np.array([0.3, -0.04])
    observed = np.ones(t.size, bool)
    observed[::5] = False
    at_c = gpost.Residuals("matern32", t, observed, g, u, ("a", "b"), c)
    nominal = gpost.Residuals("matern32", t, observed, g, u, ("a", "b"))
    hyper = dc.Hyper.of(3e-4, 0.7, 2e-4, 0.0)
    mu = jnp.asarray(0.01 + 0.003 * t)
    y = np.asarray(mu) + rng.normal(0.0, 5e-4, t.size)
    shifted = mu - jnp.asarray(g @ c)
    assert float(at_c.distribution(mu, hyper).log_prob(jnp.asarray(y)[at_c.index])) == pytest.approx(
        float(nominal.distribution(shifted, hyper).log_prob(jnp.asarray(y)[nominal.index])), rel=1e-12
    )
    mean_c, var_c = at_c.conditional(jnp.asarray(y), mu, hyper)
    mean_0, var_0 = nominal.conditional(jnp.asarray(y), shifted, hyper)
    np.testing.assert_allclose(np.asarray(mean_c), np.asarray(mean_0) - g @ c, atol=1e-12)
    np.testing.assert_allclose(np.asarray(var_c), np.asarray(var_0), rtol=1e-10)
    assert nominal.rig_mean() == 0.0


def test_a_rig_centre_naming_an_untoleranced_parameter_is_refused():
    from growjax import posterior as gpost

    with pytest.raises(ValueError, match="rig_centre names .*pump.hose_length"):
        gpost.sample(one_experiment(np.linspace(0, 1, 5), np.zeros(5)), rig_centre={"pump.hose_length": 0.1})


@pytest.mark.slow
def test_a_rig_misfit_that_runs_y_to_zero_with_the_rig_nominal_is_brought_back_by_the_rigs_errors():
    """A stepper run driven by its recorded length, on a rig drawn off nominal (both frictions 20 % low), with a
    Matérn discrepancy (one replication of ``benchmarks/design.py --next-drive inverse --discrepancy-in-data``,
    its draws in the benchmark's order). With the rig held nominal, least squares runs Y out of its box toward
    ~0 Pa, where it no longer acts and the rig's errors cannot pull it back; the fit takes the rig's errors from
    the box's edge as well, and the estimate covers the truth with a finite interval."""
    from growjax import design as gd
    from growjax.data import experiment as ex

    truth_y, noise, hyper = 8975.38, 2.0169e-4, dc.Hyper.of(2.927e-5, 1.964, 0.0, 0.0)
    base = gj.replace(gj.reference("inverse"), Y=9000.0)
    rng = np.random.default_rng([0, 2])
    tolerances = {
        "pid.proportional": 0.05,
        "pid.integral": 0.05,
        "pump.screw_viscous_friction": 0.2,
        "pump.syringe_area": 0.02,
        "tank.length": 0.05,
        "robot.catheter_friction": 0.2,
    }
    offsets = {n: float(rng.normal(0.0, u)) for n, u in tolerances.items()}
    rig = gj.replace(base, Y=truth_y, **{n: gj.get(base, n) * np.exp(b) for n, b in offsets.items()})
    space = gd.stepper_space(
        base, 10.0, ex.read(REPO / "src" / "growjax" / "data" / "datasets" / "synthetic_forward.csv")
    )
    t = space.times
    rng.normal(0.0, noise, t.size), rng.integers(2**31)  # the designed run's draws, made first in the benchmark
    maker = gj.Config(fidelity="reference", drive="inverse", t1=10.0)
    inputs = space.baseline_inputs()
    length = np.asarray(gj.simulate(rig, inputs, maker, ts=np.concatenate([[maker.t0], t])).length)[1:]
    length = length + rng.normal(0.0, noise, t.size)
    length = length + np.asarray(dc.draw(jax.random.PRNGKey(int(rng.integers(2**31))), t, hyper))
    res = cal.fit(
        one_experiment(t, length, inputs, base=gj.replace(base, Y=truth_y), drive="inverse"),
        ["Y"],
        config=gj.Config(drive="inverse", t1=10.0),
        starts=1,
        scout=16,
    )
    assert res.starts[0]["estimate"][Y] < 2500.0, res.starts  # the rig held nominal: Y run out of its box
    assert res.interval_90[Y] is not None, res.estimate
    lo, hi = res.interval_90[Y]
    assert lo <= truth_y <= hi and hi / lo < 1.5, (lo, hi)
