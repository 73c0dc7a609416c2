"""
A resin law of one's own
========================

The paper's springs are Hookean, their stiffness fixed.  Suppose the resin between leaf bases cures:
each spring's stiffness starts at ``k`` when it is made and rises toward ``final·k`` over a time
``tau``.  Written with :mod:`bark.contract`, that law is a strategy of a few lines: the stiffness
factor is a per-spring field the law declares (starting at 1), its tension and its curing are
compiled into the stepping kernel as bark's own laws are, and it runs, checkpoints and resumes like
them.  Here it replaces the Hookean resin of the reticulate regime (900 leaf bases, to time 300),
curing slowly and fast; the lines printed say what each changes.  (The example plugin's Zener law,
``examples/plugin/``, is another; ``examples/paper/README.md``, "What the resin does", measures
bark's own viscoelastic and plastic laws on the three regimes at full size.)
"""

import attrs
import matplotlib.pyplot as plt

import bark
from bark.contract import Declared, Resin, ResinPart, positive
from bark_cli.draw import PatternData, draw_pattern


def cured_tension(length, rest, k, cure, params):
    return k * cure * (length - rest)


def curing(length, rest, h, cure, params):  # toward params[0] over params[1], backward Euler: stable for any step
    return (cure + (params[0] - cure) * (h / (params[1] + h)),)


@attrs.frozen(kw_only=True)
class Curing(Resin):
    """Hookean, each spring's stiffness rising from k, when it is made, toward ``final``·k over ``tau``."""

    final: float = attrs.field(default=3.0, validator=positive)
    tau: float = attrs.field(default=100.0, validator=positive)
    declares = (Declared(name="cure", per="spring", unit="1", start=1.0, doc="the spring's stiffness over k"),)

    def part(self) -> ResinPart:
        return ResinPart(tension=cured_tension, reads=("cure",), evolve=curing, writes=("cure",),
                         params=[self.final, self.tau], stiffness=max(1.0, self.final))


scene = bark.Scene.from_toml("reticulate", {"lattice": {"n_bases": 900}, "run": {"until_time": 300.0}})
fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), layout="constrained")
for ax, resin in zip(axes, (None, Curing(tau=300.0), Curing(tau=30.0))):
    if resin is not None:  # a strategy of one's own, given as an instance: no entry point needed here
        scene = attrs.evolve(scene, strategies={**scene.strategies, "resin": resin})
    outcome = bark.run(scene)
    s = outcome.summary
    label = "Hookean" if resin is None else f"curing to 3k over tau = {resin.tau:g}"
    draw_pattern(ax, PatternData.of(outcome.sim, 7), 7, title=f"{label}: {s['n_patches']} patches")
    ax.set_xlabel("arc length r·θ (m)", fontsize=8)
    ax.set_ylabel("height z (m, stretched)" if resin is None else "", fontsize=8)
    print(f"{label}: {s['n_broken']} springs broken, {s['n_patches']} patches, mean orientation "
          f"{s['mean_orientation_deg']:.1f}° (SD {s['circular_sd_deg']:.1f}°), anisotropy {s['mean_anisotropy']:.3f}")
