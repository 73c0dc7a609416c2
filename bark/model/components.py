"""Patches: the connected components of the intact springs, as labels per base (scipy.sparse.csgraph).

Apart from the leaf-base graph (``bark.model.graph``), so that counting patches — what a run's
patch-count stop and every statistic ask — does not import networkx.
"""

from __future__ import annotations

import numpy as np

__all__ = ["components", "count_patches"]


def components(n: int, pairs: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """A label per base of ``0 .. n − 1``: the connected components of the springs ``pairs[kept]``
    (``scipy.sparse.csgraph``'s numbering: by each component's smallest base), int32."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    p = np.asarray(pairs, dtype=np.int64)[np.asarray(kept, bool)]
    adjacency = coo_matrix((np.ones(len(p)), (p[:, 0], p[:, 1])), shape=(n, n))
    return connected_components(adjacency, directed=False)[1].astype(np.int32)


def count_patches(labels: np.ndarray, min_size: int) -> int:
    """How many patches (labels, as ``components`` gives them) have at least ``min_size`` bases."""
    return int(np.count_nonzero(np.bincount(labels) >= min_size))
