"""The :class:`Simulation`: a growth law, an integrator, breakers and analyzers, composed.

The topology has one owner, the :class:`~bark.model.state.State` (springs and their intact flags,
each edit counted); the leaf-base graph (networkx: nodes are leaf bases, edges the *intact* springs)
is a read-only view of it, for every topology question outside the hot loop.  :meth:`Simulation.join`
(bases joining the mechanics), :meth:`Simulation.break_springs` and :meth:`Simulation.mend_springs`
are the only places topology changes.  Step control and the fast-path policy are
:mod:`bark.engine.stepping`'s; the compute backend is :mod:`bark.engine.kernels`'; the state is data.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, ClassVar, Iterator

import attrs
import numpy as np

from bark.engine import kernels, stepping
from bark.validators import MISSING, in_range, int_in, one_of, optional, positive, positive_int
from bark.model.components import count_patches
from bark.errors import BarkError, NonFiniteStateError, Ref
from bark.model.forces import ForceField, Mechanics, spring_geometry
from bark.model.lattice import Lattice
from bark.model.state import State, cylinder_points, grown
from bark.model.tree import Packing
from bark.units import headed
from bark.engine.stepping import Clock, Numerics
from bark.contract.parts import HOOKEAN, SPRING_INPUTS
from bark.contract.strategies import (Analysis, Analyzer, Breaker, Growth, Integrator, Made, Resin,
                                     check_recordable)

if TYPE_CHECKING:
    from bark.model.graph import LeafBaseGraph

__all__ = ["Simulation", "Stop", "BreakLog"]


@attrs.frozen(kw_only=True)
class Stop:
    """When a run ends: the first of these conditions to hold.  At least one is needed.  (The model
    has no natural end: after the first burst springs keep breaking as fragments move outward, so
    when to stop is part of a result, and summary.json records which condition ended the run.)"""

    until_time: float | None = attrs.field(default=None, validator=optional(positive))
    """Stop at this simulated time (time units; 1 = 88.5 days)."""
    until_radius: float | None = attrs.field(default=None, validator=optional(positive))
    """Stop when the mean trunk radius reaches this (length units; 1 = 0.3 m)."""
    until_patches: int | None = attrs.field(default=None, validator=optional(positive_int))
    """Stop when this many patches of ≥ min_patch_size bases exist (paper, Fig. 7A: 110)."""
    min_patch_size: int = attrs.field(default=7, validator=positive_int)
    """Smallest patch that counts, for the stop condition (the paper drops patches under 7 bases)."""

    def __attrs_post_init__(self) -> None:
        if self.until_time is None and self.until_radius is None and self.until_patches is None:
            raise BarkError("no stop condition: give {0}, {1} or {2}",
                            *(Ref("run", k, MISSING) for k in ("until_time", "until_radius", "until_patches")))

    def reason(self, sim: "Simulation") -> str | None:
        """Which condition holds now (``'time'``, ``'radius'``, ``'patches'``), or ``None``."""
        if self.until_time is not None and sim.state.t >= self.until_time - 1e-9 * sim.clock.h:
            return "time"
        if self.until_radius is not None and sim.radius >= self.until_radius:
            return "radius"
        if (self.until_patches is not None and sim.patches_at_most(self.min_patch_size) >= self.until_patches
                and sim.patch_count(self.min_patch_size) >= self.until_patches):
            return "patches"
        return None


@attrs.define(eq=False)
class BreakLog:
    """Every break: spring id, its end bases, the step and time it broke, and its tension then."""

    _chunks: list[tuple[np.ndarray, ...]] = attrs.field(factory=list)

    def record(self, ids: np.ndarray, pairs: np.ndarray, step, t, tension: np.ndarray) -> None:
        """Log springs ``ids``, broken at ``step`` and time ``t`` (each one value, or one per id)."""
        n = ids.size
        steps = np.broadcast_to(np.asarray(step, dtype=np.int64), n).copy()
        times = np.broadcast_to(np.asarray(t, dtype=float), n).copy()
        ends = pairs[ids].astype(np.int64)
        self._chunks.append((ids.astype(np.int64), ends[:, 0], ends[:, 1], steps, times, np.asarray(tension, float)))

    def __len__(self) -> int:
        return sum(c[0].size for c in self._chunks)

    COLUMNS: ClassVar[tuple[str, ...]] = ("spring", "i", "j", "step", "t", "tension")

    def arrays(self) -> dict[str, np.ndarray]:
        """Columns ``spring, i, j, step, t, tension`` in the order the breaks happened."""
        if not self._chunks:
            return {n: np.empty(0, dtype=float if n in ("t", "tension") else np.int64) for n in self.COLUMNS}
        return {n: np.concatenate([c[k] for c in self._chunks]) for k, n in enumerate(self.COLUMNS)}

    def to_pandas(self):
        """The log as a ``pandas.DataFrame``, a row per break, breaks.csv's columns: those of
        :meth:`arrays` with their units (``t_tu``, ``tension_fu``: ``bark.units.headed``; pandas is not
        a dependency of bark: install it to use this)."""
        from bark.units import data_frame

        return data_frame(self.arrays(), list(self.COLUMNS), headed(self.COLUMNS))

    @classmethod
    def of_arrays(cls, arrays: dict[str, np.ndarray]) -> "BreakLog":
        """The log whose ``arrays()`` are ``arrays``."""
        columns = tuple(np.asarray(arrays[n]) for n in cls.COLUMNS)
        return cls([columns] if columns[0].size else [])


@attrs.frozen
class Snapshot:
    """A run where it stands, as plain data: everything needed to go on from there exactly.

    ``arrays``: every field of the state (the topology too, so nothing is rebuilt from the scene) and
    the break log's columns as ``breaks_<column>``.  ``meta`` (JSON-able): the time and last step,
    the clock, the step count, the events, the random generator's state and the backend that ran.
    :meth:`Simulation.snapshot` makes one, :meth:`Simulation.restore` goes on from one; a checkpoint
    is a snapshot on disk (``bark.io.checkpoint``)."""

    arrays: dict[str, np.ndarray]
    meta: dict[str, Any]


@attrs.define(eq=False, kw_only=True)
class Simulation:
    """A trunk whose leaf-base layer grows and cracks.

    Build it from parts (every part is an attrs object; ``attrs.evolve`` makes variants for sweeps)::

        sim = Simulation(lattice=Lattice(), mechanics=Mechanics(), growth=SqrtGrowth(),
                         integrator=EulerCromer(), breakers=[ThresholdBreaker()],
                         numerics=Numerics(dt=0.01, stepping="fixed"), seed=1)
        sim.run(Stop(until_patches=110))

    Constructing does no work; the lattice is laid out by :meth:`build` (first use of ``state``).
    """

    lattice: Lattice = attrs.field(factory=Lattice)
    mechanics: Mechanics = attrs.field(factory=Mechanics)
    growth: Growth
    integrator: Integrator
    breakers: tuple[Breaker, ...] = attrs.field(converter=tuple)
    resin: Resin | None = None
    """The resin law of the springs (``None``: the paper's spring, eq. 1)."""
    analyzers: tuple[Analyzer, ...] = attrs.field(default=(), converter=tuple)
    numerics: Numerics = attrs.field(factory=Numerics)
    seed: int = attrs.field(default=0, validator=int_in(0, 2**63 - 1))
    """Seed of the simulation's one random generator (jitter, thresholds, stochastic breakers)."""
    degenerate_fraction: float = attrs.field(default=0.1, validator=in_range(0.0, 1.0, lo_open=True))
    """A step breaking more than this share of all springs is reported as degenerate: the lattice is too
    regular (on the exact lattice every spring of one offset reaches its threshold in the same step)."""
    on_degenerate: str = attrs.field(default="warn", validator=one_of("warn", "stop"))
    """warn: record the event and go on; stop: end the run there."""
    record_breaks: bool = True
    """Keep the break log; off when a scene does not ask for the ``break-log`` effect."""
    horizon: float | None = None
    """How long the run is expected to last (time units), if known: lets ``auto`` take the faster
    backend for it (``run`` sets it from the stop condition when it builds)."""

    rng: np.random.Generator = attrs.field(init=False, default=None)
    state: State = attrs.field(init=False)
    """The mechanical state (arrays and time).  This and the next four are made by :meth:`build`, on
    first use."""
    graph: LeafBaseGraph = attrs.field(init=False)
    packing: Packing = attrs.field(init=False)
    """Where and when the bases that join during the run join (``bark.model.tree.Packing``: Ridley's
    packing, from the lattice and the placed growth law)."""
    clock: Clock = attrs.field(init=False)
    backend: kernels.Backend = attrs.field(init=False)
    forces: ForceField = attrs.field(init=False)
    breaks: BreakLog = attrs.field(init=False, factory=BreakLog)
    actions: list = attrs.field(init=False, factory=list)
    """``(trigger, action)`` pairs: after each advance every action whose trigger fires is called."""
    events: list[dict] = attrs.field(init=False, factory=list)
    """Degenerate events, accepted overshoots: dicts with at least ``kind``, ``t``, ``step``."""
    stability_limit: float = attrs.field(init=False)
    step_count: int = attrs.field(init=False, default=0)
    stop_reason: str | None = attrs.field(init=False, default=None)
    _built: bool = attrs.field(init=False, default=False)
    _labels: tuple | None = attrs.field(init=False, default=None)
    _counted: tuple | None = attrs.field(init=False, default=None)
    _tension: np.ndarray = attrs.field(init=False, factory=lambda: np.empty(0))

    # -- building ---------------------------------------------------------------------------------

    def __getattr__(self, name: str):
        """The parts :meth:`build` makes (``state``, ``clock``, ``backend``, ``forces``), on first use;
        the leaf-base graph, a view of the state, when first asked for (networkx is imported then:
        a run that never asks does not pay for it)."""
        if name in _MADE_BY_BUILD and not object.__getattribute__(self, "_built"):
            self.build()
            return getattr(self, name)
        if name == "graph" and object.__getattribute__(self, "_built"):
            from bark.model.graph import LeafBaseGraph

            self.graph = LeafBaseGraph(lambda: self.state)
            return self.graph
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def build(self, state: State | None = None, clock: Clock | None = None) -> "Simulation":
        """Lay out the lattice (or take ``state`` and ``clock``, e.g. from a checkpoint), its graph a view
        of it, set the clock below the integrator's stability limit.  Does nothing once built."""
        if self._built:
            return self
        for strategy in self.strategies():
            check_recordable(strategy)  # what could not be recorded is refused before anything runs
        declared = self.declared()
        if self.rng is None:
            self.rng = np.random.default_rng(self.seed)
        self.growth = self.growth.on(self.lattice)  # features placed relative to the growing top
        self.packing = Packing.of(self.lattice, self.growth)
        kernel = kernels.KernelParts(self.integrator.part_, stepping.breaking_part(self.breakers), self.growth.part_,
                                     self.resin_part, tuple(d.name for d in declared if d.per == "spring"),
                                     self.numerics.threads, self.lattice.initial)
        self.backend = kernels.load(self.numerics.backend, stepping.expected_work(self), kernel)
        self.backend.resin = self.resin_part
        self.forces = ForceField(self.mechanics, self.backend)
        if state is None:
            self.state = State.empty(self.lattice.initial, self.lattice.n_springs * self.lattice.initial // self.lattice.n_bases,
                                     declared)
            self._built = True
            try:
                self.join(*self.lattice.sites(float(np.mean(np.broadcast_to(self.growth.radius(0.0, 0.0), 1))), self.rng))
            except BaseException:  # a strategy's first values refused: not built, nothing half made
                self._built, self.rng = False, None
                raise
        else:
            self.state, self._built = state, True
            self._tension = np.zeros(state.n_springs)
        self.stability_limit, h = stepping.stable_step(self)
        self.clock = clock or Clock(h=h, levels=self.numerics.max_halvings if self.numerics.stepping == "adaptive" else 0)
        return self

    def strategies(self) -> tuple:
        """Every strategy of the simulation: growth law, integrator, breakers, resin law, analyzers."""
        return (self.growth, self.integrator, *self.breakers, *(() if self.resin is None else (self.resin,)),
                *self.analyzers)

    @property
    def resin_part(self):
        """The resin law's part (``bark.contract.parts.ResinPart``): the paper's spring without one."""
        return HOOKEAN if self.resin is None else self.resin.part_

    def declared(self) -> tuple:
        """The fields the strategies declare (``Strategy.declares``), which the state carries beside its
        own; one owner each, and a part reads only the fields the state has."""
        owners: dict[str, Any] = {}
        specs = []
        for strategy in self.strategies():
            for spec in type(strategy).declares:
                if spec.name in owners:
                    raise BarkError(f"{type(owners[spec.name]).__name__} and {type(strategy).__name__} both declare the "
                                    f"field {spec.name!r}: a field has one owner")
                owners[spec.name] = strategy
                specs.append(spec)
        springs = {spec.name for spec in specs if spec.per == "spring"}
        for b in self.breakers:
            part = b.part_
            for name in () if part is None else (*part.reads, *part.load_reads):
                if name not in SPRING_INPUTS and name not in springs:
                    raise BarkError(f"{type(b).__name__}'s part reads {name!r}, which is neither one of "
                                    f"{', '.join(SPRING_INPUTS)} nor a per-spring field a strategy declares")
        if self.resin is not None:
            self._check_resin(springs)
        return tuple(specs)

    def _check_resin(self, springs: set) -> None:
        """A resin law has a part, reads and writes only what there is, and runs with an integrator
        whose step is compiled (the tension is the kernel's innermost work)."""
        name, part = type(self.resin).__name__, self.resin.part_
        if part is None:
            raise BarkError(f"the resin law {name} gives no part: a resin law runs inside the kernel (ResinPart)")
        for field in (*part.reads, *part.writes):
            if field != "rest" and field not in springs or field == "rest" and field in part.reads:
                raise BarkError(f"the resin law {name} names {field!r}: it reads per-spring fields declared by a "
                                "strategy, and writes those or rest")
        if part.key != HOOKEAN.key and self.integrator.part_ is None:
            raise BarkError(f"the resin law {name} needs an integrator with a compiled step: "
                            f"{type(self.integrator).__name__} takes the stiffness of the paper's spring")

    def snapshot(self) -> Snapshot:
        """The run where it stands (:class:`Snapshot`): a value, which the run going on leaves as it is.
        The declared fields are ``field_<name>`` among its arrays."""
        own = {d.name for d in self.state.declared}
        arrays = {**{(f"field_{k}" if k in own else k): np.array(v) for k, v in self.state.arrays().items()},
                  **{f"breaks_{k}": v for k, v in self.breaks.arrays().items()}}  # the log's arrays are made afresh
        meta = {"t": self.state.t, "h_last": self.state.h, "clock": attrs.asdict(self.clock), "step_count": self.step_count,
                "events": [dict(e) for e in self.events], "rng": self.rng.bit_generator.state, "backend": self.backend.name,
                "declared": {d.name: d.per for d in self.state.declared}}
        return Snapshot(arrays, meta)

    def restore(self, snapshot: Snapshot) -> "Simulation":
        """This simulation (not yet built, of the snapshot's scene) put where ``snapshot`` stands, to go
        on exactly as the run it was taken of would have.  A backend left to ``auto`` is the one the run
        had, where it is available here: auto's choice depends on the process and the time left, and
        the backends' transcendental functions (numpy's own, the C library's) may differ in the last bit."""
        if self._built:
            raise RuntimeError("restore() puts a snapshot into a simulation that has not been built or run")
        arrays, meta = snapshot.arrays, snapshot.meta
        self.rng = np.random.default_rng(self.seed)
        self.rng.bit_generator.state = meta["rng"]
        if self.numerics.backend == "auto" and meta.get("backend") in ("numpy", "numba") and kernels.available(meta["backend"]):
            self.numerics = attrs.evolve(self.numerics, backend=meta["backend"])
        declared = self.declared()
        held = meta.get("declared", {})
        if held != {d.name: d.per for d in declared}:
            raise BarkError(f"the snapshot holds the declared fields {sorted(held) or 'none'}, and this simulation's "
                            f"strategies declare {sorted(d.name for d in declared) or 'none'}: it is of another model")
        fields = {**arrays, **{d.name: arrays[f"field_{d.name}"] for d in declared}}
        self.build(State.from_arrays(fields, meta["t"], meta["h_last"], declared), Clock(**meta["clock"]))
        self.breaks = BreakLog.of_arrays({k: arrays[f"breaks_{k}"] for k in BreakLog.COLUMNS})
        self.step_count = int(meta["step_count"])
        self.events = list(meta["events"])
        return self

    # -- the loop ---------------------------------------------------------------------------------

    def run(self, stop: Stop, observe: Callable[["Simulation"], None] | None = None) -> str:
        """Run until ``stop`` holds; return why it stopped (``'time'``, ``'radius'``, ``'patches'``,
        ``'degenerate'``, or what ``observe`` set ``stop_reason`` to).  ``observe(sim)`` is called after
        every advance.  A step that makes the state NaN or infinite raises
        :class:`~bark.errors.NonFiniteStateError`, the simulation left at the last finite state.

        The loop, literally (``advance`` is one pass; a pass takes n steps in one call of the
        backend's kernel, n = 1 unless the fast path applies, see ``bark.engine.stepping.plan``)::

            while stop.reason(sim) is None:
                plan = stepping.plan(sim, stop)     # up to n steps from the clock, what may happen inside
                result = backend.steps(plan)        # each step: forces (eq. 4) -> velocities (eq. 7)
                                                    #   -> positions (eq. 8) -> surface r(t, z) (eq. 9,
                                                    #   radial velocity removed) -> tensions (the resin
                                                    #   law; eq. 1: k(|d| - l)) -> the breakers' part:
                                                    #   its rule, its load -> the resin's flow (springs
                                                    #   intact then) -> the next step's forces; if quiet
                                                    #   again (adaptive): double h, staying on its grid;
                                                    #   a refused step it takes back itself: halve h
                clock = result's ticks and halvings; t = clock.t   # integer ticks: exact time
                break_springs(what the rule broke)  # the intact flags (the graph sees them); logged
                if the last step went NaN or a load overshot (adaptive): it was undone; halve h and go on
                    (at the smallest step: NaN raises NonFiniteStateError, an overshoot is kept, recorded)
                if the breakers act in Python (no one part, or its rule named candidates):
                    break_springs(union of breaker.select(state, tension, rng))
                if a step broke more than degenerate_fraction of the springs: record a degenerate event
                join(the bases due by now)          # new bases and springs at rest
                call the actions whose triggers fire; observe(sim)

        Every spring its rule picks at the end of a step breaks in that step, all at once;
        compression never breaks a spring; a broken spring never comes back.
        """
        for _ in self.irun(stop):
            if observe is not None:
                observe(self)
        return self.stop_reason

    def prepare(self, stop: Stop) -> "Simulation":
        """Build for a run to ``stop`` (its time, if any, guides ``auto``'s backend) and refuse a stop
        time the clock cannot count."""
        if not self._built and self.horizon is None:
            self.horizon = stop.until_time
        stepping.check_countable(self.build(), stop)
        return self

    def irun(self, stop: Stop) -> Iterator["Simulation"]:
        """The loop of :meth:`run` as a generator that yields after every :meth:`advance` (and its actions)."""
        self.prepare(stop)
        self.stop_reason = None
        if self.numerics.stepping != "fixed" and not self.clock.ticks and stop.until_time is not None:
            self.clock.fit(stop.until_time)
        while (reason := stop.reason(self)) is None and self.stop_reason is None:
            self.advance(stop)
            for trigger, action in self.actions:
                if trigger.fires(self):
                    action(self)
            yield self
        self.stop_reason = self.stop_reason or reason

    def add_action(self, trigger, action: Callable[["Simulation"], None]) -> None:
        """Call ``action(sim)`` after every advance at which ``trigger`` fires (``bark.engine.triggers``); a
        call of the kernel ends where a trigger is next due, so actions see the exact step."""
        self.actions.append((trigger, action))

    def advance(self, stop: Stop | None = None, most: int | None = None) -> int:
        """One pass of the loop in :meth:`run` (of at most ``most`` steps); returns the steps taken."""
        self.build()
        plan = stepping.plan(self, stop, most)
        take = self.backend.steps if plan.compiled else (lambda *a: stepping.python_step(self, *a))
        result = take(self.state, self.mechanics, plan, self._tension)
        first_step, ends = self.step_count, result.ends
        if result.done:  # the clock as the call left it: it may have doubled the step
            last = int(ends[-1]) - (int(ends[-2]) if result.done > 1 else plan.ticks)
            self.clock.ticks, self.clock.halvings = int(ends[-1]), result.halvings
            self.state.h = last * self.clock.h_min
        else:
            self.state.h = plan.h
        self.step_count += result.done
        self.state.t = self.clock.t
        if result.broken.size:
            self.break_springs(result.broken, result.tension, step=first_step + result.step,
                               t=ends[result.step - 1] * self.clock.h_min, tension_of_ids=True)
            self._check_degenerate(np.count_nonzero(result.step == result.step[-1]))
        if result.refused:
            if self.clock.can_halve():
                self.clock.halve()  # the step was undone: take it again, smaller
                return result.done
            raise NonFiniteStateError(
                f"the state (or a breaker's load) became NaN or infinite at t = {self.clock.t + self.clock.step:.6g} "
                f"(step {self.step_count + 1}); the simulation holds the last finite state, t = {self.state.t:.6g}")
        if stepping.steers_step(self) and result.load > 1.0 + self.numerics.overshoot_tol:  # at the smallest step
            self.events.append({"kind": "overshoot", "t": self.state.t, "step": self.step_count, "load": result.load})
        if plan.breaks == "python" or plan.breaks == "candidates" and result.picked:
            self._break_selected()
        due = self.packing.bases_at(self.state.t) - self.state.n_bases
        if due > 0:  # primary growth has raised the dome past the next leaves: they join where they crossed
            top = float(np.broadcast_to(self.growth.radius(self.state.t, float(self.packing.top(self.state.t))), 1)[0])
            self.join(*self.packing.sites(top, self.rng, self.state.n_bases, due))
        return result.done

    def step(self) -> None:
        """One accepted step (adaptive stepping may first undo and halve it); for tests and tools."""
        while self.advance(None, most=1) == 0:
            pass

    def _break_selected(self) -> None:
        picks = []
        for b in self.breakers:
            with self.state.only(b.writable()):  # of the state, a breaker's select changes only its own fields
                picks.append(np.asarray(b.select(self.state, self._tension, self.rng), dtype=np.int64))
        if picks:
            ids = np.unique(np.concatenate(picks))
            ids = self.break_springs(ids[self.state.intact[ids]], self._tension)
            self._check_degenerate(ids.size)

    def _check_degenerate(self, n: int) -> None:
        """Record a degenerate event (and stop, if asked) when one step broke ``n`` springs, too many."""
        if n <= self.degenerate_fraction * self.state.n_springs:
            return
        self.events.append({"kind": "degenerate", "t": self.state.t, "step": self.step_count, "n_springs": int(n),
                            "fraction": n / self.state.n_springs})
        if self.on_degenerate == "stop":
            self.stop_reason = "degenerate"

    # -- the three places topology changes ------------------------------------------------------

    def join(self, theta: np.ndarray, z: np.ndarray) -> np.ndarray:
        """New bases join the mechanics now, at angles ``theta`` and heights ``z`` on the trunk surface,
        each anchored at its site.  Their ids continue the lattice's order; each is joined to the
        lattice neighbours (index offsets) already present — ids below the count of bases — by springs whose
        rest lengths are the distances now (a new spring is at rest) and whose thresholds the breakers
        set about the material's (``Breaker.thresholds``, told the growth law's regions).  Returns the ids."""
        s, t = self.state, self.state.t
        bases = self._new_bases(theta, z, t)
        made = Made(per="base", t=t, ids=np.arange(s.n_bases, s.n_bases + len(bases["born"])), z=bases["x"][:, 2])
        ids = s.add_bases(**bases, **self._initial(made))
        pairs = self.lattice.new_pairs(ids, range(s.n_bases))  # the bases present: ids 0 .. n − 1
        if len(pairs):  # their ends' positions gathered first (np.take of a few rows copies all of x)
            ends = s.x[pairs.ravel()]
            _, rest = spring_geometry(ends, np.arange(ends.shape[0]).reshape(-1, 2))
            mid = 0.5 * (ends[0::2, 2] + ends[1::2, 2])
            made = Made(per="spring", t=t, ids=np.arange(s.n_springs, s.n_springs + len(pairs)), z=mid,
                        offset=pairs[:, 1].astype(np.int64) - pairs[:, 0], rest=rest,
                        noise=self.rng.standard_normal(len(pairs)), regions=tuple(self.growth.regions_at(t, mid)))
            s.add_springs(pairs=pairs, rest=rest, fmax=self._thresholds(made), intact=np.ones(len(pairs), bool),
                          **self._initial(made))
        self._tension = _rows(self._tension, s.n_springs)
        return ids

    def _thresholds(self, made: Made) -> np.ndarray:
        """The thresholds of the springs ``made``: the material's ``f_max``, then each breaker's in turn
        (``Breaker.thresholds``), checked: one finite positive number per spring."""
        fmax = np.full(len(made), self.mechanics.f_max)
        for b in self.breakers:
            fmax = b.thresholds(made, fmax, self.rng)
            what = f"{type(b).__name__}.thresholds"
            try:
                fmax = np.array(np.broadcast_to(np.asarray(fmax, dtype=np.float64), (len(made),)))
            except (TypeError, ValueError) as err:
                raise BarkError(f"{what} did not give one number per spring ({err})") from None
            if not (np.isfinite(fmax).all() and (fmax > 0.0).all()):
                raise BarkError(f"{what} gave a threshold that is not a positive finite number "
                                f"({fmax[~(np.isfinite(fmax) & (fmax > 0.0))][0]!r}): a spring would break at rest or never")
        return fmax

    def _initial(self, made: Made) -> dict[str, np.ndarray]:
        """The first values of the declared fields of the springs or bases ``made``, each from the
        strategy that declares it (``Strategy.initial``, in the order of :meth:`strategies`), checked:
        one finite float each, and exactly the fields it declares."""
        values: dict[str, np.ndarray] = {}
        for strategy in self.strategies():
            names = [d.name for d in type(strategy).declares if d.per == made.per]
            if not names:
                continue
            given = strategy.initial(made, self.rng)
            what = f"{type(strategy).__name__}.initial"
            if not isinstance(given, dict) or sorted(given) != sorted(names):
                raise BarkError(f"{what} gave {sorted(given) if isinstance(given, dict) else type(given).__name__} "
                                f"for new {made.per}s: give exactly its declared fields {names}")
            for name in names:
                try:
                    value = np.array(np.broadcast_to(np.asarray(given[name], dtype=np.float64), (len(made),)))
                except (TypeError, ValueError) as err:
                    raise BarkError(f"{what}: {name!r} is not one number per {made.per} ({err})") from None
                if not np.isfinite(value).all():
                    raise BarkError(f"{what}: {name!r} holds NaN or infinite values")
                values[name] = value
        return values

    def _new_bases(self, theta, z, t: float) -> dict[str, np.ndarray]:
        """The fields of bases joining at time ``t`` at angles ``theta`` and heights ``z``: on the trunk
        surface there, at rest, each anchored at its site."""
        theta, z = np.atleast_1d(theta).astype(float), np.atleast_1d(z).astype(float)
        x = cylinder_points(theta, z, np.broadcast_to(self.growth.radius(t, z), z.shape))
        return {"x": x, "v": np.zeros_like(x), "anchor": x, "anchor_dir": np.column_stack([np.cos(theta), np.sin(theta)]),
                "born": np.full(len(z), t)}

    def whole_lattice(self) -> State:
        """The state of the whole lattice, every base laid out at t = 0 as :meth:`build` lays out the
        first ones (its own generator from the seed: the simulation's is not drawn), with its springs
        at rest: what a bound on a lattice that is still to grow is taken on.  Arrays only — no graph,
        and every threshold ``f_max`` (a bound needs neither)."""
        lattice = attrs.evolve(self.lattice, n_start=None, join_rate=0.0, organ_area=None, area_exponent=1.0)
        radius = float(np.mean(np.broadcast_to(self.growth.radius(0.0, 0.0), 1)))
        state = State.empty(lattice.n_bases, lattice.n_springs)
        state.add_bases(**self._new_bases(*lattice.sites(radius, np.random.default_rng(self.seed)), 0.0))
        pairs = lattice.pairs()
        _, rest = spring_geometry(state.x, pairs)
        state.add_springs(pairs=pairs, rest=rest, fmax=np.full(len(pairs), self.mechanics.f_max),
                          intact=np.ones(len(pairs), bool))
        return state

    def break_springs(self, ids, tension: np.ndarray | None = None, *, step=None, t=None,
                      tension_of_ids: bool = False) -> np.ndarray:
        """Break springs ``ids`` for good (their intact flags: the graph no longer has them), and log them.

        ``tension`` is every spring's tension (default: the current one), or with ``tension_of_ids``
        each given spring's; ``step`` and ``t`` say when they broke, one value or one per id (default:
        now).  Already-broken ids are ignored (an id given twice breaks at its first step).  Returns the
        ids actually broken, in the order logged: by step, then id."""
        s = self.state
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if ids.size and (ids.min() < 0 or ids.max() >= s.n_springs):
            raise IndexError(f"spring ids must be in [0, {s.n_springs}): got {ids.min() if ids.min() < 0 else ids.max()}")
        steps = np.broadcast_to(np.asarray(self.step_count if step is None else step, dtype=np.int64), ids.shape)
        times = np.broadcast_to(np.asarray(s.t if t is None else t, dtype=float), ids.shape)
        if ids.size > 1 and not _by_step_then_id(ids, steps):
            order = np.lexsort((ids, steps))
            order = order[np.sort(np.unique(ids[order], return_index=True)[1])]  # each id once, at its first step
        else:  # already in that order, each id once (what the kernel returns): nothing to sort
            order = np.arange(ids.size)
        order = order[s.intact[ids[order]]]
        if tension is None:
            tension = self.forces.tension(s)
        values = np.asarray(tension)[order] if tension_of_ids else np.asarray(tension)[ids[order]]
        ids = ids[order]
        if ids.size:
            s.set_intact(ids, False)
            if self.record_breaks:
                self.breaks.record(ids, s.pairs, steps[order], times[order], values)
        return ids

    def mend_springs(self, ids) -> np.ndarray:
        """Make the broken springs ``ids`` intact again (their flags, and so the graph's edges; the model
        never does: a broken spring stays broken; this is for tools, and for models of their own that
        heal).  Intact ids are ignored; returns the ids mended.  Their breaks stay in the break log."""
        s = self.state
        ids = np.unique(np.asarray(ids, dtype=np.int64).reshape(-1))
        if ids.size and (ids[0] < 0 or ids[-1] >= s.n_springs):
            raise IndexError(f"spring ids must be in [0, {s.n_springs}): got {ids[0] if ids[0] < 0 else ids[-1]}")
        ids = ids[~s.intact[ids]]
        if ids.size:
            s.set_intact(ids, True)
        return ids

    # -- observables ----------------------------------------------------------------------------

    @property
    def radius(self) -> float:
        """Mean trunk radius now (at the anchors' heights)."""
        return self.growth.mean_radius(self.state.t, self.state.anchor[:, 2])

    @property
    def n_broken(self) -> int:
        """How many springs are broken now."""
        return int(self.state.n_springs - np.count_nonzero(self.state.intact))

    def tension(self) -> np.ndarray:
        """Every spring's tension now (broken ones included; mask with ``state.intact``)."""
        return self.forces.tension(self.state)

    def patch_labels(self) -> np.ndarray:
        """Patch id of every base: connected components of the intact springs (the components of
        ``graph``, numbered by each one's smallest base), by the backend, cached until the topology changes."""
        s = self.state
        key = (id(s), s.n_bases, s.n_springs, s.intact_version)
        if self._labels is None or self._labels[0] != key:
            self._labels = (key, self.backend.patch_labels(s))
        return self._labels[1]

    def patch_count(self, min_size: int = 7) -> int:
        """Number of patches of at least ``min_size`` bases."""
        count = count_patches(self.patch_labels(), min_size)
        s = self.state
        self._counted = ((id(s), s.n_bases, s.n_springs, s.mends, min_size), self.n_broken, count)
        return count

    def patches_at_most(self, min_size: int = 7) -> int:
        """At least :meth:`patch_count` (``min_size``), without labelling the lattice where it can:
        the count when last taken plus the springs broken since — a broken spring splits at most one
        patch in two, so each break adds at most one patch of any least size — while no base or
        spring has joined and none has been mended; else the count itself."""
        s, counted = self.state, self._counted
        if counted is not None and counted[0] == (id(s), s.n_bases, s.n_springs, s.mends, min_size):
            return counted[2] + self.n_broken - counted[1]
        return self.patch_count(min_size)

    def analyze(self) -> dict[str, Analysis]:
        """Run every analyzer on the current pattern; results by the analyzer's recorded name (its
        entry-point name, or ``module:Class``).  An analyzer that reads springs gets them."""
        from bark.contract.registry import name_of
        from bark.contract.strategies import Springs

        labels, s = self.patch_labels(), self.state
        springs = Springs(pairs=s.pairs, intact=s.intact, offsets=tuple(self.lattice.offsets))
        return {name_of(a): (a.analyze(s.x, labels, springs) if a.reads_springs else a.analyze(s.x, labels))
                for a in self.analyzers}

    # -- pickling -------------------------------------------------------------------------------

    def __getstate__(self) -> dict:
        """A simulation pickles as its parts, its state and its records; the backend (work buffers)
        and the graph (a view of the state) are not data."""
        skip = {"graph", "backend", "forces", "packing", "_labels", "_counted", *(() if self._built else _MADE_BY_BUILD)}
        return {a.name: getattr(self, a.name) for a in attrs.fields(type(self)) if a.name not in skip}

    def __setstate__(self, data: dict) -> None:
        for a in attrs.fields(type(self)):
            if a.name in data:
                object.__setattr__(self, a.name, data[a.name])
        object.__setattr__(self, "_labels", None)
        object.__setattr__(self, "_counted", None)
        if data.get("_built"):
            object.__setattr__(self, "_built", False)
            self.build(data["state"], data["clock"])


def _by_step_then_id(ids: np.ndarray, steps: np.ndarray) -> bool:
    """Whether ``ids`` are ordered by step, then id, each id once (strictly increasing within a step;
    an id in two steps is told by the sort, not here)."""
    later = steps[1:] > steps[:-1]
    if not (later | (steps[1:] == steps[:-1])).all() or not (later | (ids[1:] > ids[:-1])).all():
        return False
    if not later.any():
        return True  # one step: ids strictly increasing are each there once
    return np.unique(ids).size == ids.size


def _rows(a: np.ndarray, n: int) -> np.ndarray:
    """The first ``n`` entries of ``a``'s buffer, grown (doubled, the new ones zero) when too short:
    an array that follows the number of springs without a copy at every join."""
    own = a.base is not None and a.base.ndim == 1 and a.base.ctypes.data == a.ctypes.data
    buffer = a.base if own else a
    if len(buffer) < n:
        buffer = np.zeros(grown(len(buffer), n))
        buffer[:len(a)] = a
    return buffer[:n]


_MADE_BY_BUILD = ("state", "graph", "packing", "clock", "backend", "forces", "stability_limit")
