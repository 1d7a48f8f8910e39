"""The fast configuration's solve: its Rosenbrock integration (`growjax.simulation.rosenbrock`), one member or a batch
stepped together, its outputs on the save grid, and its derivatives.

Forward mode (``jax.jvp``, ``jax.jacfwd``) integrates the sensitivities along the tangents with the state
(`growjax.simulation._fast_sensitivities`). The integrator's loop has no static length, so it cannot be reversed; under
``Config(adjoint="reverse")`` the derivative rule instead builds the forward-mode Jacobian in every floating-point
leaf of (params, inputs) that carries a tangent (one merged sensitivity solve) and contracts it with the
tangents: a linear map JAX transposes, so ``jax.grad`` gives Jᵀ·cotangent.
"""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

import growjax.simulation._assembly as assembly
import growjax.simulation._fast_sensitivities as fs
import growjax.simulation.fast as fm
from growjax.model.params import Parameters
from growjax.model.robot import pressure_limit
from growjax.model.signals import Inputs
from growjax.simulation.config import Config
from growjax.simulation.rosenbrock import SAVE_WINDOW, evaluate, integrate, spread
from growjax.simulation.trajectory import Trajectory, finish

# Loosest of rtol and this bounds the sensitivities' error control (see _integrate).
SENSITIVITY_TOL_FLOOR = 1e-6


class Run(eqx.Module):
    """The differentiable part of a solve.

    Attributes:
        outputs: {field: (T,)} on the save grid, SI.
        final_state: (n,) the scaled state at ``t_final``.
        t_final: the end of the solve, s.
    """

    outputs: dict
    final_state: jax.Array
    t_final: jax.Array


def _primal(run, ts, y0, theta, outputs):
    """(primal Run on ts, state block on ts (T, 1 + p, n), primal states there). A non-finite state (a failed
    run) is evaluated at y0 instead and its outputs are NaN."""
    block = evaluate(run.steps, ts) if run.saved is None else run.saved
    values, saved = assembly.outputs_where_finite(lambda t, y: outputs(t, y, theta), ts, block[:, 0], y0)
    return Run(values, run.y_final[0], run.t_final), block, saved


def _tangent_run(run, ts, saved, block, th, output_tangents):
    """Tangent `Run` (outputs field → (p, T)) of one member from its state block on ts (T, 1 + p, n)."""
    d_values = jax.vmap(output_tangents, in_axes=(0, 0, 0, None), out_axes=1)(ts, saved, block[:, 1:], th)
    # A tangent solve that stopped early (step budget) has no sensitivities past its end: NaN, never frozen.
    reached = (ts <= run.t_final) | (run.status == 1)
    d_values = {k: jnp.where(reached, v, jnp.nan) for k, v in d_values.items()}
    return Run(d_values, run.y_final[1:], jnp.zeros(run.y_final.shape[0] - 1))


def _sensitivity_run(params, config: Config, y0, theta_s, size, s0, tangent_field, **kw):
    """The state and its sensitivities integrated together (`growjax.simulation.rosenbrock.integrate`; ``kw``: breaks,
    jumps, batched), θ_s from `sensitivities`, with twice the step budget of a plain solve. With
    forward-mode tangents the state's Jacobian is taken in forward mode too: the field's ``jvp`` is compiled
    anyway, and under the Lockhart law each difference column would repeat the rod balance's Newton solve
    (one Jacobian in 3 parameters on the public experiment, small loops: 16 ms against 18 ms)."""
    rtol, atol = config.tolerances
    field, _, event = fs.callbacks(config)
    # The difference quotients carry roundoff of ~1e-10 relative: tighter sensitivity control only burns steps.
    s_rtol, s_atol = max(rtol, SENSITIVITY_TOL_FLOOR), max(atol, SENSITIVITY_TOL_FLOOR)
    return integrate(
        lambda t, y, th: field(t, y, th[0]),
        y0,
        config.t0,
        config.t1,
        args=theta_s,
        tangent_field=tangent_field,
        s0=s0,
        s_rtol=s_rtol,
        s_atol=s_atol * jnp.maximum(size, 1e-12),
        rtol=rtol,
        atol=atol,
        max_steps=2 * config.step_budget,
        dt0=config.initial_step,
        forward_jacobian=fs.forward_mode_tangents(params, config),
        small_loops=bool(config.small_loops),
        event=None if event is None else (lambda t, y, th: event(t, y, th[0])),
        **kw,
    )


