"""A fit's outcome: each coordinate's estimate, 90 % interval, standard error and budget, the runs, the rig, and
the parameters of any run at the fit."""

from __future__ import annotations

import dataclasses

import numpy as np
from jaxtyping import Float
from scipy import stats

from growjax.calibration.layout import Coordinate
from growjax.calibration.likelihood import Likelihood
from growjax.calibration.solve import RELINEARISE_TOLERANCE
from growjax.data.sets import Run
from growjax.model import params as gp

Z90 = float(stats.norm.ppf(0.95))
# Information on a coordinate below this (the data alone put its sd above 10: a factor e^±16 at 90 % in ln θ)
# leaves a direction undetermined, whatever the other directions hold: no interval is reported along it. (A
# relative test alone cannot see a single free parameter the data do not inform, such as Y driven to ~0 Pa where
# it no longer acts.)
INFORMATION_FLOOR = 1e-2


def undetermined_directions(info, names) -> tuple[list, np.ndarray]:
    """The directions of z the information ``info`` (p, p) leaves undetermined, as
    [{"eigenvalue", "direction": {name: loading}}], and which parameters (p,) bool load on any of them (> 0.1): an
    eigenvalue below 1e-10 of the largest, or below `INFORMATION_FLOOR`."""
    evals, evecs = np.linalg.eigh(np.asarray(info, float))
    tol = max(1e-10 * float(evals[-1]), INFORMATION_FLOOR)
    low = [k for k in range(len(names)) if evals[k] < tol]
    blind = np.zeros(len(names), bool)
    for k in low:
        blind |= np.abs(evecs[:, k]) > 0.1
    return [{"eigenvalue": float(evals[k]), "direction": dict(zip(names, map(float, evecs[:, k])))} for k in low], blind


