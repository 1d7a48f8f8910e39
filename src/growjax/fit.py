"""Gradient fits: least squares of the measured length (and pressure) through the differentiable model.

The free parameters are moved in log coordinates z = ln(θ/θ_ref), so every direction is
O(1) and positivity holds. Residuals are non-dimensional (length / σ_L, pressure / σ_P).
Levenberg–Marquardt (optimistix, forward-mode Jacobian) starts from the best sets of a
Latin-hypercube sweep (multi-start). At the optimum the Gauss–Newton covariance
s²(JᵀJ)⁺ gives intervals, and the eigen-directions of JᵀJ show what the data cannot pin down.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

from growjax import params as gp
from growjax import sweep as sw
from growjax.config import Config
from growjax.simulate import input_breaks, sample_times, simulate
from growjax._least_squares import levenberg_marquardt, linearise  # noqa: F401  (public through fit)
from growjax.trajectory import OK

# Multi-start boxes: the paper's investigation where it has one, else [θ/2, 2θ] around the reference.
PAPER_RANGES = {d.name: (d.low, d.high) for d in sw.paper_box()}
Z90 = float(stats.norm.ppf(0.95))
# The fast configuration's own error against the reference, carried into the intervals as a smooth,
# correlated residual: its size (m) and correlation time (s). Measured: worst RMSE 0.018 mm over the
# 32 shipped reference cases (benchmarks/agreement.py); 0.03 mm leaves a margin.
FAST_MODEL_ERROR = 3e-5
MODEL_ERROR_TIME = 0.5


def default_model_error(config: Config) -> float:
    """The fitted configuration's length error against the reference, m: :data:`FAST_MODEL_ERROR` for the
    fast configuration, 0 for the reference itself."""
    return FAST_MODEL_ERROR if config.fidelity == "fast" else 0.0

LM_TOLERANCE = 1e-6  # rtol = atol of the Levenberg–Marquardt stop, on ln θ and the cost


def default_range(base: gp.Parameters, name: str) -> tuple[float, float]:
    """Sampling box (SI) for a free parameter."""
    q = gp.resolve_name(base, name)
    if q in PAPER_RANGES:
        return PAPER_RANGES[q]
    v = float(gp.get(base, q))
    if v <= 0:
        raise ValueError(f"parameter {q} = {v} is not positive: only positive parameters can be fitted in log coordinates")
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

    def summary(self) -> dict:
        return {
            "status": self.status,
            "rmse_length_m": self.rmse_length_m,
            "parameters": {
                n: {"estimate": self.estimate[n], "standard_error": self.standard_error[n],
                    "interval_90": self.interval_90[n]}
                for n in self.names
            },
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
    sigma_length: float = eqx.field(static=True, default=1e-3)
    sigma_pressure: float = eqx.field(static=True, default=5e3)

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


def make_problem(base, names, inputs, config, times, length, pressure=None, window=None,
                 sigma_length=1e-3, sigma_pressure=5e3) -> Problem:
    """The :class:`Problem` for the parameters ``names`` on the data inside ``window`` (default: the config's)."""
    names = tuple(gp.resolve_name(base, n) for n in names)
    config = config.replace(adjoint="forward")
    refs = jnp.asarray([float(gp.get(base, n)) for n in names])
    t0, t1 = window if window is not None else (config.t0, config.t1)
    keep = (np.asarray(times) >= t0) & (np.asarray(times) <= t1)
    pick = (lambda a: None if a is None else jnp.asarray(np.asarray(a)[keep]))
    return Problem(base, inputs, refs, pick(times), pick(length), pick(pressure), input_breaks(inputs, config), names, config,
                   sigma_length, sigma_pressure)


@eqx.filter_jit
def _linearised(z, problem: Problem):
    """:func:`linearise` of the problem's residuals at z: the only compiled program of a fit."""
    return linearise(problem.residuals, z)


def fit(
    times,
    length,
    inputs,
    free: Sequence[str] = ("Y",),
    base: gp.Parameters | None = None,
    config: Config | None = None,
    pressure=None,
    window=None,
    n_starts: int = 3,
    sweep_n: int = 64,
    seed: int = 0,
    max_steps: int = 100,
    sigma_length: float = 1e-3,
    sigma_pressure: float = 5e3,
    model_error: float | None = None,
) -> FitResult:
    """Fit ``free`` parameters to a measured length (m) at ``times`` (s) (and ``pressure``, Pa, if given).

    Starts: the ``n_starts`` best of a ``sweep_n``-point Latin hypercube over each parameter's
    :func:`default_range` (``sweep_n=0``: one start, at the values in ``base``). Returns the best optimum
    over the starts.

    Intervals: Gauss–Newton s²(JᵀJ)⁻¹ for the measurement noise, plus the propagated model error:
    a smooth error δ(t) of the configuration against the reference (Gaussian process, sd
    ``model_error`` m, squared-exponential correlation over :data:`MODEL_ERROR_TIME`) moves the
    estimate by A δ, A = (JᵀJ)⁻¹Jᵀ, and adds A Σ_δ Aᵀ. Default: :data:`FAST_MODEL_ERROR` for the fast
    configuration, 0 for the reference. Being correlated, this error does not shrink with more data.
    """
    base = base if base is not None else gp.reference()
    config = (config if config is not None else Config()).replace(adjoint="forward")  # Jacobians by jvp
    names = tuple(gp.resolve_name(base, n) for n in free)
    refs = np.array([float(gp.get(base, n)) for n in names])
    if np.any(refs <= 0):
        raise ValueError(f"fitted parameters must be positive, got {dict(zip(names, refs))}")
    start_clock = time.perf_counter()

    if sweep_n < 0 or n_starts < 1:
        raise ValueError(f"sweep_n must be >= 0 and n_starts >= 1, got {sweep_n} and {n_starts}")
    if sweep_n == 0:  # no scouting sweep: start at the given values
        start_values, order = refs[None, :], [0]
    else:
        dims = [sw.Dimension(n, *default_range(base, n), log=True) for n in names]
        measured = (np.asarray(times), np.asarray(length))
        scout = sw.lhs_sweep(sweep_n, base, inputs, config, dims, seed=seed, measured=measured, window=window)
        start_values = scout.values
        order = [i for i in np.argsort(np.nan_to_num(scout.rmse, nan=np.inf)) if scout.status[i] == OK][:n_starts]
        if not order:
            raise RuntimeError("no start of the multi-start sweep simulated successfully")

    problem = make_problem(base, names, inputs, config, times, length, pressure, window,
                           sigma_length, sigma_pressure)
    z0s = jnp.log(jnp.asarray(start_values[order]) / refs)
    # One start after another through one compiled solver: under vmap every start would pay for the
    # slowest one's iterations and for both branches of each accept/reject decision.
    # Stop when a step moves ln θ by < 1e-6 and the cost by < 1e-6 of itself (far inside any interval), or at
    # the solver's noise floor in the residuals (see levenberg_marquardt: tighter only burns iterations).
    bounds = physical_bounds(base, names, refs)
    solved = [levenberg_marquardt(lambda z: _linearised(z, problem), z0, max_steps, LM_TOLERANCE, bounds=bounds)
              for z0 in z0s]
    zs, costs, oks = (np.asarray([s[k] for s in solved]) for k in range(3))
    starts = [{"start": dict(zip(names, map(float, start_values[i]))),
               "estimate": dict(zip(names, map(float, refs * np.exp(zs[k])))),
               "cost": float(costs[k]), "converged": bool(oks[k])} for k, i in enumerate(order)]
    k_best = int(np.argmin(costs))
    z = jnp.asarray(zs[k_best])
    best = starts[k_best]

    r, jac = (np.asarray(a) for a in solved[k_best][3:])
    m, p = jac.shape
    dof = max(m - p, 1)
    s2 = float(np.sum(r**2) / dof)
    jtj = jac.T @ jac
    evals, evecs = np.linalg.eigh(jtj)
    tol = 1e-10 * max(float(evals[-1]), 1e-300)
    cov = s2 * np.linalg.pinv(jtj, rcond=1e-10, hermitian=True)
    theta = refs * np.exp(np.asarray(z))
    undetermined = [
        {"eigenvalue": float(evals[k]), "direction": dict(zip(names, map(float, evecs[:, k])))}
        for k in range(p) if evals[k] < tol
    ]
    blind = np.zeros(p, bool)
    for k in range(p):
        if evals[k] < tol:
            blind |= np.abs(evecs[:, k]) > 0.1
    if model_error is None:
        model_error = default_model_error(config)
    if model_error > 0:
        t_fit = np.asarray(problem.times)
        n_fit = t_fit.size
        gap = t_fit[:, None] - t_fit[None, :]
        sigma_delta = (model_error / sigma_length) ** 2 * np.exp(-0.5 * (gap / MODEL_ERROR_TIME) ** 2)
        a = np.linalg.pinv(jtj, rcond=1e-10, hermitian=True) @ jac[:n_fit].T  # (p, n) on the length rows
        cov = cov + a @ sigma_delta @ a.T
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    interval = {n: (None if blind[i] else (float(theta[i] * np.exp(-Z90 * sd[i])), float(theta[i] * np.exp(Z90 * sd[i]))))
                for i, n in enumerate(names)}
    se = {n: (None if blind[i] else float(theta[i] * sd[i])) for i, n in enumerate(names)}
    n_len = int(np.sum((np.asarray(times) >= (window or (config.t0, config.t1))[0])
                       & (np.asarray(times) <= (window or (config.t0, config.t1))[1])))
    rmse = float(np.sqrt(np.mean((r[:n_len] * sigma_length) ** 2)))
    return FitResult(
        names=names, estimate=dict(zip(names, map(float, theta))), interval_90=interval, standard_error=se,
        rmse_length_m=rmse, cost=float(best["cost"]), covariance_log=cov, eigenvalues=evals, eigenvectors=evecs,
        undetermined=undetermined, starts=starts, wall_s=time.perf_counter() - start_clock,
        status="converged" if best["converged"] else "max_steps",
        at_bound=tuple(n for n, zi, lo, hi in zip(names, np.asarray(z), *bounds) if min(zi - lo, hi - zi) < 1e-9),
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