def _integrate_batch(params, inputs, config: Config, ts, jump_ts, step_ts, directions=None):
    """The solve of a batch (every argument with a leading axis B; ``directions`` leaves (B, p, …)) in one loop:
    (Run, tangent Run or None, status, steps), each with the leading axis B."""
    rtol, atol = config.tolerances
    field, outputs, event = fs.callbacks(config)
    theta, y0, breaks, jumps = jax.vmap(lambda p, i, j, s: fs.member(p, i, config, j, s))(
        params, inputs, jump_ts, step_ts
    )
    if y0.shape[0] >= fm.SHARED_BATCH_MIN:
        theta = (*theta[:-1], dataclasses.replace(theta[-1], share_values=True))
    if directions is None:
        run = integrate(
            field,
            y0,
            config.t0,
            config.t1,
            args=theta,
            breaks=breaks,
            jumps=jumps,
            rtol=rtol,
            atol=atol,
            max_steps=config.step_budget,
            dt0=config.initial_step,
            event=event,
            batched=True,
            save_ts=ts,
            small_loops=bool(config.small_loops),
        )
        primal = jax.vmap(lambda r, t, y, th: _primal(r, t, y, th, outputs)[0])(run, ts, y0, theta)
        return primal, None, run.status, run.steps.count
    theta_s, size, s0 = jax.vmap(lambda p, i, j, s, d: fs.sensitivities(p, i, config, j, s, d))(
        params, inputs, jump_ts, step_ts, directions
    )
    tangent_field, output_tangents = fs.sensitivity_callbacks(params, config)
    run = _sensitivity_run(
        params, config, y0, theta_s, size, s0, tangent_field, breaks=breaks, jumps=jumps, batched=True
    )

    def member(r, t, y, th):
        primal, block, saved = _primal(r, t, y, th[0], outputs)
        return primal, _tangent_run(r, t, saved, block, th, output_tangents)

    primal, tangent = jax.vmap(member)(run, ts, y0, theta_s)
    return primal, tangent, run.status, run.steps.count


def _integrate(params, inputs, config: Config, ts, jump_ts, step_ts, directions=None, start=None):
    """(Run, tangent Run with a leading axis p or None, status, accepted steps).

    ``start`` = (t_start s, t_end s, scaled state at t_start (n,)), each may be traced: the window and the
    initial state in place of ``config``'s (plain solves only).

    ``directions`` = (parameter tangents, input tangents), each leaf with a leading axis p: the
    sensitivities along them are integrated with the state, under its error control. Their field
    (``config.tangents``, `forward_mode_tangents`) is either the vector field's ``jax.jvp`` along
    each direction, the primal evaluated once, or its central difference quotient (as CVODES does by
    default), (f(y + εS, θ + εd) − f(y − εS, θ − εd))/2ε, with ε fixed per direction so that the
    parameters move by (machine ε)^⅓ of themselves, one batched evaluation of the primal field for
    all directions. (The two agree to the quotients' error, ~1e-5 relative, ``tests/test_growth_law.py``;
    the ``jvp`` batched over directions that XLA:CPU miscompiled when this solver was written is computed
    correctly now.)
    """
    rtol, atol = config.tolerances
    field, outputs, event = fs.callbacks(config)
    theta, y0, breaks, jumps = fs.member(params, inputs, config, jump_ts, step_ts)
    t0, t1 = config.t0, config.t1
    if start is not None:
        t0, t1, y0 = start
    # A window saved at fewer times than one step may cover (a plant's tick, a filter's sample) interpolates them
    # inside the loop and records no steps: its cost then does not grow with the step budget (a forward-mode
    # Jacobian in 13 directions over 10 ms: 7 ms with 200 recorded steps, 0.7 ms with 32). The steps and the
    # values are the same: no step is capped by fewer save times than a window's.
    in_loop = start is not None and ts.shape[0] < SAVE_WINDOW
    if directions is None:
        run = integrate(
            field,
            y0,
            t0,
            t1,
            args=theta,
            breaks=breaks,
            jumps=jumps,
            rtol=rtol,
            atol=atol,
            max_steps=config.step_budget,
            dt0=config.initial_step,
            event=event,
            save_ts=ts if in_loop else None,
            small_loops=bool(config.small_loops),
        )
        primal = _primal(run, ts, y0, theta, outputs)[0]
        return primal, None, run.status, run.steps.count
    theta_s, size, s0 = fs.sensitivities(params, inputs, config, jump_ts, step_ts, directions)
    tangent_field, output_tangents = fs.sensitivity_callbacks(params, config)
    run = _sensitivity_run(params, config, y0, theta_s, size, s0, tangent_field, breaks=breaks, jumps=jumps)
    primal, block, saved = _primal(run, ts, y0, theta, outputs)
    return primal, _tangent_run(run, ts, saved, block, theta_s, output_tangents), run.status, run.steps.count


