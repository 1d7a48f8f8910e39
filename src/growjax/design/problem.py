"""A design problem as data: what is known, the design space, the sensors, the criterion and the limits, with the
objective the optimiser minimises and its gradient by forward mode through the model.

The criterion is Bayesian: the posterior covariance depends on where θ and the rig really are, so it is taken at
``points`` of w = (ln θ/θ̂, b) (the estimate on the nominal rig first, then draws from the prior
blockdiag(Σ_θ, U), seeded and held fixed) and averaged (for the A-criterion, the log of the expected sum of
relative variances). An input whose information comes from a feature the nominal rig has and the others lack (a
growth threshold crossed just so) is worth what it is worth on average. With one point the design is local, at
the estimate. To that average is added what the fit's linearised rig misses (`.sensitivity.remainder`, at
``offsets``: one plain solve per draw of the rig): an input that drives the rig's nonlinearity hard can look
informative to the linearisation and not deliver, and the fit of its data would then claim more than it knows.

objective(x) = that criterion (the one the design's table reports, `covariances`) + the limits' penalty
(`.constraints.penalty`) at the estimate. Its slope: exact by forward mode through the model
(`value_and_gradient`), or by differences over a step of the demand (`smoothed_gradient`, what the
descent follows: see there why). Arrays are leaves, so one compiled program serves every design of one problem's
shapes.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

import growjax.design.constraints as dcon
import growjax.design.criterion as dcrit
import growjax.design.sensitivity as sensitivity
from growjax.calibration import discrepancy as dc
from growjax.calibration.tolerance import rig_draws
from growjax.design.knowledge import Knowledge
from growjax.design.space import DesignSpace, demand_at_knots, stepper_inputs
from growjax.model import params as gp
from growjax.model.limits import Limits
from growjax.model.limits import limits as limits_of
from growjax.model.signals import Inputs, KnotProfile
from growjax.simulation.config import Config
from growjax.simulation.simulate import Breaks, as_arrays

if TYPE_CHECKING:
    from growjax.design.discrimination import Discrimination

__all__ = [
    "DEMAND_STEP",
    "NONLINEAR_DRAWS",
    "POINTS",
    "DesignProblem",
    "covariances",
    "evaluate",
    "evaluate_many",
    "information",
    "make",
    "smoothed_gradient",
    "value_and_gradient",
    "values",
]

POINTS = 4  # points of (θ, rig) the criterion is averaged over
DEMAND_STEP = 0.02  # share of p_max by which `smoothed_gradient` moves each knot
NONLINEAR_DRAWS = 16  # draws of the rig on which what its linearisation misses is measured


class DesignProblem(eqx.Module):
    """The design problem (see the module docstring). Build it with `make`.

    Attributes:
        base: the parameters at the estimate on the nominal rig, numbers as arrays.
        knots: (K,) s, the demand's knots (forward drive) or the step controller's edges (stepper).
        p_max: the demand's ceiling, Pa (forward drive; unused by the stepper).
        catheter: the catheter length signal, m.
        times: (n,) the sensors' sample times, s.
        hyper: the residual model's hyperparameters.
        precision_known: (m, m) the prior precision of w with what is known.
        precision_alone: (m, m) the prior precision of the next experiment alone.
        prior_covariance: (m, m) of w: the penalty's spread.
        points: (P, m) points of w the criterion is averaged over (the first: 0).
        offsets: (D, q) the rig's relative errors at the draws its nonlinearity is measured on.
        breaks: the inputs' breaks.
        limits: the rig's limits.
        names: the parameters of interest θ.
        rig: the rig's toleranced parameters.
        sensors: ``("length",)`` or ``("length", "pressure")``.
        pressure_noise: sd of the pressure sensor's noise, Pa.
        criterion: what the design minimises.
        config: the fast configuration, resolved.
        spread: the penalty's sds (`growjax.design.constraints.penalty`).
        drive: ``"forward"`` or ``"inverse"``.
    """

    base: object  # Parameters at the estimate on the nominal rig, numbers as arrays
    knots: jax.Array  # (K,) s: the demand's knots (forward drive) or the step controller's edges (stepper)
    p_max: jax.Array  # Pa (forward drive; unused by the stepper)
    catheter: object  # signal, m
    times: jax.Array  # (n,) s, the sensors' samples
    hyper: dc.Hyper
    precision_known: jax.Array  # (m, m)
    precision_alone: jax.Array  # (m, m)
    prior_covariance: jax.Array  # (m, m)
    points: jax.Array  # (P, m) points of w the criterion is averaged over (the first: 0)
    offsets: jax.Array  # (D, q) the rig's relative errors at the draws its nonlinearity is measured on
    breaks: tuple
    limits: Limits = eqx.field(static=True)
    names: tuple = eqx.field(static=True)
    rig: tuple = eqx.field(static=True)
    sensors: tuple = eqx.field(static=True)
    pressure_noise: float = eqx.field(static=True)
    criterion: dcrit.Criterion = eqx.field(static=True)
    config: object = eqx.field(static=True)
    spread: float = eqx.field(static=True, default=dcon.SPREAD)
    drive: str = eqx.field(static=True, default="forward")

    def inputs(self, x: Float[ArrayLike, " k"]) -> Inputs:
        """The inputs of design x (traceable): the demand's logits (K − 1,) or the stepper's steps (N,)."""
        if self.drive == "inverse":
            return stepper_inputs(self.catheter, self.knots, x)
        return Inputs(
            catheter_length=self.catheter, pressure_demand=KnotProfile(self.knots, demand_at_knots(x, self.p_max))
        )

    def sensitivities(
        self, inputs: Inputs, breaks: Breaks | None = None, z: Float[ArrayLike, " m"] | None = None
    ) -> sensitivity.Sensitivities:
        """The `growjax.design.sensitivity.Sensitivities` of ``inputs`` (their ``breaks``, default the design
        space's) at the point ``z`` of w (default 0) (traceable)."""
        return sensitivity.solve(
            self.base,
            inputs,
            self.names,
            self.rig,
            self.config,
            self.times,
            self.breaks if breaks is None else breaks,
            z,
        )

    def predict(
        self,
        inputs: Inputs,
        breaks: Breaks | None = None,
        z: Float[ArrayLike, " m"] | None = None,
        sensors: tuple[str, ...] | None = None,
        nonlinear: bool = False,
    ) -> dcrit.Prediction:
        """The `growjax.design.criterion.Prediction` of ``inputs`` (their ``breaks``, default the design
        space's) at the point ``z`` of w (default 0), with ``sensors`` (default the problem's); ``nonlinear``: with
        what the rig's linearisation misses at the problem's ``offsets``."""
        breaks = self.breaks if breaks is None else breaks
        s = self.sensitivities(inputs, breaks, z)
        rem = None
        if nonlinear and self.offsets.shape[0]:
            rem = sensitivity.remainder(
                self.base, inputs, self.names, self.rig, self.config, self.times, breaks, s, self.offsets, z
            )
        return dcrit.posterior(
            s,
            self.times,
            self.hyper,
            self.precision_known,
            self.precision_alone,
            self.sensors if sensors is None else sensors,
            self.pressure_noise,
            rem,
        )

    def covariance(
        self, inputs: Inputs, breaks: Breaks | None = None
    ) -> tuple[Float[Array, "m m"], sensitivity.Sensitivities]:
        """The covariance (m, m) of the estimate of w with what is known that the table reports
        (`covariances`' ``"known"``): averaged over the points, plus what the rig's linearisation misses at
        the estimate (at the problem's ``offsets``); and the sensitivities at the estimate (traceable)."""
        first = self.predict(inputs, breaks, self.points[0], nonlinear=True)
        rest = jax.lax.map(lambda z: self.predict(inputs, breaks, z).covariance_linear, self.points[1:])
        mean = (first.covariance_linear + rest.sum(axis=0)) / self.points.shape[0]
        return mean + (first.covariance - first.covariance_linear), first.sensitivities

    def criterion_of(self, covariance: Float[Array, "m m"]) -> Float[Array, ""]:
        """The criterion of a covariance (m, m) of w: of its block on the parameters of interest (p, p)."""
        p = len(self.names)
        return self.criterion(covariance[:p, :p])

    def parts(self, inputs: Inputs, breaks: Breaks | None = None) -> tuple[Float[Array, ""], Float[Array, ""]]:
        """(criterion of `covariance`, penalty at the estimate) of ``inputs`` (traceable)."""
        cov, s = self.covariance(inputs, breaks)
        return self.criterion_of(cov), dcon.penalty(s, self.prior_covariance, self.limits, self.spread)

    def objective(self, x: Float[ArrayLike, " k"]) -> Float[Array, ""]:
        """criterion + penalty of design x (K,); +inf where the model failed."""
        crit, pen = self.parts(self.inputs(x))
        value = crit + pen
        return jnp.where(jnp.isfinite(value), value, jnp.inf)


def make(
    knowledge: Knowledge,
    space: DesignSpace,
    criterion: dcrit.Criterion | None = None,
    sensors: Sequence[str] = ("length",),
    pressure_noise: float = dcrit.PRESSURE_NOISE,
    limits: Limits | None = None,
    points: int = POINTS,
    seed: int = 0,
    config: Config | None = None,
    nonlinear_draws: int = NONLINEAR_DRAWS,
) -> DesignProblem:
    """The problem of designing ``space``'s input given ``knowledge``.

    Args:
        knowledge: what is known (the parameters of interest, their covariance, the rig's tolerances).
        space: the design space (the forward drive's demand or the stepper's schedule).
        criterion: what the design minimises, a `growjax.design.Criterion` of the covariance of the parameters
            of interest (None: `growjax.design.AOptimal`).
        sensors: ``("length",)`` or ``("length", "pressure")``.
        pressure_noise: Pa, sd of the pressure sensor's noise.
        limits: the rig's limits (None: `growjax.model.limits.limits` of ``knowledge.base``).
        points: the points of (θ, rig) the criterion is averaged over (1: the local design at the estimate;
            more: the estimate and draws from the prior, seeded).
        seed: the seed of the points and the rig's draws.
        config: the fast configuration's settings over the run (None: `growjax.design.space.DesignSpace.config`).
        nonlinear_draws: draws of the rig (seeded) on which what its linearisation misses is measured, in the
            objective and the reports alike (0: none, the linearised criterion).

    Returns:
        The `DesignProblem`.

    Raises:
        TypeError: a criterion that is not a `growjax.design.Criterion` (a name such as ``"A"``, say).
        ValueError: bad sensors, a configuration of the other drive, or fewer than one point.
    """
    sensors = dcrit.check_sensors(sensors)
    criterion = dcrit.AOptimal() if criterion is None else criterion
    if not isinstance(criterion, dcrit.Criterion):
        raise TypeError(f"criterion must be a growjax.design.Criterion such as AOptimal(), got {criterion!r}")
    if config is not None and config.drive != space.drive:
        raise ValueError(f"the configuration's drive is {config.drive!r}, the design space's {space.drive!r}")
    if points < 1:
        raise ValueError(f"points must be at least 1, got {points}")
    prior = knowledge.prior_covariance()
    rng = np.random.default_rng([seed, 3])
    zs = np.concatenate(
        [np.zeros((1, prior.shape[0])), rng.multivariate_normal(np.zeros(prior.shape[0]), prior, size=points - 1)]
    )
    lim = limits if limits is not None else limits_of(knowledge.base)
    drawn = rig_draws(nonlinear_draws, knowledge.base, knowledge.tolerances, seed + 1) if nonlinear_draws else {}
    offsets = np.zeros((0, len(knowledge.rig)))
    if drawn:
        offsets = np.stack([np.log(drawn[n] / float(gp.get(knowledge.base, n))) for n in knowledge.rig], axis=1)
    stepper = space.drive == "inverse"
    return DesignProblem(
        base=as_arrays(knowledge.base),
        knots=jnp.asarray(space.edges if stepper else space.knots),
        p_max=jnp.asarray(0.0 if stepper else float(space.p_max)),
        catheter=space.catheter,
        times=jnp.asarray(space.times),
        hyper=knowledge.hyper,
        precision_known=jnp.asarray(knowledge.prior_precision(True)),
        precision_alone=jnp.asarray(knowledge.prior_precision(False)),
        prior_covariance=jnp.asarray(prior),
        points=jnp.asarray(zs),
        offsets=jnp.asarray(offsets),
        breaks=space.breaks(),
        limits=lim,
        names=tuple(knowledge.names),
        rig=knowledge.rig,
        sensors=sensors,
        pressure_noise=float(pressure_noise),
        criterion=criterion,
        config=(config or space.config()).replace(t1=float(space.duration), adjoint="forward").resolved(),
        drive=space.drive,
    )


@eqx.filter_jit
def value_and_gradient(problem: DesignProblem, x: Float[Array, " k"]) -> tuple[Float[Array, ""], Float[Array, " k"]]:
    """(objective, its exact gradient (K − 1,)) of design x by forward mode through the model: the sensitivities
    (and the plain solves of what the rig's linearisation misses) differentiated again through the solver's loop
    along every design variable."""
    units = jnp.eye(x.shape[0], dtype=x.dtype)

    def f(v):
        return sum(problem.parts(problem.inputs(v)))

    value, tangent = jax.vmap(lambda e: jax.jvp(f, (x,), (e,)), out_axes=(None, 0))(units)
    return jnp.where(jnp.isfinite(value), value, jnp.inf), tangent


def information(
    problem: DesignProblem, inputs: Inputs, breaks: Breaks
) -> tuple[Float[Array, "P m m"], Float[Array, "P m m"], Float[Array, "m D"], Float[Array, " n"], Float[Array, " n"]]:
    """At every point (P of them): the information of the length rows (P, m, m) and of the pressure rows (P, m, m);
    at the estimate, the whitened cross term J̃ᵀK⁻¹V (m, D) of what the rig's linearisation misses
    (`growjax.design.criterion.posterior`), the run's length (n,) m and pressure (n,) Pa. One compiled
    program per inputs' structure, the one `evaluate` runs."""
    return _information(problem, inputs, breaks)[:5]


@eqx.filter_jit
def _information(problem: DesignProblem, inputs, breaks):
    """`information`'s outputs and the limits' penalty at the estimate (`growjax.design.constraints.penalty`).
    The first point is the estimate (`make`), so its sensitivities serve the penalty and the cross term too."""

    def info(s):
        w = dc.whiten(s.jac_length, problem.times, problem.hyper)
        jp = s.jac_pressure / problem.pressure_noise
        return w.T @ w, jp.T @ jp

    s = problem.sensitivities(inputs, breaks)
    first = info(s)
    rest = jax.lax.map(lambda z: info(problem.sensitivities(inputs, breaks, z)), problem.points[1:])
    info_l, info_p = (jnp.concatenate([a[None], b]) for a, b in zip(first, rest))
    m, d = s.jac_length.shape[1], problem.offsets.shape[0]
    cross = jnp.zeros((m, 0))
    if d:
        rem = sensitivity.remainder(
            problem.base, inputs, problem.names, problem.rig, problem.config, problem.times, breaks, s, problem.offsets
        )
        w = dc.whiten(jnp.concatenate([s.jac_length, rem / jnp.sqrt(d)], axis=1), problem.times, problem.hyper)
        cross = w[:, :m].T @ w[:, m:]
    return (
        info_l,
        info_p,
        cross,
        s.length,
        s.pressure,
        dcon.penalty(s, problem.prior_covariance, problem.limits, problem.spread),
    )


def covariances(
    problem: DesignProblem,
    info_length: Float[ArrayLike, "P m m"],
    info_pressure: Float[ArrayLike, "P m m"],
    cross: Float[ArrayLike, "m D"],
    sensors: Sequence[str],
) -> dict[str, Float[np.ndarray, "m m"]]:
    """Covariances (m, m) of the estimate of w under ``sensors``, from `information`'s output:
    ``"known"`` (with what is known) and ``"alone"`` (the next experiment alone), each averaged over the points
    plus what the rig's linearisation misses (at the estimate); ``"known_local"``, ``"alone_local"``: at the
    estimate on the nominal rig, linearised (the classical local prediction); NaN where the precision is singular."""
    info = np.asarray(info_length) + (np.asarray(info_pressure) if "pressure" in sensors else 0.0)
    c = np.asarray(cross)
    out = {}
    for key, prec in (("known", problem.precision_known), ("alone", problem.precision_alone)):
        a = np.asarray(prec)[None] + info
        try:
            covs = np.linalg.inv(0.5 * (a + np.swapaxes(a, -1, -2)))
        except np.linalg.LinAlgError:  # the input informs nothing where the prior is flat: no covariance
            covs = np.full_like(a, np.nan)
        local = covs[0]
        out[key + "_local"] = local
        out[key] = covs.mean(axis=0) + local @ c @ c.T @ local
    return out


def evaluate(problem: DesignProblem | Discrimination, x: Float[ArrayLike, " k"]) -> tuple[np.ndarray, np.ndarray]:
    """(criterion, penalty) of design x (K − 1,): the objective's two parts (`DesignProblem.parts`). For a
    `DesignProblem`, through `information`'s compiled program, the one the design's table reports from
    (the same numbers to rounding); NaN where the model failed or the information is singular (a design that
    informs nothing where the prior is flat: flagged like a failed run, not allowed to sink its batch)."""
    if not isinstance(problem, DesignProblem):
        return _parts(problem, x)
    info_l, info_p, cross, _, _, pen = (np.asarray(a) for a in _information(problem, problem.inputs(x), problem.breaks))
    if not all(np.all(np.isfinite(a)) for a in (info_l, info_p, cross)):
        return np.float64(np.nan), pen
    cov = covariances(problem, info_l, info_p, cross, problem.sensors)["known"]
    return np.asarray(problem.criterion_of(cov)), pen


@eqx.filter_jit
def _parts(problem, x):
    return problem.parts(problem.inputs(x))


def evaluate_many(
    problem: DesignProblem | Discrimination, xs: Float[ArrayLike, "S k"], workers: int | None = None
) -> Float[np.ndarray, "S 2"]:
    """(criterion, penalty) (S, 2) of designs ``xs`` (S, K − 1), one compiled evaluation each, ``workers`` at a time
    (threads: a compiled evaluation releases the GIL; default one per CPU core)."""
    xs = np.atleast_2d(np.asarray(xs, float))

    def one(x):
        return [float(v) for v in evaluate(problem, x)]

    workers = workers or os.cpu_count() or 1
    if workers == 1 or len(xs) == 1:
        return np.array([one(x) for x in xs])
    with ThreadPoolExecutor(max_workers=min(workers, len(xs))) as pool:
        return np.array(list(pool.map(one, xs)))


def values(
    problem: DesignProblem | Discrimination, xs: Float[ArrayLike, "S k"], workers: int | None = None
) -> Float[np.ndarray, " S"]:
    """The objective (S,) of designs ``xs`` (S, K − 1) (`evaluate_many`); +inf where the model failed."""
    v = evaluate_many(problem, xs, workers).sum(axis=1)
    return np.where(np.isfinite(v), v, np.inf)


def smoothed_gradient(
    problem: DesignProblem | Discrimination,
    x: Float[ArrayLike, " k"],
    step: float = DEMAND_STEP,
    workers: int | None = None,
) -> tuple[float, Float[np.ndarray, " k"]]:
    """(objective, its gradient (K − 1,)) of design x by forward differences of the demand at each knot by
    ``step`` × p_max (backward where that would pass p_max), the K perturbed designs evaluated together
    (`values`).

    The criterion is a function of the sensitivities, and those carry the model's regularised switches (the
    growth threshold's friction, the valves, the end stops: C¹ over bands far narrower than any change of a
    design worth making), so the exact derivative (`value_and_gradient`) at a design near a switch
    reports the switch, not the slope of the criterion over a step of the demand. A difference over a step of a
    few kPa is the slope that matters to the descent."""
    x = np.asarray(x, float)
    p_max = float(problem.p_max)
    demand = p_max * (1.0 / (1.0 + np.exp(-x)))
    delta = np.where(demand + step * p_max < p_max * (1 - 1e-6), step * p_max, -step * p_max)
    moved = np.clip(demand[None, :] + np.diag(delta), 1e-6 * p_max, p_max * (1 - 1e-6))
    xs = np.concatenate([x[None], np.log(moved / p_max) - np.log1p(-moved / p_max)])
    f = values(problem, xs, workers)
    slope = (f[1:] - f[0]) / delta  # per Pa
    return f[0], slope * demand * (1.0 - demand / p_max)  # chain rule: dp/dx = p(1 − p/p_max)
