"""A design problem as data: what is known, the design space, the sensors, the criterion and the limits, with the
objective the optimiser minimises and its gradient by forward mode through the model.

objective(x) = criterion(x) + penalty(x): the criterion (:mod:`.criterion`) averaged over the points of θ given
(``theta_points``, z = ln θ/θ̂; the first is the estimate itself: a local design when it is the only one) as
log E_θ[exp(criterion)], and the limits' penalty (:func:`.constraints.penalty`) at the estimate. Arrays are leaves,
so one compiled program serves every design of one problem's shapes.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from growjax import discrepancy as dc
from growjax.design import constraints as dcon
from growjax.design import criterion as dcrit
from growjax.design import sensitivity
from growjax.design.knowledge import Knowledge
from growjax.design.space import DesignSpace
from growjax.simulate import as_arrays
from growjax.signals import Inputs


class Problem(eqx.Module):
    """The design problem (see the module docstring). Build it with :func:`make`."""

    base: object  # Parameters at the estimate, numbers as arrays
    knots: jax.Array  # (K,) s
    p_max: jax.Array  # Pa
    catheter: object  # signal, m
    times: jax.Array  # (n,) s, the sensors' samples
    hyper: dc.Hyper
    precision_known: jax.Array  # (m, m)
    precision_alone: jax.Array  # (m, m)
    prior_covariance: jax.Array  # (m, m)
    theta_points: jax.Array  # (P, p) z = ln θ/θ̂ the criterion is averaged over (the first: 0)
    breaks: tuple
    limits: dcon.Limits = eqx.field(static=True)
    names: tuple = eqx.field(static=True)
    rig: tuple = eqx.field(static=True)
    sensors: tuple = eqx.field(static=True)
    pressure_noise: float = eqx.field(static=True)
    criterion: dcrit.Precision = eqx.field(static=True)
    config: object = eqx.field(static=True)
    spread: float = eqx.field(static=True, default=dcon.SPREAD)

    def inputs(self, x) -> Inputs:
        from growjax.control.profile import KnotProfile

        return Inputs(catheter_length=self.catheter, pressure_demand=KnotProfile(self.knots, self.p_max * jax.nn.sigmoid(x)))

    def predict(self, inputs, breaks=None, z=None, sensors=None) -> dcrit.Prediction:
        """The :class:`growjax.design.criterion.Prediction` of ``inputs`` (their ``breaks``, default the design
        space's) at θ̂·exp(``z``), with ``sensors`` (default the problem's)."""
        s = sensitivity.solve(self.base, inputs, self.names, self.rig, self.config, self.times,
                              self.breaks if breaks is None else breaks, z)
        return dcrit.posterior(s, self.times, self.hyper, self.precision_known, self.precision_alone,
                               self.sensors if sensors is None else sensors, self.pressure_noise)

    def parts(self, inputs, breaks=None):
        """(criterion averaged over the θ points, penalty) of ``inputs`` (traceable)."""
        def at(z):
            return self.criterion(self.predict(inputs, breaks, z))

        first = self.predict(inputs, breaks)
        values = self.criterion(first)
        if self.theta_points.shape[0] > 1:
            rest = jax.lax.map(at, self.theta_points[1:])
            values = jax.nn.logsumexp(jnp.concatenate([values[None], rest])) - jnp.log(self.theta_points.shape[0])
        return values, dcon.penalty(first.sensitivities, self.prior_covariance, self.limits, self.spread)

    def objective(self, x):
        """criterion + penalty of design x (K,); +inf where the model failed."""
        crit, pen = self.parts(self.inputs(x))
        value = crit + pen
        return jnp.where(jnp.isfinite(value), value, jnp.inf)


def make(knowledge: Knowledge, space: DesignSpace, criterion: str = "A", sensors=("length",),
         pressure_noise: float = dcrit.PRESSURE_NOISE, limits: dcon.Limits | None = None, theta_points: int = 1,
         seed: int = 0) -> Problem:
    """The :class:`Problem` of designing ``space``'s input given ``knowledge``; ``criterion`` ``"A"`` or ``"D"`` on
    the parameters of interest; ``theta_points``: 1, the local design at the estimate, or that many points of θ
    (the estimate and draws from its uncertainty, seeded) to average the criterion over."""
    sensors = tuple(sensors)
    if set(sensors) - set(dcrit.SENSORS) or "length" not in sensors:
        raise ValueError(f"sensors must be 'length' or 'length,pressure', got {','.join(sensors)}")
    if theta_points < 1:
        raise ValueError(f"theta_points must be at least 1, got {theta_points}")
    p = len(knowledge.names)
    rng = np.random.default_rng([seed, 3])
    zs = np.concatenate([np.zeros((1, p)),
                         rng.multivariate_normal(np.zeros(p), knowledge.covariance, size=theta_points - 1)])
    lim = limits if limits is not None else dcon.limits(knowledge.base)
    return Problem(
        base=as_arrays(knowledge.base), knots=jnp.asarray(space.knots), p_max=jnp.asarray(float(space.p_max)),
        catheter=space.catheter, times=jnp.asarray(space.times), hyper=knowledge.hyper,
        precision_known=jnp.asarray(knowledge.prior_precision(True)),
        precision_alone=jnp.asarray(knowledge.prior_precision(False)),
        prior_covariance=jnp.asarray(knowledge.prior_covariance()), theta_points=jnp.asarray(zs), breaks=space.breaks(),
        limits=lim, names=tuple(knowledge.names), rig=knowledge.rig, sensors=sensors, pressure_noise=float(pressure_noise),
        criterion=dcrit.Precision(p, criterion), config=space.config().resolved())


@eqx.filter_jit
def value_and_gradient(problem: Problem, x):
    """(objective, its gradient (K,)) of design x: forward mode along each design variable (the sensitivities
    differentiated again through the solver's loop)."""
    units = jnp.eye(x.shape[0], dtype=x.dtype)
    value, grad = jax.vmap(lambda e: jax.jvp(problem.objective, (x,), (e,)), out_axes=(None, 0))(units)
    return value, grad


@eqx.filter_jit
def information(problem: Problem, inputs, breaks, z):
    """(information of the length rows (m, m), of the pressure rows (m, m), the run's length (n,) m and pressure
    (n,) Pa) of ``inputs`` (their ``breaks``) at θ̂·exp(``z``) (one compiled program per inputs' structure)."""
    s = sensitivity.solve(problem.base, inputs, problem.names, problem.rig, problem.config, problem.times, breaks, z)
    info_l = dcrit.information(s, problem.times, problem.hyper, ("length",))
    jp = s.jac_pressure / problem.pressure_noise
    return info_l, jp.T @ jp, s.length, s.pressure


def covariances(problem: Problem, info_length, info_pressure, sensors) -> tuple[np.ndarray, np.ndarray]:
    """(posterior covariance of w with what is known, of the next experiment alone) (m, m) under ``sensors``."""
    info = np.asarray(info_length) + (np.asarray(info_pressure) if "pressure" in sensors else 0.0)
    inv = lambda a: np.linalg.inv(0.5 * (a + a.T))
    return inv(np.asarray(problem.precision_known) + info), inv(np.asarray(problem.precision_alone) + info)


def score(problem: Problem, inputs, breaks=None) -> float:
    """The criterion of ``inputs`` under the problem's sensors, averaged over its θ points as the objective is
    (no penalty: an input scored here is checked by simulation instead)."""
    breaks = problem.breaks if breaks is None else breaks
    values = []
    for z in np.asarray(problem.theta_points):
        info_l, info_p = information(problem, inputs, breaks, jnp.asarray(z))[:2]
        cov = covariances(problem, info_l, info_p, problem.sensors)[0]
        values.append(float(problem.criterion.of_covariance(jnp.asarray(cov))))
    values = np.asarray(values)
    if not np.all(np.isfinite(values)):
        return float("inf")
    top = values.max()
    return float(top + np.log(np.mean(np.exp(values - top))))
