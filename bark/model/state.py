"""The mechanical state: arrays and time, nothing else (picklable; no backend, no buffers).

The state owns the topology (which bases exist, which springs are intact): the simulation's networkx
graph (:class:`bark.model.graph.LeafBaseGraph`) is a read-only view of these arrays, and the hot
loop runs on them.  Only ``Simulation.break_springs``, ``mend_springs`` and ``join`` change it.

**Fields are declared once** (after LAMMPS's atom styles): ``BASE_FIELDS`` and ``SPRING_FIELDS``
list every per-base and per-spring array with its shape and type; growing, copying, checkpointing
and restoring all walk these lists, so a new per-base quantity is one line.  Arrays are allocated
with spare capacity and doubled when full, so bases and springs that join during a run cost no copy
per addition; the public arrays are views of the first ``n_bases`` (``n_springs``) rows.

Coordinates: Cartesian ``(x, y, z)`` with the trunk axis along ``z`` through the origin; a base at
angle θ sits at ``(r cos θ, r sin θ, z)``.  Per-base arrays are stored column by column (Fortran
order), so each coordinate is one contiguous vector: the compiled loops over the bases run in SIMD
lanes, and numpy's column operations are faster too.
"""

from __future__ import annotations

from typing import Any

import attrs
import numpy as np

__all__ = ["State", "BASE_FIELDS", "SPRING_FIELDS", "cylinder_points", "unit_xy", "grown"]

BASE_FIELDS: dict[str, tuple[tuple[int, ...], str]] = {
    "x": ((3,), "float64"),           # position
    "v": ((3,), "float64"),           # velocity
    "anchor": ((3,), "float64"),      # anchor point: (r(t, z0)·anchor_dir, z0), moved with the surface
    "anchor_dir": ((2,), "float64"),  # unit horizontal direction of the base's site: fixed for good
    "born": ((), "float64"),          # time the base joined the mechanics
}
SPRING_FIELDS: dict[str, tuple[tuple[int, ...], str]] = {
    "pairs": ((2,), "uint32"),        # the two bases (i, j); d = x_j − x_i; never changed (springs are appended)
    "rest": ((), "float64"),          # rest length, taken when the spring was made; never changed
    "fmax": ((), "float64"),          # breaking threshold, per spring (never per base), set then too
    "intact": ((), "bool"),           # changed only by State.set_intact (Simulation.break_springs, mend_springs)
}
MIN_CAPACITY = 64


def cylinder_points(theta: np.ndarray, z: np.ndarray, radius) -> np.ndarray:
    """Cartesian points at angle ``theta`` (radians), height ``z`` on a cylinder of ``radius``."""
    return np.column_stack([radius * np.cos(theta), radius * np.sin(theta), z])


def unit_xy(points: np.ndarray) -> np.ndarray:
    """Unit horizontal directions of ``points`` (``(1, 0)`` for a point on the axis)."""
    rho = np.hypot(points[:, 0], points[:, 1])
    safe = np.where(rho > 0.0, rho, 1.0)
    return np.where((rho > 0.0)[:, None], points[:, :2] / safe[:, None], [1.0, 0.0])


def grown(capacity: int, needed: int) -> int:
    """Rows to allocate when ``needed`` rows outgrow ``capacity``: at least double (amortised O(1) per
    row added), never under ``MIN_CAPACITY``."""
    return max(needed, 2 * capacity, MIN_CAPACITY)


def _alloc(capacity: int, shape: tuple[int, ...], dtype: str) -> np.ndarray:
    return np.zeros((capacity, *shape), dtype=dtype, order="F")


def _field(name: str, doc: str) -> property:
    """A field's active rows (a view); assigning to it writes into them (``state.x += dx`` works)."""

    def set_rows(self, value) -> None:
        self._view(name)[...] = value

    return property(lambda self: self._view(name), set_rows, doc=doc)


def _flags(name: str, doc: str) -> property:
    """A field of flags that only :meth:`State.set_intact` changes: a read-only view of its rows."""

    def get(self) -> np.ndarray:
        rows = self._view(name)
        rows.flags.writeable = False
        return rows

    def refuse(self, value) -> None:
        raise AttributeError(f"state.{name} changes only through Simulation.break_springs and mend_springs")

    return property(get, refuse, doc=doc)


