"""Built-in resin laws: how the resin between two leaf bases (a spring of the layer) answers its stretch.

Each is a :class:`~bark.contract.strategies.Resin` whose part (:class:`~bark.contract.parts.ResinPart`)
gives the spring's tension from its length and rest length, and, for a resin that flows, how its
rest length moves each step.  Flow is integrated by backward Euler (``l ← (l·τ + L·h) / (τ + h)``
for a relaxation of time constant τ), stable and monotone for any step.  Lengths in length units
(1 = 0.3 m), forces in force units, times in time units (1 = 88.5 days).
"""

from __future__ import annotations

import attrs
import numpy as np

from bark.contract.parts import ResinPart
from bark.contract.strategies import Resin
from bark.model import physics
from bark.validators import in_range, non_negative, positive

__all__ = ["Hookean", "Maxwell", "Plastic", "Nonlinear", "relaxed", "yielded", "cubic"]


def relaxed(length, rest, h, params):
    """A Maxwell resin's rest length after a step ``h``: relaxed toward the length with time
    constant ``params[0]`` (backward Euler), written as a step from the rest length so that, in
    floating point too, it never passes the length and a spring at rest stays exactly at rest."""
    tau = params[0]
    return (rest + (length - rest) * (h / (tau + h)),)


def yielded(length, rest, h, params):
    """A plastic resin's rest length after a step: where the strain ``L/l − 1`` passes the yield
    strain ``params[0]``, the rest length follows the length, by the share ``1 / (1 + params[1])``
    of the excess (hardening 0: the strain stays at the yield; large: hardly flows)."""
    grown = 1.0 + params[0]
    return (rest + np.maximum(length - rest * grown, 0.0) / (grown * (1.0 + params[1])),)


def cubic(length, rest, k, params):
    """A non-linear resin's tension: ``k·δ·(1 + β·(δ/l)²)`` with ``δ = L − l`` — stiffening for
    β > 0 (as a fibre network straightens), softening for β < 0; Hooke's law at small strain."""
    d = length - rest
    s = d / rest
    return k * d * (1.0 + params[0] * s * s)


@attrs.frozen(kw_only=True)
class Hookean(Resin):
    """The paper's spring (eq. 1): tension ``k(|d| − l)``, its rest length fixed when it is made."""

    def part(self) -> ResinPart:
        """Compiled: ``k(|d| − l)``, no flow."""
        return ResinPart(tension=physics.hookean)


@attrs.frozen(kw_only=True)
class Maxwell(Resin):
    """A viscoelastic resin (a Maxwell element): Hookean, its rest length relaxing toward its length
    with time constant ``tau``, so that a spring held stretched loses its tension over ``tau``."""

    tau: float = attrs.field(default=100.0, validator=positive)
    """Relaxation time (time units; 1 = 88.5 days)."""

    def part(self) -> ResinPart:
        """Compiled: Hooke's tension; the rest length relaxes (:func:`relaxed`) every step."""
        return ResinPart(tension=physics.hookean, evolve=relaxed, writes=("rest",), params=[self.tau])


@attrs.frozen(kw_only=True)
class Plastic(Resin):
    """A plastic resin: Hookean up to the yield strain, beyond which its rest length follows the
    length (flow), less the share ``hardening`` holds back."""

    yield_strain: float = attrs.field(default=0.1, validator=positive)
    """Strain ``|d|/l − 1`` at which the resin starts to flow."""
    hardening: float = attrs.field(default=0.0, validator=non_negative)
    """0: perfectly plastic (the strain stays at the yield); larger: less of the excess flows."""

    def part(self) -> ResinPart:
        """Compiled: Hooke's tension; the rest length yields (:func:`yielded`) every step."""
        return ResinPart(tension=physics.hookean, evolve=yielded, writes=("rest",),
                         params=[self.yield_strain, self.hardening])


@attrs.frozen(kw_only=True)
class Nonlinear(Resin):
    """A non-linear elastic resin, ``k·δ·(1 + β·(δ/l)²)``: stiffening (β > 0) or softening (β < 0)."""

    beta: float = attrs.field(default=1.0, validator=in_range(-1.0, 100.0))
    """β: how the stiffness changes with strain (at strain s the tangent stiffness is k(1 + 3βs²));
    at least −1, so that a stretched spring pulls at any strain below 1."""

    def part(self) -> ResinPart:
        # the largest tangent stiffness up to strain 1, for the stability bound
        """Compiled: the cubic law (:func:`cubic`), its stiffness bound the largest tangent stiffness up to
        strain 1."""
        return ResinPart(tension=cubic, params=[self.beta], stiffness=1.0 + 3.0 * max(self.beta, 0.0))
