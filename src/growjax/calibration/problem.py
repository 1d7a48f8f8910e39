"""One run's least-squares problem: the model, its inputs and the (windowed) measurements, and the coordinates
its free parameters are moved in.

A parameter that must stay positive is moved in z = ln(θ/θ_ref), so every direction is O(1) and positivity holds;
a *signed* one, whose physical range allows negative values (an effect's offset, such as the ``trapped_air``
effect's extra air fraction), in the linear coordinate z = (θ − θ_ref)/s, s the largest magnitude of its range.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import growjax.calibration.tolerance as tl
from growjax.calibration.least_squares import linearise
from growjax.data.experiment import informative_samples
from growjax.model import params as gp
from growjax.simulation.simulate import as_arrays, input_breaks, sample_times, simulate
from growjax.simulation.trajectory import OK


def signed_scale(base: gp.Parameters, name: str) -> float | None:
    """The scale s, SI, of the linear coordinate of a parameter whose physical range allows negative values (the
    largest magnitude of the range), or None for a parameter moved in ln θ."""
    ranges = gp.physical_ranges(base)
    if name not in ranges or not ranges[name][0] < 0:
        return None
    lo, hi = ranges[name][:2]
    return float(max(abs(lo), abs(hi)))


def coordinate_scales(base: gp.Parameters, names) -> np.ndarray:
    """(p,) the scale of each parameter's linear coordinate, NaN for those moved in ln θ."""
    return np.array([np.nan if (s := signed_scale(base, n)) is None else s for n in names], float)


def to_values(z, refs, scales):
    """θ (p,) SI at the coordinates z (p,): θ_ref + s·z where the scale s is finite, θ_ref·exp(z) elsewhere
    (NumPy or JAX arrays alike)."""
    xp = jnp if any(isinstance(a, jax.Array) for a in (z, refs, scales)) else np
    refs, scales = xp.asarray(refs), xp.asarray(scales)
    signed = xp.isfinite(scales)
    linear = refs + xp.where(signed, scales, 0.0) * z
    return xp.where(signed, linear, refs * xp.exp(xp.where(signed, 0.0, z)))


def to_coordinates(values, refs, scales) -> np.ndarray:
    """z (…, p) of the values θ (…, p) SI: (θ − θ_ref)/s where the scale s is finite, ln(θ/θ_ref) elsewhere."""
    values, refs, scales = (np.asarray(a, float) for a in (values, refs, scales))
    signed = np.isfinite(scales)
    with np.errstate(divide="ignore", invalid="ignore"):
        linear = (values - refs) / np.where(signed, scales, 1.0)
    return np.where(signed, linear, np.asarray(jnp.log(jnp.asarray(values) / refs)))  # the fit's log, as XLA takes it


def physical_bounds(base: gp.Parameters, names, refs) -> tuple[np.ndarray, np.ndarray]:
    """(lower (p,), upper (p,)) of the coordinates z of the parameters ``names`` about ``refs`` (p,) SI, from each
    parameter's physical range (±inf where it has none): ln(a/θ_ref), or (a − θ_ref)/s for a signed one."""
    ranges = gp.physical_ranges(base)
    lo = np.full(len(names), -np.inf)
    hi = np.full(len(names), np.inf)
    for i, n in enumerate(names):
        if n not in ranges:
            continue
        a, b = ranges[n][:2]
        s = signed_scale(base, n)
        if s is not None:
            lo[i], hi[i] = (a - refs[i]) / s, (b - refs[i]) / s if np.isfinite(b) else np.inf
        else:
            lo[i] = np.log(a / refs[i]) if a > 0 else -np.inf
            hi[i] = np.log(b / refs[i]) if np.isfinite(b) else np.inf
    return lo, hi


