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

import contextlib
from typing import Any

import attrs
import numpy as np

from bark.errors import BarkError, StateWriteError
from bark.validators import one_of

__all__ = ["State", "Declared", "Field", "BASE_FIELDS", "SPRING_FIELDS", "FIXED", "cylinder_points", "unit_xy", "grown"]

BASE_FIELDS: dict[str, tuple[tuple[int, ...], str]] = {
    "x": ((3,), "float64"),           # position
    "v": ((3,), "float64"),           # velocity
    "anchor": ((3,), "float64"),      # anchor point: (r(t, z0)·anchor_dir, z0), moved with the surface
    "anchor_dir": ((2,), "float64"),  # unit horizontal direction of the base's site: fixed for good
    "born": ((), "float64"),          # time the base joined the mechanics
}
SPRING_FIELDS: dict[str, tuple[tuple[int, ...], str]] = {
    "pairs": ((2,), "uint32"),        # the two bases (i, j); d = x_j − x_i; never changed (springs are appended)
    "rest": ((), "float64"),          # rest length, taken when the spring was made; changed only by declared writes
    "fmax": ((), "float64"),          # breaking threshold, per spring (never per base), set then too; ditto
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


FIXED: dict[str, str] = {
    "pairs": "springs are only appended (Simulation.join); a spring's ends never change",
    "intact": "it changes only through Simulation.break_springs and mend_springs",
}
"""Fields no declared write may open, and why."""


def _refusal(name: str) -> str:
    if name in FIXED:
        return f"state.{name} is read-only: {FIXED[name]}"
    shown = f"state.{name}" if name in BASE_FIELDS or name in SPRING_FIELDS else f"state[{name!r}]"
    return (f"{shown} is read-only outside the engine: a strategy writes only the fields its class "
            f"declares (`writes`), and a script or a test edits the state inside "
            f"`with state.writing({name!r}): ...`, so that every backend is told")


class Field(np.ndarray):
    """A field's rows as the state hands them out where they may not be written: a read-only view
    whose writes (``a[i] = v``, ``a += v``) raise :class:`~bark.errors.StateWriteError` in one line
    saying how to declare the write.  Arithmetic on it gives plain arrays."""

    _bark_field: str = ""

    def __array_finalize__(self, obj) -> None:
        self._bark_field = getattr(obj, "_bark_field", "")

    def __setitem__(self, key, value) -> None:
        if not self.flags.writeable:
            raise StateWriteError(_refusal(self._bark_field))
        super().__setitem__(key, value)

    def __array_ufunc__(self, ufunc, method, *inputs, out=None, **kwargs):
        if out is not None:
            for o in out:
                if isinstance(o, Field) and not o.flags.writeable:
                    raise StateWriteError(_refusal(o._bark_field))
            kwargs["out"] = tuple(o.view(np.ndarray) if isinstance(o, Field) else o for o in out)
        inputs = tuple(a.view(np.ndarray) if isinstance(a, Field) else a for a in inputs)
        return getattr(ufunc, method)(*inputs, **kwargs)

    def __array_wrap__(self, out, context=None, return_scalar=False):
        plain = out.view(np.ndarray)
        return plain[()] if return_scalar else plain


def _field(name: str, doc: str) -> property:
    """A field's active rows (a view): writable where the state is open to writes of it (the engine,
    a declared write), else a read-only :class:`Field`.  Assigning to the attribute writes into the
    rows where that is allowed (``state.x += dx`` in an integrator's ``step``)."""

    def get(self) -> np.ndarray:
        return self._public(name)

    def set_rows(self, value) -> None:
        if name not in self._open:
            raise StateWriteError(_refusal(name))
        self._view(name)[...] = value

    return property(get, set_rows, doc=doc)


PER = ("spring", "base")
RESERVED = ("tension", "length", "inv_fmax")
"""Names a declared field may not take: what a breaker's part reads of every spring besides the
state's fields (``bark.contract.parts.SPRING_INPUTS``)."""


def _field_name(instance, attribute, value) -> None:
    if not isinstance(value, str) or not value.isidentifier() or value.startswith("_"):
        raise BarkError(f"a declared field's name must be a Python identifier not starting with '_', not {value!r}")
    if value in BASE_FIELDS or value in SPRING_FIELDS or value in RESERVED:
        raise BarkError(f"a declared field may not be called {value!r}: the engine has a field of that name")


STARTS = {"base": ("t", "z"), "spring": ("t", "z", "rest", "offset")}
"""What a declared field's ``start`` may name, per spring or base: the arrays ``Made`` gives."""


def _start(instance, attribute, value) -> None:
    if value is None:
        return
    if isinstance(value, str):
        if value not in STARTS[instance.per]:
            raise BarkError(f"declared field {instance.name!r}: start={value!r} is not known of a new {instance.per}; "
                            f"give a number or one of {', '.join(STARTS[instance.per])}")
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise BarkError(f"declared field {instance.name!r}: start={value!r} is neither a finite number nor a name "
                        f"({', '.join(STARTS[instance.per])})")


@attrs.frozen(kw_only=True)
class Declared:
    """A per-spring or per-base quantity a strategy owns (after LAMMPS's per-atom fields and OpenMM's
    per-bond parameters): the state carries it beside its own fields — grown, copied, snapshot,
    checkpointed and restored with them, by both backends — and each new spring's or base's value
    is its ``start`` or what the strategy that declares it makes (``Strategy.initial``).  Read-only
    outside its declared writes, as every field is.  Values are float64.

    >>> Declared(name="arm", per="spring", unit="length", start="rest").start   # begins at the rest length
    'rest'
    >>> Declared(name="arm", per="base", start="rest")
    Traceback (most recent call last):
    bark.errors.BarkError: declared field 'arm': start='rest' is not known of a new base; give a number or one of t, z
    """

    name: str = attrs.field(validator=_field_name)
    """How it is read: ``state[name]``, and by name in a part's ``reads``."""
    per: str = attrs.field(validator=one_of(*PER))
    """``spring``: one value per spring; ``base``: one per leaf base."""
    unit: str = attrs.field(default="", validator=attrs.validators.instance_of(str))
    """Its unit, in the model's (``force``, ``length``, ``time``, ``1`` for a number)."""
    doc: str = attrs.field(default="", validator=attrs.validators.instance_of(str))
    """What it is, in a line."""
    start: float | str | None = attrs.field(default=None, validator=_start, kw_only=True)
    """Each new spring's or base's first value when its strategy does not make it itself
    (``Strategy.initial``): a number (every new one the same), or the name of what is known of each
    one being made (``bark.contract.strategies.Made``: ``t``, ``z``; for springs also ``rest`` and
    ``offset``).  ``None``: the strategy's ``initial`` makes it."""


@attrs.define(eq=False)
class State:
    """Positions, velocities and springs of the leaf-base layer at time ``t``.

    ``x``, ``v``, ``anchor``, ``anchor_dir``, ``born`` (per base) and ``pairs``, ``rest``, ``fmax``,
    ``intact`` (per spring) are views of the active rows, **read-only outside the engine and the
    writes declared to it**: the engine writes what its step computes; a strategy's Python verb may
    write the fields its kind declares (``Strategy.writes``: an integrator's ``step`` writes ``x``
    and ``v``, a breaker's ``select`` nothing); a script or a test opens a field with
    :meth:`writing`.  Any other write raises :class:`~bark.errors.StateWriteError` at once, so no
    backend's copy of a field (the numba frame keeps the rest lengths and thresholds in its own
    order) can go stale unseen: every declared write is counted (:attr:`version`, :meth:`edited`)
    and the copies key on that count.  ``pairs`` never changes (springs are only appended) and
    ``intact`` only through :meth:`set_intact`.
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
    mends: int = 0
    """How many of those edits made springs intact again (``Simulation.mend_springs``: tools, and
    models that heal); a count of patches can bound the next one by the breaks since only while
    this stays the same (``Simulation.patches_at_most``)."""
    version: int = 0
    """The state's one edit counter: every edit made outside the hot loop (a declared write, a
    change of the intact flags) takes the next number, and each field keeps the number of its last
    edit (:meth:`edited`).  Every cache of a field (a backend's copy of the rest lengths, the patch
    labels) keys on it; appending bases and springs is not an edit (caches extend themselves)."""
    _store: dict[str, np.ndarray] = attrs.field(factory=dict, repr=False)
    _stamps: dict[str, int] = attrs.field(factory=dict, repr=False)
    _open: frozenset = attrs.field(default=frozenset(), repr=False)
    _declared: dict[str, Declared] = attrs.field(factory=dict, repr=False)
    _of: dict[str, dict] = attrs.field(factory=lambda: {"base": dict(BASE_FIELDS), "spring": dict(SPRING_FIELDS)},
                                       repr=False)

    @classmethod
    def empty(cls, bases: int = MIN_CAPACITY, springs: int = MIN_CAPACITY, declared=()) -> "State":
        """A state with no bases or springs yet, with room for ``bases`` and ``springs``, and the
        fields ``declared`` (:class:`Declared`) beside its own."""
        state = cls()
        state._store = {name: _alloc(max(bases, 1), shape, dt) for name, (shape, dt) in BASE_FIELDS.items()}
        state._store.update({name: _alloc(max(springs, 1), shape, dt) for name, (shape, dt) in SPRING_FIELDS.items()})
        state.declare(declared)
        return state

    def declare(self, fields) -> None:
        """Carry the fields ``fields`` (:class:`Declared`) from now on.  Only before the state has
        rows of their kind (a simulation declares its strategies' fields when it lays out its
        lattice), and each name once."""
        for spec in fields:
            if spec.name in self._store:
                raise BarkError(f"two declarations of the field {spec.name!r}: each field has one owner")
            if (self.n_springs if spec.per == "spring" else self.n_bases) > 0:
                raise BarkError(f"the field {spec.name!r} is declared after {spec.per}s were made: declare it first")
            self._of[spec.per][spec.name] = ((), "float64")
            self._store[spec.name] = _alloc(self._store["pairs" if spec.per == "spring" else "x"].shape[0], (), "float64")
            self._declared[spec.name] = spec

    @property
    def declared(self) -> tuple[Declared, ...]:
        """The fields declared beside the state's own, in the order declared."""
        return tuple(self._declared.values())

    def __getitem__(self, name: str) -> np.ndarray:
        """A field by name, the state's own or a declared one (read-only where the attribute is)."""
        if name not in self._store:
            raise KeyError(f"the state has no field {name!r}: it has {', '.join(self._store)}")
        return self._public(name)

    # -- the arrays ----------------------------------------------------------------------------

    def _view(self, name: str) -> np.ndarray:
        n = self.n_bases if name in self._of["base"] else self.n_springs
        return self._store[name][:n]

    def _public(self, name: str) -> np.ndarray:
        rows = self._view(name)
        if name in self._open and name not in FIXED:
            return rows
        rows = rows.view(Field)
        rows._bark_field = name
        rows.flags.writeable = False
        return rows

    def _rows(self, name: str) -> np.ndarray:
        """A field's active rows as a plain array, for the engine's own work (the backends): writable
        but for ``intact``, which only :meth:`set_intact` changes.  Not for strategies or scripts."""
        rows = self._view(name)
        if name == "intact":
            rows.flags.writeable = False
        return rows

    @contextlib.contextmanager
    def writing(self, *names: str):
        """Open ``names`` to writes inside the block (``with state.writing("x"): state.x[3] += 1e-9``):
        a declared write, for scripts, tests and tools.  On leaving, each field is marked edited
        (:meth:`edited`), so that every backend's copy of it is made again.  Opening ``pairs`` or
        ``intact`` is refused.  Nested blocks open the union.  (The engine writes through its own
        rows, ``_rows``, and opens a strategy's declared fields around its Python verb: :meth:`only`.)"""
        unknown = [n for n in names if n not in self._store]
        fixed = [n for n in names if n in FIXED]
        if unknown or fixed:
            raise StateWriteError(_refusal(fixed[0]) if fixed else
                                  f"the state has no field {unknown[0]!r}: it has {', '.join(self._store)}")
        before = self._open
        self._open = before | frozenset(names)
        try:
            yield self
        finally:
            self._open = before
            self._stamp(names)

    @contextlib.contextmanager
    def only(self, names: tuple[str, ...]):
        """Inside the block exactly ``names`` are open to writes (a strategy's declared ones, around
        its Python verb), whatever was open outside; marked edited on leaving."""
        before = self._open
        self._open = frozenset(n for n in names if n not in FIXED)
        try:
            yield self
        finally:
            self._open = before
            self._stamp(names)

    def _stamp(self, names) -> None:
        if names:
            self.version += 1
            for name in names:
                self._stamps[name] = self.version

    def edited(self, *names: str) -> int:
        """The :attr:`version` of the last edit of any of ``names`` (0: never edited)."""
        return max((self._stamps.get(n, 0) for n in names), default=0)

    x = _field("x", "Positions of the bases, ``(n, 3)``.")
    v = _field("v", "Velocities of the bases, ``(n, 3)``.")
    anchor = _field("anchor", "Anchor points, ``(n, 3)``; a function of t alone.")
    anchor_dir = _field("anchor_dir", "Unit horizontal direction of each site, ``(n, 2)``.")
    born = _field("born", "Time each base joined, ``(n,)``.")
    pairs = _field("pairs", "Spring ends ``(i, j)``, ``(m, 2)``; row = spring id.")
    rest = _field("rest", "Rest length of every spring, ``(m,)``.")
    fmax = _field("fmax", "Breaking threshold of every spring, ``(m,)``.")
    intact = _field("intact", "Whether each spring is intact, ``(m,)`` bool (read-only: ``set_intact``).")

    @property
    def capacity(self) -> tuple[int, int]:
        """Rows allocated for bases and springs (``n_bases`` and ``n_springs`` of them in use)."""
        return self._store["x"].shape[0], self._store["pairs"].shape[0]

    def arrays(self) -> dict[str, np.ndarray]:
        """Every field's active rows, by name, the declared ones after the state's own (views,
        read-only where the fields are)."""
        return {name: self._public(name) for name in self._store}

    def set_intact(self, ids: np.ndarray, value: bool) -> None:
        """Mark springs ``ids`` intact (``value`` true) or broken: the one way the flags change, one
        edit (``intact_version``, on which the graph's table and every backend cache of the flags
        are keyed).  ``Simulation.break_springs`` and ``mend_springs`` call it."""
        self._store["intact"][np.asarray(ids, dtype=np.int64)] = bool(value)
        self.intact_version += 1
        self.mends += bool(value)
        self._stamp(("intact",))

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
        """Append bases with the given fields (every one of ``BASE_FIELDS`` and the declared
        per-base fields); returns their ids."""
        return self._append(self._of["base"], "n_bases", values)

    def add_springs(self, **values: np.ndarray) -> np.ndarray:
        """Append springs with the given fields (every one of ``SPRING_FIELDS`` and the declared
        per-spring fields); returns their ids."""
        return self._append(self._of["spring"], "n_springs", values)

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
    def from_arrays(cls, arrays: dict[str, np.ndarray], t: float = 0.0, h: float = 0.0, declared=()) -> "State":
        """A state holding copies of ``arrays`` (every field, the ``declared`` ones too), e.g. from a
        checkpoint."""
        n, m = len(arrays["x"]), len(arrays["pairs"])
        state = cls.empty(n, m, declared)
        state.add_bases(**{k: arrays[k] for k in state._of["base"]})
        state.add_springs(**{k: arrays[k] for k in state._of["spring"]})
        state.t, state.h = float(t), float(h)
        return state

    def copy(self) -> "State":
        """An independent copy: every field, declared ones included, its time and last step."""
        return State.from_arrays(self.arrays(), self.t, self.h, self.declared)

    def __getstate__(self) -> dict:
        """Pickles the active rows only (spare capacity is not data)."""
        return {"arrays": {k: np.array(v) for k, v in self.arrays().items()}, "t": self.t, "h": self.h,
                "declared": self.declared}

    def __setstate__(self, data: dict) -> None:
        restored = State.from_arrays(data["arrays"], data["t"], data["h"], data.get("declared", ()))
        for a in attrs.fields(State):
            object.__setattr__(self, a.name, getattr(restored, a.name))

    def is_finite(self) -> bool:
        """Whether every position and velocity is finite."""
        return bool(np.isfinite(self.x).all() and np.isfinite(self.v).all())
