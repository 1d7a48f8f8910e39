"""Joint fits of an experiment set: free parameters scoped per robot, rig, run or shared, one set of rig errors
per rig, each run with its own discrepancy.

The likelihood of a set is that of :func:`growjax.calibration.fit.fit` run by run, the runs independent given the
parameters and the rig: each run's length is its model plus its own smooth discrepancy plus sensor noise
(hyperparameters per run: the inputs excite different model errors, and the sensors differ), and the rig's
relative errors b (one vector per rig, prior N(0, u²) from the tolerance budget) enter every run on that rig
through its linearised sensitivity g = ∂L/∂ln ψ. Shared errors do not average out over runs; with
``rig_errors="experiment"`` each run draws its own, the treatment that takes repeated runs for independent
evidence about the rig's effect (and under-covers where they share one rig).

The runs' simulations and Jacobians run batched: runs with the same drive, sample count and input structure are
stacked (breaks padded to a common length) and solved by one ``vmap``-ed program, its runs spread over the
process's devices where it has several (:func:`_spread`); the Jacobian of each run is
taken in its own parameters (by default its θ and its rig's errors, exact tangents of one solve) and scattered into
the set's columns; the starts' scout (and, with ``rig_tangents=False``, the rig's secants) run the residuals
alone.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from growjax.calibration import discrepancy as dc
from growjax.calibration import fit as gf
from growjax.calibration import tolerance as tl
from growjax.calibration.least_squares import levenberg_marquardt, linearise, memoised
from growjax.data import experiment as ex
from growjax.data.sets import ExperimentSet, Scope
from growjax.model import params as gp
from growjax.simulation.config import Config

RIG_ERRORS = ("shared", "experiment")
# With rig_tangents=False the rig's secants are taken again where the fit puts the rig (at most this many
# linearisations, until its errors move by less than this share of their tolerance): with three or more runs on one
# rig the data pull its errors a good part of a tolerance from nominal, where the secants taken at nominal bias
# every robot's Y alike by several standard errors unless the rig is let settle. Taken again, they are central
# secants, the slope where the rig now is: a one-sided secant's slope belongs half a tolerance away, and the rig
# would drift past its optimum step after step.
RELINEARISE_STEPS = 8
RELINEARISE_TOLERANCE = 0.02


@dataclasses.dataclass
class SetFitResult:
    """Outcome of a joint fit. A coordinate is labelled ``NAME`` (shared) or ``NAME@KEY`` (its robot's, rig's or
    run's copy); values SI; ``interval_90`` None where the data do not determine it."""

    labels: tuple
    estimate: dict
    interval_90: dict
    standard_error: dict
    budget: dict  # {label: {source: sd, SI}}
    covariance_log: np.ndarray  # (P, P) in z = ln θ
    runs: list  # per run: name, robot, rig, rmse_length_m, discrepancy, samples_used
    rig: str  # "inferred", "fixed" or "none"
    rig_errors: str
    rig_offset: dict  # {rig key: {tolerance: fitted ln(ψ/ψ₀)}} when inferred
    tolerances: dict
    cost: float
    status: str
    wall_s: float
    simulate_s: float  # of which in the batched simulations and Jacobians
    programs: int = 1  # batched groups of runs: one compiled program each
    rig_labels: tuple = ()  # (Q,) (rig key, tolerance name) of the fitted rig errors b, when inferred
    rig_vector: np.ndarray | None = None  # (Q,) fitted b = ln(ψ/ψ₀)
    joint_covariance: np.ndarray | None = None  # (P + Q, P + Q) of (z, b), the z block as covariance_log
    linearisations: int = 1  # of the rig's sensitivities (see RELINEARISE_STEPS)
    rig_last_move: float = 0.0  # the rig's largest move in the last linearisation, in tolerances
    log_likelihood: float = float("nan")  # nats: the set's total at the fit (rig marginalised)
    # per run (times (n,) s, length residual (n,) m, the rig at its fitted errors)
    residuals: list = dataclasses.field(default_factory=list, repr=False)

    @property
    def rig_settled(self) -> bool:
        """Whether the rig's errors stopped moving (by ≤ RELINEARISE_TOLERANCE of a tolerance) before the cap."""
        return self.rig_last_move <= RELINEARISE_TOLERANCE

    def summary(self) -> dict:
        return {
            "status": self.status,
            "rig": self.rig,
            "rig_errors": self.rig_errors,
            "parameters": {
                k: {
                    "estimate": self.estimate[k],
                    "standard_error": self.standard_error[k],
                    "interval_90": self.interval_90[k],
                    "budget_sd": self.budget.get(k),
                }
                for k in self.labels
            },
            "runs": self.runs,
            "rig_offset": self.rig_offset,
            "tolerances": self.tolerances,
            "cost": self.cost,
            "wall_s": self.wall_s,
            "simulate_s": self.simulate_s,
            "programs": self.programs,
            "linearisations": self.linearisations,
            "rig_settled": self.rig_settled,
            "rig_last_move": self.rig_last_move,
        }


@dataclasses.dataclass(frozen=True)
class _Layout:
    """Where each run's parameters and rig errors sit among the set's coordinates."""

    index: np.ndarray  # (E, p) int: run e's parameter i is coordinate index[e, i]
    offset: np.ndarray  # (E, p): run e's z_i = z[index] + offset (its own reference)
    rig_index: np.ndarray  # (E, q) int: run e's rig error j is b[rig_index[e, j]]
    labels: tuple  # (P,)
    refs: np.ndarray  # (P,) SI
    rig_labels: tuple  # (Q,) (rig key, tolerance name)


def fit_set(
    experiments: ExperimentSet,
    free: Sequence[str] = ("Y@robot",),
    config: Config | None = None,
    n_starts: int = 1,
    sweep_n: int = 16,
    seed: int = 0,
    max_steps: int = 100,
    sigma_length: float = 1e-3,
    sigma_pressure: float = 5e3,
    model_error: float | None = None,
    discrepancy: str = "matern32",
    tolerances: dict | None = None,
    rig: str = "inferred",
    rig_errors: str = "shared",
    effects: Sequence = (),
    rig_tangents: bool = True,
) -> SetFitResult:
    """Fit the ``free`` parameters (``NAME`` shared, ``NAME@robot|rig|experiment`` one per robot, rig or run) to
    every run of ``experiments`` at once.

    ``config``: the simulation's settings (its drive is taken from each run). Starts: the ``n_starts`` best of a
    ``sweep_n``-point Latin hypercube over the free names (every copy at the same value; 0: the runs' values).
    ``discrepancy``, ``tolerances``, ``rig``, ``model_error``: as in :func:`growjax.calibration.fit.fit`, run by run;
    ``rig_errors``: ``"shared"`` (one error vector per rig) or ``"experiment"`` (one per run). ``effects``:
    :class:`growjax.Effect` instances added to every run's parameters at their given values (an effect's parameter
    can then be freed by name, e.g. ``fluid_leak.conductance@robot``, and starts there).

    ``rig_tangents`` (default), with the rig inferred: the rig's errors are parameters of every run's model beside
    its θ, their sensitivities the solver's exact tangents in the same batched solve (as
    :func:`growjax.calibration.fit.fit`): least squares of z with the rig nominal, then of (z, b) with b's prior rows, then
    generalised least squares of (z, b). False: secants of the rig taken apart and relinearised where the data put
    the rig (at most :data:`RELINEARISE_STEPS` linearisations).
    """
    if discrepancy not in dc.KINDS:
        raise ValueError(f"discrepancy must be one of {dc.KINDS}, got {discrepancy!r}")
    if rig not in gf.RIG_TREATMENTS:
        raise ValueError(f"rig must be one of {gf.RIG_TREATMENTS}, got {rig!r}")
    if rig_errors not in RIG_ERRORS:
        raise ValueError(f"rig_errors must be one of {RIG_ERRORS}, got {rig_errors!r}")
    clock = time.perf_counter()
    config = (config if config is not None else Config()).replace(adjoint="forward")
    runs = list(experiments)
    bases = [gp.with_effects(r.base(), *effects) if effects else r.base() for r in runs]
    scopes = [s if isinstance(s, Scope) else Scope.parse(s, bases[0]) for s in free]
    names = tuple(s.name for s in scopes)
    if len(set(names)) != len(names):
        raise ValueError(f"a parameter is freed twice: {list(free)}")
    tol = tl.budget(bases[0], tolerances, names, use_default=tolerances is None and discrepancy != "none")
    tangents = rig_tangents and rig == "inferred" and bool(tol)
    modelled = names + tuple(tol) if tangents else names  # the parameters each run's model is solved in
    problems, likelihoods = [], []
    for run, base in zip(runs, bases):
        cfg = config.replace(drive=run.drive)
        inputs = ex.to_inputs(run.experiment, run.drive, base, cfg.t0, cfg.t1)
        pr = gf.make_problem(
            base, modelled, inputs, cfg, run.times, run.length, run.pressure, run.window, sigma_length, sigma_pressure
        )
        if pr.times.size < 2:
            raise ValueError(f"experiment {run.name!r}: fewer than two samples inside the window")
        n = int(pr.times.size)
        used = ex.informative_samples(np.asarray(pr.length)) if discrepancy != "none" else np.ones(n, bool)
        problems.append(pr)
        likelihoods.append(
            gf.Likelihood(pr.times, jnp.asarray(used), jnp.asarray(np.flatnonzero(used)), sigma_length, n)
        )
    layout = _layout(experiments, scopes, bases, problems, tol, rig_errors)
    batch = _Batch(problems, rig_in_model=tangents)
    bounds = _bounds(bases[0], layout)
    z0s = _starts(batch, layout, likelihoods, bases[0], names, n_starts, sweep_n, seed)
    solved = [
        levenberg_marquardt(
            lambda z: _weighted(batch.linearised(z, layout), likelihoods, layout),
            z0,
            max_steps,
            gf.LM_TOLERANCE,
            bounds=bounds,
        )
        for z0 in z0s
    ]
    k_best = int(np.argmin([s[1] for s in solved]))
    z, converged = np.asarray(solved[k_best][0]), bool(solved[k_best][2])
    model_error = gf.default_model_error(config) if model_error is None else model_error
    if tangents:
        return _fit_tangents(
            batch,
            layout,
            likelihoods,
            tol,
            z,
            bounds,
            discrepancy,
            max_steps,
            model_error,
            runs,
            rig_errors,
            clock,
            bases[0],
        )
    plain = likelihoods
    centre = np.zeros(len(layout.rig_labels) if tol and rig == "inferred" else 0)  # rig point of linearisation
    b, hypers = centre.copy(), [None] * len(runs)
    linearisations = 0
    for step in range(RELINEARISE_STEPS):
        linearisations += 1
        sensitivities = batch.sensitivities(z, layout, tol, central=step > 0) if tol else None
        if sensitivities is not None and rig == "inferred":
            likelihoods = [lik.with_tolerances(g, tol, inferred=True) for lik, g in zip(plain, sensitivities)]
        z, b, hypers, cost, converged = _gls(
            batch, layout, likelihoods, hypers, z, b - centre, centre, bounds, discrepancy, max_steps
        )
        b = centre + b
        move = float(np.max(np.abs(b - centre) / _rig_sd(likelihoods, layout))) if centre.size else 0.0
        if centre.size == 0 or step == RELINEARISE_STEPS - 1 or move <= RELINEARISE_TOLERANCE:
            break
        centre = b.copy()  # the rig's errors moved: take the sensitivities again where the data put the rig
        spent = batch.simulate_s
        batch = _Batch([gf.problem_at_rig(pr, tol, centre[layout.rig_index[e]]) for e, pr in enumerate(problems)])
        batch.simulate_s = spent
    outs = batch.linearised(z, layout)
    if tol and rig == "fixed":
        likelihoods = [lik.with_tolerances(g, tol) for lik, g in zip(likelihoods, sensitivities)]
    result = _finish(
        z,
        b,
        centre,
        outs,
        likelihoods,
        layout,
        hypers,
        model_error,
        tol,
        rig,
        rig_errors,
        runs,
        cost,
        converged,
        clock,
        batch,
    )
    result.linearisations = linearisations
    result.rig_last_move = move
    return result


def _finish(
    z,
    b,
    centre,
    outs,
    likelihoods,
    layout: _Layout,
    hypers,
    model_error: float,
    tol: dict,
    rig: str,
    rig_errors: str,
    runs,
    cost,
    converged,
    clock,
    batch,
) -> SetFitResult:
    """The result of a joint fit at z (P,) with the rig's errors b (Q,), the runs (``outs``, ``likelihoods``)
    linearised with the rig at ``centre`` (Q,): covariance and budget, the set's log-likelihood, each run's
    residual with the rig at b."""
    cov, parts, info, joint = _covariance(outs, likelihoods, layout, hypers, b - centre, model_error, tol, rig, centre)
    result = _result(
        z,
        b,
        cov,
        parts,
        info,
        outs,
        likelihoods,
        layout,
        hypers,
        runs,
        tol,
        rig,
        rig_errors,
        cost,
        converged,
        clock,
        batch.simulate_s,
        centre,
    )
    result.programs = len(batch.groups)
    result.log_likelihood = _set_log_likelihood(outs, likelihoods, layout, hypers, centre, rig if tol else "none")
    result.residuals = [
        (
            np.asarray(lik.times),
            np.asarray(r[: lik.n_len]) * lik.sigma_length
            + (np.asarray(lik.sensitivity) @ (b - centre)[layout.rig_index[e]] if lik.inferred else 0.0),
        )
        for e, ((r, _), lik) in enumerate(zip(outs, likelihoods))
    ]
    if joint is not None:
        result.rig_labels, result.rig_vector, result.joint_covariance = tuple(layout.rig_labels), np.asarray(b), joint
    return result


def _on_z(outs, p: int):
    """Each run's (r, J) with J's columns cut to its θ (the first ``p``; the rig's errors' tangents after them)."""
    return [(r, jac[:, :p]) for r, jac in outs]


def _fit_tangents(
    batch: _Batch,
    layout: _Layout,
    plain,
    tol: dict,
    z,
    bounds,
    discrepancy: str,
    max_steps: int,
    model_error: float,
    runs,
    rig_errors: str,
    clock,
    base,
) -> SetFitResult:
    """The set's fit from z (P,) (least squares with the rig nominal) with the rig's errors b (Q,) among the runs'
    model parameters: least squares of w = (z, b) with b's prior rows b/u (from
    :func:`growjax.calibration.fit.rig_stage_starts` in ``base``'s sampling box), then generalised least squares of w
    alternating with each run's hyperparameters, every run linearised at w with its rig's exact tangents there (as
    :func:`growjax.calibration.fit._solve_tangents`, run by run)."""
    p, p_all, q_all = layout.index.shape[1], len(layout.labels), len(layout.rig_labels)
    u = np.array([tol[name] for _, name in layout.rig_labels])
    prior = np.concatenate([np.zeros((q_all, p_all)), np.diag(1.0 / u)], axis=1)
    w_bounds = gf.with_rig_bounds(bounds, q_all)

    def independent(w):
        r, jac = _weighted(batch.linearised(w, layout), plain, layout, q_all)
        return np.concatenate([r, np.asarray(w)[p_all:] / u]), np.concatenate([jac, prior])

    box = gf.sampling_box(base, [lab.split("@")[0] for lab in layout.labels], layout.refs)
    w, _, converged, _, _ = min(
        (
            levenberg_marquardt(
                independent, np.concatenate([z0, np.zeros(q_all)]), max_steps, gf.LM_TOLERANCE, bounds=w_bounds
            )
            for z0 in gf.rig_stage_starts(z, box)
        ),
        key=lambda run: run[1],
    )

    def at(w):  # each run linearised at w: its likelihood with the rig's tangents there, and (r, J_θ)
        outs = batch.linearised(w, layout)
        b = np.asarray(w)[p_all:]
        liks = [
            lik.with_tolerances(
                np.asarray(jac)[: lik.n_len, p:] * lik.sigma_length, tol, inferred=True, centre=b[layout.rig_index[e]]
            )
            for e, (lik, (_, jac)) in enumerate(zip(plain, outs))
        ]
        return liks, _on_z(outs, p), b

    def whitened(w, hs):
        liks, outs, b = at(w)
        return _whitened(outs, liks, layout, hs, np.zeros(q_all), b)

    def hyper_at(w, hs):
        liks, outs, _ = at(w)
        return _estimates(liks, outs, discrepancy, hs)

    w, hypers, cost, converged = gf.alternate_gls(whitened, hyper_at, w, w_bounds, max_steps, tuple([None] * len(runs)))
    likelihoods, outs, b = at(w)
    return _finish(
        np.asarray(w)[:p_all],
        b,
        b,
        outs,
        likelihoods,
        layout,
        list(hypers),
        model_error,
        tol,
        "inferred",
        rig_errors,
        runs,
        cost,
        converged,
        clock,
        batch,
    )


def _estimates(likelihoods, outs, discrepancy: str, hypers) -> tuple:
    """Each run's hyperparameters at their mode given its residuals in ``outs``, from ``hypers``."""
    return tuple(lik.estimate(r, discrepancy, h) for lik, (r, _), h in zip(likelihoods, outs, hypers))


def _set_log_likelihood(outs, likelihoods, layout: _Layout, hypers, centre, rig: str) -> float:
    """The set's total log-likelihood (nats) at the runs' residuals ``outs``: each run's length under its own
    discrepancy and noise (hyperparameters ``hypers``, at their mode), the rig's errors marginalised under their
    priors (``rig="inferred"``: one error vector per rig shared by its runs, :func:`growjax.calibration.discrepancy.
    log_likelihood_runs`, the runs linearised at the rig's errors ``centre``; ``"fixed"``: each run's own), the
    pressure rows independent normal. What the joint fit maximises, up to a constant, profiled over the rig's errors;
    the score of a nested comparison of two fits of one set."""
    total = 0.0
    rows = []
    for e, ((r, _), lik, h) in enumerate(zip(outs, likelihoods, hypers)):
        r = np.asarray(r)
        n, idx = lik.n_len, np.asarray(lik.index)
        r_len = r[:n] * lik.sigma_length
        g = None if lik.sensitivity is None else np.asarray(lik.sensitivity)
        if lik.inferred:
            r_len = r_len - g @ np.asarray(centre)[layout.rig_index[e]]  # the errors' prior is centred on nominal
        rows.append((r_len[idx], np.asarray(lik.times)[idx], None if g is None else g[idx], h))
        r_p = r[n:]  # pressure, in units of its sd
        if r_p.size:
            total += float(-0.5 * np.sum(r_p**2) - r_p.size * 0.5 * np.log(2.0 * np.pi))
    if rig == "inferred":
        q = len(likelihoods[0].tolerance_names)
        size = max(x[0].size for x in rows)
        pad = lambda a, fill: np.concatenate([a, np.full((size - a.shape[0], *a.shape[1:]), fill)])  # noqa: E731
        times = [np.concatenate([t, t[-1] + 1e-3 * np.arange(1, size - t.size + 1)]) for _, t, _, _ in rows]
        rig_of = layout.rig_index[:, 0] // q
        hyper = jax.tree_util.tree_map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *[x[3] for x in rows])
        total += float(
            _log_likelihood_runs(
                jnp.asarray(np.stack([pad(x[0], 0.0) for x in rows])),
                jnp.asarray(np.stack(times)),
                hyper,
                jnp.asarray(np.stack([pad(x[2], 0.0) for x in rows])),
                jnp.asarray(likelihoods[0].tolerance),
                jnp.asarray(np.stack([np.arange(size) < x[0].size for x in rows])),
                jnp.asarray(rig_of),
                int(rig_of.max()) + 1,
            )
        )
        return total
    for (r_e, t_e, g_e, h), lik in zip(rows, likelihoods):
        marginal = rig == "fixed" and g_e is not None
        total += float(
            _log_likelihood(
                jnp.asarray(r_e),
                jnp.asarray(t_e),
                h,
                jnp.asarray(g_e) if marginal else None,
                jnp.asarray(lik.tolerance) if marginal else None,
            )
        )
    return total


