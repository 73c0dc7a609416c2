"""A standard-linear-solid (Zener) resin: a spring k in parallel with a Maxwell arm of stiffness
ratio·k whose own rest length ``arm`` relaxes toward the length with time constant ``tau``."""
import attrs
from bark.contract import Declared, Resin, ResinPart, positive


def zener_tension(length, rest, k, arm, params):
    return k * (length - rest) + params[0] * k * (length - arm)


def arm_relaxed(length, rest, h, arm, params):
    return ((arm * params[1] + length * h) / (params[1] + h),)  # backward Euler: stable for any step


@attrs.frozen(kw_only=True)
class Zener(Resin):
    """Stiff at once (k + ratio·k), softening to k over ``tau`` (time units) as the arm relaxes."""

    ratio: float = attrs.field(default=1.0, validator=positive)
    tau: float = attrs.field(default=50.0, validator=positive)
    declares = (Declared(name="arm", per="spring", unit="length", start="rest", doc="the Maxwell arm's rest length"),)

    def part(self) -> ResinPart:
        return ResinPart(tension=zener_tension, reads=("arm",), evolve=arm_relaxed, writes=("arm",),
                         params=[self.ratio, self.tau], stiffness=1.0 + self.ratio)
