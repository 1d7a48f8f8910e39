"""Gradient fits of the measured length (and pressure) through the differentiable model.

The free parameters are moved in log coordinates z = ln(θ/θ_ref), so every direction is O(1) and positivity
holds. Levenberg–Marquardt (:mod:`growjax.calibration.least_squares`, forward-mode Jacobian) starts from the best sets of a
Latin-hypercube sweep; least squares from every start, then generalised least squares under the residual model
of :mod:`growjax.calibration.discrepancy` (a smooth discrepancy plus sensor noise). The intervals are Gauss–Newton's under
that model, plus the spread over its hyperparameters, the fast configuration's own error and the rig's
tolerances (:mod:`growjax.calibration.tolerance`: by default the rig's errors are fitted beside θ under their tolerances as
priors, so the data inform them), reported term by term; the eigen-directions of the information on θ show
what the data cannot pin down.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float
from scipy import stats

from growjax import sweep as sw
from growjax.calibration import discrepancy as dc
from growjax.calibration import tolerance as tl
from growjax.calibration.least_squares import levenberg_marquardt, linearise, memoised
from growjax.data import experiment
from growjax.model import params as gp
from growjax.simulation.config import Config
from growjax.simulation.simulate import as_arrays, input_breaks, sample_times, simulate
from growjax.simulation.trajectory import OK

RIG_TREATMENTS = ("inferred", "fixed")
# Multi-start boxes: the paper's investigation where it has one, else [θ/2, 2θ] around the reference.
PAPER_RANGES = {d.name: (d.low, d.high) for d in sw.paper_box()}
Z90 = float(stats.norm.ppf(0.95))
# The fast configuration's own error against the reference, carried into the intervals as a smooth,
# correlated residual: its standard uncertainty (m) and correlation time (s). Measured over the shipped
# reference traces of the published pulse (benchmarks/agreement.py): RMS 0.012 mm across them, worst 0.018 mm.
FAST_MODEL_ERROR = 1.5e-5
# Its correlation time: the error is a slow drift that grows over the run (on the published pulse, mean −2, −10,
# −20 µm over 0–3, 3–7, 7–10 s), so it moves a fitted Y as a whole, one sign for every set.
MODEL_ERROR_TIME = 5.0


def default_model_error(config: Config) -> float:
    """The fitted configuration's length error against the reference, m: :data:`FAST_MODEL_ERROR` for the
    fast configuration, 0 for the reference itself."""
    return FAST_MODEL_ERROR if config.fidelity == "fast" else 0.0


LM_TOLERANCE = 1e-6  # rtol = atol of the Levenberg–Marquardt stop, on ln θ and the cost
# Information on ln θ below this (the data alone put its sd above 10: a factor e^±16 at 90 %) leaves a direction
# undetermined, whatever the other directions hold: no interval is reported along it. (A relative test alone
# cannot see a single free parameter the data do not inform, such as Y driven to ~0 Pa where it no longer acts.)
INFORMATION_FLOOR = 1e-2


def default_range(base: gp.Parameters, name: str) -> tuple[float, float]:
    """Sampling box (SI) for a free parameter."""
    q = gp.resolve_name(base, name)
    if q in PAPER_RANGES:
        return PAPER_RANGES[q]
    v = float(gp.get(base, q))
    if v <= 0:
        raise ValueError(
            f"parameter {q} = {v} is not positive: only positive parameters can be fitted in log coordinates"
        )
    return 0.5 * v, 2.0 * v


@dataclasses.dataclass
class FitResult:
    """Outcome of a fit. Values in SI units; ``interval_90`` is None for directions the data do not determine."""

    names: tuple
    estimate: dict
    interval_90: dict
    standard_error: dict
    rmse_length_m: float
    cost: float
    covariance_log: np.ndarray  # (p, p), in z = ln θ
    eigenvalues: np.ndarray  # of JᵀJ in z, ascending
    eigenvectors: np.ndarray  # columns, in z
    undetermined: list  # [{"eigenvalue", "direction": {name: loading}}]
    starts: list  # [{"start", "estimate", "cost", "converged"}]
    wall_s: float
    status: str
    at_bound: tuple = ()  # parameters whose estimate ended on an edge of its physical range
    discrepancy: dict = dataclasses.field(
        default_factory=dict
    )  # kind, amplitude_m, time_scale_s, noise_m, noise_time_s
    budget: dict = dataclasses.field(default_factory=dict)  # {name: {source: sd, SI}}: noise, discrepancy, tolerances
    tolerances: dict = dataclasses.field(default_factory=dict)  # {parameter: relative sd} carried
    samples_used: int = 0  # length samples the likelihood scored (an interpolated record: its keyframes)
    tolerance_gain: dict = dataclasses.field(default_factory=dict)  # {name: {tolerance: dθ/d ln ψ, SI}}, signed
    rig: str = "none"  # how the tolerances entered: "inferred", "fixed", or "none" (no tolerances)
    rig_offset: dict = dataclasses.field(default_factory=dict)  # {tolerance: fitted ln(ψ/ψ₀)} when inferred
    rig_estimate: dict = dataclasses.field(default_factory=dict)  # {tolerance: fitted ψ, SI} when inferred
    linearisations: int = 1  # points at which the rig's sensitivities were taken (see RELINEARISE_STEPS)

    def summary(self) -> dict:
        return {
            "status": self.status,
            "rmse_length_m": self.rmse_length_m,
            "parameters": {
                n: {
                    "estimate": self.estimate[n],
                    "standard_error": self.standard_error[n],
                    "interval_90": self.interval_90[n],
                    "budget_sd": self.budget.get(n),
                }
                for n in self.names
            },
            "discrepancy": self.discrepancy,
            "tolerances": self.tolerances,
            "rig": self.rig,
            "rig_offset": self.rig_offset,
            "rig_estimate": self.rig_estimate,
            "linearisations": self.linearisations,
            "samples_used": self.samples_used,
            "undetermined_directions": self.undetermined,
            "at_physical_bound": list(self.at_bound),
            "starts": self.starts,
            "wall_s": self.wall_s,
        }


class Problem(eqx.Module):
    """A least-squares problem as data: the model, its inputs and the (windowed) measurements.

    Arrays are leaves, so one compiled program serves every call with the same shapes.
    """

    base: gp.Parameters
    inputs: object
    refs: jax.Array  # (p,) reference values of the free parameters, SI
    times: jax.Array  # (m,) s
    length: jax.Array  # (m,) m
    pressure: jax.Array | None  # (m,) Pa or None
    breaks: tuple  # (jump times, slope-break times) of the inputs, s
    names: tuple = eqx.field(static=True)
    config: object = eqx.field(static=True)
    sigma_length: jax.Array  # () m, the length's scale (a leaf: one compiled program serves every scale)
    sigma_pressure: jax.Array  # () Pa

    def residuals(self, z, args=None):
        """Non-dimensional residuals r(z), shape (m,) or (2m,), for log coordinates z = ln(θ/θ_ref)."""
        return _residuals(z, self)

    def _residuals(self, z):
        theta = self.refs * jnp.exp(z)
        p = gp.replace(self.base, **{n: theta[i] for i, n in enumerate(self.names)})
        traj = simulate(p, self.inputs, self.config, ts=sample_times(self.times, self.config), breaks=self.breaks)
        r = (traj.length - self.length) / self.sigma_length
        if self.pressure is not None:
            r = jnp.concatenate([r, (traj.pressure - self.pressure) / self.sigma_pressure])
        return jnp.where(jnp.isfinite(r), r, 1e3)  # a failed run is a very bad fit, not a crash


@eqx.filter_jit
def _residuals(z, problem: Problem):
    # A jitted leaf: the solver's traces (step, Jacobian, vmap) reuse one traced simulation.
    return problem._residuals(z)


def make_problem(
    base, names, inputs, config, times, length, pressure=None, window=None, sigma_length=1e-3, sigma_pressure=5e3
) -> Problem:
    """The :class:`Problem` for the parameters ``names`` on the data inside ``window`` (default: the config's)."""
    names = tuple(gp.resolve_name(base, n) for n in names)
    config = config.replace(adjoint="forward")
    refs = jnp.asarray([float(gp.get(base, n)) for n in names])
    t0, t1 = window if window is not None else (config.t0, config.t1)
    keep = (np.asarray(times) >= t0) & (np.asarray(times) <= t1)
    pick = lambda a: None if a is None else jnp.asarray(np.asarray(a)[keep])
    # Numbers as arrays: one compiled program serves every base (a tolerance's perturbed rig included).
    return Problem(
        as_arrays(base),
        inputs,
        refs,
        pick(times),
        pick(length),
        pick(pressure),
        input_breaks(inputs, config),
        names,
        config,
        jnp.asarray(sigma_length, float),
        jnp.asarray(sigma_pressure, float),
    )


@eqx.filter_jit
def _linearised(z, problem: Problem):
    """:func:`linearise` of the problem's residuals at z: the only compiled program of a fit."""
    return linearise(problem.residuals, z)


def fit(
    times: Float[ArrayLike, " m"],
    length: Float[ArrayLike, " m"],
    inputs,
    free: Sequence[str] = ("Y",),
    base: gp.Parameters | None = None,
    config: Config | None = None,
    pressure: Float[ArrayLike, " m"] | None = None,
    window: tuple[float, float] | None = None,
    n_starts: int = 3,
    sweep_n: int = 64,
    seed: int = 0,
    max_steps: int = 100,
    sigma_length: float = 1e-3,
    sigma_pressure: float = 5e3,
    model_error: float | None = None,
    discrepancy: str = "matern32",
    tolerances: dict | None = None,
    rig: str = "inferred",
    relinearise: bool = True,
    rig_tangents: bool = True,
) -> FitResult:
    """Fit ``free`` parameters to a measured length (m) at ``times`` (s) (and ``pressure``, Pa, if given).

    ``window`` = (t_start, t_end), s: only the samples inside it are scored; the model still runs from the
    configuration's t0. Starts: the ``n_starts`` best of a ``sweep_n``-point Latin hypercube over each
    parameter's :func:`default_range` (``sweep_n=0``: one start, at the values in ``base``).

    The likelihood (:mod:`growjax.calibration.discrepancy`): ``discrepancy="matern32"`` (default) scores the length as the
    model plus a smooth Matérn-3/2 discrepancy plus sensor noise, their amplitude, time scale and noise at
    their posterior mode given the residuals; a record interpolated between keyframes is scored at its
    keyframes (:func:`growjax.data.experiment.informative_samples`). ``"none"``: independent noise on every sample,
    its sd from the residuals. Both add the fitted configuration's own error ``model_error`` (m; default
    :data:`FAST_MODEL_ERROR` for the fast configuration), propagated as a smooth correlated error.
    ``tolerances`` {parameter: relative sd}: the rig's fixed parameters' uncertainty (:mod:`growjax.calibration.tolerance`;
    None: its default budget with the discrepancy, none without). The estimate is the generalised
    least-squares optimum under the discrepancy and noise, found by Gauss–Newton on the whitened residuals
    (Levenberg–Marquardt) from the least-squares optimum, alternating with the hyperparameters' mode.

    ``rig`` says how the tolerances enter. ``"inferred"`` (default; the posterior's treatment): each
    toleranced parameter's relative error b = ln(ψ/ψ₀) is a nuisance parameter with the prior N(0, u²), fitted
    beside θ (its effect on the length linearised, g = ∂L/∂ln ψ), so the data inform the rig; the covariance
    is the (θ, b) block of Gauss–Newton's (J̃ᵀJ̃ + prior)⁻¹ restricted to θ. ``"fixed"``: the rig held at its
    nominal values and each tolerance propagated through the estimator's gain as if the data said nothing of
    the rig (the GUM's treatment of an input quantity not estimated from the measurement): the conservative
    choice, wider where the data do inform the rig. :attr:`FitResult.budget` splits each variance into
    noise, discrepancy and each tolerance (under ``"inferred"``: what is left of each after the data).

    ``rig_tangents`` (default), with the rig inferred: the rig's errors are parameters of the model beside θ, their
    sensitivities its exact forward-mode tangents in the same solve as θ's; (θ, b) are fitted by least squares
    with b's prior rows b/u before the discrepancy is estimated (a misfit is then the model's to remove, not the
    discrepancy's to absorb), then by generalised least squares, the likelihood linearised at every point where
    the rig then is. False: the rig's secants from nominal, taken apart from the solve; with ``relinearise``
    (default) taken again where the data put the rig, until it settles (at most :data:`RELINEARISE_STEPS`
    linearisations), or with ``relinearise=False`` once, at nominal (cheaper; over-confident where the rig is off
    by a tolerance or more). Where a designed input drives the frictions hard and the rig is far off nominal, the
    secant path can settle in a side minimum whose misfit the discrepancy absorbs; the tangents do not, and they
    cost one solve per point instead of two per tolerance per linearisation.
    """
    if rig not in RIG_TREATMENTS:
        raise ValueError(f"rig must be one of {RIG_TREATMENTS}, got {rig!r}")
    if discrepancy not in dc.KINDS:
        raise ValueError(f"discrepancy must be one of {dc.KINDS}, got {discrepancy!r}")
    base = base if base is not None else gp.reference()
    config = (config if config is not None else Config()).replace(adjoint="forward")  # Jacobians by jvp
    names = tuple(gp.resolve_name(base, n) for n in free)
    refs = np.array([float(gp.get(base, n)) for n in names])
    if np.any(refs <= 0):
        raise ValueError(f"fitted parameters must be positive, got {dict(zip(names, refs))}")
    tol = tl.budget(base, tolerances, names, use_default=tolerances is None and discrepancy != "none")
    window = _check_window(window, config)
    start_clock = time.perf_counter()
    start_values, order = _starts(base, names, refs, inputs, config, times, length, window, n_starts, sweep_n, seed)
    problem = make_problem(base, names, inputs, config, times, length, pressure, window, sigma_length, sigma_pressure)
    n_len = int(problem.times.size)
    used = experiment.informative_samples(np.asarray(problem.length)) if discrepancy != "none" else np.ones(n_len, bool)
    likelihood = Likelihood(problem.times, jnp.asarray(used), jnp.asarray(np.flatnonzero(used)), sigma_length, n_len)
    bounds = physical_bounds(base, names, refs)
    z0s = jnp.log(jnp.asarray(start_values[order]) / refs)
    if rig_tangents and rig == "inferred" and tol:
        full = make_problem(
            base, names + tuple(tol), inputs, config, times, length, pressure, window, sigma_length, sigma_pressure
        )
        zs, costs, oks, z, b, raw, hyper, converged, likelihood, linearisations = _solve_tangents(
            likelihood, z0s, bounds, max_steps, full, tol, discrepancy, sampling_box(base, names, refs)
        )
    else:
        zs, costs, oks, z, b, raw, hyper, converged, likelihood, linearisations = _solve(
            likelihood, z0s, bounds, max_steps, problem, tol, discrepancy, rig, RELINEARISE_STEPS if relinearise else 1
        )
    starts = [
        {
            "start": dict(zip(names, map(float, start_values[i]))),
            "estimate": dict(zip(names, map(float, refs * np.exp(zs[k])))),
            "cost": float(costs[k]),
            "converged": bool(oks[k]),
        }
        for k, i in enumerate(order)
    ]
    theta = refs * np.exp(z)
    if model_error is None:
        model_error = default_model_error(config)
    info = likelihood.information(raw, hyper, b)
    cov, parts, gain = likelihood.covariance(raw, hyper, b, model_error)
    if discrepancy != "none":  # the hyperparameters are estimated, not known: average over them
        spread = likelihood.hyperparameter_spread(raw, hyper, cov, b)
        parts["hyperparameters"], cov = spread, cov + spread
    result = _result(
        names,
        theta,
        z,
        cov,
        parts,
        info,
        hyper,
        likelihood,
        raw,
        starts,
        converged,
        bounds,
        start_clock,
        int(np.sum(used)),
        discrepancy,
    )
    result.rig = rig if likelihood.tolerance is not None else "none"
    result.linearisations = linearisations
    if likelihood.inferred:  # the rig as fitted: its values, and the length residual with its linearised effect
        at = np.asarray(likelihood.centre) + b
        result.rig_offset = {t: float(at[j]) for j, t in enumerate(likelihood.tolerance_names)}
        result.rig_estimate = {
            t: float(gp.get(base, t)) * float(np.exp(at[j])) for j, t in enumerate(likelihood.tolerance_names)
        }
        r_len = np.asarray(raw[0])[:n_len] * sigma_length + np.asarray(likelihood.sensitivity) @ b
        result.rmse_length_m = float(np.sqrt(np.mean(r_len**2)))
    result.tolerance_gain = {
        n: {t: float(theta[i] * gain[i, j]) for j, t in enumerate(likelihood.tolerance_names)}
        for i, n in enumerate(names)
    }
    return result


def _starts(base, names, refs, inputs, config, times, length, window, n_starts: int, sweep_n: int, seed: int):
    """(start values (k, p) SI, the indices of the ``n_starts`` best): a Latin-hypercube scout of ``sweep_n`` sets over
    each parameter's :func:`default_range` ranked by length RMSE, or the values in ``base`` when ``sweep_n`` is 0."""
    if sweep_n < 0 or n_starts < 1:
        raise ValueError(f"sweep_n must be >= 0 and n_starts >= 1, got {sweep_n} and {n_starts}")
    if sweep_n == 0:  # no scouting sweep: start at the given values
        return refs[None, :], [0]
    dims = [sw.Dimension(n, *default_range(base, n), log=True) for n in names]
    measured = (np.asarray(times), np.asarray(length))
    scout = sw.lhs_sweep(sweep_n, base, inputs, config, dims, seed=seed, measured=measured, window=window)
    order = [i for i in np.argsort(np.nan_to_num(scout.rmse, nan=np.inf)) if scout.status[i] == OK][:n_starts]
    if not order:
        raise RuntimeError("no start of the multi-start sweep simulated successfully")
    return scout.values, order


def _solve(likelihood, z0s, bounds, max_steps: int, problem, tol: dict, discrepancy: str, rig: str, steps: int):
    """Least squares from every start (one after another through one compiled solver: consistent under any
    correlation of the residuals, and a start that a discrepancy absorbing the misfit cannot trap); the rig's
    sensitivities at the best; then generalised least squares alternating with the hyperparameters' mode, the
    rig's errors fitted beside z (``rig="inferred"``) or the rig held nominal (``"fixed"``: its tolerances
    propagated afterwards). When inferred, the model and the rig's sensitivities are taken again where the fit
    put the rig (at most ``steps`` linearisations), until the rig's errors move by less than
    :data:`RELINEARISE_TOLERANCE` of their tolerance. Returns (z per start, cost per start, converged per start,
    z, b (q,) the rig's errors from the likelihood's ``centre`` (empty unless inferred), the linearisation at z
    with the rig at that centre, the hyperparameters, converged, the likelihood with its tolerances, the number
    of linearisations)."""
    model = nominal = memoised(lambda w, pr=problem: _linearised(w, pr))
    solved = [
        levenberg_marquardt(lambda w: likelihood.weighted(*model(w)), z0, max_steps, LM_TOLERANCE, bounds=bounds)
        for z0 in z0s
    ]
    zs, costs, oks = (np.asarray([s[k] for s in solved]) for k in range(3))
    k_best = int(np.argmin(costs))
    z, converged = np.asarray(zs[k_best]), bool(oks[k_best])
    p = z.size
    plain, centre, hyper, linearisations = likelihood, np.zeros(len(tol)), None, 0
    b = np.zeros(len(tol) if tol and rig == "inferred" else 0)
    at_rig = problem
    for step in range(steps):
        linearisations += 1
        model = nominal if at_rig is problem else memoised(lambda w, pr=at_rig: _linearised(w, pr))
        raw = model(jnp.asarray(z))
        g = _tolerance_sensitivity(at_rig, z, raw[0], tol, central=step > 0) if tol else None
        if g is not None and rig == "inferred":
            likelihood = plain.with_tolerances(g, tol, inferred=True, centre=centre)
        w, hyper, _, converged = alternate_gls(
            lambda v, h, lik=likelihood, m=model: lik.augmented(*m(v[:p]), h, v[p:]),
            lambda v, h, lik=likelihood, m=model: lik.estimate(m(jnp.asarray(v[:p]))[0], discrepancy, h),
            np.concatenate([z, b]),
            likelihood.bounds(bounds),
            max_steps,
            hyper,
        )
        z, b = w[:p], w[p:]
        raw = model(jnp.asarray(z))
        if (
            not likelihood.inferred
            or step == steps - 1
            or np.all(np.abs(b) <= RELINEARISE_TOLERANCE * np.asarray(likelihood.tolerance))
        ):
            break
        centre, b = centre + b, np.zeros_like(b)  # the rig moved: linearise again where the data put it
        at_rig = problem_at_rig(problem, tol, centre)
    if g is not None and not likelihood.inferred:  # fixed: propagated after the fit
        likelihood = likelihood.with_tolerances(g, tol)
    return zs, costs, oks, z, b, raw, hyper, converged, likelihood, linearisations


def _solve_tangents(likelihood, z0s, bounds, max_steps: int, problem, tol: dict, discrepancy: str, box=None):
    """:func:`_solve` with the rig's errors β = ln(ψ/ψ₀) among the model's parameters (``problem`` frees θ then
    the toleranced parameters, in ``tol``'s order): least squares from every start with the rig nominal; from the
    best, least squares of (z, β) with β's prior rows β/u (before any discrepancy is estimated: a misfit is then
    the model's to remove, not the discrepancy's to absorb); then generalised least squares of (z, β)
    alternating with the hyperparameters' mode, the rig's sensitivities at every point its exact tangents there.
    The (z, β) least squares starts from :func:`rig_stage_starts` (the best start, and where it left the sampling
    ``box`` also its clip into it), the lower cost winning.
    Returns what :func:`_solve` returns, the likelihood linearised at the estimate (its centre β, b = 0)."""
    q, p = len(tol), z0s.shape[1]
    u, n, scale = np.asarray(list(tol.values()), float), likelihood.n_len, likelihood.sigma_length
    model = memoised(lambda w: _linearised(w, problem))

    def nominal(z):
        r, jac = model(jnp.concatenate([jnp.asarray(z), jnp.zeros(q)]))
        return likelihood.weighted(r, jac[:, :p])

    solved = [levenberg_marquardt(nominal, z0, max_steps, LM_TOLERANCE, bounds=bounds) for z0 in z0s]
    zs, costs, oks = (np.asarray([s[k] for s in solved]) for k in range(3))
    z1 = np.asarray(zs[int(np.argmin(costs))])
    w_bounds = with_rig_bounds(bounds, q)
    prior = np.concatenate([np.zeros((q, p)), np.diag(1.0 / u)], axis=1)

    def with_prior(v):
        r, jac = likelihood.weighted(*model(jnp.asarray(v)))
        return np.concatenate([np.asarray(r), np.asarray(v)[p:] / u]), np.concatenate([np.asarray(jac), prior])

    runs = [
        levenberg_marquardt(with_prior, np.concatenate([z, np.zeros(q)]), max_steps, LM_TOLERANCE, bounds=w_bounds)
        for z in rig_stage_starts(z1, box)
    ]
    w, _, converged, _, _ = min(runs, key=lambda run: run[1])

    def at(v):  # the likelihood linearised at v = (z, β), and (r, J_z) there
        r, jac = model(jnp.asarray(v))
        g = np.asarray(jac)[:n, p:] * scale
        return likelihood.with_tolerances(g, tol, inferred=True, centre=np.asarray(v)[p:]), (r, jac[:, :p])

    w, hyper, _, converged = alternate_gls(
        lambda v, h: (lambda lk, rw: lk.augmented(*rw, h, np.zeros(q)))(*at(v)),
        lambda v, h: (lambda lk, rw: lk.estimate(rw[0], discrepancy, h))(*at(v)),
        w,
        w_bounds,
        max_steps,
    )
    lik, raw = at(w)
    return zs, costs, oks, w[:p], np.zeros(q), raw, hyper, converged, lik, 1


def sampling_box(base: gp.Parameters, names, refs) -> np.ndarray:
    """(2, p): the starts' sampling box (:func:`default_range`) in z = ln(θ/θ_ref), lower then upper."""
    return np.log(np.array([default_range(base, n) for n in names]).T / np.asarray(refs, float))


def rig_stage_starts(z, box=None) -> list:
    """The starts of the least squares that fits the rig's errors beside z: the nominal-rig stage's best z, and
    where z left the sampling ``box`` (2, p), z brought back into it too (the lower cost is kept). With the rig
    held nominal, a misfit that is the rig's can run θ to where it stops acting (Y to ~0 Pa on a stepper run from
    a rig far off nominal), and from there the rig's errors cannot pull it back; from the box's edge they can."""
    z = np.asarray(z, float)
    if box is None or np.all((z >= box[0]) & (z <= box[1])):
        return [z]
    return [z, np.clip(z, box[0], box[1])]


def with_rig_bounds(bounds, q: int):
    """The box (lower, upper) on w = (z, b): ``bounds`` on z, none on the q rig errors b after it."""
    return tuple(np.concatenate([np.asarray(x, float), np.full(q, v)]) for x, v in zip(bounds, (-np.inf, np.inf)))


def alternate_gls(whitened, hyper_at, w, bounds, max_steps: int, hyper=None):
    """Alternate the hyperparameters' mode at w (``hyper_at(w, hyper) → hyper``) and Gauss–Newton on the whitened
    residuals (``whitened(w, hyper) → (r, J)``) from w, until a fit moves every coordinate by less than
    :data:`OUTER_TOLERANCE` of its sd (at most :data:`OUTER_STEPS` fits). Returns (w, hyper, cost, converged)."""
    w, cost, converged = np.asarray(w, float), np.nan, False
    for _ in range(OUTER_STEPS):
        hyper = hyper_at(w, hyper)
        w_new, cost, converged, _, jac_w = levenberg_marquardt(
            lambda v, h=hyper: whitened(v, h),
            w,
            max_steps,
            LM_TOLERANCE,
            bounds=bounds,
            cost_resolution=COST_RESOLUTION,
        )
        sd = np.sqrt(np.diag(np.linalg.pinv(jac_w.T @ jac_w, rcond=1e-10, hermitian=True)))
        moved, w = np.abs(w_new - w), np.asarray(w_new)
        if np.all(moved <= OUTER_TOLERANCE * sd):
            break
    return w, hyper, cost, converged


def problem_at_rig(problem: Problem, tol: dict, centre) -> Problem:
    """``problem`` with the toleranced parameters of ``tol`` at ψ₀·e^centre (``centre`` (q,) in their order)."""
    return eqx.tree_at(lambda pr: pr.base, problem, tl.rig_at(problem.base, list(tol), centre))


# The smallest change of the whitened cost (nats) that matters: a 90 % interval spans 1.35 nats, and the
# adaptive solver's own noise moves the cost by ~1e-3.
COST_RESOLUTION = 1e-2
OUTER_STEPS = 4  # alternations of the hyperparameters' mode and the GLS fit
OUTER_TOLERANCE = 0.05  # stop once a GLS fit moves ln θ by less than this share of its sd
# The rig's sensitivities are secants taken at one point: where the data pull the rig's errors a good part of a
# tolerance from nominal, secants at nominal bias θ by several standard errors. With ``relinearise`` the fit takes
# them again where it put the rig, as central secants (the slope there), at most this many linearisations, until
# the errors move by less than this share of their tolerance.
RELINEARISE_STEPS = 8
RELINEARISE_TOLERANCE = 0.02


class Likelihood(eqx.Module):
    """The fit's side of :mod:`growjax.calibration.discrepancy`: residuals and Jacobians (length rows in units of
    ``sigma_length``, pressure rows after them) weighted or whitened, and the covariance with its budget."""

    times: jax.Array  # (n,) s, the scored samples
    used: jax.Array  # (n,) bool, the samples the likelihood sees
    index: jax.Array  # (n_used,) int, their rows (the filter runs over them alone: exact, the process is Markov)
    sigma_length: float = eqx.field(static=True)
    n_len: int = eqx.field(static=True)
    sensitivity: jax.Array | None = None  # (n, q) m per unit ln ψ
    tolerance: jax.Array | None = None  # (q,) relative sd
    tolerance_names: tuple = eqx.field(static=True, default=())
    inferred: bool = eqx.field(static=True, default=False)  # the rig's errors b fitted beside z (prior N(0, u²))
    centre: jax.Array | None = None  # (q,) the rig's errors (ln ψ/ψ₀) where the model is linearised; b is from here

    def with_tolerances(self, sensitivity, tol: dict, inferred: bool = False, centre=None):
        centre = jnp.zeros(len(tol)) if centre is None else jnp.asarray(centre, float)
        return Likelihood(
            self.times,
            self.used,
            self.index,
            self.sigma_length,
            self.n_len,
            jnp.asarray(sensitivity),
            jnp.asarray(list(tol.values())),
            tuple(tol),
            inferred,
            centre,
        )

    def bounds(self, bounds):
        """The box on w = (z, b): ``bounds`` on z, none on the rig's errors b."""
        return with_rig_bounds(bounds, len(self.tolerance_names) if self.inferred else 0)

    def augmented(self, r, jac, hyper, b):
        """Whitened residuals and Jacobian of w = (z, b) under the discrepancy and noise: z alone with the rig at
        its nominal values, or, when the rig is inferred, with its linearised effect g·b on the length and
        its prior residuals b/u as q more rows."""
        return _augmented(self, r, jac, hyper, jnp.asarray(b if self.inferred else np.zeros(0)))

    def length_columns(self, r, jac, b):
        """The scored length rows, m: [residual (with the rig's g·b when inferred), Jacobian, (g when inferred)]
        (n_used, 1 + p (+ q)), and their times (n_used,) s: the columns one filter whitens together."""
        n, scale = self.n_len, self.sigma_length
        cols = [r[:n, None] * scale, jac[:n] * scale]
        if self.inferred:
            g = self.sensitivity
            cols = [cols[0] + g @ b[:, None], cols[1], g]
        return jnp.concatenate(cols, axis=1)[self.index], self.times[self.index]

    def weighted(self, r, jac):
        """Residuals and Jacobian with the unused length samples zeroed (independent noise of sd σ_L)."""
        keep = jnp.concatenate([self.used, jnp.ones(r.shape[0] - self.n_len, bool)])
        return jnp.where(keep, r, 0.0), jnp.where(keep[:, None], jac, 0.0)

    def estimate(self, r, kind, start=None):
        """The hyperparameters' mode for the residuals ``r`` (units of σ_L), the rig marginalised when inferred."""
        index = np.asarray(self.index)
        r_len = np.asarray(r)[: self.n_len] * self.sigma_length
        g, u = (np.asarray(self.sensitivity)[index], np.asarray(self.tolerance)) if self.inferred else (None, None)
        if self.inferred:  # the errors' prior is centred on nominal, not on the point of linearisation
            r_len = r_len - np.asarray(self.sensitivity) @ np.asarray(self.centre)
        return dc.estimate(r_len[index], np.asarray(self.times)[index], kind, g, u, start=start)

    def information(self, raw, hyper, b) -> np.ndarray:
        """The information (p, p) the data hold on z: J̃ᵀJ̃, or with the rig inferred its Schur complement
        (the inverse of the z block of the joint covariance)."""
        _, jac_w = (np.asarray(a) for a in self.augmented(*raw, hyper, b))
        info = jac_w.T @ jac_w
        p = np.asarray(raw[1]).shape[1]
        if not self.inferred:
            return info
        return info[:p, :p] - info[:p, p:] @ np.linalg.solve(info[p:, p:], info[p:, :p])

    def covariance(self, raw, hyper, b, model_error: float = 0.0):
        """Covariance (p, p) of z = ln θ, its parts {source: (p, p)}, which add up to it, and the estimator's gain
        (p, q) on the rig's errors (ln θ per unit ln ψ).

        The joint covariance C of w = (z, b) is Gauss–Newton's, (J̃ᵀJ̃)⁻¹ (b only when the rig is inferred);
        the estimator is linear in the data, w = A·r, and its covariance splits by the residual's sources: the
        noise and the discrepancy, A K_k Aᵀ; each tolerance, inferred, through its prior residual
        (C_{z,b_j} C_{z,b_j}ᵀ / u_j²: what of its prior the data left), fixed, propagated through the estimator
        (the GUM's sensitivity coefficients), u² (A g)(A g)ᵀ with g the length's sensitivity; the fitted
        configuration's own error against the reference (sd ``model_error`` m, squared-exponential over
        :data:`MODEL_ERROR_TIME`: too small for the data to measure, known from the agreement benchmark)
        through the same gain; the pressure noise."""
        jac = np.asarray(raw[1])
        p = jac.shape[1]
        _, jac_w = (np.asarray(a) for a in self.augmented(*raw, hyper, b))
        full = np.linalg.pinv(jac_w.T @ jac_w, rcond=1e-10, hermitian=True)
        used = np.asarray(self.used)
        t = np.asarray(self.times)[used]
        h = jac[: self.n_len][used] * self.sigma_length  # m per unit z
        g = None if self.sensitivity is None else np.asarray(self.sensitivity)[used]  # m per unit ln ψ
        if self.inferred:
            h = np.concatenate([h, g], axis=1)
        kernels = {"noise": dc.noise_kernel(t, hyper)}
        if float(hyper.amplitude) > 0:
            kernels["discrepancy"] = dc.kernel(t, hyper)
        a = full @ np.linalg.solve(sum(kernels.values()), h).T  # (p[+q], n): w per metre of residual
        parts = {k: (a @ kern @ a.T)[:p, :p] for k, kern in kernels.items()}
        if model_error > 0:
            solver = dc.drift_kernel(t, model_error, MODEL_ERROR_TIME)
            parts["fast_model_error"] = (a @ solver @ a.T)[:p, :p]
        if jac.shape[0] > self.n_len:
            j_p = jac[self.n_len :]
            j_p = np.concatenate([j_p, np.zeros((j_p.shape[0], full.shape[0] - p))], axis=1)
            a_p = full @ j_p.T
            parts["pressure_noise"] = (a_p @ a_p.T)[:p, :p]
        gain = np.zeros((p, 0))
        if g is not None:
            gain = a[:p] @ g  # (p, q): the estimate's response to a rig error
            for j, name in enumerate(self.tolerance_names):
                u = float(self.tolerance[j])
                c = full[:p, p + j] / u if self.inferred else gain[:, j] * u
                parts[name] = np.outer(c, c)
        return sum(parts.values()), parts, gain

    def hyperparameter_spread(self, raw, hyper, cov, b) -> np.ndarray:
        """The covariance (p, p) of z that the hyperparameters' own uncertainty adds.

        On a grid around their mode (amplitude, time scale and noise, log-spaced; the noise's correlation time
        held at its mode, a nuisance the data pin down where it matters), each point h is weighted by
        its posterior given the data, θ integrated out by Laplace at the linearisation ``raw``: the
        log-likelihood at the Gauss–Newton optimum ẑ(h), −½ log det J̃ᵀJ̃ and the hyperparameters' prior. The
        spread is the weighted Σ_h [C(h) + (ẑ(h) − z̄)(ẑ(h) − z̄)ᵀ], z̄ the weighted mean, minus the covariance ``cov`` at the mode
        (floored at zero): a discrepancy whose amplitude the data leave open widens the interval as sampling
        over it would. With the rig inferred (``b`` its errors at the estimate) each point integrates b out too.
        """
        grid = _hyper_grid(hyper)
        logw, shift, c_h = (np.asarray(a) for a in _hyper_scan(self, *raw, grid, jnp.asarray(b)))
        logw = np.where(np.isfinite(logw), logw, -np.inf)
        w = np.exp(logw - np.max(logw))
        w /= w.sum()
        shift = shift - w @ shift  # about the mixture's mean: the point linearised at need not be the mode's optimum
        total = np.einsum("g,gij->ij", w, c_h + shift[:, :, None] * shift[:, None, :])
        spread = total - cov
        evals, evecs = np.linalg.eigh(0.5 * (spread + spread.T))
        return (evecs * np.clip(evals, 0.0, None)) @ evecs.T


HYPER_GRID = (
    np.geomspace(1e-3, 10.0, 13),
    np.geomspace(0.1, 10.0, 7),
    np.geomspace(0.5, 2.0, 3),
)  # × the mode (each holds it)


def _hyper_grid(hyper) -> dc.Hyper:
    a, ell, s = (np.ravel(x) for x in np.meshgrid(*HYPER_GRID, indexing="ij"))
    amp = np.maximum(float(hyper.amplitude), 1e-3 * float(hyper.noise)) * a
    return dc.Hyper(
        jnp.asarray(amp),
        jnp.asarray(float(hyper.time_scale) * ell),
        jnp.asarray(float(hyper.noise) * s),
        jnp.full(amp.shape, float(hyper.noise_time)),
    )


@eqx.filter_jit
def _hyper_scan(likelihood: Likelihood, r, jac, grid: dc.Hyper, b):
    """Per grid point: log weight, the Gauss–Newton shift of z, its covariance (p, p)."""
    p = jac.shape[1]
    cols, t = likelihood.length_columns(r, jac, b)

    def one(h):
        v, s, _, _ = dc.kalman_filter(cols, t, h, hoist=False)
        wr, wj = _stacked(likelihood, v / jnp.sqrt(s)[:, None], r, jac, b)
        info = wj.T @ wj
        c = jnp.linalg.pinv(info, hermitian=True)
        step = -c @ (wj.T @ wr)
        cost = 0.5 * (wr @ wr) - 0.5 * (wj.T @ wr) @ c @ (wj.T @ wr)
        logdet = jnp.linalg.slogdet(info)[1]  # b's prior normalisation is the same at every h
        loglik = -cost - 0.5 * jnp.sum(jnp.log(2.0 * jnp.pi * s)) - 0.5 * logdet
        return loglik + dc.log_prior(h), step[:p], c[:p, :p]

    return jax.vmap(one)(grid)


def _stacked(likelihood: Likelihood, w, r, jac, b):
    """Whitened residuals and Jacobian of w = (z[, b]) from the whitened length columns ``w``, the pressure rows
    after them and, when inferred, the rig's prior rows (centre + b)/u."""
    n, p = likelihood.n_len, jac.shape[1]
    if not likelihood.inferred:
        return jnp.concatenate([w[:, 0], r[n:]]), jnp.concatenate([w[:, 1:], jac[n:]], axis=0)
    u = likelihood.tolerance
    q = u.shape[0]
    prior = jnp.concatenate([jnp.zeros((q, p)), jnp.diag(1.0 / u)], axis=1)
    pressure = jnp.concatenate([jac[n:], jnp.zeros((jac.shape[0] - n, q))], axis=1)
    return (
        jnp.concatenate([w[:, 0], (likelihood.centre + b) / u, r[n:]]),
        jnp.concatenate([w[:, 1:], prior, pressure], axis=0),
    )


@eqx.filter_jit
def _augmented(likelihood: Likelihood, r, jac, hyper, b):
    cols, t = likelihood.length_columns(r, jac, b)
    return _stacked(likelihood, dc.whiten(cols, t, hyper), r, jac, b)


def _tolerance_sensitivity(problem: Problem, z, r0, tol: dict, central: bool = False) -> np.ndarray:
    """g (n, q): the length's change, m, per unit ln ψ of each toleranced parameter: the secant from ψ to ψ·e^u, u
    its tolerance, or the central one with ``central`` (:func:`growjax.calibration.tolerance.sensitivity`; through the fit's own compiled program, the base being one of its leaves; ``r0`` (n,) the
    residuals at z, in units of σ_L)."""
    n, scale = problem.times.size, float(problem.sigma_length)

    def residual_of(rig):  # m; the data cancel in the secant
        shifted = eqx.tree_at(lambda pr: pr.base, problem, rig)
        return np.asarray(_linearised(jnp.asarray(z), shifted)[0])[:n] * scale

    return tl.sensitivity(residual_of, problem.base, tol, reference=np.asarray(r0)[:n] * scale, central=central)


def _check_window(window, config: Config):
    """(t_start, t_end) s inside the configuration's span, or None; ValueError naming the problem."""
    if window is None:
        return None
    t0, t1 = (float(w) for w in window)
    if not (np.isfinite(t0) and np.isfinite(t1)) or t0 >= t1:
        raise ValueError(f"window must be (t_start, t_end) with t_start < t_end, got {window}")
    if t1 < config.t0 or t0 > config.t1:
        raise ValueError(f"window {window} s lies outside the simulated span [{config.t0}, {config.t1}] s")
    return t0, t1


def undetermined_directions(info, names) -> tuple[list, np.ndarray]:
    """The directions of z = ln θ the information ``info`` (p, p) leaves undetermined, as
    [{"eigenvalue", "direction": {name: loading}}], and which parameters (p,) bool load on any of them (> 0.1): an
    eigenvalue below 1e-10 of the largest, or below :data:`INFORMATION_FLOOR`."""
    evals, evecs = np.linalg.eigh(np.asarray(info, float))
    tol = max(1e-10 * float(evals[-1]), INFORMATION_FLOOR)
    low = [k for k in range(len(names)) if evals[k] < tol]
    blind = np.zeros(len(names), bool)
    for k in low:
        blind |= np.abs(evecs[:, k]) > 0.1
    return [{"eigenvalue": float(evals[k]), "direction": dict(zip(names, map(float, evecs[:, k])))} for k in low], blind


def _result(
    names,
    theta,
    z,
    cov,
    parts,
    info,
    hyper,
    likelihood,
    raw,
    starts,
    converged,
    bounds,
    start_clock,
    samples_used,
    kind,
) -> FitResult:
    evals, evecs = np.linalg.eigh(info)
    undetermined, blind = undetermined_directions(info, names)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(over="ignore"):  # an sd of ln θ in the hundreds: the interval's ends are 0 and inf
        interval = {
            n: (None if blind[i] else (float(theta[i] * np.exp(-Z90 * sd[i])), float(theta[i] * np.exp(Z90 * sd[i]))))
            for i, n in enumerate(names)
        }
    se = {n: (None if blind[i] else float(theta[i] * sd[i])) for i, n in enumerate(names)}
    budget = {
        n: {k: float(theta[i] * np.sqrt(max(part[i, i], 0.0))) for k, part in parts.items()}
        for i, n in enumerate(names)
    }
    r_len = np.asarray(raw[0])[: likelihood.n_len] * likelihood.sigma_length
    best = min(starts, key=lambda s: s["cost"])
    return FitResult(
        names=names,
        estimate=dict(zip(names, map(float, theta))),
        interval_90=interval,
        standard_error=se,
        rmse_length_m=float(np.sqrt(np.mean(r_len**2))),
        cost=float(best["cost"]),
        covariance_log=cov,
        eigenvalues=evals,
        eigenvectors=evecs,
        undetermined=undetermined,
        starts=starts,
        wall_s=time.perf_counter() - start_clock,
        status="converged" if converged else "max_steps",
        at_bound=tuple(n for n, zi, lo, hi in zip(names, z, *bounds) if min(zi - lo, hi - zi) < 1e-9),
        discrepancy={"kind": kind, **hyper.as_dict()},
        budget=budget,
        tolerances=dict(zip(likelihood.tolerance_names, map(float, np.asarray(likelihood.tolerance))))
        if likelihood.tolerance is not None
        else {},
        samples_used=samples_used,
    )


def physical_bounds(base: gp.Parameters, names, refs) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) of z = ln(θ/θ_ref) from each parameter's physical range (±inf where it has none)."""
    ranges = gp.physical_ranges(base)
    lo = np.full(len(names), -np.inf)
    hi = np.full(len(names), np.inf)
    for i, n in enumerate(names):
        if n in ranges:
            a, b = ranges[n][:2]
            lo[i] = np.log(a / refs[i]) if a > 0 else -np.inf
            hi[i] = np.log(b / refs[i]) if np.isfinite(b) else np.inf
    return lo, hi
