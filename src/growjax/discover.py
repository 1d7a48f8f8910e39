"""Missing physics: where model and measurement disagree, which catalogue effect explains it, and how sure.

The workflow (:func:`discover`), on a measured length L(t):

1. **Base fit.** The base model's free parameters (default the yield pressure Y) are fitted by
   least squares, in the *superset* model that carries every candidate effect at zero (which is
   the base model exactly), so every later fit runs through the same compiled program (one per number of fitted
   coordinates). It starts from the
   given values and from 0.7 and 1.4 times them (real data can leave more than one minimum in Y), keeping
   the best, so that no candidate scores against a base stuck in a side minimum.
2. **Locate.** The residuals r = L_model − L_meas are summarised over time and by phase (growing,
   holding, retracting; pressure rising or falling) (:func:`locate`). The noise σ is estimated from
   successive differences of r (a smooth misfit barely enters them), and the misfit test asks whether
   the residuals carry more than that noise: a lag-1 autocorrelation z-score and the ratio RMSE/σ.
3. **Test each candidate.** Each effect parameter η is fitted jointly with the base parameters, starting from
   the base fit's values and from several starts of η (2, 6 and 20 % of its range's top; the misfit can have
   more than one minimum along an effect, e.g. one per alignment of a lag with the pulse period), keeping the
   best fit.
   Its score is the likelihood ratio 2ΔlogL = (RSS_base − RSS_k)/σ² of the nested models; under
   the null (effect absent, η on the boundary 0) it is distributed as ½χ²₀ + ½χ²₁, and the
   threshold is set so that the *family* of K candidates gives a false positive with probability
   ``false_positive_rate`` (Bonferroni). A Laplace estimate of the log Bayes factor against a uniform
   prior on the effect's physical range is reported beside it (``log_bayes_factor``).
4. **Confounding.** A candidate whose η correlates with a base parameter beyond
   ``confounding_correlation`` (0.99: the base parameter inflates its variance 50-fold) in the joint fit is
   reported ``confounded`` with that parameter if it clears the threshold, or if, with the base parameters
   held at their given values, it alone explains the data as well as refitting them does (within the
   threshold) while the given values themselves fit significantly worse: the effect and the base parameter
   trade one for the other. "Significantly" here allows for the fitted configuration's own error e against
   the reference (``model_error``): absorbed by a base shift it alone lowers the sum of squares by up to m·e²,
   so the effect must improve on the given values by more than the threshold plus m·e²/σ² (m samples; on
   clean reference-made data, 10 s at σ = 0.2 mm, the given Y fits worse by 2ΔlogL ≈ 9 through that error
   alone). Each base-held fit starts where its joint fit's linearisation puts the effect once the base
   parameters return to their given values (the effect taking over the base shift along their shared valley:
   :func:`_held_start`). A correlated candidate that clears the threshold with its magnitude *pinned*
   (its 90 % interval, the correlation's inflation included, within a factor ``PINNED_FACTOR`` of the
   estimate) is not confounded: refitting the base did not absorb it, and the data fix its size. Its
   correlation is still reported.
5. **Rivals.** When another candidate also clears the threshold and its 2ΔlogL falls short of the best's by
   less than the threshold, the data do not tell the two effects apart: neither is added, both are reported
   ``confounded`` (``rival_effects``), with the measurements that would separate them.
6. **Add and iterate.** The best candidate is added; the remaining ones are tested again on top of it
   (up to ``max_effects``). An effect is claimed only if, once added, the misfit test passes; if
   structure remains that no candidate removes, the answer is ``unexplained``; with no misfit and no
   candidate over the threshold, ``none``.

Effect parameters are moved in u with η = s·softplus(u) (η ≥ 0) or η = s·u for effects whose range
allows both signs; s is a tenth of the range's upper end. Every fit is bounded to the physical ranges
(η to its effect's, above a thousandth of its top, ``ETA_FLOOR``; the base parameters to theirs): a wrong candidate that would climb past its range to
absorb a misfit stops at the edge (``at_range_edge`` in the evidence), where its runs are also the slowest.
Intervals on η are Gauss–Newton (delta method) at σ, clipped to the physical range. A fit stops once its
steps no longer move 2ΔlogL by ``LR_RESOLUTION`` (σ estimated from the data's second differences) nor its
cost by ``COST_NOISE`` of itself, the fast configuration's own noise: below that its trial points only wander
(:func:`growjax.fit.levenberg_marquardt`).
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import itertools
import math
import os
import time
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

from growjax import discrepancy as dc
from growjax import effects as fx
from growjax import experiment
from growjax import params as gp
from growjax.config import Config
from growjax.fit import (
    LM_TOLERANCE,
    default_model_error,
    levenberg_marquardt,
    physical_bounds,
)
from growjax.simulate import input_breaks, simulate

Z90 = float(stats.norm.ppf(0.95))
START_FRACTIONS = (0.02, 0.06, 0.2)  # starts of a new effect parameter, as fractions of its range's top
BASE_START_FACTORS = (1.0, 0.7, 1.4)  # starts of the base fit: the given base parameters times these
PINNED_FACTOR = 2.0  # a correlated effect whose 90 % interval lies within [η/2, 2η] is determined, not confounded
PHASES = ("growing", "holding", "retracting", "pressure_rising", "pressure_falling")
ETA_FLOOR = 1e-3  # an unsigned effect's fits keep η ≥ this fraction of its range's top (below it, absent)
LR_RESOLUTION = 0.1  # 2ΔlogL below which a fit's progress no longer counts (the threshold is ~6)
COST_NOISE = 1e-4  # relative noise of a fit's cost through the adaptive solver's steps (measured: 1–2e-4)


def candidate_parameter(name: str) -> tuple[str, str, tuple[float, float]]:
    """(qualified parameter name ``effect.field``, unit, physical range) of the catalogue effect ``name``."""
    if name not in fx.CATALOGUE:
        raise ValueError(f"unknown effect {name!r}; the catalogue has {sorted(fx.CATALOGUE)}")
    cls = fx.CATALOGUE[name]
    (field, rng), = cls.ranges.items()
    return f"{name}.{field}", cls.units.get(field, ""), tuple(map(float, rng))


# -- residuals: noise, misfit, phases --------------------------------------------------------------------


def noise_from_differences(residual) -> float:
    """White-noise σ (m) of a residual series from its successive differences: var(Δr)/2 (von Neumann)."""
    d = np.diff(np.asarray(residual, float))
    return float(np.sqrt(np.mean(d**2) / 2.0))


def misfit_test(residual, sigma: float, z_limit: float = 4.0, ratio_limit: float = 1.2) -> dict:
    """Whether the residuals (m) carry structure beyond white noise of scale ``sigma`` (m).

    Two statistics: the lag-1 autocorrelation ρ̂ (its z-score ρ̂·√m is N(0, 1) for white noise) and
    the ratio RMSE/σ (≈ 1 for white noise). Structured if z > ``z_limit`` or the ratio > ``ratio_limit``.
    """
    r = np.asarray(residual, float)
    m = r.size
    c = r - r.mean()
    rho = float(np.sum(c[1:] * c[:-1]) / max(np.sum(c * c), 1e-300))
    z = rho * math.sqrt(m)
    rmse = float(np.sqrt(np.mean(r**2)))
    ratio = rmse / sigma if sigma > 0 else math.inf
    return {"rmse_m": rmse, "noise_sigma_m": float(sigma), "rmse_over_noise": ratio, "lag1_autocorrelation": rho,
            "autocorrelation_z": z, "structured": bool(z > z_limit or ratio > ratio_limit)}


def phases(times, length, pressure, rate_tol: float = 2e-4) -> dict[str, np.ndarray]:
    """Boolean masks (m,) of the phases of a simulated run: growing / holding / retracting by the
    length rate against ``rate_tol`` (m/s), pressure rising / falling by the sign of dP/dt."""
    t = np.asarray(times, float)
    v = np.gradient(np.asarray(length, float), t)
    dp = np.gradient(np.asarray(pressure, float), t)
    return {"growing": v > rate_tol, "holding": np.abs(v) <= rate_tol, "retracting": v < -rate_tol,
            "pressure_rising": dp > 0, "pressure_falling": dp < 0}


def locate(times, residual, length, pressure) -> dict:
    """Where the misfit lives: RMSE and mean residual (m) per phase, and per second of the run."""
    r = np.asarray(residual, float)
    t = np.asarray(times, float)
    out = {}
    for name, mask in phases(t, length, pressure).items():
        n = int(mask.sum())
        out[name] = {"share_of_time": n / r.size,
                     "rmse_m": float(np.sqrt(np.mean(r[mask] ** 2))) if n else None,
                     "mean_m": float(np.mean(r[mask])) if n else None}
    edges = np.arange(math.floor(t[0]), math.ceil(t[-1]) + 1.0)
    by_second = []
    for a, b in itertools.pairwise(edges):
        mask = (t >= a) & (t < b)
        if mask.any():
            by_second.append({"t0_s": float(a), "t1_s": float(b), "rmse_m": float(np.sqrt(np.mean(r[mask] ** 2))),
                              "mean_m": float(np.mean(r[mask]))})
    return {"by_phase": out, "by_second": by_second}


# -- the candidate fits: one compiled program over candidates ---------------------------------------------


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
def _linearised(w, problem: Candidates, mask, select, z_fixed):
    """Residuals r (m,), Jacobian J (m, q) and the model's pressure (m,) Pa of one model at its fitted
    coordinates w (q,), in one forward-mode pass (as :func:`growjax.fit.linearise`). The candidate is data
    (``mask``, ``select``, ``z_fixed``), so one compiled program serves every fit with the same q: q = p + 1 for the
    base fit, the first round and the base-held fits, p + 2 for the second round (each tangent direction costs a
    share of a linearisation, so a fit carries only as many as it can move). The traces
    reported come from it too."""
    units = jnp.eye(w.shape[0], dtype=w.dtype)
    (r, pressure), (jac_t, _) = jax.vmap(lambda v: jax.jvp(lambda x: problem.residuals(x, (mask, select, z_fixed)),
                                                           (w,), (v,)),
                                         out_axes=((None, None), 0))(units)
    return r, jac_t.T, pressure


def _fit_model(problem: Candidates, w0, mask, select, z_fixed, max_steps: int, resolution: float = 0.0):
    """Levenberg–Marquardt for one model (:func:`growjax.fit.levenberg_marquardt` around :func:`_linearised`),
    each fitted coordinate kept in its physical range (:meth:`Candidates.bounds`), stopping at the cost's
    ``resolution`` (mm², absolute) or :data:`COST_NOISE` of itself: (z (p + K,),
    residuals (m,), Jacobian (m, q), converged, pressure (m,) Pa at the optimum, linearisations run)."""
    pressures, runs = {}, 0
    lo, hi = problem.bounds()
    sel = np.asarray(select)
    used = sel.sum(axis=0) > 0  # a coordinate of w that moves no coordinate of z has no bound (zero Jacobian column)
    row = sel.argmax(axis=0)  # the coordinate of z each coordinate of w moves (select is a 0/1 selection)
    w_bounds = (np.where(used, lo[row], -np.inf), np.where(used, hi[row], np.inf))

    def linearised(x):
        nonlocal runs
        r, jac, pressure = _linearised(x, problem, mask, select, z_fixed)
        pressures[np.asarray(x).tobytes()] = pressure
        runs += 1
        return r, jac

    w, _, ok, r, jac = levenberg_marquardt(linearised, w0, max_steps, LM_TOLERANCE, bounds=w_bounds,
                                           cost_resolution=resolution,
                                           relative_resolution=COST_NOISE if resolution > 0.0 else 0.0)
    pressure = pressures.get(np.asarray(jnp.asarray(w)).tobytes())
    if pressure is None:  # not expected: the optimum is always an evaluated point
        pressure = _linearised(jnp.asarray(w), problem, mask, select, z_fixed)[2]
        runs += 1
    return np.asarray(z_fixed) + np.asarray(select) @ w, r, jac, ok, np.asarray(pressure), runs


def make_candidates(times, length, inputs, effect_names: Sequence[str], base: gp.Parameters,
                    base_names: Sequence[str], config: Config) -> Candidates:
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
    return Candidates(superset, inputs, refs, scales, signed, jnp.asarray(times, float), jnp.asarray(length, float),
                      input_breaks(inputs, config), base_names, qualified, config)


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


def _summarise(problem: Candidates, z, r, jac, mask, select, sigma_m, converged, effects) -> CandidateFit:
    """Estimates, delta-method intervals and correlations of one fit at noise ``sigma_m`` (m)."""
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
    interval = {n: (float(max(values[i] - Z90 * sd[i], ranges[i][0])), float(min(values[i] + Z90 * sd[i], ranges[i][1])))
                for i, n in enumerate(names)}
    corr = {n: {b: float(cov[i, jb] / max(sd[i] * sd[jb], 1e-300)) for jb, b in enumerate(names)
                if b in problem.base_names}
            for i, n in enumerate(names) if n not in problem.base_names}
    return CandidateFit(effects, estimate, interval, corr, float(np.sum(r**2)), r * 1e-3, bool(converged), z,
                        np.asarray(mask))


# -- the workflow ---------------------------------------------------------------------------------------


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


SEPARATING = {
    "active_channel_force": "the robot pressure during retraction, or a load cell on the active channel",
    "catheter_friction": "runs at two catheter insertion depths (the friction scales with the catheter length)",
    "lumen_friction": "growth in free air against growth in a duct phantom (the friction scales with the length)",
    "actuation_lag": "the syringe displacement or the line pressure at a step of the demand",
    "fluid_leak": "the pressure decay with the robot held at a fixed length",
    "trapped_air": "the line pressure at a step of the demand (its rise time scales with the compliance)",
    "growth_rate_limit": "growth at two pressure amplitudes (the cap shows as a speed that no longer rises)",
    "retraction_folding": "the length after a full retraction cycle, or the volume returned against the length lost",
}


MATERIAL_MISFIT = 5e-4  # m: a smooth misfit below this amplitude is left to the discrepancy term


class Scorer:
    """Likelihood-ratio scores and the misfit test under the fit's likelihood (:mod:`growjax.discrepancy`).

    ``discrepancy="matern32"``: a model's score is its log-likelihood with the residual model's
    hyperparameters at their mode for that model's residuals; the misfit is structured where the discrepancy
    is significant against white noise (2ΔlogL above the 1 % point of χ²₂) and larger than the noise, and
    material where its amplitude also exceeds ``material`` (m): only a material misfit that no candidate
    removes is reported ``unexplained``; a smaller one is left to the discrepancy term. ``"none"``: independent noise of sd ``sigma`` (m) and :func:`misfit_test`.
    A record interpolated between keyframes is scored at its keyframes.
    """

    def __init__(self, times, length, sigma: float, discrepancy: str, material: float = MATERIAL_MISFIT):
        self.times, self.sigma, self.kind, self.material = np.asarray(times, float), sigma, discrepancy, material
        self.observed = experiment.informative_samples(length) if discrepancy != "none" else None
        self._cache = {}

    def profile(self, residual, kind: str | None = None) -> tuple[float, dc.Hyper]:
        """(log-likelihood, nats, at the hyperparameters' mode for ``residual``; that mode)."""
        kind = kind or self.kind
        r = np.asarray(residual, float)
        key = (kind, r.tobytes())
        if key not in self._cache:
            hyper = dc.estimate(r, self.times, kind, observed=self.observed)
            value = dc.log_likelihood(r, self.times, hyper, observed=self.observed)
            self._cache[key] = (float(value), hyper)
        return self._cache[key]

    def noise(self, residual) -> float:
        return float(self.profile(residual)[1].noise)

    def lr(self, worse, better, signed: bool = False) -> float:
        """2ΔlogL of the model with residuals ``better`` (m) over the one with ``worse`` (≥ 0 unless ``signed``)."""
        if self.kind == "none":
            value = (float(np.sum(np.asarray(worse) ** 2)) - float(np.sum(np.asarray(better) ** 2))) / self.sigma**2
        else:
            value = 2.0 * (self.profile(better)[0] - self.profile(worse)[0])
        return value if signed else max(value, 0.0)

    def misfit(self, residual) -> dict:
        """:func:`misfit_test`'s statistics, and under the discrepancy its amplitude, time scale and noise, the
        2ΔlogL of the discrepancy against white noise, and ``structured`` by the rule above."""
        if self.kind == "none":
            return misfit_test(residual, self.sigma)
        smooth, hyper = self.profile(residual)
        white = self.profile(residual, "none")[0]
        out = misfit_test(residual, float(hyper.noise))
        lr = 2.0 * (smooth - white)
        out.update({"discrepancy": hyper.as_dict(), "discrepancy_lr": lr, "noise_sigma_m": float(hyper.noise),
                    "rmse_over_noise": out["rmse_m"] / float(hyper.noise),
                    "structured": bool(lr > STRUCTURE_THRESHOLD and float(hyper.amplitude) > float(hyper.noise)),
                    "material": bool(float(hyper.amplitude) > self.material)})
        return out


STRUCTURE_THRESHOLD = float(stats.chi2.isf(0.01, df=2))


def discover(
    times,
    length,
    inputs,
    *,
    base: gp.Parameters | None = None,
    config: Config | None = None,
    base_names: Sequence[str] = ("Y",),
    candidates: Sequence[str] | None = None,
    false_positive_rate: float = 0.05,
    confounding_correlation: float = 0.99,
    max_effects: int = 2,
    max_steps: int = 40,
    multistart: bool = True,
    progress: bool = False,
    workers: int | None = None,
    model_error: float | None = None,
    discrepancy: str = "matern32",
    material_misfit: float = MATERIAL_MISFIT,
) -> DiscoveryResult:
    """Find which catalogue effect the measured ``length`` (m) at ``times`` (s) needs beyond the base model.

    ``inputs``: the experiment's :class:`growjax.Inputs`; ``base``: the base parameters (default the
    published set of ``config.drive``), whose values are also the reference against which a base
    parameter's shift counts as confounding; ``base_names``: base parameters refitted with every
    candidate; ``multistart``: fit each new candidate from every start in ``START_FRACTIONS`` (False:
    from the first only, a third of the fits); ``workers``: fits run at a time (default one per CPU core; each
    fit is deterministic, so the result does not depend on it); ``model_error``: the fitted configuration's
    length error against the reference, m (default :data:`growjax.fit.FAST_MODEL_ERROR` for the fast
    configuration, 0 for the reference), allowed for in the confounding test under independent noise.
    ``discrepancy``: the likelihood every test uses (:mod:`growjax.discrepancy`): ``"matern32"`` (default) scores
    each model by its profile log-likelihood under a smooth discrepancy plus noise (hyperparameters at their mode
    for that model's residuals), and calls the misfit structured only where the discrepancy is significant and
    larger than ``material_misfit`` (m); ``"none"``: independent noise, σ from the residuals' differences.
    See the module docstring for the procedure and its thresholds.
    """
    if discrepancy not in dc.KINDS:
        raise ValueError(f"discrepancy must be one of {dc.KINDS}, got {discrepancy!r}")
    start = time.perf_counter()
    workers = workers if workers is not None else _cores()
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    config = config if config is not None else Config()
    base = base if base is not None else gp.reference(config.drive)
    candidates = tuple(candidates) if candidates else tuple(fx.CATALOGUE)
    times, length = np.asarray(times, float), np.asarray(length, float)
    problem = make_candidates(times, length, inputs, candidates, base, base_names, config)
    p, k_all = len(problem.base_names), len(candidates)
    # u of each start (K, starts): η = s·softplus(u) with s a tenth of the top; signed effects start at 0, ±5 %.
    fractions = START_FRACTIONS if multistart else START_FRACTIONS[:1]
    u_starts = np.stack([np.where(np.asarray(problem.signed), u_signed, math.log(math.expm1(10.0 * f)))
                         for f, u_signed in zip(fractions, (0.0, -0.5, 0.5))], axis=1)
    threshold = float(stats.chi2.isf(2.0 * false_positive_rate / k_all, df=1))  # ½χ²₀ + ½χ²₁, Bonferroni
    model_error = default_model_error(config) if model_error is None else model_error

    def model(effects_on: Sequence[int], fit_base: bool, z_now, start: int | None = 0):
        """(w0 (q,), mask (K,), select (p + K, q), z_fixed (p + K,)) of a model with ``effects_on`` fitted, a new
        candidate starting from its ``start``-th start (None: from its value in ``z_now``). q = p + the effects
        on, at least one (the base model shares the first round's program)."""
        q = p + max(len(effects_on), 1)
        mask, select = np.zeros(k_all), np.zeros((p + k_all, q))
        z_fixed, w0 = np.array(z_now, float), np.zeros(q)
        if fit_base:
            select[np.arange(p), np.arange(p)] = 1.0
            w0[:p], z_fixed[:p] = z_fixed[:p], 0.0
        for col, k in enumerate(effects_on):
            mask[k] = 1.0
            select[p + k, p + col] = 1.0
            w0[p + col] = z_fixed[p + k] if (k in added_index or start is None) else u_starts[k, start]
            z_fixed[p + k] = 0.0
        return w0, mask, select, z_fixed

    compiled = set()  # the numbers of fitted coordinates q whose program exists (one compiled program per q)
    fit_count, linearisations = 0, 0  # fits run, and model runs (residuals, Jacobian) over them: a run's time

    def fit_batch(specs, desc, warm=()):
        """Fit the models (``specs``: arguments of ``model``, all with the same q) through one compiled program, ``workers`` fits
        at a time; a model with a new candidate from each of its starts, keeping the lowest misfit (a model whose
        index is in ``warm``: from its value in the spec's ``z_now`` only)."""
        nonlocal compiled, fit_count, linearisations
        jobs = []
        for i, (effects_on, fit_base, z_now) in enumerate(specs):
            new = [k for k in effects_on if k not in added_index]
            base_only = fit_base and not effects_on and not added_index  # the base model: its own starts
            if i in warm:
                starts = [None]
            elif base_only:
                starts = range(len(BASE_START_FACTORS))
            else:
                starts = range(u_starts.shape[1]) if new else [0]
            for start in starts:
                if base_only:
                    z_start = np.array(z_now, float)
                    z_start[:p] += math.log(BASE_START_FACTORS[start])
                    jobs.append((i, model(effects_on, fit_base, z_start, None)))
                else:
                    jobs.append((i, model(effects_on, fit_base, z_now, start)))

        def run(job):
            m = job[1]
            z, r, jac, ok, pressure, runs = _fit_model(problem, *(jnp.asarray(a) for a in m), max_steps, resolution)
            return job[0], (np.asarray(z), np.asarray(r), np.asarray(jac), bool(ok), m, pressure), runs

        fits = [[] for _ in specs]
        q = jobs[0][1][0].size if jobs else None  # the program these fits run: new, it is compiled by the first alone
        for i, fitted, runs in _map_jobs(run, jobs, workers, progress, desc, first_alone=q not in compiled):
            fits[i].append(fitted)
            linearisations += runs
        compiled.add(q)
        fit_count += len(jobs)
        return [min(f, key=lambda f: float(f[1] @ f[1])) for f in fits]

    def summarise(out, sigma, effects):
        z, r, jac, ok, (_, mask, select, _), _ = out
        return _summarise(problem, z, r, jac, mask, select, sigma, ok, effects)

    z0 = np.concatenate([np.zeros(p), np.zeros(k_all)])
    # a fit's cost (½RSS, mm²) worth LR_RESOLUTION of 2ΔlogL, σ from the data's second differences (var 6σ²)
    sigma_data = noise_from_differences(np.diff(length)) / math.sqrt(3.0)
    resolution = 0.5 * LR_RESOLUTION * (sigma_data / 1e-3) ** 2
    added, added_index = [], []
    # Round 1: the base model, then every candidate on it with the base parameters refitted jointly, each starting
    # from the base fit (the extended model then starts within its new term of the base optimum, not in a side
    # minimum of the base parameters that the given values may lie nearer to).
    base_out = fit_batch([((), True, z0)], "base")[0]
    z_base = np.concatenate([base_out[0][:p], np.zeros(k_all)])
    outs = [base_out] + fit_batch([((k,), True, z_base) for k in range(k_all)], "round 1")
    sigma = noise_from_differences(outs[0][1] * 1e-3)
    base_fit = summarise(outs[0], sigma, ())
    fits = {candidates[k]: summarise(outs[k + 1], sigma, (candidates[k],)) for k in range(k_all)}
    scorer = Scorer(times, length, sigma, discrepancy, material_misfit)
    if discrepancy != "none":
        sigma = scorer.noise(base_fit.residual_m)
    # The same candidates with the base parameters held at their given values (deciding confounding for a candidate
    # correlated with a base parameter, reported for the others), each from one start: where its joint fit's
    # linearisation puts it with the base at the given values.
    u_held = [_held_start(problem, outs[k + 1], k, u_starts[k, 0]) for k in range(k_all)]
    held = fit_batch([((), False, z0)] + [((k,), False, np.where(np.arange(p + k_all) == p + k, u_held[k], z0))
                                          for k in range(k_all)], "base held", warm=set(range(1, k_all + 1)))
    held_res = [h[1] * 1e-3 for h in held]
    held_lr = {candidates[k]: scorer.lr(held_res[0], held_res[k + 1]) for k in range(k_all)}
    # With the base held, does the effect alone explain the data as well as refitting the base does?
    held_trades = {candidates[k]: scorer.lr(held_res[k + 1], base_fit.residual_m, signed=True) < threshold
                   for k in range(k_all)}
    # 2ΔlogL the model's own error can buy a base shift (under the discrepancy, δ carries that error)
    model_allowance = times.size * model_error**2 / sigma**2 if discrepancy == "none" else 0.0

    # The model's traces at the data's times: the length is the data plus the residual, the pressure comes with the fit.
    before_trace, pressure_trace = length + base_fit.residual_m, outs[0][5]
    misfit_before = scorer.misfit(base_fit.residual_m)
    current = base_fit
    evidence, confounded = [], {}
    for round_no in range(max_effects):
        if round_no > 0:
            if not scorer.misfit(current.residual_m)["structured"]:
                break
            others = [k for k in range(k_all) if k not in added_index]
            outs = fit_batch([(tuple(added_index) + (k,), True, current.z) for k in others], f"round {round_no + 1}")
            fits = {candidates[k]: summarise(o, sigma, tuple(added) + (candidates[k],)) for k, o in zip(others, outs)}
        scores = {}
        for name, fitted in fits.items():
            qname, unit, rng = candidate_parameter(name)
            lr = scorer.lr(current.residual_m, fitted.residual_m)
            sd = max((fitted.interval_90[qname][1] - fitted.interval_90[qname][0]) / (2 * Z90), 1e-300)
            corr = fitted.correlation.get(qname, {})
            worst, c = max(corr.items(), key=lambda kv: abs(kv[1]), default=(None, 0.0))
            h = held_lr[name] if round_no == 0 else 0.0
            # Unstructured residuals at the start: an effect (or a confounding) needs the threshold cleared
            # with the base refitted, never a trade with the base held.
            trades = (round_no == 0 and h > threshold + model_allowance and held_trades[name]
                      and (discrepancy == "none" or misfit_before["structured"]))
            pinned = lr > threshold and _pinned(fitted.estimate[qname], fitted.interval_90[qname])
            scores[name] = {
                "parameter": qname, "unit": unit, "estimate": fitted.estimate[qname],
                "interval_90": fitted.interval_90[qname], "lr_statistic": lr,
                "p_value": float(0.5 * stats.chi2.sf(lr, df=1)) if lr > 0 else 1.0,
                "log_bayes_factor": 0.5 * lr + math.log(math.sqrt(2 * math.pi) * sd / (rng[1] - max(rng[0], 0.0))),
                "rmse_m": float(np.sqrt(np.mean(fitted.residual_m**2))),
                "lr_statistic_base_held": h, "correlation_with_base": corr,
                "clears_threshold": bool(lr > threshold), "pinned": bool(pinned),
                # the fit pressed against its range's top (or a signed effect's bottom): the data ask for more
                "at_range_edge": bool(fitted.estimate[qname] >= rng[1] * (1 - 1e-6)
                                      or (rng[0] < 0 and fitted.estimate[qname] <= rng[0] * (1 - 1e-6))),
                "confounded": bool(abs(c) > confounding_correlation and (lr > threshold or trades) and not pinned),
            }
            if scores[name]["confounded"]:
                confounded[name] = {"parameter": worst, "correlation": c, "lr_statistic": lr,
                                    "lr_statistic_base_held": h, "separate_by": SEPARATING.get(name, "")}
        evidence.append(scores)
        clean = {n: s for n, s in scores.items() if s["clears_threshold"] and not s["confounded"]}
        if not clean:
            break
        best = max(clean, key=lambda n: clean[n]["lr_statistic"])
        lr_best = scores[best]["lr_statistic"]
        rivals = [n for n, s in scores.items()
                  if n != best and s["clears_threshold"] and s["lr_statistic"] > lr_best - threshold]
        if rivals:  # another effect explains the data about as well: name neither
            for name in (best, *rivals):
                others = [r for r in (best, *rivals) if r != name]
                confounded.setdefault(name, {"parameter": None, "correlation": None,
                                             "lr_statistic": scores[name]["lr_statistic"],
                                             "lr_statistic_base_held": scores[name]["lr_statistic_base_held"],
                                             "separate_by": SEPARATING.get(name, "")})
                confounded[name]["rival_effects"] = others
            break
        added.append(best)
        added_index.append(candidates.index(best))
        current = fits[best]

    misfit_after = scorer.misfit(current.residual_m)
    after_trace = length + current.residual_m
    if added and not misfit_after["structured"]:
        effect = added[0]
    elif added:
        effect = "unexplained"  # candidates helped but structure remains: no catalogue effect is claimed
    elif confounded:
        effect = "confounded"
    else:
        effect = "unexplained" if misfit_after["structured"] and misfit_after.get("material", True) else "none"
    units = {candidate_parameter(n)[0]: candidate_parameter(n)[1] for n in candidates}
    parameters = {n: {"estimate": v, "interval_90": current.interval_90[n], "unit": units.get(n, _unit(n))}
                  for n, v in current.estimate.items()}
    return DiscoveryResult(
        effect=effect, effects=added, parameters=parameters, rmse_before_m=misfit_before["rmse_m"],
        rmse_after_m=misfit_after["rmse_m"], noise_sigma_m=sigma, threshold=threshold, evidence=evidence,
        confounded_with=confounded,
        where={"before": locate(times, base_fit.residual_m, before_trace, pressure_trace),
               "after": locate(times, current.residual_m, after_trace, pressure_trace)},
        misfit_before=misfit_before, misfit_after=misfit_after,
        separating_measurement={n: SEPARATING.get(n, "") for n in confounded},
        wall_s=time.perf_counter() - start, trade_allowance=model_allowance, fits=fit_count,
        linearisations=linearisations, times=times, measured=length,
        before=before_trace, after=after_trace,
    )


def _held_start(problem: Candidates, joint, k: int, u_floor: float) -> float:
    """u of candidate ``k`` with the base parameters back at their given values (z_base = 0), from its joint fit
    ``joint`` (as ``fit_batch`` returns it): the Gauss–Newton step in η alone that takes over the base shift,
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


def _pinned(estimate: float, interval) -> bool:
    """Whether a 90 % interval excludes zero and lies within a factor :data:`PINNED_FACTOR` of the estimate. An
    interval of (near) zero width is not pinned: the effect's Jacobian column vanished (η deep in softplus's flat
    end) and the pseudo-inverse dropped its variance instead of making it infinite."""
    lo, hi = interval
    size = abs(estimate)
    return (lo * hi > 0 and hi - lo > 1e-6 * size and min(abs(lo), abs(hi)) >= size / PINNED_FACTOR
            and max(abs(lo), abs(hi)) <= PINNED_FACTOR * size)


def _map_jobs(run, jobs, workers: int, progress: bool, desc: str, first_alone: bool) -> list:
    """[``run(job)`` for every job], ``workers`` at a time on threads (XLA runs a compiled program without the
    GIL, so the fits of one process share the CPU's cores). ``first_alone``: the first job runs before the
    others start, so that their program is compiled once, not once per thread."""
    bar = _bar(progress, desc, len(jobs))
    results = []
    if jobs and (first_alone or workers == 1):
        results.append(run(jobs[0]))
        bar.update(1)
    rest = jobs[len(results):]
    if workers > 1 and len(rest) > 1:
        with concurrent.futures.ThreadPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(run, job) for job in rest]
            for future in concurrent.futures.as_completed(futures):
                bar.update(1)
            results += [f.result() for f in futures]
    else:
        for job in rest:
            results.append(run(job))
            bar.update(1)
    bar.close()
    return results


def _cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


class _NoBar:
    def update(self, n=1):
        pass

    def close(self):
        pass


def _bar(enabled: bool, desc: str, total: int):
    """A progress bar of ``total`` fits on the terminal when ``enabled`` (else one that shows nothing)."""
    if not enabled:
        return _NoBar()
    from tqdm.auto import tqdm

    return tqdm(desc=desc, unit="fit", leave=True, total=total)


def _unit(name: str) -> str:
    return {"robot.yield_pressure": "Pa", "robot.extensibility": "(m/s)·Pa^(-1/n)", "robot.growth_exponent": "-",
            "robot.lockhart_rate": "m/s", "robot.lockhart_exponent": "-"}.get(name, "")


def summary_text(result: DiscoveryResult) -> str:
    """A readable summary of a :class:`DiscoveryResult` for the terminal."""
    lines = [f"effect: {result.effect}" + (f" (added: {', '.join(result.effects)})" if result.effects else ""),
             (f"length RMSE {1e3 * result.rmse_before_m:.3f} mm before, {1e3 * result.rmse_after_m:.3f} mm after; "
              f"noise σ {1e3 * result.noise_sigma_m:.3f} mm; threshold 2ΔlogL > {result.threshold:.2f}")]
    for name, p in result.parameters.items():
        lo, hi = p["interval_90"]
        lines.append(f"  {name} = {p['estimate']:.4g} {p['unit']} (90 %: {lo:.4g} – {hi:.4g})")
    for k, scores in enumerate(result.evidence):
        lines.append(f"round {k + 1}:")
        for name, s in sorted(scores.items(), key=lambda kv: -kv[1]["lr_statistic"]):
            flag = "confounded" if s["confounded"] else ("clears" if s["clears_threshold"] else "")
            lines.append(f"  {name:22s} 2ΔlogL {s['lr_statistic']:8.2f}  {s['parameter']} = {s['estimate']:.3g} "
                         f"{s['unit']}  {flag}")
    for name, c in result.confounded_with.items():
        with_ = [f"{c['parameter']} (correlation {c['correlation']:.3f})"] if c["parameter"] else []
        with_ += [f"the effect {r}" for r in c.get("rival_effects", ())]
        lines.append(f"confounded: {name} with {' and '.join(with_)}; separate by {c['separate_by']}")
    lines.append(f"{result.wall_s:.1f} s: {result.fits} fits, {result.linearisations} linearisations of the model")
    return "\n".join(lines)
