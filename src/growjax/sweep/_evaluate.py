"""Scoring a design: every row simulated in one compiled, sharded, chunked call, and the result.

One ``jit(shard_map(vmap(...)))`` of the model scores each point against a measured length (RMSE over a
window) and reports the final length and the run status. Points are evaluated in equal chunks (one compiled
shape, memory bounded), each chunk split across all devices JAX sees, also across the processes and hosts of a
``jax.distributed.initialize`` run (each process evaluates the rows on its own devices and gets the full result).
A member that fails (solver failure, pressure limit, invalid parameter) is flagged with its reason; the others
are unaffected.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from jaxtyping import Array, ArrayLike, Float, Int

import growjax.sweep.store as _store
from growjax import progress as prog
from growjax.hashing import content_key
from growjax.model import params as gp
from growjax.model.signals import Inputs
from growjax.simulation import xla_flags
from growjax.simulation.config import Config
from growjax.simulation.metrics import rmse_at_samples
from growjax.simulation.simulate import Breaks, as_arrays, input_breaks, sample_times, simulate_members
from growjax.simulation.trajectory import OK, PRESSURE_LIMIT, SOLVER_FAILED
from growjax.sweep._processes import gather, leader, put

__all__ = [
    "FAST",
    "INVALID_PARAMETER",
    "NOT_RUN",
    "QUICK_COMPILE_ROWS",
    "REASONS",
    "ChunkCallback",
    "Measured",
    "Plan",
    "SweepResult",
    "evaluate",
    "make_members",
    "make_plan",
    "run_chunk",
]

INVALID_PARAMETER = 3
FAST = Config()  # default configuration of sweeps
NOT_RUN = _store.NOT_RUN  # status of a stored sweep's rows not yet run (`growjax.sweep.load`)
REASONS = {
    NOT_RUN: "not_run",
    OK: "ok",
    PRESSURE_LIMIT: "pressure_limit",
    SOLVER_FAILED: "solver_failed",
    INVALID_PARAMETER: "invalid_parameter",
}
# Designs up to this many rows compile with XLA's quicker emitters (xla_flags.QUICK_COMPILE) where
# Config.quick_compile is None: up to it the compile they save exceeds the slower run they give
# (``benchmarks/sweep.py`` measures both).
QUICK_COMPILE_ROWS = 15_000

Measured = tuple[Float[ArrayLike, " m"], Float[ArrayLike, " m"]]  # (sample times s, measured length m)
ChunkCallback = Callable[[int, int], Any]  # (chunks done, chunks in all) → ignored

# Compiled sweep programs of this process, keyed by everything they close over (at most 8 kept).
_COMPILED: dict = {}


@dataclasses.dataclass
class SweepResult:
    """Every point of a sweep and its score.

    Attributes:
        names: the d qualified parameter names.
        values: (n, d) parameter values, SI.
        rmse: (n,) length RMSE, m; NaN where there are no data or the member failed.
        final_length: (n,) final length, m.
        status: (n,) status codes (`REASONS` names them).
        wall_s: evaluation time after compilation, s.
        compile_s: compilation time, s, tracing and lowering included.
        n_devices: the devices the sweep was split over.
        lower_s: the part of ``compile_s`` spent tracing and lowering the program to StableHLO, s; the rest is
            XLA's (0 where this process had compiled it).
    """

    names: tuple[str, ...]
    values: Float[np.ndarray, "n d"]
    rmse: Float[np.ndarray, " n"]
    final_length: Float[np.ndarray, " n"]
    status: Int[np.ndarray, " n"]
    wall_s: float = float("nan")
    compile_s: float = float("nan")
    n_devices: int = 1
    lower_s: float = float("nan")

    @property
    def reasons(self) -> list[str]:
        """The status of each point by name (``"ok"``, ``"pressure_limit"`` …)."""
        return [REASONS.get(int(s), f"unknown({int(s)})") for s in self.status]

    @property
    def failed(self) -> np.ndarray:
        """(n,) bool: the points whose run did not succeed."""
        return self.status != OK

    @property
    def best_index(self) -> int | None:
        """Index of the lowest finite RMSE among successful members (None if there is none)."""
        ok = ~self.failed & np.isfinite(self.rmse)
        if not np.any(ok):
            return None
        return int(np.flatnonzero(ok)[np.argmin(self.rmse[ok])])

    def best(self) -> dict | None:
        """The best point, JSON-ready.

        Returns:
            Its index, parameters (SI), length RMSE (m) and final length (m); None where no point succeeded.
        """
        i = self.best_index
        if i is None:
            return None
        return {
            "index": i,
            "parameters": dict(zip(self.names, map(float, self.values[i]))),
            "rmse_length_m": float(self.rmse[i]),
            "final_length_m": float(self.final_length[i]),
        }

    def write_csv(self, path: str | Any) -> None:
        """Write one row per point: parameters, rmse_length_m, final_length_m, status.

        Args:
            path: the CSV file (a path).
        """
        import csv

        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow([*self.names, "rmse_length_m", "final_length_m", "status"])
            for row, r, fl, why in zip(self.values, self.rmse, self.final_length, self.reasons):
                w.writerow([*(repr(float(v)) for v in row), repr(float(r)), repr(float(fl)), why])


def make_members(
    base: gp.Parameters,
    names: Sequence[str],
    inputs: Inputs,
    config: Config,
    measured: Measured | None = None,
    window: tuple[float, float] | None = None,
    breaks: Breaks | None = None,
) -> Callable[[Float[Array, "B d"]], tuple[Float[Array, " B"], Float[Array, " B"], Int[Array, " B"]]]:
    """The pure function that simulates and scores a batch of parameter sets together.

    Args:
        base: the parameters the sets replace fields of.
        names: the d qualified names of the fields each set replaces.
        inputs: the inputs of every run.
        config: the configuration of every run.
        measured: (sample times s, length m) to score against; None: no RMSE (NaN).
        window: (start, end) s of the RMSE; default the simulated window.
        breaks: `growjax.simulation.simulate.input_breaks` of the inputs, where known.

    Returns:
        Θ (B, d) → (length RMSE (B,) m, final length (B,) m, status (B,)), through
        `growjax.simulation.simulate.simulate_members`.
    """
    names = tuple(names)
    t_start, t_end = window if window is not None else (config.t0, config.t1)
    breaks = input_breaks(inputs, config) if breaks is None else breaks
    if measured is None:
        ts = None
    else:  # saved at the samples (and at t1, for the final length), not interpolated between them
        times = jnp.asarray(measured[0], float)
        ts = jnp.concatenate([sample_times(times, config), jnp.full((1,), config.t1, times.dtype)])

    def score(length):
        finite = jnp.isfinite(length)
        final = length[jnp.maximum(jnp.sum(finite) - 1, 0)]
        rmse = jnp.nan if measured is None else rmse_at_samples(length[:-1], times, measured[1], t_start, t_end)
        return rmse, final

    def members(thetas):
        params = jax.vmap(lambda theta: gp.replace(base, **{n: theta[i] for i, n in enumerate(names)}))(thetas)
        traj = simulate_members(params, inputs, config, ts=ts, breaks=breaks)
        rmse, final = jax.vmap(score)(traj.length)
        return rmse, final, traj.status

    return members


def _mesh(devices=None) -> Mesh:
    return Mesh(np.asarray(devices if devices is not None else jax.devices()), ("batch",))


@dataclasses.dataclass
class Plan:
    """A sweep ready to run (`make_plan`).

    Attributes:
        names: the d qualified parameter names.
        values: (n, d) the rows, SI.
        valid: (n,) bool, the rows with admissible parameters (the others are not simulated).
        padded: (n_chunks · chunk, d) the rows run, invalid ones replaced by the base point, the last chunk padded.
        chunk: rows per chunk, a multiple of the device count.
        n_chunks: the number of chunks.
        mesh: the devices' mesh.
        compiled: the compiled program over one chunk.
        dynamic: the program's array arguments (the model's numbers), replicated.
        quick: whether the program was compiled with XLA's quicker emitters.
        compile_s: time spent compiling, s.
        lower_s: the part of it spent tracing and lowering, s.
    """

    names: tuple[str, ...]
    values: Float[np.ndarray, "n d"]
    valid: np.ndarray
    padded: np.ndarray
    chunk: int
    n_chunks: int
    mesh: Mesh
    compiled: Any
    dynamic: Any
    quick: bool
    compile_s: float
    lower_s: float

    def rows(self, c: int) -> slice:
        """The rows of chunk ``c``."""
        return slice(c * self.chunk, min((c + 1) * self.chunk, self.values.shape[0]))


def _chunk_rows(config: Config, n: int, n_dev: int, chunk_size: int | None, memory_budget_bytes: float) -> int:
    """Rows per chunk: ``chunk_size`` (default as many as the memory budget allows), at most n, rounded up to a
    multiple of the device count."""
    if chunk_size is None:
        n_save = round((config.t1 - config.t0) / 0.01) + 1
        per_member = 8 * n_save * 16 * 4  # outputs, states and solver temporaries, with margin
        chunk_size = max(1, int(memory_budget_bytes // per_member))
    chunk = min(chunk_size, n)
    return n_dev * max(1, -(-chunk // n_dev))


def make_plan(
    values: Float[ArrayLike, "n d"],
    names: Sequence[str],
    base: gp.Parameters,
    inputs: Inputs,
    config: Config,
    measured: Measured | None,
    window: tuple[float, float] | None,
    chunk_size: int | None,
    devices: Sequence[jax.Device] | None,
    memory_budget_bytes: float,
) -> Plan:
    """Check the rows, size and pad the chunks, and compile the program (the first half of `evaluate`).

    Args:
        values, names, base, inputs, config, measured, window, chunk_size, devices, memory_budget_bytes: as
            `evaluate`.

    Returns:
        The plan.

    Raises:
        ValueError: where ``values`` does not have one column per name.
    """
    values = np.atleast_2d(np.asarray(values, float))
    names = tuple(gp.resolve_name(base, n) for n in names)
    if values.shape[1] != len(names):
        raise ValueError(f"values have {values.shape[1]} columns for {len(names)} names")
    n = values.shape[0]
    mesh = _mesh(devices)
    valid = gp.admissible_rows(base, names, values)
    fill = np.array([float(gp.get(base, q)) for q in names])
    safe = np.where(valid[:, None], values, fill)
    chunk = _chunk_rows(config, n, mesh.devices.size, chunk_size, memory_budget_bytes)
    n_chunks = -(-n // chunk)
    padded = np.concatenate([safe, np.repeat(safe[-1:], n_chunks * chunk - n, axis=0)])

    start = time.perf_counter()
    # The model's numbers (base, inputs, data) are arguments of the program, not constants in it: one
    # compiled program serves every data set and base point of the same shapes.
    breaks = input_breaks(inputs, config)
    dynamic, static = eqx.partition((as_arrays(base), as_arrays(inputs), breaks, measured), eqx.is_array)
    # XLA's quicker emitters where the compile they save exceeds the slower run they give (QUICK_COMPILE_ROWS)
    quick = config.quick_compile
    if quick is None:
        quick = n <= QUICK_COMPILE_ROWS or xla_flags.quick_compile_applied()
    compiled, lower_s = _compiled(names, config.replace(quick_compile=quick), chunk, window, mesh, dynamic, static)
    dynamic = jax.device_put(dynamic, NamedSharding(mesh, PartitionSpec()))
    return Plan(
        names,
        values,
        valid,
        padded,
        chunk,
        n_chunks,
        mesh,
        compiled,
        dynamic,
        bool(quick),
        time.perf_counter() - start,
        lower_s,
    )


def run_chunk(plan: Plan, c: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run one chunk of a plan.

    Args:
        plan: the plan.
        c: the chunk's index.

    Returns:
        (length RMSE m, final length m, status) of the chunk's rows, failed and invalid members flagged.
    """
    sharding = NamedSharding(plan.mesh, PartitionSpec("batch"))
    block = put(plan.padded[c * plan.chunk : (c + 1) * plan.chunk], sharding)
    rmse, final, status = gather(plan.compiled(block, plan.dynamic))
    rows = plan.rows(c)
    valid = plan.valid[rows]
    k = valid.size
    status = np.where(valid, np.asarray(status[:k], int), INVALID_PARAMETER)
    rmse = np.where(status == OK, np.asarray(rmse[:k], float), np.nan)
    final = np.where(valid, np.asarray(final[:k], float), np.nan)
    return rmse, final, status


