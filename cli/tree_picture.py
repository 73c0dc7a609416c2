"""The whole tree seen from the side (``tree-image`` effect, tree.png; the paper's Fig. 10).

An orthographic view along −y of the trunk's leaf bases — each its rhomboid (``bark.io.mesh``), coloured
by patch, fragments grey, cracks showing as the gaps between bases — with the trunk's outline
(bulges stand out) and the apical dome on top, its leaf bases where Ridley's placement puts them
(``bark.model.tree.Apex``).  Only the half facing the viewer is drawn,
far bases first.  Lengths in metres, the title in years.  A bounded figure: the trunk's height sets
it, at most ``MAX_HEIGHT_IN`` inches.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.collections import PolyCollection

from bark.units import METRES_PER_LENGTH_UNIT, years
from bark_cli.pictures import TreeData
from bark_cli.plot import new_figure, save_figure

MAX_HEIGHT_IN = 12.0
WIDTH_IN = 5.0


def plot_tree(data: TreeData, path: str | Path, min_size: int = 7) -> Path:
    """Draw ``data`` into ``path`` (PNG, atomically)."""
    z_lo = float(data.outline[0, 0])
    z_hi = float(data.dome[:, 1].max())
    half = float(max(data.outline[:, 1].max(), 1e-9)) * 1.15
    height_in = min(MAX_HEIGHT_IN, max(3.0, WIDTH_IN * (z_hi - z_lo) / (2 * half)))
    fig = new_figure(figsize=(WIDTH_IN, height_in + 0.5), dpi=150)
    ax = fig.add_subplot()
    ax.add_collection(PolyCollection(data.polygons, facecolors=data.colours / 255.0, edgecolors="none"))
    zo, ro = data.outline[:, 0], data.outline[:, 1]
    ax.plot(ro, zo, color="0.2", lw=0.6)
    ax.plot(-ro, zo, color="0.2", lw=0.6)
    ax.fill_betweenx(data.dome[:, 1], -data.dome[:, 0], data.dome[:, 0], color="#6b8e23", alpha=0.35, lw=0)
    if len(data.organs):  # the leaf bases still on the dome, where Ridley's placement puts them
        per_organ = (72.0 * WIDTH_IN) ** 2 * 0.25 / len(data.organs)
        ax.scatter(data.organs[:, 0], data.organs[:, 1], s=float(min(4.0, per_organ)), c="#3b5e0b", linewidths=0)
    ax.set_xlim(-half, half)
    ax.set_ylim(z_lo, z_hi + 0.02 * (z_hi - z_lo))
    ax.set_aspect("auto" if height_in == MAX_HEIGHT_IN else "equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("height (m)" + ("" if height_in < MAX_HEIGHT_IN else ", compressed"))
    ax.set_title(f"{years(data.t):.1f} years, {data.n_bases} leaf bases, {data.n_patches} patches "
                 f"(≥ {min_size} bases; fragments grey)", fontsize=8)
    return save_figure(fig, path)


__all__ = ["TreeData", "plot_tree", "METRES_PER_LENGTH_UNIT"]
