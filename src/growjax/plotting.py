"""Figures (matplotlib, whichever backend the caller has selected): the paper's Fig. 3/4 style trajectory plot, and
the closed-loop figure of a control design."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

__all__ = [
    "control_figure",
    "discovery_figure",
    "population_figure",
    "posterior_figures",
    "predictive_figure",
    "rank_figure",
    "set_figure",
    "sobol_figure",
    "sweep_figure",
    "trajectory_figure",
]


def _save(fig: Any, path: str | Path) -> str | Path:
    """Write ``fig`` to ``path`` (folders created), close it, return the path."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def trajectory_figure(
    traj: Any,
    path: str | Path,
    measured: tuple[Any, Any] | None = None,
    desired: tuple[Any, Any] | None = None,
    title: str = "",
    pressure_limit: float | None = None,
) -> str | Path:
    """Two panels: pressure demand and sensed pressure (kPa); simulated (and measured) length (mm).

    Args:
        traj: a `growjax.Trajectory` (unbatched).
        path: the PNG file to write (folders created).
        measured: (time s, length m), the measured length, if any.
        desired: (time s, length m), the desired length, if any.
        title: the figure's title.
        pressure_limit: the membrane's limit, Pa, drawn where given.

    Returns:
        ``path``.
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
    return _save(fig, path)


def set_figure(traces: Sequence[tuple[str, Any, tuple[Any, Any]]], path: str | Path, title: str = "") -> str | Path:
    """One panel per experiment of a set: measured and fitted length (mm). ``traces``: [(name, trajectory,
    (time s, measured length m))]."""
    n = len(traces)
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 2.8 * rows), squeeze=False, constrained_layout=True)
    for ax, (name, traj, (t, y)) in zip(axes.ravel(), traces):
        ax.plot(t, 1e3 * np.asarray(y), color="k", lw=1, label="measured")
        ax.plot(np.asarray(traj.time), 1e3 * np.asarray(traj.length), color="C1", lw=1.3, label="fitted")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("length (mm)")
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    axes[0, 0].legend(loc="upper left", fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def population_figure(
    population: Any, band: dict, path: str | Path, measured: tuple[Any, Any] | None = None
) -> str | Path:
    """Left: each robot's posterior of the population's parameter (median, 90 %) and the population's median
    with its 90 % interval. Right: a new robot's predictive length band (mm) against time, with ``measured``
    (time s, length m) if given."""
    label, scale = _axis(population.name)
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
    theta = np.exp(population.ln_theta) * scale
    q = np.quantile(theta, [0.05, 0.5, 0.95], axis=0)
    y = np.arange(len(population.robots))
    ax0.errorbar(q[1], y, xerr=[q[1] - q[0], q[2] - q[1]], fmt="o", color="C0", label="robot")
    med = np.quantile(np.exp(population.mu) * scale, [0.05, 0.5, 0.95])
    ax0.axvspan(med[0], med[2], color="C1", alpha=0.25, label="population median, 90 %")
    ax0.axvline(med[1], color="C1")
    ax0.set_yticks(y, population.robots, fontsize=8)
    ax0.set_xlabel(label)
    ax0.legend(fontsize=8)
    t = band["times"]
    ax1.fill_between(
        t,
        1e3 * band["lower"],
        1e3 * band["upper"],
        color="C2",
        alpha=0.3,
        label=f"new robot, {round(100 * band['level'])} %",
    )
    ax1.plot(t, 1e3 * band["median"], color="C2")
    if measured is not None:
        tm, ym = (np.asarray(x) for x in measured)
        keep = (tm >= t[0]) & (tm <= t[-1])
        ax1.plot(tm[keep], 1e3 * ym[keep], color="k", lw=0.8, label="measured")
    ax1.set_xlabel("time (s)")
    ax1.set_ylabel("length (mm)")
    ax1.legend(fontsize=8, loc="upper left")
    return _save(fig, path)


_LABELS = {
    "robot.yield_pressure": ("Y (kPa)", 1e-3),
    "robot.extensibility": ("ext φ", 1.0),
    "robot.growth_exponent": ("n", 1.0),
}


def _axis(name: str) -> tuple[str, float]:
    return _LABELS.get(name, (name, 1.0))


def sweep_figure(result: Any, path: str | Path, title: str = "") -> str | Path:
    """The paper's Fig. 2: every swept set in 3-D (first three parameters) coloured by length RMSE (mm), best starred.

    With fewer than three parameters, a 2-D scatter (or RMSE against the one parameter).
    Failed members are drawn as grey crosses.
    """
    vals, rmse = np.asarray(result.values), 1e3 * np.asarray(result.rmse)
    ok = ~np.asarray(result.failed) & np.isfinite(rmse)
    best = result.best_index
    d = vals.shape[1]
    fig = plt.figure(figsize=(7.5, 6), constrained_layout=True)
    labels = [_axis(n) for n in result.names]
    cols = [vals[:, i] * labels[i][1] for i in range(d)]
    if d >= 3:
        ax = fig.add_subplot(projection="3d")
        sc = ax.scatter(cols[0][ok], cols[1][ok], cols[2][ok], c=rmse[ok], cmap="viridis", s=12)
        if np.any(~ok):
            ax.scatter(cols[0][~ok], cols[1][~ok], cols[2][~ok], c="0.6", marker="x", s=14, label="failed")
        if best is not None:
            ax.scatter(cols[0][best], cols[1][best], cols[2][best], c="r", marker="*", s=250, label="best")
        ax.set_xlabel(labels[0][0])
        ax.set_ylabel(labels[1][0])
        ax.set_zlabel(labels[2][0])
    else:
        ax = fig.add_subplot()
        x = cols[0]
        y = cols[1] if d == 2 else rmse
        sc = ax.scatter(x[ok], y[ok], c=rmse[ok], cmap="viridis", s=12)
        if best is not None:
            ax.scatter(x[best], y[best], c="r", marker="*", s=250, label="best")
        ax.set_xlabel(labels[0][0])
        ax.set_ylabel(labels[1][0] if d == 2 else "length RMSE (mm)")
    fig.colorbar(sc, ax=ax, shrink=0.7, label="length RMSE (mm)")
    if best is not None:
        ax.legend(loc="upper left", fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return _save(fig, path)


def sobol_figure(sobol: dict, path: str | Path, title: str = "") -> str | Path:
    """Bar chart of first-order (S1) and total-order (ST) Sobol indices with 95 % bootstrap intervals, per output."""
    outputs = [k for k, v in sobol["indices"].items() if "S1" in v]
    names = [_axis(n)[0] for n in sobol["names"]]
    fig, axes = plt.subplots(
        1, max(1, len(outputs)), figsize=(5 * max(1, len(outputs)), 4), constrained_layout=True, squeeze=False
    )
    x = np.arange(len(names))
    for ax, key in zip(axes[0], outputs):
        s = sobol["indices"][key]
        ax.bar(x - 0.18, s["S1"], 0.36, yerr=s["S1_conf"], capsize=3, label="first order S1")
        ax.bar(x + 0.18, s["ST"], 0.36, yerr=s["ST_conf"], capsize=3, label="total order ST")
        ax.set_xticks(x, names)
        ax.set_ylim(min(0.0, float(np.min(s["S1"])) - 0.05), 1.1)
        ax.set_title(key)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def predictive_figure(
    times: Any, observed: Any, bands: dict[str, tuple[Any, Any, Any]], path: str | Path, title: str = ""
) -> str | Path:
    """Measured length with posterior predictive 90 % bands, one per model ({label: (lower, upper, median)}, m)."""
    fig, ax = plt.subplots(figsize=(8, 3.8), constrained_layout=True)
    for k, (label, (lo, hi, med)) in enumerate(bands.items()):
        ax.fill_between(
            times, 1e3 * np.asarray(lo), 1e3 * np.asarray(hi), color=f"C{k}", alpha=0.25, label=f"{label}: 90 % band"
        )
        ax.plot(times, 1e3 * np.asarray(med), color=f"C{k}", lw=1.2)
    ax.plot(times, 1e3 * np.asarray(observed), "k.", ms=1.5, label="measured")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("robot length (mm)")
    ax.legend(loc="upper left", fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return _save(fig, path)


def _figure(plots: Any) -> Any:
    """The matplotlib figure of an arviz-plots ``PlotCollection`` or ``PlotMatrix``."""
    return plots.viz["figure"].item()


def rank_figure(idata: Any, sites: Sequence[str], bins: int = 20) -> Any:
    """The rank-bar trace plot: per chain, each scalar site's histogram (left) and the histogram of its draws'
    ranks among all chains' draws (right, ``bins`` bars; dashed: each bar's count when every chain samples the same
    distribution). ``idata``: a DataTree with a ``posterior`` group of (chain, draw) variables → the figure."""
    from scipy.stats import rankdata

    post = idata["posterior"]
    sites = list(sites)
    fig, axes = plt.subplots(len(sites), 2, figsize=(8, 1.8 * len(sites)), squeeze=False, constrained_layout=True)
    for (ax_d, ax_r), site in zip(axes, sites):
        x = np.asarray(post[site], float)  # (chains, draws)
        ranks = rankdata(x, axis=None).reshape(x.shape)
        edges, rank_edges = np.histogram_bin_edges(x, bins=30), np.linspace(0.5, x.size + 0.5, bins + 1)
        for c in range(x.shape[0]):
            ax_d.hist(x[c], bins=edges, histtype="step", density=True, color=f"C{c}")
            ax_r.hist(ranks[c], bins=rank_edges, histtype="step", color=f"C{c}")
        ax_r.axhline(x.shape[1] / bins, color="k", ls="--", lw=0.8)
        ax_d.set_ylabel(site)
        ax_d.set_yticks([])
        ax_d.locator_params(axis="x", nbins=4)
    axes[0, 0].set_title("draws per chain", fontsize=10)
    axes[0, 1].set_title("rank of each draw among all chains", fontsize=10)
    axes[-1, 1].set_xlabel("rank")
    return fig


def posterior_figures(
    idata: Any, sites: Sequence[str], folder: str | Path, prefix: str = ""
) -> tuple[str | Path, str | Path]:
    """Figures of a posterior as PNG files: the rank-bar trace (`rank_figure`) and arviz-plots' pair plot with
    marginals (``plot_pair``, in ArviZ's ``arviz-variat`` style).

    Args:
        idata: a DataTree with a ``posterior`` group (`growjax.posterior.inference_data`).
        sites: the scalar variables of ``posterior`` to show, by their names there (the noise is ``sigma_mm``).
        folder: where the files go (created).
        prefix: the files' names' prefix.

    Returns:
        (the trace figure's path, the pair plot's path): ``{prefix}trace.png`` and ``{prefix}pair.png``.
    """
    import arviz_plots as azp

    sites = list(sites)
    trace = _save(rank_figure(idata, sites), Path(folder) / f"{prefix}trace.png")
    with plt.style.context("arviz-variat"):  # ArviZ's style, registered by importing arviz_plots
        pair = azp.plot_pair(idata, var_names=sites, backend="matplotlib", figure_kwargs={"figsize": (8, 8)})
        pair = _save(_figure(pair), Path(folder) / f"{prefix}pair.png")
    return trace, pair


def discovery_figure(result: Any, path: str | Path, title: str = "") -> str | Path:
    """Measured length and the base / extended fits (mm), and their residuals over time (mm)."""
    t = np.asarray(result.times)
    fig, (ax_l, ax_r) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, constrained_layout=True)
    ax_l.plot(t, 1e3 * np.asarray(result.measured), ".", ms=2, color="0.5", label="measured")
    ax_l.plot(
        t,
        1e3 * np.asarray(result.before),
        color="C0",
        lw=1.2,
        label=f"base model (RMSE {1e3 * result.rmse_before_m:.2f} mm)",
    )
    if result.effects:
        ax_l.plot(
            t,
            1e3 * np.asarray(result.after),
            color="C3",
            lw=1.2,
            label=f"+ {', '.join(result.effects)} (RMSE {1e3 * result.rmse_after_m:.2f} mm)",
        )
    ax_l.set_ylabel("length (mm)")
    ax_l.legend(loc="best", fontsize=8)
    ax_r.plot(t, 1e3 * (np.asarray(result.before) - np.asarray(result.measured)), color="C0", lw=0.8, label="base")
    if result.effects:
        ax_r.plot(
            t, 1e3 * (np.asarray(result.after) - np.asarray(result.measured)), color="C3", lw=0.8, label="extended"
        )
    ax_r.axhline(0.0, color="k", lw=0.5)
    ax_r.set_ylabel("model − measured (mm)")
    ax_r.set_xlabel("time (s)")
    ax_r.legend(loc="best", fontsize=8)
    if title:
        ax_l.set_title(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def control_figure(res: Any, target: Any, path: str | Path, lim: Any, title: str, drive: str) -> Path:
    """Command, pressure and length against the target (three panels) of a closed loop ``res``
    (`growjax.control.ClosedLoopResult`), a `growjax.control.Target` and the rig's `growjax.model.limits.Limits`."""
    fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    if drive == "forward":
        ax[0].plot(res.tick_time, np.asarray(res.command) / 1e3, drawstyle="steps-post")
        ax[0].set_ylabel("demand (kPa)")
    else:
        ax[0].step(res.tick_time, res.command, where="post")
        ax[0].set_ylabel("step count")
    ax[1].plot(res.time, res.pressure / 1e3)
    ax[1].axhline(lim.membrane_limit / 1e3, color="r", ls="--", label="membrane limit")
    ax[1].set_ylabel("pressure (kPa)")
    ax[1].legend(loc="upper left")
    ax[2].plot(target.time, 1e3 * target.length, "k", lw=1, label="target")
    ax[2].plot(res.time, 1e3 * res.length, label="robot")
    ax[2].set_ylabel("length (mm)")
    ax[2].set_xlabel("time (s)")
    ax[2].set_xlim(0, res.time[-1])
    ax[2].legend(loc="upper left")
    ax[0].set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
