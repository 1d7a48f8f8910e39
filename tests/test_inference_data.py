"""A posterior's DataTree works with ArviZ 1.x's standard calls (arviz-base, arviz-stats, arviz-plots) as users make
them: on the saved file, with matplotlib's default style, ``arviz_plots`` imported on its own; summary, LOO, the
trace, rank, energy and predictive-check plots, and a netCDF round trip."""

import importlib.metadata
import subprocess
import sys
import tomllib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import arviz_stats as azs
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
import pytest
import xarray as xr
from conftest import linear_emulator, one_experiment
from packaging.requirements import Requirement

import growjax as gj
from growjax import plotting as gplot
from growjax import posterior as gpost
from growjax.calibration import Likelihood

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def azp():
    """ArviZ 1.x's plots (imported here: an environment outside the pins fails each plot test, not the collection)."""
    import arviz_plots

    return arviz_plots


TIMES = np.arange(0.01, 0.81, 0.01)  # s
GROUPS = {"posterior", "posterior_predictive", "log_likelihood", "sample_stats", "observed_data", "constant_data"}


@pytest.fixture(scope="module")
def small_posterior():
    """2 chains × 40 draws of Y and σ, through the emulator above, on data made at Y = 9 kPa with 0.2 mm noise."""
    prior = gpost.paper_priors()[0]
    length = 2e-2 * TIMES + np.random.default_rng(0).normal(0.0, 2e-4, TIMES.size)
    return gpost.sample(
        one_experiment(TIMES, length),
        config=gj.Config(t1=0.8),
        priors=[prior],
        chains=2,
        warmup=40,
        samples=40,
        seed=0,
        progress=False,
        emulate=linear_emulator(prior, TIMES),
        likelihood=Likelihood(discrepancy="none", tolerances={}, model_error=0.0),
    )


@pytest.fixture(scope="module")
def saved(small_posterior, tmp_path_factory):
    """The posterior as a user reads it: written as netCDF (as ``growjax posterior`` writes posterior.nc) and opened
    again with xarray (ArviZ 1.x's ``from_netcdf``)."""
    path = tmp_path_factory.mktemp("posterior") / "posterior.nc"
    small_posterior.idata.to_netcdf(str(path))
    with xr.open_datatree(str(path)) as tree:
        return tree.load()


def test_the_groups_hold_what_arviz_expects_where_it_looks(small_posterior):
    idata = small_posterior.idata
    assert isinstance(idata, xr.DataTree) and set(idata.children) == GROUPS
    assert set(idata.posterior.data_vars) == {"Y", "sigma_mm"}  # the model's length is not a sampled site
    assert set(idata.posterior_predictive.data_vars) == {"length", "length_new_experiment", "length_model"}
    assert set(idata.observed_data.data_vars) == {"length"}  # no solver_ok beside the data
    np.testing.assert_array_equal(idata.observed_data["time"], TIMES)
    assert idata.posterior_predictive["length_model"].dims == ("chain", "draw", "time")
    assert idata.log_likelihood["length"].shape == (2, 40, TIMES.size)
    assert bool(idata.sample_stats["solver_ok"].all()) and bool(idata.constant_data["scored"].all())
    # The model's length is the replicated length's mean: their difference is the noise, σ ≈ 0.2 mm.
    noise = (idata.posterior_predictive["length"] - idata.posterior_predictive["length_model"]).values
    assert np.std(noise) == pytest.approx(2e-4, rel=0.3)


