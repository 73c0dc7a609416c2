"""Pattern statistics: tangent-plane mapping, PCA of patches, axial circular statistics.

Conventions (stated once, used everywhere in bark):

* A patch is mapped to the plane tangent to the trunk at its centroid, with coordinates
  ``(u, w)``: ``u`` horizontal, increasing with θ as seen from outside the trunk (to the right),
  ``w`` vertical, up the trunk axis.
* A patch's **orientation** is the angle of its first principal axis from horizontal, in degrees,
  in ``[0, 180)``: 0 = horizontal, 90 = along the trunk axis.
* **Anisotropy** is ``2A − 1`` with ``A = λ1 / (λ1 + λ2)``: 0 for a round patch, 1 for a line.
* Orientations are axial data (θ and θ + 180° are the same axis), so means and spreads use the
  doubled-angle method (Fisher): the angles are doubled onto the full circle, ``R̄`` is the length of
  their mean unit vector, the mean axis is half its direction and the circular SD is
  ``√(−2 ln R̄)`` scaled back to degrees — what ``scipy.stats.circmean/circstd`` with
  ``low=0, high=180`` give (the tests hold the two to 1e-12).  Written here because importing
  ``scipy.stats`` would cost every run more time and memory than all its statistics, for two lines
  of arithmetic.

These functions take plain arrays, so they serve simulated patterns and patterns digitised from
photographs (points and patch ids, no simulation) alike.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["tangent_plane", "principal_axes", "axial_mean", "axial_sd", "axial_se", "axial_difference",
           "hellinger", "orientation_hellinger", "standard_error_difference"]



def _doubled(deg) -> tuple[float, float]:
    """Mean sine and cosine of the doubled angles (axes in degrees onto the full circle)."""
    a = np.radians(2.0 * np.asarray(deg, dtype=float))
    return float(np.mean(np.sin(a))), float(np.mean(np.cos(a)))


def tangent_plane(points: np.ndarray) -> np.ndarray:
    """Map 3-D points on the trunk (axis = z) to ``(u, w)`` in the plane tangent at their centroid."""
    points = np.asarray(points, dtype=float)
    angles = np.arctan2(points[:, 1], points[:, 0])
    theta_c = float(np.arctan2(np.mean(np.sin(angles)), np.mean(np.cos(angles))))  # circular mean
    e_theta = np.array([-np.sin(theta_c), np.cos(theta_c), 0.0])
    rel = points - points.mean(axis=0)
    return np.column_stack([rel @ e_theta, rel[:, 2]])


def principal_axes(points2d: np.ndarray) -> tuple[float, float, float, float]:
    """PCA of a 2-D point set (eq. 10): ``(orientation_deg, anisotropy, λ1, λ2)``.

    Points in ``(horizontal, vertical)`` coordinates; the orientation is the first axis's, in degrees
    from the horizontal in ``[0, 180)``, and the anisotropy ``(λ1 − λ2)/(λ1 + λ2)`` is 0 for a round
    patch and 1 for a line.  Four times taller than wide:

    >>> import numpy as np
    >>> points = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -4.0], [0.0, 4.0]])
    >>> orientation, anisotropy, l1, l2 = principal_axes(points)
    >>> round(orientation, 6), round(anisotropy, 4)
    (90.0, 0.8824)
    """
    cov = np.cov(np.asarray(points2d, dtype=float), rowvar=False)
    lam, vec = np.linalg.eigh(cov)  # ascending
    l2, l1 = float(max(lam[0], 0.0)), float(max(lam[1], 0.0))
    a1 = vec[:, 1]
    orientation = float(np.degrees(np.arctan2(a1[1], a1[0])) % 180.0)
    anisotropy = (l1 - l2) / (l1 + l2) if l1 + l2 > 0 else 0.0
    return orientation, float(anisotropy), l1, l2


def axial_mean(deg: np.ndarray) -> float:
    """Mean axis of orientations in degrees, in ``[0, 180)`` (doubled-angle method).

    Orientations are axes: 170° and 10° lie either side of the horizontal, not about the vertical.

    >>> import numpy as np
    >>> round(axial_mean(np.array([170.0, 10.0])), 6)
    0.0
    >>> round(axial_mean(np.array([80.0, 100.0])), 6)
    90.0
    """
    sin, cos = _doubled(deg)
    mean = float(np.degrees(np.arctan2(sin, cos)) / 2.0) % 180.0
    return 0.0 if mean >= 180.0 else mean  # −1e-17 % 180 rounds to 180.0


def axial_sd(deg: np.ndarray) -> float:
    """Circular standard deviation of orientations in degrees (doubled-angle method).

    >>> import numpy as np
    >>> round(axial_sd(np.array([80.0, 100.0])), 2), round(axial_sd(np.array([170.0, 10.0])), 2)
    (10.1, 10.1)
    """
    sin, cos = _doubled(deg)
    r = min(float(np.hypot(sin, cos)), 1.0)  # rounding can put it a hair above 1
    return float(np.sqrt(-2.0 * np.log(r)) + 0.0) * 90.0 / np.pi


def axial_se(deg: np.ndarray) -> float:
    """Standard error of the axial mean in degrees (Fisher 1993, eq. 4.21 on the doubled angles):
    ``δ = (1 − ρ₂) / (2 R̄²)``, ``SE = √(δ / n)`` on the doubled circle, halved back to axes; ``ρ₂``
    is the mean of ``cos 2(φ − μ)`` over the doubled angles ``φ``.  NaN for fewer than two."""
    deg = np.asarray(deg, dtype=float)
    if deg.size < 2:
        return float("nan")
    s, c = _doubled(deg)
    r2 = s * s + c * c
    if r2 < (64 * np.finfo(float).eps) ** 2:  # R̄ zero but for the rounding of the sines
        return float("inf")  # no mean axis: its error is unbounded
    mu = math.atan2(s, c)
    rho2 = float(np.mean(np.cos(2.0 * (np.radians(2.0 * deg) - mu))))  # 2(φ − μ), φ the doubled angles
    delta = max(0.0, 1.0 - rho2) / (2.0 * r2)
    return math.degrees(math.sqrt(delta / deg.size)) / 2.0


def axial_difference(a, b) -> np.ndarray:
    """Signed difference of two axes in degrees, in ``[-90, 90)``."""
    return (np.asarray(a, dtype=float) - np.asarray(b, dtype=float) + 90.0) % 180.0 - 90.0



def hellinger(mean_p: float, sd_p: float, mean_q: float, sd_q: float, axial: bool = False) -> float:
    """Hellinger distance between two normal distributions (paper, eqs. 12–14), in [0, 1].

    ``d = √(1 − β e^γ)``, ``β = √(2 SD_P SD_Q / (SD_P² + SD_Q²))``,
    ``γ = −¼ (μ_P − μ_Q)² / (SD_P² + SD_Q²)``.  With ``axial=True`` the means are orientations in
    degrees and their difference is taken as axes (``axial_difference``).

    >>> hellinger(90.0, 20.0, 90.0, 20.0)
    0.0
    >>> round(hellinger(175.0, 20.0, 5.0, 20.0, axial=True), 4)  # 10° apart as axes, not 170°
    0.1754
    """
    diff = float(axial_difference(mean_p, mean_q)) if axial else mean_p - mean_q
    var = sd_p * sd_p + sd_q * sd_q
    if var == 0.0:
        return 0.0 if diff == 0.0 else 1.0
    beta = np.sqrt(2.0 * sd_p * sd_q / var)
    gamma = -0.25 * diff * diff / var
    return float(np.sqrt(max(0.0, 1.0 - beta * np.exp(gamma))))


def orientation_hellinger(deg_p: np.ndarray, deg_q: np.ndarray) -> float:
    """Hellinger distance between two sets of patch orientations (axial mean and circular SD).

    >>> import numpy as np
    >>> round(orientation_hellinger(np.array([80.0, 100.0]), np.array([80.0, 100.0])), 6)
    0.0
    >>> round(orientation_hellinger(np.array([80.0, 100.0]), np.array([170.0, 10.0])), 4)  # up against across
    1.0
    """
    return hellinger(axial_mean(deg_p), axial_sd(deg_p), axial_mean(deg_q), axial_sd(deg_q), axial=True)


def standard_error_difference(mean_p: float, se_p: float, mean_q: float, axial: bool = False) -> float:
    """``d_P(P, Q) = |μ_Q − μ_P| / SE_P`` (paper, eq. 15): asymmetric, in standard errors of P; with
    ``SE_P = 0``, 0 for the same mean and ``inf`` for another."""
    diff = float(axial_difference(mean_q, mean_p)) if axial else mean_q - mean_p
    if se_p == 0.0:
        return 0.0 if diff == 0.0 else math.inf
    return abs(diff) / se_p
