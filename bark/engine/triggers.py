"""Triggers: when an analyzer, a writer or a recorder acts (after HOOMD-blue's triggers).

A trigger looks at the simulation after a step and says whether it fires now: ``fires(sim)``.  It
also says when it will next be due, so that the simulation can end a compiled run of quiet steps
exactly there (``next_step(sim)``, ``next_time(sim)``; ``None`` = no such bound), and whether it
must see every step that breaks springs (``watches_breaks()``; among these, only ``OnEvent``).
Triggers compose: ``a & b``, ``a | b``, ``~a``.

===========================  ===============================================================
``Periodic(steps, phase=0)``  every ``steps`` steps (step_count % steps == phase)
``Every(time, start=0)``      each time simulated time reaches start + k·time (once per k)
``At(times)``                 when simulated time first reaches each of ``times``
``OnEvent("first-break")``    once, after the first step that breaks a spring; also
                              ``"break"`` (every step that breaks springs) and
                              ``"degenerate"`` (every degenerate event)
===========================  ===============================================================

Triggers with memory (``Every``, ``At``, ``OnEvent``) are small mutable objects: give each action
its own.
"""

from __future__ import annotations

import math

import attrs

from bark.validators import non_negative, one_of, positive, positive_int

__all__ = ["Trigger", "Periodic", "Every", "At", "OnEvent", "And", "Or", "Not"]


class Trigger:
    """Base: ``fires(sim) -> bool`` after each step; ``next_step``/``next_time`` bound the next call."""

    def fires(self, sim) -> bool:  # pragma: no cover - abstract
        """Whether the action this trigger guards runs now, asked once after each step (a trigger with memory,
        such as :class:`Every`, counts the asking)."""
        raise NotImplementedError

    def next_step(self, sim) -> int | None:
        """The next step count at which it may fire, so a kernel call ends there; ``None``: no bound by steps."""
        return None

    def next_time(self, sim) -> float | None:
        """The next simulated time at which it may fire, so a kernel call ends there; ``None``: no bound by time."""
        return None

    def watches_breaks(self) -> bool:
        """Whether this trigger must see every step that breaks springs (``OnEvent``).  If none does,
        a compiled kernel may break springs and keep going without returning.  The base says
        ``True``: a trigger of your own may look at anything, so it sees every break unless it says
        otherwise."""
        return True

    def __and__(self, other: "Trigger") -> "Trigger":
        return And(self, other)

    def __or__(self, other: "Trigger") -> "Trigger":
        return Or(self, other)

    def __invert__(self) -> "Trigger":
        return Not(self)


@attrs.define
class Periodic(Trigger):
    """Fires every ``steps`` steps: when ``step_count % steps == phase``."""

    steps: int = attrs.field(validator=positive_int)
    phase: int = attrs.field(default=0, validator=non_negative)

    def watches_breaks(self) -> bool:
        """No: it counts steps, not breaks."""
        return False

    def fires(self, sim) -> bool:
        """Whether this step's count is ``phase`` modulo ``steps``."""
        return sim.step_count % self.steps == self.phase % self.steps

    def next_step(self, sim) -> int:
        """The next step count that is ``phase`` modulo ``steps``."""
        n = sim.step_count + 1
        return n + (self.phase - n) % self.steps


@attrs.define
class Every(Trigger):
    """Fires each time the simulated time reaches ``start + k·time`` (once per k, even when a step
    passes several)."""

    time: float = attrs.field(validator=positive)
    start: float = attrs.field(default=0.0, validator=non_negative)
    _next_k: int = attrs.field(default=0, init=False)

    def _due(self) -> float:
        return self.start + self._next_k * self.time

    def watches_breaks(self) -> bool:
        """No: it watches the time."""
        return False

    def fires(self, sim) -> bool:
        """Whether the time has reached the next due time; it then counts every due time passed, firing once."""
        eps = 1e-9 * sim.clock.h
        if sim.state.t < self._due() - eps:
            return False
        # once per crossing, even if a step jumped over several due times
        self._next_k = max(self._next_k + 1, math.floor((sim.state.t + eps - self.start) / self.time) + 1)
        return True

    def next_time(self, sim) -> float:
        """The next due time, ``start + k·time``."""
        return self._due()