@functools.lru_cache(maxsize=16)
def _plain_solver(config: Config):
    """``(params, inputs, ts, jump_ts, step_ts) → (Run, status, steps)``; under ``vmap`` the members are
    stepped together in one loop (`_integrate_batch`) instead of a vmapped loop per member."""

    def plain(params, inputs, ts, jump_ts, step_ts):
        primal, _, status, n_steps = _integrate(params, inputs, config, ts, jump_ts, step_ts)
        return primal, status, n_steps

    solver = jax.custom_batching.custom_vmap(plain)

    @solver.def_vmap
    def together(axis_size, in_batched, *args):
        args = spread(args, in_batched, axis_size)
        primal, _, status, n_steps = _integrate_batch(*args[:2], config, *args[2:])
        out = (primal, status, n_steps)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return solver


def _tangent_solver(config: Config):
    """``(params, inputs, ts, jump_ts, step_ts, d_params, d_inputs) → (Run, tangent Run, status, steps)`` for
    directions with a leading axis p, batched over directions by merging them into one solve (``custom_vmap``)."""

    def plain(params, inputs, ts, jump_ts, step_ts, d_params, d_inputs):
        return _integrate(params, inputs, config, ts, jump_ts, step_ts, (d_params, d_inputs))

    solver = jax.custom_batching.custom_vmap(plain)

    @solver.def_vmap
    def merge_directions(axis_size, in_batched, params, inputs, ts, jump_ts, step_ts, d_params, d_inputs):
        args = (params, inputs, ts, jump_ts, step_ts, d_params, d_inputs)
        if any(jax.tree_util.tree_leaves(in_batched[:5])):  # the point itself is batched: members stepped together
            args = spread(args, in_batched, axis_size)
            out = _integrate_batch(*args[:2], config, *args[2:5], directions=args[5:])
            return out, jax.tree_util.tree_map(lambda _: True, out)

        def flat(x, batched):  # (axis_size, p, …) → (axis_size·p, …)
            x = x if batched else jnp.broadcast_to(x, (axis_size,) + jnp.shape(x))
            return x.reshape((axis_size * x.shape[1],) + x.shape[2:])

        dp = jax.tree_util.tree_map(flat, d_params, in_batched[5])
        di = jax.tree_util.tree_map(flat, d_inputs, in_batched[6])
        primal, tangent, status, n_steps = solver(params, inputs, ts, jump_ts, step_ts, dp, di)
        tangent = jax.tree_util.tree_map(lambda x: x.reshape((axis_size, -1) + x.shape[1:]), tangent)
        unbatched = jax.tree_util.tree_map(lambda _: False, (primal, status, n_steps))
        return (primal, tangent, status, n_steps), (
            unbatched[0],
            jax.tree_util.tree_map(lambda _: True, tangent),
            unbatched[1],
            unbatched[2],
        )

    return solver


def _run(params, inputs, config: Config, ts, jump_ts, step_ts):
    """(Run, status, accepted steps) of the fast configuration, with the derivative rule ``config.adjoint`` picks."""
    rule = _run_forward if config.adjoint == "forward" else _run_reverse
    return rule(params, inputs, config, ts, jump_ts, step_ts)


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _run_forward(params, inputs, config: Config, ts, jump_ts, step_ts):
    """`_run` whose derivative is the sensitivity solve along the tangents (forward mode only)."""
    return _plain_solver(config)(params, inputs, ts, jump_ts, step_ts)


