"""
Fig. 9's parameter montage, small
=================================

The paper's Fig. 9 lays the pattern out over the growth constant G (across) and the springs'
threshold f_max (up).  The same grid here, each cell one run on 900 leaf bases to time 400: slow
growth and strong springs leave the layer whole or nearly, fast growth and weak springs crack it
into many patches.
``bark sweep`` runs this grid at full size in parallel, resumably, with its montage.
"""

import matplotlib.pyplot as plt

import bark
from bark_cli.draw import PatternData, draw_pattern

G = (0.007, 0.011, 0.014)
F_MAX = (0.0028, 0.005, 0.008)
fig, axes = plt.subplots(len(F_MAX), len(G), figsize=(11, 7), layout="constrained", squeeze=False)
for i, g in enumerate(G):
    for j, f_max in enumerate(F_MAX):
        settings = {"lattice": {"n_bases": 900}, "growth": {"G": g}, "mechanics": {"f_max": f_max},
                    "run": {"until_time": 400.0, "until_patches": None}}
        outcome = bark.run(bark.Scene.from_toml("vertical", settings))
        ax = axes[len(F_MAX) - 1 - j, i]  # f_max grows upwards
        s = outcome.summary
        draw_pattern(ax, PatternData.of(outcome.sim, 7), 7, title=f"{s['n_patches']} patch{'' if s['n_patches'] == 1 else 'es'}")
        ax.set_xlabel(f"G = {g:g}" if j == 0 else "", fontsize=9)
        ax.set_ylabel(f"f_max = {f_max:g}" if i == 0 else "", fontsize=9)
        ax.tick_params(labelsize=6)
        print(f"G {g:g}, f_max {f_max:g}: {s['n_broken']} broken, {s['n_patches']} patches")
