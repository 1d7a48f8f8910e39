"""What is known before the next experiment: the parameters of interest, their estimate and covariance, the rig's
tolerances and the residual model's hyperparameters, from a fit of the experiments already run.

The design's prior on w = (ln θ, b) is blockdiag(Σ_θ, U): Σ_θ the fit's covariance of ln θ (what the data
already say), U = diag(u²) the rig's tolerances (its relative errors b = ln ψ/ψ₀, `growjax.calibration.tolerance`).
The rig enters the next experiment as a fresh nuisance with its tolerance prior: what the old data said of the
rig is not carried over (conservative where the next experiment runs on the same rig). A parameter the fit left
undetermined (no interval, or one wider than its sampling box, `growjax.calibration.default_range`) takes a uniform
prior over that box instead: the box's variance of ln θ, centred on the box (the fit's estimate of such a
parameter is arbitrary, and can lie far outside the box: draws about it would run the robot in a regime nothing
supports).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from growjax.calibration import FitResult, Likelihood, default_range
from growjax.calibration import discrepancy as dc
from growjax.calibration import tolerance as tl
from growjax.model import params as gp

__all__ = ["DEFAULT_HYPER", "Knowledge", "box_variance", "from_fit", "from_summary"]

# Residual model when no fit gives one: white length noise of 0.2 mm, no discrepancy.
DEFAULT_HYPER = {"amplitude_m": 0.0, "time_scale_s": 1.0, "noise_m": 2e-4, "noise_time_s": 0.0}


@dataclasses.dataclass(frozen=True)
class Knowledge:
    """What is known: ``base`` the parameters (θ at its estimate), ``names`` (p,) the parameters of interest
    (qualified), ``covariance`` (p, p) of ln θ, ``tolerances`` {rig parameter: relative sd u}, ``hyper`` the
    length's residual model (discrepancy and noise), ``source`` where it came from."""

    base: gp.Parameters
    names: tuple
    covariance: np.ndarray
    tolerances: dict
    hyper: dc.Hyper
    source: str = ""

    def __post_init__(self):
        c = np.asarray(self.covariance, float)
        if c.shape != (len(self.names),) * 2 or not np.all(np.isfinite(c)):
            raise ValueError(f"the covariance must be a finite ({len(self.names)}, {len(self.names)}) matrix")
        if np.any(np.linalg.eigvalsh(0.5 * (c + c.T)) <= 0):
            raise ValueError("the covariance of ln θ must be positive definite")

    @property
    def estimate(self) -> np.ndarray:
        """θ (p,) SI at the estimate."""
        return np.array([float(gp.get(self.base, n)) for n in self.names])

    @property
    def rig(self) -> tuple:
        """The toleranced rig parameters (q,)."""
        return tuple(self.tolerances)

    def prior_covariance(self) -> np.ndarray:
        """blockdiag(Σ_θ, U) (p + q, p + q) of w = (ln θ, b)."""
        p, q = len(self.names), len(self.tolerances)
        out = np.zeros((p + q, p + q))
        out[:p, :p] = self.covariance
        out[p:, p:] = np.diag(np.asarray(list(self.tolerances.values()), float) ** 2)
        return out

    def prior_precision(self, known: bool = True) -> np.ndarray:
        """The prior's precision (p + q, p + q); ``known=False``: none on θ (the next experiment alone, its rig
        still under its tolerances)."""
        p = len(self.names)
        out = np.zeros_like(self.prior_covariance())
        if known:
            out[:p, :p] = np.linalg.inv(self.covariance)
        u = np.asarray(list(self.tolerances.values()), float)
        out[p:, p:] = np.diag(1.0 / u**2)
        return out

    def on(self, base: gp.Parameters) -> Knowledge:
        """What is known, carried to other parameters ``base`` (another drive's, say): θ at its estimate there,
        the rest as here."""
        return dataclasses.replace(self, base=gp.replace(base, **dict(zip(self.names, self.estimate))))

    def summary(self) -> dict:
        sd = np.sqrt(np.diag(self.covariance))
        return {
            "source": self.source,
            "parameters": {
                n: {"estimate": float(v), "sd_log": float(s)} for n, v, s in zip(self.names, self.estimate, sd)
            },
            "tolerances": dict(self.tolerances),
            "discrepancy": self.hyper.as_dict(),
        }


def box_variance(base: gp.Parameters, name: str) -> float:
    """Variance of ln θ under a uniform prior over the parameter's sampling box."""
    lo, hi = default_range(base, name)
    return float(np.log(hi / lo) ** 2 / 12.0)