@attrs.define(eq=False)
class State:
    """Positions, velocities and springs of the leaf-base layer at time ``t``.

    ``x``, ``v``, ``anchor``, ``anchor_dir``, ``born`` (per base) and ``pairs``, ``rest``, ``fmax``,
    ``intact`` (per spring) are views of the active rows; assigning into them (``state.x[:] = ...``)
    writes the state.  Integrators change ``x`` and ``v``; the simulation changes ``t``, applies the
    surface constraint, breaks springs and adds bases.  A spring's ``rest`` and ``fmax`` are its
    material, set when it is made and never changed afterwards, and its ``pairs`` too: springs are only
    appended (backends keep derived data of them, extended when springs are added).
    """

    n_bases: int = 0
    n_springs: int = 0
    t: float = 0.0
    """Simulated time."""
    h: float = 0.0
    """Length of the step that led to this state (rate-based breakers use it)."""
    intact_version: int = 0
    """How many times the intact flags have been edited (``set_intact``): a backend's copy of them
    is in step while this is the count it saw.  Appended springs do not count (backends extend
    their copies with them)."""
    _store: dict[str, np.ndarray] = attrs.field(factory=dict, repr=False)

    @classmethod
    def empty(cls, bases: int = MIN_CAPACITY, springs: int = MIN_CAPACITY) -> "State":
        """A state with no bases or springs yet, with room for ``bases`` and ``springs``."""
        state = cls()
        state._store = {name: _alloc(max(bases, 1), shape, dt) for name, (shape, dt) in BASE_FIELDS.items()}
        state._store.update({name: _alloc(max(springs, 1), shape, dt) for name, (shape, dt) in SPRING_FIELDS.items()})
        return state

    # -- the arrays ----------------------------------------------------------------------------

    def _view(self, name: str) -> np.ndarray:
        n = self.n_bases if name in BASE_FIELDS else self.n_springs
        return self._store[name][:n]

    x = _field("x", "Positions of the bases, ``(n, 3)``.")
    v = _field("v", "Velocities of the bases, ``(n, 3)``.")
    anchor = _field("anchor", "Anchor points, ``(n, 3)``; a function of t alone.")
    anchor_dir = _field("anchor_dir", "Unit horizontal direction of each site, ``(n, 2)``.")
    born = _field("born", "Time each base joined, ``(n,)``.")
    pairs = _field("pairs", "Spring ends ``(i, j)``, ``(m, 2)``; row = spring id.")
    rest = _field("rest", "Rest length of every spring, ``(m,)``.")
    fmax = _field("fmax", "Breaking threshold of every spring, ``(m,)``.")
    intact = _flags("intact", "Whether each spring is intact, ``(m,)`` bool (read-only: ``set_intact``).")

    @property
    def capacity(self) -> tuple[int, int]:
        """Rows allocated for bases and springs (``n_bases`` and ``n_springs`` of them in use)."""
        return self._store["x"].shape[0], self._store["pairs"].shape[0]

    def arrays(self) -> dict[str, np.ndarray]:
        """Every field's active rows, by name (views)."""
        return {name: self._view(name) for name in (*BASE_FIELDS, *SPRING_FIELDS)}

    def set_intact(self, ids: np.ndarray, value: bool) -> None:
        """Mark springs ``ids`` intact (``value`` true) or broken: the one way the flags change, one
        edit (``intact_version``, on which the graph's table and every backend cache of the flags
        are keyed).  ``Simulation.break_springs`` and ``mend_springs`` call it."""
        self._store["intact"][np.asarray(ids, dtype=np.int64)] = bool(value)
        self.intact_version += 1

    # -- growing --------------------------------------------------------------------------------

    def _reserve(self, fields: dict, count: int, needed: int) -> None:
        capacity = self._store[next(iter(fields))].shape[0]
        if needed <= capacity:
            return
        size = grown(capacity, needed)
        for name, (shape, dtype) in fields.items():
            bigger = _alloc(size, shape, dtype)
            bigger[:count] = self._store[name][:count]
            self._store[name] = bigger

    def add_bases(self, **values: np.ndarray) -> np.ndarray:
        """Append bases with the given fields (every one of ``BASE_FIELDS``); returns their ids."""
        return self._append(BASE_FIELDS, "n_bases", values)

    def add_springs(self, **values: np.ndarray) -> np.ndarray:
        """Append springs with the given fields (every one of ``SPRING_FIELDS``); returns their ids."""
        return self._append(SPRING_FIELDS, "n_springs", values)

    def _append(self, fields: dict, counter: str, values: dict[str, Any]) -> np.ndarray:
        if set(values) != set(fields):
            raise ValueError(f"give exactly {sorted(fields)}, not {sorted(values)}")
        count = getattr(self, counter)
        added = len(np.atleast_1d(values[next(iter(fields))]))
        self._reserve(fields, count, count + added)
        for name, value in values.items():
            shape = fields[name][0]
            self._store[name][count:count + added] = np.reshape(value, (added, *shape))
        setattr(self, counter, count + added)
        return np.arange(count, count + added)

    # -- whole states ---------------------------------------------------------------------------

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], t: float = 0.0, h: float = 0.0) -> "State":
        """A state holding copies of ``arrays`` (every field), e.g. from a checkpoint."""
        n, m = len(arrays["x"]), len(arrays["pairs"])
        state = cls.empty(n, m)
        state.add_bases(**{k: arrays[k] for k in BASE_FIELDS})
        state.add_springs(**{k: arrays[k] for k in SPRING_FIELDS})
        state.t, state.h = float(t), float(h)
        return state

    def copy(self) -> "State":
        return State.from_arrays(self.arrays(), self.t, self.h)

    def __getstate__(self) -> dict:
        """Pickles the active rows only (spare capacity is not data)."""
        return {"arrays": {k: np.array(v) for k, v in self.arrays().items()}, "t": self.t, "h": self.h}

    def __setstate__(self, data: dict) -> None:
        restored = State.from_arrays(data["arrays"], data["t"], data["h"])
        for a in attrs.fields(State):
            object.__setattr__(self, a.name, getattr(restored, a.name))

    def is_finite(self) -> bool:
        return bool(np.isfinite(self.x).all() and np.isfinite(self.v).all())
