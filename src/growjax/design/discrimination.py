"""A criterion of model discrimination: how surely the next experiment's length names which of two rival catalogue
effects A and B is real.

Data from "base + A at size a" are fitted by "base + B" (the base parameters θ and B's parameter free, as the
discovery fits a candidate). Linearised about B's model at its starting size b (θ at the estimate), the expected
2ΔlogL by which the data reject that fit is (Atkinson & Fedorov's T-optimality with the linearised refit of
Hunter–Reiner and Box–Hill)

    T_AB = rᵀΣ⁻¹r − rᵀΣ⁻¹J (JᵀΣ⁻¹J)⁻¹ JᵀΣ⁻¹r,

r = μ_A − μ_B (n,) m the two models' lengths on the sample times, J (n, p + 1) the sensitivities of μ_B to its
free parameters (ln θ and B's parameter), Σ = K + G U Gᵀ: K the discrepancy and the sensor noise of the residual
model (whitened by the Kalman filter, `growjax.calibration.discrepancy.whiten`), G the rig's sensitivities and
U = diag(u²) its tolerances (marginalised, as the discovery's scores do). T_BA swaps the roles. The design
maximises min(T_AB, T_BA): whichever effect is real, the data should name it.

Why this criterion: it is cheap (two sensitivity solves per input, the two models sharing one compiled program),
differentiable (forward mode through the solves, as the precision criterion), and under the linearisation it is
exactly the non-centrality of the discovery's statistic: the difference of the two candidates' 2ΔlogL, which
`growjax.discover.discover` compares with its threshold to tell rivals apart. T is invariant to the
coordinate each parameter is moved in (a column scaling of J); B's parameter moves linearly, by a tenth of its
range's top per unit, as in the discovery. Its limits: the refit is linearised (a large effect, or one whose
rival must move far to imitate it, is rejected more surely than T says), and the true effect's size is assumed
(its class's ``moderate`` size, `growjax.model.effects.Effect`, unless given).
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

import growjax.design.constraints as dcon
import growjax.design.sensitivity as sensitivity
from growjax.calibration import discrepancy as dc
from growjax.design.knowledge import Knowledge
from growjax.design.space import DesignSpace, demand_at_knots
from growjax.model import effects as fx
from growjax.model import params as gp
from growjax.model.limits import Limits
from growjax.model.limits import limits as limits_of
from growjax.model.signals import Inputs, KnotProfile
from growjax.simulation.config import Config
from growjax.simulation.simulate import Breaks, as_arrays

__all__ = ["FLOOR", "Discrimination", "make", "rivals", "statistic", "statistics", "value_and_gradient"]

FLOOR = 1e-12  # T below which the objective −ln T is held (rivals indistinguishable there)


# One model's run: (length (n,) m, pressure (n,) Pa, jac_length (n, m), jac_pressure (n, m)); two stacked: (2, …).
_Run = tuple[Float[Array, "*two n"], Float[Array, "*two n"], Float[Array, "*two n m"], Float[Array, "*two n m"]]


def rivals(effects: Sequence[str]) -> tuple[str, str]:
    """``effects`` as a pair of distinct catalogue names; ValueError naming what is wrong."""
    effects = tuple(effects)
    if len(effects) != 2:
        raise ValueError(
            f"model discrimination needs exactly two rival effects, got {len(effects)}: {', '.join(effects) or 'none'}"
        )
    for name in effects:
        if name not in fx.CATALOGUE:
            raise ValueError(f"unknown effect {name!r}; the catalogue: {', '.join(sorted(fx.CATALOGUE))}")
    if effects[0] == effects[1]:
        raise ValueError(f"model discrimination needs two different effects, got {effects[0]} twice")
    return effects


def checked_pair(
    effects: Sequence[str], sizes: Sequence[float] | None = None, drive: str = "forward"
) -> tuple[tuple[str, str], tuple[float, float]]:
    """The rivals and their sizes for a design of ``drive``'s input, checked.

    Args:
        effects: two distinct catalogue names (`rivals`).
        sizes: each effect's size, SI, inside its physical range; None: their classes' ``moderate`` sizes.
        drive: the drive whose input is designed: the forward drive's demand alone.

    Returns:
        (effects, sizes).

    Raises:
        ValueError: naming what is wrong.
    """
    if drive != "forward":
        raise ValueError("--discriminate designs the forward drive's demand: drop --next-drive inverse")
    effects = rivals(effects)
    if sizes is None:
        return effects, tuple(float(fx.CATALOGUE[e].moderate) for e in effects)
    sizes = tuple(float(v) for v in sizes)
    if len(sizes) != 2:
        raise ValueError(f"--size takes one size per effect of --discriminate (two), got {len(sizes)}")
    for effect, size in zip(effects, sizes):
        fx.CATALOGUE[effect].at(size)  # ValueError outside its physical range
    return effects, sizes


def statistic(
    r: Float[Array, " n"],
    jac: Float[Array, "n k"],
    rig: Float[Array, "n q"],
    tolerance: Float[ArrayLike, " q"],
    times: Float[ArrayLike, " n"],
    hyper: dc.Hyper,
) -> Float[Array, ""]:
    """T = rᵀΣ⁻¹r − rᵀΣ⁻¹J(JᵀΣ⁻¹J)⁻¹JᵀΣ⁻¹r ≥ 0 for Σ = K + G U Gᵀ: ``r`` (n,) m, ``jac`` J (n, k) m per unit,
    ``rig`` G (n, q) m per unit of the rig's relative errors, ``tolerance`` u (q,), ``times`` (n,) s, K of
    ``hyper``. The Kalman filter whitens by K with the rig's terms in its state (traceable)."""
    w = dc.whiten(jnp.concatenate([r[:, None], jac], axis=1), times, hyper, rig, tolerance)
    rw, jw = w[:, 0], w[:, 1:]
    proj = jw.T @ rw
    a = jw.T @ jw
    return rw @ rw - proj @ jnp.linalg.solve(0.5 * (a + a.T), proj)


