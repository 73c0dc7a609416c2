"""Simulation-based calibration of ``bark fit``: does a fit's posterior say as much as it knows?

    from bark.studies.sbc import Calibration, run_calibration, summarise
    cal = Calibration(base=read_toml("reticulate"), draws=60, population=30, generations=3)
    rows = run_calibration(cal, "runs/sbc", workers=2)
    summarise(rows, cal.keys)        # per setting: rank histogram, chi-square p, interval coverage

**The check** (Cook, Gelman & Rubin 2006; Talts et al. 2018): draw a setting θ from the prior, grow
a pattern at it (a seed of its own), fit that pattern as an observed one, and see where θ falls in
its posterior.  If the posterior is right, θ is one more draw from it, so over many draws its rank
among the posterior's draws is uniform and each central interval of level q holds it in a fraction
q of the draws.  A ∩-shaped histogram (too many middle ranks, coverage above q) is a posterior wider
than it needs to be, the expected state of ABC, whose posterior counts every run within ε as a
match; a ∪ shape (coverage below q) is an overconfident one, which is a defect; a slope, a bias.

**The rank** of θ in a weighted ABC population is the posterior's weight below it (ties counted
half): the limit of Talts' rank among L draws over L, uniform on [0, 1] for a calibrated posterior.
The joint check is the weight of the settings more probable than θ (``FitResult.hpd_level``): θ lies
in the q highest-density region in a fraction q of the draws.

**Deterministic and resumable**: draw i's setting and seed come from a generator seeded by
``(seed, i)``, its fit by seed i; each draw's fit is its own database (``draw-NNN.db``, resumable as
``bark fit`` is) and its row (``draw-NNN.json``) is written when the fit ends, so that a study
stopped at any moment and run again redoes only the unfinished draw and ends with the same rows.
A draw whose pattern has no statistics (no patch of the least size) is recorded as such and left out
of the ranks: the fit conditions on a pattern, and so does the check.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Callable

import attrs
import numpy as np

from bark.errors import BarkError
from bark.studies.fit import DEFAULT_PRIORS, STATISTICS, Fit, Observed, Prior, run_fit, simulate_statistics, warm_worker

__all__ = ["Calibration", "run_calibration", "summarise", "LEVELS"]

LEVELS = (0.5, 0.8, 0.95)
"""The interval levels whose coverage is reported."""


@attrs.frozen
class Calibration:
    """A calibration study: ``draws`` settings from the ``priors``, each grown from ``base`` (a scene
    dict) and fitted with ``population`` runs a generation for ``generations`` generations on the
    ``statistics`` (default: every one of :data:`~bark.studies.fit.STATISTICS`)."""

    base: dict
    priors: tuple[Prior, ...] = attrs.field(default=DEFAULT_PRIORS, converter=tuple)
    statistics: tuple[str, ...] = attrs.field(default=tuple(STATISTICS), converter=tuple)
    draws: int = attrs.field(default=60, validator=attrs.validators.and_(attrs.validators.instance_of(int),
                                                                       attrs.validators.ge(1)))
    population: int = 30
    generations: int = 3
    seed: int = 0

    @property
    def keys(self) -> tuple[str, ...]:
        """The calibrated scene keys, in the priors' order."""
        return tuple(p.key for p in self.priors)

    def truth(self, i: int) -> tuple[dict[str, float], int]:
        """Draw ``i``'s setting (from the priors: uniform, or uniform in the logarithm) and its seed."""
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 2**34, i]))
        settings = {}
        for p in self.priors:
            u = rng.random()
            settings[p.key] = (math.exp(math.log(p.low) + u * (math.log(p.high) - math.log(p.low))) if p.log
                               else p.low + u * (p.high - p.low))
        return settings, int(rng.integers(0, 2**31 - 1))

    def fit(self, i: int, values: dict) -> Fit:
        """The fit of draw ``i``'s pattern (its statistics ``values``)."""
        return Fit(observed=Observed(name=f"draw {i}", values=values, source="synthetic"), base=self.base,
                   priors=self.priors, statistics=self.statistics, population=self.population,
                   generations=self.generations, seed=i)


