"""Dense covariances (n, n) m² of the residual model's parts at ``times`` (n,) s, for reports and checks on
small n (a likelihood uses the filter of `growjax.calibration.discrepancy`), and the columns of a slow drift."""

from __future__ import annotations

import math

import numpy as np

from growjax.calibration.hyperparameters import Hyper

__all__ = ["DRIFT_GRID", "DRIFT_SHARE", "drift_columns", "drift_kernel", "kernel", "noise_kernel"]


def kernel(times, hyper: Hyper) -> np.ndarray:
    """Dense covariance (n, n) m² of δ at ``times``: a²(1 + √3|Δt|/ℓ)exp(−√3|Δt|/ℓ). For reports on small n."""
    t = np.asarray(times, float)
    x = math.sqrt(3.0) * np.abs(t[:, None] - t[None, :]) / float(hyper.time_scale)
    return float(hyper.amplitude) ** 2 * (1.0 + x) * np.exp(-x)


def drift_kernel(times, sd: float, time_scale: float) -> np.ndarray:
    """Dense covariance (n, n) m² of a slow drift at ``times``: sd² exp(−½(Δt/``time_scale``)²) (squared
    exponential), the fitted configuration's own error against the reference."""
    t = np.asarray(times, float)
    return sd**2 * np.exp(-0.5 * ((t[:, None] - t[None, :]) / time_scale) ** 2)


DRIFT_GRID = 64  # points of the grid a drift's columns are built on (over the span of the times)
DRIFT_SHARE = 1e-6  # the share of a drift's variance its columns may leave out


def drift_columns(times, sd: float, time_scale: float) -> np.ndarray:
    """Columns G (n, k) m at ``times`` (n,) s whose weights w ~ N(0, I) make G·w the slow drift of
    `drift_kernel` (G Gᵀ ≈ sd² exp(−½(Δt/``time_scale``)²)): the kernel's leading eigenvectors on a grid of
    `DRIFT_GRID` points over the times' span, extended to the times (Nyström), as many as carry all but
    `DRIFT_SHARE` of its variance. A smooth kernel over a span of a few of its time scales needs a handful, so
    the drift enters a likelihood as a few more static states of its filter, like the rig's errors."""
    t = np.asarray(times, float)
    grid = np.linspace(t.min(), t.max(), DRIFT_GRID if t.max() > t.min() else 1)
    kernel_of = lambda a, b: np.exp(-0.5 * ((a[:, None] - b[None, :]) / time_scale) ** 2)  # noqa: E731
    lam, vec = np.linalg.eigh(kernel_of(grid, grid))
    lam, vec = lam[::-1], vec[:, ::-1]
    k = int(np.searchsorted(np.cumsum(lam) / np.sum(lam), 1.0 - DRIFT_SHARE) + 1)
    return sd * kernel_of(t, grid) @ vec[:, :k] / np.sqrt(lam[:k])


def noise_kernel(times, hyper: Hyper) -> np.ndarray:
    """Dense covariance (n, n) m² of the sensor noise at ``times``: σ² exp(−|Δt|/τ) (σ² I for τ = 0)."""
    t = np.asarray(times, float)
    tau = float(hyper.noise_time)
    dt = np.abs(t[:, None] - t[None, :])
    corr = np.exp(-dt / tau) if tau > 0 else (dt == 0).astype(float)
    return float(hyper.noise) ** 2 * corr
