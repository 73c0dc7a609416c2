"""A power-law growth law: the trunk radius ``r0 + G·t^a``."""
import attrs
import numpy as np

from bark.contract.strategies import Growth
from bark.validators import non_negative, positive


def power_radius(t, z, p):
    return p[0] + p[1] * t ** p[2]  # p = (r0, G, a)


@attrs.frozen(kw_only=True)
class PowerLawGrowth(Growth):
    """``r(t) = r0 + G·t^a`` (length units, time units): a = 0.5 is the paper's square root."""

    compiled = staticmethod(power_radius)  # the compiled form; radius(t, z) follows from it
    uniform = True  # the same radius at every height
    r0: float = attrs.field(default=0.2, validator=positive)
    G: float = attrs.field(default=0.014, validator=non_negative)
    a: float = attrs.field(default=0.5, validator=positive)

    def compiled_params(self) -> np.ndarray:
        return np.array([self.r0, self.G, self.a])
