"""How a run steps: the numerical settings, the clock, and the plan of each call of the kernel.

* :class:`Numerics` — the settings (dt, stepping mode, overshoot tolerance, halvings, backend),
  declared once: a scene's ``[run]`` table and the command line take them from here.
* :class:`Clock` — step control.  Time is an integer count of the smallest step
  (``t = ticks × h / 2**levels``), never a running sum, so variable steps stay exact and stop times
  are hit exactly.  Adaptive stepping halves the step around breaks and doubles it back on its grid.
* :func:`plan` — the fast-path policy: how many steps the next call takes and what may happen inside
  it, from what the strategies' parts declare and what must be seen from Python
  (stop conditions, triggers, adaptive halving).
* :func:`python_step` — one step for parts without a compiled form (an integrator that solves a
  linear system, a growth law given only as ``radius``), by the backends' step algorithm.
"""

from __future__ import annotations

import math
import os

import attrs
import numpy as np

from bark.contract import registry
from bark.contract.parts import NO_BREAKING, BreakerPart
from bark.validators import int_in, one_of, positive
from bark.errors import BarkError, Ref
from bark.model.forces import ForceField
from bark.engine.kernels import BACKENDS, Plan, Steps, take_steps

__all__ = ["Numerics", "Clock", "plan", "steers_step", "breaking_part", "python_step", "stable_step", "check_countable",
           "DEFAULT_DT", "DEFAULT_STEPPING", "DEFAULT_OVERSHOOT_TOL"]

DEFAULT_DT = 0.3
"""Default (largest) time step.  With adaptive stepping and ``DEFAULT_OVERSHOOT_TOL`` this setting
was measured by ``bark bench accuracy`` to give pattern statistics within the seed-to-seed spread of
a fine dt = 0.005 reference, in the vertical and the diamond regime, faster than the paper's fixed
dt = 0.01 (which ``dt = 0.01, stepping = "fixed"`` reproduces); ``bark bench accuracy`` prints by
how much on the machine it runs on."""
DEFAULT_STEPPING = "adaptive"
DEFAULT_OVERSHOOT_TOL = 0.002
SAFETY = 0.9
"""Automatic stepping keeps sub-steps at or below this fraction of the stability limit."""
CHUNK = 128
"""Most steps in one kernel call (progress, signals and periodic checkpoints are seen between calls)."""
CHUNK_WORK = 60_000_000
"""Most base- and spring-steps in one call (a base and a spring cost about as much a step), so
that a very large or very dense scene still answers a signal promptly: a call's length bounded in
work, not in steps (``bark bench speed`` prints a base-step's time here)."""


@attrs.frozen(kw_only=True)
class Numerics:
    """How a run is stepped."""

    dt: float = attrs.field(default=DEFAULT_DT, validator=positive)
    """Time step, time units (1 = 88.5 days); with adaptive stepping the largest one.  The paper
    used a fixed 0.01 (21 h): dt 0.01 with fixed stepping reproduces it."""
    stepping: str = attrs.field(default=DEFAULT_STEPPING, validator=one_of("fixed", "auto", "adaptive"))
    """fixed: refuse a dt above the integrator's stability limit; auto: split it into sub-steps;
    adaptive: also halve steps around breaks to keep overshoot below overshoot_tol."""
    overshoot_tol: float = attrs.field(default=DEFAULT_OVERSHOOT_TOL, validator=positive)
    """Adaptive stepping: largest overshoot of a breaker's load past 1 allowed at a break (the load is
    the breaker's own measure of how far a spring is from breaking: tension/f_max for the threshold
    breaker)."""
    max_halvings: int = attrs.field(default=10, validator=int_in(1, 40))
    """Adaptive stepping: the smallest step is the full step / 2**max_halvings (at most 40)."""
    backend: str = attrs.field(default="auto", validator=one_of(*BACKENDS))
    """Compute backend: numpy, numba, or auto (numba if installed, else numpy)."""
    threads: int = attrs.field(default=0, validator=int_in(0, 65536))
    """Threads the numba backend's kernel shares each step among: 0 = automatic (as many as the cores
    this process may use, for a lattice of at least 16,000 bases; else 1), at most that many.  Results
    are the same to the bit whatever the count; the numpy backend runs on one."""


