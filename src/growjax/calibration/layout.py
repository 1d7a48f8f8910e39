"""Where each run's free parameters and rig errors sit among a fit's coordinates.

A free parameter has one copy per robot, rig or run, or one for all (its `growjax.data.sets.Scope`); each copy is
one coordinate of the fit, labelled ``NAME`` (shared) or ``NAME@KEY``. The rig's relative errors b = ln(ψ/ψ₀) have
one vector per rig (``rig_errors="shared"``) or one per run.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from growjax.calibration.problem import physical_bounds, signed_scale, to_coordinates, to_values
from growjax.data.sets import ExperimentSet
from growjax.model import params as gp


@dataclasses.dataclass(frozen=True)
class Coordinate:
    """One coordinate of a fit: a free parameter's copy.

    Attributes:
        label: ``NAME`` (shared) or ``NAME@KEY``.
        name: the parameter's qualified name.
        scope: ``"shared"``, ``"robot"``, ``"rig"`` or ``"experiment"``.
        key: the robot, rig or run the copy belongs to (``"all"`` when shared).
        scale: the linear coordinate's scale s, SI, for a parameter whose range allows negative values (it moves
            as θ = θ_ref + s·z); None for one moved in ln θ.
    """

    label: str
    name: str
    scope: str
    key: str
    scale: float | None = None


@dataclasses.dataclass(frozen=True)
class Layout:
    """The fit's coordinates and each run's place among them.

    Attributes:
        index: (E, p) int: run e's parameter i is coordinate ``index[e, i]``.
        offset: (E, p): run e's own coordinate of parameter i is z[index] + offset (its own reference).
        rig_index: (E, q) int: run e's rig error j is b[rig_index[e, j]].
        coordinates: (P,) the coordinates.
        refs: (P,) SI, the value at z = 0 of each coordinate.
        rig_labels: (Q,) (rig key, tolerance name) of each rig error.
    """

    index: np.ndarray
    offset: np.ndarray
    rig_index: np.ndarray
    coordinates: tuple
    refs: np.ndarray
    rig_labels: tuple

    @property
    def labels(self) -> tuple:
        """(P,) the coordinates' labels."""
        return tuple(c.label for c in self.coordinates)

    @property
    def names(self) -> tuple:
        """(P,) the qualified parameter name of each coordinate."""
        return tuple(c.name for c in self.coordinates)

    @property
    def scales(self) -> np.ndarray:
        """(P,) the linear coordinates' scales, SI; NaN for those in ln θ."""
        return np.array([np.nan if c.scale is None else c.scale for c in self.coordinates], float)

    def values(self, z) -> np.ndarray:
        """θ (P,) SI at the coordinates z (P,)."""
        return np.asarray(to_values(np.asarray(z, float)[: len(self.coordinates)], self.refs, self.scales))

    def coordinates_of(self, values) -> np.ndarray:
        """z (…, P) of the values θ (…, P) SI."""
        return to_coordinates(values, self.refs, self.scales)

    def bounds(self, base: gp.Parameters) -> tuple[np.ndarray, np.ndarray]:
        """(lower (P,), upper (P,)) of z from each parameter's physical range in ``base``."""
        return physical_bounds(base, self.names, self.refs)


def make_layout(experiments: ExperimentSet, scopes, bases, problems, tol: dict, rig_errors: str) -> Layout:
    """The layout of the free parameters ``scopes`` (`growjax.data.sets.Scope` s) over the runs of
    ``experiments`` (their parameters ``bases``, their problems ``problems``) with the rig's tolerances ``tol``,
    one error vector per rig (``rig_errors="shared"``) or per run.

    Raises:
        ValueError: a parameter moved in ln θ that is not positive.
    """
    runs, p = list(experiments), len(scopes)
    coordinates, refs, index = [], [], np.zeros((len(runs), p), int)
    for i, s in enumerate(scopes):
        keys = experiments.group_of(s.scope)
        scale = signed_scale(bases[0], s.name)
        for key in dict.fromkeys(keys):
            first = keys.index(key)
            label = s.name if s.scope == "shared" else f"{s.name}@{key}"
            coordinates.append(Coordinate(label, s.name, s.scope, key, scale))
            refs.append(float(gp.get(bases[first], s.name)))
            for e, k in enumerate(keys):
                if k == key:
                    index[e, i] = len(coordinates) - 1
    refs = np.asarray(refs)
    positive = [c.scale is not None or v > 0 for c, v in zip(coordinates, refs)]
    if not all(positive):
        bad = {c.label: v for c, v, ok in zip(coordinates, refs, positive) if not ok}
        raise ValueError(f"fitted parameters must be positive (they are fitted in ln θ), got {bad}")
    own = np.stack([np.asarray(pr.refs)[:p] for pr in problems])  # (E, p) each run's own reference
    scales = np.array([np.nan if c.scale is None else c.scale for c in coordinates], float)
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = np.where(
            np.isfinite(scales[index]),
            (refs[index] - own) / np.where(np.isfinite(scales[index]), scales[index], 1.0),
            np.log(refs[index] / own),
        )
    rig_keys = experiments.group_of("rig" if rig_errors == "shared" else "experiment")
    rig_labels, rig_index = [], np.zeros((len(runs), len(tol)), int)
    for key in dict.fromkeys(rig_keys):
        for j, t in enumerate(tol):
            rig_labels.append((key, t))
            for e, k in enumerate(rig_keys):
                if k == key:
                    rig_index[e, j] = len(rig_labels) - 1
    return Layout(index, offset, rig_index, tuple(coordinates), refs, tuple(rig_labels))


__all__ = ["Coordinate", "Layout", "make_layout"]
