"""Calibration: the likelihood (discrepancy, noise, the rig's tolerances, the configuration's own error), least
squares, and the fit of one experiment or a set of them.

The entry point is `fit` (a function: ``growjax.calibration.fit(experiments, free, likelihood=Likelihood())``),
its options `Likelihood`, its outcome `FitResult`.
"""

from growjax.calibration.fit import fit  # the function takes the name of its module
from growjax.calibration.gls import LM_TOLERANCE
from growjax.calibration.layout import Coordinate
from growjax.calibration.least_squares import levenberg_marquardt, linearise
from growjax.calibration.likelihood import (
    FAST_MODEL_ERROR,
    MODEL_ERROR_TIME,
    RIG_ERRORS,
    RIG_TREATMENTS,
    Likelihood,
    default_model_error,
)
from growjax.calibration.problem import Problem, make_problem, physical_bounds
from growjax.calibration.result import INFORMATION_FLOOR, Z90, FitResult, undetermined_directions
from growjax.calibration.scoring import RunScore
from growjax.calibration.solve import RELINEARISE_STEPS, RELINEARISE_TOLERANCE
from growjax.calibration.starts import default_range, sampling_box

__all__ = [
    "FAST_MODEL_ERROR",
    "INFORMATION_FLOOR",
    "LM_TOLERANCE",
    "MODEL_ERROR_TIME",
    "RELINEARISE_STEPS",
    "RELINEARISE_TOLERANCE",
    "RIG_ERRORS",
    "RIG_TREATMENTS",
    "Z90",
    "Coordinate",
    "FitResult",
    "Likelihood",
    "Problem",
    "RunScore",
    "default_model_error",
    "default_range",
    "fit",
    "levenberg_marquardt",
    "linearise",
    "make_problem",
    "physical_bounds",
    "sampling_box",
    "undetermined_directions",
]
