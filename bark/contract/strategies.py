"""The five kinds of strategy a :class:`~bark.engine.simulation.Simulation` is composed of.

Each kind is a small attrs class with **one verb**, its work in the step (or, for an analyzer, after
it).  To write your own, subclass the base, decorate it with ``@attrs.frozen(kw_only=True)``,
declare every parameter as a validated field (no logic in ``__init__``), implement the verb or
declare its part, and register the class under the kind's entry-point group (``bark.growth``,
``bark.integrator``, ``bark.breaker``, ``bark.resin``, ``bark.analyzer``).  The built-in strategies
in ``bark_plugins`` are registered the same way.  What a strategy draws or computes per spring or
per base is a field it declares (``declares``, its first values from ``initial``), never an
attribute of its own: its parameters are its constructor's keywords (``check_recordable``).

=============  ======================================  =================================================
kind           verb                                    contract
=============  ======================================  =================================================
Growth         ``radius(t, z) -> r``                   trunk radius at time ``t`` for heights ``z`` (an
                                                       array, or a scalar that broadcasts).  Pure.
Integrator     ``step(state, dt, forces) -> None``     advance ``state.x`` and ``state.v`` by ``dt`` in
                                                       place, with ``forces`` (a ``ForceField``).
                                                       Touches nothing else (its ``writes``): the
                                                       simulation advances ``t``, applies the surface
                                                       constraint and breaks springs.  Explicit methods
                                                       also give ``stability_limit(state, forces)``,
                                                       unconditionally stable ones
                                                       ``accuracy_limit(state, forces)``.
Breaker        ``select(state, tension, rng)``         ids (int array) of *intact* springs to break now.
               ``-> ids``                              Changes nothing but its own declared fields;
                                                       draws from ``rng`` only.
Resin          ``tension(length, rest, k, *fields)``   a spring's tension; its part (required: it runs
               ``-> t``                                in the kernel) may make the resin flow each step.
Analyzer       ``analyze(points, patches)``            statistics of a pattern, as an :class:`Analysis`
               ``-> Analysis``                         (``reads_springs``: also given the springs).
=============  ======================================  =================================================

**Compiled work: what a strategy declares.**  A strategy whose work fits a pure,
elementwise function may declare it; the engine then runs it inside its stepping kernel (compiled
and inlined by the numba backend, on whole arrays by the numpy backend) instead of calling the
strategy in Python once per step.  The function is the definition: the verb is derived from it.

* ``Integrator.part() -> IntegratorPart``: its update of one coordinate of one base,
  ``update(x, v, f, hm, h, params) -> (x, v)`` with ``hm = h/m`` (Euler–Cromer: ``v ← v + f·hm;
  x ← x + v·h``), and its numbers.  ``step`` then follows from it.
* ``Breaker.part() -> BreakerPart``: its rule, its own load (how far a spring is from breaking,
  which adaptive stepping holds to its tolerance), the per-spring fields they read and the
  breaker's numbers (:mod:`bark.contract.parts`).  ``select`` then follows from it.  A subclass that writes
  ``select`` again and not ``part`` has no part: a compiled rule and a Python ``select`` can never
  disagree.
* ``Growth.part() -> GrowthPart``: its radius as a function of time, height and the law's numbers,
  what of it depends on time alone (once a step), and optionally the weights of a radius that is a
  weighted sum and a block form (:mod:`bark.contract.parts`).  ``radius`` then follows from it; a
  subclass that writes ``radius`` again and not ``part`` has no part.

The functions must be importable by name (module-level functions or static methods) to be cached
on disk; others are compiled once per process.  Written with numpy ufuncs (``np.sqrt``), one
function serves arrays and scalars alike.
"""

from __future__ import annotations

import abc
import functools
from typing import Any, ClassVar

import attrs
import numpy as np

