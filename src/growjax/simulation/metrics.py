"""Agreement between simulated and measured series."""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["length_rmse", "rmse_at_samples"]


def length_rmse(traj, times, measured, t_start=None, t_end=None):
    """Root-mean-square length error (m) of ``traj`` against ``measured`` (m) sampled at ``times`` (s).

    The simulated length is interpolated linearly onto ``times`` (exact where ``traj`` was saved at
    them, :func:`growjax.simulation.simulate.sample_times`); samples outside [t_start, t_end] (default: the simulated
    window) are ignored. Works under ``jit``/``grad``. NaN if the trajectory stopped before covering the window.
    """
    times = jnp.asarray(times)
    t_start = traj.time[0] if t_start is None else t_start
    t_end = traj.time[-1] if t_end is None else t_end
    return rmse_at_samples(jnp.interp(times, traj.time, traj.length), times, measured, t_start, t_end)


def rmse_at_samples(simulated, times, measured, t_start, t_end):
    """Root-mean-square error (m) of ``simulated`` against ``measured`` (both (m,), m, at ``times`` s) over the
    samples inside [t_start, t_end] s. NaN where a simulated sample inside is NaN."""
    times = jnp.asarray(times)
    inside = (times >= t_start - 1e-12) & (times <= t_end + 1e-12)
    err = jnp.where(inside, simulated - jnp.asarray(measured), 0.0)
    return jnp.sqrt(jnp.sum(err**2) / jnp.sum(inside))
