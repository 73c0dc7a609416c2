"""Built-in analyzers."""

from __future__ import annotations

import attrs
import numpy as np

from bark.validators import positive_int
from bark.analysis.patches import patch_statistics, pattern_summary
from bark.contract.strategies import Analysis, Analyzer

__all__ = ["PatchAnalyzer"]


@attrs.frozen(kw_only=True)
class PatchAnalyzer(Analyzer):
    """Patches = connected components of intact springs; each patch of at least ``min_size`` bases is
    mapped to its tangent plane and characterised by PCA (orientation, anisotropy 2A − 1); the
    summary gives the axial circular mean and SD of orientation over patches (``bark.analysis.patches``)."""

    min_size: int = attrs.field(default=7, validator=positive_int)
    """Patches with fewer bases are dropped (the paper: 7)."""

    def analyze(self, points: np.ndarray, patches: np.ndarray) -> Analysis:
        rows = patch_statistics(points, patches, self.min_size)
        return Analysis(summary=pattern_summary(rows), patches=rows)
