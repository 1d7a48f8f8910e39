"""The candidate fits: the superset model as one least-squares problem per candidate, its linearisation
and fits, and their estimates."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

from growjax.calibration import LM_TOLERANCE, levenberg_marquardt, physical_bounds
from growjax.model import effects as fx
from growjax.model import params as gp
from growjax.simulation.config import Config
from growjax.simulation.simulate import input_breaks, simulate

Z90 = float(stats.norm.ppf(0.95))
START_FRACTIONS = (0.02, 0.06, 0.2)  # starts of a new effect parameter, as fractions of its range's top
BASE_START_FACTORS = (1.0, 0.7, 1.4)  # starts of the base fit: the given base parameters times these
ETA_FLOOR = 1e-3  # an unsigned effect's fits keep η ≥ this fraction of its range's top (below it, absent)
COST_NOISE = 1e-4  # relative noise of a fit's cost through the adaptive solver's steps (measured: 1–2e-4)


def candidate_parameter(name: str) -> tuple[str, str, tuple[float, float]]:
    """(qualified parameter name ``effect.field``, unit, physical range) of the catalogue effect ``name``."""
    if name not in fx.CATALOGUE:
        raise ValueError(f"unknown effect {name!r}; the catalogue has {sorted(fx.CATALOGUE)}")
    cls = fx.CATALOGUE[name]
    ((field, rng),) = cls.ranges.items()
    return f"{name}.{field}", cls.units.get(field, ""), tuple(map(float, rng))


class Candidates(eqx.Module):
    """The superset model and the data: one least-squares problem per candidate, the candidate given as data.

    The superset carries every candidate effect (K of them); at zero they are the base model exactly.
    A model is (``mask`` (K,): which effects are on; ``select`` (p + K, q): which coordinates move).
    The full coordinate vector is z = (ln(θ_base/θ_ref) (p,), u (K,)), z = z_fixed + select·w with w (q,)
    the fitted coordinates, so every candidate has the same shapes and runs through one program.
    """

    base: gp.Parameters
    inputs: object
    refs: jax.Array  # (p,) SI
    scales: jax.Array  # (K,) s
    signed: jax.Array  # (K,) bool: η = s·u instead of s·softplus(u)
    times: jax.Array  # (m,) s
    length: jax.Array  # (m,) m
    breaks: tuple
    base_names: tuple = eqx.field(static=True)
    effect_names: tuple = eqx.field(static=True)
    config: Config = eqx.field(static=True)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) (p + K,) of z: the base parameters' physical ranges in ln(θ/θ_ref) and each effect's
        range in u, so no fit leaves the range a candidate is defined on (a wrong candidate drifting beyond its
        range is both unphysical and where the model turns stiff and its runs slow). An unsigned effect's η stays
        above :data:`ETA_FLOOR` of its top, a size no measurement here tells from 0 (a thousandth of the range; the
        moderate sizes of the tests are 2–30 % of it): nearer 0 a fit only drifts along softplus's flat end, and a
        lag of microseconds makes the model stiff, its linearisations several times slower and its Jacobian poor."""
        lo_base, hi_base = physical_bounds(self.base, self.base_names, np.asarray(self.refs))
        lo_eff, hi_eff = [], []
        for name, s, signed in zip(self.effect_names, np.asarray(self.scales), np.asarray(self.signed)):
            lo, hi = candidate_parameter(name.split(".")[0])[2]
            if signed:  # η = s·u
                lo_eff.append(lo / s)
                hi_eff.append(hi / s)
            else:  # η = s·softplus(u), kept above ETA_FLOOR of the range's top (u → -∞ would be η = 0)
                lo_eff.append(math.log(math.expm1(ETA_FLOOR * hi / s)))
                hi_eff.append(math.log(math.expm1(hi / s)))
        return np.concatenate([lo_base, lo_eff]), np.concatenate([hi_base, hi_eff])

    def effect_value_and_slope(self, k: int, u: float) -> tuple[float, float]:
        """(η (SI), dη/du) of effect ``k`` at its coordinate u (host floats)."""
        s, signed = float(self.scales[k]), bool(self.signed[k])
        if signed:
            return s * u, s
        return s * float(jax.nn.softplus(u)), s * float(jax.nn.sigmoid(u))

    def effect_values(self, u, mask):
        """η (K,) in SI from u (K,) under the candidate ``mask`` (K,)."""
        eta = self.scales * jnp.where(self.signed, u, jax.nn.softplus(u))
        return jnp.where(mask > 0, eta, 0.0)

    def parameters(self, z, mask):
        p = len(self.base_names)
        theta = self.refs * jnp.exp(z[:p])
        eta = self.effect_values(z[p:], mask)
        values = {n: theta[i] for i, n in enumerate(self.base_names)}
        values.update({n: eta[k] for k, n in enumerate(self.effect_names)})
        return gp.replace(self.base, **values)

    def model_length(self, z, mask):
        """(length (m,) m, pressure (m,) Pa) of the model at coordinates z (p + K,)."""
        traj = simulate(self.parameters(z, mask), self.inputs, self.config, ts=self.times, breaks=self.breaks)
        return traj.length, traj.pressure

    def residuals(self, w, model):
        """(residuals (m,) in units of 1 mm, model pressure (m,) Pa) at the fitted coordinates w (q,) of
        ``model`` = (mask, select, z_fixed)."""
        mask, select, z_fixed = model
        length, pressure = self.model_length(z_fixed + select @ w, mask)
        r = (length - self.length) / 1e-3
        return jnp.where(jnp.isfinite(r), r, 1e3), pressure  # a failed run is a very bad fit, not a crash


