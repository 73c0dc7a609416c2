"""Compute backends for the hot loop: one interface, chosen once per simulation (after OpenMM's
platforms).  The Simulation never knows which runs.

=============================================  ====================================================
method                                          does
=============================================  ====================================================
``spring_forces(state, mech, x) -> f``          the intact springs' forces (eq. 1) on every base at ``x``
``measure(state, mech, out) -> finite``         every spring's tension ``k(|d| − l)`` into ``out``;
                                                returns whether all of them are finite
``constrain(state, r_x, r_anchor)``             eq. 9 on the bases (radial velocity removed) and
                                                the anchors (radius × fixed direction)
``call(state, mech, plan, tension) -> Call``    one call's steps (:class:`Call`) with the
                                                strategies' parts (``bark.contract.parts``): forces,
                                                the integrator's update, the surface at the growth
                                                law's radius, tensions, the breakers' rule and load
``patch_labels(state) -> labels``               connected components of the intact springs, numbered
                                                in order of each component's smallest base
=============================================  ====================================================

``Backend.steps`` runs a call by the one step algorithm every backend shares (:func:`take_steps`):
each step ends the call or not by :func:`ends_call`, and a last step that is undone is taken back by
replaying the call up to it, or by the call itself where it kept a copy of the state before that
step (``Call.undone``: the numba kernel under adaptive stepping).  A backend supplies only how its steps are computed (the numba
backend compiles ``ends_call`` into its kernel; the Python path of ``bark.engine.stepping`` is the
numpy backend's array step with the strategies' verbs, one step a call); the per-step and the
many-step paths are this one algorithm.

Both backends evaluate the physics of :mod:`bark.model.physics` and the strategies' parts, the
same functions, each base's sums taken in the same order (``bark.model.forces.SpringOrder``).
``numpy`` is always there; ``numba`` (compiled, cached on disk) is used when importable and the run
is long enough to repay its start (``auto``; the results are the same to the bit).  A backend
holds its own work buffers (derived data, rebuilt when the topology grows); the state is only data.
"""

from __future__ import annotations

import importlib
import importlib.util
import logging
import math
import sys
import warnings

import attrs
import numpy as np

from bark.errors import BarkError, BarkWarning, Ref
from bark.contract.parts import HOOKEAN, NO_BREAKING, BreakerPart, GrowthPart, IntegratorPart

__all__ = ["BACKENDS", "Backend", "Call", "Plan", "Steps", "doubles", "ends_call", "limits", "take_steps", "available",
           "resolve", "load", "expect_many", "runs_many"]

BACKENDS = ("auto", "numpy", "numba")


