"""The mechanics of the leaf-base layer: material constants and pure force kernels.

Equations from the paper ("Fracture simulation"):

* neighbour spring (eq. 1), force on base ``i`` from the spring to ``j``:
  ``f = k (|d| − l) d/|d|`` with ``d = x_j − x_i`` — a stretched spring pulls the two ends together;
* anchor spring of zero rest length (eq. 2): ``f = −c (x − x_anchor)``;
* damping (eq. 3): ``f = −b v``.

Tension of a spring is ``k (|d| − l)``: positive when stretched, negative when compressed; only
tension can break a spring.  Each expression is written once, in :mod:`bark.model.physics`; the backends
evaluate it, and :class:`ForceField` gives integrators the forces.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import attrs
import numpy as np

from bark.model import physics
from bark.validators import non_negative, positive

if TYPE_CHECKING:
    import scipy.sparse as sp

__all__ = ["Mechanics", "ForceField", "SpringOrder", "order_keys", "spring_geometry", "incidence", "stiffness_matvec"]


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
    """Breaking threshold of a neighbour spring, force units (Table 2: 0.0028 vertical, 0.005
    reticulate, 0.008 diamond): the material's, about which the breaker spreads each spring's own
    (``[breaker] spread``, ``weibull_shape``) and by region sets it (``[breaker] regions``)."""


def spring_geometry(x: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vector ``d = x_j − x_i`` and length ``|d|`` of every spring ``(i, j)``."""
    d = np.take(x, pairs[:, 1], axis=0) - np.take(x, pairs[:, 0], axis=0)
    return d, physics.length(d[:, 0], d[:, 1], d[:, 2])


def order_keys(pairs: np.ndarray) -> np.ndarray:
    """Sort keys of springs ``(i, j)``: by offset ``j − i``, then by ``i`` (one unsigned integer each)."""
    i, j = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    return ((j - i + 2**31).astype(np.uint64) << np.uint64(32)) | i.astype(np.uint64)


