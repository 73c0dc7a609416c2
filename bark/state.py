"""The mechanical state the hot loop works on: arrays mirrored from the leaf-base graph.

The networkx graph held by :class:`bark.simulation.Simulation` is the topology of record (which
bases exist, which springs are intact).  :class:`State` mirrors it as flat arrays so that one step is
a handful of vectorised numpy operations.  Only ``Simulation.break_springs`` changes ``intact``,
and it changes the graph in the same call, so the two never drift.

Coordinates: Cartesian ``(x, y, z)`` with the trunk axis along ``z`` through the origin; a base at
angle θ sits at ``(r cos θ, r sin θ, z)``.

Layout: the per-base arrays (``x``, ``v``, ``anchor``, ``anchor_dir``) are ``(n, 3)`` (or ``(n, 2)``)
arrays stored column by column (Fortran order), so that each coordinate is one contiguous vector:
the compiled loops over the bases then run in SIMD lanes, and numpy's column operations are faster
too (both measured with ``bark bench speed``).  Indexing is the same as for any ``(n, 3)`` array;
assigning a C-ordered array to these fields converts it.
"""

from __future__ import annotations

from types import ModuleType

import attrs
import numpy as np

import scipy.sparse as sp

from bark.forces import Mechanics, damping_forces, incidence

__all__ = ["State", "project_to_surface", "cylinder_points", "columns"]


def cylinder_points(theta: np.ndarray, z: np.ndarray, radius) -> np.ndarray:
    """Cartesian points at angle ``theta`` (radians), height ``z`` on a cylinder of ``radius``."""
    return np.column_stack([radius * np.cos(theta), radius * np.sin(theta), z])


def project_to_surface(points: np.ndarray, radius, velocities: np.ndarray | None = None) -> None:
    """Surface constraint (eq. 9), in place: move each point radially onto the trunk surface.

    ``radius`` is the trunk radius at each point's height (a scalar or one value per point).  When
    ``velocities`` is given, their radial component is removed as well: a base constrained to the
    surface has no velocity through it, and a radial velocity left in place would leak into the
    tangential motion as the base moves round the trunk.
    """
    xy = points[:, :2]
    radius = np.asarray(radius, dtype=float)
    xy *= (radius / np.sqrt(np.einsum("ij,ij->i", xy, xy)))[:, None]
    if velocities is not None:
        vxy = velocities[:, :2]
        vxy -= (np.einsum("ij,ij->i", vxy, xy) / (radius * radius))[:, None] * xy


def _unit_xy(points: np.ndarray) -> np.ndarray:
    rho = np.hypot(points[:, 0], points[:, 1])
    safe = np.where(rho > 0.0, rho, 1.0)
    return np.where((rho > 0.0)[:, None], points[:, :2] / safe[:, None], [1.0, 0.0])


def columns(a) -> np.ndarray:
    """``a`` as a float array stored column by column (a view when it already is one)."""
    return np.asfortranarray(a, dtype=float)


def _default_kernels() -> ModuleType:
    from bark.kernels import load

    return load("numpy")


@attrs.define(eq=False, kw_only=True)
class State:
    """Positions, velocities and springs of the leaf-base layer at time ``t``.

    Integrators change ``x`` and ``v`` (and only those); the simulation changes ``t``, projects onto
    the surface and breaks springs.
    """

    x: np.ndarray = attrs.field(converter=columns)
    """Positions of the bases, shape ``(n, 3)``."""
    v: np.ndarray = attrs.field(converter=columns)
    """Velocities of the bases, shape ``(n, 3)``."""
    anchor: np.ndarray = attrs.field(converter=columns)
    """Anchor points (each base's original site, moved with the trunk surface), ``(n, 3)``.
    Anchors move only radially: ``anchor = (r(t, z0)·anchor_dir, z0)``, a function of t alone."""
    anchor_dir: np.ndarray = attrs.field(
        default=attrs.Factory(lambda self: _unit_xy(self.anchor), takes_self=True), converter=columns
    )
    """Unit horizontal direction of each anchor, ``(n, 2)``: fixed for the whole run (default: the
    directions of ``anchor``)."""
    pairs: np.ndarray
    """Spring end points ``(i, j)``, shape ``(m, 2)``; row number = spring id."""
    rest: np.ndarray
    """Rest length of every spring, ``(m,)``."""
    fmax: np.ndarray
    """Breaking threshold of every spring (force units), ``(m,)``."""
    intact: np.ndarray
    """Whether each spring is still intact, ``(m,)`` bool.  Changed only by ``Simulation.break_springs``."""
    mechanics: Mechanics
    """Material constants (k, c, b, m)."""
    t: float = 0.0
    """Simulated time."""
    h: float = 0.0
    """Length of the step that led to this state (set by the simulation; rate-based breakers use it)."""
    kernels: ModuleType = attrs.field(factory=lambda: _default_kernels(), repr=False)
    """The compute backend (a module of ``bark.kernels``); the simulation sets it."""
    scratch: dict = attrs.field(factory=dict, init=False, repr=False)
    """Work buffers a backend keeps between steps (derived; never part of the state proper)."""
    _inc: tuple[np.ndarray, sp.csr_matrix] | None = attrs.field(default=None, init=False, repr=False)

    @property
    def incidence(self) -> sp.csr_matrix:
        """Spring-to-base incidence of ``pairs`` (derived, rebuilt whenever ``pairs`` is replaced)."""
        if self._inc is None or self._inc[0] is not self.pairs:
            self._inc = (self.pairs, incidence(self.pairs, self.n_bases))
        return self._inc[1]

    @property
    def n_bases(self) -> int:
        return self.x.shape[0]

    @property
    def n_springs(self) -> int:
        return self.pairs.shape[0]

    def forces(self, x: np.ndarray | None = None, v: np.ndarray | None = None) -> np.ndarray:
        """Total force on every base (eq. 4): intact neighbour springs + anchors + damping.

        ``x`` and ``v`` default to the state's own; integrators may evaluate at trial points.
        """
        f = self.elastic_forces(x)
        if self.mechanics.b:
            f += damping_forces(self.v if v is None else v, self.mechanics.b)
        return f

    def elastic_forces(self, x: np.ndarray | None = None) -> np.ndarray:
        """Spring and anchor forces only (no damping), at ``x`` (default: the state's own)."""
        return self.kernels.elastic_forces(self, self.x if x is None else x)

    def tension(self) -> np.ndarray:
        """Tension of every spring at the current positions (broken ones included; mask with ``intact``)."""
        out = np.empty(self.n_springs)
        self.kernels.measure(self, out)
        return out

    def is_finite(self) -> bool:
        return bool(np.isfinite(self.x).all() and np.isfinite(self.v).all())