def test_the_noise_is_recorded_in_mm_and_the_summary_json_keeps_si(small_posterior, saved):
    post = small_posterior.idata.posterior
    assert post["sigma_mm"].attrs["units"] == "mm" and "units" not in post["Y"].attrs
    assert saved.posterior["sigma_mm"].attrs["units"] == "mm" and saved.observed_data["length"].attrs["units"] == "m"
    assert saved.posterior_predictive["time"].attrs["units"] == "s"
    assert "units" not in saved.log_likelihood["length"].attrs  # a log-density, not a length
    assert float(post["sigma_mm"].mean()) == pytest.approx(0.2, abs=0.05)  # the data's noise, 0.2 mm
    sigma = gpost.site_draws(post, "sigma")
    np.testing.assert_allclose(sigma, post["sigma_mm"] / 1e3, rtol=1e-15)
    assert gpost.recorded_name("sigma") == "sigma_mm" and gpost.recorded_name("Y") == "Y"
    json_sigma = small_posterior.summary["parameters"]["sigma"]  # m, as every length in growjax's JSON
    assert json_sigma["mean"] == pytest.approx(float(sigma.mean()), rel=1e-12)
    assert json_sigma["interval_90"][0] == pytest.approx(float(np.quantile(sigma, 0.05)), rel=1e-12)


def test_the_posterior_model_marginalises_the_configurations_error_as_a_slow_drift():
    """The likelihood NUTS samples with ``discrepancy="none"`` and the fast configuration's allowance is the Gaussian
    whose covariance is the noise plus the drift's (`growjax.calibration.discrepancy.drift_columns`), as the fit's;
    without the allowance it is independent noise. (The whole posterior run: the slow test below.)"""
    from numpyro.infer.util import log_density
    from scipy import stats

    from growjax.calibration import FAST_MODEL_ERROR, MODEL_ERROR_TIME
    from growjax.calibration import discrepancy as dc

    times = np.arange(0.1, 10.0, 0.1)
    mu = 2e-2 * times
    y = mu + np.random.default_rng(4).normal(0.0, 5e-5, times.size)
    prior = gpost.paper_priors()[0]
    values = {"Y": 9000.0, "sigma": 7e-5}

    def total(model_error):
        residuals = gpost.Residuals("none", times, np.ones(times.size, bool), model_error=model_error)
        model = lambda data: gpost.growth_model(  # noqa: E731
            data, mean_length=lambda th: jnp.asarray(mu), priors=[prior], residuals=residuals
        )
        return float(log_density(model, (jnp.asarray(y),), {}, values)[0])

    drift = dc.drift_columns(times, FAST_MODEL_ERROR, MODEL_ERROR_TIME)
    dense = stats.multivariate_normal(mu, 7e-5**2 * np.eye(times.size) + drift @ drift.T).logpdf(y)
    white = stats.norm(mu, 7e-5).logpdf(y).sum()
    carried, bare = total(FAST_MODEL_ERROR), total(0.0)
    assert carried - bare == pytest.approx(dense - white, rel=1e-8, abs=1e-6)  # the priors' terms cancel
    assert abs(carried - bare) > 0.5  # the drift's term is there


@pytest.mark.slow  # the end-to-end run of the model above: ~90 s of compiling
def test_the_posterior_carries_the_fits_model_error_allowance_without_a_discrepancy():
    """``discrepancy="none"``: the posterior reads the configuration's error allowance from the likelihood's options
    as the fit does (`growjax.calibration.FAST_MODEL_ERROR` for the fast configuration) and marginalises it as the
    slow drift the fit carries. On a length linear in Y over 10 s the drift, not the noise, limits Y (the
    posterior's sd of Y grows over the allowance-free one's by the factor the Gaussian marginal gives)."""
    from growjax.calibration import FAST_MODEL_ERROR, MODEL_ERROR_TIME
    from growjax.calibration import discrepancy as dc

    prior = gpost.paper_priors()[0]
    times = np.arange(0.1, 10.0, 0.1)
    length = 2e-2 * times + np.random.default_rng(4).normal(0.0, 5e-5, times.size)
    config = gj.Config(t1=10.0)
    none = Likelihood(discrepancy="none", tolerances={})
    kw = dict(config=config, priors=[prior], chains=2, warmup=150, samples=300, seed=0, progress=False)
    emulate = linear_emulator(prior, times)
    carried = gpost.sample(one_experiment(times, length), likelihood=none, emulate=emulate, **kw)
    bare = gpost.sample(one_experiment(times, length), likelihood=none.replace(model_error=0.0), emulate=emulate, **kw)
    assert none.model_error_for(config) == FAST_MODEL_ERROR  # what the fit propagates (its fast_model_error)
    assert carried.summary["configuration_error_m"] == carried.residuals.model_error == FAST_MODEL_ERROR
    assert bare.residuals is None and bare.summary["configuration_error_m"] == 0.0
    jac = -1e-6 * times  # dL/dY, m/Pa
    drift = dc.drift_columns(times, FAST_MODEL_ERROR, MODEL_ERROR_TIME)
    noise = 5e-5**2 * np.eye(times.size)
    widened = np.sqrt((jac @ jac / 5e-5**2) / (jac @ np.linalg.solve(noise + drift @ drift.T, jac)))
    assert widened > 1.5  # the drift, not the noise, limits Y
    sd = lambda res: res.summary["parameters"]["Y"]["sd"]  # noqa: E731
    assert sd(carried) / sd(bare) == pytest.approx(widened, rel=0.15)