_log_likelihood = jax.jit(dc.log_likelihood)
_log_likelihood_runs = jax.jit(dc.log_likelihood_runs, static_argnums=7)


def _gls(batch, layout: _Layout, likelihoods, hypers, z, b, centre, bounds, discrepancy: str, max_steps: int):
    """Alternate each run's hyperparameter mode and the whitened Gauss–Newton fit of (z, b), b the rig's errors
    from ``centre``. Returns (z, b, hypers, cost, converged)."""
    p_all = z.size

    def hyper_at(w, hs):
        return _estimates(likelihoods, batch.linearised(w[:p_all], layout), discrepancy, hs)

    w, hypers, cost, converged = gf.alternate_gls(
        lambda w, hs: _whitened(batch.linearised(w[:p_all], layout), likelihoods, layout, hs, w[p_all:], centre),
        hyper_at,
        np.concatenate([z, b]),
        gf.with_rig_bounds(bounds, b.size),
        max_steps,
        tuple(hypers),
    )
    return w[:p_all], w[p_all:], list(hypers), cost, converged


def _layout(experiments: ExperimentSet, scopes, bases, problems, tol: dict, rig_errors: str) -> _Layout:
    runs, p = list(experiments), len(scopes)
    labels, refs, index = [], [], np.zeros((len(runs), p), int)
    for i, s in enumerate(scopes):
        keys = experiments.group_of(s.scope)
        for key in dict.fromkeys(keys):
            first = keys.index(key)
            labels.append(s.name if s.scope == "shared" else f"{s.name}@{key}")
            refs.append(float(gp.get(bases[first], s.name)))
            for e, k in enumerate(keys):
                if k == key:
                    index[e, i] = len(labels) - 1
    refs = np.asarray(refs)
    if np.any(refs <= 0):
        raise ValueError(f"fitted parameters must be positive, got {dict(zip(labels, refs))}")
    offset = np.log(refs[index] / np.stack([np.asarray(pr.refs)[:p] for pr in problems]))
    rig_keys = experiments.group_of("rig" if rig_errors == "shared" else "experiment")
    rig_labels, rig_index = [], np.zeros((len(runs), len(tol)), int)
    for key in dict.fromkeys(rig_keys):
        for j, t in enumerate(tol):
            rig_labels.append((key, t))
            for e, k in enumerate(rig_keys):
                if k == key:
                    rig_index[e, j] = len(rig_labels) - 1
    return _Layout(index, offset, rig_index, tuple(labels), refs, tuple(rig_labels))


