"""Where a bulge turns elongated bark reticulate: the strains a growth law imposes on a stretch of
trunk, and a logistic boundary law between the two kinds of pattern fitted to runs.

The paper shows bulges making the pattern reticulate ("Integrative model") and names the cause: a
bulge changes how the trunk stretches there.  Two numbers of a stretch of trunk, both from the
growth law alone (``radius(t, z)``), say how:

* its **hoop strain** ``ε_h``: the mean over its heights of ``r(t, z) / r(0, z) − 1``, the stretch of
  the circumference a spring made at the start spans;
* its **axial strain** ``ε_a``: the meridian's length over it, ``∫ √(1 + (∂r/∂z)²) dz``, at ``t``
  over at the start, minus 1 — zero on a straight trunk, which only widens.

The **boundary law** is a logistic regression of the pattern's kind (1: elongated) on features of
the stretch, such as the strain ratio ``ε_a / ε_h`` and ``ln(f_max / G)``::

    P(elongated) = 1 / (1 + exp(−(β₀ + β₁ x₁ + β₂ x₂ + ...)))

fitted by maximum likelihood (statsmodels' ``Logit``), with Wald intervals for the coefficients,
the likelihood-ratio test against the law with no feature and McFadden's pseudo-R² (two nested laws
compare by :func:`nested_p`); its boundary,
``P = ½``, is the plane ``β₀ + β·x = 0``.  Its misclassification rate is measured on runs it was not
fitted to (other seeds), against the rate of always guessing the commoner kind.
"""

from __future__ import annotations

import math
import warnings
from typing import Callable

import attrs
import numpy as np

__all__ = ["BoundaryLaw", "fit_boundary", "nested_p", "stretch_strains"]


def stretch_strains(radius: Callable[[float, np.ndarray], np.ndarray], t: float, low: float, high: float,
                    samples: int = 2001) -> tuple[float, float]:
    """``(ε_h, ε_a)``: the hoop and axial strain at time ``t`` of the trunk between heights ``low`` and
    ``high`` under the growth law ``radius(t, z)`` (e.g. a growth strategy's ``radius``), against the
    start (t = 0), on ``samples`` evenly spaced heights (the trapezoid rule)."""
    if not (math.isfinite(low) and math.isfinite(high) and high > low):
        raise ValueError(f"a stretch of trunk from {low} to {high}: expected finite heights, the second above the first")
    if not math.isfinite(t) or t < 0:
        raise ValueError(f"time {t}: expected a finite time from 0 on")
    z = np.linspace(low, high, samples)
    r0 = np.broadcast_to(np.asarray(radius(0.0, z), dtype=float), z.shape)
    rt = np.broadcast_to(np.asarray(radius(t, z), dtype=float), z.shape)
    if not (np.all(np.isfinite(r0)) and np.all(np.isfinite(rt)) and np.all(r0 > 0)):
        raise ValueError("the growth law gives a radius that is not finite and positive on the stretch")
    hoop = float(np.mean(rt / r0) - 1.0)

    def length(r: np.ndarray) -> float:
        return float(np.trapezoid(np.sqrt(1.0 + np.gradient(r, z) ** 2), z))

    return hoop, length(rt) / length(r0) - 1.0


@attrs.frozen
class BoundaryLaw:
    """A fitted boundary law: ``names`` of the features, ``coef`` (intercept first) with their
    ``low``–``high`` intervals at ``level``; ``llr_p``, the likelihood-ratio test's p against the law
    with the intercept alone; ``pseudo_r2``, McFadden's; ``n`` runs fitted."""

    names: tuple[str, ...]
    coef: tuple[float, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    level: float
    llr_p: float
    pseudo_r2: float
    n: int
    loglik: float
    """The log-likelihood at the fit: two laws of the same runs compare by twice its difference."""

    def probability(self, features) -> np.ndarray:
        """P(elongated) at each row of ``features`` (one column per name)."""
        x = np.atleast_2d(np.asarray(features, dtype=float))
        if x.shape[1] != len(self.names):
            raise ValueError(f"{x.shape[1]} feature columns for a law of {len(self.names)} ({', '.join(self.names)})")
        eta = self.coef[0] + x @ np.asarray(self.coef[1:])
        return 1.0 / (1.0 + np.exp(-eta))

    def misclassified(self, features, elongated) -> float:
        """The fraction of runs whose kind (``elongated``: true or false) the law gets wrong."""
        y = np.asarray(elongated, dtype=bool)
        return float(np.mean((self.probability(features) >= 0.5) != y))

    def formula(self) -> str:
        """The law as one line, coefficients to three significant figures."""
        terms = " ".join(f"{'+' if c >= 0 else '−'} {abs(c):.3g}·{n}" for c, n in zip(self.coef[1:], self.names))
        return f"logit P(elongated) = {self.coef[0]:.3g} {terms}"


def fit_boundary(features, elongated, names, level: float = 0.95) -> BoundaryLaw:
    """The logistic boundary law of ``elongated`` (true or false per run) on ``features`` (a row per
    run, a column per name), by maximum likelihood.  Refused (``ValueError``) when the two kinds are
    not both there, or when the features separate them perfectly: the coefficients are then infinite,
    and the boundary is any plane between the two sets."""
    import statsmodels.api as sm

    x = np.atleast_2d(np.asarray(features, dtype=float))
    y = np.asarray(elongated, dtype=bool)
    names = tuple(names)
    if x.shape != (y.size, len(names)):
        raise ValueError(f"features of shape {x.shape} for {y.size} runs and {len(names)} names")
    if not np.all(np.isfinite(x)):
        raise ValueError("a feature is not finite")
    if y.all() or not y.any():
        raise ValueError(f"all {y.size} runs are of one kind: there is no boundary to fit")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # perfect separation and no convergence: refused, not a silent guess
        try:
            fit = sm.Logit(y.astype(float), sm.add_constant(x, has_constant="add")).fit(disp=0, maxiter=200)
        except Exception as err:  # statsmodels' PerfectSeparationError/-Warning, ConvergenceWarning
            raise ValueError(f"the logistic law cannot be fitted: {err}") from None
    ci = np.asarray(fit.conf_int(alpha=1 - level))
    return BoundaryLaw(names=names, coef=tuple(map(float, fit.params)), low=tuple(map(float, ci[:, 0])),
                       high=tuple(map(float, ci[:, 1])), level=level, llr_p=float(fit.llr_pvalue),
                       pseudo_r2=float(fit.prsquared), n=int(y.size), loglik=float(fit.llf))


def nested_p(smaller: BoundaryLaw, larger: BoundaryLaw) -> float:
    """The likelihood-ratio test's p of ``larger`` against ``smaller``, a law of the same runs that it
    contains (χ² with as many degrees of freedom as it has more coefficients): small when the larger
    law's extra freedom explains the runs better than chance would."""
    from scipy import stats

    extra = len(larger.coef) - len(smaller.coef)
    if extra < 1 or larger.n != smaller.n:
        raise ValueError("the larger law must have more coefficients than the smaller, fitted to the same runs")
    return float(stats.chi2.sf(max(2.0 * (larger.loglik - smaller.loglik), 0.0), extra))