def test_arviz_summary_shows_the_noise_at_its_default_rounding(saved):
    table = azs.summary(saved)
    assert list(table.index) == ["Y", "sigma_mm"]  # by default: the sampled sites, not 80 entries of length_model
    assert table.loc["Y", "mean"] == pytest.approx(9000.0, abs=300.0) and table.loc["Y", "r_hat"] < 1.1
    noise = table.loc["sigma_mm"]
    assert noise["mean"] == pytest.approx(0.2, abs=0.05)  # two decimals of mm: 0.2 mm, not 0.00 m
    assert 0.0 < noise["eti89_lb"] < noise["mean"] < noise["eti89_ub"] and noise["sd"] > 0.0


def test_loo_reads_every_scored_sample(saved):
    loo = azs.loo(saved)
    assert np.isfinite(loo.elpd) and np.isfinite(loo.se) and loo.n_data_points == TIMES.size
    # 80 samples with 0.2 mm noise: log-density ≈ −ln(0.2 mm · √(2π e)) ≈ 7.1 each
    assert loo.elpd == pytest.approx(TIMES.size * -np.log(2e-4 * np.sqrt(2 * np.pi * np.e)), rel=0.05)
    assert float(np.max(loo.pareto_k)) < 0.7


def _axes(plots) -> list:
    """The axes of the matplotlib figure of an arviz-plots result."""
    return list(plots.viz["figure"].item().axes)


@pytest.fixture
def figures():
    yield
    plt.close("all")


def test_plot_trace_draws_each_chain_of_each_site(azp, saved, figures):
    axes = _axes(azp.plot_trace(saved))
    assert [ax.get_title() for ax in axes] == ["Y", "sigma_mm"]
    for ax in axes:
        traces = {tuple(line.get_ydata()) for line in ax.get_lines()}
        chains = {tuple(np.asarray(chain)) for chain in saved.posterior[ax.get_title()]}
        assert traces == chains  # one line per chain, its draws in order


def test_plot_rank_draws_each_chains_rank_ecdf(azp, saved, figures):
    axes = _axes(azp.plot_rank(saved))
    assert [ax.get_title() for ax in axes] == ["Y", "sigma_mm"]
    for ax in axes:
        assert len(ax.get_lines()) == 2 and ax.get_xlabel() == "Fractional ranks"  # a rank ECDF per chain


def test_plot_energy_shows_both_energy_distributions_and_the_bfmi(azp, saved, figures):
    axes = {ax.get_title(): ax for ax in _axes(azp.plot_energy(saved))}
    assert set(axes) == {"Energy", "BFMI"}
    assert len(axes["Energy"].get_lines()) == 2  # the marginal energy and the energy transition


def test_plot_ppc_dist_pairs_the_measured_with_replicated_lengths(azp, saved, figures):
    (ax,) = _axes(azp.plot_ppc_dist(saved, var_names=["length"], num_samples=20))
    assert ax.get_title() == "length" and len(ax.get_lines()) == 21  # 20 replicated, 1 measured


