"""The whole grasstree's geometry: an apical dome on the trunk, and Ridley's packing of the leaves on it.

Paper, "Phyllotactic pattern generation" and Fig. 3: the trunk is a cylinder topped by an apical dome,
a surface of revolution given by a profile curve and joined smoothly to the cylinder.  "All leaves were
positioned using the Ridley (1986) model": a fixed divergence angle, each organ displaced along the
surface by the area it occupies, run dynamically — a new leaf is inserted at the tip as primary growth
(the dome rising) and secondary growth (the dome widening with the trunk) make room for it, and a leaf
leaves the dome for the trunk when the dome's base rises past it.  There it joins the mechanics
(:meth:`Simulation.join`) at the site where it crossed, its springs at the lengths they have then.

**The formulation implemented.**  Leaf ``i`` turns ``i·φ`` about the axis (``φ`` the divergence angle,
signed by the lattice's handedness).  Primary growth raises the dome's base at ``v = join_rate · rise``:
``H(t) = H₀ + v·t``, ``H₀`` the site of the last base of the trunk of the start (Table 1's "vertical
displacement for the initial cylindrical trunk", ``h = rise``: that trunk is the cylinder lattice, base
``i`` at height ``i·h``).  A leaf takes the area ``a(t) = a₀ · (R̄(t)/R̄(0))^p`` (``organ_area`` a₀,
``area_exponent`` p; R̄ the trunk's radius at the dome's base without the growth law's own features,
such as bulges: a leaf's size follows the plant, not a bulge it passes).  Between two leaves that have
crossed onto the trunk lies the area ``a`` of the band of trunk between them, so the leaves cross at
the rate ``dN/dt = v / s(t)``, ``s(t) = a(t) / (2π R(t, H(t)))`` the vertical spacing of the leaves
crossing at ``t`` (R the radius there, bulges included: a bulge at the dome's base packs its leaves
closer in height and stretches them around the trunk).  Leaf ``i`` crosses when ``N(t) = i − (n₀ − 1)``,
at height ``H(t)`` (:class:`Packing`, which tabulates ``N`` by the trapezoid rule every
``STEP_ORGANS`` leaves, closer where the spacing changes fast).  On the dome the leaves above its
base lie ``a`` apart in area, counted from
the base (:class:`Apex`), so each meets the trunk exactly where :class:`Packing` puts it.

With the defaults (``a₀`` one base's area on the trunk of the start, ``p = 1``) and a radius that is
the same at every height, ``s`` is Table 1's ``h`` for good: the leaves continue the lattice, and
the paper's calibration (45,000 bases on 1.62 m, 412.5 leaves a year, 0.9 m of trunk in 60 years)
holds; their area then grows with the trunk (``2πRh``).  ``p = 0`` keeps the paper's leaf area
instead, ``p = 2`` the lattice's shape (its parastichy angle); no one law keeps all three as the
trunk widens from 10.5 to 29 cm (docs/model.md: The whole tree).

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

__all__ = ["Dome", "Packing", "Apex", "SAMPLES", "STEP_ORGANS", "leaf_corners", "join_radii"]

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
        from scipy.interpolate import CubicSpline  # slow to import: only for a curve given by points
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


STEP_ORGANS = 16
"""Leaves between two samples of :class:`Packing`'s table: the trunk's radius changes over thousands."""
STEP_CHANGE = 1e-3
"""Largest relative change of the spacing between two samples; a step that would change it more is
halved (up to ``STEP_HALVINGS`` times): where the radius changes fast, as ``√t`` at ``t = 0``."""
STEP_HALVINGS = 30
MAX_SAMPLES = 10_000_000


@attrs.frozen(kw_only=True, eq=False)
class Packing:
    """Where and when each leaf base joins the trunk: Ridley's packing on a trunk whose bases follow
    ``lattice`` (module docstring).  A value made once per simulation (:meth:`of`), a pure function
    of the lattice and the growth law: checkpoints need nothing from it.

    Without a table the leaves keep the lattice's rise (``Lattice.keeps_rise`` on a trunk of one
    radius at every height, or a trunk none join): ``N(t) = join_rate · t`` and leaf ``i`` at ``i·h``,
    the lattice's own sites."""

    lattice: Lattice
    times: np.ndarray | None = None
    """Sample times of the table (time units), from 0 until every leaf has crossed."""
    counts: np.ndarray | None = None
    """Leaves crossed onto the trunk by each sample time (fractional: ``N``)."""
    rises: np.ndarray | None = None
    """The vertical spacing ``s`` of the leaves crossing at each sample time (length units)."""

    @classmethod
    def of(cls, lattice: Lattice, growth=None) -> "Packing":
        """The packing on ``lattice`` of a trunk growing by ``growth`` (a placed growth strategy: its
        ``radius(t, z)``, and ``without(effect)`` for each effect it ``provides``).  ``growth`` may be
        left out for leaves that keep the lattice's rise (the defaults, and no growth features)."""
        uniform = lattice.keeps_rise and (growth is None or not getattr(growth, "provides", ()))
        if lattice.initial >= lattice.n_bases or uniform:
            return cls(lattice=lattice)
        if growth is None:
            raise ValueError("a packing with its own leaf area, or on a trunk with features, needs the growth law")
        trunk = growth
        for effect in growth.provides:
            trunk = trunk.without(effect.name)

        def at_top(law, t: float) -> float:
            return float(np.asarray(law.radius(t, float(lattice.top(t)))).reshape(-1)[0])

        v = lattice.join_rate * lattice.rise
        r0 = at_top(trunk, 0.0)
        s0 = lattice.rise if lattice.organ_area is None else lattice.organ_area / (2.0 * math.pi * r0)  # at t = 0

        def rise(t: float) -> float:  # a(t) / 2πR, as s0 times ratios: exactly s0 where they are 1
            plain = at_top(trunk, t)
            s = s0 * (plain / r0) ** (lattice.area_exponent - 1.0) * (plain / at_top(growth, t))
            if not (math.isfinite(s) and s > 0.0):
                raise BarkError(f"Ridley's packing: the leaves joining at t = {t:.6g} would have a spacing of {s!r} "
                                "(the trunk's radius at the dome's base is not a positive number then)")
            return s

        need = lattice.n_bases - lattice.initial
        times, counts, rises = [0.0], [0.0], [rise(0.0)]
        slope = 0.0  # |ds/dt| over the last step: the next is sized to change s by STEP_CHANGE at most
        while counts[-1] < need:
            if len(times) > MAX_SAMPLES:
                raise BarkError(f"Ridley's packing: more than {MAX_SAMPLES:,} samples to place {need:,} leaves (the spacing "
                                f"changes too fast: at t = {times[-1]:.6g} it is {rises[-1]!r})")
            dt = STEP_ORGANS * rises[-1] / v
            if slope > 0.0:
                dt = min(dt, STEP_CHANGE * rises[-1] / slope)
            for _ in range(STEP_HALVINGS):  # and finer where it changes faster still (r0 + G√t at t = 0)
                s = rise(times[-1] + dt)
                if abs(s - rises[-1]) <= STEP_CHANGE * rises[-1]:
                    break
                dt *= 0.5
            slope = abs(s - rises[-1]) / dt
            counts.append(counts[-1] + 0.5 * dt * v * (1.0 / rises[-1] + 1.0 / s))
            times.append(times[-1] + dt)
            rises.append(s)
        return cls(lattice=lattice, times=np.array(times), counts=np.array(counts), rises=np.array(rises))

    @property
    def uniform(self) -> bool:
        """Whether the leaves keep the lattice's rise (no table)."""
        return self.times is None

    def crossed(self, t) -> np.ndarray:
        """``N(t)``: how many leaves have crossed onto the trunk by time ``t`` (fractional)."""
        if self.uniform:
            return self.lattice.join_rate * np.asarray(t, dtype=float)
        return np.interp(t, self.times, self.counts)

    def top(self, t) -> np.ndarray:
        """Height of the dome's base at time ``t`` (``Lattice.top``: primary growth, linear in time)."""
        return self.lattice.top(t)

    def top_index(self, t) -> np.ndarray:
        """The (fractional) index of the leaf at the dome's base at time ``t``."""
        if self.uniform:
            return self.lattice.top_index(t)
        return self.lattice.initial - 1 + self.crossed(t)

    def crossing(self, ids) -> np.ndarray:
        """When each leaf ``ids`` (ids of bases that join, ``>= lattice.initial``) crosses onto the trunk."""
        m = np.asarray(ids, dtype=float) - (self.lattice.initial - 1)
        if self.uniform:
            return m / self.lattice.join_rate
        return np.interp(m, self.counts, self.times)

    def rise_at(self, t) -> np.ndarray:
        """The vertical spacing of the leaves crossing at time ``t``."""
        if self.uniform:
            return np.full(np.shape(t), self.lattice.rise)
        return np.interp(t, self.times, self.rises)

    def rise_of(self, ids) -> np.ndarray:
        """Each base's rise where it joined (the lattice's for the trunk of the start): its rhomboid's height."""
        ids = np.asarray(ids)
        out = np.full(ids.shape, self.lattice.rise)
        later = ids >= self.lattice.initial
        if not self.uniform and later.any():
            out[later] = self.rise_at(self.crossing(ids[later]))
        return out

    def bases_at(self, t: float) -> int:
        """How many bases the trunk has at time ``t`` (bases join at multiples of ``join_every``)."""
        lat = self.lattice
        if self.uniform:
            return lat.bases_at(t)
        joined_until = math.floor(t / lat.join_every + 1e-9) * lat.join_every
        return min(lat.n_bases, lat.initial + int(math.floor(float(self.crossed(joined_until)) + 1e-9)))

    def next_join(self, t: float, present: int) -> float | None:
        """When bases next join after time ``t`` (``present`` on the trunk), or ``None``: all are there."""
        lat = self.lattice
        if self.uniform or present >= lat.n_bases:
            return lat.next_join(t, present)
        k = max(math.floor(t / lat.join_every + 1e-9) + 1, math.floor(float(self.crossing(present)) / lat.join_every) - 1)
        while self.bases_at(k * lat.join_every) <= present:
            k += 1
        return k * lat.join_every

    def sites(self, radius: float, rng: np.random.Generator, first: int, count: int) -> tuple[np.ndarray, np.ndarray]:
        """Angle θ and height z of the bases ``first .. first + count − 1`` that join now, on a trunk of
        ``radius`` at the dome's base: where each crossed (``Lattice.sites``, jittered alike)."""
        if self.uniform:
            return self.lattice.sites(radius, rng, first, count)
        when = self.crossing(np.arange(first, first + count))
        return self.lattice.sites(radius, rng, first, count, z=self.top(when), rise=self.rise_at(when))


