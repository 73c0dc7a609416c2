"""The whole tree seen from the side (``tree-image`` effect, tree.png; ``tree-series``, tree-series.png:
the paper's Fig. 10).

An orthographic view along −y of the trunk's leaf bases — each its rhomboid (``bark.io.mesh``), coloured
by patch, fragments grey, cracks showing dark between bases — with the trunk's outline (bulges stand
out) and the apical dome on top, its leaf bases where Ridley's placement puts them
(``bark.model.tree.Apex``).  Only the half facing the viewer is drawn, far bases first.  With the
``leaves`` effect, the plant's leaves (``bark.model.leaves``): those behind the trunk first, hidden
by it, then the trunk, then those in front, each a line as wide as the leaf, green when young,
browning with age.  Lengths in metres, the title in years.  A bounded figure: the tree's height sets
it, at most ``MAX_HEIGHT_IN`` inches (a taller tree is drawn with its height axis compressed, said on
the axis).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.collections import LineCollection, PolyCollection

from bark.units import METRES_PER_LENGTH_UNIT, years
from bark_cli.pictures import SeriesData, TreeData
from bark_cli.plot import new_figure, patches, save_figure

MAX_HEIGHT_IN = 12.0
WIDTH_IN = 5.0
TRUNK = "0.22"
"""The trunk's own colour, seen through the cracks between its leaf bases."""


def _extent(data: TreeData) -> tuple[float, float, float]:
    """Half the width, the lowest and the highest height the drawing needs (metres)."""
    z_lo = float(data.outline[0, 0])
    z_hi = float(data.dome[:, 1].max())
    half = float(max(data.outline[:, 1].max(), 1e-9)) * 1.15
    if len(data.leaves):  # the crown, its height and spread; leaves hanging below the trunk's foot are cut there
        half = max(half, 1.05 * float(np.abs(data.leaves[..., 0]).max()))
        z_hi = max(z_hi, float(data.leaves[..., 1].max()))
    return half, z_lo, z_hi


def _leaves(ax, data: TreeData, which: np.ndarray, points_per_metre: float, zorder: float) -> None:
    if not which.any():
        return
    axes = data.leaves[which]
    segments = np.stack([axes[:, :-1], axes[:, 1:]], axis=2).reshape(-1, 2, 2)
    widths = np.maximum(data.leaf_widths[which].ravel() * points_per_metre, 0.25)
    colours = np.repeat(data.leaf_colours[which], axes.shape[1] - 1, axis=0)
    ax.add_collection(LineCollection(segments, linewidths=widths, colors=colours, capstyle="round", zorder=zorder))


def draw_tree(ax, data: TreeData, extent: tuple[float, float, float] | None = None,
              points_per_metre: float | None = None) -> None:
    """Draw ``data`` into ``ax`` within ``extent`` (half the width, the lowest and the highest height,
    metres; default: what the tree needs), its leaves ``points_per_metre`` wide on the page (default:
    from the axes' height): leaves behind, trunk, leaves in front."""
    half, z_lo, z_hi = extent = _extent(data) if extent is None else extent
    if points_per_metre is None:
        points_per_metre = 72.0 * ax.get_position().height * ax.figure.get_figheight() / (z_hi - z_lo)
    zo, ro = data.outline[:, 0], data.outline[:, 1]
    _leaves(ax, data, ~data.leaf_front, points_per_metre, 1.0)
    ax.fill_betweenx(zo, -ro, ro, color=TRUNK, lw=0, zorder=1.5)  # hides the leaves behind; dark in the cracks
    ax.add_collection(PolyCollection(data.polygons, facecolors=data.colours / 255.0, edgecolors="none", zorder=2))
    ax.plot(ro, zo, color="0.2", lw=0.6, zorder=2.1)
    ax.plot(-ro, zo, color="0.2", lw=0.6, zorder=2.1)
    ax.fill_betweenx(data.dome[:, 1], -data.dome[:, 0], data.dome[:, 0], color="#6b8e23", alpha=0.35, lw=0, zorder=2)
    if len(data.organs):  # the leaf bases still on the dome, where Ridley's placement puts them
        per_organ = (72.0 * WIDTH_IN) ** 2 * 0.25 / len(data.organs)
        ax.scatter(data.organs[:, 0], data.organs[:, 1], s=float(min(4.0, per_organ)), c="#3b5e0b", linewidths=0, zorder=2.2)
    _leaves(ax, data, data.leaf_front, points_per_metre, 3.0)
    ax.set_xlim(-half, half)
    ax.set_ylim(z_lo, z_hi + 0.02 * (z_hi - z_lo))


