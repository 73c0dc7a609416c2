"""A power-law growth law: the trunk radius ``r0 + G·t^a``."""
import attrs

from bark.contract.parts import GrowthPart
from bark.contract.strategies import Growth
from bark.validators import non_negative, positive


def power_radius(t, z, p):
    return p[0] + p[1] * t ** p[2]  # p = (r0, G, a)


@attrs.frozen(kw_only=True)
class PowerLawGrowth(Growth):
    """``r(t) = r0 + G·t^a`` (length units, time units): a = 0.5 is the paper's square root."""

    r0: float = attrs.field(default=0.2, validator=positive)
    G: float = attrs.field(default=0.014, validator=non_negative)
    a: float = attrs.field(default=0.5, validator=positive)

    def part(self) -> GrowthPart:  # its compiled work; radius(t, z) follows from it
        return GrowthPart(radius=power_radius, params=(self.r0, self.G, self.a), uniform=True)
