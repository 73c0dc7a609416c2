"""Comparing patterns as the paper does ("Pattern comparisons", eqs. 12–15, Fig. 8).

* **Hellinger distance** between the normal distributions two patterns' statistics describe
  (:func:`bark.analysis.circular.hellinger`): of their orientations (means compared as axes) or of their
  anisotropies.  Symmetric, 0 for equal distributions, towards 1 as they part.
* **d_P** (eq. 15): how far Q's mean lies from P's, in standard errors of P.  Asymmetric.
* **Quartet analysis** of four patterns (Bandelt & Dress 1986): of the six pairwise distances keep
  the three shortest; if the two shortest join disjoint pairs (PQ and RS), the quartet is *valid*
  and pairs P with Q and R with S; if they share a pattern (PQ and PR) no pairing is reliable.
* **d_P pairing** (Fig. 8F, G): each pattern's outgoing edge with the smallest d_P points to its
  nearest; the pairing is valid when the four pointers form two mutual pairs.

All take :class:`bark.analysis.pattern.PatternStatistics`, so simulated patterns, photographs and published
summaries compare alike.
"""

from __future__ import annotations

import itertools
import math
from typing import Sequence

import attrs
import numpy as np

from bark.analysis.circular import hellinger, standard_error_difference
from bark.errors import BarkError
from bark.analysis.pattern import PatternStatistics

__all__ = ["QUANTITIES", "Quartet", "Pairing", "Comparison", "distances", "d_p", "quartet", "pairing", "compare"]

QUANTITIES = ("orientation", "anisotropy")


def _moments(s: PatternStatistics, quantity: str) -> tuple[float, float, float]:
    """(mean, SD, SE) of ``quantity`` in ``s``; NaNs where ``s`` does not give it."""
    if quantity == "orientation":
        o = s.orientation
        return o.mean_deg, o.sd_deg, o.se_deg
    if quantity == "anisotropy":
        a = s.anisotropy
        return (math.nan,) * 3 if a is None else (a.mean, a.sd, a.se)
    raise BarkError(f"quantity {quantity!r}: must be one of {', '.join(QUANTITIES)}")


def distances(stats: Sequence[PatternStatistics], quantity: str = "orientation") -> np.ndarray:
    """Pairwise Hellinger distances (eqs. 12–14), ``n × n``, symmetric, zero diagonal; NaN where a
    pattern lacks the quantity or its SD."""
    m = [_moments(s, quantity) for s in stats]
    n = len(m)
    d = np.zeros((n, n))
    for i, j in itertools.combinations(range(n), 2):
        (mp, sp, _), (mq, sq, _) = m[i], m[j]
        ok = all(math.isfinite(v) for v in (mp, sp, mq, sq))
        d[i, j] = d[j, i] = hellinger(mp, sp, mq, sq, axial=quantity == "orientation") if ok else math.nan
    return d


def d_p(stats: Sequence[PatternStatistics], quantity: str = "orientation") -> np.ndarray:
    """``d[p, q] = d_P(P, Q)`` (eq. 15): ``|μ_Q − μ_P|`` in standard errors of P; zero diagonal, NaN where
    a mean or P's standard error is missing, ``inf`` where P's standard error is 0 and the means differ."""
    m = [_moments(s, quantity) for s in stats]
    n = len(m)
    d = np.zeros((n, n))
    for p, q in itertools.permutations(range(n), 2):
        (mp, _, se), (mq, _, _) = m[p], m[q]
        finite = all(math.isfinite(v) for v in (mp, se, mq))
        d[p, q] = standard_error_difference(mp, se, mq, axial=quantity == "orientation") if finite else math.nan
    return d


