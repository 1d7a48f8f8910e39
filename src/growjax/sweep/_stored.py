"""Sweeps that survive a stop: each chunk written to a store as it finishes, and the sweep resumed from it.

``lhs_sweep(..., store=DIR)`` writes each chunk to DIR as it finishes, and `resume` completes an interrupted
sweep with the same result, bit for bit, as an uninterrupted run (`load` reads a store as far as it has run).
The store is a Zarr v3 group (`growjax.sweep.store`): a folder with one file per chunk of each array, each
written to a temporary file and renamed into place, so a stop or a crash loses at most the chunk in flight and
never leaves a half-written file; its JSON attributes hold the definition. Zarr is a standard chunked format that
xarray, zarr and other languages read as it is (``xarray.open_zarr(DIR)``), where one netCDF/HDF5 file can be
left unreadable whole by a write cut short.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np

import growjax.sweep.stopping as _stopping
import growjax.sweep.store as _store
from growjax import progress as prog
from growjax.model import params as gp
from growjax.model.signals import Inputs
from growjax.simulation.config import Config
from growjax.simulation.simulate import as_arrays
from growjax.sweep._box import Dimension, latin_hypercube, paper_box
from growjax.sweep._evaluate import FAST, ChunkCallback, Measured, Plan, SweepResult, evaluate, make_plan, run_chunk
from growjax.sweep._processes import broadcast, leader, signal_anywhere

__all__ = ["SweepInterrupted", "lhs_sweep", "load", "resume"]


class SweepInterrupted(Exception):
    """A stored sweep stopped before its end (SIGINT, SIGTERM or ``max_chunks``); the chunks done are in its store.

    Attributes:
        store: the store's path.
        done: the chunks done.
        total: the chunks in all.
        signal: the number of the signal that stopped it, or None.
    """

    def __init__(self, store: str | Path, done: int, total: int, signal: int | None = None):
        self.store, self.done, self.total, self.signal = str(store), done, total, signal
        super().__init__(
            f"sweep stopped with {done} of {total} chunks done, kept in {store}; "
            f"growjax.sweep.resume({str(store)!r}, ...) completes it"
        )


def lhs_sweep(
    n: int,
    base: gp.Parameters,
    inputs: Inputs,
    config: Config = FAST,
    dims: Sequence[Dimension] | None = None,
    *,
    seed: int = 0,
    measured: Measured | None = None,
    window: tuple[float, float] | None = None,
    store: str | Path | None = None,
    max_chunks: int | None = None,
    metadata: dict | None = None,
    chunk_size: int | None = None,
    devices: Sequence[jax.Device] | None = None,
    memory_budget_bytes: float = 2**30,
    progress: bool = False,
    on_chunk: ChunkCallback | None = None,
) -> SweepResult:
    """A Latin-hypercube sweep of ``n`` points over ``dims``, scored as `evaluate` scores them.

    Args:
        n: the number of points.
        base: the parameters the points replace fields of.
        inputs: the inputs of every run.
        config: the configuration of every run.
        dims: the box; default the paper's (`paper_box`).
        seed: the design's seed.
        measured, window, chunk_size, devices, memory_budget_bytes, progress: as `evaluate`.
        store: a new folder (a Zarr v3 group) that receives each chunk as it finishes, with the sweep's
            definition. SIGINT or SIGTERM then stop the sweep after the chunk in flight (a second signal: at
            once, dropping that chunk), as does reaching ``max_chunks`` chunks in this call; `resume` completes
            the store, with the result, bit for bit, of an uninterrupted sweep on the same device count.
        max_chunks: the most chunks this call runs (with a store only).
        metadata: JSON-ready notes kept in the store's definition.
        on_chunk: called as ``on_chunk(done, total)`` (chunks) after each chunk (with a store: once it is
            written).

    Returns:
        The sweep's result.

    Raises:
        SweepInterrupted: where a stored sweep stopped before its end.
        growjax.sweep.StoreError: where ``store`` already exists.
        ValueError: for ``max_chunks`` without a store, or bad values as `evaluate`.
    """
    dims = tuple(dims) if dims is not None else paper_box()
    taken = store is not None and Path(store).exists() and (not Path(store).is_dir() or any(Path(store).iterdir()))
    if taken and leader():  # (under jax.distributed the first process makes it: the others may see it made)
        raise _store.StoreError(f"{store} already exists; a new sweep needs a new folder (or resume the one there)")
    values = latin_hypercube(dims, n, seed)
    names = [d.name for d in dims]
    options = {
        "measured": measured,
        "window": window,
        "chunk_size": chunk_size,
        "devices": devices,
        "memory_budget_bytes": memory_budget_bytes,
        "progress": progress,
        "on_chunk": on_chunk,
    }
    if store is None:
        if max_chunks is not None:
            raise ValueError("max_chunks stops a sweep that keeps its chunks: give a store")
        return evaluate(values, names, base, inputs, config, **options)
    definition = {
        "design": "latin_hypercube",
        "n": int(n),
        "seed": int(seed),
        "dims": [dataclasses.asdict(d) for d in dims],
        "config": _store.config_record(config),
        "metadata": metadata or {},
    }
    return _stored(store, None, definition, values, base, inputs, config, max_chunks=max_chunks, **options)


def resume(
    store: str | Path,
    base: gp.Parameters,
    inputs: Inputs,
    measured: Measured | None = None,
    *,
    window: tuple[float, float] | None = None,
    progress: bool = False,
    max_chunks: int | None = None,
    devices: Sequence[jax.Device] | None = None,
    on_chunk: ChunkCallback | None = None,
) -> SweepResult:
    """Complete the sweep kept in ``store`` (`lhs_sweep`'s ``store``) and return its whole result.

    The design, ranges, seed, configuration and chunk rows are the store's.

    Args:
        store: the store's folder.
        base, inputs, measured, window: those the sweep was started with (their fingerprints are in the store).
        progress, max_chunks, devices, on_chunk: as `lhs_sweep`.

    Returns:
        The sweep's whole result.

    Raises:
        growjax.sweep.StoreError: (a ``ValueError``) for a missing or corrupt store or one written for other
            inputs, before anything is written.
        SweepInterrupted: as `lhs_sweep`.
    """
    group, definition = _store.open_store(store, mode="r+" if leader() else "r")
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
        on_chunk=on_chunk,
    )


def load(store: str | Path) -> SweepResult:
    """The sweep kept in ``store`` as far as it has run.

    Args:
        store: the store's folder.

    Returns:
        The result; rows not yet run have status ``NOT_RUN`` (``"not_run"``) and NaN scores.

    Raises:
        growjax.sweep.StoreError: for a missing or corrupt store.
    """
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


def _check_identity(path, definition: dict, identity: dict) -> None:
    """Refuse a store written for other base parameters, inputs, measured data or window."""
    wrong = _store.differences(definition.get("identity", {}), identity)
    if wrong:
        what = {"base": "base parameters", "inputs": "inputs", "measured": "measured data", "window": "window"}
        raise _store.StoreError(f"{path} holds a sweep of other {', '.join(what[k] for k in wrong)} than these")


def _open_chunks(path, group, definition: dict, identity: dict, plan: Plan, stop: _stopping.Stopper):
    """(the store's group, which of the plan's chunks are done, this process's view): a new store made (by the
    first process) where ``group`` is None, else the chunks the store holds."""
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
        if leader():
            with stop.writing():
                group = _store.create(path, definition, plan.values, plan.chunk)
        return group, np.zeros(plan.n_chunks, bool)
    if plan.chunk != int(definition["chunk"]):
        raise _store.StoreError(
            f"{path} holds chunks of {definition['chunk']} rows, which "
            f"{plan.mesh.devices.size} devices cannot split evenly; resume on a device "
            "count that divides it"
        )
    return group, _store.done_chunks(_store.read(group, "status"), plan.chunk)


def _run_chunks(plan: Plan, group, todo: list, stop, max_chunks, progress: bool, on_chunk) -> tuple[int, Any]:
    """Run the chunks ``todo``, each written as it finishes, until a signal (in any process) or ``max_chunks``:
    (chunks run, the stopping signal's number: None where none stopped it, 0 for ``max_chunks``)."""
    ran, stopped = 0, None
    with prog.bar(len(todo), "sweep", "chunk", progress and len(todo) > 1 and leader()) as shown:
        for c in todo:
            signalled = signal_anywhere(stop.signal)
            if signalled or (max_chunks is not None and ran >= max_chunks):
                stopped = signalled
                break
            out = run_chunk(plan, c)
            if leader():
                with stop.writing():
                    _store.write_chunk(group, c, plan.chunk, *out)
            ran += 1
            shown.update(1)
            if on_chunk is not None:
                on_chunk(plan.n_chunks - len(todo) + ran, plan.n_chunks)
    return ran, stopped


def _read_back(plan: Plan, group, wall_s: float) -> SweepResult:
    """The whole result, read from the store (by the first process, sent to the others)."""
    n = plan.values.shape[0]
    if leader():
        rmse, final, status = (_store.read(group, k) for k in ("rmse", "final_length", "status"))
    else:  # the store is the first process's: its rows are sent to the others
        rmse, final, status = np.zeros(n), np.zeros(n), np.zeros(n, np.int32)
    rmse, final, status = broadcast((rmse, final, status))
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
    on_chunk=None,
) -> SweepResult:
    """Run the chunks of ``values`` not yet in the store at ``path`` (a new one where ``group`` is None), writing
    each as it finishes (the first process only, under ``jax.distributed``); the whole result read back."""
    names = [d["name"] for d in definition["dims"]]
    identity = _identity(base, inputs, measured, window)
    if group is not None:
        _check_identity(path, definition, identity)
        chunk_size = int(definition["chunk"])
        config = config.replace(quick_compile=definition.get("quick_compile"))
    # A signal from here on stops the sweep between chunks (one during compilation: before the first).
    with _stopping.Stopper(announce=leader()) as stop:
        prog.note(f"sweep: {values.shape[0]} sets, kept in {path} as they finish; compiling", progress and leader())
        plan = make_plan(
            values, names, base, inputs, config, measured, window, chunk_size, devices, memory_budget_bytes
        )
        group, done = _open_chunks(path, group, definition, identity, plan, stop)
        done = broadcast(done)
        todo = [c for c in range(plan.n_chunks) if not done[c]]
        start = time.perf_counter()
        ran, stopped = _run_chunks(plan, group, todo, stop, max_chunks, progress, on_chunk)
    wall_s = time.perf_counter() - start
    if stopped is not None:
        raise SweepInterrupted(path, plan.n_chunks - len(todo) + ran, plan.n_chunks, stopped or None)
    return _read_back(plan, group, wall_s)


def _version() -> str:
    from growjax import __version__

    return __version__