def plot_tree(data: TreeData, path: str | Path, min_size: int = 7) -> Path:
    """Draw ``data`` into ``path`` (PNG, atomically)."""
    extent = _extent(data)
    half, z_lo, z_hi = extent
    height_in = min(MAX_HEIGHT_IN, max(3.0, WIDTH_IN * (z_hi - z_lo) / (2 * half)))
    fig = new_figure(figsize=(WIDTH_IN, height_in + 0.5), dpi=150)
    ax = fig.add_subplot()
    draw_tree(ax, data, extent, 72.0 * height_in / (z_hi - z_lo))
    ax.set_aspect("auto" if height_in == MAX_HEIGHT_IN else "equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("height (m)" + ("" if height_in < MAX_HEIGHT_IN else ", compressed"))
    broken = "" if data.n_broken is None else f", {data.n_broken} broken springs"
    ax.set_title(f"{years(data.t):.1f} years, {data.n_bases:,} leaf bases, {patches(data.n_patches)} "
                 f"(≥ {min_size} bases; fragments grey){broken}", fontsize=8)
    return save_figure(fig, path)


SERIES_COLUMNS = 6
"""The most panels a row of tree-series.png holds; more ages wrap into further rows."""


def plot_tree_series(data: SeriesData, path: str | Path, min_size: int = 7) -> Path:
    """The tree at each age of ``data`` on one scale (the paper's Fig. 10), into ``path``: side by
    side, in rows of at most :data:`SERIES_COLUMNS` panels, read left to right and down."""
    import math

    extents = [_extent(tree) for tree in data.trees]
    z_lo = min(e[1] for e in extents)
    z_hi = max(e[2] for e in extents)
    half = max(e[0] for e in extents)
    n = max(len(data.trees), 1)
    cols = min(n, SERIES_COLUMNS)
    rows = math.ceil(n / cols)
    panel_in = 2.0 * WIDTH_IN / cols * 1.5
    height_in = min(MAX_HEIGHT_IN / rows, max(1.5, panel_in * (z_hi - z_lo) / (2 * half)))
    squeezed = height_in < panel_in * (z_hi - z_lo) / (2 * half)
    fig = new_figure(figsize=(panel_in * cols, rows * (height_in + 0.6) + 0.4), dpi=150)
    grid = fig.subplots(rows, cols, sharex=True, sharey=True, squeeze=False)  # inner panels: no tick labels
    axes = list(grid.ravel())
    for ax, tree in zip(axes, data.trees):
        draw_tree(ax, tree, (half, z_lo, z_hi), 72.0 * height_in / (z_hi - z_lo))
        ax.set_aspect("auto" if squeezed else "equal")
        ax.set_title(f"{years(tree.t):.0f} years: {tree.n_bases:,} bases, {patches(tree.n_patches)}", fontsize=8)
    for ax in axes[len(data.trees):]:  # the last row's empty places
        ax.set_visible(False)
    for row in grid:
        row[0].set_ylabel("height (m)" + (", compressed" if squeezed else ""))
    for ax in axes[max(len(data.trees) - cols, 0):len(data.trees)]:  # the lowest panel of each column
        ax.xaxis.set_tick_params(labelbottom=True)
        ax.set_xlabel("x (m)")
    for ax in axes:
        ax.apply_aspect()  # where the panels end up, so that the heading sits just above them
    top = max(ax.get_position().y1 for ax in axes[:cols])
    fig.text(0.5, top + 0.35 / (rows * (height_in + 0.6) + 0.4), f"The tree as it grew (patches of ≥ {min_size} "
             "bases coloured; fragments grey)", ha="center", va="bottom", fontsize=9)
    return save_figure(fig, path)


__all__ = ["TreeData", "SeriesData", "draw_tree", "plot_tree", "plot_tree_series", "METRES_PER_LENGTH_UNIT"]
