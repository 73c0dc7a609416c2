"""An example bark plugin, outside the bark package.

Six strategies, each registered under bark's entry-point groups exactly as bark's own:

* ``cracks-by-parastichy`` (:mod:`.cracks`): an analyzer that reads the springs — per lattice
  direction, the cracked share and the spacing of cracks — beside bark's own (``[[analyzer]]``).

* ``strain`` (:mod:`.strain`): a spring breaks when its strain ``|d|/l − 1`` exceeds ``eps``; its
  compiled part runs inside bark's kernel, and adaptive stepping holds its own load (strain / eps).
* ``parastichy-weibull`` (:mod:`.disorder`): quenched disorder — each spring's own threshold, a field
  the breaker declares, drawn once when the spring is made from a Weibull law whose scale depends
  on the spring's parastichy; its part reads the field inside the kernel.
* ``zener`` (:mod:`.zener`): a resin law, the standard linear solid — a spring in parallel with a
  Maxwell arm whose own rest length (a declared field) relaxes every step, compiled.
* ``power-law`` (:mod:`.power_law`): the trunk radius ``r0 + G·t^a``, compiled.
* ``most-overloaded`` (here): bark's threshold breaker with the quasi-static rule of lattice fracture
  models: of the springs over their threshold, only the ``max_per_step`` most overloaded (largest
  tension / threshold) break in a step; the others wait for the next step, by which time the load
  may have moved elsewhere.  Its choice depends on the other springs, which no per-spring rule can
  say, so it writes ``select``; its part declares the threshold rule as naming *candidates*, so
  bark's kernel still takes many steps per call and hands it the state after a step that overloads
  a spring.

Install it (``pip install examples/plugin``) and ``bark strategies`` lists them; select one with
``bark simulate --breaker strain --set breaker.eps=0.03`` or ``--growth power-law``.
"""

from __future__ import annotations

import attrs
import numpy as np

from bark.contract.parts import BreakerPart
from bark.validators import positive_int
from bark_example_plugin.power_law import PowerLawGrowth
from bark_example_plugin.strain import StrainBreaker
from bark_plugins.breakers import ThresholdBreaker

__all__ = ["MostOverloadedBreaker", "StrainBreaker", "PowerLawGrowth"]


@attrs.frozen(kw_only=True)
class MostOverloadedBreaker(ThresholdBreaker):
    """Break only the ``max_per_step`` intact springs most over their thresholds."""

    max_per_step: int = attrs.field(default=1, validator=positive_int)
    """How many springs may break in one step, the most overloaded first."""

    def part(self) -> BreakerPart:
        return attrs.evolve(super().part(), decides=False)  # the threshold names candidates; select decides

    def select(self, state, tension: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        over = super().select(state, tension, rng)
        if over.size <= self.max_per_step:
            return over
        load = tension[over] / state.fmax[over]
        keep = np.argsort(-load, kind="stable")[: self.max_per_step]
        return np.sort(over[keep])
