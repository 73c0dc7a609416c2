"""The mechanics of the leaf-base layer: material constants and pure force kernels.

Equations from the paper ("Fracture simulation"):

* neighbour spring (eq. 1), force on base ``i`` from the spring to ``j``:
  ``f = k (|d| − l) d/|d|`` with ``d = x_j − x_i`` — a stretched spring pulls the two ends together;
* anchor spring of zero rest length (eq. 2): ``f = −c (x − x_anchor)``;
* damping (eq. 3): ``f = −b v``.

Tension of a spring is ``k (|d| − l)``: positive when stretched, negative when compressed; only
tension can break a spring.  The kernels are pure functions of arrays (no state, no Python loop over
bases or springs), so property tests can hit them directly.
"""

from __future__ import annotations

import math

import attrs
import numpy as np
import scipy.sparse as sp

from bark._validate import in_range, non_negative, optional, positive
from bark.errors import BarkError, Ref

__all__ = [
    "Mechanics",
    "spring_geometry",
    "spring_forces",
    "anchor_forces",
    "damping_forces",
    "tensions",
    "scatter",
    "incidence",
]


@attrs.frozen(kw_only=True)
class Mechanics:
    """Material constants of the leaf-base layer (Table 2 values as defaults, vertical regime)."""

    k: float = attrs.field(default=0.4, validator=positive)
    """Stiffness of the springs between neighbouring bases (force / length)."""
    c: float = attrs.field(default=0.1, validator=non_negative)
    """Stiffness of the zero-rest-length anchor springs (force / length); 0 switches anchors off."""
    b: float = attrs.field(default=5.0, validator=non_negative)
    """Damping constant (force / velocity)."""
    m: float = attrs.field(default=1.0, validator=positive)
    """Mass of one leaf base (mass units; Table 2: 1)."""
    f_max: float = attrs.field(default=0.0028, validator=positive)
    """Mean breaking threshold of a neighbour spring, force units (Table 2: 0.0028 vertical,
    0.005 reticulate, 0.008 diamond)."""
    fmax_spread: float = attrs.field(default=0.0, validator=in_range(0.0, 10.0))
    """Relative spread of the per-spring thresholds: each spring's f_max is drawn log-normally
    with mean ``f_max`` and coefficient of variation ≈ ``fmax_spread``.  0 = all equal.  At most
    10: beyond that some thresholds underflow to zero."""
    fmax_weibull_shape: float | None = attrs.field(default=None, validator=optional(in_range(0.01, 1e12)))
    """Instead: draw each spring's threshold from a Weibull distribution of this shape (modulus) k,
    scaled to mean ``f_max`` — the weakest-link law of brittle strength (small k: very unequal
    springs; k ≈ 10: a few percent).  ``None``: log-normal with ``fmax_spread``.  At least 0.01:
    below that the Weibull scale Γ(1 + 1/k) overflows."""

    def __attrs_post_init__(self) -> None:
        if self.fmax_weibull_shape is not None and self.fmax_spread > 0:
            raise BarkError("{0} and {1} are two ways to spread the thresholds: give one",
                            Ref("mechanics", "fmax_spread", self.fmax_spread),
                            Ref("mechanics", "fmax_weibull_shape", self.fmax_weibull_shape))

    def thresholds(self, n_springs: int, rng: np.random.Generator) -> np.ndarray:
        """Per-spring breaking thresholds, drawn from ``rng`` (the normal draw is always made, for a
        stable stream whatever the spread)."""
        s = self.fmax_spread
        noise = rng.standard_normal(n_springs)
        if self.fmax_weibull_shape is not None:
            k = self.fmax_weibull_shape
            return self.f_max * rng.weibull(k, n_springs) / math.gamma(1.0 + 1.0 / k)
        return self.f_max * np.exp(s * noise - 0.5 * s * s)


