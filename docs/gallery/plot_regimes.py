"""
Table 2's three regimes, small
==============================

The paper's three regimes of the trunk segment (Fig. 7): vertical, reticulate and diamond, each
grown here on 900 leaf bases (the shipped scenes have 3000) to a third of its patches and drawn into axes of one's own.
"""

import matplotlib.pyplot as plt

import bark
from bark.analysis.pattern import Pattern
from bark_cli.draw import PatternData, draw_pattern, draw_radial

fig = plt.figure(figsize=(12, 7.5), layout="constrained")
# each regime's stop scaled to the smaller lattice: a third of Fig. 7's 110, 115 and 80 patches
STOPS = {"vertical": (33, 1000.0), "reticulate": (35, 3000.0), "diamond": (24, 5000.0)}
for k, (name, (patches, cap)) in enumerate(STOPS.items()):
    scene = bark.Scene.from_toml(name, {"lattice": {"n_bases": 900}, "run": {"until_patches": patches, "until_time": cap}})
    outcome = bark.run(scene)
    stats = Pattern.of_simulation(outcome.sim).statistics(7)
    pattern = fig.add_subplot(2, 3, k + 1)
    draw_pattern(pattern, PatternData.of(outcome.sim, 7), 7, title=name)
    # the full labels name units and scales for a figure of its own; three side by side need short ones
    pattern.set_xlabel("arc length r·θ (m)", fontsize=8)
    pattern.set_ylabel("height z (m, stretched)" if k == 0 else "", fontsize=8)
    radial = fig.add_subplot(2, 3, k + 4, projection="polar")
    draw_radial(radial, stats)
    radial.set_title(f"{name}: orientation × anisotropy", fontsize=9)
    print(f"{name}: {stats}")
