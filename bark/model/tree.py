"""The whole grasstree's geometry: an apical dome on the trunk, and Ridley's placement of leaf bases on it.

Paper, "Phyllotactic pattern generation" and Fig. 3: the trunk is a cylinder topped by an apical dome,
a surface of revolution given by a profile curve and joined smoothly to the cylinder.  Leaves are
placed by Ridley's (1986) model as applied by Prusinkiewicz et al. (2001): a fixed divergence angle,
and each organ displaced along the surface by the area it occupies — successive organs are the organ
area ``a`` apart in surface area, each at the middle of its own.  It runs dynamically: a new organ is
inserted at the tip as soon as primary growth (the dome rising) and secondary growth (the dome
widening with the trunk) have made room for it (area ``a/2`` between it and the tip), and an organ
leaves the dome for the trunk when the area below it on the dome is used up.  There it joins the mechanics (:meth:`Simulation.join`).

**The formulation implemented.**  Let ``h`` be the lattice's vertical displacement (``rise``), ``φ`` its
divergence angle and ``R(t)`` the trunk radius at the dome's base.  The organ area is the area one base
takes on the trunk just below the dome, ``a(t) = 2π R(t) h``, so that on the cylinder Ridley's rule
puts successive bases ``h`` apart — Table 1's ``h`` — and the paper's calibration holds together (1.62 m
of trunk = 45,000 bases × 0.036 mm; a leaf a time unit per ``h`` of height growth, 412.5 a year).
With ``j(t) = n_start − 1 + join_rate·t`` the (fractional) index of the base at the dome's base, at
height ``H(t) = j(t)·h``, organ ``i > j(t)`` has area ``σ = (i − j(t))·a`` between it and the dome's base,
so its area from the tip is ``A_dome(R) − σ``; it exists (has been inserted) once that is ``≥ 0``, i.e.
the dome holds ``A_dome/a`` organs, and it passes onto the trunk at ``t`` where ``j(t) = i``: at height
``i·h`` and angle ``i·φ``, the lattice's site (:class:`~bark.model.lattice.Lattice`, whose jitter then breaks
the lattice's symmetry).  Everything here is a pure function of ``t`` and ``R``: nothing is stored, so
checkpoints need nothing from it.

**The profile** is given in units of the trunk radius, as ``(ρ, u)`` = (distance from the axis,
height above the dome's base): from ``(1, 0)``, where it meets the cylinder with a vertical tangent,
to ``(0, height)``, the tip.  ``shape = "ellipse"`` is the superellipse ``ρ^p + (u/height)^p = 1``
(``p = exponent``; 2 is an ellipse, larger is flatter); ``shape = "points"`` passes a parametric cubic
spline (scipy) through the given points with the tangent vertical at the join and horizontal at the
tip, so a scene's own curve also joins the cylinder smoothly and closes without a cusp.
"""

from __future__ import annotations

import functools
import math

import attrs
import numpy as np

from bark.validators import in_range, one_of
from bark.errors import BarkError, Ref
from bark.model.lattice import Lattice
from bark.model.physics import weighted_radius

__all__ = ["Dome", "Apex", "SAMPLES", "leaf_corners", "join_radii"]

SAMPLES = 8193
"""Points along the profile at which its arc length and area are tabulated (area error ~1e-8)."""


def _points(value):
    """Lists of pairs become a tuple of float pairs; anything else is left for the validator."""
    if isinstance(value, (list, tuple)) and all(isinstance(p, (list, tuple)) for p in value):
        try:
            return tuple((float(p[0]), float(p[1])) if len(p) == 2 else tuple(p) for p in value)
        except (TypeError, ValueError):
            return value
    return value