def cores() -> int:
    """The cores this process may use (its CPU affinity, where the system tells it): what automatic
    threads, a sweep's local workers and the picture processes share."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


@attrs.define
class Clock:
    """Step control: the full step ``h``, the current halving, and time as integer ticks."""

    h: float
    """The full step: dt, or dt split into sub-steps below the stability limit."""
    levels: int = 0
    """Halvings allowed (adaptive stepping), so the smallest step is ``h / 2**levels``."""
    ticks: int = 0
    halvings: int = 0
    """The current step is ``h / 2**halvings``."""

    @property
    def h_min(self) -> float:
        """The smallest step: ``h / 2**levels`` (one tick)."""
        return self.h / (1 << self.levels)

    @property
    def t(self) -> float:
        """The time: ``ticks`` smallest steps (exact: a sum of steps never drifts)."""
        return self.ticks * self.h_min

    @property
    def size(self) -> int:
        """The current step, in ticks."""
        return 1 << (self.levels - self.halvings)

    @property
    def step(self) -> float:
        """The current step's length (``h / 2**halvings``)."""
        return self.size * self.h_min

    def times(self, n: int) -> np.ndarray:
        """Time at the end of each of the next ``n`` steps of the current size."""
        return (self.ticks + (np.arange(n) + 1.0) * self.size) * self.h_min

    def advance(self, steps: int) -> None:
        """Move the time on by ``steps`` steps of the current size."""
        self.ticks += steps * self.size

    def can_halve(self) -> bool:
        """Whether the step may be halved again (adaptive stepping's levels not used up)."""
        return self.halvings < self.levels

    def halve(self) -> None:
        """Halve the current step."""
        self.halvings += 1

    def fit(self, until_time: float) -> None:
        """Shrink ``h`` a little so that ``until_time`` is a whole number of steps (a fresh run with
        automatic or adaptive stepping then ends exactly there)."""
        steps = max(1, math.ceil(until_time / self.h - 1e-9))
        self.h = until_time / steps


def stable_step(sim) -> tuple[float, float]:
    """``(stability limit, full step)``: the integrator's limit — of the lattice as it will be, when
    bases are still to join — and the step, ``dt`` or ``dt`` split into equal sub-steps below the
    limit (``auto``, ``adaptive``).  A ``dt`` above the limit with ``fixed`` stepping is refused.
    The integrator's accuracy limit bounds the steps nothing controls in the same way (``fixed``:
    refused above it; ``auto``: sub-stepped); ``adaptive`` stepping controls overshoot instead."""
    stiff = sim.resin_part.stiffness  # a resin stiffer than k·(its stretch) lowers the bound
    forces = sim.forces if stiff == 1.0 else ForceField(attrs.evolve(sim.mechanics, k=sim.mechanics.k * stiff), sim.backend)
    whole = None
    if sim.lattice.initial < sim.lattice.n_bases:  # its own forces: their caches are of the simulation's state
        whole = (sim.whole_lattice(), ForceField(forces.mechanics, sim.backend))

    def least(limit_of) -> float:
        return min(float(limit_of(sim.state, forces)), float(limit_of(*whole)) if whole else math.inf)

    limit = least(sim.integrator.stability_limit)
    accurate = math.inf if sim.numerics.stepping == "adaptive" else least(sim.integrator.accuracy_limit)
    h = sim.numerics.dt
    if h <= min(limit, accurate):
        return limit, h
    method = type(sim.integrator).__name__
    if sim.numerics.stepping == "fixed" and h > limit:
        massless = [name for kind, name in registry.find(lambda cls: cls.kind == "integrator" and cls.overdamped)]
        refs = [Ref("run", "dt", h), Ref("run", "stepping", "auto"), *(Ref("integrator", "name", n) for n in massless[:1])]
        raise BarkError(
            f"{{0}} is above {method}'s stability limit h_max = {limit:.4g} for this scene: "
            f"use a step of at most {_round_down(limit)}, or {{1}} for sub-steps"
            + (", or {2}, which has no such limit" if massless else "") + " (docs/numerics.md)", *refs)
    if sim.numerics.stepping == "fixed":
        raise BarkError(
            f"{{0}} is above {method}'s accuracy limit for fixed steps, {accurate:.4g} for this scene (the time "
            "scale a step must resolve; docs/numerics.md): springs that would break one after another would "
            f"break together. Use a step of at most {_round_down(accurate)}, or {{1}}, which holds each breaking "
            "step to the overshoot tolerance", Ref("run", "dt", h), Ref("run", "stepping", "adaptive"))
    return limit, h / math.ceil(h / (SAFETY * min(limit, accurate)))