from bark.contract.parts import BreakerPart, GrowthPart, IntegratorPart, ResinPart, picks
from bark.errors import BarkError
from bark.model.effects import Effect
from bark.model.state import Declared

__all__ = ["Strategy", "Growth", "Integrator", "Breaker", "Resin", "Analyzer", "Analysis", "Springs", "KINDS", "pattern_of",
           "check_recordable", "Declared", "Made"]


@attrs.frozen(kw_only=True)
class Strategy(abc.ABC):
    """Common base: parameters are attrs fields, so ``attrs.evolve(s, G=0.01)`` makes a variant.

    A part is the definition only for the verb it came with: a subclass that writes the verb again
    (``select``, ``step``, ``radius``) and not ``part`` loses the inherited part, so the engine never
    runs work its Python verb no longer follows (its ``super()`` verb still means the parent's part)."""

    kind: ClassVar[str] = ""
    provides: ClassVar[tuple[Effect, ...]] = ()
    """Effects this strategy simulates beyond the model's own (``bark.model.effects.EFFECTS``): a
    scene that chooses it gets them unless its ``want`` list leaves them out, and then runs
    ``without(name)`` in its place (what a scene does not ask for is never built)."""

    verb: ClassVar[str] = ""
    """The verb a part defines (``radius``, ``step``, ``select``): a class that writes it again and
    not ``part`` has no part."""

    writes: ClassVar[tuple[str, ...]] = ()
    """The state's fields its Python verb may write (``bark.model.state.State``), besides the fields
    it declares (``declares``): the engine opens exactly these around the call, and any other write
    fails at once (:class:`~bark.errors.StateWriteError`).  An integrator writes ``x`` and ``v``;
    the other kinds nothing of the state's own."""

    moved_in: ClassVar[dict[tuple[str, str], tuple[str, Any]]] = {}
    """Settings of earlier versions that lived in one of a scene's own tables (``lattice``,
    ``mechanics``, ``run``, ``dome``, ``leaves``) and are this strategy's now: ``{(table, key): (its
    key here, the value that meant "not used")}``, e.g. ``{("mechanics", "fmax_spread"): ("spread",
    0.0)}`` (checked when the class is defined).  A scene that gives one is refused in one line
    naming the new key; one that gives the unused value (as an earlier run's scene.toml records it)
    is read as it meant.  The scene asks the installed strategies only when a table holds a key it
    does not know."""

    declares: ClassVar[tuple[Declared, ...]] = ()
    """Per-spring and per-base fields this strategy owns (``bark.model.state.Declared``: name, per
    spring or base, unit): the state carries them beside its own — grown, snapshot, checkpointed,
    restored, on both backends —, each new spring's or base's value is its ``start`` or what
    :meth:`initial` makes, a part reads them by name (a breaker's ``reads``), and its Python verb
    may write them."""

    def initial(self, made: "Made", rng: np.random.Generator) -> dict[str, np.ndarray]:
        """The first values of the fields this strategy declares for ``made.per`` (``spring`` or
        ``base``), one per spring or base being made (:class:`Made`: when, where, which lattice
        offset), drawn from ``rng`` (the simulation's one generator: the same seed gives the same
        values, and a resumed run goes on with the generator where it was).  By default each
        field's ``start`` (:class:`Declared`): a number, or what ``made`` knows of each by that name."""
        values = {}
        for field in (d for d in type(self).declares if d.per == made.per):
            if field.start is None:
                raise NotImplementedError(f"{type(self).__name__} declares {field.name!r} without a start: "
                                          "give it one (Declared(start=...)) or make its first values (initial)")
            start = getattr(made, field.start) if isinstance(field.start, str) else field.start
            values[field.name] = np.broadcast_to(np.asarray(start, dtype=np.float64), (len(made),))
        return values

    def writable(self) -> tuple[str, ...]:
        """What its Python verb may write: ``writes`` and the fields it declares."""
        return (*self.writes, *(d.name for d in self.declares))

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if cls.verb and cls.verb in vars(cls) and "part" not in vars(cls):
            cls.part = Strategy.part
        moved = vars(cls).get("moved_in", {})
        if not (isinstance(moved, dict) and all(
                isinstance(old, tuple) and len(old) == 2 and all(isinstance(k, str) for k in old)
                and isinstance(new, tuple) and len(new) == 2 and isinstance(new[0], str) for old, new in moved.items())):
            raise TypeError(f"{cls.__name__}.moved_in must map (table, key) to (its key, the unused value), "
                            f"e.g. {{('mechanics', 'fmax_spread'): ('spread', 0.0)}}: got {moved!r}")

    def part(self):
        """This strategy's compiled work (a :mod:`bark.contract.parts` value), or ``None``: its verb
        alone, in Python."""
        return None

    @functools.cached_property
    def part_(self):
        """``part()``, made once (a strategy's parameters never change; the engine asks at every call
        of its kernel)."""
        return self.part()

    def params(self) -> dict[str, Any]:
        """Constructor keywords of this strategy, as given: ``type(s)(**s.params())`` is ``s`` (for
        scene files, summaries, checkpoints and sweeps).  Only the constructor's fields: what a
        strategy computes is not a parameter (and is refused: :func:`check_recordable`)."""
        return {a.alias: getattr(self, a.name) for a in attrs.fields(type(self)) if a.init}

    def without(self, effect: str) -> "Strategy":
        """The strategy that does this one's work less its effect ``effect`` (one of ``provides``)."""
        raise NotImplementedError(f"{type(self).__name__} provides {effect!r} and must say what runs without it")


