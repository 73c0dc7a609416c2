"""The :class:`Simulation`: one growth law, one integrator, breakers and analyzers, composed.

The leaf-base graph (networkx) is the topology of record: nodes are leaf bases (with their initial
site ``theta0``, ``z0``), edges are *intact* springs (with their row number ``spring`` in the
arrays).  :class:`~bark.state.State` mirrors it as arrays for the hot loop, and
:meth:`Simulation.break_springs` is the only place where springs break — in both at once.
"""

from __future__ import annotations

import math
from typing import Callable, Iterator

import attrs
import networkx as nx
import numpy as np

from bark import kernels
from bark._validate import in_range, int_in, one_of, optional, positive, positive_int
from bark.errors import BarkError, NonFiniteStateError, Ref
from bark.forces import Mechanics, spring_geometry
from bark.lattice import Lattice
from bark.state import State, cylinder_points
from bark.strategies import Analysis, Analyzer, Breaker, Growth, Integrator

__all__ = ["Simulation", "Stop", "BreakLog"]


DEFAULT_DT = 0.3
"""Default (largest) time step.  With adaptive stepping and ``DEFAULT_OVERSHOOT_TOL`` this setting
was measured by ``bark bench accuracy`` to give pattern statistics within the seed-to-seed spread of
a fine dt = 0.005 reference, in the vertical and the diamond regime, faster than the paper's fixed
dt = 0.01 (which ``dt = 0.01, stepping = "fixed"`` reproduces): 4.9× in the vertical regime as last
measured (``bark bench accuracy`` prints the current figure)."""
DEFAULT_STEPPING = "adaptive"
DEFAULT_OVERSHOOT_TOL = 0.002

SAFETY = 0.9
"""Automatic stepping keeps sub-steps at or below this fraction of the stability limit."""

QUIET_CHUNK = 128
"""Most steps one call of a compiled quiet-step kernel takes (progress and Ctrl-C are seen between calls)."""
QUIET_START = 8
"""Steps in the first call after a break; doubled after each call that ended quiet."""


def _first(flags: np.ndarray) -> int:
    """Index of the first True in ``flags``, or ``len(flags)`` if none."""
    return int(np.argmax(flags)) if flags.any() else len(flags)


def _defined_in(cls: type, name: str) -> type | None:
    return next((c for c in cls.__mro__ if name in vars(c)), None)


def _trusted_rule(breaker: Breaker) -> str | None:
    """``breaker.kernel_rule`` if the class that names it also defines ``select``, else ``None``."""
    cls = type(breaker)
    rule = getattr(breaker, "kernel_rule", None)
    return rule if rule is not None and _defined_in(cls, "kernel_rule") is _defined_in(cls, "select") else None


def _round_down(x: float) -> str:
    """``x`` rounded down to two significant digits, as text (for suggestions)."""
    if not x > 0:
        return f"{x:g}"
    exp = math.floor(math.log10(x)) - 1
    return f"{math.floor(x / 10**exp) * 10**exp:.{max(0, -exp)}f}"


@attrs.frozen(kw_only=True)
class Stop:
    """When a run ends: the first of these conditions to hold.  At least one is needed.  (The model
    has no natural end: after the first burst springs keep breaking as fragments move outward, so
    when to stop is part of a result, and summary.json records which condition ended the run.)"""

    until_time: float | None = attrs.field(default=None, validator=optional(positive))
    """Stop once simulated time ≥ this."""
    until_radius: float | None = attrs.field(default=None, validator=optional(positive))
    """Stop once the mean trunk radius ≥ this."""
    until_patches: int | None = attrs.field(default=None, validator=optional(positive_int))
    """Stop once the number of patches of at least ``min_patch_size`` bases ≥ this."""
    min_patch_size: int = attrs.field(default=7, validator=positive_int)
    """Smallest patch that counts (the paper drops patches under 7 bases)."""

    def __attrs_post_init__(self) -> None:
        if self.until_time is None and self.until_radius is None and self.until_patches is None:
            raise BarkError("no stop condition: give until_time, until_radius or until_patches")

    def reason(self, sim: "Simulation") -> str | None:
        """Which condition holds now (``'time'``, ``'radius'``, ``'patches'``), or ``None``."""
        eps = 1e-9 * sim.h
        if self.until_time is not None and sim.state.t >= self.until_time - eps:
            return "time"
        if self.until_radius is not None and sim.radius >= self.until_radius:
            return "radius"
        if self.until_patches is not None and sim.patch_count(self.min_patch_size) >= self.until_patches:
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
        self._chunks.append((ids.copy(), pairs[ids, 0], pairs[ids, 1], steps, times, tension[ids]))

    def __len__(self) -> int:
        return sum(c[0].size for c in self._chunks)

    def arrays(self) -> dict[str, np.ndarray]:
        """Columns ``spring, i, j, step, t, tension`` in the order the breaks happened."""
        names = ("spring", "i", "j", "step", "t", "tension")
        if not self._chunks:
            return {n: np.empty(0, dtype=float if n in ("t", "tension") else np.int64) for n in names}
        return {n: np.concatenate([c[k] for c in self._chunks]) for k, n in enumerate(names)}


