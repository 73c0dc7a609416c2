"""Patches: the connected components of the intact springs, as labels per base.

Apart from the leaf-base graph (``bark.model.graph``), so that counting patches — what a run's
patch-count stop and every statistic ask — imports neither networkx nor scipy.sparse (whose
graph routines import scipy.linalg, a large share of a short run's start-up).  The labels are those of
``scipy.sparse.csgraph.connected_components``, the tests' oracle: numbered by each component's
smallest base.
"""

from __future__ import annotations

import numpy as np

__all__ = ["components", "count_patches"]


def components(n: int, pairs: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """A label per base of ``0 .. n − 1``: the connected components of the springs ``pairs[kept]``,
    numbered in order of each component's smallest base, int32.

    Union–find on whole arrays (Shiloach–Vishkin): each round hooks every tree's root under the
    smallest root a spring reaches from it, then points every base at its root by pointer
    jumping; a round at least halves the trees still to be joined, so the rounds are logarithmic,
    and a root is always its component's smallest base."""
    p = np.asarray(pairs)[np.asarray(kept, bool)]
    u, v = p[:, 0].astype(np.intp), p[:, 1].astype(np.intp)
    root = np.arange(n, dtype=np.intp)
    while u.size:
        ru, rv = root[u], root[v]
        apart = ru != rv  # springs inside one tree are done with
        u, v, ru, rv = u[apart], v[apart], ru[apart], rv[apart]
        if not u.size:
            break
        np.minimum.at(root, np.maximum(ru, rv), np.minimum(ru, rv))  # hook: roots only, so no cycle
        jumped = root[root]
        while not np.array_equal(jumped, root):
            root, jumped = jumped, jumped[jumped]
    first = root == np.arange(n)  # the roots, one per component, in order of base
    return (np.cumsum(first, dtype=np.int32) - 1)[root]


def count_patches(labels: np.ndarray, min_size: int) -> int:
    """How many patches (labels, as ``components`` gives them) have at least ``min_size`` bases."""
    return int(np.count_nonzero(np.bincount(labels) >= min_size))
