"""bark — grow a virtual grasstree trunk and let its bark-like layer of leaf bases crack.

The model is Dale, Runions, Hobill & Prusinkiewicz (2014), "Modelling biomechanics of bark
patterning in grasstrees": leaf bases on a phyllotactic lattice, joined by springs that break as the
trunk grows in girth; the patches left are the bark's pattern.

A run from Python, as ``bark simulate`` makes it (a shipped scene by name, or a TOML file, with
settings of one's own over it; without a folder the run stays in memory):

>>> import bark
>>> scene = bark.Scene.from_toml("vertical", {"lattice": {"n_bases": 600}, "run": {"until_patches": 20}})
>>> outcome = bark.run(scene)
>>> outcome.stop_reason, outcome.summary["n_patches"]
('patches', 20)
>>> round(outcome.summary["mean_orientation_deg"])   # degrees from horizontal: 90 is up the trunk
98

``bark.run(scene, "runs/vertical")`` writes the run's files, checkpoints and pictures there, and
``bark.resume("runs/vertical")`` goes on with an interrupted run, to the bit.  ``Scene``, ``run``
and ``resume`` are loaded when first used; the drawing functions (into axes of one's own) are in
``bark_cli.draw``, which imports matplotlib.  Strategies of one's own subclass the kinds in
:mod:`bark.contract` (one import has them all).
"""

from bark.errors import BarkError, NonFiniteStateError
from bark.model.forces import Mechanics
from bark.model.lattice import Lattice
from bark.engine.simulation import BreakLog, Simulation, Stop
from bark.model.state import State
from bark.contract.strategies import Analysis, Analyzer, Breaker, Growth, Integrator
from bark.version import __version__

__all__ = [
    "Scene",
    "run",
    "resume",
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

_LAZY = {"Scene": ("bark.engine.scene", "Scene"), "run": ("bark.studies.runner", "run"),
         "resume": ("bark.studies.runner", "resume")}
"""The notebook API, imported when first asked for: ``import bark`` stays as light as it was."""


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        module, attribute = _LAZY[name]
        value = getattr(importlib.import_module(module), attribute)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'bark' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
