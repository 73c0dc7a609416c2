"""A strain breaker: a spring breaks when it is stretched past ``eps`` of its rest length."""
import attrs

from bark.contract.parts import BreakerPart
from bark.contract.strategies import Breaker
from bark.validators import positive


def over_strain(length, rest, params):
    return length / rest - 1.0 > params[0]  # |d|/l − 1 > eps


def strain_load(length, rest, params):
    return (length / rest - 1.0) / params[0]  # 1 at breaking: adaptive stepping holds it to 1 + tol


@attrs.frozen(kw_only=True)
class StrainBreaker(Breaker):
    """Break an intact spring when its strain ``|d|/l − 1`` exceeds ``eps`` (dimensionless)."""

    eps: float = attrs.field(default=0.05, validator=positive)

    def part(self) -> BreakerPart:
        return BreakerPart(rule=over_strain, load=strain_load, reads=("length", "rest"), params=[self.eps])