@attrs.frozen(kw_only=True)
class Plan:
    """What one call of :meth:`Backend.steps` may do.

    The call keeps adaptive stepping's clock itself: time in integer ticks of the smallest step
    ``h_min``, the step ``2**(levels − halvings)`` ticks long.  After a kept step that ends quiet
    (load at most 1) at a halved step, on the grid of the next larger step, it doubles the step and
    goes on (:func:`doubles`).  A refused step ends the call, and the caller halves it
    (``Clock.halve``), unless the call takes it back itself (``Call.undone``): it may then halve it
    and go on.  Every time is ``ticks · h_min`` and every step ``size · h_min``: the same numbers however
    the run is split into calls."""

    h_min: float
    """The smallest step: one tick (``Clock.h_min``)."""
    ticks: int
    """The clock where the call begins, in ticks."""
    n: int
    """The most steps the call may take."""
    integrator: IntegratorPart | None
    """The integrator's part (``bark.contract.parts``): its update of one coordinate of one base
    (``None``: one step in Python)."""
    growth: GrowthPart | None
    """The growth law's part (``bark.contract.parts``): its radius, once a step what depends on time
    alone, and per base what depends on height (``None``: one step in Python)."""
    breaker: BreakerPart = NO_BREAKING
    """The breakers' part (``bark.contract.parts``): its rule picks springs, its load steers the step."""
    breaks: str = "kernel"
    """``kernel``: springs the rule picks break inside the call, which goes on.  ``candidates``:
    nothing breaks inside; the call ends after the first step in which the rule picks a spring, for
    the breakers to judge in Python.  ``python``: the breakers judge in Python after every step (the
    part is ``NO_BREAKING``)."""
    levels: int = 0
    """Halvings adaptive stepping allows (``Clock.levels``)."""
    halvings: int = 0
    """The step's halvings where the call begins (``Clock.halvings``)."""
    over: float = math.inf
    """``1 + overshoot_tol`` where the breakers' load steers the step, else ``inf``: a step whose load
    exceeds it is refused while the step may still be halved (``accept_load``), and ends the call,
    kept, at the smallest step (``report_load``: an overshoot the simulation records)."""
    t_limit: float = math.inf
    """The call ends after the first step that reaches this time (bases join, a trigger is due, a
    time stop may hold)."""
    may_double: bool = True
    """Whether the call goes on at a doubled step; else it ends where it doubles (a radius stop,
    whose bound on the steps was found at the step's size)."""
    break_budget: float = math.inf
    """End the call after the step at which the springs the rule broke in it reach this many: 1 when
    Python must see every break (a trigger that watches breaks), the breaks that may first reach a
    patch-count stop (``stepping.plan``), ``inf`` for none."""
    max_batch: float = math.inf
    """End the call after a step that breaks more springs than this (a degenerate event)."""
    patch_goal: int = 0
    """The patches a patch-count stop asks (of at least ``min_patch_size`` bases), where that stop
    alone sets ``break_budget`` (0: none).  A backend that labels patches inside its call may, when
    the breaks reach the budget, count them and go on to a new budget while there are fewer (each
    break adds at most one patch); one that does not ends the call there, and Python counts."""
    min_patch_size: int = 7
    """The least patch ``patch_goal`` counts (read only with a goal)."""
    compiled: bool = True
    """Whether the integrator and the growth law have compiled work (else one step in Python)."""

    threads: int = 1
    """Threads the call may share its work among (``Numerics.threads``: 0 = the backend decides);
    the result does not depend on it."""

    @property
    def h(self) -> float:
        """The step where the call begins."""
        return (1 << (self.levels - self.halvings)) * self.h_min

    @property
    def accept_load(self) -> float:
        """Where the call begins: a step whose load exceeds this is refused (:func:`limits`)."""
        return limits(self.over, self.halvings, self.levels)[0]

    @property
    def report_load(self) -> float:
        """Where the call begins: a kept step whose load exceeds this ends the call (:func:`limits`)."""
        return limits(self.over, self.halvings, self.levels)[1]

    def clock(self) -> np.ndarray:
        """The call's clock as the backends take it, ``[ticks, halvings, levels, may_double]`` (int64);
        a call leaves in it the ticks and halvings it ends with."""
        return np.array([self.ticks, self.halvings, self.levels, int(self.may_double)], dtype=np.int64)


def limits(over: float, halvings: int, levels: int) -> tuple[float, float]:
    """``(accept_load, report_load)`` at ``halvings`` of ``levels``: a load over ``over`` is refused
    while the step may still be halved, and reported (kept, the call ended) at the smallest step."""
    return (over if halvings < levels else math.inf), (over if halvings >= levels else math.inf)


def ends_call(finite, load, accept_load, report_load, candidate, broke, broken, break_budget, max_batch, stop_here):
    """Whether a call ends after a step: the step went non-finite or its load passed ``accept_load``
    (it is undone) or ``report_load`` (it is kept, and recorded), the rule named a ``candidate`` for
    the breakers to judge in Python, it ``broke`` springs and the call's breaks so far (``broken``)
    reach ``break_budget``, or it broke more than ``max_batch``, or it reached the call's time limit
    or doubled where the call may not go on (``stop_here``).  Scalars only: the numba backend
    compiles this into its kernel, the others call it."""
    return (not finite or load > accept_load or load > report_load or candidate or broke > 0 and (broken >= break_budget or broke > max_batch)
            or stop_here)


def doubles(halvings, load, end_tick, size) -> bool:
    """Whether the clock doubles the step after a kept step of ``size`` ticks that ends at
    ``end_tick`` with ``load``: at a halved step, quiet (load at most 1), on the grid of the next
    larger step, staying on its grid.  Scalars only, as :func:`ends_call`."""
    return halvings > 0 and load <= 1.0 and end_tick % (size * 2) == 0


@attrs.frozen
class Steps:
    """What one call of :meth:`Backend.steps` did."""

    done: int
    """Steps taken and kept (a step undone for ``accept_load`` or a non-finite state is not counted)."""
    load: float
    """Largest load (the breaker part's) over intact springs after the last step tried, ``-inf`` for
    a part without one; NaN if that step went non-finite (it was undone)."""
    broken: np.ndarray
    """Springs the rule broke, in order of step then id (the caller applies them: ``break_springs``)."""
    step: np.ndarray
    """The step of the call (from 1) each broke in."""
    tension: np.ndarray
    """Each one's tension when it broke."""
    picked: bool = False
    """Whether the rule named a candidate in the last step kept (``Plan.breaks == "candidates"``)."""
    ends: np.ndarray = attrs.field(factory=lambda: np.empty(0, np.int64))
    """The clock, in ticks, at the end of each step kept."""
    halvings: int = 0
    """The step's halvings after the last step kept (the clock may have doubled it in the call)."""
    refused: bool = False
    """Whether the last step tried was refused (and undone): its load over the accepted or NaN."""