@attrs.frozen(kw_only=True)
class Apex:
    """The dome on a trunk whose leaves are packed by ``packing``, and Ridley's placement of the organs
    on it.

    ``t`` is simulated time, ``radius`` the trunk radius at the dome's base at that time (the growth
    law's, at height :meth:`top`)."""

    dome: Dome = attrs.field(factory=Dome)
    packing: Packing = attrs.field(factory=lambda: Packing(lattice=Lattice()))

    def top_index(self, t) -> np.ndarray:
        """The (fractional) index of the leaf at the dome's base at time ``t`` (``Packing.top_index``)."""
        return self.packing.top_index(t)

    def top(self, t) -> np.ndarray:
        """Height of the dome's base (where the trunk's cylinder ends) at time ``t``: primary growth,
        linear in time at ``join_rate · rise`` (``Lattice.top``)."""
        return self.packing.top(t)

    def organ_area(self, t, radius) -> np.ndarray:
        """Area one organ takes at time ``t`` on a dome of ``radius``: that of one base crossing onto the
        trunk then, ``2πR·s(t)``."""
        return 2.0 * math.pi * np.asarray(radius, dtype=float) * self.packing.rise_at(t)

    def tip_index(self, t, radius) -> int:
        """Index of the youngest organ (at the tip) at time ``t``."""
        room = self.dome.area(radius) / self.organ_area(t, radius)  # organs the dome holds
        return int(math.floor(float(self.top_index(t)) + float(room) - 0.5 + 1e-9))

    def organs(self, t, radius, first: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Ids and positions ``(n, 3)`` of the organs on the dome at time ``t`` (those above the dome's
        base, from ``first``, default the first above it, up to the tip), youngest last: each the
        organ area apart in area, counted from the dome's base, so that each reaches the base where
        and when the packing has it cross."""
        j = float(self.top_index(t))
        first = math.floor(j) + 1 if first is None else first
        ids = np.arange(first, self.tip_index(t, radius) + 1)
        sigma = np.maximum(ids - j, 0.0) * self.organ_area(t, radius)  # area between organ and the dome's base
        rho, u = self.dome.at_area(self.dome.area(radius) - sigma, radius)
        theta = ids * self.packing.lattice.turn
        return ids, np.column_stack([rho * np.cos(theta), rho * np.sin(theta), float(self.top(t)) + u])


def leaf_corners(lattice: Lattice, radius, rise=None) -> np.ndarray:
    """Corners of each base's rhomboid leaf-base shape (paper, Fig. 5C, D), shape ``(n, 4, 2)``: offsets
    (arc length, height) from the base's centre, counter-clockwise seen from outside the trunk.

    The corners are the midpoints between a base and its partition neighbours ``±p``, ``±q``
    (``lattice.partition_offsets()``) on the lattice at ``radius``, the trunk radius where and when the
    base joined, and ``rise``, the vertical spacing of the leaves packed then (``Packing.rise_of``;
    default the lattice's), one of each per base: the shape is fixed then and carried with its base.
    With ``p``, ``q`` whose lattice vectors span twice a base's area (34 and 144 on a golden-angle
    lattice), each rhomboid has exactly the area ``2πR·rise`` of one base, and together they
    partition the cylinder."""
    u, v = _half_vectors(lattice, radius, rise)
    ccw = (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0] > 0)[:, None, None]
    return np.where(ccw, np.stack([u, v, -u, -v], axis=1), np.stack([u, -v, -u, v], axis=1))


def _half_vectors(lattice: Lattice, radius, rise=None) -> tuple[np.ndarray, np.ndarray]:
    """Half the lattice vectors (arc length, height) to the partition neighbours ``p`` and ``q`` at
    ``radius`` and ``rise`` (one per base; default rise: the lattice's): the rhomboid's corners are
    ``±`` these."""
    radius = np.atleast_1d(np.asarray(radius, dtype=float))
    rise = np.broadcast_to(lattice.rise if rise is None else np.asarray(rise, dtype=float), radius.shape)
    phi = lattice.turn

    def half(o: int) -> np.ndarray:
        turn = math.remainder(o * phi, 2.0 * math.pi)
        return 0.5 * np.column_stack([radius * turn, o * rise])

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
