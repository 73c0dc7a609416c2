"""The leaf-base graph of record (networkx): bases as nodes, intact springs as edges.

Its own module so that ``import bark`` (and reading a scene) does not pay for networkx's import:
a simulation imports it when it is built.
"""

from __future__ import annotations

import networkx as nx
import numpy as np

__all__ = ["LeafBaseGraph"]

_NO_ATTRIBUTES: dict = {}
_clear_cache = getattr(nx, "_clear_cache", lambda graph: None)  # what networkx's own edits call (its backends' caches)


class LeafBaseGraph(nx.Graph):
    """The graph of record: bases as nodes, intact springs as edges, with no attribute dictionaries
    (positions, sites and thresholds live in the state's arrays, by node and spring id).  Every node
    and edge shares one empty mapping, and each base is one int object: 22.6 MiB at 70 000 bases
    against 71 MiB for a plain ``Graph`` carrying the old per-node and per-edge attributes (measured
    with tracemalloc).  Do not set attributes on it; ``bark.io.output.write_graphml`` exports a copy with them."""

    node_attr_dict_factory = staticmethod(lambda: _NO_ATTRIBUTES)
    edge_attr_dict_factory = staticmethod(lambda: _NO_ATTRIBUTES)

    def add_bases(self, n: int) -> None:
        """Nodes for the next ``n`` bases (ids continue from the number of nodes)."""
        keys = self._keys()
        new = list(range(len(keys), len(keys) + n))
        self.add_nodes_from(new)
        keys.extend(new)

    def has_bases(self, ids: np.ndarray) -> np.ndarray:
        """Whether each of ``ids`` is a node: the nodes are the ids 0 … n-1 (``add_bases`` adds them in
        order, and bases never leave)."""
        ids = np.asarray(ids)
        return (ids >= 0) & (ids < len(self._node))

    def add_springs(self, pairs: np.ndarray) -> None:
        """Edges for the springs ``pairs`` (rows of base ids, both ends bases already), keyed by the node
        objects themselves: one int object per base rather than one per spring end, 7.5 MiB less at
        70 000 bases.  Written into the adjacency directly, as ``add_edges_from`` does for an edge
        without attributes, less its per-edge checks (the ends are checked at once): 2,400 joins
        add 50,000 springs."""
        pairs = np.asarray(pairs)
        if pairs.size and not self.has_bases(pairs).all():
            raise ValueError("a spring's ends must be bases of the graph (add_bases first)")
        keys, adj = self._keys(), self._adj
        for start in range(0, len(pairs), 4096):  # in chunks: a list of 140 000 pairs is 19 MiB
            for i, j in pairs[start:start + 4096].tolist():
                u, v = keys[i], keys[j]
                adj[u][v] = _NO_ATTRIBUTES
                adj[v][u] = _NO_ATTRIBUTES
        _clear_cache(self)

    def remove_springs(self, pairs: np.ndarray) -> None:
        """Remove the edges of the springs ``pairs`` (each an edge of the graph), as
        ``remove_edges_from`` does, less its per-edge checks."""
        adj = self._adj
        for i, j in np.asarray(pairs).tolist():
            del adj[i][j]
            if i != j:
                del adj[j][i]
        _clear_cache(self)

    def _keys(self) -> list:
        """The node objects by base id (nodes are the ids 0 … n-1, added in order by ``add_bases``)."""
        keys = self.__dict__.get("_key_list")
        if keys is None or len(keys) != len(self._node):
            keys = self.__dict__["_key_list"] = list(self._node)
        return keys
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