class _Batch:
    """The runs' problems stacked in groups that one compiled program solves (same configuration and input
    structure): the inputs' break lists padded to a common length, and the samples to a common count with a pressure
    record for every run where one run has it; each run's outputs cut back to its own rows."""

    def __init__(self, problems, rig_in_model: bool = False):
        self.size = len(problems)
        self.rig_in_model = rig_in_model  # each run's model parameters: its θ, then its rig's errors
        self.sigma_length = float(problems[0].sigma_length)
        self.n_len = [int(pr.times.size) for pr in problems]
        problems, self.rows = _pad_samples(_pad_breaks(problems))
        groups: dict = {}
        for e, pr in enumerate(problems):
            leaves, tree = jax.tree_util.tree_flatten(pr)
            key = (tree, tuple(np.shape(x) for x in leaves))
            groups.setdefault(key, []).append(e)
        self.groups = [(members, _stack([problems[e] for e in members])) for members in groups.values()]
        self.simulate_s = 0.0
        self._at = memoised(lambda z, layout: self._run(_linearise_runs, z, layout))

    def linearised(self, z, layout: _Layout, stacked=None):
        """[(r (m_e,), J (m_e, p))] per run at the set's coordinates z (P,) (the last few points kept: the fit asks
        for a point again where one solver's end is the next one's start). With the rig's errors in the model
        (``rig_in_model``), z may be w = (z, b) (P + Q,) and J is (m_e, p + q)."""
        if stacked is None:
            return self._at(z, layout)
        return self._run(_linearise_runs, z, layout, stacked)

    def residuals(self, z, layout: _Layout, stacked=None):
        """[(r (m_e,), None)] per run at the set's coordinates z (P,): the runs alone, no tangents."""
        return self._run(_residuals_runs, z, layout, stacked)

    def residuals_at(self, zs, layout: _Layout):
        """[[(r (m_e,), None)] per run] per point of ``zs`` (K, P): every run at every point in one call of the
        runs' program per group (K copies of each run)."""
        clock = time.perf_counter()
        k = len(zs)
        z_local = [self._local(z, layout) for z in zs]
        out = [[None] * self.size for _ in range(k)]
        for members, problem in self.groups:
            copies = jax.tree_util.tree_map(lambda x: jnp.concatenate([x] * k), problem)
            z_all = np.concatenate([z[members] for z in z_local])
            r = np.asarray(_spread(_residuals_runs, jnp.asarray(z_all), copies)[0])
            for j in range(k):
                for i, e in enumerate(members):
                    out[j][e] = (r[j * len(members) + i][self.rows[e]], None)
        self.simulate_s += time.perf_counter() - clock
        return out

    def _local(self, z, layout: _Layout) -> np.ndarray:
        """Each run's model coordinates (E, p) (with the rig in the model, (E, p + q)) at the set's z (P,) or w."""
        p_all = len(layout.labels)
        z_local = np.asarray(z)[:p_all][layout.index] + layout.offset
        if self.rig_in_model:  # w = (z, b): each run's rig errors after its θ (b = 0 when only z given)
            b = np.asarray(z)[p_all:] if np.size(z) > p_all else np.zeros(len(layout.rig_labels))
            z_local = np.concatenate([z_local, b[layout.rig_index]], axis=1)
        return z_local

    def _run(self, program, z, layout: _Layout, stacked=None):
        clock = time.perf_counter()
        z_local = self._local(z, layout)
        out = [None] * self.size
        for k, (members, problem) in enumerate(self.groups):
            pr = problem if stacked is None else stacked[k]
            results = tuple(
                None if x is None else np.asarray(x) for x in _spread(program, jnp.asarray(z_local[members]), pr)
            )
            for i, e in enumerate(members):
                out[e] = tuple(None if x is None else x[i][self.rows[e]] for x in results)
        self.simulate_s += time.perf_counter() - clock
        return out

    def sensitivities(self, z, layout: _Layout, tol: dict, central: bool = False) -> list:
        """Per run g (n_e, q): the length's change, m, per unit ln ψ of each toleranced parameter (the secant from
        ψ to ψ·e^u, or with ``central`` from ψ·e^(−u/2) to ψ·e^(u/2), as :func:`growjax.calibration.tolerance.sensitivity`;
        every run of a group in one batched solve)."""
        cols = [[] for _ in range(self.size)]
        lo_hi = (-0.5, 0.5) if central else (0.0, 1.0)
        r0 = None if central else self.residuals(z, layout)
        for name, u in tol.items():
            ends = []
            for f in lo_hi:
                if f == 0.0:
                    ends.append(r0)
                    continue
                shifted = [
                    eqx.tree_at(
                        lambda pr: pr.base,
                        problem,
                        gp.replace(problem.base, **{name: gp.get(problem.base, name) * np.exp(f * u)}),
                    )
                    for _, problem in self.groups
                ]
                ends.append(self.residuals(z, layout, shifted))
            for e in range(self.size):
                n = self.n_len[e]
                cols[e].append((ends[1][e][0][:n] - ends[0][e][0][:n]) * self.sigma_length / u)
        g = [np.stack(c, axis=1) for c in cols]
        if not all(np.all(np.isfinite(x)) for x in g):
            raise RuntimeError("the model failed while measuring the rig's tolerance sensitivities")
        return g


