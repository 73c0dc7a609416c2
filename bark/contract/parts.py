"""Compiled parts: what a strategy declares of its work, so that the engine can run it in its kernel.

A part is a value, not a hook: pure elementwise functions, the strategy's own numbers as a parameter
array, and the names of the fields the functions read (after OpenMM's custom forces, whose per-bond
and global parameters are declared, never guessed).  Every backend evaluates the same declaration:
the numpy backend on whole arrays, the numba backend inlined into its stepping kernel, per spring.
The engine knows no strategy by name; a third party's part is run exactly as a built-in one.

A breaker's part (:class:`BreakerPart`)
----------------------------------------
``rule(*reads, params) -> bool``
    whether an intact spring breaks now (``decides``), or is a candidate for the breaker's own
    ``select`` to judge in Python (``decides = False``: the kernel's call ends after the first step
    in which the rule picks a spring).
``load(*reads, params) -> float``, or ``None``
    how far a spring is from breaking, ``1`` at breaking: adaptive stepping halves the step where a
    spring's load would pass ``1 + overshoot_tol`` and doubles it back once every load is at most 1.
    ``None``: the breaker does not steer the step (a hazard-rate breaker, whose breaking does not
    depend on landing a step on a threshold).
``reads``, ``load_reads``
    the per-spring fields the rule and the load take, in order, from :data:`SPRING_INPUTS` and the
    per-spring fields the simulation's strategies declare (``Strategy.declares``: a breaker's own
    quenched thresholds, say) (the load's the rule's unless given); ``params`` (the breaker's numbers,
    a float array) always comes last.

An integrator's part (:class:`IntegratorPart`)
----------------------------------------------
``update(x, v, f, hm, h, params) -> (x, v)``
    one coordinate of one base advanced by a step ``h`` under its total force ``f`` (``hm = h/m``):
    Euler–Cromer is ``v ← v + f·hm; x ← x + v·h``.  The surface constraint, the breaking and the
    clock are the engine's.

A resin law's part (:class:`ResinPart`)
---------------------------------------
``tension(length, rest, k, *reads, params) -> t``
    a spring's tension (force units, positive when stretched) from its length and rest length, the
    layer's stiffness ``k`` and the declared per-spring fields it ``reads`` (the paper's spring:
    ``k (length − rest)``).  Its force on the two bases is along the spring.
``evolve(length, rest, h, *reads, params) -> (values, ...)``, or ``None``
    how the resin flows in a step ``h``: new values of the fields it ``writes`` (``rest``, or its own
    declared fields), in that order, as a tuple.  Inside a step: forces, velocities, positions,
    the surface, the tensions (judged by the breaker), then the flow of every spring intact then,
    then the next step's forces from the new values.
``stiffness``
    the largest tangent stiffness ``dt/dlength`` over ``k`` (at least 1): the stability bound of an
    explicit integrator is taken with ``k`` times it.

A growth law's part (:class:`GrowthPart`)
------------------------------------------
``radius(t, z, q) -> r``
    the trunk radius at time ``t`` and height ``z``; ``q`` is what ``time`` made of the law's
    ``params`` for this step (the params themselves by default).  ``uniform = True``: the radius is
    the same at every height, evaluated once per step (``z`` is then 0).
``time(t, params) -> q``
    what depends on time alone, once a step (a fading bulge's ``exp``), so that per base only what
    depends on height is left.
``weights(z, params) -> w``, optional
    for a radius ``q[0] + w_0(z)·q[1] + w_1(z)·q[2] + ...`` (summed left to right): one row of
    weights per term.  The anchors, whose heights never change, then have their weights taken once
    and their radii summed each step (checked against ``radius`` when first taken).
``radii(t, z, q, out)``, optional
    the radius at every height of the array ``z`` into ``out``, the same bits as ``radius`` at each
    — for a law that does a block of heights faster than one at a time (SIMD lanes).
``inner``, optional
    a uniform part this one is built on (a bulge law on any law that has a part): ``time`` is then
    called as ``time(t, params, inner_time, inner_radius)``, with the inner part's own functions to
    call on numbers the outer part keeps in its ``params`` (the inner law's, and variants of them).

Written with numpy operations (``np.sqrt``), one function serves arrays and scalars alike.  The
functions must be importable by name (module-level functions or static methods) for the numba
backend to cache their compiled kernel on disk; others are compiled once per process.
"""

from __future__ import annotations

from typing import Callable

import attrs
import numpy as np

from bark.model import physics
from bark.errors import BarkError

__all__ = ["BreakerPart", "GrowthPart", "IntegratorPart", "ResinPart", "SPRING_INPUTS", "NO_BREAKING", "HOOKEAN",
           "spring_inputs", "picks", "largest_load", "resin_tension", "resin_evolve", "how_it_runs"]