class Discrimination(eqx.Module):
    """The problem of designing an input that tells ``effects`` (A, B) apart; build it with `make`. Its
    ``parts`` and ``inputs`` are those of `growjax.design.DesignProblem`, so the random batch, the descent and
    the check (`growjax.design.optimise`, `growjax.design.constraints`) take it as they take a precision problem.

    Attributes:
        base: the parameters at the estimate, both effects present (numbers as arrays).
        sizes: (2, 2) SI, the two models' effect sizes: A's model (a, 0), then B's (0, b).
        scales: (2,) SI per unit of each effect's coordinate.
        knots: (K,) the demand's knots, s.
        p_max: the demand's ceiling, Pa.
        catheter: the catheter length signal, m.
        times: (n,) the sample times, s.
        hyper: the residual model's hyperparameters.
        tolerance: (q,) the rig's relative sds.
        prior_covariance: (m, m) of w = (ln θ, u_A, u_B, b): the penalty's spread.
        breaks: the inputs' breaks.
        limits: the rig's limits.
        names: θ, the base parameters refitted.
        effects: (A, B), catalogue names.
        fields: their parameters, qualified.
        rig: the rig's toleranced parameters.
        config: the configuration, resolved.
        spread: the penalty's sds (`growjax.design.constraints.penalty`).
    """

    base: object  # Parameters at the estimate, both effects present (numbers as arrays)
    sizes: jax.Array  # (2, 2) SI: the two models' effect sizes, A's model (a, 0) then B's (0, b)
    scales: jax.Array  # (2,) SI per unit of each effect's coordinate
    knots: jax.Array  # (K,) s
    p_max: jax.Array  # Pa
    catheter: object
    times: jax.Array  # (n,) s
    hyper: dc.Hyper
    tolerance: jax.Array  # (q,) the rig's relative sds
    prior_covariance: jax.Array  # (m, m) of w = (ln θ, u_A, u_B, b): the penalty's spread
    breaks: tuple
    limits: Limits = eqx.field(static=True)
    names: tuple = eqx.field(static=True)  # θ, the base parameters refitted
    effects: tuple = eqx.field(static=True)  # (A, B)
    fields: tuple = eqx.field(static=True)  # their parameters, qualified
    rig: tuple = eqx.field(static=True)
    config: object = eqx.field(static=True)
    spread: float = eqx.field(static=True, default=dcon.SPREAD)

    def inputs(self, x: Float[ArrayLike, " K-1"]) -> Inputs:
        """The inputs of design x (K − 1,) (traceable)."""
        return Inputs(
            catheter_length=self.catheter, pressure_demand=KnotProfile(self.knots, demand_at_knots(x, self.p_max))
        )

    def solve(self, inputs: Inputs, sizes: Float[Array, " 2"], breaks: Breaks | None = None) -> _Run:
        """(length (n,), pressure (n,), jac_length (n, m), jac_pressure (n, m)) of the model at effect ``sizes``
        (2,), along w = (ln θ (p), u_A, u_B, ln ψ/ψ₀ (q)) (traceable)."""
        p = len(self.names)

        def params_of(w):
            moved = {n: gp.get(self.base, n) * jnp.exp(w[i]) for i, n in enumerate(self.names)}
            moved.update({n: gp.get(self.base, n) * jnp.exp(w[p + 2 + j]) for j, n in enumerate(self.rig)})
            moved.update({f: sizes[k] + self.scales[k] * w[p + k] for k, f in enumerate(self.fields)})
            return gp.replace(self.base, **moved)

        s = sensitivity.solve_along(
            params_of, p + 2 + len(self.rig), inputs, self.config, self.times, self.breaks if breaks is None else breaks
        )
        return s.length, s.pressure, s.jac_length, s.jac_pressure

    def solves(self, inputs: Inputs, breaks: Breaks | None = None) -> _Run:
        """`solve` of A's model and B's, stacked (2, …) (traceable)."""
        return jax.lax.map(lambda sz: self.solve(inputs, sz, breaks), self.sizes)

    def statistics(self, runs: _Run) -> Float[Array, " 2"]:
        """(T_AB, T_BA) of the stacked runs of `solves`: data from A's model fitted by B's, and the
        reverse."""
        length, _, jac, _ = runs
        p = len(self.names)
        out = []
        for truth, rival in ((0, 1), (1, 0)):
            cols = [*range(p), p + rival]
            out.append(
                statistic(
                    length[truth] - length[rival],
                    jac[rival][:, cols],
                    jac[rival][:, p + 2 :],
                    self.tolerance,
                    self.times,
                    self.hyper,
                )
            )
        return jnp.stack(out)

    def of_runs(self, runs: _Run) -> tuple[Float[Array, ""], Float[Array, ""]]:
        """(criterion −ln min(T_AB, T_BA), penalty of the limits summed over both models) of `solves`'s
        runs (traceable)."""
        t = self.statistics(runs)
        crit = -jnp.log(jnp.maximum(jnp.min(t), FLOOR))
        pen = 0.0
        for k in range(2):
            s = sensitivity.Sensitivities(runs[0][k], runs[1][k], runs[2][k], runs[3][k], jnp.asarray(True))
            pen = pen + dcon.penalty(s, self.prior_covariance, self.limits, self.spread)
        return crit, pen

    def parts(self, inputs: Inputs, breaks: Breaks | None = None) -> tuple[Float[Array, ""], Float[Array, ""]]:
        """(criterion, penalty) of ``inputs`` (traceable): what `growjax.design.evaluate` returns."""
        return self.of_runs(self.solves(inputs, breaks))

    def objective(self, x: Float[ArrayLike, " K-1"]) -> Float[Array, ""]:
        """criterion + penalty of design x; +inf where not finite (traceable)."""
        crit, pen = self.parts(self.inputs(x))
        value = crit + pen
        return jnp.where(jnp.isfinite(value), value, jnp.inf)


