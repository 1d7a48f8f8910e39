"""A tracked record: the state's belief at every sample, the quantities read from it with their 90 % bands, their
CSV, and the score against a measured length the filter did not see.

A quantity's band is the Gaussian belief's central 90 % interval (± 1.645 sd) carried to the quantity through
its linearisation at the mean: the sensed outputs (length with the discrepancy, pressure, syringe displacement,
inlet flow) through the model's outputs; a parameter's through exp for a log coordinate (a band that stays
positive); an estimated input's level directly.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from growjax.data.experiment import write_csv
from growjax.model import params as gp
from growjax.model.signals import Inputs
from growjax.track.model import StateSpace
from growjax.track.noise import InputState, StateParameter

Z90 = 1.6448536269514722  # the standard normal's 95th percentile: a central 90 % band is ± Z90 sd


@dataclasses.dataclass(frozen=True)
class Quantity:
    """A reported quantity: its ``name`` (the CSV column's stem) and ``unit`` (the column's suffix; "" for none)."""

    name: str
    unit: str

    @property
    def column(self) -> str:
        return self._join("")

    @property
    def lower(self) -> str:
        return self._join("_lower")

    @property
    def upper(self) -> str:
        return self._join("_upper")

    def _join(self, part: str) -> str:
        return f"{self.name}{part}_{self.unit}" if self.unit else f"{self.name}{part}"


# The sensed outputs every track reports, in the order of ``OUTPUTS``' first four.
OUTPUT_QUANTITIES = (
    Quantity("robot_length", "m"),
    Quantity("pressure", "Pa"),
    Quantity("syringe_displacement", "m"),
    Quantity("robot_flow", "m3_s"),
)
REPORTED_OUTPUTS = ("length", "pressure", "syringe_displacement", "robot_flow")


def unit_suffix(unit: str) -> str:
    """A unit as a column suffix: ``Pa`` → ``Pa``, ``m^3/(s·Pa)`` → ``m3_s_Pa``, ``-`` → none."""
    text = unit.replace("^", "").replace("·", "_").replace("*", "_").replace("/", "_").replace("(", "").replace(")", "")
    return "_".join(p for p in text.replace(" ", "_").split("_") if p and p != "-")


def parameter_quantity(base: gp.Parameters, name: str) -> Quantity:
    """The column of a parameter: its published symbol where it has one (``Y``), else its qualified name, with
    its unit (``Y_Pa``)."""
    alias = next((a for a, q in gp.ALIASES.items() if q == name), name)
    unit = gp.physical_ranges(base).get(name, (None, None, ""))[2]
    return Quantity(alias, unit_suffix(unit))


def input_quantity(held: InputState) -> Quantity:
    """The column of an estimated input (``pressure_demand_Pa``, ``steps``, ``catheter_length_m``)."""
    stem, _, unit = held.column.rpartition("_")
    return Quantity(stem, unit) if stem and unit in ("Pa", "m") else Quantity(held.column, "")


def asked(model: StateSpace) -> tuple[StateParameter, ...]:
    """The parameters asked to be estimated (not the rig's toleranced ones)."""
    return tuple(p for p in model.parameters if not p.tolerance)


def quantities(model: StateSpace) -> tuple[Quantity, ...]:
    """What a track reports, in order: the sensed outputs, the estimated parameters, the estimated inputs."""
    params = tuple(parameter_quantity(model.params, p.name) for p in asked(model))
    return OUTPUT_QUANTITIES + params + tuple(input_quantity(i) for i in model.inputs)


def values(model: StateSpace, x, t, inputs: Inputs):
    """The reported quantities (Q,) at state ``x`` and time ``t`` s: outputs SI, parameters in their coordinate,
    inputs SI."""
    out = model.outputs(x, t, inputs)
    n, k, j, _ = model.sizes
    own = np.array([i for i, p in enumerate(model.parameters) if not p.tolerance], int)
    scales = jnp.asarray([i.scale for i in model.inputs], float)
    head = jnp.stack([out[o] for o in REPORTED_OUTPUTS])
    return jnp.concatenate([head, x[n + own], x[n + k : n + k + j] * scales])


def linearised_values(model: StateSpace, times, means, covs, inputs: Inputs):
    """(values (T, Q), their sd (T, Q)) of the reported quantities (`values`) at the beliefs ``means`` (T, N),
    ``covs`` (T, N, N) at ``times`` (T,) s, through their Jacobian at each mean."""

    def one(t, x, p):
        jac, v = jax.jacfwd(lambda z: (values(model, z, t, inputs),) * 2, has_aux=True)(x)
        return v, jnp.sqrt(jnp.maximum(jnp.einsum("ij,jk,ik->i", jac, p, jac), 0.0))

    return jax.vmap(one)(times, means, covs)


def report(model: StateSpace, mids, sds) -> dict:
    """{column: (T,)} of every quantity of `quantities` and its 90 % band, from their linearised values
    ``mids`` (T, Q) and sd ``sds`` (T, Q) (`linearised_values`)."""
    mids, sds = np.asarray(mids), np.asarray(sds)
    n_out, params = len(OUTPUT_QUANTITIES), asked(model)
    out = {}
    for i, q in enumerate(quantities(model)):
        v, s = mids[:, i], sds[:, i]
        band = (v, v - Z90 * s, v + Z90 * s)
        if n_out <= i < n_out + len(params):  # a parameter: from its coordinate to its value (exp is monotone)
            p = params[i - n_out]
            nominal = float(gp.get(model.params, p.name))
            band = tuple(np.asarray(p.value(nominal, b)) for b in band)
        out[q.column], out[q.lower], out[q.upper] = band
    return out


@dataclasses.dataclass(frozen=True)
class TrackResult:
    """A tracked record.

    Attributes:
        time: (T,) s, the samples.
        quantities: the reported `Quantity` s (`quantities`).
        columns: {column: (T,)} the reported quantities and their 90 % bands (`report`), SI.
        mean: (T, N) the state's mean at each sample.  cov: (T, N, N) its covariance.
        state_names: (N,) what each element of the state is.
        sensors: the columns the filter read.
        nis: (T,) each sample's normalised innovation squared; ``dof`` (T,) its degrees of freedom (readings present).
        log_likelihood: log p(readings), nats (the sum of the steps').
        method: the filter's name.  smoothed: whether the beliefs are the smoother's (the whole record) or the
            filter's (causal: each sample given the readings up to it).
        step_seconds: (T,) wall time of each filter step, s (the first includes the compile).
    """

    time: np.ndarray
    quantities: tuple
    columns: dict
    mean: np.ndarray
    cov: np.ndarray
    state_names: tuple
    sensors: tuple
    nis: np.ndarray
    dof: np.ndarray
    log_likelihood: float
    method: str
    smoothed: bool
    step_seconds: np.ndarray

    def band(self, column: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(estimate, lower, upper) (T,) of a reported quantity by its column (``robot_length_m``, ``Y_Pa``, ...).

        Raises:
            ValueError: a column that is not reported.
        """
        found = [q for q in self.quantities if q.column == column]
        if not found:
            raise ValueError(f"no quantity {column!r}; reported: {', '.join(q.column for q in self.quantities)}")
        q = found[0]
        return self.columns[q.column], self.columns[q.lower], self.columns[q.upper]

    def write_csv(self, path, extra: dict | None = None) -> None:
        """The CSV: ``time_s``, every reported column with its band, then ``extra`` {column: (T,)}."""
        write_csv(path, self.time, {**self.columns, **(extra or {})})

    def score(self, measured_length, noise_m: float = 0.0) -> dict:
        """The length estimate against a measured length (T,) m at the same samples (NaN: none there), read with
        noise of sd ``noise_m`` (m; 0 for the true length): {"rmse_m", "coverage_90" (share of samples inside the
        band widened by that noise, the band a reading falls in), "samples"}."""
        y = np.asarray(measured_length, float)
        est, lo, hi = self.band("robot_length_m")
        ok = np.isfinite(y)
        if not np.any(ok):
            return {"rmse_m": None, "coverage_90": None, "samples": 0}
        err = est[ok] - y[ok]
        half = np.sqrt(((hi[ok] - lo[ok]) / 2) ** 2 + (Z90 * noise_m) ** 2)
        inside = np.abs(err) <= half
        return {
            "rmse_m": float(np.sqrt(np.mean(err**2))),
            "coverage_90": float(np.mean(inside)),
            "samples": int(ok.sum()),
        }

    def consistency(self) -> dict:
        """The innovations' consistency: mean NIS per reading (1 when the filter's bands are honest) and the share of
        samples whose NIS lies inside its χ² 90 % interval."""
        from scipy.stats import chi2

        ok = self.dof > 0
        if not np.any(ok):
            return {"nis_per_reading": None, "nis_inside_90": None}
        lo, hi = chi2.ppf(0.05, self.dof[ok]), chi2.ppf(0.95, self.dof[ok])
        inside = (self.nis[ok] >= lo) & (self.nis[ok] <= hi)
        per = float(np.sum(self.nis[ok]) / np.sum(self.dof[ok]))
        return {"nis_per_reading": per if math.isfinite(per) else None, "nis_inside_90": float(np.mean(inside))}


__all__ = [
    "OUTPUT_QUANTITIES",
    "Z90",
    "Quantity",
    "TrackResult",
    "asked",
    "input_quantity",
    "linearised_values",
    "parameter_quantity",
    "quantities",
    "report",
    "unit_suffix",
    "values",
]