@attrs.frozen
class Quartet:
    """The quartet analysis of four patterns from their distance matrix."""

    edges: tuple[tuple[int, int, float], ...]
    """The six pairs ``(i, j, d)``, shortest first (ties in index order)."""
    valid: bool
    """Whether the two shortest pairs are disjoint (a reliable pairing)."""
    tied: bool
    """Whether the second and third shortest distances are equal: the verdict then rests on index order."""

    @property
    def pairing(self) -> tuple[tuple[int, int], tuple[int, int]] | None:
        """The two pairs a valid quartet infers, else ``None``."""
        (a, b, _), (c, d, _) = self.edges[:2]
        return ((a, b), (c, d)) if self.valid else None


def quartet(d: np.ndarray) -> Quartet:
    """Quartet analysis of a ``4 × 4`` distance matrix (the paper, Fig. 8A–C)."""
    d = np.asarray(d, dtype=float)
    if d.shape != (4, 4):
        raise BarkError(f"a quartet needs four patterns, not {d.shape[0]}")
    if not np.isfinite(d).all():
        raise BarkError("a quartet needs all six distances; a pattern lacks this quantity")
    edges = sorted(((i, j, float(d[i, j])) for i, j in itertools.combinations(range(4), 2)), key=lambda e: e[2])
    first, second = edges[0], edges[1]
    valid = not {first[0], first[1]} & {second[0], second[1]}
    return Quartet(edges=tuple(edges), valid=valid, tied=edges[1][2] == edges[2][2])


@attrs.frozen
class Pairing:
    """The d_P analysis (the paper, Fig. 8F, G): each pattern's nearest by its own standard error."""

    nearest: tuple[int, ...]
    """Each pattern's nearest (``-1``: none — its standard error is zero and every other mean elsewhere)."""
    valid: bool
    """Whether every pattern's nearest has it as its own nearest (disjoint mutual pairs)."""


def pairing(d: np.ndarray) -> Pairing:
    """Each row's smallest off-diagonal entry of a ``d_P`` matrix, and whether they pair up (a row
    whose entries are all infinite — a pattern with a standard error of zero, every other mean
    elsewhere — has no nearest: no valid pairing)."""
    d = np.asarray(d, dtype=float)
    n = d.shape[0]
    if np.isnan(d).any():
        raise BarkError("a pairing needs every d_P; a pattern lacks this quantity")
    off = np.where(np.eye(n, dtype=bool), np.inf, d)
    nearest = tuple(int(j) if np.isfinite(row[j]) else -1 for row, j in zip(off, np.argmin(off, axis=1)))
    valid = all(j >= 0 and nearest[j] == p for p, j in enumerate(nearest))
    return Pairing(nearest=nearest, valid=valid)


@attrs.frozen(eq=False)
class Comparison:
    """Every comparison of some patterns, per quantity (``orientation``, ``anisotropy``)."""

    stats: tuple[PatternStatistics, ...]
    hellinger: dict[str, np.ndarray]
    d_p: dict[str, np.ndarray]
    quartets: dict[str, Quartet | None]
    """Per quantity, the quartet analysis (four patterns that all give the quantity), else ``None``."""
    pairings: dict[str, Pairing | None]

    @property
    def names(self) -> list[str]:
        """The compared patterns' names, in order."""
        return [s.name for s in self.stats]


def compare(stats: Sequence[PatternStatistics]) -> Comparison:
    """Compare two or more patterns; with exactly four, the quartet analyses too."""
    stats = tuple(stats)
    if len(stats) < 2:
        raise BarkError(f"comparing needs at least two patterns, not {len(stats)}")
    h = {q: distances(stats, q) for q in QUANTITIES}
    dp = {q: d_p(stats, q) for q in QUANTITIES}
    four = len(stats) == 4
    quartets = {q: quartet(h[q]) if four and np.isfinite(h[q]).all() else None for q in QUANTITIES}
    pairings = {q: pairing(dp[q]) if four and not np.isnan(dp[q]).any() else None for q in QUANTITIES}  # inf: far
    return Comparison(stats=stats, hellinger=h, d_p=dp, quartets=quartets, pairings=pairings)