# The runs of a program follow one another (``jax.lax.map``), each with its own adaptive steps: vmapped, every run
# would keep step with the slowest (a linearisation of benchmarks/set_speed.py's eight 10 s runs on two cores:
# 0.61 s mapped, 0.75 s vmapped).


def _linearise_runs(z_local, problems: gf.Problem):
    """Residuals (E, m) and Jacobians (E, m, p) of stacked problems: each run's forward-mode linearisation, one run
    after another in one program."""
    return jax.lax.map(lambda a: linearise(a[1].residuals, a[0]), (z_local, problems))


def _residuals_runs(z_local, problems: gf.Problem):
    """Residuals (E, m) of stacked problems, and None for the Jacobian: the runs one after another in one
    program."""
    return jax.lax.map(lambda a: a[1].residuals(a[0]), (z_local, problems)), None


@eqx.filter_jit
def _one_device(program, z_local, problems: gf.Problem):
    """``program`` on the E stacked runs as one program on the default device."""
    return program(z_local, problems)


def _spread(program, z_local, problems: gf.Problem):
    """``program`` (:func:`_linearise_runs` or :func:`_residuals_runs`) on the E stacked runs, spread over the
    process's devices: each device solves its share of the runs in one program (``jax.shard_map``). On a CPU with
    several cores exposed as devices (``jax_num_cpu_devices``) the shares run on different cores at once. With one
    run, or one device, it is the program itself."""
    n = int(z_local.shape[0])
    d = min(len(jax.devices()), n)
    if d < 2:
        return _one_device(program, z_local, problems)
    arrays, static = eqx.partition(problems, eqx.is_array)
    size = -(-n // d) * d
    if size > n:  # padded with copies of the first run to fill every device's share
        take = jnp.asarray(np.r_[np.arange(n), np.zeros(size - n, dtype=int)])
        z_local, arrays = z_local[take], jax.tree_util.tree_map(lambda x: x[take], arrays)
    out = _spread_compiled(program, _mesh(d), static, z_local, arrays)
    return out if size == n else jax.tree_util.tree_map(lambda x: x[:n], out)


@functools.cache
def _mesh(d: int):
    return jax.sharding.Mesh(np.asarray(jax.devices()[:d]), ("runs",))


@eqx.filter_jit
def _spread_compiled(program, mesh, static, z_local, arrays):
    def share(z, a):
        return program(z, eqx.combine(a, static))

    runs = jax.sharding.PartitionSpec("runs")
    # check_vma off: the solver's loop starts from constants that are the same on every device
    return jax.shard_map(share, mesh=mesh, in_specs=runs, out_specs=runs, check_vma=False)(z_local, arrays)


def _stack(problems):
    return jax.tree_util.tree_map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *problems)