SPRING_INPUTS: tuple[str, ...] = ("tension", "length", "rest", "fmax", "inv_fmax")
"""What a breaker's part may read of each spring besides the per-spring fields declared by the
simulation's strategies (``Strategy.declares``, read by name): its tension ``k(|d| − l)`` (force
units), its length ``|d|`` and rest length ``l`` (length units; 1 = 0.3 m), its breaking threshold
``f_max`` (force units) and ``1 / f_max`` (kept per spring: a product is cheaper than a division in
the hot loop)."""


def _reads(value) -> tuple[str, ...]:
    reads = tuple(value)
    unknown = [r for r in reads if not isinstance(r, str) or not r.isidentifier() or r.startswith("_")]
    if unknown or len(set(reads)) != len(reads):
        raise BarkError(f"a breaker part reads {', '.join(map(repr, reads))}: each field once, from "
                        + ", ".join(SPRING_INPUTS) + " or a per-spring field its breaker declares")
    return reads


def _params(value) -> np.ndarray:
    params = np.ascontiguousarray(np.atleast_1d(np.asarray(value, dtype=float)) if np.size(value) else np.empty(0))
    if params.ndim != 1:
        raise BarkError(f"a part's params must be a flat list of numbers, not of shape {params.shape}")
    params.setflags(write=False)
    return params


class _ByKey:
    """Equality and hashing by ``key``: two parts are equal when they are the same work."""

    __slots__ = ()

    def __eq__(self, other) -> bool:
        return type(other) is type(self) and self.key == other.key

    def __hash__(self) -> int:
        return hash(self.key)


@attrs.frozen(kw_only=True, eq=False)
class BreakerPart(_ByKey):
    """A breaker's compiled work (see the module's docstring)."""

    rule: Callable = attrs.field(validator=attrs.validators.is_callable())
    """``rule(*reads, params) -> bool``: whether an intact spring breaks (or is a candidate)."""
    reads: tuple[str, ...] = attrs.field(default=("tension", "fmax"), converter=_reads)
    """The per-spring fields the functions take, in order (from :data:`SPRING_INPUTS`)."""
    params: np.ndarray = attrs.field(factory=lambda: np.empty(0), converter=_params)
    """The breaker's own numbers, passed last to both functions."""
    load: Callable | None = attrs.field(default=None, validator=attrs.validators.optional(attrs.validators.is_callable()))
    """``load(*load_reads, params) -> float``, 1 at breaking; ``None``: the breaker does not steer the step."""
    load_reads: tuple[str, ...] = attrs.field(default=attrs.Factory(lambda self: self.reads, takes_self=True),
                                              converter=_reads)
    """The per-spring fields the load takes, in order (default: ``reads``)."""
    decides: bool = attrs.field(default=True, validator=attrs.validators.instance_of(bool))
    """``True``: what the rule picks breaks, inside the kernel.  ``False``: the rule names candidates,
    and the breaker's ``select`` decides in Python after a step in which it names one."""

    @property
    def key(self) -> tuple:
        """What makes two parts the same work (their functions, fields and numbers)."""
        return (self.rule, self.load, self.reads, self.load_reads, self.params.tobytes(), self.decides)


def _inner(instance, attribute, value) -> None:
    if value is not None and (not isinstance(value, GrowthPart) or not value.uniform or value.inner is not None):
        raise BarkError("a growth part's inner part must be a uniform GrowthPart with no inner part of its own")


_callable = attrs.validators.is_callable()
_optional_callable = attrs.validators.optional(_callable)


