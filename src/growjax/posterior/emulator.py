"""A tensor-grid emulator of the model length, so that NUTS costs microseconds per gradient.

NUTS on the measured 10 s needs ~10⁴ gradients of the likelihood. Through the ODE each
costs ~0.5 s on a 2-core CPU (forward mode, quasi-static model), so a 4 × (500 + 500)
run would take about an hour. The posterior only needs the length at the measured times
as a smooth function of the few sampled parameters, so it is tabulated once, in one
batched sweep, on a grid over the prior box, and interpolated:

    L(t_i; θ) ≈ Σ_k w_k(θ) L(t_i; θ_k)      (tensor-product Catmull–Rom, C¹ in θ)

Each axis is uniform in θ or in ln θ. The end nodes are extended linearly, so an axis with
two nodes interpolates linearly. The interpolation error is measured, not assumed: ``validate``
compares the emulator with the model at seeded Latin-hypercube points. The posterior adds
that error's RMS to the noise variance, so a coarse emulator widens intervals rather than
biasing them. Emulators also serve the fit and the predictive bands at the same inputs.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from growjax.model import params as gp
from growjax.simulation.simulate import sample_times, simulate
from growjax.simulation.trajectory import OK

__all__ = ["Axis", "Emulator", "build", "model_lengths", "pad_linear", "predicted_length", "validate"]


@dataclasses.dataclass(frozen=True)
class Axis:
    """One emulator axis: a parameter (qualified name), its box in SI units, node count and spacing."""

    name: str
    low: float
    high: float
    nodes: int
    log: bool = False

    def __post_init__(self):
        if not (np.isfinite(self.low) and np.isfinite(self.high) and self.high > self.low):
            raise ValueError(f"emulator axis {self.name}: need finite low < high, got [{self.low}, {self.high}]")
        if self.nodes < 2:
            raise ValueError(f"emulator axis {self.name}: need at least 2 nodes, got {self.nodes}")
        if self.log and self.low <= 0:
            raise ValueError(f"emulator axis {self.name}: a log axis needs low > 0, got {self.low}")

    def points(self) -> np.ndarray:
        """Node values, SI, shape (nodes,)."""
        if self.log:
            return np.exp(np.linspace(np.log(self.low), np.log(self.high), self.nodes))
        return np.linspace(self.low, self.high, self.nodes)


class Emulator(eqx.Module):
    """Interpolant of the model length (m) at ``times`` over a box of parameters.

    Attributes:
        values: (n_1 + 2, …, n_d + 2, m) lengths at the nodes, m, with one linear ghost node per side.
        times: (m,) s.
        lows, highs: (d,) box in the axis coordinate (θ, or ln θ on a log axis).
        error_rms, error_max: validation error against the model, m (NaN before :func:`validate`).
        names: qualified parameter names (static).  log: per-axis log flags (static).
        base, inputs, config: the model it stands for (static config; arrays as leaves).
    """

    values: jax.Array
    times: jax.Array
    lows: jax.Array
    highs: jax.Array
    error_rms: jax.Array
    error_max: jax.Array
    base: gp.Parameters
    inputs: object
    names: tuple = eqx.field(static=True)
    log: tuple = eqx.field(static=True)
    nodes: tuple = eqx.field(static=True)
    config: object = eqx.field(static=True)

    def inside(self, theta) -> jax.Array:
        """True where θ (..., d) lies in the box."""
        u = _coordinate(jnp.asarray(theta), self.log)
        return jnp.all((u >= self.lows) & (u <= self.highs), axis=-1)

    def __call__(self, theta) -> jax.Array:
        """Length (m), shape (m,), at parameters θ (d,) in SI units; NaN outside the box."""
        theta = jnp.asarray(theta)
        u = _coordinate(theta, self.log)
        s = (u - self.lows) / (self.highs - self.lows) * (jnp.asarray(self.nodes) - 1.0)
        cell = jnp.clip(jnp.floor(s), 0.0, jnp.asarray(self.nodes) - 2.0)
        frac = s - cell
        block = jax.lax.dynamic_slice(
            self.values, tuple(cell.astype(int)) + (0,), (4,) * len(self.nodes) + (self.values.shape[-1],)
        )
        for k in range(len(self.nodes)):
            block = jnp.tensordot(_catmull_rom_weights(frac[k]), block, axes=(0, 0))
        return jnp.where(self.inside(theta), block, jnp.nan)


def _coordinate(theta, log):
    return jnp.where(jnp.asarray(log), jnp.log(jnp.where(jnp.asarray(log), theta, 1.0)), theta)


def _catmull_rom_weights(f):
    """Weights (4,) of nodes i−1, i, i+1, i+2 at fraction f ∈ [0, 1] of cell [i, i+1] (C¹, exact for cubics' chords)."""
    f2, f3 = f * f, f * f * f
    return 0.5 * jnp.stack([-f3 + 2 * f2 - f, 3 * f3 - 5 * f2 + 2, -3 * f3 + 4 * f2 + f, f3 - f2])


def pad_linear(values: np.ndarray, n_axes: int) -> np.ndarray:
    """A table of lengths at the nodes with one ghost node per side along each axis, extrapolated linearly from
    the two nodes nearest that side: the `Emulator`'s ``values``.

    Args:
        values: (n_1, …, n_d, m) lengths at the nodes, m (``n_axes`` = d leading axes, the times last).
        n_axes: d, the number of parameter axes.

    Returns:
        (n_1 + 2, …, n_d + 2, m) lengths, m.
    """
    for ax in range(n_axes):
        lo = 2 * np.take(values, [0], axis=ax) - np.take(values, [1], axis=ax)
        hi = 2 * np.take(values, [-1], axis=ax) - np.take(values, [-2], axis=ax)
        values = np.concatenate([lo, values, hi], axis=ax)
    return values


def predicted_length(theta: dict, base, inputs, config, times):
    """Model length (m) at ``times`` for parameter values ``theta`` {qualified name: value}; NaN if the run failed."""
    p = gp.replace(base, **theta)
    traj = simulate(p, inputs, config, ts=sample_times(times, config))
    return jnp.where(traj.status == OK, traj.length, jnp.nan)


def model_lengths(thetas, names: Sequence[str], base, inputs, config, times, chunk: int = 512):
    """Model length (m) at ``times`` for each row of ``thetas`` (N, d), shape (N, m); NaN rows for failed runs."""
    names = tuple(names)
    times = jnp.asarray(times)

    @jax.jit
    def batch(th):
        return jax.vmap(
            lambda row: predicted_length({n: row[i] for i, n in enumerate(names)}, base, inputs, config, times)
        )(th)

    thetas = np.asarray(thetas, float)
    out = []
    for start in range(0, thetas.shape[0], chunk):
        part = thetas[start : start + chunk]
        pad = chunk - part.shape[0] if thetas.shape[0] > chunk else 0
        rows = np.concatenate([part, np.repeat(part[-1:], pad, axis=0)]) if pad else part
        out.append(np.asarray(batch(jnp.asarray(rows)))[: part.shape[0]])
    return np.concatenate(out)


def build(axes: Sequence[Axis], base, inputs, config, times, chunk: int = 512) -> Emulator:
    """Tabulate the model on the tensor grid of ``axes`` (one batched sweep) → :class:`Emulator` (unvalidated).

    Raises ValueError if any node's run failed: the table must be complete to interpolate it.
    """
    axes = tuple(axes)
    names = tuple(gp.resolve_name(base, a.name) for a in axes)
    grids = np.meshgrid(*[a.points() for a in axes], indexing="ij")
    thetas = np.stack([g.ravel() for g in grids], axis=1)
    lengths = model_lengths(thetas, names, base, inputs, config, times, chunk)
    bad = ~np.all(np.isfinite(lengths), axis=1)
    if np.any(bad):
        raise ValueError(
            f"{int(bad.sum())} of {bad.size} emulator nodes failed to simulate, e.g. at "
            f"{dict(zip(names, thetas[np.argmax(bad)]))}: shrink the box"
        )
    values = lengths.reshape(*[a.nodes for a in axes], -1)
    lows = [np.log(a.low) if a.log else a.low for a in axes]
    highs = [np.log(a.high) if a.log else a.high for a in axes]
    return Emulator(
        values=jnp.asarray(pad_linear(values, len(axes))),
        times=jnp.asarray(times),
        lows=jnp.asarray(lows),
        highs=jnp.asarray(highs),
        error_rms=jnp.asarray(np.nan),
        error_max=jnp.asarray(np.nan),
        base=base,
        inputs=inputs,
        names=names,
        log=tuple(a.log for a in axes),
        nodes=tuple(a.nodes for a in axes),
        config=config,
    )


def validate(emulator: Emulator, n_points: int = 64, seed: int = 0) -> Emulator:
    """Emulator with ``error_rms`` and ``error_max`` (m) measured against the model at seeded LHS points in its box."""
    from scipy.stats import qmc

    d = len(emulator.names)
    unit = qmc.LatinHypercube(d=d, seed=seed).random(n_points)
    u = np.asarray(emulator.lows) + unit * (np.asarray(emulator.highs) - np.asarray(emulator.lows))
    log = np.asarray(emulator.log)
    thetas = np.where(log, np.exp(np.where(log, u, 0.0)), u)
    exact = model_lengths(thetas, emulator.names, emulator.base, emulator.inputs, emulator.config, emulator.times)
    approx = np.asarray(jax.jit(jax.vmap(emulator))(jnp.asarray(thetas)))
    err = (approx - exact)[np.all(np.isfinite(exact), axis=1)]
    return dataclasses.replace(
        emulator,
        error_rms=jnp.asarray(float(np.sqrt(np.mean(err**2)))),
        error_max=jnp.asarray(float(np.max(np.abs(err)))),
    )