def _pad_breaks(problems):
    """Problems of one configuration with their break lists padded to the longest (beyond t1: never reached)."""
    out = list(problems)
    for members in _by_config(problems):
        sizes = [max(problems[e].breaks[k].size for e in members) for k in range(2)]
        for e in members:
            pr = problems[e]
            padded = tuple(
                jnp.concatenate([b, jnp.full(s - b.size, pr.config.t1 + 1.0)]) for b, s in zip(pr.breaks, sizes)
            )
            out[e] = eqx.tree_at(lambda p: p.breaks, pr, padded)
    return out


def _by_config(problems) -> list:
    """The indices of the problems, grouped by configuration (a group may share one compiled program)."""
    groups: dict = {}
    for e, pr in enumerate(problems):
        groups.setdefault(pr.config, []).append(e)
    return list(groups.values())


def _pad_samples(problems):
    """Problems of one configuration padded to one row layout, and the rows (indices) each keeps of it.

    The samples are padded to the most of any run (the last one repeated: a copy of a saved point), and where one
    run records the pressure every run gets a pressure record (zeros where it has none). A padded run's residuals
    are (M,) or (2M,): its own rows are its first m_e, then (with the pressure) M to M + m_e. Runs measured alike
    and runs with and without the pressure sensor are then one compiled program instead of one per shape.
    """
    out, rows = list(problems), [None] * len(problems)
    for members in _by_config(problems):
        size = max(int(np.size(problems[e].times)) for e in members)
        sensed = any(problems[e].pressure is not None for e in members)
        for e in members:
            pr, m = problems[e], int(np.size(problems[e].times))
            pad = lambda a: jnp.concatenate([jnp.asarray(a), jnp.repeat(jnp.asarray(a)[-1:], size - m)])  # noqa: E731
            pressure = pad(pr.pressure) if pr.pressure is not None else jnp.zeros(size) if sensed else None
            out[e] = eqx.tree_at(
                lambda p: (p.times, p.length, p.pressure),
                pr,
                (pad(pr.times), pad(pr.length), pressure),
                is_leaf=lambda x: x is None,
            )
            rows[e] = np.r_[np.arange(m), size + np.arange(m)] if pr.pressure is not None else np.arange(m)
    return out, rows