@attrs.define(eq=False)
class SpringOrder:
    """The order in which every base sums its springs' forces: by offset ``j − i``, then by first end
    ``i`` (ties by id).  A fixed lattice is made in this order; springs that join later are appended
    to the state (their ids follow the join), and this order places them among the others, so the
    compiled pass can take the springs in long runs of equal offset and the numpy backend sums in
    the same order (the same bits).  Derived data: extended as springs are appended (a join costs
    a sort of its new springs and an insertion, not a sort of all), made again for springs it has not
    seen."""

    pairs: np.ndarray | None = None
    """A copy of the springs it was made for, when they came without a state (see ``of``)."""
    keys: np.ndarray = attrs.field(factory=lambda: np.empty(0, np.uint64))
    """Their sort keys, in order."""
    ids: np.ndarray = attrs.field(factory=lambda: np.empty(0, np.int64))
    """Spring ids in order."""
    state: object = None
    """The state whose springs these are, when given: its springs are only ever appended."""

    def of(self, pairs: np.ndarray, state=None) -> np.ndarray | None:
        """Spring ids of ``pairs`` in summation order; ``None`` when that is id order.  With ``state``
        (whose ``pairs`` these are), springs seen before are known to be unchanged — a state only
        appends springs — and are not compared again: a join then costs its new springs only."""
        m, seen = len(pairs), len(self.ids)
        known = (state is self.state) if state is not None else (
            self.pairs is not None and seen <= m and np.array_equal(pairs[:seen], self.pairs))
        if not (known and seen <= m):
            seen, self.keys, self.ids = 0, np.empty(0, np.uint64), np.empty(0, np.int64)
        self.state = state
        if m > seen:
            keys = order_keys(pairs[seen:])
            new = np.argsort(keys, kind="stable")
            keys = keys[new]
            at = np.searchsorted(self.keys, keys, side="right")  # after equal keys: ties stay in id order
            self.keys = np.insert(self.keys, at, keys)
            self.ids = np.insert(self.ids, at, new + seen)
        self.pairs = np.array(pairs, dtype=np.int64) if state is None else None
        return None if bool(np.all(self.ids[1:] > self.ids[:-1])) else self.ids

    def runs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The springs in this order as runs ``(first position, length, first i, offset o)`` of
        consecutive springs ``(i, i + o), (i + 1, i + 1 + o), ...`` with ``o > 0`` (a lattice of any
        size is one run per offset); any other spring is a run of its own."""
        keys = self.keys
        i = (keys & np.uint64(0xFFFFFFFF)).astype(np.int64)
        o = (keys >> np.uint64(32)).astype(np.int64) - 2**31
        joins = (keys[1:] == keys[:-1] + np.uint64(1)) & (o[1:] > 0)  # the same offset, the next i
        starts = np.flatnonzero(np.concatenate([[True], ~joins])) if len(keys) else np.empty(0, np.int64)
        lengths = np.diff(np.append(starts, len(keys)))
        return starts.astype(np.int64), lengths.astype(np.int64), i[starts], o[starts]


def incidence(pairs: np.ndarray, n: int, order: np.ndarray | None = None) -> sp.csr_matrix:
    """The ``(n, m)`` matrix that sums per-spring vectors onto bases: ``+1`` at ``(i, s)``, ``−1`` at
    ``(j, s)`` for spring ``s = (i, j)``.  Each row holds its entries in summation order (``order``,
    spring ids, from :class:`SpringOrder`; default id order), so a product sums each base's springs
    in that order.  (scipy.sparse is imported here, not with the module: a run on the compiled
    backend never needs it.)"""
    import scipy.sparse as sp

    m = pairs.shape[0]
    ids = np.arange(m) if order is None else np.asarray(order, dtype=np.int64)
    ends = pairs[ids].T.astype(np.int64).ravel()
    cols = np.concatenate([np.arange(m), np.arange(m)])
    vals = np.concatenate([np.ones(m), -np.ones(m)])
    mat = sp.csr_matrix((vals, (ends, cols)), shape=(n, m))
    mat.sort_indices()  # each row in summation order (columns are positions in it, so far)
    if order is not None:
        mat.indices = ids[mat.indices].astype(mat.indices.dtype)  # positions -> spring ids, the rows' order kept
        mat.has_sorted_indices = False
    return mat


@attrs.define(eq=False)
class ForceField:
    """The forces on the leaf-base layer, for integrators: the material constants and the backend that
    evaluates them (the springs' sum; anchors and damping by :func:`bark.model.physics.base_force`)."""

    mechanics: Mechanics
    backend: object
    _inc: tuple | None = attrs.field(default=None, init=False, repr=False)

    def elastic(self, state, x: np.ndarray | None = None) -> np.ndarray:
        """Spring (eq. 1) and anchor (eq. 2) forces at ``x`` (default: the state's positions)."""
        x = state.x if x is None else x
        fs = self.backend.spring_forces(state, self.mechanics, x)
        return np.asfortranarray(physics.base_force(fs, x, state.anchor, 0.0, self.mechanics.c, 0.0))

    def total(self, state, x: np.ndarray | None = None, v: np.ndarray | None = None) -> np.ndarray:
        """All forces (eq. 4): springs, anchors and damping, at ``x`` and ``v`` (default: the state's)."""
        x = state.x if x is None else x
        v = state.v if v is None else v
        fs = self.backend.spring_forces(state, self.mechanics, x)
        mech = self.mechanics
        return np.asfortranarray(physics.base_force(fs, x, state.anchor, v, mech.c, mech.b))

    def tension(self, state) -> np.ndarray:
        """Every spring's tension now (broken ones included; mask with ``intact``)."""
        out = np.empty(state.n_springs)
        self.backend.measure(state, self.mechanics, out)
        return out

    def incidence(self, state) -> sp.csr_matrix:
        """The springs' signed incidence matrix (springs × bases, sparse), kept while the numbers of bases and
        springs stay the same."""
        key = (state.n_bases, state.n_springs)
        if self._inc is None or self._inc[0] != key:
            self._inc = (key, incidence(state.pairs, state.n_bases))
        return self._inc[1]

    def stiffness(self, state, x: np.ndarray | None = None):
        """``(matvec, diagonal)`` of the stiffness ``K = −∂F/∂x`` at ``x`` (:func:`stiffness_matvec`)."""
        mech = self.mechanics
        return stiffness_matvec(state.x if x is None else x, state.pairs, state.rest, mech.k, state.intact, mech.c,
                                self.incidence(state))


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
    p0, p1 = pairs[:, 0], pairs[:, 1]

    def matvec(p: np.ndarray) -> np.ndarray:
        p = np.asarray(p).reshape(n, 3)
        dp = np.take(p, p0, axis=0) - np.take(p, p1, axis=0)  # p_i − p_j
        f = dp * wa[:, None] + e * (wl * np.einsum("ij,ij->i", e, dp))[:, None]
        return (np.asarray(inc @ f) + c * p).ravel()

    ee = e * e
    per_spring = ee * wl[:, None] + wa[:, None]
    diag = np.asarray(abs(inc) @ per_spring) + c
    return matvec, diag.ravel()