@dataclasses.dataclass
class FitResult:
    """Outcome of a fit. A coordinate is labelled ``NAME`` (one value for every run) or ``NAME@KEY`` (its robot's,
    rig's or run's copy). Values SI; ``interval_90`` and ``standard_error`` None where the data do not determine a
    coordinate.

    Attributes:
        labels: (P,) the coordinates' labels.
        estimate: {label: θ}.
        interval_90: {label: (low, high) or None}: ln-symmetric, or symmetric for a signed parameter.
        standard_error: {label: sd or None}.
        covariance: (P, P) of the coordinates z (ln θ, or (θ − θ_ref)/s for a signed parameter).
        budget: {label: {source: sd}}: noise, discrepancy, the configuration's own error, pressure noise, each
            tolerance, the hyperparameters' spread; their squares add up to the standard error's.
        coordinates: (P,) each coordinate's parameter, scope, key and scale.
        information: (P, P) the information the data hold on z, the rig's errors marginalised.
        undetermined: [{"eigenvalue", "direction": {label: loading}}] the directions the data leave open.
        runs: per run: name, robot, rig, drive, rmse_length_m, discrepancy (its hyperparameters), samples_used.
        rig: how the tolerances entered: ``"inferred"``, ``"fixed"``, or ``"none"`` (no tolerances).
        rig_errors: ``"shared"`` or ``"experiment"``.
        rig_offset: {rig key: {tolerance: fitted ln(ψ/ψ₀)}} when inferred.
        rig_estimate: {rig key: {tolerance: fitted ψ}} when inferred.
        tolerances: {tolerance: relative sd} carried.
        tolerance_gain: {label: {rig key: {tolerance: dθ/d ln ψ}}}: the estimate's response to a rig error.
        discrepancy: {"kind", and the runs' median hyperparameters: amplitude_m, time_scale_s, noise_m,
            noise_time_s} (a new run's residual model; each run's own in ``runs``).
        starts: [{"start", "estimate", "cost", "converged"}] of the least squares from each start.
        at_bound: the labels whose estimate ended on an edge of the physical range.
        samples_used: the length samples the likelihood scored over all runs.
        rmse_length_m: the length RMSE over all runs' samples, m.
        cost: the whitened cost at the estimate, nats.
        status: ``"converged"`` or ``"max_steps"``.
        linearisations: points at which the rig's sensitivities were taken.
        rig_last_move: the rig's largest move in the last linearisation, in tolerances.
        log_likelihood: the set's total at the fit (rig marginalised), nats.
        rig_labels: (Q,) (rig key, tolerance) of the fitted rig errors, when inferred.
        rig_vector: (Q,) their fitted values ln(ψ/ψ₀).
        joint_covariance: (P + Q, P + Q) of (z, b), the z block the covariance.
        residuals: per run (times (n,) s, length residual (n,) m, the rig at its fitted errors).
        likelihood: the likelihood's options the fit used.
        model_error_m: the configuration's own error it carried, m.
        bases: per run, its parameters before the fit (effects included).
        run_keys: per run (name, robot, rig).
    """

    labels: tuple
    estimate: dict
    interval_90: dict
    standard_error: dict
    covariance: Float[np.ndarray, "P P"]
    budget: dict = dataclasses.field(default_factory=dict)
    coordinates: tuple = ()
    information: Float[np.ndarray, "P P"] | None = None
    undetermined: list = dataclasses.field(default_factory=list)
    runs: list = dataclasses.field(default_factory=list)
    rig: str = "none"
    rig_errors: str = "shared"
    rig_offset: dict = dataclasses.field(default_factory=dict)
    rig_estimate: dict = dataclasses.field(default_factory=dict)
    tolerances: dict = dataclasses.field(default_factory=dict)
    tolerance_gain: dict = dataclasses.field(default_factory=dict)
    discrepancy: dict = dataclasses.field(default_factory=dict)
    starts: list = dataclasses.field(default_factory=list)
    at_bound: tuple = ()
    samples_used: int = 0
    rmse_length_m: float = float("nan")
    cost: float = float("nan")
    status: str = "converged"
    wall_s: float = 0.0
    simulate_s: float = 0.0
    programs: int = 1
    linearisations: int = 1
    rig_last_move: float = 0.0
    log_likelihood: float = float("nan")
    rig_labels: tuple = ()
    rig_vector: Float[np.ndarray, " Q"] | None = None
    joint_covariance: Float[np.ndarray, "S S"] | None = None
    residuals: list = dataclasses.field(default_factory=list, repr=False)
    likelihood: Likelihood = dataclasses.field(default_factory=Likelihood)
    model_error_m: float = 0.0
    bases: tuple = dataclasses.field(default=(), repr=False)
    run_keys: tuple = ()

    @property
    def rig_settled(self) -> bool:
        """Whether the rig's errors stopped moving (by at most `growjax.calibration.solve.RELINEARISE_TOLERANCE`
        of a tolerance) before the cap on linearisations."""
        return self.rig_last_move <= RELINEARISE_TOLERANCE

    def coordinate(self, label: str) -> Coordinate:
        """The coordinate ``label``: its parameter, scope, key and scale."""
        for c in self.coordinates:
            if c.label == label:
                return c
        raise KeyError(f"the fit has no coordinate {label!r} (it has {', '.join(self.labels)})")

    def parameters(self, run: Run | str, rig: bool = True) -> gp.Parameters:
        """The parameters of ``run`` (one of the fit's runs by name or as a `growjax.data.sets.Run`, or another run of
        the same set's robots and rigs) at the fit: its base (effects included) with the values of the coordinates
        it uses and, with ``rig``, its rig's fitted errors applied (else the rig nominal).

        Raises:
            KeyError: a run named that the fit does not hold.
        """
        names = [k[0] for k in self.run_keys]
        if isinstance(run, str):
            if run not in names:
                raise KeyError(f"the fit has no run {run!r} (it has {', '.join(names)})")
            e = names.index(run)
            name, robot, rig_name = self.run_keys[e]
            base = self.bases[e]
        else:
            name, robot, rig_name = run.name, run.robot, run.rig
            own = run.name in names and self.run_keys[names.index(run.name)] == (name, robot, rig_name)
            base = self.bases[names.index(run.name)] if own else _with_effects_of(run.base(), self.bases)
        keys = {"shared": "all", "robot": robot, "rig": rig_name, "experiment": name}
        values = {c.name: self.estimate[c.label] for c in self.coordinates if c.key == keys[c.scope]}
        if rig:
            offsets = self.rig_offset.get(rig_name if self.rig_errors == "shared" else name, {})
            values = {**{t: float(gp.get(base, t)) * float(np.exp(b)) for t, b in offsets.items()}, **values}
        return gp.replace(base, **values)

    def summary(self) -> dict:
        """The JSON-ready record of the fit."""
        return {
            "status": self.status,
            "rmse_length_m": self.rmse_length_m,
            "parameters": {
                k: {
                    "estimate": self.estimate[k],
                    "standard_error": self.standard_error[k],
                    "interval_90": self.interval_90[k],
                    "budget_sd": self.budget.get(k),
                    "coordinate": "log" if c.scale is None else "linear",
                }
                for k, c in zip(self.labels, self.coordinates)
            },
            "discrepancy": self.discrepancy,
            "runs": self.runs,
            "tolerances": self.tolerances,
            "rig": self.rig,
            "rig_errors": self.rig_errors,
            "rig_offset": self.rig_offset,
            "rig_estimate": self.rig_estimate,
            "linearisations": self.linearisations,
            "rig_settled": self.rig_settled,
            "rig_last_move": self.rig_last_move,
            "samples_used": self.samples_used,
            "undetermined_directions": self.undetermined,
            "at_physical_bound": list(self.at_bound),
            "starts": self.starts,
            "cost": self.cost,
            "wall_s": self.wall_s,
            "simulate_s": self.simulate_s,
            "programs": self.programs,
        }


def _with_effects_of(base: gp.Parameters, bases) -> gp.Parameters:
    """``base`` with the effects the fit's runs carry."""
    effects = bases[0].effects if bases else ()
    return gp.with_effects(base, *effects) if effects and not base.effects else base


def intervals(coordinates, theta, cov, info) -> tuple[dict, dict, list]:
    """({label: 90 % interval or None}, {label: standard error or None}, the undetermined directions) at θ (P,)
    with the covariance ``cov`` (P, P) and the information ``info`` (P, P) on z."""
    labels = [c.label for c in coordinates]
    undetermined, blind = undetermined_directions(info, labels)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    interval, se = {}, {}
    for i, c in enumerate(coordinates):
        if blind[i]:
            interval[c.label] = se[c.label] = None
        elif c.scale is None:
            with np.errstate(over="ignore"):  # an sd of ln θ in the hundreds: the interval's ends are 0 and inf
                interval[c.label] = (float(theta[i] * np.exp(-Z90 * sd[i])), float(theta[i] * np.exp(Z90 * sd[i])))
            se[c.label] = float(theta[i] * sd[i])
        else:
            half = Z90 * c.scale * sd[i]
            interval[c.label] = (float(theta[i] - half), float(theta[i] + half))
            se[c.label] = float(c.scale * sd[i])
    return interval, se, undetermined


def slopes(coordinates, theta) -> np.ndarray:
    """(P,) dθ/dz of each coordinate at θ: θ for ln θ, s for a signed one."""
    return np.array([theta[i] if c.scale is None else c.scale for i, c in enumerate(coordinates)], float)


__all__ = ["INFORMATION_FLOOR", "Z90", "FitResult", "intervals", "slopes", "undetermined_directions"]
