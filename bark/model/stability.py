"""Explicit stability bound (docs/numerics.md) and the largest stiffness eigenvalue it needs.

For Euler–Cromer on the damped mass-spring system with ``β = b/m`` and ``ω² = λ_max(K)/m``:
stable iff ``βh < 2`` and ``ω²h² + 2βh < 4``, i.e. ``h < h_max = (√(β² + 4ω²) − β)/ω²``.

``λ_max(K)`` comes either from Gershgorin's theorem (cheap, always an upper bound:
``c + 2k · max springs per base``) or from a few Lanczos iterations on the matrix-free stiffness
operator (``scipy.sparse.linalg.eigsh``; tight).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["lambda_max", "explicit_h_max", "euler_cromer_h_max"]


def lambda_max(state, forces, method: str = "lanczos") -> float:
    """Largest eigenvalue of the stiffness ``K`` of ``state`` (intact springs + anchors); ``forces``
    is the simulation's ``ForceField``."""
    mech = forces.mechanics
    if method == "gershgorin":
        degree = np.bincount(state.pairs[state.intact].ravel(), minlength=state.n_bases)
        return mech.c + 2.0 * mech.k * float(degree.max(initial=0))
    if method != "lanczos":
        raise ValueError(f"method = {method!r}: must be one of gershgorin, lanczos")
    from scipy.sparse.linalg import ArpackError, ArpackNoConvergence, LinearOperator, eigsh

    matvec, _ = forces.stiffness(state)
    size = 3 * state.n_bases
    op = LinearOperator((size, size), matvec=matvec, dtype=float)
    # a fixed pseudo-random start: deterministic, and (unlike a constant vector, which the anchors'
    # c·I maps onto itself) with a component along the top eigenvector
    v0 = np.random.default_rng(0).standard_normal(size)
    try:
        top = eigsh(op, k=1, which="LA", v0=v0, tol=1e-8, maxiter=5000, return_eigenvectors=False)
    except (ArpackNoConvergence, ArpackError):
        return lambda_max(state, forces, "gershgorin")
    return float(top[0]) * (1.0 + 1e-6)  # the tolerance, on the safe side


def explicit_h_max(beta: float, omega2: float) -> float:
    """``h_max = (√(β² + 4ω²) − β)/ω²`` (``2/β`` as ω → 0; ``2/ω`` without damping), evaluated as
    the equal ``4/(√(β² + 4ω²) + β)``, which does not cancel when ω² ≪ β²."""
    if omega2 <= 0.0:
        return 2.0 / beta if beta > 0 else math.inf
    return 4.0 / (math.sqrt(beta * beta + 4.0 * omega2) + beta)


def euler_cromer_h_max(state, forces, method: str = "lanczos") -> float:
    """Largest stable Euler–Cromer step for ``state`` (docs/numerics.md)."""
    m = forces.mechanics.m
    return explicit_h_max(forces.mechanics.b / m, lambda_max(state, forces, method) / m)