def evaluate(
    values: Float[ArrayLike, "n d"],
    names: Sequence[str],
    base: gp.Parameters,
    inputs: Inputs,
    config: Config = FAST,
    *,
    measured: Measured | None = None,
    window: tuple[float, float] | None = None,
    chunk_size: int | None = None,
    devices: Sequence[jax.Device] | None = None,
    memory_budget_bytes: float = 2**30,
    progress: bool = False,
    on_chunk: ChunkCallback | None = None,
) -> SweepResult:
    """Simulate and score every row of ``values`` in one compiled, sharded, chunked call.

    Rows with invalid parameters are flagged, not simulated. The last chunk is padded, so one shape compiles once.

    Args:
        values: (n, d) parameter values, SI.
        names: the d parameter names (as `growjax.replace` accepts them).
        base: the parameters the rows replace fields of.
        inputs: the inputs of every run.
        config: the configuration of every run.
        measured: (sample times s, length m): scores the length RMSE over ``window``; None: no RMSE.
        window: (start, end) s of the RMSE; default the simulated window.
        chunk_size: rows per chunk (default as many as ``memory_budget_bytes`` allows), rounded up to a multiple
            of the device count.
        devices: the devices to split each chunk over; default all that JAX sees.
        memory_budget_bytes: the memory a chunk may take, bytes.
        progress: a bar per chunk on a terminal, a line every ~10 % on another stream (stderr).
        on_chunk: called as ``on_chunk(done, total)`` (chunks) after each chunk.

    Returns:
        The result, rows in the order of ``values``.

    Raises:
        ValueError: where ``values`` does not have one column per name, or a name is unknown.
    """
    plan = make_plan(values, names, base, inputs, config, measured, window, chunk_size, devices, memory_budget_bytes)
    outs = []
    start = time.perf_counter()
    with prog.bar(plan.n_chunks, "sweep", "chunk", progress and plan.n_chunks > 1 and leader()) as shown:
        for c in range(plan.n_chunks):
            outs.append(run_chunk(plan, c))
            shown.update(1)
            if on_chunk is not None:
                on_chunk(c + 1, plan.n_chunks)
    wall_s = time.perf_counter() - start
    rmse, final, status = (np.concatenate([o[k] for o in outs]) for k in range(3))
    return SweepResult(
        plan.names, plan.values, rmse, final, status, wall_s, plan.compile_s, plan.mesh.devices.size, plan.lower_s
    )


