"""The fast configuration's forward sensitivities: the problem a solve along directions in (params, inputs) sets
its integrator (`growjax.simulation.rosenbrock.integrate`), with the field's derivative either in forward mode or by
central differences (``Config.tangents``).

θ is one member's (params, inputs, prepared constants); a direction d has the structure of (params, inputs) with
a leading axis p. The callbacks take the scaled state y (n,), its sensitivities S (p, n) and θ_s.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, PyTree

import growjax.simulation._assembly as assembly
import growjax.simulation.fast as fm
from growjax.model.params import Parameters
from growjax.model.robot import pressure_limit
from growjax.model.signals import Inputs
from growjax.simulation.config import Config


def relative_size(theta: PyTree, direction: PyTree, typical: PyTree) -> Float[Array, ""]:
    """How large a direction is relative to the values it perturbs: max |d|/|θ| over the leaves (–). Where θ = 0
    the leaf's ``typical`` size stands in (an effect parameter: the top of its physical range; a leak of
    3e-13 m³/(s·Pa) absent at 0 and moved along d = 1 must be shifted by ε·1e-12, not by ε), and where that is
    0 too, |d| itself."""
    # A step size, not a quantity of the model: held constant under differentiation (its derivative at a leaf
    # that is 0 would be 0/0).
    theta, direction, typical = jax.lax.stop_gradient((theta, direction, typical))
    ratios = [
        jnp.max(
            jnp.abs(d)
            / jnp.maximum(
                jnp.where(jnp.abs(x) > 0, jnp.abs(x), jnp.where(jnp.abs(c) > 0, jnp.abs(c), jnp.abs(d))), 1e-300
            )
        )
        for x, d, c in zip(
            jax.tree_util.tree_leaves(theta), jax.tree_util.tree_leaves(direction), jax.tree_util.tree_leaves(typical)
        )
        if jnp.issubdtype(jnp.result_type(d), jnp.floating) and jnp.size(d)
    ]
    return jnp.max(jnp.stack(ratios)) if ratios else jnp.asarray(0.0)


def typical_sizes(params: Parameters) -> Parameters:
    """``params`` with each effect's parameters set to the top of their physical ranges (their typical size)."""
    effects = tuple(
        dataclasses.replace(e, **{f: max(abs(lo), abs(hi)) for f, (lo, hi) in e.ranges.items()}) for e in params.effects
    )
    return dataclasses.replace(params, effects=effects)


def moved_by(theta: PyTree, direction: PyTree, step: Float[Array, ""]) -> PyTree:
    """θ + step·d, leaf by leaf (leaves that are not floating point are left alone)."""

    def shift(x, d):
        if jnp.issubdtype(jnp.result_type(x), jnp.floating) and jnp.size(x):
            return x + step * d
        return x

    return jax.tree_util.tree_map(shift, theta, direction)


def member(
    params: Parameters, inputs: Inputs, config: Config, jump_ts: Float[Array, " J"], step_ts: Float[Array, " K"]
) -> tuple[tuple, Float[Array, " n"], Float[Array, " J+K"], Bool[Array, " J+K"]]:
    """One member's solver inputs: (θ = (params, inputs, prepared constants), scaled initial state, sorted
    breaks, jump flags)."""
    theta = (params, inputs, fm.prepare(params, config))
    times = jnp.concatenate([jump_ts, step_ts])
    order = jnp.argsort(times)
    is_jump = jnp.concatenate([jnp.ones(jump_ts.shape, bool), jnp.zeros(step_ts.shape, bool)])
    return theta, fm.initial_state(params, config), times[order], is_jump[order]


def callbacks(config: Config) -> tuple[Callable, Callable, Callable | None]:
    """(field, outputs, event) of the scaled state, each ``(t, y, θ)`` with θ from `member`."""

    def field(t, y, th):
        p, i, pr = th
        return fm.vector_field(t, y, (p, i, config, pr))

    def outputs(t, y, th):
        p, i, pr = th
        scales = jnp.asarray(fm.layout(p, config.drive)[1])
        length, pressure, q_r, x_p, p_r = fm.rates(t, y * scales, p, i, config, pr)[1]
        return dict(zip(assembly.OUTPUTS, (length, pressure, q_r, x_p, p_r)))

    event = None
    if config.stop_at_pressure_limit:

        def event(t, y, th):  # decreases through 0 where the sensed pressure crosses the limit
            p, _, pr = th
            return 1.0 - fm.pressure_of(p, config, y, pr.storage) / pressure_limit(p.robot)

    return field, outputs, event


