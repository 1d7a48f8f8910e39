"""Figures (matplotlib, Agg backend): the paper's Fig. 3/4 style trajectory plot."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def trajectory_figure(traj, path, measured=None, desired=None, title: str = "", pressure_limit=None):
    """Two panels: pressure demand and sensed pressure (kPa); simulated (and measured) length (mm).

    ``measured``/``desired``: optional (time s, length m) pairs.
    """
    t = np.asarray(traj.time)
    fig, (ax_p, ax_l) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, constrained_layout=True)
    demand = np.asarray(traj.pressure_demand)
    if np.any(demand != 0):
        ax_p.plot(t, demand / 1e3, color="0.6", lw=1, label="demand")
    ax_p.plot(t, np.asarray(traj.pressure) / 1e3, color="C0", lw=1.2, label="sensed P (before check valve)")
    if pressure_limit is not None:
        ax_p.axhline(pressure_limit / 1e3, color="C3", ls=":", lw=1, label="membrane limit")
    ax_p.set_ylabel("pressure (kPa)")
    ax_p.legend(loc="upper right", fontsize=8)
    if measured is not None:
        ax_l.plot(measured[0], 1e3 * np.asarray(measured[1]), color="k", lw=1, label="measured")
    if desired is not None:
        ax_l.plot(desired[0], 1e3 * np.asarray(desired[1]), color="0.6", lw=1, ls="--", label="desired")
    ax_l.plot(t, 1e3 * np.asarray(traj.length), color="C1", lw=1.5, label="simulated")
    ax_l.set_ylabel("robot length (mm)")
    ax_l.set_xlabel("time (s)")
    ax_l.legend(loc="upper left", fontsize=8)
    if title:
        ax_p.set_title(title, fontsize=10)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
