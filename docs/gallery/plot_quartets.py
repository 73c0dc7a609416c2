"""
Fig. 8's quartet analysis, small
================================

Four patterns grown here, two of the vertical regime and two of the diamond regime (900 leaf bases
each, seeds 0 and 1), compared as the paper compares simulated bark with photographs (Fig. 8): the
Hellinger distances between their orientation and anisotropy distributions make a quartet whose two
shortest edges, when they share no pattern, pair the four; ``d_P`` (a difference of means in
standard errors) points each pattern at its nearest.  Patterns of one regime should pair.
"""

import matplotlib.pyplot as plt

import bark
from bark.analysis.compare import compare
from bark.analysis.pattern import Pattern
from bark_cli.draw import PatternData, draw_pairing, draw_pattern, draw_quartet

fig = plt.figure(figsize=(12, 11), layout="constrained")
top, bottom = fig.subfigures(2, 1, height_ratios=[1, 3])
stats = []
for k, (regime, patches, seed) in enumerate((("vertical", 33, 0), ("vertical", 33, 1), ("diamond", 24, 0), ("diamond", 24, 1))):
    settings = {"lattice": {"n_bases": 900}, "run": {"until_patches": patches, "until_time": 5000.0, "seed": seed}}
    outcome = bark.run(bark.Scene.from_toml(regime, settings))
    name = f"{regime} {seed}"
    stats.append(Pattern.of_simulation(outcome.sim, name=name).statistics(7))
    ax = top.add_subplot(1, 4, k + 1)
    draw_pattern(ax, PatternData.of(outcome.sim, 7), 7, title=name)
    ax.set_xlabel("arc length r·θ (m)", fontsize=8)  # short labels: four patterns side by side
    ax.set_ylabel("height z (m, stretched)" if k == 0 else "", fontsize=8)

comparison = compare(stats)
axes = bottom.subplots(2, 2)
for row, quantity in zip(axes, ("orientation", "anisotropy")):
    draw_quartet(row[0], comparison, quantity)
    draw_pairing(row[1], comparison, quantity)
for quantity in ("orientation", "anisotropy"):
    print(f"{quantity}: quartet pairs {comparison.quartets[quantity].pairing}, "
          f"d_P nearest {comparison.pairings[quantity].nearest} (valid: {comparison.pairings[quantity].valid})")