@attrs.define
class At(Trigger):
    """Fires when the simulated time first reaches each of ``times`` (once each, in order)."""

    times: tuple[float, ...] = attrs.field(converter=lambda v: tuple(sorted(float(t) for t in v)))
    _i: int = attrs.field(default=0, init=False)

    def watches_breaks(self) -> bool:
        """No: it watches the time."""
        return False

    def fires(self, sim) -> bool:
        """Whether the time has reached the next of ``times``; it then passes every one reached, firing once."""
        eps = 1e-9 * sim.clock.h
        fired = False
        while self._i < len(self.times) and sim.state.t >= self.times[self._i] - eps:
            self._i += 1
            fired = True
        return fired

    def next_time(self, sim) -> float | None:
        """The next of ``times`` not yet reached; ``None`` when all are."""
        return self.times[self._i] if self._i < len(self.times) else None


@attrs.define
class OnEvent(Trigger):
    """Fires after a step with ``event``: ``first-break`` (once, the first step that breaks a spring),
    ``break`` (every step that breaks springs) or ``degenerate`` (every degenerate event)."""

    event: str = attrs.field(validator=one_of("first-break", "break", "degenerate"))
    _seen_breaks: int = attrs.field(default=0, init=False)
    _seen_events: int = attrs.field(default=0, init=False)
    _done: bool = attrs.field(default=False, init=False)

    def fires(self, sim) -> bool:
        """Whether the step just taken had the event (the breaks and degenerate events since it last asked)."""
        if self.event == "degenerate":
            n = sum(e["kind"] == "degenerate" for e in sim.events)
            fired, self._seen_events = n > self._seen_events, n
            return fired
        broke = sim.n_broken > self._seen_breaks
        self._seen_breaks = sim.n_broken
        if self.event == "break":
            return broke
        if broke and not self._done:
            self._done = True
            return True
        return False


def _min(a, b):
    return b if a is None else a if b is None else min(a, b)


@attrs.define
class And(Trigger):
    """Fires when both ``a`` and ``b`` fire (``a & b``; both are asked every time, so that triggers
    with memory stay in step)."""

    a: Trigger
    b: Trigger

    def fires(self, sim) -> bool:
        """Whether both fire (both asked)."""
        fa, fb = self.a.fires(sim), self.b.fires(sim)  # both asked: triggers with memory stay in step
        return fa and fb

    def next_step(self, sim):
        """The earlier of the two bounds by steps."""
        return _min(self.a.next_step(sim), self.b.next_step(sim))

    def next_time(self, sim):
        """The earlier of the two bounds by time."""
        return _min(self.a.next_time(sim), self.b.next_time(sim))

    def watches_breaks(self) -> bool:
        """Whether either watches breaks."""
        return self.a.watches_breaks() or self.b.watches_breaks()


@attrs.define
class Or(And):
    """Fires when ``a`` or ``b`` fires (``a | b``; both asked)."""

    def fires(self, sim) -> bool:
        """Whether either fires (both asked)."""
        fa, fb = self.a.fires(sim), self.b.fires(sim)
        return fa or fb


@attrs.define
class Not(Trigger):
    """Fires when ``a`` does not (``~a``); due at any step."""

    a: Trigger

    def fires(self, sim) -> bool:
        """Whether ``a`` does not fire."""
        return not self.a.fires(sim)

    def watches_breaks(self) -> bool:
        """Whether ``a`` watches breaks."""
        return self.a.watches_breaks()

    def next_step(self, sim):
        """The next step: a negation may be due at any step."""
        return sim.step_count + 1  # a negation may be due at any step