def forward_mode_tangents(params: Parameters, config: Config) -> bool:
    """Whether the sensitivities' field is taken in forward mode, else by central differences.

    ``jax.jvp`` evaluates the primal field, and its inner Newton solve, once for all p directions where
    differences evaluate it 1 + 2p times; but its many small operations are launched one by one unless the
    solver's loop is compiled whole (``config.small_loops``, `growjax.simulation.xla_flags`). ``"auto"`` takes
    forward mode where the loop is compiled whole or the rod balance is solved by Newton in every evaluation (the
    Lockhart law); ``python benchmarks/simulate.py --tangents`` measures both.

    Args:
        params: the parameters (their growth law and effects decide the rod solve).
        config: the configuration (``config.tangents``, ``config.small_loops``).

    Returns:
        True for forward mode; decided when a solve is traced.
    """
    if config.tangents == "auto":
        return bool(config.small_loops) or fm.rod_solve(params) == "newton"
    return config.tangents == "forward"


def sensitivities(
    params: Parameters,
    inputs: Inputs,
    config: Config,
    jump_ts: Float[Array, " J"],
    step_ts: Float[Array, " K"],
    directions: tuple[Parameters, Inputs],
) -> tuple[tuple, Float[Array, " p"], Float[Array, "p n"]]:
    """One member's sensitivity problem along ``directions`` (see `_integrate`): (θ_s, sizes |d|/|θ| (p,),
    S0 (p, n)), θ_s for the callbacks of `sensitivity_callbacks`."""
    build = _forward_sensitivities if forward_mode_tangents(params, config) else _difference_sensitivities
    return build(params, inputs, config, jump_ts, step_ts, directions)


def sensitivity_callbacks(params: Parameters, config: Config) -> tuple[Callable, Callable]:
    """(tangent field ``(t, y, S, θ_s) → (f, S')``, output tangents ``(t, y, S, θ_s) → {output: (p,)}``)."""
    return (_forward_callbacks if forward_mode_tangents(params, config) else _difference_callbacks)(config)


def difference_step(size: Float[Array, " p"]) -> Float[Array, " p"]:
    """Step ε along each direction (p,) that moves the parameters by (machine ε)^⅓ of themselves (0 where |d| = 0)."""
    return jnp.where(size > 0, jnp.finfo(jnp.result_type(float)).eps ** (1 / 3) / jnp.where(size > 0, size, 1.0), 0.0)


def _difference_sensitivities(params, inputs, config: Config, jump_ts, step_ts, directions):
    """One member's sensitivity problem along ``directions`` = (parameter tangents, input tangents), each leaf
    with a leading axis p: (θ_s = (θ, θ moved by ±εd (2p, …), ±ε (2p,), 1/2ε (p,)), sizes |d|/|θ| (p,),
    S0 (p, n)), for `_difference_callbacks`."""
    d_params, d_inputs = directions
    theta = member(params, inputs, config, jump_ts, step_ts)[0]
    typical = (typical_sizes(params), inputs)
    size = jax.vmap(lambda dp, di: relative_size((params, inputs), (dp, di), typical))(d_params, d_inputs)  # (p,)
    step = difference_step(size)
    signed = jnp.concatenate([step, -step])  # (2p,): central differences
    both = jax.tree_util.tree_map(lambda d: jnp.concatenate([d, d]), (d_params, d_inputs))
    moved = jax.vmap(lambda dp, di, e: member(*moved_by((params, inputs), (dp, di), e), config, jump_ts, step_ts)[0])(
        *both, signed
    )
    quotient = jnp.where(step > 0, 0.5 / jnp.where(step > 0, step, 1.0), 0.0)
    if theta[2].newton is not None:  # Newton where the point or any shifted one needs it: one flag for all of them
        newton = theta[2].newton | jnp.any(moved[2].newton)
        theta = eqx.tree_at(lambda th: th[2].newton, theta, newton)
        moved = eqx.tree_at(lambda th: th[2].newton, moved, newton)
    theta_s = (theta, moved, signed, quotient)
    s0 = _central(quotient, jax.vmap(lambda p: fm.initial_state(p, config))(moved[0]))
    return theta_s, size, s0


