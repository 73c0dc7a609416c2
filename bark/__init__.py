"""bark — grow a virtual grasstree trunk and let its bark-like layer of leaf bases crack.

The model is Dale, Runions, Hobill & Prusinkiewicz (2014), "Modelling biomechanics of bark
patterning in grasstrees".  See ARCHITECTURE.md for the data model, the loop and the plugin contract.
"""

from importlib.metadata import PackageNotFoundError, version

from bark.errors import BarkError, NonFiniteStateError
from bark.forces import Mechanics
from bark.lattice import Lattice
from bark.simulation import BreakLog, Simulation, Stop
from bark.state import State
from bark.strategies import Analysis, Analyzer, Breaker, Growth, Integrator

try:
    __version__ = version("bark")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

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
