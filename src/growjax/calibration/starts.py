"""Where a fit starts: each free parameter's sampling box and one Latin-hypercube scout of it for all the runs.

The scout draws points over each free parameter's `default_range` (scipy's ``qmc.LatinHypercube``, seeded; log
scale, or linear for a parameter whose range allows negative values), every copy of a parameter at the same value,
runs every run at every point through the batch and ranks the points by the length RMSE over all the runs' scored
samples: a fit starts from the best.
"""

from __future__ import annotations

import numpy as np

from growjax.calibration.batch import Batch
from growjax.calibration.layout import Layout
from growjax.calibration.problem import signed_scale, to_coordinates
from growjax.model import params as gp

# Multi-start boxes: the paper's investigation where it has one, else [θ/2, 2θ] around the reference.
PAPER_RANGES = {d.name: (d.low, d.high) for d in gp.paper_box()}


def default_range(base: gp.Parameters, name: str) -> tuple[float, float]:
    """The sampling box (low, high), SI, of a free parameter: the paper's investigation where it has one; for a
    parameter whose range allows negative values, its physical range; else [θ/2, 2θ] about its value in ``base``.

    Raises:
        ValueError: a parameter moved in ln θ that is not positive, or a signed one without a finite range.
    """
    q = gp.resolve_name(base, name)
    if q in PAPER_RANGES:
        return PAPER_RANGES[q]
    if signed_scale(base, q) is not None:
        lo, hi = gp.physical_ranges(base)[q][:2]
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise ValueError(f"parameter {q} can be negative but its physical range [{lo}, {hi}] is not finite")
        return float(lo), float(hi)
    v = float(gp.get(base, q))
    if v <= 0:
        raise ValueError(
            f"parameter {q} = {v} is not positive: only positive parameters can be fitted in log coordinates"
        )
    return 0.5 * v, 2.0 * v


def dimensions(base: gp.Parameters, names) -> list[gp.Dimension]:
    """The sampling boxes of ``names`` as `growjax.model.params.Dimension` s (log scale unless signed)."""
    return [gp.Dimension(n, *default_range(base, n), log=signed_scale(base, n) is None) for n in names]


def sampling_box(base: gp.Parameters, names, refs, scales=None) -> np.ndarray:
    """(2, p): the starts' sampling box (`default_range`) in the coordinates z about ``refs`` (p,) SI, lower then
    upper (``scales`` (p,): the linear coordinates', NaN for ln θ; None: from ``base``)."""
    if scales is None:
        scales = [np.nan if (s := signed_scale(base, n)) is None else s for n in names]
    box = np.array([default_range(base, n) for n in names]).T
    return to_coordinates(box, np.asarray(refs, float)[None, :], np.asarray(scales, float)[None, :])


def scout_starts(batch: Batch, layout: Layout, base: gp.Parameters, starts: int, points: int, seed: int):
    """(values (K, P) SI of the points scouted, per coordinate; the indices of the ``starts`` best).

    ``points`` Latin-hypercube points over each free parameter's `default_range` (every copy of a parameter at
    the same value), ranked by the length RMSE over every run's scored samples (a point where a run fails, or
    outside a physical range, is not a start); 0: one point, the runs' own values.

    Raises:
        ValueError: ``points`` < 0 or ``starts`` < 1.
        RuntimeError: no point simulated successfully.
    """
    if points < 0 or starts < 1:
        raise ValueError(f"scout must be >= 0 and starts >= 1, got {points} and {starts}")
    if points == 0:
        return layout.refs[None, :], [0]
    names = tuple(dict.fromkeys(layout.names))
    design = gp.latin_hypercube(dimensions(base, names), points, seed)  # (K, p) per free name
    values = design[:, [names.index(n) for n in layout.names]]  # (K, P) per coordinate
    admissible = gp.admissible_rows(base, names, design)
    zs = layout.coordinates_of(values)
    rmse = np.full(points, np.nan)
    kept = np.flatnonzero(admissible)
    for k, outs in zip(kept, batch.scout([zs[k] for k in kept], layout) if kept.size else []):
        if all(ok for _, ok in outs):
            r = np.concatenate([np.asarray(x)[:n] for (x, _), n in zip(outs, batch.n_len)])
            rmse[k] = batch.sigma_length * float(np.sqrt(np.mean(r**2)))
    order = [int(i) for i in np.argsort(np.nan_to_num(rmse, nan=np.inf)) if np.isfinite(rmse[i])][:starts]
    if not order:
        raise RuntimeError("no start of the multi-start scout simulated successfully")
    return values, order


__all__ = ["PAPER_RANGES", "default_range", "dimensions", "sampling_box", "scout_starts"]
