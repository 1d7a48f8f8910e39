"""Agreement between simulated and measured series."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from growjax.simulation.trajectory import Trajectory

__all__ = ["length_rmse", "rmse_at_samples"]


def length_rmse(
    traj: Trajectory,
    times: Float[ArrayLike, " m"],
    measured: Float[ArrayLike, " m"],
    t_start: Float[ArrayLike, ""] | None = None,
    t_end: Float[ArrayLike, ""] | None = None,
) -> Float[Array, ""]:
    """Root-mean-square error of a trajectory's length against a measured one.

    The simulated length is interpolated linearly onto ``times`` (exact where ``traj`` was saved at
    them, `growjax.simulation.simulate.sample_times`). Works under ``jit``/``grad``.

    Args:
        traj: the trajectory (unbatched).
        times: (m,) the sample times, s.
        measured: (m,) the measured length, m.
        t_start: samples before it are ignored, s (default: the simulated window's start).
        t_end: samples after it are ignored, s (default: the simulated window's end).

    Returns:
        The RMSE, m; NaN if the trajectory stopped before covering the window.
    """
    times = jnp.asarray(times)
    t_start = traj.time[0] if t_start is None else t_start
    t_end = traj.time[-1] if t_end is None else t_end
    return rmse_at_samples(jnp.interp(times, traj.time, traj.length), times, measured, t_start, t_end)


def rmse_at_samples(
    simulated: Float[ArrayLike, " m"],
    times: Float[ArrayLike, " m"],
    measured: Float[ArrayLike, " m"],
    t_start: Float[ArrayLike, ""],
    t_end: Float[ArrayLike, ""],
) -> Float[Array, ""]:
    """Root-mean-square error of a simulated series against a measured one over the samples inside a window.

    Args:
        simulated: (m,) simulated values, m.
        times: (m,) their times, s.
        measured: (m,) measured values, m.
        t_start: the window's start, s.
        t_end: the window's end, s.

    Returns:
        The RMSE, m; NaN where a simulated sample inside is NaN.
    """
    times = jnp.asarray(times)
    inside = (times >= t_start - 1e-12) & (times <= t_end + 1e-12)
    err = jnp.where(inside, simulated - jnp.asarray(measured), 0.0)
    return jnp.sqrt(jnp.sum(err**2) / jnp.sum(inside))
