"""Built-in analyzers."""

from __future__ import annotations

import attrs
import numpy as np

from bark.validators import positive_int
from bark.analysis.network import measure
from bark.analysis.patches import patch_statistics, pattern_summary
from bark.contract.strategies import Analysis, Analyzer

__all__ = ["PatchAnalyzer", "NetworkAnalyzer"]


@attrs.frozen(kw_only=True)
class PatchAnalyzer(Analyzer):
    """Patches = connected components of intact springs; each patch of at least ``min_size`` bases is
    mapped to its tangent plane and characterised by PCA (orientation, anisotropy 2A − 1); the
    summary gives the axial circular mean and SD of orientation over patches (``bark.analysis.patches``)."""

    min_size: int = attrs.field(default=7, validator=positive_int)
    """Patches with fewer bases are dropped (the paper: 7)."""

    def analyze(self, points: np.ndarray, patches: np.ndarray) -> Analysis:
        """One row per patch of at least ``min_size`` points (size, centroid, orientation, anisotropy) and the
        paper's pattern statistics of them."""
        rows = patch_statistics(points, patches, self.min_size)
        return Analysis(summary=pattern_summary(rows), patches=rows)


@attrs.frozen(kw_only=True)
class NetworkAnalyzer(Analyzer):
    """The statistics beyond the paper's (``bark.analysis.network``): the distribution of patch sizes
    (power law against log-normal) and, where the pattern has springs, its crack network — junctions
    in the (n̄, v̄) plane, T and Y junctions, the cracks' nematic order and director, and each spring
    offset's share of the cracks against its share of the springs (the table ``lattice_bias``).  A
    photograph, without springs, gets the sizes alone."""

    min_size: int = attrs.field(default=7, validator=positive_int)
    """Patches with fewer bases are left out (the paper: 7)."""

    reads_springs = True

    def analyze(self, points, patches, springs) -> Analysis:
        """The patch-size law and, with springs, the crack network's statistics, its table ``lattice_bias`` one
        row per spring offset."""
        given = () if springs is None else (springs.pairs, springs.intact, springs.offsets)
        summary = measure(points, patches, self.min_size, *given)
        bias = summary.pop("lattice_bias", None) or {}
        return Analysis(summary=summary, tables={"lattice_bias": [{"offset": int(o), **row} for o, row in bias.items()]}
                        if bias else {})
