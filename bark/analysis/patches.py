"""Patches measured: per-patch statistics, patches as photographs show them, the summary over patches.

Plain arrays in, rows out (points and patch ids, no simulation), so these serve simulated patterns and
patterns digitised from photographs alike; conventions as in :mod:`bark.analysis.circular`.
"""

from __future__ import annotations

import numpy as np

from bark.analysis.pattern import Pattern, PatternStatistics
from bark.model.components import components

__all__ = ["patch_statistics", "window_labels", "pattern_summary"]


def patch_statistics(points: np.ndarray, labels: np.ndarray, min_size: int = 7) -> list[dict]:
    """One row per patch of at least ``min_size`` points: size, centroid, orientation, anisotropy
    (``bark.analysis.pattern.Pattern.patch_table`` as rows).

    ``points`` are 3-D positions on the trunk (mapped per patch to its tangent plane) or 2-D
    positions already in a plane ``(horizontal, vertical)``.  The centroid is reported as
    ``theta_deg`` (angle round the trunk) and ``z`` for 3-D input, ``x``/``y`` for 2-D input.
    """
    return Pattern(points=points, patches=labels).patch_table(min_size).rows()



def window_labels(points: np.ndarray, pairs: np.ndarray, intact: np.ndarray, size: float) -> np.ndarray:
    """Patches as photographs of the trunk show them: the surface unrolled (arc length × height) is
    cut into windows about ``size`` × ``size`` (rows of height ``size``; in each row, a whole number
    of equal windows round the trunk at the row's mean radius, the first at θ = 0), and a patch is a
    connected component of the intact springs whose two bases lie in the same window.  A network of
    strands that joins far away is, in a window, the strands it shows.  Returns a label per base
    (numbered as :func:`components` numbers them)."""
    points = np.asarray(points, dtype=float)
    n = len(points)
    radius = np.hypot(points[:, 0], points[:, 1])
    turn = (np.arctan2(points[:, 1], points[:, 0]) / (2.0 * np.pi)) % 1.0
    row = np.floor((points[:, 2] - (points[:, 2].min() if n else 0.0)) / size).astype(np.int64)  # from the lowest base
    rows, inverse = np.unique(row, return_inverse=True)
    mean_radius = np.bincount(inverse, weights=radius) / np.bincount(inverse)
    across = np.maximum(1, np.rint(2.0 * np.pi * mean_radius / size)).astype(np.int64)[inverse]
    window = inverse * (int(across.max(initial=1)) + 1) + np.minimum((turn * across).astype(np.int64), across - 1)
    pairs = np.asarray(pairs, dtype=np.int64)
    return components(n, pairs, np.asarray(intact, bool) & (window[pairs[:, 0]] == window[pairs[:, 1]]))


def pattern_summary(rows: list[dict]) -> dict:
    """Summary over patches (``bark.analysis.pattern.PatternStatistics`` as the values of summary.json):
    count, axial mean, SD and standard error of orientation, mean, SD and standard error of
    anisotropy, and the share of patches whose orientation lies within 45° of the mean axis (NaN
    where there are no patches)."""
    stats = PatternStatistics.of_values([r["orientation_deg"] for r in rows], [r["anisotropy"] for r in rows])
    return {k: v for k, v in stats.as_dict().items() if k not in ("name", "source", "handedness")}
