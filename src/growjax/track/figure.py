"""The figure of a tracked record: the length, the pressure, each estimated parameter and input over time, each
with its 90 % band, beside what was measured (and, for an estimated demand, a demand to compare with)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from growjax.track.result import TrackResult

# How each kind of column is drawn: (scale to the axis unit, axis label).
AXES = {
    "robot_length_m": (1e3, "robot length (mm)"),
    "pressure_Pa": (1e-3, "sensed pressure (kPa)"),
    "pressure_demand_Pa": (1e-3, "pressure demand (kPa)"),
    "catheter_length_m": (1e3, "catheter length (mm)"),
}


def _axis(column: str) -> tuple[float, str]:
    if column in AXES:
        return AXES[column]
    if column.endswith("_Pa"):
        return 1e-3, f"{column[:-3]} (kPa)"
    return 1.0, column


def _limits(est, lo, hi, seen=()) -> tuple[float, float]:
    """The axis: the band and what was measured, the band no more than twice the estimate's own range beyond it (a
    quantity no sensor reads can carry a band far wider than anything physical, its linearisation held by no data)."""
    span = max(float(np.ptp(est)), 1e-12)
    low = max(float(np.min(lo)), float(np.min(est)) - 2 * span)
    high = min(float(np.max(hi)), float(np.max(est)) + 2 * span)
    for values in seen:
        finite = np.asarray(values)[np.isfinite(values)]
        if finite.size:
            low, high = min(low, float(finite.min())), max(high, float(finite.max()))
    pad = 0.05 * (high - low) if high > low else max(abs(high), 1e-12)  # a quantity held exactly: an axis about it
    return low - pad, high + pad


def track_figure(
    result: TrackResult,
    path,
    *,
    measured: dict | None = None,
    compare: tuple | None = None,
    title: str = "",
) -> Path:
    """Draw ``result`` to ``path`` (PNG): one panel per quantity shown, estimate and 90 % band.

    Args:
        result: the tracked record.
        path: where the figure goes (folders created).
        measured: {column: (T,) SI} readings at the result's samples to draw over their estimate
            (``robot_length_m``, ``pressure_Pa``, ...; NaN where none).
        compare: (label, time (K,) s, values (K,) SI) drawn over the estimated demand (a recorded or published
            demand).
        title: the figure's title.

    Returns:
        ``path``.
    """
    measured = measured or {}
    shown = ["robot_length_m", "pressure_Pa"] + [
        q.column for q in result.quantities[4:] if q.column != "catheter_length_m"
    ]
    fig, axes = plt.subplots(len(shown), 1, figsize=(8, 2.2 * len(shown) + 0.6), sharex=True, squeeze=False)
    kind = "smoothed (whole record)" if result.smoothed else "filtered (causal)"
    for ax, column in zip(axes[:, 0], shown):
        scale, label = _axis(column)
        est, lo, hi = result.band(column)
        ax.fill_between(result.time, scale * lo, scale * hi, color="C0", alpha=0.25, lw=0, label="90 % band")
        ax.plot(result.time, scale * est, color="C0", lw=1.2, label=f"estimate, {kind}")
        if column in measured:
            ax.plot(result.time, scale * np.asarray(measured[column]), color="k", lw=0.8, label="measured")
        if compare is not None and column.startswith("pressure_demand"):
            name, t, v = compare
            ax.plot(t, scale * np.asarray(v), color="C3", lw=1.0, ls="--", label=name)
        ax.set_ylabel(label)
        seen = [scale * np.asarray(measured[column])] if column in measured else []
        ax.set_ylim(*_limits(scale * est, scale * lo, scale * hi, seen))
        ax.legend(loc="best", fontsize=7)
    axes[-1, 0].set_xlabel("time (s)")
    if title:
        axes[0, 0].set_title(title, fontsize=10)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


__all__ = ["track_figure"]
