"""The likelihood's options as one object: what every workflow that scores data against the model (the fit, the
posterior, discovery, the design's "what is known") takes, so that the same data get the same treatment.

The measured length is the model plus a smooth discrepancy (``discrepancy="matern32"``, `growjax.calibration.
discrepancy`) plus sensor noise, or the model plus independent noise (``"none"``); the rig's fixed parameters are
known to their tolerances (`growjax.calibration.tolerance`), and the fitted configuration's own error against the
reference is carried as a slow, correlated drift.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from types import MappingProxyType

import growjax.calibration.discrepancy as dc
import growjax.calibration.tolerance as tl
from growjax.model import params as gp

RIG_TREATMENTS = ("inferred", "fixed")
RIG_ERRORS = ("shared", "experiment")
# The fast configuration's own error against the reference, carried into the intervals as a smooth, correlated
# residual: its standard uncertainty (m) and correlation time (s). Measured over the shipped reference traces of
# the published pulse (benchmarks/agreement.py): RMS 0.012 mm across them, worst 0.018 mm.
FAST_MODEL_ERROR = 1.5e-5
# Its correlation time: the error is a slow drift that grows over the run (on the published pulse, mean −2, −10,
# −20 µm over 0–3, 3–7, 7–10 s), so it moves a fitted Y as a whole, one sign for every set.
MODEL_ERROR_TIME = 5.0


def default_model_error(config) -> float:
    """The configuration ``config``'s length error against the reference, m: `FAST_MODEL_ERROR` for the fast
    configuration, 0 for the reference itself."""
    return FAST_MODEL_ERROR if config.fidelity == "fast" else 0.0


@dataclasses.dataclass(frozen=True)
class Likelihood:
    """How the data are scored: one object for every workflow.

    Attributes:
        discrepancy: ``"matern32"``: the length is the model plus a smooth Matérn-3/2 discrepancy plus sensor
            noise (hyperparameters at their mode, or sampled by the posterior); ``"none"``: independent noise.
        sigma_length: the length residual's scale, m (the least-squares stages' units; the intervals use the
            noise estimated from the data).
        sigma_pressure: the pressure sensor's noise, Pa, where a run records the pressure.
        model_error: the fitted configuration's own length error against the reference, m, carried as a slow drift
            (squared exponential over `MODEL_ERROR_TIME`); None: the configuration's default
            (`default_model_error`).
        tolerances: {rig parameter: relative sd} on top of the default budget (`growjax.calibration.tolerance`;
            a 0 drops one); None: the default budget with a discrepancy, none without.
        rig: ``"inferred"``: the rig's relative errors are fitted beside θ under their tolerances as priors;
            ``"fixed"``: the rig held nominal and its tolerances propagated (the conservative choice).
        rig_errors: ``"shared"``: one vector of rig errors per rig, shared by its experiments; ``"experiment"``:
            one per experiment.

    Raises:
        ValueError: at construction, naming a value out of its range.
    """

    discrepancy: str = "matern32"
    sigma_length: float = 1e-3
    sigma_pressure: float = 5e3
    model_error: float | None = None
    tolerances: Mapping[str, float] | None = None
    rig: str = "inferred"
    rig_errors: str = "shared"

    def __post_init__(self):
        if self.discrepancy not in dc.KINDS:
            raise ValueError(f"discrepancy must be one of {dc.KINDS}, got {self.discrepancy!r}")
        if self.rig not in RIG_TREATMENTS:
            raise ValueError(f"rig must be one of {RIG_TREATMENTS}, got {self.rig!r}")
        if self.rig_errors not in RIG_ERRORS:
            raise ValueError(f"rig_errors must be one of {RIG_ERRORS}, got {self.rig_errors!r}")
        for name in ("sigma_length", "sigma_pressure"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if self.model_error is not None and not (math.isfinite(self.model_error) and self.model_error >= 0):
            raise ValueError(f"model_error must be a length >= 0 m or None, got {self.model_error!r}")
        if self.tolerances is not None:
            for name, rel in dict(self.tolerances).items():
                if not (isinstance(rel, (int, float)) and 0.0 <= rel < 1.0):
                    raise ValueError(f"tolerance {name}={rel!r}: a relative uncertainty must lie in [0, 1)")
            object.__setattr__(self, "tolerances", MappingProxyType(dict(self.tolerances)))

    def model_error_for(self, config) -> float:
        """The model-error allowance, m, for a fit or posterior in ``config``: `model_error`, or the
        configuration's default."""
        return default_model_error(config) if self.model_error is None else float(self.model_error)

    def budget(self, base: gp.Parameters, free: Sequence[str] = ()) -> dict[str, float]:
        """The tolerances in force {qualified name: relative sd} for ``base`` with the parameters ``free`` fitted
        (they carry none): the default budget with a discrepancy (none without) and `tolerances` on top.

        Raises:
            ValueError: a toleranced parameter unknown or not positive.
        """
        use_default = self.tolerances is None and self.discrepancy != "none"
        return tl.budget(base, None if self.tolerances is None else dict(self.tolerances), free, use_default)

    def replace(self, **changes) -> Likelihood:
        """A copy with ``changes`` (fields by name), validated."""
        return dataclasses.replace(self, **changes)


__all__ = [
    "FAST_MODEL_ERROR",
    "MODEL_ERROR_TIME",
    "RIG_ERRORS",
    "RIG_TREATMENTS",
    "Likelihood",
    "default_model_error",
]