def _bounds(base, layout: _Layout):
    names = [lab.split("@")[0] for lab in layout.labels]
    lo, hi = np.full(len(names), -np.inf), np.full(len(names), np.inf)
    for i, n in enumerate(names):
        a, b_ = gf.physical_bounds(base, [n], layout.refs[i : i + 1])
        lo[i], hi[i] = a[0], b_[0]
    return lo, hi


def _starts(batch: _Batch, layout: _Layout, likelihoods, base, names, n_starts: int, sweep_n: int, seed: int):
    """Start points z (P,): the ``n_starts`` best of a Latin hypercube over the free names (every copy at the same
    value) by the set's independent-noise cost, or the runs' own values (``sweep_n=0``)."""
    if sweep_n < 0 or n_starts < 1:
        raise ValueError(f"sweep_n must be >= 0 and n_starts >= 1, got {sweep_n} and {n_starts}")
    if sweep_n == 0:
        return [np.zeros(len(layout.labels))]
    from scipy.stats import qmc

    boxes = np.log(np.array([gf.default_range(base, n) for n in names]))
    unit = qmc.LatinHypercube(d=len(names), seed=seed).random(sweep_n)
    values = np.exp(boxes[:, 0] + unit * (boxes[:, 1] - boxes[:, 0]))  # (k, p) SI
    per_name = [names.index(lab.split("@")[0]) for lab in layout.labels]  # each coordinate's free name
    zs = [np.log(v[per_name] / layout.refs) for v in values]
    costs = []
    for outs in batch.residuals_at(zs, layout):
        r = np.concatenate(
            [
                np.asarray(lik.weighted(jnp.asarray(x), jnp.zeros((x.size, 0)))[0])
                for (x, _), lik in zip(outs, likelihoods)
            ]
        )
        costs.append(float(r @ r) if np.all(np.isfinite(r)) else np.inf)
    order = np.argsort(costs)[:n_starts]
    return [zs[k] for k in order if np.isfinite(costs[k])] or [np.zeros(len(layout.labels))]


