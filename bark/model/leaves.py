"""The plant's leaves, for pictures and the 3-D mesh (paper, "Visual presentation of the model", Fig. 10).

"Leaves were modelled as generalized cylinders with the area of the diamond-shaped cross-section
decreasing towards the endpoints ... Leaf bending due to gravity was approximated by gradually
turning the leaf downwards along its axis (Prusinkiewicz and Lindenmayer, 1990).  As the leaves aged,
they turned brown and to simulate the role of a forest fire the majority of the older leaves were
eventually removed, leaving only the base."

Each leaf grows from its leaf base: from the organs on the apical dome (Ridley's placement,
:class:`bark.model.tree.Apex`) and from the bases on the trunk.  Its age is the time since it passed
from the dome onto the trunk (negative on the dome: its place on the dome says how young it is).  Its
axis is a curve in the plane through the trunk's axis and the leaf's base: it leaves the base at an
elevation that falls with age (upright at the dome's tip, level at its base, lower on the trunk: a
crown radiating from the apex),
and each of ``segments`` equal segments turns it down by ``droop · cos(elevation)`` (a tropism towards
the ground, stronger as the leaf ages: the bending of Prusinkiewicz and Lindenmayer).  A leaf is
green while young, yellows and browns up to ``lifespan`` after it reached the trunk, and is dead
after that; of the leaves dead for less than another ``lifespan`` the fires leave a share ``kept``
(chosen by each leaf's id, the same at every age of the tree), hanging down along the trunk as a
skirt below the crown, and take all the others, leaving their bases.

Geometry only: pure functions of the time, the packing, the dome and the positions of the bases,
in model units.  Nothing is simulated or stored.
"""

from __future__ import annotations

import math

import attrs
import numpy as np

from bark.validators import in_range, non_negative, positive, positive_int

__all__ = ["Leaves", "LeafSet", "leaves_at", "plant_leaves", "leaf_rings", "leaf_faces"]

GREEN, STRAW, BROWN = (np.array(c) for c in ((0.30, 0.47, 0.13), (0.70, 0.62, 0.33), (0.42, 0.29, 0.17)))
"""A leaf's colours: young, at the end of its life, dead (RGB in [0, 1])."""


@attrs.frozen(kw_only=True)
class Leaves:
    """The ``[leaves]`` table: how the ``leaves`` effect draws the plant's leaves."""

    length: float = attrs.field(default=2.5, validator=in_range(1e-6, 100.0))
    """A grown leaf's length, length units (2.5 = 0.75 m; grasstree leaves are 0.6–1 m)."""
    width: float = attrs.field(default=0.012, validator=in_range(1e-6, 10.0))
    """A leaf's widest cross-section, length units (0.012 = 3.6 mm); its thickness is ``thickness``
    times that."""
    thickness: float = attrs.field(default=0.6, validator=in_range(0.01, 1.0))
    """The diamond cross-section's thickness over its width."""
    lifespan: float = attrs.field(default=8.25, validator=positive)
    """Time a leaf stays alive after it passes onto the trunk (time units; 8.25 = 2 years)."""
    kept: float = attrs.field(default=0.1, validator=in_range(0.0, 1.0))
    """Share of the dead leaves the fires left (the others are gone, their bases bare)."""
    droop: float = attrs.field(default=0.3, validator=non_negative)
    """How far gravity turns a grown, horizontal leaf down per segment (radians); a young leaf turns
    less, a dead one more."""
    segments: int = attrs.field(default=8, validator=positive_int)
    """Segments along each leaf's axis (each a ring of the generalized cylinder)."""


@attrs.frozen(eq=False)
class LeafSet:
    """Leaves at one time: each leaf's axis, widths along it, colour and the id of its base."""

    axes: np.ndarray
    """Points along each axis, ``(n, segments + 1, 3)``, from the base to the tip (model units)."""
    widths: np.ndarray
    """The cross-section's width at each point, ``(n, segments + 1)``."""
    colours: np.ndarray
    """RGB in [0, 1], ``(n, 3)``."""
    ids: np.ndarray
    """The id of each leaf's base (organ), ``(n,)``."""

    def __len__(self) -> int:
        return len(self.ids)


def _kept(ids: np.ndarray, share: float) -> np.ndarray:
    """Whether the fires left each dead leaf: a fixed draw per id (splitmix64's mixing of the id, so
    that neighbours in id — and so in angle, on a phyllotactic spiral — draw independently), the same
    at every age of the tree."""
    z = ids.astype(np.uint64) + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(float) / 2.0**53 < share