@attrs.frozen(kw_only=True)
class Made:
    """Springs or bases being made now (a simulation's lattice laid out, bases joining at the top):
    what the first value of a declared field may depend on (``Strategy.initial``)."""

    per: str
    """``spring`` or ``base``."""
    t: float
    """The time they are made (time units)."""
    ids: np.ndarray
    """Their ids (rows of the state)."""
    z: np.ndarray
    """Their heights: a base's site, a spring's midpoint (length units)."""
    offset: np.ndarray | None = None
    """Springs: each one's lattice index offset ``j − i`` (its parastichy); ``None`` for bases."""
    rest: np.ndarray | None = None
    """Springs: each one's rest length."""
    noise: np.ndarray | None = None
    """Springs: one standard normal number each, drawn for every spring made whatever the strategies
    (the built-in breakers' log-normal spread of thresholds uses it), so that which strategy draws
    what leaves the rest of the run's random stream alone.  ``None`` for bases."""
    regions: tuple[tuple[str, np.ndarray], ...] = ()
    """Springs: the trunk's regions of their own material at their midpoints, from the growth law
    (``Growth.regions_at``): a name and one weight in [0, 1] per spring each, in the order they blend."""

    def __len__(self) -> int:
        return len(self.ids)


_PLAIN = (bool, int, float, str, type(None))


def _unrecordable(value, path: str) -> tuple[str, Any] | None:
    """``(where, value)`` of the first part of ``value`` a scene file and a checkpoint cannot record
    (plain numbers, strings, booleans, None, lists and tables of them, attrs values of such fields),
    or ``None``."""
    if isinstance(value, _PLAIN):
        return None
    if isinstance(value, (list, tuple)):
        return next((bad for i, v in enumerate(value) if (bad := _unrecordable(v, f"{path}[{i}]"))), None)
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            return path, value
        return next((bad for k, v in value.items() if (bad := _unrecordable(v, f"{path}.{k}"))), None)
    if attrs.has(type(value)):
        hidden = [a.name for a in attrs.fields(type(value)) if not a.init]
        if hidden:
            return f"{path}.{hidden[0]}", getattr(value, hidden[0], None)
        return next((bad for a in attrs.fields(type(value))
                     if (bad := _unrecordable(getattr(value, a.name), f"{path}.{a.alias}"))), None)
    return path, value