def spring_geometry(x: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vector ``d = x_j − x_i`` and length ``|d|`` of every spring ``(i, j)``."""
    d = np.take(x, pairs[:, 1], axis=0) - np.take(x, pairs[:, 0], axis=0)
    return d, np.sqrt(np.einsum("ij,ij->i", d, d))


def incidence(pairs: np.ndarray, n: int) -> sp.csr_matrix:
    """The ``(n, m)`` matrix that sums per-spring forces onto bases: ``+1`` at ``(i, s)``, ``−1`` at
    ``(j, s)`` for spring ``s = (i, j)``.  Build it once per topology; :func:`scatter` takes it."""
    m = pairs.shape[0]
    cols = np.concatenate([np.arange(m), np.arange(m)])
    vals = np.concatenate([np.ones(m), -np.ones(m)])
    return sp.csr_matrix((vals, (pairs.T.ravel(), cols)), shape=(n, m))


def scatter(pairs: np.ndarray, f: np.ndarray, n: int, inc: sp.csr_matrix | None = None) -> np.ndarray:
    """Sum per-spring forces onto the bases: ``+f`` on end ``i``, ``−f`` on end ``j``.

    ``inc`` is :func:`incidence` of ``pairs`` (built here when not given)."""
    return np.asarray((incidence(pairs, n) if inc is None else inc) @ f)


def tensions(x: np.ndarray, pairs: np.ndarray, rest: np.ndarray, k: float) -> np.ndarray:
    """Tension ``k (|d| − l)`` of every spring (positive = stretched)."""
    _, length = spring_geometry(x, pairs)
    return k * (length - rest)


def spring_forces(
    x: np.ndarray,
    pairs: np.ndarray,
    rest: np.ndarray,
    k: float,
    active: np.ndarray | None = None,
    inc: sp.csr_matrix | None = None,
) -> np.ndarray:
    """Net neighbour-spring force on every base (eq. 1); springs with ``active == False`` are skipped.

    A spring of zero length exerts no force (its direction is undefined), rather than a NaN.
    ``inc`` is the :func:`incidence` matrix of ``pairs``, if the caller keeps one.
    """
    d, length = spring_geometry(x, pairs)
    scale = k * (length - rest) / np.where(length > 0.0, length, np.inf)
    if active is not None:
        scale *= active
    d *= scale[:, None]
    return scatter(pairs, d, x.shape[0], inc)


def anchor_forces(x: np.ndarray, anchor: np.ndarray, c: float) -> np.ndarray:
    """Zero-rest-length anchor springs (eq. 2)."""
    return -c * (x - anchor)


def damping_forces(v: np.ndarray, b: float) -> np.ndarray:
    """Linear damping (eq. 3)."""
    return -b * v


def stiffness_matvec(
    x: np.ndarray, pairs: np.ndarray, rest: np.ndarray, k: float, active: np.ndarray, c: float,
    inc: sp.csr_matrix | None = None,
):
    """``p ↦ K p`` for the stiffness ``K = −∂F/∂x`` of the springs and anchors at ``x`` (3n × 3n).

    Each intact spring contributes the block ``k [e eᵀ + α (I − e eᵀ)]`` with ``e`` its unit vector
    and ``α = max(0, 1 − l/|d|)``.  Clamping the transverse (geometric) term of compressed springs at
    zero keeps ``K`` symmetric positive semi-definite (the usual choice for implicit mass-spring
    solvers): conjugate gradients then apply, and ``λ_max`` of this ``K`` bounds the true one from
    above, which is what a stability bound needs.  Matrix-free: one product costs about one force
    evaluation.  Returns ``(matvec, diagonal)``, the diagonal being the Jacobi preconditioner.
    """
    n = x.shape[0]
    inc = incidence(pairs, n) if inc is None else inc
    d, length = spring_geometry(x, pairs)
    safe = np.where(length > 0.0, length, np.inf)
    e = d / safe[:, None]
    alpha = np.clip(1.0 - rest / safe, 0.0, None)
    w = k * np.asarray(active, dtype=float)
    wa = w * alpha
    wl = w - wa  # weight of the longitudinal part e eᵀ

    def matvec(p: np.ndarray) -> np.ndarray:
        p = np.asarray(p).reshape(n, 3)
        dp = np.take(p, pairs[:, 0], axis=0) - np.take(p, pairs[:, 1], axis=0)  # p_i − p_j
        f = dp * wa[:, None] + e * (wl * np.einsum("ij,ij->i", e, dp))[:, None]
        return (np.asarray(inc @ f) + c * p).ravel()

    ee = e * e
    per_spring = ee * wl[:, None] + wa[:, None]
    diag = np.asarray(abs(inc) @ per_spring) + c
    return matvec, diag.ravel()