def make(
    knowledge: Knowledge,
    space: DesignSpace,
    effects: Sequence[str],
    sizes: Sequence[float] | None = None,
    limits: Limits | None = None,
    config: Config | None = None,
) -> Discrimination:
    """The `Discrimination` of ``effects`` (two catalogue names) on ``space``, θ = ``knowledge``'s
    parameters at their estimate (refitted with the rival's effect), its rig and residual model; ``sizes`` (a, b)
    SI: each effect's size, as the truth and as the rival's starting point (default their moderate magnitudes);
    ``config`` as `growjax.design.make`."""
    effects, sizes = checked_pair(effects, sizes)
    classes = [fx.CATALOGUE[e] for e in effects]
    fields = tuple(f"{e}.{cls.magnitude_field()}" for e, cls in zip(effects, classes))
    scales = [0.1 * cls.ranges[cls.magnitude_field()][1] for cls in classes]
    base = gp.with_effects(knowledge.base, *(cls() for cls in classes))
    p, q = len(knowledge.names), len(knowledge.rig)
    prior = np.zeros((p + 2 + q,) * 2)
    prior[:p, :p] = knowledge.covariance
    u = np.asarray(list(knowledge.tolerances.values()), float)
    prior[p + 2 :, p + 2 :] = np.diag(u**2)
    return Discrimination(
        base=as_arrays(base),
        sizes=jnp.asarray([[sizes[0], 0.0], [0.0, sizes[1]]]),
        scales=jnp.asarray(scales),
        knots=jnp.asarray(space.knots),
        p_max=jnp.asarray(float(space.p_max)),
        catheter=space.catheter,
        times=jnp.asarray(space.times),
        hyper=knowledge.hyper,
        tolerance=jnp.asarray(u),
        prior_covariance=jnp.asarray(prior),
        breaks=space.breaks(),
        limits=limits if limits is not None else limits_of(knowledge.base),
        names=tuple(knowledge.names),
        effects=effects,
        fields=fields,
        rig=knowledge.rig,
        config=(config or space.config()).replace(t1=float(space.duration), adjoint="forward").resolved(),
    )