def _determined(base, names, cov, known) -> list[bool]:
    """Whether each parameter is determined: ``known`` (it has an interval) and its variance of ln θ in ``cov``
    positive and below its box's."""
    return [bool(k) and 0.0 < cov[i, i] < box_variance(base, n) for i, (n, k) in enumerate(zip(names, known))]


def _covariance(base, names, cov, determined) -> np.ndarray:
    """``cov`` with each undetermined parameter's row and column replaced by its box variance (uncorrelated)."""
    cov = np.array(cov, float)
    for i, n in enumerate(names):
        if not determined[i]:
            cov[i, :] = cov[:, i] = 0.0
            cov[i, i] = box_variance(base, n)
    return cov


def _centred(base, names, estimate: dict, determined) -> dict:
    """``estimate`` with each undetermined parameter at its box's geometric centre."""
    out = dict(estimate)
    for n, d in zip(names, determined):
        if not d:
            lo, hi = default_range(base, n)
            out[n] = float(np.sqrt(lo * hi))
    return out


def _hyper(record: dict | None) -> dc.Hyper:
    h = {**DEFAULT_HYPER, **{k: v for k, v in (record or {}).items() if k in DEFAULT_HYPER}}
    return dc.Hyper.of(h["amplitude_m"], h["time_scale_s"], h["noise_m"], h["noise_time_s"])


def _tolerances(fitted: dict, base: gp.Parameters, names, likelihood: Likelihood | None) -> dict:
    """The rig's tolerances for the next experiment: the fit's where it carried some and ``likelihood`` names none,
    else the default budget with ``likelihood``'s tolerances on top (the next experiment always has a rig)."""
    given = None if likelihood is None or likelihood.tolerances is None else dict(likelihood.tolerances)
    return dict(fitted) if given is None and fitted else tl.budget(base, given, names)


def from_fit(result: FitResult, base: gp.Parameters, *, likelihood: Likelihood | None = None) -> Knowledge:
    """What a `growjax.calibration.FitResult` of ``base`` knows: θ at its estimate, its covariance of ln θ, its
    residual model (the runs' median hyperparameters) and its tolerances (``likelihood``'s tolerances override
    them; None: the fit's, else the default budget).

    Raises:
        ValueError: a coordinate of the fit not in ln θ (a signed parameter), or copies of a parameter per robot,
            rig or run: what is known is one value of each parameter, in ln θ.
    """
    names = tuple(result.labels)
    odd = [c.label for c in result.coordinates if c.scale is not None or c.scope != "shared"]
    if odd:
        raise ValueError(f"what is known takes parameters fitted once each in ln θ; the fit has {', '.join(odd)}")
    raw = np.asarray(result.covariance, float)
    determined = _determined(base, names, raw, [result.standard_error.get(n) is not None for n in names])
    cov = _covariance(base, names, raw, determined)
    est = _centred(base, names, {n: result.estimate[n] for n in names}, determined)
    tol = _tolerances(result.tolerances, base, names, likelihood)
    return Knowledge(gp.replace(base, **{**result.estimate, **est}), names, cov, tol, _hyper(result.discrepancy), "fit")


def from_summary(path, base: gp.Parameters, names, *, likelihood: Likelihood | None = None) -> Knowledge:
    """What a saved fit knows: the JSON summary ``growjax fit --json FILE`` writes. It holds each parameter's
    estimate and standard error (not their correlations: the covariance is taken diagonal), the residual model
    (``discrepancy``) and the tolerances it carried (``likelihood``'s tolerances override them; None: the saved
    ones, else the default budget). ``names``: the parameters of interest, each among the fit's.

    Raises:
        ValueError: naming what is missing or unreadable.
    """
    path = Path(path)
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise ValueError(f"cannot read the saved fit {path}: {err}") from None
    fitted = record.get("parameters") if isinstance(record, dict) else None
    if not isinstance(fitted, dict):
        raise ValueError(f"{path} is not the JSON summary of `growjax fit` (no 'parameters')")
    names = tuple(gp.resolve_name(base, n) for n in names)
    missing = [n for n in names if n not in fitted]
    if missing:
        raise ValueError(f"{path} did not fit {', '.join(missing)} (it fitted {', '.join(fitted)})")
    est = {n: float(fitted[n]["estimate"]) for n in names}
    se = [fitted[n].get("standard_error") for n in names]
    var = [0.0 if s is None else (float(s) / est[n]) ** 2 for s, n in zip(se, names)]
    determined = _determined(base, names, np.diag(var), [s is not None for s in se])
    cov = _covariance(base, names, np.diag(var), determined)
    est = _centred(base, names, est, determined)
    tol = _tolerances(record.get("tolerances") or {}, base, names, likelihood)
    return Knowledge(gp.replace(base, **est), names, cov, tol, _hyper(record.get("discrepancy")), str(path))