def _weighted(outs, likelihoods, layout: _Layout, q_all: int = 0):
    """The set's residuals and Jacobian under independent noise, unscored samples zeroed: P columns, or with
    ``q_all`` the P + Q columns of w = (z, b) (each run's Jacobian then has its rig's errors after its θ)."""
    p_all, p = len(layout.labels), layout.index.shape[1]
    rs, js = [], []
    for e, ((r, jac), lik) in enumerate(zip(outs, likelihoods)):
        wr, wj = (np.asarray(a) for a in lik.weighted(jnp.asarray(r), jnp.asarray(jac)))
        full = np.zeros((wr.size, p_all + q_all))
        np.add.at(full.T, layout.index[e], wj[:, :p].T)
        if q_all:
            np.add.at(full.T, p_all + layout.rig_index[e], wj[:, p:].T)
        rs.append(wr)
        js.append(full)
    return np.concatenate(rs), np.concatenate(js)


def _whitened(outs, likelihoods, layout: _Layout, hypers, b, centre=None):
    """The set's whitened residuals and Jacobian of w = (z (P,), b (Q,)): every run whitened under its own
    hyperparameters, its rig columns (when inferred) those of its rig's errors b from the point ``centre`` (Q,)
    where the runs are linearised, then the rig's prior rows (centre + b)/u."""
    p_all, q_all = len(layout.labels), np.asarray(b).size
    rs, js = [], []
    for e, ((r, jac), lik, h) in enumerate(zip(outs, likelihoods, hypers)):
        b_e = np.asarray(b)[layout.rig_index[e]] if lik.inferred else np.zeros(0)
        wr, wl, wg, rp, jp = (
            np.asarray(a) for a in _run_rows(lik, jnp.asarray(r), jnp.asarray(jac), h, jnp.asarray(b_e))
        )
        full = np.zeros((wr.size + rp.size, p_all + q_all))
        np.add.at(full.T, layout.index[e], np.concatenate([wl, jp]).T)
        if lik.inferred:
            np.add.at(full[: wr.size].T, p_all + layout.rig_index[e], wg.T)
        rs.append(np.concatenate([wr, rp]))
        js.append(full)
    if q_all:
        u = _rig_sd(likelihoods, layout)
        rs.append((np.asarray(b) + (0.0 if centre is None else np.asarray(centre))) / u)
        js.append(np.concatenate([np.zeros((q_all, p_all)), np.diag(1.0 / u)], axis=1))
    return np.concatenate(rs), np.concatenate(js)


def _rig_sd(likelihoods, layout: _Layout) -> np.ndarray:
    tol = dict(zip(likelihoods[0].tolerance_names, np.asarray(likelihoods[0].tolerance)))
    return np.array([tol[name] for _, name in layout.rig_labels])


@eqx.filter_jit
def _run_rows(likelihood: gf.Likelihood, r, jac, hyper, b):
    """One run's whitened length rows (residual (n,), Jacobian (n, p), rig columns (n, q)) and its pressure rows."""
    cols, t = likelihood.length_columns(r, jac, b)
    w = dc.whiten(cols, t, hyper)
    p, n = jac.shape[1], likelihood.n_len
    return w[:, 0], w[:, 1 : 1 + p], w[:, 1 + p :], r[n:], jac[n:]


