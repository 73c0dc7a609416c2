"""How a pattern cracked: broken springs, cracks and patches against time, from the break log.

The paper counts a run's "initial fractures" and finds their number a power law of the rate of energy
dissipation (its Discussion: "behaves like a brittle material") without defining either; bark's
definitions, used by the ``fracture-history`` effect, ``fracture.csv`` and ``examples/paper/figures.py fractures``:

* A **crack** is a connected set of broken springs, two broken springs being connected when they are
  sides of one cell of the lattice — the rhombus of bases ``i, i+a, i+b, i+a+b`` for the two spring
  offsets ``a < b`` — since a crack that crosses a cell breaks two of its sides.  Cracks start apart
  and join as they grow, so their number rises to a peak and falls.
* A run's **initial fractures** are the most cracks it has at once (counted exactly, after every step
  that breaks springs); its **initial fracture phase** runs from the first break to that peak.
* The **dissipation** is the power the damping takes out of the motion (eq. 3: ``b·|v|²`` summed over
  the bases), per base, sampled every ``history_every``; a run's **dissipation rate** is its mean over
  the samples of the initial fracture phase (the first sample at or after the first break, if the
  phase is shorter than a sample interval).
* The **growth dissipation** is what the damping would take out of a base moving at the trunk's
  growth speed at the first break, ``b·(dr/dt)²`` (dr/dt: the mean over the bases' sites, by a
  central difference of the growth law): a rate set by the parameters alone — the paper: the damping
  "together with the growth rate, determines the energy dissipation rate".
* **Patches** are connected groups of at least ``min_size`` bases over the springs that existed and
  were intact at a time (bases that join during a run count from their join).

Everything here works on plain arrays (a break log, the springs, a sampling), so it serves a run in
memory and a run folder alike.
"""

from __future__ import annotations

import math
from typing import Callable

import attrs
import numpy as np


__all__ = ["FractureHistory", "PowerLaw", "PowerLawCheck", "check_power_law", "crack_counts", "history", "power_law"]

COLUMNS = ["t", "n_broken", "n_cracks", "n_patches", "dissipation"]
"""Columns of ``fracture.csv``: one row per sample."""


def _cells(pairs: np.ndarray, offsets: tuple[int, ...], n_bases: int) -> np.ndarray:
    """``(m, 2)``: the two lattice cells each spring is a side of, by their lowest base (``-1``: a
    cell beyond the lattice's first or last base, which has no other side).  Spring ``(i, i+a)`` is a
    side of the cells of ``i`` and ``i − b``; ``(i, i+b)`` of those of ``i`` and ``i − a``."""
    a, b = sorted(offsets)
    pairs = np.asarray(pairs, dtype=np.int64)
    i = np.minimum(pairs[:, 0], pairs[:, 1])
    o = np.abs(pairs[:, 1] - pairs[:, 0])
    cells = np.column_stack([i, i - np.where(o == a, b, a)])
    return np.where((cells >= 0) & (cells + a + b < n_bases), cells, -1)


def crack_counts(broken: np.ndarray, pairs: np.ndarray, offsets: tuple[int, ...]) -> np.ndarray:
    """The number of cracks after each break of ``broken`` (spring ids in the order they broke)."""
    import networkx as nx

    if len(tuple(offsets)) != 2:
        raise ValueError(f"cracks are counted on a lattice of two spring offsets, not {tuple(offsets)}")
    pairs = np.asarray(pairs, dtype=np.int64)
    cells = _cells(pairs[np.asarray(broken, dtype=np.int64)], offsets, int(pairs.max()) + 1 if pairs.size else 0)
    sets = nx.utils.UnionFind()
    first_in: dict[int, int] = {}  # a cell -> the first broken spring seen in it
    counts = np.empty(len(cells), dtype=np.int64)
    n = 0
    for k, (c1, c2) in enumerate(cells.tolist()):
        n += 1
        sets[k]  # a crack of its own
        for c in (c1, c2):
            if c < 0:
                continue
            other = first_in.setdefault(c, k)
            if other != k and sets[other] != sets[k]:
                sets.union(other, k)
                n -= 1
        counts[k] = n
    return counts


