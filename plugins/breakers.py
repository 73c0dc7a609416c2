"""Built-in breakers."""

from __future__ import annotations

from typing import ClassVar

import attrs
import numpy as np

from bark.strategies import Breaker

__all__ = ["ThresholdBreaker"]


@attrs.frozen(kw_only=True)
class ThresholdBreaker(Breaker):
    """The paper's rule: an intact spring breaks when its tension ``k(|d| − l)`` exceeds its own
    threshold ``state.fmax`` (per spring, never collapsed to per base).  Deterministic."""

    overload_only: ClassVar[bool] = True

    def select(self, state, tension: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return np.flatnonzero(state.intact & (tension > state.fmax))
