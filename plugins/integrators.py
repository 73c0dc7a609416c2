"""Built-in integrators."""

from __future__ import annotations

import attrs

from bark.strategies import Integrator

__all__ = ["EulerCromer"]


@attrs.frozen(kw_only=True)
class EulerCromer(Integrator):
    """Semi-implicit (symplectic) Euler, the paper's method (eqs. 7–8)::

        v ← v + F(x, v)/m · dt
        x ← x + v · dt

    First order; stable while ``dt`` is below ``h_max = (√(β² + 4ω²) − β)/ω²`` with ``β = b/m`` and
    ``ω² = λ_max(K)/m`` (NOTES.md §3; ≈ 0.369 for Table 2's values).
    """

    def step(self, state, dt: float) -> None:
        state.v += state.forces() * (dt / state.mechanics.m)
        state.x += state.v * dt