@pytest.mark.parametrize("name", ["plot_trace_dist", "plot_rank_dist"])
def test_trace_plots_with_marginals(azp, saved, figures, name):
    axes = _axes(getattr(azp, name)(saved))
    assert len(axes) == 4  # Y and σ: marginal and trace or ranks
    assert [ax.get_xlabel() for ax in axes][::2] == ["Y", "sigma_mm"]


def test_a_likelihood_that_scores_some_samples_keeps_every_sample_observed(azp, tmp_path):
    """With a discrepancy on a piecewise-linear record only its keyframes are scored (the log-likelihood is 0
    elsewhere, no term of it); the observed, replicated and model lengths still cover every sample, so the
    predictive check pairs them, and the log-likelihood holds the scored samples alone, those LOO counts. The
    discrepancy's amplitude and the noise's correlation time are recorded in mm and ms."""
    rng = np.random.default_rng(1)
    chains, draws, n = 2, 30, TIMES.size
    model = 2e-2 * TIMES * (1.0 + 0.01 * rng.standard_normal((chains, draws, 1)))
    scored = np.zeros(n, bool)
    scored[::8] = True
    loglik = np.where(scored, rng.normal(5.0, 0.1, (chains, draws, n)), 0.0)
    fields = {
        "diverging": np.zeros((chains, draws), bool),
        "energy": rng.normal(size=(chains, draws)),
        "num_steps": np.full((chains, draws), 7),
    }
    sites = {
        "Y": rng.normal(9e3, 1e2, (chains, draws)),
        "sigma": rng.uniform(1.5e-4, 2.5e-4, (chains, draws)),  # m
        "delta_amplitude": rng.uniform(3e-4, 5e-4, (chains, draws)),  # m
        "delta_time_scale": rng.uniform(0.6, 1.0, (chains, draws)),  # s
        "noise_time": rng.uniform(0.01, 0.03, (chains, draws)),  # s
    }
    idata = gpost.inference_data(
        {**sites, "length_model": model},
        fields,
        TIMES,
        2e-2 * TIMES,
        scored,
        loglik,
        model + 2e-4 * rng.standard_normal(model.shape),
    )
    assert idata.observed_data["length"].shape == (n,) and int(idata.constant_data["scored"].sum()) == 10
    assert set(idata.sample_stats.data_vars) == {"diverging", "energy", "n_steps", "tree_depth", "solver_ok"}
    assert int(idata.sample_stats["tree_depth"].max()) == 3  # 7 leapfrog steps: a tree of depth 3
    assert idata.posterior.attrs["inference_library"] == "numpyro"
    np.testing.assert_array_equal(idata.log_likelihood["time"], TIMES[scored])
    np.testing.assert_array_equal(idata.log_likelihood["length"], loglik[..., scored])
    units = {name: idata.posterior[name].attrs.get("units") for name in idata.posterior.data_vars}
    assert units == {
        "Y": None,
        "sigma_mm": "mm",
        "delta_amplitude_mm": "mm",
        "delta_time_scale": "s",
        "noise_time_ms": "ms",
    }
    for site, values in sites.items():
        np.testing.assert_allclose(gpost.site_draws(idata.posterior, site), values, rtol=1e-15)
    table = azs.summary(idata)
    assert table.loc["delta_amplitude_mm", "mean"] == pytest.approx(0.4, abs=0.05)  # mm
    assert table.loc["noise_time_ms", "mean"] == pytest.approx(20.0, abs=2.0)  # ms
    assert table.loc["sigma_mm", "eti89_lb"] > 0.1 and table.loc["delta_time_scale", "mean"] == pytest.approx(
        0.8, abs=0.05
    )
    record = gpost.diagnostics(idata, gpost.paper_priors()[:1], 2e-2 * TIMES)["parameters"]
    assert set(record) == set(sites)  # keyed by NumPyro's sites, in SI units
    for site, values in sites.items():
        assert record[site]["mean"] == pytest.approx(float(values.mean()), rel=1e-12)
    assert len(_axes(azp.plot_ppc_dist(idata, var_names=["length"]))) == 1
    plt.close("all")
    assert azs.loo(idata).n_data_points == 10
    idata.to_netcdf(str(tmp_path / "p.nc"))
    with xr.open_datatree(str(tmp_path / "p.nc")) as back:
        np.testing.assert_array_equal(back.log_likelihood["time"], TIMES[scored])
        assert back.observed_data["length"].shape == (n,) and azs.loo(back).n_data_points == 10
        assert back.constant_data["scored"].dtype == bool
        assert azs.summary(back).equals(table)


