"""bark — grow a virtual grasstree trunk and let its bark-like layer of leaf bases crack.

The model is Dale, Runions, Hobill & Prusinkiewicz (2014), "Modelling biomechanics of bark
patterning in grasstrees".  See ARCHITECTURE.md for the data model, the loop and the plugin contract.
"""

from bark.errors import BarkError, NonFiniteStateError
from bark.model.forces import Mechanics
from bark.model.lattice import Lattice
from bark.engine.simulation import BreakLog, Simulation, Stop
from bark.model.state import State
from bark.contract.strategies import Analysis, Analyzer, Breaker, Growth, Integrator
from bark.version import __version__

__all__ = [
    "Analysis",
    "Analyzer",
    "BarkError",
    "BreakLog",
    "Breaker",
    "Growth",
    "Integrator",
    "Lattice",
    "Mechanics",
    "NonFiniteStateError",
    "Simulation",
    "State",
    "Stop",
    "__version__",
]
