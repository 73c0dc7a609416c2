"""Built-in breakers."""

from __future__ import annotations

import attrs
import numpy as np

from bark.model import physics
from bark.contract.parts import BreakerPart
from bark.contract.strategies import Breaker
from bark.validators import non_negative, positive

__all__ = ["ThresholdBreaker", "ProbabilisticBreaker", "stretched"]


def stretched(tension, params):
    """Whether a spring is stretched (the probabilistic breaker's candidates)."""
    return tension > 0.0


@attrs.frozen(kw_only=True)
class ThresholdBreaker(Breaker):
    """The paper's rule: an intact spring breaks when its tension ``k(|d| − l)`` exceeds its own
    threshold ``state.fmax`` (per spring, never collapsed to per base).  Deterministic.  Its part is
    the rule itself (``bark.model.physics.over_threshold``), so springs break inside the stepping kernel
    and ``select`` follows from the same function; its load is ``tension / f_max``, which adaptive
    stepping keeps from passing 1 by more than the overshoot tolerance."""

    def part(self) -> BreakerPart:
        return BreakerPart(rule=physics.over_threshold, reads=("tension", "fmax"),
                           load=physics.threshold_load, load_reads=("tension", "inv_fmax"))


@attrs.frozen(kw_only=True)
class ProbabilisticBreaker(Breaker):
    """Stochastic breaking, in the spirit of Skjeltorp & Meakin (1988): a stretched spring breaks
    at a rate that rises steeply with its load ``L = tension / fmax``::

        rate(L) = nu · L**eta          (L > 0; compressed springs never break)
        P(break within a step of length h) = 1 − exp(−h · rate(L))

    A hazard rate rather than a per-step probability, so that the breaking statistics do not
    depend on the step size (as h → 0).  Large ``eta`` approaches the threshold rule: at ``eta = 20``
    a spring at 90 % of its threshold breaks 8× more slowly than at 100 %, at 110 % 6.7× faster.
    Every check draws one uniform number per stretched intact spring from the simulation's seeded
    generator, in spring order: the same seed gives the same breaks.

    Its part names the candidates (every stretched spring) and has no load: a hazard rate gives the
    same breaking statistics whatever the step (as h → 0), so landing a step on a load of 1 means
    nothing to it, and it does not steer the step.  ``select`` draws in Python after every step.
    """

    nu: float = attrs.field(default=10.0, validator=positive)
    """Breaking rate of a spring exactly at its threshold, per time unit (1 = 88.5 days)."""
    eta: float = attrs.field(default=20.0, validator=non_negative)
    """Exponent of the load: how sharply the rate rises through the threshold."""

    def part(self) -> BreakerPart:
        return BreakerPart(rule=stretched, reads=("tension",), decides=False)

    def select(self, state, tension: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        candidates = np.flatnonzero(state.intact & (tension > 0.0))
        load = tension[candidates] / state.fmax[candidates]
        p = -np.expm1(-state.h * self.nu * load**self.eta)
        return candidates[rng.random(candidates.size) < p]
