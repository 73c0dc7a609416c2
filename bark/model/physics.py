"""The model's physics, each piece written once (paper, "Fracture simulation", eqs. 1–9).

Every function here is elementwise arithmetic: called with numpy arrays it computes a whole lattice
at once (the numpy backend), called with floats inside compiled code it is inlined per base or per
spring (the numba backend compiles these very functions with ``inline="always"``).  So the two
backends evaluate the same expressions in the same order, and adding a force term is one edit here.

Conventions: Cartesian ``(x, y, z)``, trunk axis along ``z`` through the origin; tension positive
when a spring is stretched.
"""

from __future__ import annotations

import numpy as np

__all__ = ["length", "tension", "hookean", "spring_force_scale", "base_force", "surface_scale", "radial_speed", "over_threshold",
           "threshold_load", "threshold_ratio", "no_breaking", "as_given", "weighted_radius"]


def length(d0, d1, d2):
    """Length of a spring whose end-to-end vector is ``(d0, d1, d2)``, summed in this order: a rest
    length is taken by it, and every tension measured by it, so a spring made at rest has tension
    exactly 0 (in every backend, in a join made in Python or inside a kernel call)."""
    return np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


def tension(length, rest, k):
    """Tension of a spring of rest length ``rest`` stretched to ``length`` (eq. 1): ``k (|d| − l)``."""
    return k * (length - rest)


def hookean(length, rest, k, params):
    """Eq. 1 as a resin law's tension (``bark.contract.parts.ResinPart``): ``k (|d| − l)``, the same
    arithmetic as :func:`tension`, so that the paper's spring gives the same bits as ever."""
    return k * (length - rest)


def spring_force_scale(t, length):
    """The factor ``g`` with ``g · d`` the force on a spring's first end (``d = x_j − x_i``): a
    stretched spring pulls its ends together.  Only called for ``length > 0`` (a spring of zero
    length has no direction, and exerts no force)."""
    return t / length


def base_force(spring_force, x, anchor, v, c, b):
    """Total force on a base along one axis (eq. 4): its springs' sum, its anchor spring of zero
    rest length (eq. 2) and damping (eq. 3)."""
    return spring_force - c * (x - anchor) - b * v


def surface_scale(px, py, r):
    """The factor that moves a point radially onto the trunk surface of radius ``r`` (eq. 9)."""
    return r / np.sqrt(px * px + py * py)


def radial_speed(vx, vy, px, py, inv_r2):
    """The radial component of a velocity at a point on the surface, over the radius (``inv_r2 =
    1/r²``): ``(v·p)/r²``; subtracting it times ``p`` leaves the velocity tangential."""
    return (vx * px + vy * py) * inv_r2


def over_threshold(tension, fmax, params):
    """The paper's breaking rule (a breaker part's rule): a spring breaks when its tension exceeds
    its threshold (compression never breaks a spring)."""
    return tension > fmax


def threshold_load(tension, inv_fmax, params):
    """How far a spring is from the paper's threshold (a breaker part's load): ``tension / f_max``,
    as a product with the threshold's inverse (1 at breaking)."""
    return tension * inv_fmax


def threshold_ratio(tension, threshold, params):
    """How far a spring is from a threshold of its own kept as a declared field (a breaker part's
    load, reading ``tension`` and that field): ``tension / threshold``, 1 at breaking."""
    return tension / threshold


def no_breaking(tension, params):
    """The rule of a layer without fracture: nothing breaks."""
    return False


def as_given(t, params):
    """The per-step preparation of a growth law that has none: its parameters as they are."""
    return params


def weighted_radius(q: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``q[0] + w[0]·q[1] + w[1]·q[2] + ...`` summed left to right: the radius a growth law's
    part's ``weights`` promise gives, to the bit.  ``weights`` is ``(K, n)``; ``q`` is one per-step
    vector (the part's ``at(t)``) or ``(K + 1, n)``, each base's own."""
    q = np.asarray(q, dtype=float)
    r = np.array(np.broadcast_to(q[0], weights.shape[1:]), dtype=float)
    for k in range(len(weights)):
        r = r + weights[k] * q[1 + k]
    return r
