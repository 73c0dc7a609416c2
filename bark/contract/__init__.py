"""The plugin contract: the strategy base classes, the compiled parts they declare, the registry.

What a plugin author subclasses and what bark's own built-ins (``bark_plugins``) use, no more:
imports the model and the base modules only.  A plugin's vocabulary is importable from here in one
line — the kinds (:mod:`.strategies`), their parts (:mod:`.parts`), the rules and laws a part may
name as they are (:mod:`bark.model.physics`) and the validators of a strategy's keywords
(:mod:`bark.validators`).  A Maxwell resin of one's own, its rest length relaxing toward its length:

>>> import attrs
>>> from bark.contract import Resin, ResinPart, hookean, positive
>>> def relax(length, rest, h, params):             # backward Euler over the time constant params[0]
...     return (rest + (length - rest) * (h / (params[0] + h)),)
>>> @attrs.frozen(kw_only=True)
... class Relaxing(Resin):
...     tau: float = attrs.field(default=100.0, validator=positive)
...     def part(self) -> ResinPart:
...         return ResinPart(tension=hookean, evolve=relax, writes=("rest",), params=[self.tau])
>>> Relaxing(tau=50.0).params()
{'tau': 50.0}
>>> Relaxing(tau=-1.0)
Traceback (most recent call last):
bark.errors.BarkError: tau = -1.0: must be > 0
"""

from bark.contract.parts import BreakerPart, GrowthPart, IntegratorPart, ResinPart
from bark.contract.strategies import (Analysis, Analyzer, Breaker, Declared, Growth, Integrator, Made, Resin, Springs,
                                      Strategy)
from bark.model.physics import hookean, no_breaking, over_threshold, threshold_load, threshold_ratio
from bark.validators import finite, in_range, int_in, non_negative, one_of, optional, positive, positive_int, table_of

__all__ = ["Strategy", "Growth", "Integrator", "Breaker", "Resin", "Analyzer", "Analysis", "Springs", "Declared", "Made",
           "BreakerPart", "GrowthPart", "IntegratorPart", "ResinPart",
           "hookean", "over_threshold", "threshold_load", "threshold_ratio", "no_breaking",
           "finite", "in_range", "int_in", "non_negative", "one_of", "optional", "positive", "positive_int", "table_of"]