class Call:
    """One call of :meth:`Backend.steps` as a backend computes it; :func:`take_steps` drives it."""

    undone = False
    """Whether the last :meth:`take` took its last step back itself (the state before it kept: the
    numba kernel's second buffer or copy), so that no replay is needed."""
    refused = False
    """Whether the last :meth:`take`'s last step was refused (``Plan.over`` at the clock's halvings
    then, or non-finite)."""

    def take(self, n: int) -> tuple[int, float, bool]:
        """Up to ``n`` steps from the state and the clock the call began with (``Plan``), each
        followed by :func:`ends_call`; returns ``(steps taken, the last one's load, whether the
        rule named a candidate in it)``, the last step counted even if it is to be undone (the state
        holds it), its load NaN if it went non-finite.  The clock it ends with: :meth:`result`."""
        raise NotImplementedError

    def undo(self) -> None:
        """The state, and what the call broke, back to where the call began."""
        raise NotImplementedError

    def result(self, done: int, load: float, picked: bool, refused: bool) -> Steps:
        """What the call did, its last :meth:`take` kept (``refused``: whether the step after them
        was tried and refused)."""
        raise NotImplementedError


def take_steps(call: Call, plan: Plan) -> Steps:
    """The one step algorithm: the call's steps; a last step that is refused (over the load the
    clock accepts where it was taken, or non-finite) is taken back — by the call itself, which kept
    the state before it (``Call.undone``), or by replaying the call up to it from its start —
    exact either way, because a step's arithmetic does not depend on where calls begin and end."""
    done, load, picked = call.take(plan.n)
    refused = call.refused
    if refused:
        if call.undone:
            picked = False
        else:
            call.undo()
            picked = done > 1 and call.take(done - 1)[2]
        done -= 1
    return call.result(done, load, picked, refused)


class Backend:
    """The hot loop's operations (see the module's docstring)."""

    name = ""
    expected_work: float | None = None
    """Base-steps the run is expected to take (``stepping.expected_work``; ``None``: not known), set
    by :func:`load`: what a backend weighs a compile it might start against."""
    resin = HOOKEAN
    """The springs' resin law (``bark.contract.parts.ResinPart``), which every tension and force of
    this backend's follows: set once, by the simulation that loads it."""

    def steps(self, state, mech, plan: Plan, tension: np.ndarray) -> Steps:
        """Up to ``plan.n`` whole steps (:func:`take_steps` of :meth:`call`)."""
        return take_steps(self.call(state, mech, plan, tension), plan)

    def call(self, state, mech, plan: Plan, tension: np.ndarray) -> Call:
        """One call's steps (:class:`Call`) as ``plan`` asks, from ``state`` with the mechanics ``mech``: forces,
        the integrator's update, the surface at the growth law's radius, the resin's tensions into ``tension``
        and the breakers' rule and load, each from the strategies' parts."""
        raise NotImplementedError

    def spring_forces(self, state, mech, x: np.ndarray) -> np.ndarray:
        """The force of every intact spring on every base at positions ``x`` (eq. 1, by the resin law), summed
        per base: an array shaped like ``x`` (force units)."""
        raise NotImplementedError

    def measure(self, state, mech, out: np.ndarray) -> bool:
        """Every spring's tension by the resin law (``k(|d| − l)`` for the paper's spring; force units) at the
        state's positions, into ``out``; whether all of them are finite."""
        raise NotImplementedError

    def geometry(self, state, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every spring's vector ``x_j − x_i`` and length, on whole arrays (the array call's)."""
        from bark.model.forces import spring_geometry

        return spring_geometry(x, state._rows("pairs"))

    def constrain(self, state, r_x, r_anchor) -> None:
        """Eq. 9: each base put back on the trunk's surface at radius ``r_x`` (a number or one per base) with its
        radial velocity removed, and each anchor at radius ``r_anchor`` along its fixed direction."""
        raise NotImplementedError

    def patch_labels(self, state) -> np.ndarray:
        """The connected components of the intact springs: one label per base, numbered in order of each
        component's smallest base (int32)."""
        raise NotImplementedError

    def ready(self, kernel: KernelParts) -> bool:
        """Whether a run of ``kernel`` can start at once, with nothing to compile first."""
        return True