def _moved_axes(moved):
    """``vmap`` axes of the shifted members: 0, except for the Newton flag they share (None)."""
    axes = jax.tree_util.tree_map(lambda _: 0, moved)
    if moved[2].newton is not None:
        axes = eqx.tree_at(lambda th: th[2].newton, axes, None)
    return axes


def _central(quotient, values):
    """(values at θ + εd − values at θ − εd)/2ε: (2p, …) → (p, …)."""
    n_dir = quotient.shape[0]
    return (values[:n_dir] - values[n_dir:]) * quotient.reshape((-1,) + (1,) * (values.ndim - 1))


def _difference_callbacks(config: Config):
    """(tangent field, output tangents) over θ_s from `_difference_sensitivities`: central difference
    quotients of the primal field and outputs along every direction, in one batched evaluation."""
    field, outputs, _ = callbacks(config)

    def tangent_field(t, y, sens, th):
        theta, moved, signed, quotient = th
        shifted = jax.vmap(lambda s, e, m: field(t, y + e * s, m), in_axes=(0, 0, _moved_axes(moved)))(
            jnp.concatenate([sens, sens]), signed, moved
        )
        return field(t, y, theta), _central(quotient, shifted)

    def output_tangents(t, y, sens, th):
        _, moved, signed, quotient = th
        shifted = jax.vmap(lambda s, e, m: outputs(t, y + e * s, m), in_axes=(0, 0, _moved_axes(moved)))(
            jnp.concatenate([sens, sens]), signed, moved
        )
        return {k: _central(quotient, shifted[k]) for k in assembly.OUTPUTS}

    return tangent_field, output_tangents


def _forward_sensitivities(params, inputs, config: Config, jump_ts, step_ts, directions):
    """One member's sensitivity problem along ``directions`` = (parameter tangents, input tangents), each leaf
    with a leading axis p: (θ_s = (θ, dθ: the tangents of θ's floating-point leaves (p, …)), sizes |d|/|θ| (p,),
    S0 (p, n)), for `_forward_callbacks`."""
    d_params, d_inputs = directions
    theta = member(params, inputs, config, jump_ts, step_ts)[0]
    typical = (typical_sizes(params), inputs)
    size = jax.vmap(lambda dp, di: relative_size((params, inputs), (dp, di), typical))(d_params, d_inputs)  # (p,)
    if theta[2].newton is not None:  # Newton also where a small move along a direction needs it (an effect at 0)
        moved = jax.vmap(
            lambda dp, di, e: member(*moved_by((params, inputs), (dp, di), e), config, jump_ts, step_ts)[0][2].newton
        )(d_params, d_inputs, difference_step(size))
        theta = eqx.tree_at(lambda th: th[2].newton, theta, theta[2].newton | jnp.any(moved))
    point, fixed = eqx.partition((params, inputs), eqx.is_inexact_array)
    d_point = eqx.filter((d_params, d_inputs), jax.tree_util.tree_map(eqx.is_inexact_array, (params, inputs)))

    def floating(x):  # θ's and the initial state's floating-point leaves at the floating-point leaves x
        p, i = eqx.combine(x, fixed)
        return eqx.filter(member(p, i, config, jump_ts, step_ts)[0], eqx.is_inexact_array), fm.initial_state(p, config)

    d_theta, s0 = jax.vmap(lambda d: jax.jvp(floating, (point,), (d,))[1])(d_point)
    return (theta, d_theta), size, s0


def _forward_callbacks(config: Config):
    """(tangent field, output tangents) over θ_s from `_forward_sensitivities`: forward-mode derivatives of the
    primal field and outputs along every direction, the primal (and its inner Newton solve) evaluated once."""
    field, outputs, _ = callbacks(config)

    def along(fn, t, y, sens, th):
        theta, d_theta = th
        x, fixed = eqx.partition(theta, eqx.is_inexact_array)

        def one(s, d):
            return jax.jvp(lambda y_, x_: fn(t, y_, eqx.combine(x_, fixed)), (y, x), (s, d))

        return jax.vmap(one, out_axes=(None, 0))(sens, d_theta)

    def tangent_field(t, y, sens, th):
        return along(field, t, y, sens, th)

    def output_tangents(t, y, sens, th):
        return along(outputs, t, y, sens, th)[1]

    return tangent_field, output_tangents