@eqx.filter_jit
def statistics(problem: Discrimination, inputs: Inputs, breaks: Breaks) -> Float[Array, " 2"]:
    """(T_AB, T_BA) (2,) of ``inputs`` with their ``breaks`` (one compiled program per inputs' structure)."""
    return problem.statistics(problem.solves(inputs, breaks))


@eqx.filter_jit
def value_and_gradient(
    problem: Discrimination, x: Float[Array, " K-1"]
) -> tuple[Float[Array, ""], Float[Array, " K-1"]]:
    """(objective, its exact gradient (K − 1,)) of design x by forward mode through both models' sensitivity
    solves (the map over the two models outside the batch of directions)."""
    units = jnp.eye(x.shape[0], dtype=x.dtype)

    def at(sizes):
        f = lambda v: problem.solve(problem.inputs(v), sizes)
        return jax.vmap(lambda e: jax.jvp(f, (x,), (e,)), out_axes=(None, 0))(units)

    runs, d_runs = jax.lax.map(at, problem.sizes)  # d_runs: (2, K − 1, …)
    d_runs = jax.tree_util.tree_map(lambda a: jnp.swapaxes(a, 0, 1), d_runs)
    total = lambda rs: sum(problem.of_runs(rs))
    value, grad = jax.vmap(lambda d: jax.jvp(total, (runs,), (d,)), out_axes=(None, 0))(d_runs)
    return jnp.where(jnp.isfinite(value), value, jnp.inf), grad
