"""A posterior's InferenceData works with ArviZ's standard calls: summary, LOO, the predictive check, the trace and
posterior plots, and a NetCDF round trip."""

import matplotlib

matplotlib.use("Agg")

import arviz as az
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
import pytest

import growjax as gj
from growjax import emulator as em
from growjax import posterior as gpost

TIMES = np.arange(0.01, 0.81, 0.01)  # s
GROUPS = {"posterior", "posterior_predictive", "log_likelihood", "sample_stats", "observed_data", "constant_data"}


def _linear_emulator(prior):
    """An emulator whose table is a known length, L = 20 mm/s · (1 − (Y − 9 kPa)/20 kPa) · t, linear in Y (so its
    ghost nodes are exact): NUTS runs in seconds, no model solve or compile of the simulator."""
    spacing = (prior.high - prior.low) / (prior.nodes - 1)
    nodes = prior.low + spacing * np.arange(-1, prior.nodes + 1)  # with one ghost node per side
    values = 2e-2 * (1.0 - (nodes[:, None] - 9000.0) / 20000.0) * TIMES[None, :]
    return em.Emulator(values=jnp.asarray(values), times=jnp.asarray(TIMES), lows=jnp.asarray([prior.low]),
                       highs=jnp.asarray([prior.high]), error_rms=jnp.asarray(0.0), error_max=jnp.asarray(0.0),
                       base=gj.reference(), inputs=None, names=(prior.name,), log=(False,), nodes=(prior.nodes,),
                       config=gj.Config(t1=0.8))


@pytest.fixture(scope="module")
def small_posterior():
    """2 chains × 40 draws of Y and σ, through the emulator above, on data made at Y = 9 kPa with 0.2 mm noise."""
    prior = gpost.paper_priors()[0]
    length = 2e-2 * TIMES + np.random.default_rng(0).normal(0.0, 2e-4, TIMES.size)
    return gpost.sample(TIMES, length, None, config=gj.Config(t1=0.8), priors=[prior], chains=2, warmup=40,
                        samples=40, seed=0, progress=False, emulate=_linear_emulator(prior), discrepancy="none",
                        tolerances={})


def test_the_groups_hold_what_arviz_expects_where_it_looks(small_posterior):
    idata = small_posterior.idata
    assert set(idata.groups()) == GROUPS
    assert set(idata.posterior.data_vars) == {"Y", "sigma"}  # the model's length is not a sampled site
    assert set(idata.posterior_predictive.data_vars) == {"length", "length_new_experiment", "length_model"}
    assert set(idata.observed_data.data_vars) == {"length"}  # no solver_ok beside the data
    np.testing.assert_array_equal(idata.observed_data["time"], TIMES)
    assert idata.posterior_predictive["length_model"].dims == ("chain", "draw", "time")
    assert idata.log_likelihood["length"].shape == (2, 40, TIMES.size)
    assert bool(idata.sample_stats["solver_ok"].all()) and bool(idata.constant_data["scored"].all())
    # The model's length is the replicated length's mean: their difference is the noise, σ ≈ 0.2 mm.
    noise = (idata.posterior_predictive["length"] - idata.posterior_predictive["length_model"]).values
    assert np.std(noise) == pytest.approx(2e-4, rel=0.3)


def test_arviz_summary_loo_and_plots_run_on_it_and_it_survives_netcdf(small_posterior, tmp_path):
    idata = small_posterior.idata
    table = az.summary(idata)
    assert list(table.index) == ["Y", "sigma"]  # by default: the sampled sites, not 80 entries of length_model
    assert table.loc["Y", "mean"] == pytest.approx(9000.0, abs=300.0)
    loo = az.loo(idata)
    assert np.isfinite(loo.elpd_loo) and loo.n_data_points == TIMES.size
    for plot in (az.plot_ppc, az.plot_trace, az.plot_posterior):
        assert np.asarray(plot(idata)).size >= 1, plot.__name__
        plt.close("all")
    path = tmp_path / "posterior.nc"
    idata.to_netcdf(str(path))
    back = az.from_netcdf(str(path))
    assert set(back.groups()) == GROUPS
    np.testing.assert_array_equal(back.posterior_predictive["length_model"], idata.posterior_predictive["length_model"])
    np.testing.assert_array_equal(back.constant_data["scored"], idata.constant_data["scored"])
    assert az.summary(back).equals(table)
    az.plot_ppc(back)
    plt.close("all")


def test_a_likelihood_that_scores_some_samples_keeps_every_sample_observed():
    """With a discrepancy on a piecewise-linear record only its keyframes are scored (the log-likelihood is 0
    elsewhere); the observed, replicated and model lengths still cover every sample, so the predictive check
    pairs them, and ``scored`` says which samples LOO counts."""
    rng = np.random.default_rng(1)
    chains, draws, n = 2, 30, TIMES.size
    model = 2e-2 * TIMES * (1.0 + 0.01 * rng.standard_normal((chains, draws, 1)))
    scored = np.zeros(n, bool)
    scored[::8] = True
    loglik = np.where(scored, rng.normal(5.0, 0.1, (chains, draws, n)), 0.0)
    fields = {"diverging": np.zeros((chains, draws), bool), "energy": rng.normal(size=(chains, draws)),
              "num_steps": np.full((chains, draws), 7)}
    idata = gpost.inference_data({"Y": rng.normal(9e3, 1e2, (chains, draws)), "sigma": np.full((chains, draws), 2e-4),
                                  "length_model": model}, fields, TIMES, 2e-2 * TIMES, scored, loglik,
                                 model + 2e-4 * rng.standard_normal(model.shape))
    assert idata.observed_data["length"].shape == (n,) and int(idata.constant_data["scored"].sum()) == 10
    assert set(idata.sample_stats.data_vars) == {"diverging", "energy", "n_steps", "tree_depth", "solver_ok"}
    assert int(idata.sample_stats["tree_depth"].max()) == 3  # 7 leapfrog steps: a tree of depth 3
    az.plot_ppc(idata)
    plt.close("all")
    assert az.loo(idata).n_data_points == n