@eqx.filter_jit
def linearised(w, problem: Candidates, mask, select, z_fixed):
    """One model's residuals, Jacobian and pressure at its fitted coordinates, in one forward-mode pass (as
    `growjax.calibration.linearise`).

    The candidate is data (``mask``, ``select``, ``z_fixed``), so one compiled program serves every fit with the
    same q: q = p + 1 for the base fit, the first round and the base-held fits, p + 2 for the second round (each
    tangent direction costs a share of a linearisation, so a fit carries only as many as it can move).

    Args:
        w: the fitted coordinates (q,).
        problem: the `Candidates` problem.
        mask: (K,) which candidate effects are on.
        select: (p + K, q) 0/1, the coordinate of z each coordinate of w moves.
        z_fixed: (p + K,) the coordinates held.

    Returns:
        (residuals r (m,) in units of 1 mm, Jacobian J (m, q), the model's pressure (m,) Pa).
    """
    units = jnp.eye(w.shape[0], dtype=w.dtype)
    (r, pressure), (jac_t, _) = jax.vmap(
        lambda v: jax.jvp(lambda x: problem.residuals(x, (mask, select, z_fixed)), (w,), (v,)),
        out_axes=((None, None), 0),
    )(units)
    return r, jac_t.T, pressure


def fit_model(problem: Candidates, w0, mask, select, z_fixed, max_steps: int, resolution: float = 0.0):
    """Levenberg–Marquardt for one model (`growjax.calibration.levenberg_marquardt` around `linearised`), each
    fitted coordinate kept in its physical range (`Candidates.bounds`).

    Args:
        problem, mask, select, z_fixed: the problem and the model, as `linearised` takes them.
        w0: the start (q,).
        max_steps: the most steps.
        resolution: the cost's resolution (mm², absolute) below which steps stop counting; also `COST_NOISE` of
            the cost itself when positive.

    Returns:
        (z (p + K,), residuals (m,) mm, Jacobian (m, q), converged, pressure (m,) Pa at the optimum, the number
        of linearisations run).
    """
    pressures, runs = {}, 0
    lo, hi = problem.bounds()
    sel = np.asarray(select)
    used = sel.sum(axis=0) > 0  # a coordinate of w that moves no coordinate of z has no bound (zero Jacobian column)
    row = sel.argmax(axis=0)  # the coordinate of z each coordinate of w moves (select is a 0/1 selection)
    w_bounds = (np.where(used, lo[row], -np.inf), np.where(used, hi[row], np.inf))

    def evaluate(x):
        nonlocal runs
        r, jac, pressure = linearised(x, problem, mask, select, z_fixed)
        pressures[np.asarray(x).tobytes()] = pressure
        runs += 1
        return r, jac

    w, _, ok, r, jac = levenberg_marquardt(
        evaluate,
        w0,
        max_steps,
        LM_TOLERANCE,
        bounds=w_bounds,
        cost_resolution=resolution,
        relative_resolution=COST_NOISE if resolution > 0.0 else 0.0,
    )
    pressure = pressures.get(np.asarray(jnp.asarray(w)).tobytes())
    if pressure is None:  # not expected: the optimum is always an evaluated point
        pressure = linearised(jnp.asarray(w), problem, mask, select, z_fixed)[2]
        runs += 1
    return np.asarray(z_fixed) + np.asarray(select) @ w, r, jac, ok, np.asarray(pressure), runs


def make_candidates(
    times, length, inputs, effect_names: Sequence[str], base: gp.Parameters, base_names: Sequence[str], config: Config
) -> Candidates:
    """The :class:`Candidates` problem on the data (times (m,) s, length (m,) m)."""
    superset = gp.with_effects(base, *[fx.CATALOGUE[n]() for n in effect_names])
    base_names = tuple(gp.resolve_name(superset, n) for n in base_names)
    qualified = tuple(candidate_parameter(n)[0] for n in effect_names)
    ranges = [candidate_parameter(n)[2] for n in effect_names]
    refs = jnp.asarray([float(gp.get(superset, n)) for n in base_names])
    if np.any(np.asarray(refs) <= 0):
        raise ValueError(f"base parameters must be positive to be fitted in log coordinates: {base_names}")
    scales = jnp.asarray([0.1 * hi for lo, hi in ranges])
    signed = jnp.asarray([lo < 0 for lo, hi in ranges])
    config = config.replace(adjoint="forward")
    return Candidates(
        superset,
        inputs,
        refs,
        scales,
        signed,
        jnp.asarray(times, float),
        jnp.asarray(length, float),
        input_breaks(inputs, config),
        base_names,
        qualified,
        config,
    )