@attrs.frozen(kw_only=True, eq=False)
class GrowthPart(_ByKey):
    """A growth law's compiled work (see the module's docstring)."""

    radius: Callable = attrs.field(validator=_callable)
    """``radius(t, z, q) -> r``."""
    params: np.ndarray = attrs.field(factory=lambda: np.empty(0), converter=_params)
    """The law's own numbers, which ``time`` turns into each step's ``q``."""
    uniform: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    """The same radius at every height (evaluated once per step, not per base)."""
    time: Callable = attrs.field(default=physics.as_given, validator=_callable)
    """``time(t, params) -> q`` (with ``inner``: ``time(t, params, inner_time, inner_radius)``)."""
    weights: Callable | None = attrs.field(default=None, validator=_optional_callable)
    """``weights(z, params) -> w``, shape ``(K, len(z))``: ``radius`` is ``q[0] + w[0]·q[1] + ...``."""
    radii: Callable | None = attrs.field(default=None, validator=_optional_callable)
    """``radii(t, z, q, out)``: ``radius`` at a block of heights at once, the same bits."""
    inner: "GrowthPart | None" = attrs.field(default=None, validator=_inner)
    """The uniform part this one is built on, whose functions ``time`` is given."""

    def at(self, t: float):
        """``q`` at time ``t``: what ``radius`` is given for this step."""
        if self.inner is None:
            return self.time(t, self.params)
        return self.time(t, self.params, self.inner.time, self.inner.radius)

    def radius_at(self, t: float, z):
        """The radius at time ``t`` and heights ``z``, as every backend evaluates it (one value when uniform)."""
        return self.radius(t, 0.0 if self.uniform else z, self.at(t))

    @property
    def functions(self) -> tuple[Callable, ...]:
        """Every function of the part and of its inner part (what the compiled kernel inlines)."""
        own = tuple(fn for fn in (self.radius, self.time, self.weights, self.radii) if fn is not None)
        return own + (self.inner.functions if self.inner is not None else ())

    @property
    def key(self) -> tuple:
        """What makes two parts the same work (their functions, numbers and inner part)."""
        return (self.radius, self.time, self.weights, self.radii, self.uniform, self.params.tobytes(),
                None if self.inner is None else self.inner.key)


@attrs.frozen(kw_only=True, eq=False)
class IntegratorPart(_ByKey):
    """An integrator's compiled work (see the module's docstring)."""

    update: Callable = attrs.field(validator=_callable)
    """``update(x, v, f, hm, h, params) -> (x, v)`` along one coordinate of one base."""
    params: np.ndarray = attrs.field(factory=lambda: np.empty(0), converter=_params)
    """The integrator's own numbers, passed last."""

    @property
    def key(self) -> tuple:
        """What makes two parts the same work (the function and the numbers)."""
        return (self.update, self.params.tobytes())


def _fields(value) -> tuple[str, ...]:
    names = tuple(value)
    if any(not isinstance(n, str) or not n.isidentifier() or n.startswith("_") for n in names) \
            or len(set(names)) != len(names):
        raise BarkError(f"a resin part's fields {', '.join(map(repr, names))}: each once, a field's name")
    return names


def _stiffness(instance, attribute, value) -> None:
    if not (isinstance(value, (int, float)) and 1.0 <= value < float("inf")):
        raise BarkError(f"a resin part's stiffness must be a finite number of at least 1, not {value!r}")


@attrs.frozen(kw_only=True, eq=False)
class ResinPart(_ByKey):
    """A resin law's compiled work (see the module's docstring)."""

    tension: Callable = attrs.field(validator=_callable)
    """``tension(length, rest, k, *reads, params) -> t``."""
    reads: tuple[str, ...] = attrs.field(default=(), converter=_fields)
    """The declared per-spring fields both functions take after ``rest``, in order."""
    evolve: Callable | None = attrs.field(default=None, validator=_optional_callable)
    """``evolve(length, rest, h, *reads, params) -> tuple`` of new values of ``writes``; ``None``: no flow."""
    writes: tuple[str, ...] = attrs.field(default=(), converter=_fields)
    """What ``evolve`` gives, in order: ``rest`` and the resin's own declared fields."""
    params: np.ndarray = attrs.field(factory=lambda: np.empty(0), converter=_params)
    """The law's own numbers, passed last."""
    stiffness: float = attrs.field(default=1.0, converter=float, validator=_stiffness)
    """The largest tangent stiffness over ``k``, for the stability bound."""

    def __attrs_post_init__(self) -> None:
        if (self.evolve is None) != (not self.writes):
            raise BarkError("a resin part that flows gives both evolve and the fields it writes; one that does not, neither")

    @property
    def evolves(self) -> bool:
        """Whether it flows (writes fields every step)."""
        return self.evolve is not None

    @property
    def key(self) -> tuple:
        """What makes two parts the same work."""
        return (self.tension, self.evolve, self.reads, self.writes, self.params.tobytes(), self.stiffness)


HOOKEAN = ResinPart(tension=physics.hookean)
"""The paper's spring (eq. 1), a resin law's part: a simulation without a resin law has this one."""


def _resin_args(part: ResinPart, state) -> list:
    return [state._rows(name) for name in part.reads]


def resin_tension(part: ResinPart, state, length: np.ndarray, k: float) -> np.ndarray:
    """Every spring's tension at ``length`` by the resin law ``part`` (on whole arrays: the kernel's bits)."""
    return part.tension(length, state._rows("rest"), k, *_resin_args(part, state), part.params)


