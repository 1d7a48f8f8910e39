"""What a discovery reports: where the misfit lives (phases, seconds), the result and its summary text."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

PHASES = ("growing", "holding", "retracting", "pressure_rising", "pressure_falling")


def phases(times, length, pressure, rate_tol: float = 2e-4) -> dict[str, np.ndarray]:
    """Boolean masks (m,) of the phases of a simulated run: growing / holding / retracting by the
    length rate against ``rate_tol`` (m/s), pressure rising / falling by the sign of dP/dt."""
    t = np.asarray(times, float)
    v = np.gradient(np.asarray(length, float), t)
    dp = np.gradient(np.asarray(pressure, float), t)
    return {
        "growing": v > rate_tol,
        "holding": np.abs(v) <= rate_tol,
        "retracting": v < -rate_tol,
        "pressure_rising": dp > 0,
        "pressure_falling": dp < 0,
    }


def locate(times, residual, length, pressure) -> dict:
    """Where the misfit lives: RMSE and mean residual (m) per phase, and per second of the run."""
    r = np.asarray(residual, float)
    t = np.asarray(times, float)
    out = {}
    for name, mask in phases(t, length, pressure).items():
        n = int(mask.sum())
        out[name] = {
            "share_of_time": n / r.size,
            "rmse_m": float(np.sqrt(np.mean(r[mask] ** 2))) if n else None,
            "mean_m": float(np.mean(r[mask])) if n else None,
        }
    edges = np.arange(math.floor(t[0]), math.ceil(t[-1]) + 1.0)
    by_second = []
    for a, b in itertools.pairwise(edges):
        mask = (t >= a) & (t < b)
        if mask.any():
            by_second.append(
                {
                    "t0_s": float(a),
                    "t1_s": float(b),
                    "rmse_m": float(np.sqrt(np.mean(r[mask] ** 2))),
                    "mean_m": float(np.mean(r[mask])),
                }
            )
    return {"by_phase": out, "by_second": by_second}


@dataclasses.dataclass
class DiscoveryResult:
    """What :func:`discover` found (see :meth:`report` for the JSON form)."""

    effect: str  # a catalogue name, "none", "unexplained" or "confounded"
    effects: list  # catalogue names added, in order
    parameters: dict  # {qualified name: {"estimate", "interval_90", "unit"}} of the final model
    rmse_before_m: float
    rmse_after_m: float
    noise_sigma_m: float
    threshold: float
    evidence: dict  # per round, per candidate
    confounded_with: dict
    where: dict  # before / after, by phase
    misfit_before: dict
    misfit_after: dict
    separating_measurement: dict
    wall_s: float
    trade_allowance: float = 0.0  # 2ΔlogL the fitted configuration's own error can buy (confounding test)
    fits: int = 0  # least-squares fits run (every start counted)
    linearisations: int = 0  # model linearisations over all fits (each one forward-mode solve)
    times: np.ndarray = dataclasses.field(repr=False, default=None)
    measured: np.ndarray = dataclasses.field(repr=False, default=None)
    before: np.ndarray = dataclasses.field(repr=False, default=None)
    after: np.ndarray = dataclasses.field(repr=False, default=None)

    def report(self) -> dict:
        return {k: v for k, v in dataclasses.asdict(self).items() if k not in ("times", "measured", "before", "after")}


def _unit(name: str) -> str:
    return {
        "robot.yield_pressure": "Pa",
        "robot.extensibility": "(m/s)·Pa^(-1/n)",
        "robot.growth_exponent": "-",
        "robot.lockhart_rate": "m/s",
        "robot.lockhart_exponent": "-",
    }.get(name, "")


def confounded_lines(confounded_with: dict) -> list[str]:
    """One line per confounded effect: what it trades with and the measurement that would separate them."""
    lines = []
    for name, c in confounded_with.items():
        with_ = [f"{c['parameter']} (correlation {c['correlation']:.3f})"] if c["parameter"] else []
        with_ += [f"the effect {r}" for r in c.get("rival_effects", ())]
        lines.append(f"confounded: {name} with {' and '.join(with_)}; separate by {c['separate_by']}")
    return lines


def summary_text(result: DiscoveryResult) -> str:
    """A readable summary of a :class:`DiscoveryResult` for the terminal."""
    lines = [
        f"effect: {result.effect}" + (f" (added: {', '.join(result.effects)})" if result.effects else ""),
        (
            f"length RMSE {1e3 * result.rmse_before_m:.3f} mm before, {1e3 * result.rmse_after_m:.3f} mm after; "
            f"noise σ {1e3 * result.noise_sigma_m:.3f} mm; threshold 2ΔlogL > {result.threshold:.2f}"
        ),
    ]
    for name, p in result.parameters.items():
        lo, hi = p["interval_90"]
        lines.append(f"  {name} = {p['estimate']:.4g} {p['unit']} (90 %: {lo:.4g} – {hi:.4g})")
    for k, scores in enumerate(result.evidence):
        lines.append(f"round {k + 1}:")
        for name, s in sorted(scores.items(), key=lambda kv: -kv[1]["lr_statistic"]):
            flag = "confounded" if s["confounded"] else ("clears" if s["clears_threshold"] else "")
            lines.append(
                f"  {name:22s} 2ΔlogL {s['lr_statistic']:8.2f}  {s['parameter']} = {s['estimate']:.3g} "
                f"{s['unit']}  {flag}"
            )
    lines += confounded_lines(result.confounded_with)
    lines.append(f"{result.wall_s:.1f} s: {result.fits} fits, {result.linearisations} linearisations of the model")
    return "\n".join(lines)