def patch_count(n_bases: int, pairs: np.ndarray, intact: np.ndarray, min_size: int) -> int:
    """Patches of at least ``min_size`` of bases ``0 .. n_bases − 1`` over the ``intact`` springs."""
    from bark.model.components import components, count_patches

    return count_patches(components(n_bases, pairs, intact), min_size)


@attrs.frozen
class FractureHistory:
    """A run's fracture history: per sample and its summary (see the module's definitions)."""

    samples: dict[str, np.ndarray]
    """``COLUMNS``, one value per sample time."""
    first_break_t: float | None
    initial_fractures: int
    """The most cracks at once (0: nothing broke)."""
    initial_fractures_t: float | None
    dissipation_rate: float | None
    """Mean dissipation per base over the initial fracture phase (``None``: nothing broke, or no sample)."""
    growth_dissipation: float | None = None
    """``b·(dr/dt)²`` at the first break (``None``: nothing broke)."""

    def summary(self) -> dict:
        """What summary.json's ``fracture`` holds: the first break's time, the initial fractures and their time,
        the measured dissipation rate and the growth-driven one."""
        return {"first_break_t": self.first_break_t, "initial_fractures": self.initial_fractures,
                "initial_fractures_t": self.initial_fractures_t, "dissipation_rate": self.dissipation_rate,
                "growth_dissipation": self.growth_dissipation}

    def rows(self) -> list[dict]:
        """The samples as rows (one dict per sample, counts as integers), for a CSV."""
        ints = ("n_broken", "n_cracks", "n_patches")
        cols = [[int(v) if c in ints else float(v) for v in self.samples[c].tolist()] for c in COLUMNS]
        return [dict(zip(COLUMNS, vals)) for vals in zip(*cols)]


def history(log: dict[str, np.ndarray], pairs: np.ndarray, offsets: tuple[int, ...], bases_at: Callable[[float], int],
            times: np.ndarray, dissipation: np.ndarray, min_size: int) -> FractureHistory:
    """The history of a run whose breaks are ``log`` (``spring``, ``t`` columns in break order; see
    ``BreakLog.arrays``) on springs ``pairs``, sampled at ``times`` (ascending) with the dissipation
    measured there; ``bases_at(t)``: how many bases the trunk had at time ``t``."""
    ids, when = np.asarray(log["spring"], dtype=np.int64), np.asarray(log["t"], dtype=float)
    times = np.asarray(times, dtype=float)
    dissipation = np.asarray(dissipation, dtype=float)
    cracks = crack_counts(ids, pairs, offsets)
    done = np.searchsorted(when, times, side="right")  # breaks by each sample time
    at_sample = np.concatenate([[0], cracks])[done]  # cracks after the last of them (none before any)
    pairs = np.asarray(pairs, dtype=np.int64)
    spring_top = np.maximum(pairs[:, 0], pairs[:, 1])
    broke_at = np.full(len(pairs), np.inf)
    broke_at[ids] = when
    patches = []
    for t in times.tolist():
        n = bases_at(t)
        patches.append(patch_count(n, pairs, (spring_top < n) & (broke_at > t), min_size))
    samples = {"t": times, "n_broken": done.astype(np.int64), "n_cracks": at_sample.astype(np.int64),
               "n_patches": np.array(patches, dtype=np.int64), "dissipation": dissipation}
    if not ids.size:
        return FractureHistory(samples, None, 0, None, None)
    # the peak, after the last break of a step (a step's breaks happen at once)
    last_of_step = np.append(when[1:] != when[:-1], True)
    k = int(np.argmax(np.where(last_of_step, cracks, -1)))
    t0, t_peak = float(when[0]), float(when[k])
    phase = (times >= t0) & (times <= t_peak)
    if not phase.any():
        phase = times >= t0
        phase &= np.cumsum(phase) == 1  # the first sample at or after the first break
    rate = float(np.mean(dissipation[phase])) if phase.any() else None
    return FractureHistory(samples, t0, int(cracks[k]), t_peak, rate)


