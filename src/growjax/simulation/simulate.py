"""``simulate(params, inputs, config)``: the one entry point above both configurations."""

from __future__ import annotations

import weakref
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PyTree

import growjax.model.effects as fx
import growjax.simulation._fast_solve as _fast_solve
import growjax.simulation.reference as reference_model
from growjax.model.params import Parameters
from growjax.model.signals import Inputs
from growjax.simulation.config import Config
from growjax.simulation.trajectory import Trajectory

__all__ = [
    "Breaks",
    "as_arrays",
    "forward_sensitivities",
    "input_breaks",
    "length_jacobian",
    "sample_times",
    "simulate",
    "simulate_from",
    "simulate_members",
]

_PAD_BLOCK = 32
_DEFAULT_CONFIG = Config()  # Config is immutable: one default instance serves every call
Breaks = tuple[Float[Array, " J"], Float[Array, " K"]]  # (jump times, slope-break times), s, padded beyond t1


def _traced(tree) -> bool:
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(tree))


def as_arrays(tree: PyTree) -> PyTree:
    """Python numbers in a pytree as float arrays, so ``jit`` traces them instead of recompiling per value.

    NumPy scalars, not JAX arrays: making a device array per leaf costs ~0.1 ms each, more than a simulation's step
    loop.

    Args:
        tree: any pytree (parameters, inputs).

    Returns:
        The pytree, its Python floats and ints (not bools) as float64 NumPy scalars.
    """

    def convert(x):
        if isinstance(x, (float, int)) and not isinstance(x, bool):
            return np.asarray(x, np.float64)
        return x

    return jax.tree_util.tree_map(convert, tree)


