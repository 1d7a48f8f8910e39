"""Batched parameter sweeps: Latin hypercubes and Sobol designs through one compiled, sharded call.

A sweep is a box of parameters (:class:`Dimension`), a design of points in it, and one
``jit(vmap(...))`` of the model that scores every point against a measured length
(RMSE over a window) and reports the final length and the run status. Points are
evaluated in equal chunks (one compiled shape, memory bounded), each chunk split across
all devices JAX sees (``jax.sharding``), also across the processes and hosts of a
``jax.distributed.initialize`` run (each process evaluates the rows on its own devices and gets the full
result). A member that fails (solver failure, pressure limit, invalid parameter) is flagged with its reason;
the others are unaffected.

Sweeps that survive a stop: ``lhs_sweep(..., store=DIR)`` writes each chunk to DIR as it finishes, and
:func:`resume` completes an interrupted one with the same result, bit for bit, as an uninterrupted run
(:func:`load` reads a store as far as it has run). The store is a Zarr v3 group (:mod:`growjax.sweep.store`):
a folder with one file per chunk of each array, each written to a temporary file and renamed into place, so a
stop or a crash loses at most the chunk in flight and never leaves a half-written file; its JSON attributes
hold the definition. Zarr rather than one netCDF/HDF5 file, which a write cut short can leave unreadable
whole, or hand-written ``.npz`` files and a manifest: a standard chunked format that xarray, zarr and other
languages read as it is (``xarray.open_zarr(DIR)``), with that bookkeeping already done.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from growjax import progress as prog
from growjax.hashing import content_key
from growjax.model import params as gp
from growjax.model.params import Dimension, latin_hypercube, paper_box
from growjax.simulation import xla_flags
from growjax.simulation.config import Config
from growjax.simulation.metrics import rmse_at_samples
from growjax.simulation.simulate import as_arrays, input_breaks, sample_times, simulate_members
from growjax.simulation.trajectory import OK, PRESSURE_LIMIT, SOLVER_FAILED
from growjax.sweep import stopping as _stopping
from growjax.sweep import store as _store

INVALID_PARAMETER = 3
FAST = Config()  # default configuration of sweeps
NOT_RUN = _store.NOT_RUN  # status of a stored sweep's rows not yet run (:func:`load`)
REASONS = {
    NOT_RUN: "not_run",
    OK: "ok",
    PRESSURE_LIMIT: "pressure_limit",
    SOLVER_FAILED: "solver_failed",
    INVALID_PARAMETER: "invalid_parameter",
}
StoreError = _store.StoreError  # a missing or corrupt store, or one of another sweep (a ValueError)


def parse_dimension(text: str, params: gp.Parameters) -> Dimension:
    """``NAME=LOW:HIGH[:log]`` → :class:`Dimension` (NAME as accepted by :func:`growjax.replace`)."""
    if "=" not in text:
        raise ValueError(f"--param expects NAME=LOW:HIGH[:log], got {text!r}")
    name, rng = text.split("=", 1)
    parts = rng.split(":")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] not in ("log", "lin")):
        raise ValueError(f"--param {name}: range must be LOW:HIGH or LOW:HIGH:log, got {rng!r}")
    try:
        low, high = float(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(f"--param {name}: bounds {rng!r} are not numbers") from None
    return Dimension(gp.resolve_name(params, name.strip()), low, high, len(parts) == 3 and parts[2] == "log")


@dataclasses.dataclass
class SweepResult:
    """Every point of a sweep and its score.

    Attributes:
        names: qualified parameter names, (d,).  values: (n, d) parameter values, SI.
        rmse: (n,) length RMSE, m (NaN where no data or failed).  final_length: (n,) m.
        status: (n,) codes, see :data:`REASONS`.  wall_s: evaluation time after compilation, s.
        compile_s: compilation time, s (tracing and lowering included).
        lower_s: the part of ``compile_s`` spent tracing and lowering the program to StableHLO, s; the rest is
            XLA's (0 where this process had compiled it).
        n_devices: devices the sweep was split over.
    """

    names: tuple
    values: np.ndarray
    rmse: np.ndarray
    final_length: np.ndarray
    status: np.ndarray
    wall_s: float = float("nan")
    compile_s: float = float("nan")
    n_devices: int = 1
    lower_s: float = float("nan")

    @property
    def reasons(self) -> list[str]:
        return [REASONS.get(int(s), f"unknown({int(s)})") for s in self.status]

    @property
    def failed(self) -> np.ndarray:
        return self.status != OK

    @property
    def best_index(self) -> int | None:
        """Index of the lowest finite RMSE among successful members (None if there is none)."""
        ok = ~self.failed & np.isfinite(self.rmse)
        if not np.any(ok):
            return None
        return int(np.flatnonzero(ok)[np.argmin(self.rmse[ok])])

    def best(self) -> dict | None:
        i = self.best_index
        if i is None:
            return None
        return {
            "index": i,
            "parameters": dict(zip(self.names, map(float, self.values[i]))),
            "rmse_length_m": float(self.rmse[i]),
            "final_length_m": float(self.final_length[i]),
        }

    def write_csv(self, path) -> None:
        """One row per point: parameters, rmse_length_m, final_length_m, status."""
        import csv

        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow([*self.names, "rmse_length_m", "final_length_m", "status"])
            for row, r, fl, why in zip(self.values, self.rmse, self.final_length, self.reasons):
                w.writerow([*(repr(float(v)) for v in row), repr(float(r)), repr(float(fl)), why])


def _valid_rows(names, values, base: gp.Parameters) -> np.ndarray:
    """Rows whose parameter values are finite and inside their physical ranges
    (`growjax.model.params.admissible_rows`)."""
    return gp.admissible_rows(base, names, values)


def make_members(base: gp.Parameters, names: Sequence[str], inputs, config, measured=None, window=None, breaks=None):
    """Function Θ (B, d) → (rmse (B,) m, final length (B,) m, status (B,)) of a batch of parameter sets, simulated
    together (:func:`growjax.simulation.simulate.simulate_members`); pure."""
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


# Designs up to this many rows compile with XLA's quicker emitters (xla_flags.QUICK_COMPILE) where
# Config.quick_compile is None. On a 2-core CPU, 500 sets of 10 s compile ~1.5 s sooner and sweep ~0.08 ms
# per set slower with them (``benchmarks/sweep.py`` measures both), so they pay up to ~17 000 sets.
QUICK_COMPILE_ROWS = 15_000

# Compiled sweep programs of this process, keyed by everything they close over (at most 8 kept).
_COMPILED: dict = {}


def _mesh(devices=None) -> Mesh:
    return Mesh(np.asarray(devices if devices is not None else jax.devices()), ("batch",))


def _put(block: np.ndarray, sharding: NamedSharding) -> jax.Array:
    """Host rows → one array sharded over the mesh. Under ``jax.distributed`` (several processes,
    every one holding the same ``block``) each process fills only the shards on its own devices."""
    if jax.process_count() == 1:
        return jax.device_put(block, sharding)
    return jax.make_array_from_callback(block.shape, sharding, lambda index: block[index])


def _get(outputs):
    """Sharded outputs → host arrays; under ``jax.distributed`` gathered from all processes, so each has them all."""
    if jax.process_count() == 1:
        return jax.device_get(outputs)
    from jax.experimental import multihost_utils

    return multihost_utils.process_allgather(outputs, tiled=True)


@dataclasses.dataclass
class _Plan:
    """A sweep ready to run: its rows, chunks and compiled program (:func:`_plan`)."""

    names: tuple
    values: np.ndarray
    valid: np.ndarray
    padded: np.ndarray
    chunk: int
    n_chunks: int
    mesh: Mesh
    compiled: object
    dynamic: object
    quick: bool
    compile_s: float
    lower_s: float

    def rows(self, c: int) -> slice:
        return slice(c * self.chunk, min((c + 1) * self.chunk, self.values.shape[0]))


def _plan(values, names, base, inputs, config, measured, window, chunk_size, devices, memory_budget_bytes) -> _Plan:
    """Check the rows, size and pad the chunks, compile the program (:func:`evaluate`'s first half)."""
    values = np.atleast_2d(np.asarray(values, float))
    names = tuple(gp.resolve_name(base, n) for n in names)
    if values.shape[1] != len(names):
        raise ValueError(f"values have {values.shape[1]} columns for {len(names)} names")
    n = values.shape[0]
    mesh = _mesh(devices)
    n_dev = mesh.devices.size
    valid = _valid_rows(names, values, base)
    fill = np.array([float(gp.get(base, q)) for q in names])
    safe = np.where(valid[:, None], values, fill)

    if chunk_size is None:
        n_save = round((config.t1 - config.t0) / 0.01) + 1
        per_member = 8 * n_save * 16 * 4  # outputs, states and solver temporaries, with margin
        chunk_size = max(1, int(memory_budget_bytes // per_member))
    chunk = min(chunk_size, n)
    chunk = n_dev * max(1, -(-chunk // n_dev))
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
    return _Plan(
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


def _run_chunk(plan: _Plan, c: int):
    """(rmse m, final length m, status) of the rows of chunk ``c``, failed and invalid members flagged."""
    sharding = NamedSharding(plan.mesh, PartitionSpec("batch"))
    block = _put(plan.padded[c * plan.chunk : (c + 1) * plan.chunk], sharding)
    rmse, final, status = _get(plan.compiled(block, plan.dynamic))
    rows = plan.rows(c)
    valid = plan.valid[rows]
    k = valid.size
    status = np.where(valid, np.asarray(status[:k], int), INVALID_PARAMETER)
    rmse = np.where(status == OK, np.asarray(rmse[:k], float), np.nan)
    final = np.where(valid, np.asarray(final[:k], float), np.nan)
    return rmse, final, status


def evaluate(
    values,
    names: Sequence[str],
    base: gp.Parameters,
    inputs,
    config: Config = FAST,
    measured=None,
    window=None,
    chunk_size: int | None = None,
    devices=None,
    memory_budget_bytes: float = 2**30,
    progress: bool = False,
) -> SweepResult:
    """Simulate and score every row of ``values`` (n, d) in one compiled, sharded, chunked call.

    ``measured`` = (times s, length m) scores the length RMSE over ``window`` (s, default the
    simulated window). Rows with invalid parameters are flagged, not simulated. Chunks
    hold ``chunk_size`` rows (default: as many as ``memory_budget_bytes`` allows), rounded
    to a multiple of the device count; the last chunk is padded, so one shape compiles once.
    ``progress``: a bar per chunk on a terminal, a line every ~10 % on another stream (stderr).
    """
    plan = _plan(values, names, base, inputs, config, measured, window, chunk_size, devices, memory_budget_bytes)
    outs = []
    start = time.perf_counter()
    with prog.bar(plan.n_chunks, "sweep", "chunk", progress and plan.n_chunks > 1 and _leader()) as shown:
        for c in range(plan.n_chunks):
            outs.append(_run_chunk(plan, c))
            shown.update(1)
    wall_s = time.perf_counter() - start
    rmse, final, status = (np.concatenate([o[k] for o in outs]) for k in range(3))
    return SweepResult(
        plan.names, plan.values, rmse, final, status, wall_s, plan.compile_s, plan.mesh.devices.size, plan.lower_s
    )


def _compiled(names, config: Config, chunk: int, window, mesh: Mesh, dynamic, static):
    """(the compiled sweep program over chunks of ``chunk`` rows, seconds spent tracing and lowering it; 0 where
    :data:`_COMPILED` has it), compiled with ``config.quick_compile``'s emitters."""
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
        lowered = batched.lower(jax.ShapeDtypeStruct((chunk, len(names)), jnp.float64, sharding=sharding), dynamic)
        lower_s = time.perf_counter() - start
    compiled = xla_flags.compile_quickly(lowered, config.quick_compile)
    if len(_COMPILED) >= 8:
        _COMPILED.pop(next(iter(_COMPILED)))
    _COMPILED[key] = compiled
    return compiled, lower_s


class SweepInterrupted(Exception):
    """A stored sweep stopped before its end (SIGINT, SIGTERM or ``max_chunks``); the chunks done are in its store.

    Attributes: ``store`` (path), ``done`` and ``total`` (chunks), ``signal`` (the signal's number, or None).
    """

    def __init__(self, store, done: int, total: int, signal: int | None = None):
        self.store, self.done, self.total, self.signal = str(store), done, total, signal
        super().__init__(
            f"sweep stopped with {done} of {total} chunks done, kept in {store}; "
            f"growjax.sweep.resume({str(store)!r}, ...) completes it"
        )


def lhs_sweep(
    n: int,
    base: gp.Parameters,
    inputs,
    config: Config = FAST,
    dims: Sequence[Dimension] | None = None,
    seed: int = 0,
    store=None,
    max_chunks: int | None = None,
    metadata: dict | None = None,
    **kwargs,
) -> SweepResult:
    """Latin-hypercube sweep of ``n`` points over ``dims`` (default: the paper's box); kwargs as :func:`evaluate`.

    ``store``: a new folder (a Zarr v3 group) that receives each chunk as it finishes, with the sweep's
    definition; SIGINT or SIGTERM then stop the sweep after the chunk in flight (a second signal: at once,
    dropping that chunk) and raise :class:`SweepInterrupted`, as does reaching ``max_chunks`` chunks in this
    call. :func:`resume` completes the store; its result equals, bit for bit, that of an uninterrupted sweep
    on the same device count. ``metadata``: JSON-ready notes kept in the store's definition.
    """
    dims = tuple(dims) if dims is not None else paper_box()
    taken = store is not None and Path(store).exists() and (not Path(store).is_dir() or any(Path(store).iterdir()))
    if taken and _leader():  # (under jax.distributed the first process makes it: the others may see it made)
        raise _store.StoreError(f"{store} already exists; a new sweep needs a new folder (or resume the one there)")
    values = latin_hypercube(dims, n, seed)
    names = [d.name for d in dims]
    if store is None:
        if max_chunks is not None:
            raise ValueError("max_chunks stops a sweep that keeps its chunks: give a store")
        return evaluate(values, names, base, inputs, config, **kwargs)
    definition = {
        "design": "latin_hypercube",
        "n": int(n),
        "seed": int(seed),
        "dims": [dataclasses.asdict(d) for d in dims],
        "config": _store.config_record(config),
        "metadata": metadata or {},
    }
    return _stored(store, None, definition, values, base, inputs, config, max_chunks=max_chunks, **kwargs)


def resume(
    store,
    base: gp.Parameters,
    inputs,
    measured=None,
    window=None,
    *,
    progress: bool = False,
    max_chunks: int | None = None,
    devices=None,
) -> SweepResult:
    """Complete the sweep kept in ``store`` (:func:`lhs_sweep`'s ``store``) and return its whole result.

    ``base``, ``inputs``, ``measured`` and ``window`` must be those the sweep was started with (their
    fingerprints are in the store); the design, ranges, seed, configuration and chunk rows are the store's.
    Raises :class:`growjax.sweep.store.StoreError` (a ``ValueError``) for a missing or corrupt store or one
    written for other inputs, before anything is written; :class:`SweepInterrupted` as :func:`lhs_sweep`.
    """
    group, definition = _store.open_store(store, mode="r+" if _leader() else "r")
    try:
        dims = tuple(Dimension(**d) for d in definition["dims"])
        config = Config(**definition["config"])
        n, seed = int(definition["n"]), int(definition["seed"])
    except (KeyError, TypeError, ValueError) as err:
        raise _store.StoreError(f"{store}: corrupt sweep definition ({err})") from None
    values = _store.read(group, "values")
    if definition.get("design") != "latin_hypercube" or not np.array_equal(values, latin_hypercube(dims, n, seed)):
        raise _store.StoreError(
            f"{store}: its design is not the Latin hypercube of its ranges and seed "
            "(written by another SciPy, or altered)"
        )
    return _stored(
        store,
        group,
        definition,
        values,
        base,
        inputs,
        config,
        measured=measured,
        window=window,
        progress=progress,
        max_chunks=max_chunks,
        devices=devices,
    )


def load(store) -> SweepResult:
    """The sweep kept in ``store`` as far as it has run: rows not yet run have status ``NOT_RUN`` (``"not_run"``)
    and NaN scores."""
    group, definition = _store.open_store(store)
    names = tuple(definition["names"])
    arrays = {k: _store.read(group, k) for k in _store.ARRAYS}
    return SweepResult(
        names,
        arrays["values"],
        arrays["rmse"],
        arrays["final_length"],
        arrays["status"].astype(int),
        n_devices=int(definition.get("n_devices", 1)),
    )


def _identity(base, inputs, measured, window) -> dict:
    return {
        "base": _store.fingerprint(as_arrays(base)),
        "inputs": _store.fingerprint(as_arrays(inputs)),
        "measured": _store.fingerprint(measured),
        "window": None if window is None else [float(w) for w in window],
    }


def _stored(
    path,
    group,
    definition: dict,
    values,
    base,
    inputs,
    config,
    *,
    measured=None,
    window=None,
    chunk_size=None,
    devices=None,
    memory_budget_bytes: float = 2**30,
    progress: bool = False,
    max_chunks: int | None = None,
) -> SweepResult:
    """Run the chunks of ``values`` not yet in the store at ``path`` (a new one where ``group`` is None), writing
    each as it finishes (the first process only, under ``jax.distributed``); the whole result read back."""
    names = [d["name"] for d in definition["dims"]]
    identity = _identity(base, inputs, measured, window)
    if group is not None:
        wrong = _store.differences(definition.get("identity", {}), identity)
        if wrong:
            what = {"base": "base parameters", "inputs": "inputs", "measured": "measured data", "window": "window"}
            raise _store.StoreError(f"{path} holds a sweep of other {', '.join(what[k] for k in wrong)} than these")
        chunk_size = int(definition["chunk"])
        config = config.replace(quick_compile=definition.get("quick_compile"))
    # A signal from here on stops the sweep between chunks (one during compilation: before the first).
    with _stopping.Stopper(announce=_leader()) as stop:
        prog.note(f"sweep: {values.shape[0]} sets, kept in {path} as they finish; compiling", progress and _leader())
        plan = _plan(values, names, base, inputs, config, measured, window, chunk_size, devices, memory_budget_bytes)
        if group is None:
            definition = {
                **definition,
                "names": list(plan.names),
                "chunk": plan.chunk,
                "quick_compile": plan.quick,
                "n_devices": int(plan.mesh.devices.size),
                "identity": identity,
                "growjax": _version(),
            }
            if _leader():
                with stop.writing():
                    group = _store.create(path, definition, plan.values, plan.chunk)
            done = np.zeros(plan.n_chunks, bool)
        else:
            if plan.chunk != int(definition["chunk"]):
                raise _store.StoreError(
                    f"{path} holds chunks of {definition['chunk']} rows, which "
                    f"{plan.mesh.devices.size} devices cannot split evenly; resume on a device "
                    "count that divides it"
                )
            done = _store.done_chunks(_store.read(group, "status"), plan.chunk)
        done = _from_leader(done)
        todo = [c for c in range(plan.n_chunks) if not done[c]]
        start, ran, stopped = time.perf_counter(), 0, None
        with prog.bar(len(todo), "sweep", "chunk", progress and len(todo) > 1 and _leader()) as shown:
            for c in todo:
                signalled = _signal_anywhere(stop.signal)
                if signalled or (max_chunks is not None and ran >= max_chunks):
                    stopped = signalled
                    break
                out = _run_chunk(plan, c)
                if _leader():
                    with stop.writing():
                        _store.write_chunk(group, c, plan.chunk, *out)
                ran += 1
                shown.update(1)
    wall_s = time.perf_counter() - start
    if stopped is not None:
        raise SweepInterrupted(path, plan.n_chunks - len(todo) + ran, plan.n_chunks, stopped or None)
    n = plan.values.shape[0]
    if _leader():
        rmse, final, status = (_store.read(group, k) for k in ("rmse", "final_length", "status"))
    else:  # the store is the first process's: its rows are sent to the others
        rmse, final, status = np.zeros(n), np.zeros(n), np.zeros(n, np.int32)
    rmse, final, status = _from_leader((rmse, final, status))
    return SweepResult(
        plan.names,
        plan.values,
        np.asarray(rmse, float),
        np.asarray(final, float),
        np.asarray(status).astype(int),
        wall_s,
        plan.compile_s,
        plan.mesh.devices.size,
        plan.lower_s,
    )


def _leader() -> bool:
    """Whether this is the process that writes (the first, under ``jax.distributed``; the only one otherwise)."""
    return jax.process_index() == 0


def _signal_anywhere(number: int | None) -> int:
    """The number of a stopping signal received by this or any process (0: none); every process must call it at
    the same point, so that all stop at the same chunk."""
    if jax.process_count() == 1:
        return int(number or 0)
    from jax.experimental import multihost_utils

    return int(np.max(multihost_utils.process_allgather(np.array([number or 0], np.int32))))


def _from_leader(tree):
    """The first process's ``tree`` of NumPy arrays, in every process (each passes arrays of the same shapes)."""
    if jax.process_count() == 1:
        return tree
    from jax.experimental import multihost_utils

    dtypes = jax.tree_util.tree_map(lambda a: np.asarray(a).dtype, tree)
    sent = jax.tree_util.tree_map(lambda a: np.asarray(a).astype(np.int32) if np.asarray(a).dtype == bool else a, tree)
    got = multihost_utils.broadcast_one_to_all(sent)
    return jax.tree_util.tree_map(lambda a, t: np.asarray(a).astype(t), got, dtypes)


def _version() -> str:
    from growjax import __version__

    return __version__


def sobol_indices(
    dims: Sequence[Dimension],
    base: gp.Parameters,
    inputs,
    config: Config = FAST,
    n_base: int = 256,
    seed: int = 0,
    n_bootstrap: int = 1000,
    **kwargs,
) -> dict:
    """First- and total-order Sobol indices of the RMSE and of the final length (SALib, Saltelli design).

    ``n_base`` (a power of 2) base points give n_base·(d + 2) model runs, evaluated as one
    sweep. Confidence half-widths are 95 % bootstrap intervals. Returns
    ``{output: {"S1", "S1_conf", "ST", "ST_conf"}}`` (lists ordered as ``dims``) plus the sweep.
    """
    from SALib.analyze import sobol as sobol_analyze
    from SALib.sample import sobol as sobol_sample

    dims = tuple(dims)
    problem = {"num_vars": len(dims), "names": [d.name for d in dims], "bounds": [[0.0, 1.0]] * len(dims)}
    unit = sobol_sample.sample(problem, n_base, calc_second_order=False, seed=seed)
    values = np.column_stack([d.from_unit(unit[:, i]) for i, d in enumerate(dims)])
    result = evaluate(values, [d.name for d in dims], base, inputs, config, **kwargs)
    outputs = {"final_length_m": result.final_length}
    if kwargs.get("measured") is not None:
        outputs["rmse_length_m"] = result.rmse
    indices = {}
    for key, y in outputs.items():
        if not np.all(np.isfinite(y)):
            indices[key] = {"error": f"{int(np.sum(~np.isfinite(y)))} failed members; indices not defined"}
            continue
        s = sobol_analyze.analyze(problem, y, calc_second_order=False, num_resamples=n_bootstrap, seed=seed)
        indices[key] = {k: [float(v) for v in s[k]] for k in ("S1", "S1_conf", "ST", "ST_conf")}
    return {"names": [d.name for d in dims], "indices": indices, "n_runs": int(values.shape[0]), "sweep": result}
