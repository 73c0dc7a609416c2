"""An example bark plugin, outside the bark package.

``MostOverloadedBreaker`` subclasses bark's threshold breaker with the quasi-static rule of lattice
fracture models: of the springs over their threshold, only the ``max_per_step`` most overloaded
(largest tension / threshold) break in a step; the others wait for the next step, by which time the
load may have moved elsewhere.  Writing ``select`` again, it gives up the threshold breaker's compiled
rule (its choice depends on the other springs, which no per-spring rule can say); it promises again
that it breaks only springs over their threshold (``overload_only``), so bark's kernel still takes
many steps per call and hands it the state after a step that overloads a spring.

Install it (``pip install examples/plugin``) and ``bark strategies`` lists it; select it with
``bark simulate --breaker most-overloaded --set breaker.max_per_step=2``.
"""

from __future__ import annotations

from typing import ClassVar

import attrs
import numpy as np

from bark.validators import positive_int
from bark_plugins.breakers import ThresholdBreaker

__all__ = ["MostOverloadedBreaker"]


@attrs.frozen(kw_only=True)
class MostOverloadedBreaker(ThresholdBreaker):
    """Break only the ``max_per_step`` intact springs most over their thresholds."""

    overload_only: ClassVar[bool] = True

    max_per_step: int = attrs.field(default=1, validator=positive_int)
    """How many springs may break in one step, the most overloaded first."""

    def select(self, state, tension: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        over = super().select(state, tension, rng)
        if over.size <= self.max_per_step:
            return over
        load = tension[over] / state.fmax[over]
        keep = np.argsort(-load, kind="stable")[: self.max_per_step]
        return np.sort(over[keep])
