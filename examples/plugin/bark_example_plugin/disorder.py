"""Quenched disorder by parastichy: each spring's threshold drawn once, when the spring is made, from
a Weibull law of shape ``m`` whose scale depends on the spring's lattice direction (its index offset)."""
import attrs
import numpy as np
from bark.contract import Breaker, BreakerPart, Declared, over_threshold, positive, positive_int, threshold_ratio


@attrs.frozen(kw_only=True)
class ParastichyWeibull(Breaker):
    """Break a spring when its tension exceeds its own threshold: Weibull(m), of scale ``scale_steep``
    along the parastichy of offset ``steep`` (Table 2's lattice: 34) and ``scale_shallow`` along others."""

    m: float = attrs.field(default=6.0, validator=positive)
    scale_steep: float = attrs.field(default=0.0028, validator=positive)
    scale_shallow: float = attrs.field(default=0.0028, validator=positive)
    steep: int = attrs.field(default=34, validator=positive_int)
    declares = (Declared(name="threshold", per="spring", unit="force", doc="this spring's own threshold"),)

    def initial(self, made, rng):
        scale = np.where(made.offset == self.steep, self.scale_steep, self.scale_shallow)
        return {"threshold": scale * rng.weibull(self.m, len(made))}

    def part(self) -> BreakerPart:  # tension > threshold; its load tension/threshold steers the step
        return BreakerPart(rule=over_threshold, reads=("tension", "threshold"), load=threshold_ratio)