def test_diagnostics_and_loo_comparison_come_from_arviz_stats(small_posterior):
    s = small_posterior.summary
    rhat = azs.rhat(small_posterior.idata)
    assert s["rhat_max"] == pytest.approx(max(float(rhat["Y"]), float(rhat["sigma_mm"])))
    assert s["ess_bulk_min"] > 10 and 0.0 < s["bfmi_min"] and s["divergences"] == 0
    table = gpost.compare_loo({"a": small_posterior, "b": small_posterior})
    assert {t["rank"] for t in table.values()} == {0, 1}
    for t in table.values():
        assert t["elpd_loo"] == pytest.approx(float(azs.loo(small_posterior.idata).elpd))
        assert t["elpd_diff"] == pytest.approx(0.0) and t["weight"] == pytest.approx(0.5, abs=0.01)
        assert t["pareto_k_max"] < 1.0 and t["p_loo"] > 0.0


def test_posterior_figures_are_written(small_posterior, tmp_path):
    trace, pair = gplot.posterior_figures(small_posterior.idata, ["Y", "sigma_mm"], tmp_path, prefix="a_")
    assert trace.name == "a_trace.png" and pair.name == "a_pair.png"
    assert trace.stat().st_size > 10_000 and pair.stat().st_size > 10_000
    assert not plt.get_fignums()  # both closed


def _python(*args: str) -> subprocess.CompletedProcess:
    """This interpreter in a fresh process, deprecation and refactor warnings raised as errors."""
    warnings = ["error::FutureWarning", "error::DeprecationWarning", "error::PendingDeprecationWarning"]
    flags = [flag for w in warnings for flag in ("-W", w)]
    return subprocess.run([sys.executable, *flags, *args], capture_output=True, text=True, check=False, timeout=300)


def test_arviz_plots_imports_on_its_own_with_its_styles():
    """``import arviz_plots`` in a process that has not imported growjax: it registers ArviZ's matplotlib styles."""
    code = (
        "import sys, arviz_plots, matplotlib.pyplot as plt; assert 'growjax' not in sys.modules; "
        "print(sorted(s for s in plt.style.available if s.startswith('arviz-')))"
    )
    done = _python("-c", code)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "arviz-variat" in done.stdout


def test_importing_growjax_and_its_arviz_stack_warns_of_nothing():
    """No deprecation or refactor warning at import (an error here), and ArviZ 0.x's package is not imported."""
    code = (
        "import sys, growjax, growjax.posterior, growjax.plotting, arviz_plots, arviz_base, arviz_stats; "
        "assert 'arviz' not in sys.modules, 'arviz 0.x imported'"
    )
    done = _python("-c", code)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "arviz" not in done.stderr.lower(), done.stderr


ARVIZ_STACK = ("arviz-base", "arviz-stats", "arviz-plots", "matplotlib", "xarray")


@pytest.mark.parametrize("package", ARVIZ_STACK)
def test_the_arviz_stack_installed_is_the_one_pyproject_asks_for(package):
    """The calls above hold for the versions ``pyproject.toml`` allows (on this Python): an environment with
    others installed fails here, by name, rather than in the plots."""
    declared = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    wanted = [r for r in map(Requirement, declared) if r.name == package and (r.marker is None or r.marker.evaluate())]
    installed = importlib.metadata.version(package)
    for requirement in wanted:
        assert requirement.specifier.contains(installed, prereleases=True), (
            f"{package} {installed} is installed; growjax needs {requirement} (pip install -e .)"
        )
    assert wanted
