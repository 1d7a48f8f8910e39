"""One fingerprint of a pytree's content, for in-memory caches keyed on what their results depend on."""

from __future__ import annotations

import hashlib

import jax
import numpy as np
from jaxtyping import PyTree

__all__ = ["content_key"]


def content_key(tree: PyTree) -> tuple[str, str]:
    """A key equal for pytrees of equal structure and leaves.

    Args:
        tree: any pytree; leaves that are not numeric enter by their ``repr``.

    Returns:
        (the structure, the SHA-1 of every leaf's dtype, shape and values).
    """
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    digest = hashlib.sha1()
    for leaf in leaves:
        a = np.asarray(leaf)
        digest.update(str((a.dtype, a.shape)).encode())
        digest.update(repr(leaf).encode() if a.dtype == object else np.ascontiguousarray(a).tobytes())
    return str(treedef), digest.hexdigest()