def expected_work(sim) -> float | None:
    """Base-steps the run is expected to take (for ``auto``'s choice of backend): its bases times its
    horizon over the step — the step bounded by the Gershgorin stability limit of the lattice (cheap,
    before anything is built), and adaptive halving counted (1.5 times the steps in the vertical
    regime, measured); ``None`` with no time bound."""
    if sim.horizon is None:
        return None
    mech = sim.mechanics
    from bark.model.stability import explicit_h_max

    lam = mech.c + 4.0 * mech.k * len(sim.lattice.offsets)
    h = min(sim.numerics.dt, SAFETY * explicit_h_max(mech.b / mech.m, lam / mech.m))
    halving = 1.5 if sim.numerics.stepping == "adaptive" else 1.0  # steps halved around breaks (measured)
    return halving * sim.lattice.n_bases * sim.horizon / h


def check_countable(sim, stop) -> None:
    """Refuse, before a run starts, a stop time the clock cannot count: time is kept as an integer
    number of the smallest step, exact only below 2**53 of them."""
    clock = sim.clock
    ticks = stop.until_time / clock.h_min if stop.until_time is not None else 0.0
    if not ticks < 2.0**53:
        raise BarkError(
            f"{{0}} is {ticks:.3g} of the smallest step (the step {clock.h:.3g} / 2^{clock.levels}), more than the "
            "2^53 that time can be counted in exactly: lower {1} or {2}, or stop earlier",
            Ref("run", "until_time", stop.until_time), Ref("run", "dt", sim.numerics.dt),
            Ref("run", "max_halvings", sim.numerics.max_halvings))


def _round_down(x: float) -> str:
    """``x`` rounded down to two significant digits, as text (for suggestions)."""
    if not (x > 0 and math.isfinite(x)):
        return f"{x:g}"
    exp = math.floor(math.log10(x)) - 1
    v = math.floor(x / 10**exp) * 10**exp
    return f"{v:.{max(0, -exp)}f}" if -8 <= exp <= 15 else f"{v:.2g}"  # 0.0034, 120; 5.6e-124, not 124 digits


def _first(flags: np.ndarray) -> int:
    """Index of the first True in ``flags``, or ``len(flags)`` if none."""
    return int(np.argmax(flags)) if flags.any() else len(flags)


def plan(sim, stop, most: int | None = None) -> Plan:
    """The next call: how many steps of what size, and what may happen inside it.

    Many steps go in one call when the integrator and the growth law have compiled forms and the
    breakers share one part (``Breaker.part``); the call then ends where a stop condition can next
    hold (a patch count: after as many breaks as patches are missing, where a backend that counts
    patches itself counts them and goes on while there are fewer: ``Plan.patch_goal``), a trigger is
    next due or bases next join, or after a step it refuses; it doubles a halved step itself where
    the clock would (``Plan``).
    Springs the part's rule picks break inside the call when the part decides (a step that adaptive
    stepping undoes is taken back, its breaks with it: ``take_steps``); when it names candidates,
    the call ends after the first step in which it names one, and the breakers select in Python.
    Breakers with no part, or with different parts, are asked in Python after every step (one step
    a call), and the step is held to their loads in Python (``python_step``) if any of them has one.
    A strategy without a part makes every call one step of ``python_step``, whose breaker part judges
    inside it as the kernel's does (before the resin flows)."""
    clock = sim.clock
    part = breaking_part(sim.breakers)
    steers = steers_step(sim)
    growth, integrator = sim.growth.part_, sim.integrator.part_
    compiled = integrator is not None and growth is not None and (part is not None or not steers)
    breaks = "python" if part is None else "kernel" if part.decides else "candidates"  # the Python path's too
    n = 1
    if compiled and breaks != "python":
        n = min(call_steps(sim.state.n_bases, sim.state.n_springs), most or CHUNK)
    n, t_limit, may_double = _bounded(sim, stop, n) if n > 1 else (n, math.inf, True)
    budget, goal = _break_budget(sim, stop)
    return Plan(
        h_min=clock.h_min, ticks=clock.ticks, n=n, levels=clock.levels, halvings=clock.halvings,
        integrator=integrator if compiled else None, growth=growth if compiled else None,
        breaker=part if breaks != "python" else NO_BREAKING, breaks=breaks,
        over=1.0 + sim.numerics.overshoot_tol if steers else math.inf, t_limit=t_limit, may_double=may_double,
        break_budget=budget, max_batch=sim.degenerate_fraction * sim.state.n_springs, compiled=compiled,
        threads=sim.numerics.threads, patch_goal=goal, min_patch_size=stop.min_patch_size if goal else 1,
    )


