"""Built-in growth laws: the trunk radius as a function of time (eq. 9)."""

from __future__ import annotations

import math

import attrs
import numpy as np

from bark._validate import non_negative, positive
from bark.strategies import Growth

__all__ = ["SqrtGrowth", "LinearGrowth"]


@attrs.frozen(kw_only=True)
class SqrtGrowth(Growth):
    """``r(t) = r0 + G·√t`` — the paper's secondary growth (eq. 9)."""

    r0: float = attrs.field(default=0.2, validator=positive)
    """Initial trunk radius r_i (Table 2: 0.2 = 6 cm)."""
    G: float = attrs.field(default=0.014, validator=non_negative)
    """Growth constant, length / time^½ (Table 2: 0.014 vertical, 0.011 reticulate, 0.007 diamond)."""

    def radius(self, t: float, z: np.ndarray) -> float:
        return self.r0 + self.G * math.sqrt(t)


@attrs.frozen(kw_only=True)
class LinearGrowth(Growth):
    """``r(t) = r0 + G·t`` — constant radial growth rate."""

    r0: float = attrs.field(default=0.2, validator=positive)
    """Initial trunk radius."""
    G: float = attrs.field(default=0.014, validator=non_negative)
    """Growth rate, length / time."""

    def radius(self, t: float, z: np.ndarray) -> float:
        return self.r0 + self.G * t
