"""A sweep across the processes of a ``jax.distributed.initialize`` run: the rows each process fills, the results
every process gets, the process that writes, and a stop that all processes agree on."""

from __future__ import annotations

from typing import Any

import jax
import numpy as np
from jax.sharding import NamedSharding

__all__ = ["broadcast", "gather", "leader", "put", "signal_anywhere"]


def leader() -> bool:
    """Whether this process writes: the first under ``jax.distributed``, the only one otherwise."""
    return jax.process_index() == 0


def put(block: np.ndarray, sharding: NamedSharding) -> jax.Array:
    """Host rows as one array sharded over the mesh.

    Args:
        block: (B, d) rows, the same in every process.
        sharding: the rows' sharding over the mesh.

    Returns:
        The sharded array; under ``jax.distributed`` each process fills only the shards on its own devices.
    """
    if jax.process_count() == 1:
        return jax.device_put(block, sharding)
    return jax.make_array_from_callback(block.shape, sharding, lambda index: block[index])


def gather(outputs: Any) -> Any:
    """Sharded outputs as host arrays, gathered from all processes under ``jax.distributed``.

    Args:
        outputs: a pytree of sharded arrays.

    Returns:
        The same pytree of NumPy arrays, whole in every process.
    """
    if jax.process_count() == 1:
        return jax.device_get(outputs)
    from jax.experimental import multihost_utils

    return multihost_utils.process_allgather(outputs, tiled=True)


def signal_anywhere(number: int | None) -> int:
    """The number of a stopping signal received by this or any process.

    Every process must call it at the same point, so that all stop at the same chunk.

    Args:
        number: this process's signal, or None.

    Returns:
        The largest signal number received by any process; 0 for none.
    """
    if jax.process_count() == 1:
        return int(number or 0)
    from jax.experimental import multihost_utils

    return int(np.max(multihost_utils.process_allgather(np.array([number or 0], np.int32))))


def broadcast(tree: Any) -> Any:
    """The first process's pytree of NumPy arrays, in every process.

    Args:
        tree: a pytree of arrays, of the same shapes in every process.

    Returns:
        The first process's ``tree``, with its dtypes.
    """
    if jax.process_count() == 1:
        return tree
    from jax.experimental import multihost_utils

    dtypes = jax.tree_util.tree_map(lambda a: np.asarray(a).dtype, tree)
    sent = jax.tree_util.tree_map(lambda a: np.asarray(a).astype(np.int32) if np.asarray(a).dtype == bool else a, tree)
    got = multihost_utils.broadcast_one_to_all(sent)
    return jax.tree_util.tree_map(lambda a, t: np.asarray(a).astype(t), got, dtypes)
