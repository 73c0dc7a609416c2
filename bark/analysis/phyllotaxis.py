"""The paper's checks of the phyllotactic pattern ("Growth simulation", Fig. 4), on the bases' sites."""

from __future__ import annotations

import math

import numpy as np

from bark.analysis.circular import axial_difference, axial_mean
from bark.model.lattice import Lattice
from bark.model.tree import _half_vectors
from bark.units import METRES_PER_LENGTH_UNIT

__all__ = ["phyllotaxis", "lattice_angle"]


def phyllotaxis(lattice: Lattice, anchor: np.ndarray, radius_joined: np.ndarray, rise: np.ndarray | None = None,
                n_lines: int = 16) -> dict:
    """The paper's checks of the phyllotactic pattern ("Growth simulation", Fig. 4), measured on the
    bases' sites (``anchor``, one row per base, consecutive ids), the radius each joined at and the
    rise of the leaves packed then (``bark.model.tree.Packing.rise_of``; default the lattice's):

    * ``leaf_base_area_mm2``: the mean area of the bases' rhomboids, ``2πR·rise`` each (mm²; the
      paper assumed ≈ 30 mm²).
    * ``parastichy_angle_deg``: the acute angle between the two parastichies of the spring offsets
      (55 and 89 in Table 1) — each the axial mean direction of its site-to-site vectors, unrolled on
      the trunk (arc length at the sites' radius, height); the paper measured ≈ 57° on real trunks.
    * ``bases_crossed_front``: leaf bases whose rhomboid a horizontal line crosses on the half of the
      trunk facing a viewer (as in a photograph), averaged over ``n_lines`` heights and four sides.
    * ``bases_side_by_side_front``: half the circumference over a rhomboid's width — the bases seen in
      one horizontal row on that half; the paper reports ≈ 37 (observed) and ≈ 40 (its model).
      ``None`` when rhomboids have no width (a divergence angle that stacks the bases in columns), or
      too little for a finite count.
    """
    anchor = np.asarray(anchor, dtype=float)
    theta = np.arctan2(anchor[:, 1], anchor[:, 0])
    z = anchor[:, 2]
    r_site = np.hypot(anchor[:, 0], anchor[:, 1])
    angles = []
    for o in sorted(lattice.offsets)[:2]:  # slices, not index arrays: 70 000 bases at a few MiB
        arc = theta[o:] - theta[:-o]
        arc += math.pi
        np.remainder(arc, 2 * math.pi, out=arc)
        arc -= math.pi
        arc *= r_site[:-o]
        up = z[o:] - z[:-o]
        angles.append(axial_mean(np.degrees(np.arctan2(up, arc, out=arc), out=arc)))
        del arc, up
    radius_joined = np.asarray(radius_joined, dtype=float)
    rise = np.broadcast_to(lattice.rise if rise is None else np.asarray(rise, dtype=float), radius_joined.shape)
    area = float(np.mean(2.0 * math.pi * radius_joined * rise)) * (1000.0 * METRES_PER_LENGTH_UNIT) ** 2
    u, v = _half_vectors(lattice, radius_joined, rise)  # the corners are ±u, ±v: extents without them
    reach = np.maximum(np.abs(u[:, 1]), np.abs(v[:, 1]))
    low, high = z - reach, z + reach
    width = 2.0 * np.maximum(np.abs(u[:, 0]), np.abs(v[:, 0]))
    del u, v, reach
    lines = np.linspace(np.quantile(z, 0.1), np.quantile(z, 0.9), n_lines)
    facing = [np.cos(theta - side) > 0 for side in (0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi)]
    counts = [np.count_nonzero((low < h) & (h < high) & front) for h in lines for front in facing]
    # rhomboids of no width (a divergence angle that stacks the bases in columns), or too little: no count
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        side_by_side = float(np.mean(math.pi * radius_joined / width))
    return {"leaf_base_area_mm2": area,
            "parastichy_angle_deg": float(abs(axial_difference(angles[0], angles[1]))),
            "parastichy_directions_deg": [float(a) for a in angles],
            "bases_crossed_front": float(np.mean(counts)),
            "bases_side_by_side_front": side_by_side if math.isfinite(side_by_side) else None}


def lattice_angle(lattice: Lattice, radius, rise) -> np.ndarray:
    """The acute angle (degrees) between the exact lattice vectors of the two spring offsets (arc
    length ``radius · (o·φ mod 2π)``, height ``o · rise``) of leaves packed at ``rise`` on a trunk of
    ``radius``: the parastichy angle of bases as they cross from the dome, before jitter."""
    radius, rise = np.broadcast_arrays(np.asarray(radius, dtype=float), np.asarray(rise, dtype=float))
    o1, o2 = sorted(lattice.offsets)[:2]
    angle = [np.degrees(np.arctan2(o * rise, radius * math.remainder(o * lattice.turn, 2.0 * math.pi))) for o in (o1, o2)]
    return np.abs(axial_difference(angle[0], angle[1]))
