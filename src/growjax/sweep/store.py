"""A sweep's results on disk as its chunks finish: a Zarr v3 group, one chunk of the sweep per chunk file.

Layout of the group (a folder): ``values`` (n, d) parameter values, SI, written whole when the store is made;
``rmse`` (n,) m, ``final_length`` (n,) m and ``status`` (n,) codes, chunked as the sweep is (one chunk file per
array and sweep chunk). ``status`` is written after the other two: a status chunk on disk marks its chunk done
(its fill value, `NOT_RUN`, marks rows not yet run). Every chunk file is written to a temporary file and
renamed into place (zarr's local store), so a stop never leaves a half-written chunk. The group's attributes
hold the sweep's definition (design, ranges, seed, n, configuration, chunk rows) and fingerprints of the base
parameters, inputs, measured data and window, so that a resume can refuse what belongs to another sweep.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import jax
import numpy as np
from jaxtyping import Bool, Float, Int, PyTree

if TYPE_CHECKING:
    import zarr

    from growjax.simulation.config import Config

__all__ = [
    "ARRAYS",
    "FORMAT",
    "NOT_RUN",
    "VERSION",
    "StoreError",
    "config_record",
    "create",
    "differences",
    "done_chunks",
    "fingerprint",
    "open_store",
    "read",
    "write_chunk",
]

FORMAT = "growjax-sweep"
VERSION = 1
NOT_RUN = -1  # status of a row whose chunk has not been run
ARRAYS = ("values", "rmse", "final_length", "status")


class StoreError(ValueError):
    """A store that is missing, corrupt or of another sweep (one line naming the problem)."""


def fingerprint(tree: PyTree) -> str:
    """SHA-256 of a pytree's structure and leaves (dtype, shape, bytes); stable across processes."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    digest = hashlib.sha256(re.sub(r" at 0x[0-9a-fA-F]+", "", str(treedef)).encode())
    for leaf in leaves:
        a = np.asarray(leaf)
        digest.update(str((a.dtype.str, a.shape)).encode())
        text = re.sub(r" at 0x[0-9a-fA-F]+", "", repr(leaf)).encode()
        digest.update(text if a.dtype == object else np.ascontiguousarray(a).tobytes())
    return digest.hexdigest()


def config_record(config: Config) -> dict[str, Any]:
    """A `growjax.Config` as a JSON-ready dict (rebuilt by ``Config(**record)``)."""
    return dataclasses.asdict(config)


def create(path: str | Path, definition: dict[str, Any], values: Float[np.ndarray, "n d"], chunk: int) -> zarr.Group:
    """A new store.

    Args:
        path: its folder, new or empty.
        definition: the sweep's definition (JSON-ready), kept in the group's attributes.
        values: (n, d) the parameter values, SI, written whole.
        chunk: the rows per chunk.

    Returns:
        The zarr group.

    Raises:
        StoreError: where ``path`` exists and is not empty.
    """
    import zarr

    path = Path(path)
    if path.exists() and (not path.is_dir() or any(path.iterdir())):
        raise StoreError(f"{path} already exists; a new sweep needs a new folder (or resume the one there)")
    n, d = values.shape
    group = zarr.open_group(str(path), mode="w-")
    group.attrs.update({"format": FORMAT, "version": VERSION, "definition": definition})
    group.create_array(
        "values",
        shape=(n, d),
        chunks=(chunk, d),
        dtype="float64",
        fill_value=np.nan,
        dimension_names=("row", "parameter"),
    )[...] = values
    for name in ("rmse", "final_length"):
        group.create_array(
            name, shape=(n,), chunks=(chunk,), dtype="float64", fill_value=np.nan, dimension_names=("row",)
        )
    group.create_array(
        "status", shape=(n,), chunks=(chunk,), dtype="int32", fill_value=NOT_RUN, dimension_names=("row",)
    )
    return group


def open_store(path: str | Path, mode: str = "r") -> tuple[zarr.Group, dict[str, Any]]:
    """Open a store.

    Args:
        path: its folder.
        mode: zarr's mode (``"r"`` to read, ``"r+"`` to resume).

    Returns:
        (the zarr group, the sweep's definition).

    Raises:
        StoreError: where it is missing, corrupt or of another format or version.
    """
    import zarr

    path = Path(path)
    if not path.is_dir():
        raise StoreError(f"{path}: no sweep store there (no such folder)")
    try:
        group = zarr.open_group(str(path), mode=mode)
        attrs = dict(group.attrs)
        arrays = {name: group[name] for name in ARRAYS}
    except Exception as err:  # zarr's errors for missing or unreadable metadata vary by kind
        raise StoreError(f"{path}: not a readable sweep store ({type(err).__name__}: {_first_line(err)})") from None
    definition = attrs.get("definition")
    if attrs.get("format") != FORMAT or not isinstance(definition, dict):
        raise StoreError(f"{path}: not a growjax sweep store (no sweep definition in its attributes)")
    if attrs.get("version") != VERSION:
        raise StoreError(f"{path}: sweep store version {attrs.get('version')}, this growjax reads version {VERSION}")
    try:
        n, d, chunk = int(definition["n"]), len(definition["names"]), int(definition["chunk"])
    except (KeyError, TypeError, ValueError):
        raise StoreError(f"{path}: corrupt sweep store (incomplete definition)") from None
    shapes = {"values": (n, d), "rmse": (n,), "final_length": (n,), "status": (n,)}
    for name, shape in shapes.items():
        if tuple(arrays[name].shape) != shape or arrays[name].chunks[0] != chunk:
            raise StoreError(
                f"{path}: corrupt sweep store ({name} has shape {arrays[name].shape}, "
                f"chunks {arrays[name].chunks}; the definition says {shape} in chunks of {chunk})"
            )
    return group, definition


def read(group: zarr.Group, name: str) -> np.ndarray:
    """One array of the store (one of `ARRAYS`), whole; `StoreError` where a chunk cannot be read."""
    try:
        return np.asarray(group[name][...])
    except Exception as err:
        raise StoreError(
            f"{group.store}: corrupt sweep store ({name}: {type(err).__name__}: {_first_line(err)})"
        ) from None


def write_chunk(
    group: zarr.Group,
    c: int,
    chunk: int,
    rmse: Float[np.ndarray, " r"],
    final: Float[np.ndarray, " r"],
    status: Int[np.ndarray, " r"],
) -> None:
    """Write the r ≤ ``chunk`` rows of chunk ``c``: ``rmse`` (m) and ``final`` length (m) first, then ``status``,
    which marks it done."""
    rows = slice(c * chunk, c * chunk + len(status))
    group["rmse"][rows] = rmse
    group["final_length"][rows] = final
    group["status"][rows] = status


def done_chunks(status: Int[np.ndarray, " n"], chunk: int) -> Bool[np.ndarray, " n_chunks"]:
    """(n_chunks,) bool: chunks whose rows all have a status."""
    n_chunks = -(-status.size // chunk)
    padded = np.concatenate([status, np.zeros(n_chunks * chunk - status.size, status.dtype)])
    return np.all(padded.reshape(n_chunks, chunk) != NOT_RUN, axis=1)


def differences(recorded: dict[str, Any], wanted: dict[str, Any]) -> list[str]:
    """Keys whose values differ between two definitions (compared as JSON)."""
    return [k for k in wanted if json.dumps(recorded.get(k), sort_keys=True) != json.dumps(wanted[k], sort_keys=True)]


def _first_line(err) -> str:
    text = str(err).strip().splitlines()
    return text[0][:200] if text else ""
