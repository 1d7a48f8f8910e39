"""The figure of a design: its demand beside the baseline's (the published pulse train; for the stepper, the
recorded length as its demand) and the best random input's, and the length and sensed pressure each gives over
the draws of the rig and θ (bands: the range over the draws)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from growjax.design.workflow import DesignResult

__all__ = ["BASELINE_COLOUR", "STYLE", "design_figure"]

STYLE = {"design": "C3", "best random input": "C0"}
BASELINE_COLOUR = "0.45"


def design_figure(result: DesignResult, path: str | Path) -> Path:
    """Three panels over the run: demand (kPa; for the stepper, the commanded length, mm), sensed pressure (kPa)
    with the ceiling and the membrane limit, and length (mm) with the stroke's ceiling; ``result`` a
    `growjax.design.DesignResult`."""
    import matplotlib.pyplot as plt

    space, lim = result.space, result.limits
    t = np.asarray(space.times)
    fine = np.linspace(0.0, space.duration, 2001)
    fig, (ax_d, ax_p, ax_l) = plt.subplots(3, 1, figsize=(8, 8), sharex=True, constrained_layout=True)
    stepper = space.drive == "inverse"
    scale_d = 1e3 if stepper else 1e-3  # mm of commanded length, or kPa of demand
    baseline = space.baseline_label
    demands = {
        baseline: space.baseline_command(fine),
        "best random input": space.command(result.random.designs[result.random.best], fine),
        "design": space.command(result.x, fine),
    }
    for label in (baseline, "best random input", "design"):
        color = STYLE.get(label, BASELINE_COLOUR)
        ax_d.plot(fine, demands[label] * scale_d, color=color, lw=1.6 if label == "design" else 1.0, label=label)
        check = result.checks[label]
        for ax, runs, scale in ((ax_p, check.pressure, 1e-3), (ax_l, check.length, 1e3)):
            if runs is None:
                continue
            runs = np.asarray(runs)[0] * scale  # (D, n)
            ax.fill_between(t, np.nanmin(runs, axis=0), np.nanmax(runs, axis=0), color=color, alpha=0.25, lw=0)
            ax.plot(t, np.nanmedian(runs, axis=0), color=color, lw=1.4 if label == "design" else 0.9, label=label)
    for ax in (ax_p,) if stepper else (ax_d, ax_p):
        ax.axhline(lim.pressure_ceiling / 1e3, color="C1", ls="--", lw=1, label="ceiling (limit × margin)")
        ax.axhline(lim.membrane_limit / 1e3, color="C3", ls=":", lw=1, label="membrane limit")
    for ax in (ax_d, ax_l) if stepper else (ax_l,):
        ax.axhline(lim.length_ceiling * 1e3, color="C1", ls="--", lw=1, label="length ceiling (stroke × margin)")
    ax_d.set_ylabel("commanded length (mm)" if stepper else "demand (kPa)")
    ax_p.set_ylabel("sensed pressure (kPa)")
    ax_l.set_ylabel("length (mm)")
    ax_l.set_xlabel("time (s)")
    for ax in (ax_d, ax_p, ax_l):
        ax.legend(loc="upper right", fontsize=7)
    row = next(r for r in result.rows if r["input"] == "design" and tuple(r["sensors"]) == result.sensors)
    if result.discrimination:
        a, b = result.discrimination["effects"]
        ax_d.set_title(
            f"designed input to tell {a} from {b}: min T {row['T_min']:.1f} (threshold "
            f"{result.discrimination['threshold']:.1f}) (bands: range over the rig and θ draws)",
            fontsize=9,
        )
    else:
        sds = ", ".join(f"{n.split('.')[-1]} ±{100 * p['sd_log']:.2f} %" for n, p in row["parameters"].items())
        what = "designed step schedule" if stepper else "designed input"
        ax_d.set_title(
            f"{what} ({result.criterion}-optimal; {', '.join(result.sensors)}): {sds} "
            "(bands: range over the rig and θ draws)",
            fontsize=9,
        )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