class Problem(eqx.Module):
    """A least-squares problem as data: the model, its inputs and the (windowed) measurements.

    Arrays are leaves, so one compiled program serves every call with the same shapes.
    """

    base: gp.Parameters
    inputs: object
    refs: jax.Array  # (p,) reference values of the free parameters, SI
    scales: jax.Array  # (p,) scale of each linear coordinate, SI; NaN where the parameter moves in ln θ
    times: jax.Array  # (m,) s
    length: jax.Array  # (m,) m
    pressure: jax.Array | None  # (m,) Pa or None
    breaks: tuple  # (jump times, slope-break times) of the inputs, s
    names: tuple = eqx.field(static=True)
    config: object = eqx.field(static=True)
    sigma_length: jax.Array  # () m, the length's scale (a leaf: one compiled program serves every scale)
    sigma_pressure: jax.Array  # () Pa
    pressure_weight: jax.Array | None = None  # (m,) 1 where a pressure sample is scored, 0 where it repeats others

    def residuals(self, z, args=None):
        """Non-dimensional residuals r(z), shape (m,) or (2m,), at the coordinates z (p,)."""
        return _residuals(z, self)

    def simulated(self, z):
        """(residuals (m,) or (2m,), whether the run succeeded ()): the residuals NaN where it did not."""
        traj = self._run(z)
        return self._scaled(traj), traj.status == OK

    def _run(self, z):
        theta = to_values(z, self.refs, self.scales)
        p = gp.replace(self.base, **{n: theta[i] for i, n in enumerate(self.names)})
        return simulate(p, self.inputs, self.config, ts=sample_times(self.times, self.config), breaks=self.breaks)

    def _scaled(self, traj):
        r = (traj.length - self.length) / self.sigma_length
        if self.pressure is not None:
            weight = 1.0 if self.pressure_weight is None else self.pressure_weight
            r = jnp.concatenate([r, weight * (traj.pressure - self.pressure) / self.sigma_pressure])
        return r

    def _residuals(self, z):
        r = self._scaled(self._run(z))
        return jnp.where(jnp.isfinite(r), r, 1e3)  # a failed run is a very bad fit, not a crash


@eqx.filter_jit
def _residuals(z, problem: Problem):
    # A jitted leaf: the solver's traces (step, Jacobian, vmap) reuse one traced simulation.
    return problem._residuals(z)


def make_problem(
    base,
    names,
    inputs,
    config,
    times,
    length,
    pressure=None,
    window=None,
    sigma_length=1e-3,
    sigma_pressure=5e3,
    thin_pressure: bool = False,
) -> Problem:
    """The `Problem` for the parameters ``names`` on the data inside ``window`` (t_start, t_end) s (default: the
    configuration's span); ``times`` (m,) s, ``length`` (m,) m, ``pressure`` (m,) Pa or None. ``thin_pressure``:
    a pressure record interpolated between keyframes is scored at its keyframes alone
    (`growjax.data.experiment.informative_samples`), so that resampling it does not change its information."""
    names = tuple(gp.resolve_name(base, n) for n in names)
    config = config.replace(adjoint="forward")
    refs = jnp.asarray([float(gp.get(base, n)) for n in names])
    t0, t1 = window if window is not None else (config.t0, config.t1)
    keep = (np.asarray(times) >= t0) & (np.asarray(times) <= t1)
    pick = lambda a: None if a is None else jnp.asarray(np.asarray(a)[keep])  # noqa: E731
    # Numbers as arrays: one compiled program serves every base (a tolerance's perturbed rig included).
    return Problem(
        as_arrays(base),
        inputs,
        refs,
        jnp.asarray(coordinate_scales(base, names)),
        pick(times),
        pick(length),
        pick(pressure),
        input_breaks(inputs, config),
        names,
        config,
        jnp.asarray(sigma_length, float),
        jnp.asarray(sigma_pressure, float),
        _pressure_weight(pick(pressure), thin_pressure),
    )


def _pressure_weight(pressure, thin: bool):
    """(m,) 1.0 at the pressure samples scored, 0.0 at those an interpolation fixed; None without a pressure."""
    if pressure is None:
        return None
    used = informative_samples(np.asarray(pressure)) if thin else np.ones(np.size(pressure), bool)
    return jnp.asarray(used, float)


@eqx.filter_jit
def linearised(z, problem: Problem):
    """`linearise` of the problem's residuals at z (p,): (r (m,), J (m, p)), one compiled program per problem's
    shapes."""
    return linearise(problem.residuals, z)


def problem_at_rig(problem: Problem, tol: dict, centre) -> Problem:
    """``problem`` with the toleranced parameters of ``tol`` at ψ₀·e^centre (``centre`` (q,) in their order)."""
    return eqx.tree_at(lambda pr: pr.base, problem, tl.rig_at(problem.base, list(tol), centre))


def check_window(window, config):
    """(t_start, t_end) s inside the configuration's span, or None.

    Raises:
        ValueError: naming the problem.
    """
    if window is None:
        return None
    t0, t1 = (float(w) for w in window)
    if not (np.isfinite(t0) and np.isfinite(t1)) or t0 >= t1:
        raise ValueError(f"window must be (t_start, t_end) with t_start < t_end, got {window}")
    if t1 < config.t0 or t0 > config.t1:
        raise ValueError(f"window {window} s lies outside the simulated span [{config.t0}, {config.t1}] s")
    return t0, t1


__all__ = [
    "Problem",
    "check_window",
    "coordinate_scales",
    "linearised",
    "make_problem",
    "physical_bounds",
    "problem_at_rig",
    "signed_scale",
    "to_coordinates",
    "to_values",
]
