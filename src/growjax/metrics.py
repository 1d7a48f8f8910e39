"""Agreement between simulated and measured series."""

from __future__ import annotations

import jax.numpy as jnp


def length_rmse(traj, times, measured, t_start=None, t_end=None):
    """Root-mean-square length error (m) of ``traj`` against ``measured`` (m) sampled at ``times`` (s).

    The simulated length is interpolated linearly onto ``times``; samples outside
    [t_start, t_end] (default: the simulated window) are ignored. Works under ``jit``/``grad``.
    NaN if the trajectory stopped before covering the window.
    """
    times = jnp.asarray(times)
    t_start = traj.time[0] if t_start is None else t_start
    t_end = traj.time[-1] if t_end is None else t_end
    sim = jnp.interp(times, traj.time, traj.length)
    mask = (times >= t_start - 1e-12) & (times <= t_end + 1e-12)
    err = jnp.where(mask, sim - jnp.asarray(measured), 0.0)
    return jnp.sqrt(jnp.sum(err**2) / jnp.sum(mask))
