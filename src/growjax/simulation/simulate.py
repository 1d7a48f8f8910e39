"""``simulate(params, inputs, config)``: the one entry point above both configurations."""

from __future__ import annotations

import weakref

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from growjax.model import effects as fx
from growjax.model.params import Parameters
from growjax.model.signals import Inputs
from growjax.simulation import _fast_solve
from growjax.simulation import reference as reference_model
from growjax.simulation.config import Config
from growjax.simulation.trajectory import Trajectory

_PAD_BLOCK = 32
_DEFAULT_CONFIG = Config()  # Config is immutable: one default instance serves every call
Breaks = tuple[Float[Array, " J"], Float[Array, " K"]]  # (jump times, slope-break times), s, padded beyond t1


def _traced(tree) -> bool:
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(tree))


def as_arrays(tree):
    """Python numbers in a pytree as float arrays, so ``jit`` traces them instead of recompiling per value.

    NumPy scalars, not JAX arrays: making a device array per leaf costs ~0.1 ms each, more than a simulation's step
    loop.
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
    """(jump times, slope-break times) of ``inputs`` inside the window, padded: what the solvers step onto.

    Needs concrete inputs; under a trace, compute it outside and pass it to :func:`simulate`. Remembered per
    inputs object (~2 ms of Python each time, a tenth of a simulation) while it lives, when its leaves are
    immutable (JAX arrays, numbers, empty or read-only NumPy arrays; others could change in place).
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


def sample_times(times, config: Config):
    """``times`` (s, sorted) clipped into the simulated window [t0, t1]: a save grid at the samples themselves.

    Fits and scores save the solution where the data were taken instead of interpolating the default
    10 ms grid linearly: that grid starts at t0, so it falls between samples taken at whole hundredths,
    and a straight line between its points misses the length where a pulse edge bends it. Samples
    outside the window land on its ends.
    """
    return jnp.clip(jnp.asarray(times, float), config.t0, config.t1)


def simulate(
    params: Parameters,
    inputs: Inputs,
    config: Config = _DEFAULT_CONFIG,
    ts: Float[ArrayLike, " T"] | None = None,
    breaks: Breaks | None = None,
) -> Trajectory:
    """Simulate the robot: (parameters, inputs, configuration) → :class:`growjax.Trajectory`.

    Pure and usable under ``jax.jit``, ``jax.vmap``, ``jax.grad`` and ``jax.jvp`` with respect to
    any leaf of ``params`` (effects included). ``config.fidelity`` picks the configuration:
    ``"fast"`` (default; :mod:`growjax.simulation.fast`) or ``"reference"`` (:mod:`growjax.simulation.reference`).
    ``ts`` (s, sorted, within [t0, t1]) is the save grid, default ``config.save_grid()``.
    ``breaks`` = (jump times, slope-break times) of the inputs, found from ``inputs`` when they
    are concrete (:func:`input_breaks`). A failed solve is reported in ``status``, never raised.
    """
    return _solve(*_arguments(params, inputs, config, ts, breaks))


def simulate_members(
    params: Parameters,
    inputs: Inputs,
    config: Config = _DEFAULT_CONFIG,
    ts: Float[ArrayLike, " T"] | None = None,
    breaks: Breaks | None = None,
) -> Trajectory:
    """:func:`simulate` for a batch of parameter sets: every leaf of ``params`` with a leading axis B (e.g. made by
    ``jax.vmap`` of :func:`growjax.replace`), the inputs, ``ts`` and ``breaks`` shared. → a
    :class:`growjax.Trajectory` whose fields have a leading axis B.

    Equal to ``jax.vmap(simulate, in_axes=(0, None))``, and quicker to compile in the fast configuration (its
    one-member program is never traced). Not differentiable: differentiate ``jax.vmap(simulate)``.
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
    """:func:`simulate` from a scaled state ``state`` (the configuration's layout, as ``Trajectory.final_state``)
    over ``window`` = (t_start, t_end) s in place of ``config``'s [t0, t1] and its state at rest: a plant stepped
    tick by tick. The state and window may be traced (``breaks`` must then be given: (jump times, slope-break
    times), each padded beyond t_end); ``ts`` (s) within the window. Under ``vmap`` each member is its own loop.
    Forward-mode differentiable through the integrator's loop, in the parameters, the inputs and the state (the
    tangents of its W-method, whose Jacobian is held over each step: the exact derivative of the discrete map);
    not in the window. ``config.first_step`` near the window's length spares the climb from a 10 µs first step.
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


def length_jacobian(params_of, w, inputs, config: Config, ts, breaks=None) -> tuple[Trajectory, jax.Array]:
    """(trajectory, ∂length/∂w (T, p)) of the fast configuration at ``params_of(w)``, w (p,), on the save grid
    ``ts`` (s): one solve carries the p sensitivities and gives both
    (:func:`growjax.simulation._fast_solve.solve_with_sensitivities`), where ``jax.jacfwd`` of :func:`simulate` adds a
    plain solve for the primal. ``params_of``: w → Parameters (traceable; hashable, the compiled program is kept per
    function). ``breaks`` as in :func:`simulate`.
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
    traj, tangents = _fast_solve.solve_with_sensitivities(
        params, inputs, config, ts, jump_ts, step_ts, (d_params, d_inputs)
    )
    return traj, tangents["length"].T