@attrs.define(eq=False, kw_only=True)
class Simulation:
    """A trunk segment whose leaf-base layer grows and cracks.

    Build it from parts (every part is an attrs object; ``attrs.evolve`` makes variants for sweeps)::

        sim = Simulation(lattice=Lattice(), mechanics=Mechanics(), growth=SqrtGrowth(),
                         integrator=EulerCromer(), breakers=[ThresholdBreaker()], dt=0.01, seed=1)
        sim.run(Stop(until_patches=110))
    """

    lattice: Lattice = attrs.field(factory=Lattice)
    mechanics: Mechanics = attrs.field(factory=Mechanics)
    growth: Growth
    integrator: Integrator
    breakers: tuple[Breaker, ...] = attrs.field(converter=tuple)
    analyzers: tuple[Analyzer, ...] = attrs.field(default=(), converter=tuple)
    dt: float = attrs.field(default=DEFAULT_DT, validator=positive)
    """Time step; with adaptive stepping, the largest one (the paper's fixed step: 0.01)."""
    seed: int = attrs.field(default=0)
    """Seed of the simulation's one random generator (jitter, thresholds, stochastic breakers)."""
    degenerate_fraction: float = attrs.field(default=0.1, validator=in_range(0.0, 1.0, lo_open=True))
    """A step that breaks more than this share of all springs is a degenerate event: the lattice is too
    regular (on the exact lattice every spring of one offset reaches its threshold in the same step)."""
    on_degenerate: str = attrs.field(default="warn", validator=one_of("warn", "stop"))
    """What a degenerate event does: ``warn`` records it and goes on; ``stop`` ends the run."""
    stepping: str = attrs.field(default=DEFAULT_STEPPING, validator=one_of("fixed", "auto", "adaptive"))
    """``fixed``: every step is ``dt``, and a ``dt`` above the integrator's stability limit is
    refused (BarkError).  ``auto``: such a ``dt`` is split into equal sub-steps below the limit.
    ``adaptive``: as ``auto``, and around breaks a step whose largest tension overshoots its
    threshold by more than ``overshoot_tol`` is undone and retried at half the size; steps double
    again (up to the full step, on its grid) once no spring is over its threshold."""
    overshoot_tol: float = attrs.field(default=DEFAULT_OVERSHOOT_TOL, validator=positive)
    """Adaptive stepping's accuracy knob: largest allowed relative overshoot ``tension/fmax − 1``
    at a break (0.002 = a spring may break at up to 100.2 % of its threshold)."""
    max_halvings: int = attrs.field(default=10, validator=int_in(1, 40))
    """Adaptive stepping's smallest step is the full step / 2**max_halvings."""
    backend: str = attrs.field(default="auto", validator=one_of(*kernels.BACKENDS))
    """Compute backend of the hot loop: ``numpy``, ``numba``, or ``auto`` (numba if installed)."""
    record_breaks: bool = attrs.field(default=True)
    """Keep the break log (spring, step, time, tension of every break).  Off when a scene does not
    ask for the ``break-log`` effect: nothing is recorded along the way."""

    rng: np.random.Generator = attrs.field(init=False)
    graph: nx.Graph = attrs.field(init=False)
    state: State = attrs.field(init=False)
    breaks: BreakLog = attrs.field(init=False, factory=BreakLog)
    actions: list = attrs.field(init=False, factory=list)
    """``(trigger, action)`` pairs: after each step (or run of quiet steps) every action whose trigger
    fires is called with the simulation (see :meth:`add_action` and ``bark.triggers``)."""
    events: list[dict] = attrs.field(init=False, factory=list)
    """Degenerate events and other notable happenings, as dicts with at least ``kind``, ``t``, ``step``."""
    h: float = attrs.field(init=False)
    """The full step: ``dt``, or ``dt`` split into sub-steps below the stability limit (auto,
    adaptive).  Adaptive stepping takes ``h / 2**j`` around breaks."""
    stability_limit: float = attrs.field(init=False)
    """The integrator's largest stable step for this scene (``inf`` for unconditionally stable ones)."""
    step_count: int = attrs.field(init=False, default=0)
    stop_reason: str | None = attrs.field(init=False, default=None)
    _labels: np.ndarray | None = attrs.field(init=False, default=None)
    _last_finite: tuple[np.ndarray, ...] | None = attrs.field(init=False, default=None)
    _tension: np.ndarray | None = attrs.field(init=False, default=None)
    _quiet_n: int = attrs.field(init=False, default=QUIET_START)
    _levels: int = attrs.field(init=False, default=0)  # halvings allowed (0 unless adaptive)
    _halvings: int = attrs.field(init=False, default=0)  # current step = h / 2**_halvings
    _ticks: int = attrs.field(init=False, default=0)  # t = _ticks * _h_min, exactly
    _h_min: float = attrs.field(init=False, default=0.0)

    def __attrs_post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        r_ref = float(np.mean(self.growth.radius(0.0, np.zeros(1))))
        theta, z = self.lattice.sites(r_ref, self.rng)
        pairs = self.lattice.pairs()
        x = cylinder_points(theta, z, np.broadcast_to(self.growth.radius(0.0, z), z.shape))
        self.graph = nx.Graph()
        self.graph.add_nodes_from((i, {"theta0": t, "z0": h}) for i, (t, h) in enumerate(zip(theta, z)))
        self.graph.add_edges_from((int(i), int(j), {"spring": s}) for s, (i, j) in enumerate(pairs))
        _, rest = spring_geometry(x, pairs)
        self.state = State(
            x=x,
            v=np.zeros_like(x),
            anchor=x.copy(),
            anchor_dir=np.column_stack([np.cos(theta), np.sin(theta)]),
            pairs=pairs,
            rest=rest,
            fmax=self.growth.adjust_thresholds(0.5 * (z[pairs[:, 0]] + z[pairs[:, 1]]),
                                               self.mechanics.thresholds(len(pairs), self.rng)),
            intact=np.ones(len(pairs), dtype=bool),
            mechanics=self.mechanics,
            kernels=kernels.load(self.backend),
        )
        self._tension = np.zeros(len(pairs))
        self._guard()

    def _guard(self) -> None:
        """Refuse, or split into sub-steps, a ``dt`` above the integrator's stability limit."""
        limit = self.stability_limit = float(self.integrator.stability_limit(self.state))
        self.h = self.dt
        if self.dt <= limit:
            return self._set_grid()
        if self.stepping == "fixed":
            name = type(self.integrator).__name__
            raise BarkError(
                f"{{0}} is above {name}'s stability limit h_max = {limit:.4g} for this scene: use a step of at "
                f"most {_round_down(limit)}, or {{1}} for sub-steps, or {{2}} (docs/numerics.md)",
                Ref("run", "dt", self.dt), Ref("run", "stepping", "auto"), Ref("integrator", "name", "implicit-overdamped"),
            )
        self.h = self.dt / math.ceil(self.dt / (SAFETY * limit))
        self._set_grid()

    def check(self, stop: "Stop") -> None:
        """Refuse, before a run starts, a stop time that the clock cannot count: time is kept as an
        integer number of the smallest step (``h / 2**max_halvings``), exact only below 2**53 of them."""
        if stop.until_time is None:
            return
        ticks = stop.until_time / self._h_min
        if not ticks < 2.0**53:
            raise BarkError(
                f"{{0}} is {ticks:.3g} of the smallest step (the step {self.h:.3g} / 2^{self._levels}), more than "
                "the 2^53 that time can be counted in exactly: lower {1} or {2}, or stop earlier",
                Ref("run", "until_time", stop.until_time), Ref("run", "dt", self.dt), Ref("run", "max_halvings", self.max_halvings),
            )

    def _fit_step_to(self, stop: Stop) -> None:
        """With auto or adaptive stepping, a fresh run shrinks the full step a little so that
        ``stop.until_time`` is a whole number of steps: the run ends exactly there.  (Fixed steps are
        the user's: such a run ends at the first step at or past the stop time.)"""
        if self.stepping == "fixed" or self._ticks or stop.until_time is None:
            return
        steps = max(1, math.ceil(stop.until_time / self.h - 1e-9))
        self.h = stop.until_time / steps
        self._set_grid()

    def _set_grid(self) -> None:
        self._levels = self.max_halvings if self.stepping == "adaptive" else 0
        self._h_min = self.h / (1 << self._levels)

    # -- the loop ---------------------------------------------------------------------------

    def run(self, stop: Stop, observe: Callable[["Simulation"], None] | None = None) -> str:
        """Run until ``stop`` holds; return why it stopped (``'time'``, ``'radius'``, ``'patches'``,
        ``'degenerate'``).  ``observe(sim)`` is called after every step.  A step that makes the
        state NaN or infinite raises :class:`~bark.errors.NonFiniteStateError` and leaves the
        simulation at the last finite state.

        The loop, literally::

            while stop.reason(sim) is None:
                integrator.step(state, h)        # forces (eq. 4) -> velocities (eq. 7) -> positions (eq. 8)
                t += h                           # h = dt, or dt/n below the stability limit (auto, adaptive)
                constrain to surface r(t, z)     # eq. 9 on bases and anchors; radial velocity removed
                tension = k(|d| - l)             # every spring, at the constrained positions
                load = max(tension / fmax)       # over intact springs; NaN if any tension is not finite
                if adaptive and (load is NaN or load > 1 + overshoot_tol) and h can be halved:
                    undo the step, halve h, try again
                if load is NaN: back to the last finite state, raise NonFiniteStateError
                ids = union of breaker.select(state, tension, rng) over breakers
                if len(ids) > degenerate_fraction * n_springs: record a degenerate event
                break_springs(ids, tension)      # graph and arrays together; logged
                if adaptive and load <= 1: double h (up to the full step, staying on its grid)
                observe(sim)

        Every spring over its threshold at the end of a step breaks in that step, all at once;
        compression never breaks a spring; a broken spring never comes back.
        """
        for _ in self.irun(stop):
            if observe is not None:
                observe(self)
        return self.stop_reason

    def irun(self, stop: Stop) -> Iterator["Simulation"]:
        """The loop of :meth:`run` as a generator that yields after every :meth:`advance` (and its actions)."""
        self.stop_reason = None
        self._fit_step_to(stop)
        while (reason := stop.reason(self)) is None and self.stop_reason is None:
            self.advance(stop)
            for trigger, action in self.actions:
                if trigger.fires(self):
                    action(self)
            yield self
        self.stop_reason = self.stop_reason or reason

    def add_action(self, trigger, action: Callable[["Simulation"], None]) -> None:
        """Call ``action(sim)`` after every step at which ``trigger`` fires (``bark.triggers``).  A
        compiled run of quiet steps ends where a trigger is next due, so actions see the exact step."""
        self.actions.append((trigger, action))

    def advance(self, stop: Stop | None = None) -> int:
        """One :meth:`step`; or, where a compiled quiet-step kernel applies, up to ``QUIET_CHUNK``
        full steps in one call.  Returns the number of steps taken.

        The quiet path runs exactly the loop of :meth:`run`, step by step, inside compiled code; it
        applies when the integrator names a ``quiet_kernel`` that the backend has, every breaker is
        ``overload_only`` (so nothing needs Python until a spring is over its threshold), the
        growth law is uniform (the radius does not depend on height) and the step is full size.
        It returns on a non-finite state, at the step where ``stop``'s time or radius is reached
        or a trigger is next due, and around breaks: if every breaker names the same trusted
        ``kernel_rule`` and stepping is not adaptive, the kernel breaks springs itself and goes on
        (the batch is handed to :meth:`break_springs` here), returning after a breaking step only
        when Python must see it (a patch stop, a trigger that watches breaks, a degenerate step);
        otherwise it returns after the first step that overloads a spring, whose breaks are then
        made here, as in :meth:`step`.  A last step that adaptive stepping rejects comes back undone
        (the kernel replays its call up to the step before, exactly) and is retried at half the size.
        """
        kernel = self._quiet_kernel() if self._halvings == 0 else None
        radii = self._quiet_radii(stop) if kernel is not None else None
        if radii is None:
            self.step()
            return 1
        s = self.state
        adaptive = self._levels > 0
        rule = None if adaptive else self._kernel_rule()  # adaptive stepping returns at each break: undoing a
        must_see = rule is not None and self._must_see_breaks(stop)  # long call of breaks costs a replay
        done, load, (ids, steps, tensions) = kernel(
            s, self.h, radii, self._tension, 1.0 + self.overshoot_tol if adaptive else math.inf,
            break_rule=rule, return_on_break=must_see, max_batch=self._degenerate_limit,
        )
        first_step, first_tick = self.step_count, self._ticks
        self._ticks += done << self._levels
        self.step_count += done
        s.t = self._ticks * self._h_min
        s.h = self.h
        if ids.size:  # broken inside the call, by the breakers' own rule: the graph, the log, the events
            self._tension[ids] = tensions
            self.break_springs(ids, self._tension, step=first_step + steps,
                               t=(first_tick + (steps << self._levels)) * self._h_min)
            self._check_degenerate(np.count_nonzero(steps == done))  # the kernel returns after such a step
        # quiet steps come in runs: grow the next call while they last, start small after a break
        # that Python had to see (with the kernel breaking springs itself, every step is quiet)
        saw_break = load > 1.0 and (rule is None or must_see)
        self._quiet_n = QUIET_START if saw_break else min(2 * self._quiet_n, QUIET_CHUNK)
        if adaptive and (math.isnan(load) or load > 1.0 + self.overshoot_tol):
            self._halvings = 1  # the kernel undid that step: take it again, smaller
            self.step()
            return done + 1
        if math.isnan(load):  # the kernel put x and v back to the state before the bad step
            self._non_finite(s.t + self.h)
        if rule is None:
            self._break_selected(load)
        return done

    def step(self) -> None:
        """One step of the loop in :meth:`run` (adaptive: one accepted step, after the halvings it needed)."""
        s = self.state
        while True:
            self._keep_last_finite()
            size = 1 << (self._levels - self._halvings)  # this step, in ticks
            s.h = size * self._h_min
            self.integrator.step(s, s.h)
            s.t = (self._ticks + size) * self._h_min  # from integer ticks: no drift over 10^5 steps
            # surface constraint (eq. 9), then every spring's tension and the largest tension/fmax of intact ones
            load = s.kernels.constrain_measure(s, self._radius_at(s.x[:, 2]), self._radius_at(s.anchor[:, 2]), self._tension)
            non_finite = math.isnan(load)
            if not non_finite and not (self._levels and load > 1.0 + self.overshoot_tol):
                break
            if self._halvings < self._levels:  # undo the step and try again at half the size
                self._restore_last_finite()
                self._halvings += 1
                continue
            if non_finite:  # at the smallest step: stop at the last finite state
                bad_t = s.t
                self._restore_last_finite()
                self._non_finite(bad_t)
            # an overshoot at the smallest step is accepted, and recorded
            self.events.append({"kind": "overshoot", "t": s.t, "step": self.step_count + 1, "load": load})
            break
        self._ticks += size
        self.step_count += 1
        self._break_selected(load)
        if self._halvings and load <= 1.0 and self._ticks % (size << 1) == 0:
            self._halvings -= 1  # quiet again: double the step, staying on the coarser grid

    def _break_selected(self, max_load: float) -> None:
        ids = self._select(self._tension, max_load)
        if ids.size:
            self._check_degenerate(ids.size)
            self.break_springs(ids, self._tension)

    def _non_finite(self, bad_t: float) -> None:
        """Raise after a non-finite step; the caller has put the state back to the last finite one."""
        self.state.t = self._ticks * self._h_min
        raise NonFiniteStateError(
            f"the state became NaN or infinite at t = {bad_t:.6g} (step {self.step_count + 1}); "
            f"the simulation holds the last finite state, t = {self.state.t:.6g}"
        )

    def _restore_last_finite(self) -> None:
        """Undo the step just taken: x, v and anchors from the copy kept before it; t from the ticks."""
        s = self.state
        for keep, a in zip(self._last_finite, (s.x, s.v, s.anchor)):
            np.copyto(a, keep)
        s.t = self._ticks * self._h_min

    def _quiet_kernel(self):
        name = self.integrator.quiet_kernel
        if name is None or not all(b.overload_only for b in self.breakers):
            return None
        return getattr(self.state.kernels, name, None)

    def _kernel_rule(self) -> str | None:
        """The compiled rule by which the quiet kernel may break springs itself: the one every
        breaker names (and defines ``select`` alongside; see ``Breaker.kernel_rule``), else ``None``."""
        rules = {_trusted_rule(b) for b in self.breakers}
        return rules.pop() if len(rules) == 1 else None

    def _must_see_breaks(self, stop: Stop | None) -> bool:
        """Whether Python must look at the state after each step that breaks springs: to count
        patches for ``stop``, or for a trigger that watches breaks."""
        if stop is not None and stop.until_patches is not None:
            return True
        return any(trigger.watches_breaks() for trigger, _ in self.actions)

    def _quiet_radii(self, stop: Stop | None) -> np.ndarray | None:
        """The uniform trunk radius at each of the next steps — or ``None`` where the quiet path does
        not apply (height-dependent growth, or fewer than two steps before a stop condition)."""
        ts = (self._ticks + (np.arange(self._quiet_n) + 1.0) * (1 << self._levels)) * self._h_min
        z = self.state.x[:, 2]
        first = self.growth.radius(float(ts[0]), z)
        if np.ndim(first) != 0:
            return None
        radius = self.growth.radius
        r = np.array([float(first), *(float(radius(t, z)) for t in ts[1:].tolist())])
        n = len(r)
        for trigger, _ in self.actions:  # end where an action is next due
            step, due = trigger.next_step(self), trigger.next_time(self)
            if step is not None:
                n = min(n, max(1, step - self.step_count))
            if due is not None:
                n = min(n, _first(ts >= due - 1e-9 * self.h) + 1)
        if stop is not None and stop.until_time is not None:
            n = min(n, _first(ts >= stop.until_time - 1e-9 * self.h) + 1)
        if stop is not None and stop.until_radius is not None:
            n = min(n, _first(r >= stop.until_radius) + 1)
        return r[:n] if n >= 2 else None

    def _keep_last_finite(self) -> None:
        """Copy what a step changes (x, v, and the anchors, which a non-finite radius would spoil)."""
        s = self.state
        now = (s.x, s.v, s.anchor)
        if self._last_finite is None or self._last_finite[0].shape != s.x.shape:
            self._last_finite = tuple(a.copy(order="K") for a in now)
        else:
            for keep, a in zip(self._last_finite, now):
                np.copyto(keep, a)

    def _radius_at(self, z: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.growth.radius(self.state.t, z), z.shape)

    def _select(self, tension: np.ndarray, max_load: float) -> np.ndarray:
        picks = [
            np.asarray(b.select(self.state, tension, self.rng), dtype=np.int64)
            for b in self.breakers
            if max_load > 1.0 or not b.overload_only
        ]
        if not picks:
            return np.empty(0, np.int64)
        ids = np.unique(np.concatenate(picks))
        return ids[self.state.intact[ids]]

    @property
    def _degenerate_limit(self) -> float:
        """A step that breaks more springs than this is a degenerate event."""
        return self.degenerate_fraction * self.state.n_springs

    def _check_degenerate(self, n: int) -> None:
        """Record a degenerate event (and stop, if asked) when one step breaks ``n`` springs, too many."""
        if n <= self._degenerate_limit:
            return
        self.events.append(
            {
                "kind": "degenerate",
                "t": self.state.t,
                "step": self.step_count,
                "n_springs": int(n),
                "fraction": n / self.state.n_springs,
            }
        )
        if self.on_degenerate == "stop":
            self.stop_reason = "degenerate"

    # -- checkpoints ------------------------------------------------------------------------------

    def snapshot(self) -> tuple[dict[str, np.ndarray], dict]:
        """Everything needed to go on from here exactly: the arrays of the state and the break log,
        and (JSON-able) the clock, the step control and the random generator's state.  The graph is
        not stored: it is rebuilt from the scene and the intact mask."""
        s = self.state
        arrays = {"x": s.x, "v": s.v, "anchor": s.anchor, "intact": s.intact, "fmax": s.fmax, "pairs": s.pairs}
        arrays.update({f"breaks_{k}": v for k, v in self.breaks.arrays().items()})
        meta = {
            "t": s.t, "h_last": s.h, "h": self.h, "step_count": self.step_count, "ticks": self._ticks,
            "halvings": self._halvings, "quiet_n": self._quiet_n, "events": self.events,
            "rng": self.rng.bit_generator.state,
        }
        return arrays, meta

    def restore(self, arrays: dict[str, np.ndarray], meta: dict) -> None:
        """Put this (freshly built, same scene) simulation in the state ``snapshot`` recorded."""
        s = self.state
        if arrays["pairs"].shape != s.pairs.shape or not np.array_equal(arrays["pairs"], s.pairs) or arrays["x"].shape != s.x.shape:
            raise BarkError("the checkpoint's bases and springs do not match its scene's lattice: it was written by another scene")
        for name in ("x", "v", "anchor", "intact", "fmax"):
            np.copyto(getattr(s, name), arrays[name])
        broken = s.pairs[~s.intact]
        self.graph.remove_edges_from(broken.tolist())
        names = ("spring", "i", "j", "step", "t", "tension")
        log = tuple(np.asarray(arrays[f"breaks_{k}"]) for k in names)
        self.breaks = BreakLog([log] if log[0].size else [])
        s.t, s.h = float(meta["t"]), float(meta["h_last"])
        self.h = float(meta["h"])
        self._set_grid()
        self.step_count, self._ticks = int(meta["step_count"]), int(meta["ticks"])
        self._halvings, self._quiet_n = int(meta["halvings"]), int(meta["quiet_n"])
        self.events = list(meta["events"])
        self.rng.bit_generator.state = meta["rng"]
        self._labels = None

    # -- the one place springs break ------------------------------------------------------------

    def break_springs(self, ids, tension: np.ndarray | None = None, *, step=None, t=None) -> np.ndarray:
        """Break springs ``ids`` for good, in the graph and in the arrays, and log them.

        ``tension`` is every spring's tension (default: the current one); ``step`` and ``t`` say when
        they broke, one value or one per id (default: now).  Breaks are logged in order of step,
        then spring id.  Already-broken ids are ignored (and an id given twice breaks at its first
        step).  Returns the ids actually broken.
        """
        s = self.state
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if ids.size and (ids.min() < 0 or ids.max() >= s.n_springs):
            bad = ids.min() if ids.min() < 0 else ids.max()
            raise IndexError(f"spring ids must be in [0, {s.n_springs}): got {bad}")
        steps = np.broadcast_to(np.asarray(self.step_count if step is None else step, dtype=np.int64), ids.shape)
        times = np.broadcast_to(np.asarray(s.t if t is None else t, dtype=float), ids.shape)
        order = np.lexsort((ids, steps))
        first = np.sort(np.unique(ids[order], return_index=True)[1])  # each id once, at its first step
        order = order[first]
        order = order[s.intact[ids[order]]]
        if order.size == 0:
            return ids[:0]
        ids, steps, times = ids[order], steps[order], times[order]
        if tension is None:
            tension = s.tension()
        s.intact[ids] = False
        self.graph.remove_edges_from(s.pairs[ids].tolist())
        if self.record_breaks:
            self.breaks.record(ids, s.pairs, steps, times, tension)
        self._labels = None
        return ids

    # -- observables ----------------------------------------------------------------------------

    @property
    def radius(self) -> float:
        """Mean trunk radius now (at the anchors' heights)."""
        return float(np.mean(self._radius_at(self.state.anchor[:, 2])))

    @property
    def n_broken(self) -> int:
        return int(self.state.n_springs - np.count_nonzero(self.state.intact))

    def patch_labels(self) -> np.ndarray:
        """Patch id of every base: connected components of the intact springs (cached until a break)."""
        if self._labels is None:
            self._labels = self.state.kernels.patch_labels(self.state)
        return self._labels

    def patch_count(self, min_size: int = 7) -> int:
        """Number of patches of at least ``min_size`` bases."""
        return int(np.count_nonzero(np.bincount(self.patch_labels()) >= min_size))

    def analyze(self) -> dict[str, Analysis]:
        """Run every analyzer on the current pattern; results by analyzer class name."""
        labels = self.patch_labels()
        return {type(a).__name__: a.analyze(self.state.x, labels) for a in self.analyzers}
