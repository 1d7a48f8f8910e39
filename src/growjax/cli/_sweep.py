"""The sweep command's store and processes: the options recorded in the store, their restoration by
``--resume``, a stop's exit status and message, and ``jax.distributed``'s start."""

from __future__ import annotations

import shutil
import signal
from pathlib import Path

from growjax.cli.command import Stopped

STORE = "sweep.zarr"  # the store's folder inside --out
# the options that define a sweep (recorded in its store; --resume takes them from there)
DEFINING = ("data", "drive", "param", "fidelity", "rtol", "seed", "t_end", "sets", "range", "chunk_size")
STOPPED_BY_REQUEST = 3  # exit status of a sweep stopped by --max-chunks (a signal: 128 + its number)


def store_path(folder) -> Path:
    return Path(folder) / STORE


def record(args) -> dict:
    """The defining options of ``args``, JSON-ready (the data as an absolute path)."""
    from growjax.data.datasets import default_data_path

    data = Path(args.data) if args.data else default_data_path()
    values = {k: getattr(args, k) for k in DEFINING}
    values["data"] = str(data.resolve())
    values["param"], values["range"] = list(args.param), list(args.range)
    return values


def restore(args) -> None:
    """Set ``args``' defining options to those recorded in ``--resume DIR``'s store; ValueError (one line) where
    the command line gives one another value, or the store is missing or corrupt."""
    from growjax import sweep as sw
    from growjax.sweep.store import open_store

    folder = Path(args.resume)
    _, definition = open_store(store_path(folder)) if folder.is_dir() else (None, None)
    if definition is None:
        raise sw.StoreError(f"--resume {folder}: no such folder")
    recorded = definition.get("metadata", {}).get("cli")
    if not isinstance(recorded, dict) or set(recorded) != set(DEFINING):
        raise sw.StoreError(f"--resume {folder}: its store was not written by `growjax sweep` (no options recorded)")
    if "out" in getattr(args, "given", ()) and Path(args.out).resolve() != folder.resolve():
        raise ValueError(f"--resume {folder} writes its results there; drop --out {args.out}")
    given = record(args)
    for key in DEFINING:
        if key in getattr(args, "given", ()) and given[key] != recorded[key]:
            option = "DATA" if key == "data" else "--" + key.replace("_", "-")
            raise ValueError(
                f"--resume {folder} holds another sweep: {option} {given[key]} here, {recorded[key]} there"
            )
        setattr(args, key, recorded[key])
    args.out = str(folder)


def prepare_new(folder) -> Path:
    """The store path for a new sweep in ``folder``: a finished sweep's store there is replaced; an unfinished
    one, or anything else named like it, is a ValueError (nothing removed)."""
    from growjax import sweep as sw

    path = store_path(folder)
    if not path.exists():
        return path
    result = sw.load(path)  # StoreError where it is not a sweep store
    if (result.status == sw.NOT_RUN).any():
        raise ValueError(
            f"{folder} holds an unfinished sweep: complete it with `growjax sweep --resume {folder}`, "
            "or choose another --out"
        )
    shutil.rmtree(path)
    return path


def stopped(error, folder, distributed: bool) -> Stopped:
    """The `Stopped` of an interrupted sweep (``error``: `growjax.sweep.SweepInterrupted`, or a
    ``KeyboardInterrupt`` that cut the chunk in flight)."""
    done = f"{error.done} of {error.total} chunks" if hasattr(error, "done") else "the chunks finished"
    again = " with the same process options" if distributed else ""
    message = f"stopped; {done} kept in {store_path(folder)}; complete it with: growjax sweep --resume {folder}{again}"
    if not store_path(folder).exists():
        message = "stopped before the sweep's store was made; nothing kept"
    number = getattr(error, "signal", None)
    if number is None and not hasattr(error, "done"):
        number = signal.SIGINT
    return Stopped(message, 128 + int(number) if number else STOPPED_BY_REQUEST)


def start_distributed(args) -> None:
    """``jax.distributed.initialize``: the cluster detected (``--distributed``) or ``--coordinator``'s;
    ValueError (one line) for an incomplete set of options."""
    import jax

    explicit = (args.coordinator, args.num_processes, args.process_id)
    if any(v is not None for v in explicit):
        if any(v is None for v in explicit):
            raise ValueError("--coordinator, --num-processes and --process-id go together")
        if not 0 <= args.process_id < args.num_processes:
            raise ValueError(f"--process-id {args.process_id} must lie in 0..{args.num_processes - 1}")
        jax.distributed.initialize(
            coordinator_address=args.coordinator, num_processes=args.num_processes, process_id=args.process_id
        )
    elif args.distributed:
        try:
            jax.distributed.initialize()
        except (ValueError, RuntimeError) as err:
            raise ValueError(
                f"--distributed: no cluster detected ({str(err).splitlines()[0]}); give --coordinator, "
                "--num-processes and --process-id"
            ) from None