def _check_points(instance, attribute, value) -> None:
    def bad(problem: str) -> BarkError:
        return BarkError("{0}: " + problem, Ref(None, attribute.name, value))

    if value == ():
        if instance.shape == "points":
            raise bad("shape 'points' needs at least two points, from [1, 0] (the join) to [0, height] (the tip)")
        return
    if instance.shape != "points":
        raise bad(f"points draw the dome only with shape = 'points'; with shape = {instance.shape!r} they would be "
                  "ignored: give shape = 'points', or leave the points out")
    if not isinstance(value, tuple) or not all(isinstance(p, tuple) and len(p) == 2 for p in value):
        raise bad("must be a list of [radius fraction, height] pairs, e.g. [[1, 0], [0.6, 0.8], [0, 1]]")
    arr = np.array(value, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise bad("every coordinate must be a finite number")
    if len(arr) < 2 or tuple(arr[0]) != (1.0, 0.0) or arr[-1, 0] != 0.0 or not arr[-1, 1] > 0.0:
        raise bad("must run from [1, 0] (the join with the trunk) to [0, height > 0] (the tip)")
    step = np.diff(arr, axis=0)
    if np.any(step[:, 0] > 0) or np.any(step[:, 1] < 0) or np.any(np.all(step == 0, axis=1)):
        raise bad("each point must be no further from the axis and no lower than the one before, and differ from it")
    if arr[:, 1].max() > 100.0:
        raise bad("a dome higher than 100 trunk radii is outside what bark represents")


@attrs.frozen(kw_only=True)
class Dome:
    """The apical dome's profile, in units of the trunk radius (module docstring)."""

    shape: str = attrs.field(default="ellipse", validator=one_of("ellipse", "points"))
    """``ellipse`` (a superellipse with ``height`` and ``exponent``) or ``points`` (a curve through ``points``)."""
    height: float = attrs.field(default=1.0, validator=in_range(0.01, 100.0))
    """Height of the dome over the trunk radius (``ellipse``; 1 is a hemisphere)."""
    exponent: float = attrs.field(default=2.0, validator=in_range(1.1, 20.0))
    """Superellipse exponent p (``ellipse``): 2 is an ellipse, larger values a flatter top."""
    points: tuple[tuple[float, float], ...] = attrs.field(default=(), converter=_points, validator=_check_points)
    """``[radius fraction, height]`` pairs from ``[1, 0]`` (the join) to ``[0, height]`` (the tip) (``points``)."""

    def curve(self, n: int = SAMPLES) -> tuple[np.ndarray, np.ndarray]:
        """``(ρ, u)`` at ``n`` points from the join to the tip."""
        if self.shape == "ellipse":
            psi = np.linspace(0.0, 0.5 * math.pi, n)
            e = 2.0 / self.exponent
            rho, u = np.cos(psi) ** e, self.height * np.sin(psi) ** e
            rho[-1] = 0.0
            return rho, u
        return self._spline()(np.linspace(0.0, 1.0, n)).T.copy()

    def _spline(self):
        """The parametric spline through ``points`` on normalised chord length, tangents clamped."""
        from scipy.interpolate import CubicSpline  # 0.5 s to import: only for a curve given by points
        p = np.array(self.points)
        c = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
        length = c[-1]
        s = c / length
        keep = np.ones(len(s), bool)  # a point within rounding of the one before (or of the tip) adds nothing
        keep[1:-1] = (s[1:-1] > s[:-2]) & (s[1:-1] < 1.0)
        return CubicSpline(s[keep], p[keep], bc_type=((1, [0.0, length]), (1, [-length, 0.0])))

    def tangent_at_join(self) -> np.ndarray:
        """Unit tangent ``(dρ, du)`` of the profile where it meets the trunk (``(0, 1)``: vertical)."""
        if self.shape == "points":
            d = self._spline()(0.0, 1)
        else:
            rho, u = self.curve(2**16 + 1)
            d = np.array([rho[1] - rho[0], u[1] - u[0]])
        return d / np.hypot(*d)

    @property
    def table(self) -> "_Table":
        """Arc length and area from the tip along the profile (cached per dome)."""
        return _table(self)

    def area(self, radius) -> np.ndarray:
        """Surface area of the dome on a trunk of ``radius``."""
        return self.table.total * np.square(radius)

    def at_area(self, area_from_tip, radius) -> tuple[np.ndarray, np.ndarray]:
        """Distance from the axis and height above the join of the points whose surface area up to the
        tip is ``area_from_tip``, on a trunk of ``radius``."""
        radius = np.asarray(radius, dtype=float)
        a = np.clip(np.asarray(area_from_tip, dtype=float) / np.square(radius), 0.0, self.table.total)
        t = self.table
        return radius * np.interp(a, t.area, t.rho), radius * np.interp(a, t.area, t.u)


@attrs.frozen
class _Table:
    """The profile tabulated from the tip (``area`` increasing from 0): ρ, u, area per radius²."""

    rho: np.ndarray
    u: np.ndarray
    area: np.ndarray

    @property
    def total(self) -> float:
        return float(self.area[-1])


@functools.lru_cache(maxsize=32)
def _table(dome: Dome) -> _Table:
    rho, u = (a[::-1] for a in dome.curve())
    if np.any(rho < -1e-9) or np.any(rho > 1.0 + 1e-9):
        raise BarkError("{0}: the curve through these points leaves the trunk's width (radius fraction outside 0..1); add points",
                        Ref(None, "points", dome.points))
    rho = np.clip(rho, 0.0, 1.0)
    slant = np.hypot(np.diff(rho), np.diff(u))
    band = math.pi * (rho[1:] + rho[:-1]) * slant  # each band a frustum: exact for the sampled curve
    return _Table(rho=rho, u=u, area=np.concatenate([[0.0], np.cumsum(band)]))


@attrs.frozen(kw_only=True)
class Apex:
    """The dome on a trunk whose bases follow ``lattice``, and Ridley's placement of the organs on it.

    ``t`` is simulated time, ``radius`` the trunk radius at the dome's base at that time (the growth
    law's, at height :meth:`top`)."""

    dome: Dome = attrs.field(factory=Dome)
    lattice: Lattice = attrs.field(factory=Lattice)

    def top_index(self, t) -> np.ndarray:
        """The (fractional) index of the base at the dome's base at time ``t`` (``Lattice.top_index``)."""
        return self.lattice.top_index(t)

    def top(self, t) -> np.ndarray:
        """Height of the dome's base (where the trunk's cylinder ends) at time ``t``: primary growth,
        linear in time at ``join_rate · rise`` (``Lattice.top``)."""
        return self.lattice.top(t)

    def organ_area(self, radius) -> np.ndarray:
        """Area one organ takes: that of one base on the trunk below the dome, ``2π R h``."""
        return 2.0 * math.pi * np.asarray(radius, dtype=float) * self.lattice.rise

    def tip_index(self, t, radius) -> int:
        """Index of the youngest organ (at the tip) at time ``t``."""
        room = self.dome.area(radius) / self.organ_area(radius)  # organs the dome holds
        return int(math.floor(float(self.top_index(t)) + float(room) - 0.5 + 1e-9))

    def organs(self, t, radius, first: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Ids and positions ``(n, 3)`` of the organs on the dome at time ``t`` (those above the dome's
        base, from ``first``, default the first above it, up to the tip), youngest last."""
        j = float(self.top_index(t))
        first = math.floor(j) + 1 if first is None else first
        ids = np.arange(first, self.tip_index(t, radius) + 1)
        sigma = np.maximum(ids - j, 0.0) * self.organ_area(radius)  # area between organ and the dome's base
        rho, u = self.dome.at_area(self.dome.area(radius) - sigma, radius)
        theta = ids * self.lattice.turn
        return ids, np.column_stack([rho * np.cos(theta), rho * np.sin(theta), float(self.top(t)) + u])


def leaf_corners(lattice: Lattice, radius) -> np.ndarray:
    """Corners of each base's rhomboid leaf-base shape (paper, Fig. 5C, D), shape ``(n, 4, 2)``: offsets
    (arc length, height) from the base's centre, counter-clockwise seen from outside the trunk.

    The corners are the midpoints between a base and its partition neighbours ``±p``, ``±q``
    (``lattice.partition_offsets()``) on the lattice at ``radius``, the trunk radius where and when the
    base joined (one per base): the shape is fixed then and carried with its base.  With ``p``, ``q``
    whose lattice vectors span twice a base's area (34 and 144 on a golden-angle lattice), each
    rhomboid has exactly the area ``2πRh`` of one base, and together they partition the cylinder."""
    u, v = _half_vectors(lattice, radius)
    ccw = (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0] > 0)[:, None, None]
    return np.where(ccw, np.stack([u, v, -u, -v], axis=1), np.stack([u, -v, -u, v], axis=1))


def _half_vectors(lattice: Lattice, radius) -> tuple[np.ndarray, np.ndarray]:
    """Half the lattice vectors (arc length, height) to the partition neighbours ``p`` and ``q`` at
    ``radius`` (one per base): the rhomboid's corners are ``±`` these."""
    radius = np.atleast_1d(np.asarray(radius, dtype=float))
    phi = lattice.turn

    def half(o: int) -> np.ndarray:
        turn = math.remainder(o * phi, 2.0 * math.pi)
        return 0.5 * np.column_stack([radius * turn, np.full_like(radius, o * lattice.rise)])

    p, q = lattice.partition_offsets()
    return half(p), half(q)


def join_radii(sim) -> np.ndarray:
    """The trunk radius at each base's site when it joined (the growth law at its birth time)."""
    s, growth = sim.state, sim.growth
    z, born = s.anchor[:, 2], s.born
    times, group = np.unique(born, return_inverse=True)
    part = growth.part_
    if len(times) and part is not None and part.weights is not None and not part.uniform:
        # radius = q(t)[0] + w(z)[0]·q(t)[1] + ..., to the bit: the weights of all sites at once
        q = np.array([part.at(float(t)) for t in times]).reshape(len(times), -1)
        return weighted_radius(q[group].T, np.atleast_2d(np.asarray(part.weights(z, part.params), dtype=float)))
    out = np.empty(s.n_bases)
    for i, t in enumerate(times):  # bases join in groups: one call of the law per group
        at = group == i
        out[at] = np.broadcast_to(growth.radius(float(t), z[at]), z[at].shape)
    return out