def _rank(x: np.ndarray, w: np.ndarray, true: float) -> float:
    """The posterior's weight below ``true`` (ties counted half)."""
    return float(np.sum(w[x < true]) + 0.5 * np.sum(w[x == true]))


def run_calibration(cal: Calibration, folder: str | Path, *, workers: int = 1,
                    draw_done: Callable[[dict], None] | None = None) -> list[dict]:
    """Run the study into ``folder`` (a row and a fit database per draw), going on from the draws
    already there; returns the rows in draw order.  ``draw_done(row)`` after each draw finished here."""
    from bark.io.files import write_json
    from bark.studies.pool import LocalPool

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cal.fit(0, dict.fromkeys(cal.statistics, 0.0)).check(workers)  # one line for a bad setting, before any run
    rows, pool = [], None
    try:
        for i in range(cal.draws):
            path = folder / f"draw-{i:03d}.json"
            if path.is_file():
                rows.append(json.loads(path.read_text()))
                continue
            settings, seed = cal.truth(i)
            values = simulate_statistics(cal.fit(i, dict.fromkeys(cal.statistics, 0.0)).scene(settings, seed),
                                         cal.statistics)
            row = {"draw": i, "truth": settings, "seed": seed, "observed": values}
            if any(values[n] is None for n in cal.statistics):
                row["skipped"] = "the pattern has no statistics (no patch of the least size, or a non-finite run)"
            else:
                fit = cal.fit(i, values)
                pool = pool or LocalPool(workers, "calibration", (warm_worker, (fit.base,)))
                result = run_fit(fit, folder / f"draw-{i:03d}.db", pool=pool)
                x, w = result.posterior()
                row["rank"] = {k: _rank(x[:, j], w, settings[k]) for j, k in enumerate(cal.keys)}
                row["hpd_level"] = result.hpd_level(settings)
                row["runs"] = sum(g.runs for g in result.generations)
                row["epsilon"] = result.generations[-1].epsilon
            write_json(path, row)
            rows.append(row)
            if draw_done is not None:
                draw_done(row)
    finally:
        if pool is not None:
            pool.close()
    return rows


def summarise(rows: list[dict], keys: tuple[str, ...], bins: int | None = None) -> dict:
    """Per fitted setting and jointly: the rank histogram over ``bins`` equal bins (default: about
    ten draws a bin, at least 2), the chi-square p of its uniformity, and each :data:`LEVELS`
    interval's coverage (central intervals for a setting, highest-density regions jointly) with
    its binomial 95 % range under calibration."""
    from scipy.stats import binom, chisquare

    used = [r for r in rows if "rank" in r]
    n = len(used)
    if n == 0:
        raise BarkError("calibration: no draw has a fitted posterior yet")
    bins = bins or max(2, min(20, n // 10))

    def one(u: np.ndarray, inside) -> dict:
        counts = np.histogram(np.clip(u, 0.0, 1.0), bins=bins, range=(0.0, 1.0))[0]
        cover = {}
        for q in LEVELS:
            lo, hi = binom.ppf(0.025, n, q), binom.ppf(0.975, n, q)
            cover[f"{q:g}"] = {"covered": float(np.mean(inside(u, q))), "expected": [lo / n, hi / n]}
        return {"counts": counts.tolist(), "chi2_p": float(chisquare(counts).pvalue), "coverage": cover}

    out = {"draws": n, "skipped": len(rows) - n, "bins": bins}
    for k in keys:
        out[k] = one(np.array([r["rank"][k] for r in used]), lambda u, q: np.abs(u - 0.5) <= q / 2)
    out["joint"] = one(np.array([r["hpd_level"] for r in used]), lambda u, q: u <= q)
    return out