def _compiled(names, config: Config, chunk: int, window, mesh: Mesh, dynamic, static):
    """(the compiled sweep program over chunks of ``chunk`` rows, seconds spent tracing and lowering it; 0 where
    ``_COMPILED`` has it), compiled with ``config.quick_compile``'s emitters."""
    shapes = jax.tree_util.tree_map(lambda a: (a.shape, str(a.dtype)), dynamic)
    with xla_flags.compiling(config.quick_compile):
        key = (
            names,
            config.resolved(),
            chunk,
            None if window is None else tuple(window),
            tuple(d.id for d in mesh.devices.flat),
            str(jax.tree_util.tree_structure(dynamic)),
            str(jax.tree_util.tree_leaves(shapes)),
            content_key(static),
        )
        if key in _COMPILED:
            return _COMPILED[key], 0.0
        start = time.perf_counter()
        lowered = _lowered(names, config, chunk, window, mesh, dynamic, static)
        lower_s = time.perf_counter() - start
    compiled = xla_flags.compile_quickly(lowered, config.quick_compile)
    if len(_COMPILED) >= 8:
        _COMPILED.pop(next(iter(_COMPILED)))
    _COMPILED[key] = compiled
    return compiled, lower_s


def _lowered(names, config: Config, chunk: int, window, mesh: Mesh, dynamic, static):
    """The sweep program over chunks of ``chunk`` rows, traced and lowered."""

    def members(thetas, dynamic):
        p, i, b, m = eqx.combine(dynamic, static)
        return make_members(p, names, i, config, m, window, breaks=b)(thetas)

    sharding, replicated = NamedSharding(mesh, PartitionSpec("batch")), NamedSharding(mesh, PartitionSpec())
    # Each device steps its own members in its own loop (shard_map): a vmapped loop over the whole
    # sharded batch would wait, at every attempt, for a cross-device "is any member still running?".
    # check_vma=False: the solver's loop carries replicated constants beside per-device members.
    local = jax.shard_map(
        members,
        mesh=mesh,
        in_specs=(PartitionSpec("batch"), PartitionSpec()),
        out_specs=PartitionSpec("batch"),
        check_vma=False,
    )
    batched = jax.jit(local, in_shardings=(sharding, replicated), out_shardings=sharding)
    return batched.lower(jax.ShapeDtypeStruct((chunk, len(names)), jnp.float64, sharding=sharding), dynamic)
