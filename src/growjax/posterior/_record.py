"""A NUTS run as an xarray DataTree, its groups laid out for ArviZ's standard calls (ArviZ 1.x: arviz-base,
arviz-stats, arviz-plots).

- ``posterior``: the sampled sites (chain, draw): the parameters (SI), the noise ``sigma_mm`` (mm), the
  discrepancy's hyperparameters ``delta_amplitude_mm`` (mm), ``delta_time_scale`` (s) and ``noise_time_ms`` (ms),
  and a bounded prior's sampling coordinate (``u_<site>``, ``v_<site>``);
- ``posterior_predictive``: ``length`` (chain, draw, time), m, this experiment replicated (its discrepancy and
  rig error as the data determine them, fresh sensor noise); ``length_new_experiment``, a new experiment under the
  same input (a fresh discrepancy and rig error); ``length_model`` (chain, draw, time), m, the model's length at
  each draw, without noise or discrepancy;
- ``log_likelihood``: ``length`` (chain, draw, time), the pointwise log-likelihood at the samples the likelihood
  scores (all of them, but a discrepancy on a piecewise-linear record scores its keyframes alone);
- ``sample_stats``: NUTS's ``diverging``, ``energy``, ``n_steps``, ``tree_depth``, and ``solver_ok``, the model's
  solve succeeded at the draw (a failed solve has zero likelihood, so NUTS keeps none);
- ``observed_data``: ``length`` (time,), m, the measured length;
- ``constant_data``: ``scored`` (time,) bool, the samples the likelihood scores.

Every ``time`` coordinate is the sample time in s (in ``log_likelihood``, the scored samples' times). The lengths,
the times and the noise's and discrepancy's sites carry their unit in a ``units`` attribute; the parameters are in
SI units, as ``growjax params`` lists them.

The NumPyro model samples in SI units. The record keeps the sites of a sub-millimetre or sub-second size in mm
or ms (`RECORDED`), under names that say so, so that ``arviz_stats.summary``'s two decimals show their digits;
`site_draws` reads any site back in SI units. ``arviz_stats.summary`` lists the posterior's sites alone,
``arviz_plots.plot_ppc_dist`` pairs the observed with the replicated length, ``arviz_stats.loo`` reads the
log-likelihood, and ``tree.to_netcdf`` / ``xarray.open_datatree`` (ArviZ 1.x's ``from_netcdf``) keep all of it.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np
from jaxtyping import ArrayLike, Bool, Float

if TYPE_CHECKING:
    import xarray as xr

MODEL_SITE = "length_model"  # the deterministic site growth_model records the model's length in
NUTS_STATS = {"diverging": "diverging", "energy": "energy", "num_steps": "n_steps"}  # NumPyro's → ArviZ's names


@dataclasses.dataclass(frozen=True)
class Recorded:
    """How the DataTree records a sampled site: as the variable ``name``, in ``units``, its SI value × ``scale``."""

    name: str
    scale: float
    units: str


RECORDED = {
    "sigma": Recorded("sigma_mm", 1e3, "mm"),
    "delta_amplitude": Recorded("delta_amplitude_mm", 1e3, "mm"),
    "noise_time": Recorded("noise_time_ms", 1e3, "ms"),
}
LENGTH_UNITS = {name: "m" for name in ("length", "length_new_experiment", MODEL_SITE)}


def recorded_name(site: str) -> str:
    """The DataTree's name of a NumPyro site.

    Args:
        site: the site's name in the NumPyro model (`growjax.posterior.growth_model`).

    Returns:
        Its variable's name in the ``posterior`` group: ``"sigma"`` → ``"sigma_mm"`` (`RECORDED`); other sites keep
        theirs.
    """
    return RECORDED[site].name if site in RECORDED else site


def site_draws(posterior, site: str) -> np.ndarray:
    """A NumPyro site's draws in SI units, read from a DataTree's posterior.

    Args:
        posterior: the ``posterior`` group of a DataTree from `inference_data` (or its Dataset).
        site: the site's name in the NumPyro model (``"sigma"``, not ``"sigma_mm"``).

    Returns:
        (chain, draw, ...) the draws in SI units (m for ``sigma``).

    Raises:
        KeyError: the posterior records no such site.
    """
    if site in RECORDED:
        return np.asarray(posterior[RECORDED[site].name], float) / RECORDED[site].scale
    return np.asarray(posterior[site])


def _as_recorded(samples: dict) -> tuple[dict, dict]:
    """NumPyro's draws {site: array} (SI) → (the DataTree's {name: array}, {name: units})."""
    out, units = {}, {"delta_time_scale": "s"}
    for site, x in samples.items():
        r = RECORDED.get(site)
        out[r.name if r else site] = x * r.scale if r else x
        if r:
            units[r.name] = r.units
    return out, units


def inference_data(
    samples: dict,
    extra_fields: dict,
    times: Float[ArrayLike, " T"],
    observed: Float[ArrayLike, " T"],
    scored: Bool[ArrayLike, " T"],
    loglik: Float[ArrayLike, "C S T"],
    predicted: Float[ArrayLike, "C S T"],
    new_experiment: Float[ArrayLike, "C S T"] | None = None,
) -> xr.DataTree:
    """One NUTS run as an xarray DataTree (ArviZ 1.x's data structure), laid out for ArviZ's standard calls.

    ``posterior``: the sampled sites (the noise and the discrepancy's amplitude in mm, its noise time in ms:
    `RECORDED`); ``posterior_predictive``: ``length`` (replicated data) and ``length_model`` (the model's length at
    each draw, no noise or discrepancy), m; ``log_likelihood``: ``length``, pointwise at the scored samples;
    ``sample_stats``: NUTS's statistics and ``solver_ok`` per draw; ``observed_data``: ``length``, m;
    ``constant_data``: ``scored``. Lengths and log-likelihoods have a ``time`` coordinate (s); every sampled
    variable has ``chain`` and ``draw`` dimensions. So ``arviz_stats.summary`` lists the sampled sites alone,
    ``arviz_plots.plot_ppc_dist`` pairs the measured with the replicated length and ``arviz_stats.loo`` reads the
    pointwise terms.

    Args:
        samples: NumPyro's draws by chain {site: (C, S, ...)}, SI units, with the deterministic ``length_model``
            (C, S, T), m.
        extra_fields: NumPyro's extra fields by chain {name: (C, S)} (``diverging``, ``energy``, ``num_steps``).
        times: (T,) the sample times, s.
        observed: (T,) the measured length, m.
        scored: (T,) bool, the samples the likelihood scores.
        loglik: (C, S, T) the pointwise log-likelihood, read at the scored samples only (elsewhere it is no term of
            the likelihood, and a constant column would stop PSIS-LOO).
        predicted: (C, S, T) the replicated length, m.
        new_experiment: (C, S, T) a new experiment's length, m, stored as ``length_new_experiment`` where given.

    Returns:
        The DataTree, its groups as listed above.
    """
    import arviz_base as azb
    import numpyro
    import xarray as xr

    samples = {k: np.asarray(v) for k, v in samples.items()}
    model = samples.pop(MODEL_SITE)
    samples, units = _as_recorded(samples)
    stats = {NUTS_STATS[k]: np.asarray(v) for k, v in extra_fields.items() if k in NUTS_STATS}
    if "n_steps" in stats:
        stats["tree_depth"] = np.log2(stats["n_steps"]).astype(int) + 1  # as ArviZ's from_numpyro
    stats["solver_ok"] = np.all(np.isfinite(model), axis=-1)
    dims = {"length": ["time"], MODEL_SITE: ["time"], "scored": ["time"], "length_new_experiment": ["time"]}
    predictive = {"length": np.asarray(predicted), MODEL_SITE: model}
    if new_experiment is not None:
        predictive["length_new_experiment"] = np.asarray(new_experiment)
    scored, times = np.asarray(scored, bool), np.asarray(times, float)
    library = {"inference_library": "numpyro", "inference_library_version": numpyro.__version__}

    def group(data, at=times, sampled=True, attrs=None, units=LENGTH_UNITS):
        ds = azb.dict_to_dataset(
            data, coords={"time": at}, dims=dims, attrs=attrs, sample_dims=["chain", "draw"] if sampled else []
        )
        for name, unit in {**units, "time": "s"}.items():
            if name in ds.variables:
                ds[name].attrs["units"] = unit
        return ds

    return xr.DataTree.from_dict(
        {
            "posterior": group(samples, attrs=library, units=units),
            "posterior_predictive": group(predictive),
            "log_likelihood": group({"length": np.asarray(loglik)[..., scored]}, at=times[scored], units={}),
            "sample_stats": group(stats, attrs=library, units={}),
            "observed_data": group({"length": np.asarray(observed, float)}, sampled=False),
            "constant_data": group({"scored": scored}, sampled=False),
        }
    )