@_run_forward.defjvp
def _run_forward_jvp(config, primals, tangents):
    params, inputs, ts, jump_ts, step_ts = primals
    d_params, d_inputs = tangents[0], tangents[1]
    # The primal is a plain solve: under jax.linearize (optimistix, numpyro) it must not depend on the
    # tangents, whose error control moves the steps of the solve that carries them.
    primal, status, n_steps = _plain_solver(config)(params, inputs, ts, jump_ts, step_ts)

    def one(x):
        return jnp.asarray(x)[None]

    tangent = _tangent_solver(config)(
        params,
        inputs,
        ts,
        jump_ts,
        step_ts,
        jax.tree_util.tree_map(one, d_params),
        jax.tree_util.tree_map(one, d_inputs),
    )[1]
    tangent = jax.tree_util.tree_map(lambda x: x[0], tangent)
    zero = np.zeros((), dtype=jax.dtypes.float0)
    return (primal, status, n_steps), (tangent, zero, zero)


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _run_reverse(params, inputs, config: Config, ts, jump_ts, step_ts):
    """`_run` whose derivative is the Jacobian in the leaves that carry tangents, contracted with them
    (forward and reverse mode)."""
    return _plain_solver(config)(params, inputs, ts, jump_ts, step_ts)


def _inexact(x) -> bool:
    return jnp.issubdtype(jnp.result_type(x), jnp.inexact)


def _unit_directions(point, d_point):
    """(unit directions (N, …) over every element of the floating-point leaves of ``point`` whose tangent in
    ``d_point`` is not a symbolic zero, with ``point``'s structure; those tangents flattened (N,))."""
    leaves, treedef = jax.tree_util.tree_flatten(point)
    d_leaves = treedef.flatten_up_to(d_point)
    active = [not isinstance(d, jax.custom_derivatives.SymbolicZero) and _inexact(x) for x, d in zip(leaves, d_leaves)]
    sizes = [int(np.size(x)) if a else 0 for x, a in zip(leaves, active)]
    total, offset, directions = sum(sizes), 0, []
    for x, a, size in zip(leaves, active, sizes):
        shape = np.shape(x)
        if not _inexact(x):
            directions.append(np.zeros((total,) + shape, dtype=jax.dtypes.float0))
            continue
        unit = np.zeros((total, int(np.size(x))))
        if a:
            unit[offset : offset + size] = np.eye(size)
        directions.append(jnp.asarray(unit.reshape((total,) + shape), jnp.result_type(x)))
        offset += size
    flat = [jnp.ravel(d) for d, a in zip(d_leaves, active) if a]
    return jax.tree_util.tree_unflatten(treedef, directions), (jnp.concatenate(flat) if flat else None)


def _run_reverse_jvp(config, primals, tangents):
    params, inputs, ts, jump_ts, step_ts = primals
    primal, status, n_steps = _plain_solver(config)(params, inputs, ts, jump_ts, step_ts)
    zero = np.zeros((), dtype=jax.dtypes.float0)
    directions, d_flat = _unit_directions((params, inputs), (tangents[0], tangents[1]))
    if d_flat is None:  # no leaf carries a tangent
        return (primal, status, n_steps), (jax.tree_util.tree_map(jnp.zeros_like, primal), zero, zero)
    # The Jacobian depends on the primals only (JAX keeps it out of the linear part); its contraction is linear.
    jac = _tangent_solver(config)(params, inputs, ts, jump_ts, step_ts, *directions)[1]
    tangent = jax.tree_util.tree_map(lambda j: jnp.tensordot(d_flat, j, axes=1), jac)
    return (primal, status, n_steps), (tangent, zero, zero)


_run_reverse.defjvp(_run_reverse_jvp, symbolic_zeros=True)


def solve(
    params: Parameters,
    inputs: Inputs,
    config: Config,
    ts: Float[Array, " T"],
    jump_ts: Float[Array, " J"],
    step_ts: Float[Array, " K"],
) -> Trajectory:
    """Integrate the fast configuration and return a `growjax.simulation.trajectory.Trajectory` on ``ts``.

    Differentiable in ``params`` and ``inputs``: the sensitivities are integrated with the state under the same
    error control (`growjax.simulation.rosenbrock.integrate`), and a batch of directions is one solve. With
    ``config.adjoint == "forward"`` along the tangents themselves (forward mode only); with ``"reverse"`` as the
    Jacobian in every leaf that carries a tangent, contracted with them (forward mode and ``jax.grad``).
    """
    run, status, n_steps = _run(params, inputs, config, ts, jump_ts, step_ts)
    return _trajectory(params, inputs, config, ts, run, status, n_steps)