AUTO_WORK = 3e6
"""Base-steps below which ``auto`` takes numpy: numba's start in a fresh process (importing it,
loading its compiled code) costs more than it saves a base-step (at 3000 bases, with adaptive
stepping) — the break-even point of the two, measured when it was set."""


AUTO_COMPILE_WORK = 5e7
"""Expected base-steps (``stepping.expected_work``) below which ``auto`` runs a lone simulation on
numpy rather than first compile numba's kernel for it.  The compile is paid once per combination
of parts; numpy costs more than numba a base-step; and the estimate can be several times low (the
whole tree's is), so below this bound numpy costs at most about what the compile would (the three
as measured on 2-core machines when it was set; ``bark bench`` measures them).  A process that runs
many simulations (a sweep's or a fit's worker, :func:`expect_many`) compiles regardless: its runs
share the cost."""

LOG = logging.getLogger("bark")
_MANY = [False]


def expect_many() -> None:
    """Tell ``auto`` that this process will run many simulations (a worker of a sweep or a fit):
    a kernel compiled for the first is then worth its compile whatever one run's length."""
    _MANY[0] = True


def runs_many() -> bool:
    """Whether this process runs many simulations (:func:`expect_many`)."""
    return _MANY[0]


@attrs.frozen
class KernelParts:
    """What a run's stepping kernel is made of, as ``auto`` asks whether it is compiled already
    (``Backend.ready``): the parts (``None`` where a strategy has none: the run then steps in
    Python), the declared per-spring fields, the threads asked for and the bases at the start."""

    integrator: IntegratorPart | None
    breaker: BreakerPart | None
    growth: GrowthPart | None
    resin: object
    columns: tuple[str, ...]
    threads: int
    n_bases: int


def _numba_available() -> bool:
    return importlib.util.find_spec("numba") is not None  # without importing it (a noticeable share of a start)


def available(name: str) -> bool:
    """Whether the concrete backend ``name`` can run here."""
    return name == "numpy" or (name == "numba" and _numba_available())


def resolve(name: str, work: float | None = None) -> str:
    """The concrete backend ``name`` stands for.  ``auto``: numba if installed, unless the run is
    expected to be short (``work`` base-steps under ``AUTO_WORK``) and numba is not loaded in this
    process yet: then numpy.  The two give the same results to the bit, so the choice is one of speed
    alone."""
    if name not in BACKENDS:
        raise BarkError("{0}: must be one of " + ", ".join(BACKENDS), Ref("run", "backend", name))
    if name == "auto":
        if not _numba_available():
            return "numpy"
        started = "numba" in sys.modules  # its start is paid already (a sweep, a benchmark)
        return "numba" if started or work is None or work >= AUTO_WORK else "numpy"
    if name == "numba" and not _numba_available():
        raise BarkError("{0} but numba is not installed: pip install numba, or use the numpy backend",
                        Ref("run", "backend", name))
    return name


def load(name: str, work: float | None = None, kernel: KernelParts | None = None) -> Backend:
    """A new instance of the backend ``name`` stands for (``resolve``; its module imported only when
    asked for; its compiled code is shared, its work buffers are this instance's: one per simulation).
    ``auto`` with the run's ``kernel``: numpy where numba would first have to compile that kernel and
    the run is too short to repay it (:data:`AUTO_COMPILE_WORK`), unless this process runs many."""
    concrete = resolve(name, work)
    try:
        module = importlib.import_module(f"bark.engine.kernels.{concrete}_backend")
    except (ImportError, OSError) as err:  # numba installed but unusable here (no cache folder, a broken install)
        if concrete != "numba":
            raise
        if name != "auto":
            raise BarkError(f"{{0}} cannot be loaded here ({type(err).__name__}: {err}): use the numpy backend",
                            Ref("run", "backend", name)) from err
        warnings.warn(f"the numba backend cannot be loaded here ({type(err).__name__}: {err}): running on numpy, "
                      "with the same results, more slowly", BarkWarning, stacklevel=2)
        module = importlib.import_module("bark.engine.kernels.numpy_backend")
    backend = module.BACKEND_CLASS()
    if (name == "auto" and backend.name == "numba" and kernel is not None and not _MANY[0] and work is not None
            and work < AUTO_COMPILE_WORK and not backend.ready(kernel)):
        LOG.info("running on numpy, with the same results: this run is too short to repay compiling numba's kernel "
                 "for it first (tens of seconds, once); `bark compile` or --backend numba compiles it")
        backend = importlib.import_module("bark.engine.kernels.numpy_backend").BACKEND_CLASS()
    backend.expected_work = work
    return backend
