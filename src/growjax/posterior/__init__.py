"""Bayesian calibration: a NumPyro model of the measured length, NUTS, ArviZ diagnostics, predictive bands.

The statistical model reads like its maths::

    Y ~ Uniform(5, 15) kPa,  ext ~ Uniform(4000, 10000),  n ~ Uniform(0.9, 1.1)   (the paper's box)
    σ ~ HalfNormal(1 mm),  a ~ HalfNormal(2 mm),  ℓ ~ LogNormal(ln 1 s, 1)
    L_obs = L_model(t; Y, ext, n) + δ(t) + Σ_j g_j(t) b_j + ε,
    δ ~ GP(0, Matérn-3/2(a, ℓ)),  b_j ~ N(0, u_j²),  ε_i ~ N(0, σ²)

δ (the model discrepancy) and b (the rig's tolerances) are marginalised exactly by a Kalman filter
(:mod:`growjax.calibration.discrepancy`); ``discrepancy="none"`` keeps L_obs(t_i) ~ Normal(L_model(t_i), σ).

NumPyro samples the bounded priors in unconstrained (logit) coordinates, which are O(1).
The model runs in the fast configuration by default, with forward-mode gradients (or through an
emulator, opt-in); through the model, NUTS starts at the mode found in those coordinates, with the
Hessian there as its mass matrix (:func:`laplace_unconstrained`), and a prior whose mode lies
against a bound is sampled in a softplus coordinate instead (:class:`SoftplusPrior`, :func:`bound_start`), the
others across the ridge they form with it (:class:`RidgePrior`). A failed solve gives zero likelihood
(−∞ log density, rejected by NUTS), never an exception.

The model, its priors and its mean length (``_priors``, ``_model``), NUTS's start (``_laplace``), the sampler
(``_sample``), its record as an xarray DataTree for ArviZ 1.x (``_record``) and the checks on its output
(``_checks``).
"""

from ._checks import (
    compare_loo,
    diagnostics,
    forecast,
    laplace,
    nuts_chain,
    predict,
    predictive_band,
    sbc,
)
from ._laplace import (
    LAPLACE_DECREMENT,
    LAPLACE_MAX_STEPS,
    LAPLACE_STALL,
    PRIOR_CURVATURE_FLOOR,
    bound_start,
    laplace_unconstrained,
    precondition,
    ridge_coordinates,
)
from ._model import (
    DirectMean,
    Residuals,
    build_emulator,
    direct_mean,
    emulated_mean,
    growth_model,
    value_and_jacobian,
    with_model_tangents,
)
from ._priors import (
    BOUND_FRACTION,
    Prior,
    RidgePrior,
    SoftplusPrior,
    bound_coordinates,
    coordinate,
    fraction,
    lockhart_priors,
    paper_priors,
)
from ._record import RECORDED, Recorded, inference_data, recorded_name, site_draws
from ._residuals import build_residuals, observation_draws
from ._sample import PosteriorResult, sample

__all__ = [
    "BOUND_FRACTION",
    "LAPLACE_DECREMENT",
    "LAPLACE_MAX_STEPS",
    "LAPLACE_STALL",
    "PRIOR_CURVATURE_FLOOR",
    "RECORDED",
    "DirectMean",
    "PosteriorResult",
    "Prior",
    "Recorded",
    "Residuals",
    "RidgePrior",
    "SoftplusPrior",
    "bound_coordinates",
    "bound_start",
    "build_emulator",
    "build_residuals",
    "compare_loo",
    "coordinate",
    "diagnostics",
    "direct_mean",
    "emulated_mean",
    "forecast",
    "fraction",
    "growth_model",
    "inference_data",
    "laplace",
    "laplace_unconstrained",
    "lockhart_priors",
    "nuts_chain",
    "observation_draws",
    "paper_priors",
    "precondition",
    "predict",
    "predictive_band",
    "recorded_name",
    "ridge_coordinates",
    "sample",
    "sbc",
    "site_draws",
    "value_and_jacobian",
    "with_model_tangents",
]