def leaves_at(settings: Leaves, t: float, ids: np.ndarray, base: np.ndarray, age: np.ndarray,
              on_dome: np.ndarray) -> LeafSet:
    """The leaves of the bases ``ids`` at positions ``base`` (``(n, 3)``), each ``age`` since it passed
    onto the trunk (for a leaf on the dome, ``on_dome`` says how far down it is, 0 at the tip to 1 at
    its base, and ``age`` is ignored; NaN for a leaf on the trunk).  Bases whose leaf the fires took
    are left out."""
    ids, base = np.asarray(ids), np.asarray(base, dtype=float)
    age, on_dome = np.asarray(age, dtype=float), np.asarray(on_dome, dtype=float)
    dome = ~np.isnan(on_dome)
    life = np.where(dome, 0.0, np.clip(age / settings.lifespan, 0.0, None))  # 0 young .. 1 end of life, > 1 dead
    keep = dome | (life <= 1.0) | ((life <= 2.0) & _kept(ids, settings.kept))
    ids, base, life, on_dome, dome = ids[keep], base[keep], life[keep], on_dome[keep], dome[keep]
    dead = life > 1.0
    down = np.nan_to_num(on_dome)
    # where it leaves its base: upright at the dome's tip, level at its base, lower as it ages on the trunk,
    # hanging when dead (a crown of leaves radiating from the apex, a skirt of dead ones below it)
    elevation = np.radians(np.where(dome, 88.0 - 85.0 * down, np.where(dead, -70.0, -40.0 * np.minimum(life, 1.0))))
    bend = settings.droop * np.where(dome, 0.2 + 0.6 * down, np.where(dead, 1.5, 0.8 + 0.6 * np.minimum(life, 1.0)))
    length = settings.length * np.where(dome, np.minimum(1.0, 0.6 + 20.0 * down), 1.0)  # the youngest still growing
    outward = base[:, :2] / np.maximum(np.hypot(base[:, 0], base[:, 1]), 1e-300)[:, None]
    n, k = len(ids), settings.segments
    axes = np.empty((n, k + 1, 3))
    axes[:, 0] = base
    step = length / k
    for j in range(k):  # each segment along the current heading, then the heading turned down
        axes[:, j + 1, :2] = axes[:, j, :2] + (step * np.cos(elevation))[:, None] * outward
        axes[:, j + 1, 2] = axes[:, j, 2] + step * np.sin(elevation)
        elevation = np.maximum(elevation - bend * np.cos(elevation), -0.5 * math.pi)
    s = np.linspace(0.0, 1.0, k + 1)
    widths = settings.width * np.sin(math.pi * (0.1 + 0.9 * s))[None, :] * np.ones((n, 1))
    widths[:, -1] = 0.0  # a point at the tip
    f = np.clip(life, 0.0, 1.0)[:, None]
    colours = np.where(dead[:, None], BROWN, (1.0 - f) * GREEN + f * STRAW)
    return LeafSet(axes=axes, widths=widths, colours=colours, ids=ids)


def leaf_rings(leaves: LeafSet, thickness: float) -> np.ndarray:
    """The corners of the diamond cross-section at each point of each leaf's axis, ``(n, segments + 1,
    4, 3)``: ± half the width across the leaf (horizontally, around the trunk) and ± half the
    ``thickness`` times the width in the plane of the axis.  Successive rings, corner to corner, make
    the generalized cylinder's surface (:func:`leaf_faces`)."""
    axes = leaves.axes
    heading = np.diff(axes, axis=1)
    heading = np.concatenate([heading, heading[:, -1:]], axis=1)  # the tip keeps the last segment's heading
    heading /= np.maximum(np.linalg.norm(heading, axis=-1, keepdims=True), 1e-300)
    across = np.stack([-heading[..., 1], heading[..., 0], np.zeros(heading.shape[:2])], axis=-1)
    flat = np.linalg.norm(across, axis=-1, keepdims=True)
    radial = axes[:, :1, :].copy()
    radial[..., 2] = 0.0
    fallback = np.stack([-radial[..., 1], radial[..., 0], np.zeros(radial.shape[:2])], axis=-1)  # a vertical leaf
    fallback /= np.maximum(np.linalg.norm(fallback, axis=-1, keepdims=True), 1e-300)
    across = np.where(flat > 1e-12, across / np.maximum(flat, 1e-300), np.broadcast_to(fallback, across.shape))
    normal = np.cross(heading, across)
    half = 0.5 * leaves.widths[..., None]
    return np.stack([axes + half * across, axes + thickness * half * normal,
                     axes - half * across, axes - thickness * half * normal], axis=2)


def leaf_faces(n: int, segments: int) -> np.ndarray:
    """The quads of ``n`` leaves' surfaces as indices into their rings flattened (``leaf_rings``
    reshaped to ``(-1, 3)``): for each leaf, segment and side of the diamond, ``(n·segments·4, 4)``."""
    ring = np.arange(4)
    j = np.arange(segments)[:, None]
    one = np.stack([4 * j + ring, 4 * j + np.roll(ring, -1), 4 * (j + 1) + np.roll(ring, -1), 4 * (j + 1) + ring], axis=-1)
    per_leaf = 4 * (segments + 1)
    return (np.arange(n)[:, None, None, None] * per_leaf + one[None]).reshape(-1, 4)


def plant_leaves(settings: Leaves, apex, growth, t: float, x: np.ndarray) -> LeafSet:
    """Every leaf of the tree at time ``t``: those of the organs on the dome (``apex``, a
    :class:`bark.model.tree.Apex`, at the growth law's radius at its base) and those of the ``len(x)``
    bases on the trunk, at their positions ``x``.  The trunk of the start crossed before the run, one
    base every ``1 / join_rate`` (``Packing.crossing`` carried back)."""
    packing = apex.packing
    lattice = packing.lattice
    radius = float(np.asarray(growth.radius(t, float(packing.top(t)))).reshape(-1)[0])
    organs, where = apex.organs(t, radius)
    j, tip = float(apex.top_index(t)), apex.tip_index(t, radius)
    down = 1.0 - (organs - j) / max(tip - j, 1.0)  # 0 at the tip, 1 at the dome's base
    ids = np.arange(len(x))
    rate = lattice.join_rate if lattice.join_rate > 0 else 1.0
    crossed = (ids - (lattice.initial - 1)) / rate
    later = ids >= lattice.initial
    if later.any():
        crossed[later] = packing.crossing(ids[later])
    age = t - crossed
    young = age <= 2.0 * settings.lifespan  # older ones are gone whatever the draw
    return leaves_at(settings, t, np.concatenate([ids[young], organs]), np.concatenate([x[young], where]),
                     np.concatenate([age[young], np.zeros(len(organs))]),
                     np.concatenate([np.full(int(young.sum()), np.nan), down]))
