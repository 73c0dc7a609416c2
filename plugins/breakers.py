"""Built-in breakers."""

from __future__ import annotations

import math
from typing import ClassVar

import attrs
import numpy as np

from bark.errors import BarkError, Ref
from bark.model import physics
from bark.contract.parts import BreakerPart
from bark.contract.strategies import Breaker, Made
from bark.validators import in_range, non_negative, optional, positive, table_of

__all__ = ["Thresholds", "ThresholdBreaker", "ProbabilisticBreaker", "stretched"]


def stretched(tension, params):
    """Whether a spring is stretched (the probabilistic breaker's candidates)."""
    return tension > 0.0


@attrs.frozen(kw_only=True)
class Thresholds(Breaker):
    """A breaker whose springs each have their own threshold (``state.fmax``), set when the spring is
    made: the material's ``f_max`` (``[mechanics]``), spread log-normally (``spread``) or drawn from a
    Weibull law (``weibull_shape``, ``weibull_scale``), then moved towards each region's own value by
    the region's weight (``regions``; the growth law says where its regions are: a bulge is a
    ``bulge``).  Quenched disorder: drawn once per spring, never again.  (The checks that the two
    ways to spread them are not both given are ``weibull_shape``'s and ``weibull_scale``'s validators:
    a subclass that defines those fields again gives its own.)"""

    spread: float = attrs.field(default=0.0, validator=in_range(0.0, 10.0))
    """Relative spread of the thresholds: each is ``f_max · exp(s·n − s²/2)`` with ``n`` the spring's
    standard normal number (``Made.noise``), log-normal with mean ``f_max`` and coefficient of
    variation ≈ ``s``.  0: all equal.  At most 10: beyond that some thresholds underflow to zero."""
    weibull_shape: float | None = attrs.field(default=None, validator=optional(in_range(0.01, 1e12)))
    """Instead, draw each threshold from a Weibull law of this shape (modulus) m: the weakest-link law
    of brittle strength (small m: very unequal springs; m ≈ 10: a few percent).  At least 0.01: below
    that its mean's Γ(1 + 1/m) overflows."""
    weibull_scale: float | None = attrs.field(default=None, validator=optional(positive))
    """The Weibull law's scale (force units); ``None``: the scale whose mean is the threshold before
    (``f_max``)."""
    regions: dict[str, float] = attrs.field(factory=dict, validator=table_of(positive), hash=False)
    """Thresholds by region of the trunk (force units), e.g. ``{ bulge = 0.006 }`` (the paper's
    Table 1): a spring made in a region moves from its threshold to the region's by the region's
    weight there (1 inside, 0 outside, smooth between); regions not named keep the material's."""

    moved_in: ClassVar[dict] = {("mechanics", "fmax_spread"): ("spread", 0.0),
                                ("mechanics", "fmax_weibull_shape"): ("weibull_shape", None)}

    @weibull_shape.validator
    def _one_way_to_spread(self, attribute, value) -> None:
        if value is not None and self.spread > 0:
            raise BarkError("{0} and {1} are two ways to spread the thresholds: give one",
                            Ref(None, "spread", self.spread), Ref(None, "weibull_shape", value))

    @weibull_scale.validator
    def _scale_of_a_shape(self, attribute, value) -> None:
        if value is not None and self.weibull_shape is None:
            raise BarkError("{0} is the scale of a Weibull law: give its shape too ({1})",
                            Ref(None, "weibull_scale", value), Ref(None, "weibull_shape", None))

    def thresholds(self, made: Made, fmax: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Each new spring's threshold: ``fmax`` spread log-normally or drawn from the Weibull law, then moved
        towards its region's own value by the region's weight."""
        if self.weibull_shape is not None:
            m = self.weibull_shape
            w = rng.weibull(m, len(made))
            fmax = self.weibull_scale * w if self.weibull_scale is not None else fmax * w / math.gamma(1.0 + 1.0 / m)
        else:
            s = self.spread
            fmax = fmax * np.exp(s * made.noise - 0.5 * s * s)
        for name, weight in made.regions:
            if name in self.regions:
                fmax = fmax + weight * (self.regions[name] - fmax)
        return fmax


@attrs.frozen(kw_only=True)
class ThresholdBreaker(Thresholds):
    """The paper's rule: an intact spring breaks when its tension ``k(|d| − l)`` exceeds its own
    threshold ``state.fmax`` (per spring, never collapsed to per base).  Deterministic.  Its part is
    the rule itself (``bark.model.physics.over_threshold``), so springs break inside the stepping kernel
    and ``select`` follows from the same function; its load is ``tension / f_max``, which adaptive
    stepping keeps from passing 1 by more than the overshoot tolerance."""

    def part(self) -> BreakerPart:
        """The paper's rule, compiled: tension over ``fmax``, its load ``tension / fmax``."""
        return BreakerPart(rule=physics.over_threshold, reads=("tension", "fmax"),
                           load=physics.threshold_load, load_reads=("tension", "inv_fmax"))


@attrs.frozen(kw_only=True)
class ProbabilisticBreaker(Thresholds):
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
        """Compiled: every stretched spring a candidate, judged by :meth:`select` in Python."""
        return BreakerPart(rule=stretched, reads=("tension",), decides=False)

    def select(self, state, tension: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The stretched intact springs that break in this step, each with probability ``1 − exp(−h·nu·L**eta)``
        (one uniform number each, in spring order)."""
        candidates = np.flatnonzero(state.intact & (tension > 0.0))
        load = tension[candidates] / state.fmax[candidates]
        p = -np.expm1(-state.h * self.nu * load**self.eta)
        return candidates[rng.random(candidates.size) < p]