def _padded(times, t1: float) -> jax.Array:
    """Times padded beyond t1 (never reached) to a multiple of a block, so inputs with a similar number of
    edges share one compiled solver."""
    times = np.asarray(times, float).ravel()
    size = _PAD_BLOCK * max(1, -(-times.size // _PAD_BLOCK))
    return jnp.asarray(np.concatenate([np.sort(times), np.full(size - times.size, t1 + 1.0)]))


def input_breaks(inputs: Inputs, config: Config) -> Breaks:
    """The discontinuities of the inputs inside the simulated window: what the solvers step onto.

    Needs concrete inputs; under a trace, compute it outside and pass it to `simulate`. Remembered per
    inputs object (~2 ms of Python each time, a tenth of a simulation) while it lives, when its leaves are
    immutable (JAX arrays, numbers, empty or read-only NumPy arrays; others could change in place).

    Args:
        inputs: the input signals.
        config: the configuration (its window [t0, t1]).

    Returns:
        (jump times (J,), slope-break times (K,)), s, each padded beyond t1 to a multiple of 32.

    Raises:
        ValueError: where the inputs are traced.
    """
    window = (float(config.t0), float(config.t1))
    hit = _BREAKS.get(id(inputs))
    if hit is not None and hit[0]() is inputs and hit[1] == window:
        return hit[2]
    try:
        jumps = inputs.jump_times(config.t0, config.t1)
        kinks = inputs.kink_times(config.t0, config.t1)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        raise ValueError(
            "the inputs are traced, so their discontinuities cannot be found here: compute "
            "growjax.input_breaks(inputs, config) outside the transformation and pass it as breaks="
        ) from None
    breaks = _padded(jumps, config.t1), _padded(np.setdiff1d(kinks, jumps), config.t1)
    # Not under a trace: there JAX makes even a constant array a tracer, which must not outlive it.
    if not _traced(breaks) and all(map(_immutable, jax.tree_util.tree_leaves(inputs))):
        key = id(inputs)
        try:  # forgotten when the inputs are freed (before their id can be reused)
            ref = weakref.ref(inputs, lambda _, k=key: _BREAKS.pop(k, None))
        except TypeError:
            return breaks
        _BREAKS[key] = (ref, window, breaks)
    return breaks


_BREAKS: dict[int, tuple] = {}  # id(inputs) → (weak reference to them, (t0, t1), their breaks)


def _immutable(leaf) -> bool:
    if isinstance(leaf, np.ndarray):
        return leaf.size == 0 or not leaf.flags.writeable
    return isinstance(leaf, (jax.Array, float, int, np.generic))


def sample_times(times: Float[ArrayLike, " T"], config: Config) -> Float[Array, " T"]:
    """Sample times clipped into the simulated window [t0, t1]: a save grid at the samples themselves.

    Fits and scores save the solution where the data were taken instead of interpolating the default
    10 ms grid linearly: that grid starts at t0, so it falls between samples taken at whole hundredths,
    and a straight line between its points misses the length where a pulse edge bends it. Samples
    outside the window land on its ends.

    Args:
        times: (T,) sorted sample times, s.
        config: the configuration (its window).

    Returns:
        (T,) the save grid, s.
    """
    return jnp.clip(jnp.asarray(times, float), config.t0, config.t1)


def simulate(
    params: Parameters,
    inputs: Inputs,
    config: Config = _DEFAULT_CONFIG,
    ts: Float[ArrayLike, " T"] | None = None,
    breaks: Breaks | None = None,
) -> Trajectory:
    """Simulate the robot.

    Pure and usable under ``jax.jit``, ``jax.vmap``, ``jax.grad`` and ``jax.jvp`` with respect to
    any leaf of ``params`` (effects included). A failed solve is reported in ``status``, never raised.

    Args:
        params: the parameters, SI.
        inputs: the input signals.
        config: the configuration; ``config.fidelity`` picks ``"fast"`` (default; `growjax.simulation.fast`) or
            ``"reference"`` (`growjax.simulation.reference`).
        ts: (T,) the save grid, s, sorted, within [t0, t1]; default ``config.save_grid()``.
        breaks: (jump times, slope-break times) of the inputs, s (`input_breaks`); found from ``inputs`` when
            they are concrete.

    Returns:
        The `growjax.Trajectory` on ``ts``.

    Raises:
        ValueError: for a save grid that is not 1-D, finite, sorted and within [t0, t1], or traced inputs
            without ``breaks``.
    """
    return _solve(*_arguments(params, inputs, config, ts, breaks))


def simulate_members(
    params: Parameters,
    inputs: Inputs,
    config: Config = _DEFAULT_CONFIG,
    ts: Float[ArrayLike, " T"] | None = None,
    breaks: Breaks | None = None,
) -> Trajectory:
    """`simulate` for a batch of parameter sets, the inputs, ``ts`` and ``breaks`` shared.

    Equal to ``jax.vmap(simulate, in_axes=(0, None))``, and quicker to compile in the fast configuration (its
    one-member program is never traced). Not differentiable: differentiate ``jax.vmap(simulate)``.

    Args:
        params: the parameters, every leaf with a leading axis B (e.g. made by ``jax.vmap`` of `growjax.replace`).
        inputs: the input signals.
        config: the configuration.
        ts: (T,) the save grid, s (as in `simulate`).
        breaks: the inputs' breaks (as in `simulate`).

    Returns:
        A `growjax.Trajectory` whose fields have a leading axis B.
    """
    return _solve_members(*_arguments(params, inputs, config, ts, breaks))


def simulate_from(
    params: Parameters,
    inputs: Inputs,
    config: Config,
    state: Float[ArrayLike, " n"],
    window: tuple[Float[ArrayLike, ""], Float[ArrayLike, ""]],
    ts: Float[ArrayLike, " T"],
    breaks: Breaks,
) -> Trajectory:
    """`simulate` from a given state over a given window, in place of ``config``'s [t0, t1] and its state at
    rest: a plant stepped tick by tick.

    Under ``vmap`` each member is its own loop. ``config.first_step`` near the window's length spares the climb
    from a 10 µs first step. Forward-mode differentiable through the integrator (not in the
    state or window).

    Args:
        params: the parameters, SI.
        inputs: the input signals.
        config: the configuration.
        state: (n,) the scaled state in the configuration's layout (as ``Trajectory.final_state``); may be traced.
        window: (t_start, t_end), s; may be traced.
        ts: (T,) the save grid, s, within the window.
        breaks: (jump times, slope-break times) of the inputs, s, each padded beyond t_end (`input_breaks`).

    Returns:
        The `growjax.Trajectory` on ``ts``.
    """
    jump_ts, step_ts = breaks
    config = config.resolved()
    start = (jnp.asarray(window[0], float), jnp.asarray(window[1], float), jnp.asarray(state, float))
    return _solve_from(as_arrays(params), as_arrays(inputs), config, jnp.asarray(ts, float), jump_ts, step_ts, start)


@eqx.filter_jit
def _solve_from(params, inputs, config: Config, ts, jump_ts, step_ts, start) -> Trajectory:
    params = fx.apply_all(params)
    solve = _fast_solve.solve_from if config.fidelity == "fast" else reference_model.solve
    return solve(params, inputs, config, ts, jump_ts, step_ts, start)


def _arguments(params, inputs, config: Config, ts, breaks):
    """(params, inputs, config, ts, jump times, slope-break times) of a solve: the save grid checked (default
    ``config.save_grid()``), the inputs' breaks found unless given, Python numbers as arrays."""
    if ts is None:
        ts = config.save_grid()
    _check_times(ts, config)
    jump_ts, step_ts = input_breaks(inputs, config) if breaks is None else breaks
    return as_arrays(params), as_arrays(inputs), config.resolved(), jnp.asarray(ts, float), jump_ts, step_ts


def _check_times(ts, config: Config):
    """Refuse a save grid that is not 1-D, finite, sorted and inside [t0, t1] (unless traced)."""
    if _traced(ts):
        return
    t = np.asarray(ts, float)
    if t.ndim != 1 or t.size < 1 or not np.all(np.isfinite(t)):
        raise ValueError("ts must be a 1-D array of finite times (s)")
    if np.any(np.diff(t) < 0):
        raise ValueError("ts must be sorted")
    if t[0] < config.t0 - 1e-12 or t[-1] > config.t1 + 1e-12:
        raise ValueError(f"ts must lie within [t0, t1] = [{config.t0}, {config.t1}] s")


@eqx.filter_jit
def _solve(params, inputs, config: Config, ts, jump_ts, step_ts) -> Trajectory:
    params = fx.apply_all(params)
    solve = _fast_solve.solve if config.fidelity == "fast" else reference_model.solve
    return solve(params, inputs, config, ts, jump_ts, step_ts)


@eqx.filter_jit
def _solve_members(params, inputs, config: Config, ts, jump_ts, step_ts) -> Trajectory:
    params = jax.vmap(fx.apply_all)(params)
    if config.fidelity == "fast":
        return _fast_solve.solve_members(params, inputs, config, ts, jump_ts, step_ts)
    return jax.vmap(reference_model.solve, in_axes=(0, None, None, None, None, None))(
        params, inputs, config, ts, jump_ts, step_ts
    )


def length_jacobian(
    params_of: Callable[[Float[Array, " p"]], Parameters],
    w: Float[ArrayLike, " p"],
    inputs: Inputs,
    config: Config,
    ts: Float[ArrayLike, " T"],
    breaks: Breaks | None = None,
) -> tuple[Trajectory, Float[Array, "T p"]]:
    """The fast configuration's trajectory and the length's Jacobian in w, from one solve that carries the p
    sensitivities (`forward_sensitivities`, compiled here), where ``jax.jacfwd`` of `simulate` adds a plain
    solve for the primal.

    Args:
        params_of: w → Parameters, traceable and hashable (the compiled program is kept per function).
        w: (p,) the point.
        inputs: the input signals.
        config: the fast configuration.
        ts: (T,) the save grid, s.
        breaks: the inputs' breaks (as in `simulate`).

    Returns:
        (the trajectory at ``params_of(w)`` on ``ts``, ∂length/∂w (T, p) in m per unit of w).

    Raises:
        ValueError: for the reference configuration or a bad save grid.
    """
    if config.fidelity != "fast":
        raise ValueError("length_jacobian runs the fast configuration; use jax.jacfwd of simulate for the reference")
    _check_times(ts, config)
    if breaks is None:
        breaks = input_breaks(inputs, config)
    jump_ts, step_ts = breaks
    return _length_jacobian(
        params_of, jnp.asarray(w, float), as_arrays(inputs), config.resolved(), jnp.asarray(ts, float), jump_ts, step_ts
    )


@eqx.filter_jit
def _length_jacobian(params_of, w, inputs, config: Config, ts, jump_ts, step_ts):
    traj, tangents = forward_sensitivities(params_of, w, inputs, config, ts, (jump_ts, step_ts))
    return traj, tangents["length"].T


def forward_sensitivities(
    params_of: Callable[[Float[Array, " p"]], Parameters],
    w: Float[Array, " p"],
    inputs: Inputs,
    config: Config,
    ts: Float[ArrayLike, " n"],
    breaks: Breaks,
) -> tuple[Trajectory, dict[str, Float[Array, "p n"]]]:
    """The fast configuration's trajectory at ``params_of(w)`` and its sensitivities to w, from one solve that
    integrates the state with its tangents (one plain solve cheaper than ``jax.jvp`` through `simulate`).

    Traceable and not compiled here: a caller compiles it inside its own program, and may differentiate it again
    in forward mode (the solver's loop carries the tangents, so a design's gradient goes through them).

    Args:
        params_of: w → Parameters (traceable); its effects are applied here.
        w: (p,) the point the sensitivities are taken at.
        inputs: the inputs, their numbers as arrays (`as_arrays`).
        config: the fast configuration, resolved (`Config.resolved`).
        ts: (n,) s, the save times (inside the configuration's window).
        breaks: (jump times, slope-break times) of the inputs, s (`input_breaks`).

    Returns:
        (the trajectory on ``ts``, {output: (p, n) its derivative along each coordinate of w}) for the outputs
        ``"length"`` (m) and ``"pressure"`` (Pa) among others; NaN past a stop.
    """

    def applied(v):
        return fx.apply_all(as_arrays(params_of(v)))

    params = applied(w)
    mask = jax.tree_util.tree_map(eqx.is_inexact_array, params)
    p = w.shape[0]

    def zeros(x):
        return jnp.zeros((p,) + jnp.shape(x))

    d_float = jax.vmap(lambda e: jax.jvp(lambda v: eqx.filter(applied(v), mask), (w,), (e,))[1])(jnp.eye(p))
    d_params = eqx.combine(d_float, jax.tree_util.tree_map(zeros, eqx.filter(params, mask, inverse=True)))
    d_inputs = jax.tree_util.tree_map(zeros, inputs)
    return _fast_solve.solve_with_sensitivities(params, inputs, config, ts, *breaks, (d_params, d_inputs))
