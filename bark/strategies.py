"""The four kinds of strategy a :class:`~bark.simulation.Simulation` is composed of.

Each kind is a small attrs class with **one verb**.  To write your own, subclass the base, decorate
it with ``@attrs.frozen(kw_only=True)``, declare every parameter as a validated field (no logic in
``__init__``), implement the verb, and register the class under the kind's entry-point group
(``bark.growth``, ``bark.integrator``, ``bark.breaker``, ``bark.analyzer``).  The built-in strategies
in ``bark_plugins`` are registered the same way.

=============  ==============================  =======================================================
kind           verb                            contract
=============  ==============================  =======================================================
Growth         ``radius(t, z) -> r``           trunk radius at time ``t`` for heights ``z`` (array, or
                                               a scalar that broadcasts).  Pure: no state, no rng.
Integrator     ``step(state, dt) -> None``     advance ``state.x`` and ``state.v`` by ``dt`` in place
                                               using ``state.forces(x, v)``.  Touches nothing else: the
                                               simulation advances ``t``, applies the surface
                                               constraint and breaks springs.  Explicit methods also
                                               override ``stability_limit(state)`` (largest stable dt).
Breaker        ``select(state, tension, rng)`` ids (int array) of *intact* springs to break now.
               ``-> ids``                      Must not change anything; ``rng`` is the simulation's
                                               one seeded generator (draw from it only).
Analyzer       ``analyze(points, patches)``    statistics of a pattern, returned as an
               ``-> Analysis``                 :class:`Analysis` (summary dict + tables).  Reads only.
=============  ==============================  =======================================================
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import attrs
import numpy as np

__all__ = ["Strategy", "Growth", "Integrator", "Breaker", "Analyzer", "Analysis", "KINDS"]


@attrs.frozen(kw_only=True)
class Strategy(abc.ABC):
    """Common base: parameters are attrs fields, so ``attrs.evolve(s, G=0.01)`` makes a variant."""

    kind: ClassVar[str] = ""

    def params(self) -> dict[str, Any]:
        """Constructor keywords of this strategy, as given (for summaries and sweeps)."""
        return attrs.asdict(self, recurse=False)


@attrs.frozen(kw_only=True)
class Growth(Strategy):
    """Secondary growth: how the trunk radius changes with time (and, for bulges, with height)."""

    kind: ClassVar[str] = "growth"

    @abc.abstractmethod
    def radius(self, t: float, z: np.ndarray) -> np.ndarray | float:
        """Trunk radius at time ``t`` at heights ``z``."""

    def adjust_thresholds(self, z: np.ndarray, fmax: np.ndarray) -> np.ndarray:
        """Breaking thresholds of springs whose midpoints are at heights ``z`` (called once, when the
        simulation is built).  The default leaves them as they are; a law with regions of their own
        material (bulges) overrides it."""
        return fmax


@attrs.frozen(kw_only=True)
class Integrator(Strategy):
    """Time integration of the equations of motion (eqs. 5–8)."""

    kind: ClassVar[str] = "integrator"
    quiet_kernel: ClassVar[str | None] = None
    """Name of a backend function that takes many steps of this method in one compiled call (see
    ``Simulation.advance``); ``None`` (the default) means one ``step`` per call, always correct."""

    @abc.abstractmethod
    def step(self, state, dt: float) -> None:
        """Advance ``state.x`` and ``state.v`` by ``dt`` in place."""

    def stability_limit(self, state) -> float:
        """Largest ``dt`` for which this method is stable on ``state``; ``inf`` if unconditionally stable.

        The simulation refuses (or, with automatic stepping, sub-steps) a ``dt`` above it."""
        return float("inf")


@attrs.frozen(kw_only=True)
class Breaker(Strategy):
    """Which intact springs break now."""

    kind: ClassVar[str] = "breaker"
    overload_only: ClassVar[bool] = False
    """Set ``True`` if ``select`` only ever picks springs whose tension exceeds their ``fmax``: the
    simulation then skips the call while no intact spring is over its threshold."""
    kernel_rule: ClassVar[str | None] = None
    """Name of a compiled rule that picks exactly what ``select`` picks, so that a compiled kernel
    may break springs itself and keep stepping (``Simulation.advance``).  The one rule the kernels
    know is ``"over-threshold"``: every intact spring whose tension exceeds its ``fmax``.  It is
    trusted only when the class that names it also defines ``select``: a subclass that overrides
    ``select`` without naming a rule again gets ``select`` called, as every other breaker does."""

    @abc.abstractmethod
    def select(self, state, tension: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Ids of intact springs to break, given every spring's current ``tension``."""


@attrs.frozen(kw_only=True)
class Analysis:
    """What an analyzer returns: a flat summary and named tables (lists of row dicts)."""

    summary: dict[str, Any]
    tables: dict[str, list[dict[str, Any]]] = attrs.field(factory=dict)


@attrs.frozen(kw_only=True)
class Analyzer(Strategy):
    """Statistics of a bark pattern.

    Works on points and patch labels alone, so the same analyzer serves simulated bark and bark
    digitised from photographs.  ``points`` are either 3-D positions on the trunk, shape ``(n, 3)``
    (each patch is then mapped to its tangent plane), or 2-D positions already in a plane
    ``(horizontal, vertical)``, shape ``(n, 2)``.  ``patches`` holds one integer label per point.
    """

    kind: ClassVar[str] = "analyzer"

    @abc.abstractmethod
    def analyze(self, points: np.ndarray, patches: np.ndarray) -> Analysis:
        """Statistics of the pattern given by ``points`` and their patch labels."""


KINDS: tuple[str, ...] = ("growth", "integrator", "breaker", "analyzer")
