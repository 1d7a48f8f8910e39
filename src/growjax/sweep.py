"""Batched parameter sweeps: Latin hypercubes and Sobol designs through one compiled, sharded call.

A sweep is a box of parameters (:class:`Dimension`), a design of points in it, and one
``jit(vmap(...))`` of the model that scores every point against a measured length
(RMSE over a window) and reports the final length and the run status. Points are
evaluated in equal chunks (one compiled shape, memory bounded), each chunk split across
all devices JAX sees (``jax.sharding``), also across the processes and hosts of a
``jax.distributed.initialize`` run (each runs the same sweep and gets the full result). A member
that fails (solver failure, pressure limit, invalid parameter) is flagged with its reason; the
others are unaffected.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from growjax import params as gp
from growjax import xla_flags
from growjax._pytree_hash import content_key
from growjax.config import Config
from growjax.metrics import rmse_at_samples
from growjax.simulate import as_arrays, input_breaks, sample_times, simulate_members
from growjax.trajectory import OK, PRESSURE_LIMIT, SOLVER_FAILED

INVALID_PARAMETER = 3
FAST = Config()  # default configuration of sweeps
REASONS = {OK: "ok", PRESSURE_LIMIT: "pressure_limit", SOLVER_FAILED: "solver_failed", INVALID_PARAMETER: "invalid_parameter"}


@dataclasses.dataclass(frozen=True)
class Dimension:
    """One swept parameter: qualified ``name`` (``block.field``), bounds in SI units, linear or log scale."""

    name: str
    low: float
    high: float
    log: bool = False

    def __post_init__(self):
        if not (math.isfinite(self.low) and math.isfinite(self.high)) or not self.high > self.low:
            raise ValueError(f"{self.name}: need finite LOW < HIGH, got {self.low}:{self.high}")
        if self.log and self.low <= 0:
            raise ValueError(f"{self.name}: a log scale needs LOW > 0, got {self.low}")

    def from_unit(self, u):
        """Map u ∈ [0, 1] to the parameter value."""
        u = np.asarray(u, float)
        if self.log:
            return np.exp(np.log(self.low) + u * (np.log(self.high) - np.log(self.low)))
        return self.low + u * (self.high - self.low)


def paper_box() -> tuple[Dimension, ...]:
    """The published investigation: n 0.9–1.1, Y 5–15 kPa, ext 4000–10000."""
    return (
        Dimension("robot.growth_exponent", 0.9, 1.1),
        Dimension("robot.yield_pressure", 5e3, 15e3),
        Dimension("robot.extensibility", 4000.0, 10000.0),
    )


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


def latin_hypercube(dims: Sequence[Dimension], n: int, seed: int) -> np.ndarray:
    """(n, d) Latin-hypercube design in parameter units (``scipy.stats.qmc.LatinHypercube``, seeded)."""
    from scipy.stats import qmc

    if n < 1:
        raise ValueError(f"a sweep needs n ≥ 1 points, got {n}")
    unit = qmc.LatinHypercube(d=len(dims), seed=np.random.default_rng(seed)).random(n)
    return np.column_stack([d.from_unit(unit[:, i]) for i, d in enumerate(dims)])


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
        return {"index": i, "parameters": dict(zip(self.names, map(float, self.values[i]))),
                "rmse_length_m": float(self.rmse[i]), "final_length_m": float(self.final_length[i])}

    def write_csv(self, path) -> None:
        """One row per point: parameters, rmse_length_m, final_length_m, status."""
        import csv

        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow([*self.names, "rmse_length_m", "final_length_m", "status"])
            for row, r, fl, why in zip(self.values, self.rmse, self.final_length, self.reasons):
                w.writerow([*(repr(float(v)) for v in row), repr(float(r)), repr(float(fl)), why])


def _valid_rows(names, values, base: gp.Parameters) -> np.ndarray:
    """Rows whose parameter values are finite and inside their physical ranges (:func:`growjax.params.admissible_rows`)."""
    return gp.admissible_rows(base, names, values)


def make_members(base: gp.Parameters, names: Sequence[str], inputs, config, measured=None, window=None, breaks=None):
    """Function Θ (B, d) → (rmse (B,) m, final length (B,) m, status (B,)) of a batch of parameter sets, simulated
    together (:func:`growjax.simulate.simulate_members`); pure."""
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

    One function: chunking, placing the chunks on the devices and flagging failed members act on the same
    arrays in one pass.
    """
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

    sharding = NamedSharding(mesh, PartitionSpec("batch"))
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
    compile_s = time.perf_counter() - start

    outs = []
    start = time.perf_counter()
    chunks = range(n_chunks)
    if progress and n_chunks > 1:
        from tqdm import tqdm

        chunks = tqdm(chunks, desc="sweep", unit="chunk", total=n_chunks)
    for c in chunks:
        block = _put(padded[c * chunk:(c + 1) * chunk], sharding)
        outs.append(_get(compiled(block, dynamic)))
    wall_s = time.perf_counter() - start

    rmse, final, status = (np.concatenate([o[k] for o in outs])[:n] for k in range(3))
    status = np.where(valid, np.asarray(status, int), INVALID_PARAMETER)
    rmse = np.where(status == OK, rmse, np.nan)
    final = np.where(valid, final, np.nan)
    return SweepResult(names, values, np.asarray(rmse, float), np.asarray(final, float), status, wall_s, compile_s,
                       n_dev, lower_s)


def _compiled(names, config: Config, chunk: int, window, mesh: Mesh, dynamic, static):
    """(the compiled sweep program over chunks of ``chunk`` rows, seconds spent tracing and lowering it; 0 where
    :data:`_COMPILED` has it), compiled with ``config.quick_compile``'s emitters."""
    shapes = jax.tree_util.tree_map(lambda a: (a.shape, str(a.dtype)), dynamic)
    with xla_flags.compiling(config.quick_compile):
        key = (names, config.resolved(), chunk, None if window is None else tuple(window),
               tuple(d.id for d in mesh.devices.flat), str(jax.tree_util.tree_structure(dynamic)),
               str(jax.tree_util.tree_leaves(shapes)), content_key(static))
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
        local = jax.shard_map(members, mesh=mesh,
                              in_specs=(PartitionSpec("batch"), PartitionSpec()), out_specs=PartitionSpec("batch"),
                              check_vma=False)
        batched = jax.jit(local, in_shardings=(sharding, replicated), out_shardings=sharding)
        lowered = batched.lower(jax.ShapeDtypeStruct((chunk, len(names)), jnp.float64, sharding=sharding), dynamic)
        lower_s = time.perf_counter() - start
    compiled = xla_flags.compile_quickly(lowered, config.quick_compile)
    if len(_COMPILED) >= 8:
        _COMPILED.pop(next(iter(_COMPILED)))
    _COMPILED[key] = compiled
    return compiled, lower_s


def lhs_sweep(
    n: int,
    base: gp.Parameters,
    inputs,
    config: Config = FAST,
    dims: Sequence[Dimension] | None = None,
    seed: int = 0,
    **kwargs,
) -> SweepResult:
    """Latin-hypercube sweep of ``n`` points over ``dims`` (default: the paper's box); kwargs as :func:`evaluate`."""
    dims = tuple(dims) if dims is not None else paper_box()
    values = latin_hypercube(dims, n, seed)
    return evaluate(values, [d.name for d in dims], base, inputs, config, **kwargs)


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
