"""The leaf-base graph (networkx): bases as nodes, intact springs as edges — a view of the state.

The topology has one owner, the :class:`~bark.model.state.State`: its ``pairs`` and ``intact`` flags
(``State.set_intact`` the one way those change, each edit counted in ``intact_version``).  The graph
is a read-only ``networkx.Graph`` over them, so every networkx algorithm, query and writer works on
the simulation's leaf bases, and graph and arrays cannot disagree: there is no second copy to keep in
step.  Its adjacency is a compressed sparse row table made from the state when first read after an
edit (a pass over the springs); asking the number of bases or whether ids are
bases (what a joining base asks) reads the state alone.

Its own module so that ``import bark`` (and reading a scene) does not pay for networkx's import:
a simulation imports it when its ``graph`` is first read.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Callable

import networkx as nx
import numpy as np

from bark.model.components import components, count_patches  # noqa: F401 — their home before

__all__ = ["LeafBaseGraph", "components", "count_patches"]

_NO_DATA = MappingProxyType({})


class _Nodes(Mapping):
    """The nodes: the ids ``0 … n_bases − 1`` of the state's bases (bases never leave), no data."""

    def __init__(self, graph: "LeafBaseGraph") -> None:
        self._graph = graph

    def _n(self) -> int:
        return self._graph.state.n_bases

    def __getitem__(self, node):
        if node in self:
            return _NO_DATA
        raise KeyError(node)

    def __contains__(self, node) -> bool:
        try:
            return 0 <= node < self._n() and int(node) == node
        except TypeError:
            return False

    def __iter__(self):
        return iter(range(self._n()))

    def __len__(self) -> int:
        return self._n()


class _Neighbours(Mapping):
    """One base's neighbours over intact springs, each with its edge's data ``{"spring": id}``."""

    def __init__(self, ids: np.ndarray, springs: np.ndarray) -> None:
        self._ids, self._springs = ids, springs
        self._index = None

    def _lookup(self) -> dict:
        if self._index is None:
            self._index = dict(zip(self._ids.tolist(), self._springs.tolist()))
        return self._index

    def __getitem__(self, node):
        return MappingProxyType({"spring": self._lookup()[node]})

    def __contains__(self, node) -> bool:
        return node in self._lookup()

    def __iter__(self):
        return iter(self._ids.tolist())

    def __len__(self) -> int:
        return len(self._ids)


class _Adjacency(Mapping):
    """The adjacency, base by base, from the graph's table of the state's intact springs."""

    def __init__(self, graph: "LeafBaseGraph") -> None:
        self._graph = graph

    def __getitem__(self, node):
        if node not in self._graph._node:
            raise KeyError(node)
        indptr, ids, springs = self._graph.table()
        a, b = indptr[node], indptr[node + 1]
        return _Neighbours(ids[a:b], springs[a:b])

    def __contains__(self, node) -> bool:
        return node in self._graph._node

    def __iter__(self):
        return iter(self._graph._node)

    def __len__(self) -> int:
        return len(self._graph._node)


def _read_only(name: str):
    def refuse(self, *args, **kwargs):
        raise nx.NetworkXError(f"the leaf-base graph is a view of the simulation's springs and cannot be changed "
                               f"({name}): use Simulation.join, break_springs or mend_springs, or copy() it")
    refuse.__name__ = name
    refuse.__doc__ = (f"Refused (``NetworkXError``): the leaf-base graph is a read-only view of the springs; "
                      f"``Simulation.join``, ``break_springs`` and ``mend_springs`` change them, and ``copy()`` "
                      f"gives a graph of one's own to change.")
    return refuse


class LeafBaseGraph(nx.Graph):
    """The leaf-base graph of ``state_of()`` (the simulation's current state): nodes are base ids,
    edges the intact springs, each edge's data ``{"spring": id}`` (positions, sites and thresholds
    are the state's, by node and spring id).  Read-only: changing it raises ``NetworkXError``, since
    the topology changes through the simulation (``join``, ``break_springs``, ``mend_springs``);
    ``copy()`` gives an ordinary graph to edit."""

    def __init__(self, state_of: Callable[[], object]) -> None:  # noqa: D107 (no dicts to fill: nx.Graph's own would)
        self.graph = {}
        self.__networkx_cache__ = {}
        self._state_of = state_of
        self._table_key = None
        self._table = None
        self._node = _Nodes(self)
        self._adj = _Adjacency(self)

    @property
    def state(self):
        """The simulation's state this graph is a view of (its current one)."""
        return self._state_of()

    def table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(indptr, neighbours, springs)``: each base's neighbours over intact springs, ascending, and
        the springs to them, as a compressed sparse row table — made again after any edit of the state's
        topology (a new state, bases or springs added, ``intact_version``)."""
        s = self.state
        key = (id(s), s.n_bases, s.n_springs, s.intact_version)
        if key != self._table_key:
            springs = np.flatnonzero(s.intact).astype(np.int64)
            ends = s.pairs[springs].astype(np.int64)
            rows = np.concatenate([ends[:, 0], ends[:, 1]])
            cols = np.concatenate([ends[:, 1], ends[:, 0]])
            order = np.lexsort((cols, rows))
            indptr = np.zeros(s.n_bases + 1, dtype=np.int64)
            np.cumsum(np.bincount(rows, minlength=s.n_bases), out=indptr[1:])
            self._table = (indptr, cols[order].astype(np.int32), np.concatenate([springs, springs])[order].astype(np.int32))
            self._table_key = key
            self.__networkx_cache__.clear()
        return self._table

    def has_bases(self, ids: np.ndarray) -> np.ndarray:
        """Whether each of ``ids`` is a node (the nodes are the ids 0 … n-1: bases never leave)."""
        ids = np.asarray(ids)
        return (ids >= 0) & (ids < self.state.n_bases)

    def number_of_edges(self, u=None, v=None) -> int:
        """The intact springs (between ``u`` and ``v`` when given, as networkx counts them)."""
        if u is None:
            return int(np.count_nonzero(self.state.intact))
        return super().number_of_edges(u, v)

    for _name in ("add_node", "add_nodes_from", "remove_node", "remove_nodes_from", "add_edge", "add_edges_from",
                  "add_weighted_edges_from", "remove_edge", "remove_edges_from", "update", "clear", "clear_edges"):
        locals()[_name] = _read_only(_name)
    del _name

    def copy(self, as_view: bool = False) -> nx.Graph:
        """An ordinary ``networkx.Graph`` with these nodes and edges (and the edges' spring ids)."""
        if as_view:
            return nx.graphviews.generic_graph_view(self)
        g = nx.Graph()
        g.add_nodes_from(self._node)
        indptr, ids, springs = self.table()
        rows = np.repeat(np.arange(self.state.n_bases), np.diff(indptr))
        once = rows < ids  # each spring once, from its lower end
        g.add_edges_from((i, j, {"spring": k}) for i, j, k in zip(rows[once].tolist(), ids[once].tolist(),
                                                                  springs[once].tolist()))
        return g

    def __reduce__(self):
        raise TypeError("the leaf-base graph is a view of a simulation's state: pickle the simulation, or copy() it")