def check_recordable(strategy: "Strategy", what: str | None = None) -> None:
    """Refuse, in one line, a strategy that a scene file and a checkpoint cannot record exactly: a
    field that is not a constructor keyword (``init=False``: what a strategy computes or draws is
    state, which it declares to the simulation, or a resumed run would not have it), or a parameter
    that is not plain data (numbers, strings, booleans, lists, tables).  Asked before a run starts,
    so that nothing is computed or written that could not be recorded."""
    what = what or f"{strategy.kind} {type(strategy).__name__}"
    hidden = [a.name for a in attrs.fields(type(strategy)) if not a.init]
    if hidden:
        raise BarkError(f"{what}: its field {hidden[0]!r} is not a constructor keyword (init=False), so no scene "
                        "file or checkpoint records it: keep only parameters on a strategy, and its state in the "
                        "simulation's state")
    for name, value in strategy.params().items():
        bad = _unrecordable(value, name)
        if bad is not None:
            where, found = bad
            raise BarkError(f"{what}: its parameter {where} holds a {type(found).__name__}, which no scene file or "
                            "checkpoint can record: give numbers, strings, booleans, lists or tables")


@attrs.frozen(kw_only=True)
class Growth(Strategy):
    """Secondary growth: how the trunk radius changes with time (and, for bulges, with height).

    A law declares its compiled work as a :class:`~bark.contract.parts.GrowthPart` (``part()``): its
    radius as a pure function of time, height and the law's numbers, and what of it depends on time
    alone.  ``radius`` is then derived from the part.  A class that writes ``radius`` and not
    ``part`` has no part: it runs on the Python path, one step a call."""

    kind: ClassVar[str] = "growth"
    verb: ClassVar[str] = "radius"

    def radius(self, t: float, z: np.ndarray) -> np.ndarray | float:
        """Trunk radius at time ``t`` at heights ``z`` (from the part: one value when it is uniform)."""
        part: GrowthPart | None = _declared_part(self)
        if part is None:
            raise NotImplementedError(f"{type(self).__name__} writes neither radius nor part")
        return part.radius_at(t, z)

    def mean_radius(self, t: float, z: np.ndarray) -> float:
        """The mean of ``radius(t, z)`` over the heights ``z`` (derived from ``radius``: a law that
        gives one radius for all heights counts it once for each)."""
        z = np.asarray(z, dtype=float)
        return float(np.mean(np.broadcast_to(self.radius(t, z), z.shape)))

    def on(self, lattice) -> "Growth":
        """This law on a trunk whose leaf bases follow ``lattice`` (``bark.model.lattice.Lattice``):
        a law with features placed relative to the top of the trunk as it grows (bulges made below
        the apical dome, every so often) places them here, at fixed heights and times, and returns
        the law that has them; the simulation asks it once, before it runs.  The default is the law
        itself."""
        return self

    def regions_at(self, t: float, z: np.ndarray) -> list[tuple[str, np.ndarray]]:
        """The trunk's regions of their own material at time ``t`` at heights ``z``: one ``(name,
        weight)`` per feature, the weight 1 inside it, 0 outside, smooth between, in the order they
        blend (asked when springs are made, whose thresholds the breaker sets by region:
        ``Breaker.thresholds``).  None on a plain trunk (the default); a bulge is a ``bulge``."""
        return []

    def region(self, z: np.ndarray) -> np.ndarray:
        """The name of the region of the trunk at each height ``z``, for pattern statistics per region
        (summary.json ``regions``).  One region, ``trunk``, unless a law has regions of its own."""
        return np.full(np.shape(z), "trunk", dtype=object)


