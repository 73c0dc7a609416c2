"""
The whole tree, small
=====================

The paper's integrative model (Table 1) at a reduced size — ``whole-tree-small``: the top 16 cm of
trunk over 18 years, 4,500 → 12,000 leaf bases, one bulge, its apical dome and leaves — seen from the
side as ``tree.png`` draws it, the leaves in front of the trunk cut away so that its bark shows: the
patches of the trunk grown in those years, coloured, fragments grey.
"""

import matplotlib.pyplot as plt

import bark
from bark_cli.draw import TreeData, draw_tree

scene = bark.Scene.from_toml("whole-tree-small")
outcome = bark.run(scene)
fig, ax = plt.subplots(figsize=(5, 6), layout="constrained")
draw_tree(ax, TreeData.of(outcome.sim, 7, scene.dome, scene.leaves))
ax.set(xlabel="x (m)", ylabel="height (m)", aspect="equal")
ax.set_title(f"{outcome.summary['n_bases']:,} leaf bases, {outcome.summary['n_patches']} patches, "
             f"{outcome.summary['n_broken']:,} broken springs", fontsize=9)
print(outcome.stop_reason, outcome.summary["n_patches"], "patches")