@attrs.frozen
class PowerLaw:
    """``y = A·x^k`` fitted by least squares on ``log y`` against ``log x``."""

    exponent: float
    ci: tuple[float, float]
    """The exponent's confidence interval (Student's t on the slope's standard error)."""
    level: float
    prefactor: float
    r2: float
    n: int


def power_law(x, y, level: float = 0.95) -> PowerLaw:
    """Fit ``y = A·x^k`` to the points with ``x, y > 0`` (at least three), with the exponent's
    confidence interval at ``level``."""
    from scipy import stats

    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    if np.count_nonzero(ok) < 3:
        raise ValueError(f"a power law needs at least three points with both values positive, not {np.count_nonzero(ok)}")
    fit = stats.linregress(np.log(x[ok]), np.log(y[ok]))
    n = int(np.count_nonzero(ok))
    half = float(stats.t.ppf(0.5 + level / 2, n - 2) * fit.stderr)  # n ≥ 3: checked above
    return PowerLaw(exponent=float(fit.slope), ci=(float(fit.slope - half), float(fit.slope + half)), level=level,
                    prefactor=float(math.exp(fit.intercept)), r2=float(fit.rvalue**2), n=n)


@attrs.frozen
class PowerLawCheck:
    """Whether ``log y`` is a straight line in ``log x`` and nothing else (nested least-squares models,
    F tests): ``curvature_p``, the p of adding ``(log x)²``; ``alone_p``, the p of adding the
    covariates (the settings that set ``x``): small when ``y`` depends on them other than through ``x``,
    so that no single power law of ``x`` describes it; ``decades``: the ``x`` range, log10(max/min)."""

    curvature_p: float
    alone_p: float | None
    decades: float
    n: int


def _rss(y: np.ndarray, columns: list[np.ndarray]) -> tuple[float, int]:
    design = np.column_stack([np.ones_like(y), *columns])
    coef = np.linalg.lstsq(design, y, rcond=None)[0]
    return float(np.sum((y - design @ coef) ** 2)), design.shape[1]


def _nested_p(y: np.ndarray, smaller: list[np.ndarray], larger: list[np.ndarray]) -> float:
    """The F test's p of the larger least-squares model against the smaller one it contains."""
    from scipy import stats

    rss0, p0 = _rss(y, smaller)
    rss1, p1 = _rss(y, larger)
    dof = y.size - p1
    if dof <= 0 or p1 <= p0:
        return math.nan
    exact = 1e-20 * float(np.sum(y * y)) + 1e-300  # residuals of round-off only: a perfect fit
    if rss1 <= exact:
        return 0.0 if rss0 > exact else 1.0
    f = ((rss0 - rss1) / (p1 - p0)) / (rss1 / dof)
    return float(stats.f.sf(max(f, 0.0), p1 - p0, dof))


def check_power_law(x, y, covariates: dict[str, np.ndarray] | None = None) -> PowerLawCheck:
    """Test the power law ``y = A·x^k`` on the points with ``x, y > 0`` (see :class:`PowerLawCheck`);
    ``covariates``: the settings behind ``x`` (e.g. b and G), each entered as its logarithm."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    extra = [np.log(np.asarray(v, dtype=float)) for v in (covariates or {}).values()]
    for v in extra:
        ok &= np.isfinite(v)
    if np.count_nonzero(ok) < 5:
        raise ValueError(f"a power law's check needs at least five points with both values positive, not {np.count_nonzero(ok)}")
    lx, ly = np.log(x[ok]), np.log(y[ok])
    extra = [v[ok] for v in extra]
    return PowerLawCheck(curvature_p=_nested_p(ly, [lx], [lx, lx**2]),
                         alone_p=_nested_p(ly, [lx], [lx, *extra]) if extra else None,
                         decades=float(np.log10(x[ok].max() / x[ok].min())), n=int(lx.size))