@attrs.frozen(kw_only=True)
class Integrator(Strategy):
    """Time integration of the equations of motion (eqs. 5–8).

    An integrator whose step is an update of each coordinate of each base declares it as an
    :class:`~bark.contract.parts.IntegratorPart` (``part()``); ``step`` is then derived from it.  A
    class that writes ``step`` and not ``part`` (an implicit method, solving a system) has no part:
    it runs on the Python path, one step a call."""

    kind: ClassVar[str] = "integrator"
    verb: ClassVar[str] = "step"
    writes: ClassVar[tuple[str, ...]] = ("x", "v")
    overdamped: ClassVar[bool] = False
    """Whether it integrates the massless limit ``b·dx/dt = F(x)`` rather than eq. 3 (masses, inertia):
    no stability limit from the masses; a work-precision study measures it against that model."""

    def step(self, state, dt: float, forces) -> None:
        """Advance ``state.x`` and ``state.v`` by ``dt`` in place (from the part: its update of every
        coordinate, on whole arrays)."""
        part: IntegratorPart | None = _declared_part(self)
        if part is None:
            raise NotImplementedError(f"{type(self).__name__} writes neither step nor part")
        f = forces.total(state)
        for axis in range(3):
            state.x[:, axis], state.v[:, axis] = part.update(state.x[:, axis], state.v[:, axis], f[:, axis],
                                                             dt / forces.mechanics.m, dt, part.params)

    def stability_limit(self, state, forces) -> float:
        """Largest ``dt`` for which this method is stable on ``state``; ``inf`` if unconditionally stable.

        The simulation refuses (or, with automatic stepping, sub-steps) a ``dt`` above it."""
        return float("inf")

    def accuracy_limit(self, state, forces) -> float:
        """Largest ``dt`` of a step nothing controls (``fixed`` and ``auto`` stepping) for this method
        on ``state``: the time scale a step must resolve where stability does not bound it; ``inf``
        where the stability limit is the only one.  Refused (``fixed``) or sub-stepped (``auto``)
        above it, as above the stability limit; ``adaptive`` stepping controls each breaking step's
        overshoot instead."""
        return float("inf")


def _declared_part(strategy):
    """The part of the nearest class of ``strategy`` that declares one: a subclass that wrote its verb
    again has no part of its own, but its ``super()`` verb still means the parent's part."""
    for klass in type(strategy).__mro__:
        declared = vars(klass).get("part")
        if declared is not None and declared is not Strategy.part:
            return declared(strategy)
    return None