@dataclasses.dataclass
class CandidateFit:
    """One fitted model: the effects on, its estimates and 90 % intervals (SI), correlations, residuals."""

    effects: tuple
    estimate: dict
    interval_90: dict
    correlation: dict  # effect parameter → {base parameter: correlation}
    rss_mm2: float
    residual_m: np.ndarray
    converged: bool
    z: np.ndarray
    mask: np.ndarray
    jacobian: np.ndarray | None = None  # (n, k) mm per unit of each fitted coordinate
    slopes: np.ndarray | None = None  # (k,) each parameter's change (SI) per unit of its coordinate
    log_coordinate: np.ndarray | None = None  # (k,) bool: the coordinate is ln(θ/θ_ref)
    ranges: tuple = ()  # (k,) (low, high) SI of each parameter


def _summarise(problem: Candidates, z, r, jac, mask, select, sigma_m, converged, effects) -> CandidateFit:
    """Estimates, delta-method intervals and correlations of one fit at noise ``sigma_m`` (m) (independent noise:
    what the rounds' confounding test reads; the final model's reported intervals are the shared likelihood's,
    :func:`growjax.discover._scoring.shared_intervals`)."""
    z, r, jac, select = np.asarray(z), np.asarray(r), np.asarray(jac), np.asarray(select)
    p = len(problem.base_names)
    moved = np.flatnonzero(select.sum(axis=1) > 0)  # coordinates of z that were fitted
    j = jac @ np.linalg.pinv(select[moved])  # d r / d z_moved (select is a 0/1 selection)
    sigma = sigma_m / 1e-3
    cov_free = sigma**2 * np.linalg.pinv(j.T @ j, rcond=1e-12, hermitian=True)
    refs = np.asarray(problem.refs)
    names, values, derivs, ranges = [], [], [], []
    for i in moved:
        if i < p:
            names.append(problem.base_names[i])
            values.append(refs[i] * math.exp(z[i]))
            derivs.append(values[-1])  # dθ/dz
            ranges.append((0.0, math.inf))
        else:
            k, u = i - p, z[i]
            names.append(problem.effect_names[k])
            value, slope = problem.effect_value_and_slope(k, u)
            values.append(value)
            derivs.append(slope)
            ranges.append(candidate_parameter(problem.effect_names[k].split(".")[0])[2])
    d = np.asarray(derivs)
    cov = cov_free * np.outer(d, d)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    estimate = dict(zip(names, map(float, values)))
    interval = {
        n: (float(max(values[i] - Z90 * sd[i], ranges[i][0])), float(min(values[i] + Z90 * sd[i], ranges[i][1])))
        for i, n in enumerate(names)
    }
    corr = {
        n: {b: float(cov[i, jb] / max(sd[i] * sd[jb], 1e-300)) for jb, b in enumerate(names) if b in problem.base_names}
        for i, n in enumerate(names)
        if n not in problem.base_names
    }
    return CandidateFit(
        effects,
        estimate,
        interval,
        corr,
        float(np.sum(r**2)),
        r * 1e-3,
        bool(converged),
        z,
        np.asarray(mask),
        j,
        d,
        np.arange(len(names)) < sum(i < p for i in moved),
        tuple(ranges),
    )


def _held_start(problem: Candidates, joint, k: int, u_floor: float) -> float:
    """u of candidate ``k`` with the base parameters back at their given values (z_base = 0), from its joint fit
    ``joint`` (as :meth:`Fitter.batch` returns it): the Gauss–Newton step in η alone that takes over the base shift,
    η_held = η + (J_ηᵀJ_B z_B)/(J_ηᵀJ_η), clipped to the effect's range (and for an unsigned effect to at least
    its first start ``u_floor``: near η = 0 softplus has no slope to climb)."""
    z, _, jac, _, _, _ = joint
    p = len(problem.base_names)
    u, s, signed = float(z[p + k]), float(problem.scales[k]), bool(problem.signed[k])
    eta, deta_du = problem.effect_value_and_slope(k, u)
    j_eta = np.asarray(jac)[:, p] / max(deta_du, 1e-300)  # the candidate is the first effect column of w
    curvature = float(j_eta @ j_eta)
    if curvature > 0.0 and np.isfinite(curvature):
        eta += float(j_eta @ (np.asarray(jac)[:, :p] @ np.asarray(z[:p]))) / curvature
    lo, hi = candidate_parameter(problem.effect_names[k].split(".")[0])[2]
    eta = float(np.clip(eta, lo, hi))
    if signed:
        return eta / s
    x = max(eta / s, 1e-12)
    return max(math.log(math.expm1(x)), u_floor)