def solve_from(
    params: Parameters,
    inputs: Inputs,
    config: Config,
    ts: Float[Array, " T"],
    jump_ts: Float[Array, " J"],
    step_ts: Float[Array, " K"],
    start: tuple[Float[ArrayLike, ""], Float[ArrayLike, ""], Float[Array, " n"]],
) -> Trajectory:
    """`solve` from a scaled state over a window that may be traced, ``start`` = (t_start s, t_end s, state
    (n,)); under ``vmap`` a loop per member. Forward mode only (through the integrator's loop)."""
    run, _, status, n_steps = _integrate(params, inputs, config, ts, jump_ts, step_ts, start=start)
    return _trajectory(params, inputs, config, ts, run, status, n_steps)


def solve_members(
    params: Parameters,
    inputs: Inputs,
    config: Config,
    ts: Float[Array, " T"],
    jump_ts: Float[Array, " J"],
    step_ts: Float[Array, " K"],
) -> Trajectory:
    """`solve` for a batch of parameter sets (every leaf of ``params`` with a leading axis B; inputs, ``ts``
    and breaks shared): a `growjax.simulation.trajectory.Trajectory` with a leading axis B.

    The members are stepped together in one loop, as under ``jax.vmap(solve)``, but the one-member solve is
    never traced (``custom_vmap`` traces it to learn its output shapes: 0.46 s of the 500-set sweep's
    compile). Not differentiable: differentiate ``jax.vmap(solve)``.
    """
    return _members(params, inputs, config, ts, jump_ts, step_ts)


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _members(params, inputs, config: Config, ts, jump_ts, step_ts):
    """The batched solve of `solve_members`; its derivative rule refuses (no error-controlled tangents here)."""
    size = jax.tree_util.tree_leaves(params)[0].shape[0]
    inputs_b, ts_b, jump_b, step_b = jax.tree_util.tree_map(
        lambda x: jnp.broadcast_to(x, (size,) + jnp.shape(x)), (inputs, ts, jump_ts, step_ts)
    )
    run, _, status, n_steps = _integrate_batch(params, inputs_b, config, ts_b, jump_b, step_b)
    return jax.vmap(_trajectory, in_axes=(0, None, None, None, 0, 0, 0))(
        params, inputs, config, ts, run, status, n_steps
    )


@_members.defjvp
def _members_jvp(config, primals, tangents):
    raise TypeError(
        "fast_model.solve_members (simulate_members) is not differentiable: differentiate jax.vmap(simulate) instead"
    )


def _trajectory(params, inputs, config: Config, ts, run: Run, status, n_steps):
    """The `growjax.simulation.trajectory.Trajectory` of a primal `Run` on ``ts``."""
    demand = jax.vmap(inputs.pressure_demand)(ts)
    return finish(
        ts,
        run.outputs,
        pressure_limit(params.robot),
        demand,
        config.stop_at_pressure_limit,
        t_final=run.t_final,
        status=status,
        n_steps=n_steps,
        final_state=run.final_state,
    )


def solve_with_sensitivities(
    params: Parameters,
    inputs: Inputs,
    config: Config,
    ts: Float[Array, " T"],
    jump_ts: Float[Array, " J"],
    step_ts: Float[Array, " K"],
    directions: tuple[Parameters, Inputs],
) -> tuple[Trajectory, dict[str, Float[Array, "p T"]]]:
    """(`growjax.simulation.trajectory.Trajectory` on ``ts``, tangent outputs {field: (p, T)}) from one solve that
    integrates the state with its sensitivities along ``directions`` = (parameter tangents, input tangents),
    each leaf with a leading axis p (`_integrate`).

    Cheaper by one plain solve than ``jax.jvp`` through `solve`, whose primal comes from a plain solve so
    that it never depends on the tangents (``jax.linearize`` needs that); here the primal is the sensitivity
    solve's own, whose steps the tangents' error control also sets (they differ within the tolerance). For
    fixed directions (a Jacobian), where that dependence is harmless. Tangents past a stop are NaN.
    """
    primal, tangent, status, n_steps = _integrate(params, inputs, config, ts, jump_ts, step_ts, directions)
    traj = _trajectory(params, inputs, config, ts, primal, status, n_steps)
    after = ts > primal.t_final + 1e-12
    return traj, {k: jnp.where(after, jnp.nan, v) for k, v in tangent.outputs.items()}