@attrs.frozen(kw_only=True)
class Breaker(Strategy):
    """Which intact springs break now.

    A breaker declares its compiled work as a :class:`~bark.contract.parts.BreakerPart` (``part()``): its
    rule, its own load (what adaptive stepping holds to its tolerance), the fields they read and its
    numbers.  ``select`` is then derived from the part.  A class that writes ``select`` and not
    ``part`` has no part (a rule and a Python ``select`` can never disagree): it runs on the Python
    path, asked after every step, and does not steer the step."""

    kind: ClassVar[str] = "breaker"
    verb: ClassVar[str] = "select"

    def thresholds(self, made: Made, fmax: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The breaking thresholds (``state.fmax``, force units) of the springs ``made``, given them as
        the breakers before this one left them (the first is given the material's ``f_max``): what
        every breaker's load ``tension / fmax`` and adaptive stepping measure against.  Asked once per
        batch of springs made, never per step.  The default leaves them as they are; a breaker with a
        spread of thresholds or thresholds of its own by region gives them here."""
        return fmax

    def select(self, state, tension: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Ids of intact springs to break, given every spring's current ``tension`` (from the part:
        the live springs its rule picks)."""
        part: BreakerPart | None = _declared_part(self)
        if part is None:
            raise NotImplementedError(f"{type(self).__name__} writes neither select nor part")
        return picks(part, state, tension, state.intact)


@attrs.frozen(kw_only=True)
class Resin(Strategy):
    """The resin between two leaf bases: a spring's tension from its length, and how the resin flows
    (after LAMMPS's bond styles: the bond law a chosen style with its own coefficients and its own
    per-bond history).  A law declares its work as a :class:`~bark.contract.parts.ResinPart`
    (``part()``), which runs inside the stepping kernel on both backends: the tension is in the
    innermost loop, so a resin law has no Python path.  Its per-spring history (a Maxwell arm's rest
    length) is a field it declares (``declares``); it may write ``rest`` (a viscoelastic or plastic
    resin's rest length follows the length).  A simulation without one has the paper's spring."""

    kind: ClassVar[str] = "resin"
    verb: ClassVar[str] = "tension"

    def tension(self, length, rest, k: float, *fields) -> np.ndarray:
        """Tension of springs of ``length`` and ``rest`` length (and the fields the part reads), from the part."""
        part: ResinPart | None = _declared_part(self)
        if part is None:
            raise NotImplementedError(f"{type(self).__name__} gives no part: a resin law runs inside the kernel")
        return part.tension(length, rest, k, *fields, part.params)


@attrs.frozen(kw_only=True)
class Analysis:
    """What an analyzer returns: a flat summary, its patches if it measures them, named tables."""

    summary: dict[str, Any]
    """Flat statistics.  With ``patches``: the pattern's, ``n_patches`` and the keys of summary.json's
    pattern statistics (``mean_orientation_deg``, ``circular_sd_deg``, ...) among them."""
    patches: list[dict[str, Any]] | None = None
    """One row per patch measured (``patch``, ``size``, centroid, ``orientation_deg``, ``anisotropy``,
    ...), or ``None`` from an analyzer that does not measure patches.  A run's patches.csv, its
    pattern statistics and their regions come from the first analysis that has them."""
    tables: dict[str, list[dict[str, Any]]] = attrs.field(factory=dict)
    """Further tables of rows, by name: a run writes each as ``analysis-<analyzer>-<table>.csv``
    (the analyzer's recorded name, its characters outside letters, digits, ``.``, ``_`` and ``-``
    written ``-``), a column per key of the first row."""


@attrs.frozen(kw_only=True)
class Springs:
    """The springs of a simulated pattern, for an analyzer that reads them (``reads_springs``): which
    bases each joins, which are intact, and the lattice's index offsets (a spring's parastichy is
    its offset ``j − i``).  A photograph has none."""

    pairs: np.ndarray
    """``(m, 2)``: the two bases of each spring, ``i < j``."""
    intact: np.ndarray
    """``(m,)`` bool: whether each spring is intact (a broken one is a crack)."""
    offsets: tuple[int, ...]
    """The lattice's index offsets."""


def pattern_of(analyses) -> Analysis | None:
    """The first of ``analyses`` (``Simulation.analyze``'s values) that measured patches."""
    return next((a for a in analyses if a.patches is not None), None)


@attrs.frozen(kw_only=True)
class Analyzer(Strategy):
    """Statistics of a bark pattern.

    Works on points and patch labels alone, so the same analyzer serves simulated bark and bark
    digitised from photographs.  ``points`` are either 3-D positions on the trunk, shape ``(n, 3)``
    (each patch is then mapped to its tangent plane), or 2-D positions already in a plane
    ``(horizontal, vertical)``, shape ``(n, 2)``.  ``patches`` holds one integer label per point.
    """

    kind: ClassVar[str] = "analyzer"
    reads_springs: ClassVar[bool] = False
    """Whether ``analyze`` takes the springs too, as a third argument (:class:`Springs`, or ``None`` for
    a pattern without them: a photograph's)."""

    @abc.abstractmethod
    def analyze(self, points: np.ndarray, patches: np.ndarray) -> Analysis:
        """Statistics of the pattern given by ``points`` and their patch labels (an analyzer that
        ``reads_springs``: ``analyze(points, patches, springs)``)."""


KINDS: tuple[str, ...] = ("growth", "integrator", "breaker", "resin", "analyzer")