def _covariance(outs, likelihoods, layout: _Layout, hypers, b, model_error: float, tol: dict, rig: str, centre=None):
    """(covariance (P, P) of z, its parts {source: (P, P)}, the information on z (P, P)): as
    :meth:`growjax.calibration.fit.Likelihood.covariance`, summed over the runs, a shared rig error counted once."""
    _, jac_w = _whitened(outs, likelihoods, layout, hypers, b, centre)
    full = np.linalg.pinv(jac_w.T @ jac_w, rcond=1e-10, hermitian=True)
    p_all, size = len(layout.labels), full.shape[0]
    parts: dict = {}
    fixed_gain = np.zeros((p_all, len(layout.rig_labels)))

    def add(name, part):
        parts[name] = parts.get(name, 0.0) + part

    for e, ((r, jac), lik, hyper) in enumerate(zip(outs, likelihoods, hypers)):
        used = np.asarray(lik.used)
        t = np.asarray(lik.times)[used]
        h = np.zeros((int(used.sum()), size))
        np.add.at(h.T, layout.index[e], (jac[: lik.n_len][used] * lik.sigma_length).T)
        g = None if lik.sensitivity is None else np.asarray(lik.sensitivity)[used]
        if lik.inferred:
            np.add.at(h.T, p_all + layout.rig_index[e], g.T)
        kernels = {"noise": dc.noise_kernel(t, hyper)}
        if float(hyper.amplitude) > 0:
            kernels["discrepancy"] = dc.kernel(t, hyper)
        a = full @ np.linalg.solve(sum(kernels.values()), h).T
        for k, kern in kernels.items():
            add(k, (a @ kern @ a.T)[:p_all, :p_all])
        if model_error > 0:
            add("fast_model_error", (a @ dc.drift_kernel(t, model_error, gf.MODEL_ERROR_TIME) @ a.T)[:p_all, :p_all])
        if jac.shape[0] > lik.n_len:
            hp = np.zeros((jac.shape[0] - lik.n_len, size))
            np.add.at(hp.T, layout.index[e], jac[lik.n_len :].T)
            a_p = full @ hp.T
            add("pressure_noise", (a_p @ a_p.T)[:p_all, :p_all])
        if g is not None and rig == "fixed":
            np.add.at(fixed_gain.T, layout.rig_index[e], (a[:p_all] @ g).T)
    if tol:
        u = _rig_sd(likelihoods, layout)
        for j, (_, name) in enumerate(layout.rig_labels):
            c = full[:p_all, p_all + j] / u[j] if rig == "inferred" else fixed_gain[:, j] * u[j]
            add(name, np.outer(c, c))
    info = np.linalg.pinv(full[:p_all, :p_all], rcond=1e-12, hermitian=True)
    cov = sum(parts.values())
    joint = None
    if rig == "inferred" and tol:
        joint = full.copy()
        joint[:p_all, :p_all] = cov
    return cov, parts, info, joint


def _result(
    z,
    b,
    cov,
    parts,
    info,
    outs,
    likelihoods,
    layout: _Layout,
    hypers,
    runs,
    tol,
    rig,
    rig_errors,
    cost,
    converged,
    clock,
    simulate_s,
    centre,
) -> SetFitResult:
    theta = layout.refs * np.exp(z)
    evals, evecs = np.linalg.eigh(info)
    blind = np.zeros(theta.size, bool)
    for k in range(theta.size):
        if evals[k] < 1e-10 * max(float(evals[-1]), 1e-300):
            blind |= np.abs(evecs[:, k]) > 0.1
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    labels = layout.labels
    estimate = dict(zip(labels, map(float, theta)))
    interval = {
        k: None if blind[i] else (float(theta[i] * np.exp(-gf.Z90 * sd[i])), float(theta[i] * np.exp(gf.Z90 * sd[i])))
        for i, k in enumerate(labels)
    }
    se = {k: None if blind[i] else float(theta[i] * sd[i]) for i, k in enumerate(labels)}
    budget = {
        k: {s: float(theta[i] * np.sqrt(max(part[i, i], 0.0))) for s, part in parts.items()}
        for i, k in enumerate(labels)
    }
    rig_offset: dict = {}
    if rig == "inferred" and tol:
        for j, (key, name) in enumerate(layout.rig_labels):
            rig_offset.setdefault(key, {})[name] = float(b[j])
    per_run = []
    for e, ((r, _), lik, hyper, run) in enumerate(zip(outs, likelihoods, hypers, runs)):
        r_len = np.asarray(r)[: lik.n_len] * lik.sigma_length
        if lik.inferred:
            r_len = r_len + np.asarray(lik.sensitivity) @ (np.asarray(b) - centre)[layout.rig_index[e]]
        per_run.append(
            {
                "name": run.name,
                "robot": run.robot,
                "rig": run.rig,
                "drive": run.drive,
                "rmse_length_m": float(np.sqrt(np.mean(r_len**2))),
                "discrepancy": hyper.as_dict(),
                "samples_used": int(np.sum(np.asarray(lik.used))),
            }
        )
    return SetFitResult(
        labels,
        estimate,
        interval,
        se,
        budget,
        cov,
        per_run,
        rig if tol else "none",
        rig_errors,
        rig_offset,
        dict(tol),
        float(cost),
        "converged" if converged else "max_steps",
        time.perf_counter() - clock,
        simulate_s,
    )