def call_steps(n_bases: int, n_springs: int) -> int:
    """The most steps one call of a compiled kernel takes on this many bases and springs: ``CHUNK``,
    or fewer on a scene so large that ``CHUNK_WORK`` base- and spring-steps come first (at least one)."""
    return max(1, min(CHUNK, CHUNK_WORK // max(n_bases + n_springs, 1)))


def _break_budget(sim, stop) -> tuple[float, int]:
    """The breaks a call may make before Python must look, and the patch count it may judge itself
    (``Plan.patch_goal``, 0: none): 1 where a trigger watches breaks; with a patch-count stop, as
    many as the patches that may still be missing (``Simulation.patches_at_most``: each break adds
    at most one patch), for the stop cannot hold before that many breaks (the call then ends at the
    same step as one ending at every break would stop at: the result is the same to the bit), and
    that stop's count; else none."""
    if any(t.watches_breaks() for t, _ in sim.actions):
        return 1.0, 0
    if stop is not None and stop.until_patches is not None:
        return float(max(1, stop.until_patches - sim.patches_at_most(stop.min_patch_size))), int(stop.until_patches)
    return math.inf, 0


def steers_step(sim) -> bool:
    """Whether steps are held to the overshoot tolerance: adaptive stepping, and a breaker whose part
    has a load (how far a spring is from breaking, by the breaker's own measure).  A breaker without
    one does not steer: for it a load over 1 is no overshoot, and halving the step would not change
    what it breaks."""
    return sim.clock.levels > 0 and any(b.part_ is not None and b.part_.load is not None for b in sim.breakers)


def breaking_part(breakers) -> BreakerPart | None:
    """The one part the kernel evaluates for ``breakers`` (``NO_BREAKING`` for none), or ``None``
    where no one part says what they do: a breaker without a part, or breakers with different parts
    (each is then asked in Python)."""
    if not breakers:
        return NO_BREAKING
    parts = {b.part_ for b in breakers}
    return parts.pop() if len(parts) == 1 else None


def _bounded(sim, stop, n: int) -> tuple[int, float, bool]:
    """``(n, t_limit, may_double)``: the call ends after the first step that reaches ``t_limit``,
    where bases next join, a trigger is next due or a time stop can next hold, and after ``n``
    steps: cut where a trigger counting steps is next due, and where the present step would reach
    ``t_limit`` (or a radius stop: the call then may not go on at a doubled step).  A doubled step
    only reaches them sooner, so the cut is the most steps the call can take, which is what decides,
    at per-base radii, how a refused step is taken back (``IN_PLACE_STEPS``)."""
    eps = 1e-9 * sim.clock.h
    limits = [sim.packing.next_join(sim.state.t, sim.state.n_bases)]
    for trigger, _ in sim.actions:
        step, due = trigger.next_step(sim), trigger.next_time(sim)
        if step is not None:
            n = min(n, max(1, step - sim.step_count))
        limits.append(due)
    if stop is not None:
        limits.append(stop.until_time)
    t_limit = min((t - eps for t in limits if t is not None), default=math.inf)
    times = sim.clock.times(n)
    n = min(n, _first(times >= t_limit) + 1)
    if stop is not None and stop.until_radius is not None:
        z = sim.state.anchor[:, 2]
        radii = np.array([sim.growth.mean_radius(t, z) for t in times[:n].tolist()])
        return max(1, min(n, _first(radii >= stop.until_radius) + 1)), t_limit, False
    return max(n, 1), t_limit, True


def python_step(sim, state, mech, plan: Plan, tension: np.ndarray) -> Steps:
    """One step for parts without compiled forms: the array step of the numpy backend
    (``ArrayCall``) with the integrator's ``step`` and the growth law's ``radius`` in place of their
    parts, by the backends' step algorithm (:func:`~bark.engine.kernels.take_steps`): a step that
    goes non-finite or over the load the clock accepts undone."""
    from bark.engine.kernels.numpy_backend import ArrayCall

    return take_steps(ArrayCall(sim.backend, state, mech, plan, tension, verbs=_Verbs(sim)), plan)


@attrs.frozen
class _Verbs:
    """The strategies' Python verbs where the array step would use their parts: the integrator moves
    the bases (changing only what it declares it writes), the growth law gives the radius at the
    bases' and the anchors' heights; the step is held to each breaker part's load."""

    sim: object

    @property
    def parts(self) -> list:
        return [p for p in {b.part_ for b in self.sim.breakers} if p is not None]

    def move(self, state, h: float) -> None:
        with state.only(self.sim.integrator.writable()):  # what it declares it writes, and nothing else
            self.sim.integrator.step(state, h, self.sim.forces)

    def radii(self, t: float, state) -> tuple[np.ndarray, np.ndarray]:
        growth, n = self.sim.growth, state.n_bases  # the public, read-only views: the law may not write them
        return (np.broadcast_to(growth.radius(t, state.x[:, 2]), (n,)),
                np.broadcast_to(growth.radius(t, state.anchor[:, 2]), (n,)))