def resin_evolve(part: ResinPart, state, length: np.ndarray, h: float, which: np.ndarray) -> None:
    """The resin flows for a step ``h`` at ``length``: the fields ``part`` writes, of the springs
    ``which`` (a mask), take their new values (on whole arrays: the kernel's bits).  The engine's."""
    new = part.evolve(length, state._rows("rest"), h, *_resin_args(part, state), part.params)
    for name, value in zip(part.writes, new):
        rows = state._rows(name)
        rows[which] = np.broadcast_to(value, rows.shape)[which]
    state._stamp(part.writes)  # an edit every cache of these fields must see


NO_BREAKING = BreakerPart(rule=physics.no_breaking, reads=("tension",))
"""The part of a layer without fracture: nothing breaks, nothing steers the step."""


def _fields_of(state, reads: tuple[str, ...]) -> dict:
    """The state's per-spring fields ``reads`` names, as plain read-only views (a part reads them, as
    in the kernel), ``inv_fmax`` made from ``fmax``; ``tension`` and ``length`` are given per step."""
    out = {}
    for name in reads:
        if name in ("tension", "length") or name in out:  # a name the rule and the load both read: made once
            continue
        rows = state._rows("fmax" if name == "inv_fmax" else name).view()
        rows.flags.writeable = False
        out[name] = 1.0 / rows if name == "inv_fmax" else rows
    return out


def _inputs(fields: dict, reads: tuple[str, ...], tension: np.ndarray, length, state) -> list:
    if "length" in reads and length is None:  # measured from the positions, as the kernels do
        from bark.model.forces import spring_geometry

        length = spring_geometry(state._rows("x"), state._rows("pairs"))[1]
    return [tension if name == "tension" else length if name == "length" else fields[name] for name in reads]


def spring_inputs(state, tension: np.ndarray, reads: tuple[str, ...], length: np.ndarray | None = None) -> list:
    """The per-spring arrays ``reads`` names, for ``state`` with ``tension`` (every spring's); the
    length is measured from the positions when not given (``bark.model.physics.length``, as the kernels)."""
    return _inputs(_fields_of(state, reads), reads, tension, length, state)


class Judge:
    """A breaker part bound to a state for the steps of one call: the fields its rule and load read
    taken from the state once (inside a call a field changes only in place, and ``fmax`` not at
    all), then :meth:`picks` and :meth:`largest_load` per step."""

    def __init__(self, part: BreakerPart, state) -> None:
        self.part, self.state = part, state
        self.fields = _fields_of(state, part.reads + (part.load_reads if part.load is not None else ()))

    def picks(self, tension: np.ndarray, live: np.ndarray, length: np.ndarray | None = None) -> np.ndarray:
        """Ids of the ``live`` springs the part's rule picks, given every spring's ``tension`` (and length)."""
        part = self.part
        return np.flatnonzero(live & part.rule(*_inputs(self.fields, part.reads, tension, length, self.state),
                                               part.params))

    def largest_load(self, tension: np.ndarray, live: np.ndarray, length: np.ndarray | None = None) -> float:
        """The largest load of the ``live`` springs (``-inf`` if none, or if the part has no load; NaN
        if a load is NaN)."""
        part = self.part
        if part.load is None or not live.any():
            return -np.inf
        # every spring's load, the dead ones' put below any: the same largest number as gathering the
        # live springs first (a maximum is exact; a live NaN stays NaN), without the gather's copies
        load = part.load(*_inputs(self.fields, part.load_reads, tension, length, self.state), part.params)
        return float(np.max(np.where(live, load, -np.inf)))


def picks(part: BreakerPart, state, tension: np.ndarray, live: np.ndarray, length: np.ndarray | None = None) -> np.ndarray:
    """Ids of the ``live`` springs the part's rule picks, given every spring's ``tension`` (and length)."""
    return Judge(part, state).picks(tension, live, length)


def largest_load(part: BreakerPart, state, tension: np.ndarray, live: np.ndarray,
                 length: np.ndarray | None = None) -> float:
    """The largest load of the ``live`` springs (``-inf`` if none, or if the part has no load; NaN
    if a load is NaN)."""
    return Judge(part, state).largest_load(tension, live, length)


def how_it_runs(strategy) -> str:
    """Where a strategy's work runs, in words (``bark strategies``): ``compiled`` inside the stepping
    kernel, or in Python, and what of it."""
    kind = getattr(strategy, "kind", "")
    if kind == "breaker":
        part = strategy.part_
        if part is None:
            return "Python (select after every step)"
        return "compiled" if part.decides else "compiled candidates; select in Python"
    if kind == "growth":
        return "compiled" if strategy.part_ is not None else "Python (radius, one step a call)"
    if kind == "integrator":
        return "compiled" if strategy.part_ is not None else "Python (step, one step a call)"
    if kind == "resin":
        return "compiled" if strategy.part_ is not None else "cannot run (no part)"
    return "Python (after the run)"
