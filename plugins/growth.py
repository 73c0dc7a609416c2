"""Built-in growth laws: the trunk radius as a function of time (eq. 9)."""

from __future__ import annotations

import math
from typing import ClassVar

import attrs
import numpy as np

from bark.validators import REAL_MAX, construct, in_range, non_negative, optional, positive, positive_int
from bark.errors import BarkError, Ref
from bark.contract.parts import GrowthPart
from bark.contract.strategies import Growth
from bark.model.effects import Effect
from bark.model.physics import weighted_radius

__all__ = ["SqrtGrowth", "LinearGrowth", "Bulge", "BulgeSeries", "BulgeGrowth", "bulge_radius", "bulge_time",
           "bulge_weights", "sin2_profile"]

ROW = 6
"""Numbers per bulge in the bulge law's part: peak, half width, magnitude, decay, has its own G, start."""


def sqrt_radius(t, z, p):
    """``r0 + G·√t`` with ``p = (r0, G)`` (eq. 9)."""
    return p[0] + p[1] * np.sqrt(t)


def linear_radius(t, z, p):
    """``r0 + G·t`` with ``p = (r0, G)``."""
    return p[0] + p[1] * t


@attrs.frozen(kw_only=True)
class SqrtGrowth(Growth):
    """``r(t) = r0 + G·√t`` — the paper's secondary growth (eq. 9)."""

    r0: float = attrs.field(default=0.2, validator=positive)
    """Initial trunk radius r_i (Table 2: 0.2 = 6 cm)."""
    G: float = attrs.field(default=0.014, validator=non_negative)
    """Growth constant, length / time^½ (Table 2: 0.014 vertical, 0.011 reticulate, 0.007 diamond)."""

    def part(self) -> GrowthPart:
        """Compiled: ``r0 + G·√t``, the same at every height."""
        return GrowthPart(radius=sqrt_radius, params=(self.r0, self.G), uniform=True)


@attrs.frozen(kw_only=True)
class LinearGrowth(SqrtGrowth):
    """``r(t) = r0 + G·t`` — constant radial growth rate."""

    r0: float = attrs.field(default=0.2, validator=positive)
    """Initial trunk radius."""
    G: float = attrs.field(default=0.014, validator=non_negative)
    """Growth rate, length / time."""

    def part(self) -> GrowthPart:
        """Compiled: ``r0 + G·t``, the same at every height."""
        return GrowthPart(radius=linear_radius, params=(self.r0, self.G), uniform=True)


def _tables_of(cls, key: str, what: str):
    """A converter: a list of tables (or ``cls`` instances) → a tuple of ``cls``; a bad entry is a
    one-line error naming it (``bulges[1].G``)."""
    def convert(value):
        if not isinstance(value, (list, tuple)):
            raise BarkError(f"{{0}}: must be a list of {what} tables ([[growth.{key}]] in a scene file)",
                            Ref(None, key, value))
        return tuple(v if isinstance(v, cls) else construct(cls, _threshold_moved(v, key, i), f"a {what}",
                                                            prefix=f"{key}[{i}].")
                     for i, v in enumerate(value))
    return convert


def _threshold_moved(table, key: str, i: int):
    """A bulge's table as an earlier version wrote it: its ``f_max`` (the bulge's threshold) is the
    breaker's setting now, refused in one line naming the new key; ``None`` (unset, as an earlier
    run's scene.toml records it) is dropped."""
    if not (isinstance(table, dict) and "f_max" in table):
        return table
    if table["f_max"] is not None:
        raise BarkError("{0}: a bulge's threshold is the breaker's setting now: give [breaker] regions = "
                        f"{{{{ bulge = {table['f_max']!r} }}}}", Ref(None, f"{key}[{i}].f_max", table["f_max"]))
    return {k: v for k, v in table.items() if k != "f_max"}


def _base(value):
    if isinstance(value, Growth):
        return value
    if isinstance(value, dict):
        from bark.contract import registry

        params = dict(value)
        name = params.pop("name", "sqrt")
        if name == "bulge":
            raise BarkError("{0}: a bulge law cannot sit on another bulge law; list all bulges in one", Ref(None, "base.name", name))
        try:
            return registry.create("growth", name, **params)
        except BarkError as err:
            raise err.within(prefix="base.") from None
    raise BarkError("{0}: must be a growth strategy or a table like {{name = 'sqrt', G = 0.014}}", Ref(None, "base", value))


def sin2_profile(u):
    """``sin²(π(u + 1)/2) = cos²(πu/2)`` for ``|u| <= 1``, by arithmetic alone: ``((1 − s)·G(s))²`` with
    ``s = u²`` and ``G(s) = cos(π√s/2)/(1 − s) = Σ b_n sⁿ``, whose Taylor coefficients are
    ``b_n = Σ_{k≤n} (−π²/4)^k/(2k)!`` (the series of ``cos(π√s/2)`` summed; the first left out is
    1.8e−17).  1 at ``u = 0`` and 0 at ``u = ±1`` exactly, even in ``u`` exactly, within 4e−16 of
    ``sin²`` (closer than ``np.sin`` squared, measured against extended precision).  No call of a
    transcendental function: the compiled kernel evaluates it for every base inside a bulge at every
    step, where the sine was measured to cost a large share of the whole tree's kernel time."""
    s = u * u
    g = -3.419461019595456e-15 + s * 1.8278159503151067e-17
    g = 5.26020559053867e-13 + s * g
    g = -6.513361059074086e-11 + s * g
    g = 6.321469473201112e-09 + s * g
    g = -4.64766008408616e-07 + s * g
    g = 2.473727636465199e-05 + s * g
    g = -0.0008945229984747746 + s * g
    g = 0.019968957764878188 + s * g
    g = -0.23370055013616983 + s * g
    g = 1.0 + s * g
    w = (1.0 - s) * g
    return w * w


def bump(z, center, half_width):
    """The ``sin²`` profile of a bulge (:func:`sin2_profile`): 1 at ``center``, 0 with zero slope at
    ``center ± half_width`` and 0 beyond.  One height (the compiled kernel, per base) takes it only
    inside the bulge; an array of heights takes it of ``u = 1`` (exactly 0) outside (``profile``:
    of those inside only).  All give the same bits."""
    if isinstance(z, float):  # one height: most bases are outside every bulge, and cost a comparison
        if not abs(z - center) < half_width:  # outside, without the division (the test below decides)
            return 0.0
        u = (z - center) / half_width
        if abs(u) < 1.0:
            return sin2_profile(u)
        return 0.0
    u = (z - center) / half_width
    inside = np.abs(u) < 1.0
    u = np.where(inside, u, 1.0)  # u inside, 1 outside (and for a NaN height, as one height gives)
    return sin2_profile(u) * inside


def profile(z, center, half_width) -> np.ndarray:
    """:func:`bump` of an array of heights in Python, evaluated only where a height is inside the
    bulge (what the engine asks of a join's new bases, which are mostly outside every bulge: no
    arithmetic at all then).  The same bits as ``bump``."""
    return profiles(z, np.array([center], dtype=float), np.array([half_width], dtype=float)).reshape(np.shape(z))


def profiles(z, centers: np.ndarray, half_widths: np.ndarray) -> np.ndarray:
    """:func:`profile` of the heights ``z`` for each bulge (``centers``, ``half_widths``) at once: one
    row per bulge, one column per height (``z`` flattened), each entry the bits ``profile`` gives it
    (the same operations per entry): a join asks it of every bulge, once per join."""
    u = (np.ravel(np.asarray(z, dtype=float))[None, :] - centers[:, None]) / half_widths[:, None]
    inside = np.abs(u) < 1.0
    out = np.zeros(u.shape)
    if inside.any():
        out[inside] = sin2_profile(u[inside])
    return out


def bulge_time(t, p, inner_time, inner_radius):
    """The per-step part of :class:`BulgeGrowth`'s compiled work (its part's ``time``): everything that
    depends on time alone, once per step, on the uniform law the bulges sit on (``inner_time`` and
    ``inner_radius``: that law's part).  From ``p = (nb, the law's nb numbers, n, then for each bulge
    z, half_width, magnitude, decay, has_G, start, then for each bulge the law's numbers with its own
    G)`` it makes ``q = (r_base(t), extra_1(t), ..., extra_n(t), z_1, half_width_1, ..., z_n,
    half_width_n, n)``, where a bulge's ``extra`` is 0 before its start and then its fading magnitude
    plus what its own growth constant has added to the base law since: the radius is
    ``q[0] + s_1(z)·q[1] + ... + s_n(z)·q[n]`` (``bulge_weights`` gives the ``s_b``)."""
    nb = int(p[0])
    n = int(p[1 + nb])
    rows, variants = 2 + nb, 2 + nb + ROW * n
    base = inner_radius(t, 0.0, inner_time(t, p[1:1 + nb]))
    q = np.empty(2 + 3 * n)
    q[0] = base
    q[-1] = p[1 + nb]
    for b in range(n):
        o = rows + ROW * b
        start = p[o + 5]
        extra = 0.0
        if t >= start:  # there: its magnitude at start, fading (a scalar: the C library's exp in numpy and numba alike)
            extra = p[o + 2] * math.exp(-p[o + 3] * (t - start))
            if p[o + 4] != 0.0:  # and its own growth constant since start (0 at t = 0 for laws like r0 + G·f(t))
                g = variants + nb * b
                extra = extra + inner_radius(t, 0.0, inner_time(t, p[g:g + nb])) - base
                extra = extra - (inner_radius(start, 0.0, inner_time(start, p[g:g + nb]))
                                 - inner_radius(start, 0.0, inner_time(start, p[1:1 + nb])))
        q[1 + b] = extra
        q[1 + n + 2 * b] = p[o]
        q[2 + n + 2 * b] = p[o + 1]
    return q


def bulge_radius(t, z, q):
    """The per-base part of :class:`BulgeGrowth`'s compiled work: ``r_base + Σ_b s_b(z)·extra_b`` with
    ``q`` from :func:`bulge_time`."""
    n = int(q[-1])
    r = q[0]
    for b in range(n):
        r = r + bump(z, q[1 + n + 2 * b], q[2 + n + 2 * b]) * q[1 + b]
    return r


def bulge_radii(t, z, q, out):
    """:class:`BulgeGrowth`'s part's ``radii``: :func:`bulge_radius` at each height of the block ``z``
    into ``out``, to the bit, with no branch per height (SIMD lanes): each bulge adds ``s·extra`` to
    every radius, ``s`` the profile of ``u = (z − peak)/half_width`` inside and of ``u = 1`` (exactly
    0) outside, as :func:`bump` does for an array.  A bulge the whole block is out of reach of adds
    nothing (``0·extra``, for a finite ``extra``) and is skipped: the block's lowest and highest
    heights decide (:func:`_extent`); so is a bulge whose
    ``extra`` is 0 (not yet there: ``s·0`` adds nothing)."""
    n = int(q[-1])
    lowest, highest = _extent(z)
    for i in range(z.shape[0]):
        out[i] = q[0]
    for b in range(n):
        extra, center, half_width = q[1 + b], q[1 + n + 2 * b], q[2 + n + 2 * b]
        if extra == 0.0 or (highest - center <= -half_width or lowest - center >= half_width) and abs(extra) < np.inf:
            continue  # nothing to add, or |z - peak| >= half_width for every height: bump gives 0 for each
        for i in range(z.shape[0]):
            u = (z[i] - center) / half_width
            inside = abs(u) < 1.0
            out[i] = out[i] + sin2_profile(u if inside else 1.0) * inside * extra


_MAGNITUDE = np.int64(0x7FFF_FFFF_FFFF_FFFF)
"""A double's bits but its sign: flipped where the double is negative, its bits as an integer order as
the numbers do (:func:`_extent`)."""


def _extent(z):
    """The lowest and the highest of the heights ``z`` (a contiguous block), found on integers that
    order as the doubles do (each one's bits, its magnitude bits flipped where it is negative), so
    that the compiled loop, run on every block at every step, goes in SIMD lanes (numba compares
    doubles one at a time).  A NaN height may come out as either end (NaN): no bulge is then
    skipped, which changes no bit; an empty block gives NaN too."""
    bits = z.view(np.int64)
    low, high = _MAGNITUDE, -_MAGNITUDE - 1
    for i in range(bits.shape[0]):
        key = bits[i] ^ ((bits[i] >> 63) & _MAGNITUDE)
        low = key if key < low else low
        high = key if key > high else high
    ends = np.empty(2, np.int64)
    ends[0] = low ^ ((low >> 63) & _MAGNITUDE)
    ends[1] = high ^ ((high >> 63) & _MAGNITUDE)
    lowest, highest = ends.view(np.float64)
    return lowest, highest


def bulge_weights(z, p):
    """:class:`BulgeGrowth`'s part's ``weights``: each bulge's profile ``s_b`` at heights ``z``, one
    row per bulge (``p`` as for :func:`bulge_time`)."""
    nb = int(p[0])
    rows = np.asarray(p[2 + nb:2 + nb + ROW * int(p[1 + nb])], dtype=float).reshape(-1, ROW)
    return profiles(z, rows[:, 0], rows[:, 1])


@attrs.frozen(kw_only=True)
class Bulge:
    """One bulge: where it is, how far it reaches and how high it rises (a region of the trunk, ``bulge``,
    whose material the breaker sets: ``[breaker] regions``)."""

    z: float = attrs.field(validator=non_negative)
    """Height of the bulge's peak (length units)."""
    half_width: float = attrs.field(validator=positive)
    """Half the height range it covers; outside ``|z − peak| < half_width`` it has no effect."""
    magnitude: float = attrs.field(default=0.0, validator=non_negative)
    """Extra radius at the peak when the bulge appears (length units)."""
    decay: float = attrs.field(default=0.0, validator=non_negative)
    """The magnitude falls as ``exp(−decay·(t − start))`` (paper, "Integrative model": the bulge fades)."""
    G: float | None = attrs.field(default=None, validator=optional(non_negative))
    """Growth constant at the peak from the bulge's start on (paper, Table 1: 0.02 at the peak, 0.04 at
    the ends; below the base law's, it makes the bulge fade); ``None`` keeps the base law's."""
    start: float = attrs.field(default=0.0, validator=non_negative)
    """Time the bulge appears (time units; 0: there from the start).  Before it the trunk has no bulge
    there; bases that join inside it once it is there take their rest lengths at its larger radius."""

    def profile(self, z: np.ndarray) -> np.ndarray:
        """``sin²`` bump: 1 at the peak, 0 with zero slope at ``peak ± half_width``, 0 outside."""
        return profile(z, self.z, self.half_width)


@attrs.frozen(kw_only=True)
class BulgeSeries:
    """Bulges made one after another below the apical dome as the tree grows (paper, "Growth
    simulation": "a periodic increase in the trunk diameter ('bulging') below the apical dome",
    possibly at the sites of inflorescences): the k-th (k = 0, 1, ...) appears at ``first + k·every``
    with its peak ``offset`` above the top of the trunk then (``Lattice.top``), and stays at that
    height while the trunk grows on above it.  Each is a :class:`Bulge` with these numbers."""

    every: float = attrs.field(validator=positive)
    """Time between two bulges (time units; 1 = 88.5 days, so 4.13 is a year)."""
    half_width: float = attrs.field(validator=positive)
    """Half the height range each covers (length units)."""
    count: int = attrs.field(default=1, validator=positive_int)
    """How many bulges the series makes."""
    first: float = attrs.field(default=0.0, validator=non_negative)
    """When the first appears (time units)."""
    offset: float | None = attrs.field(default=None, validator=optional(in_range(-REAL_MAX, REAL_MAX)))
    """Height of each peak above the top of the trunk when it appears (length units; negative: below
    it).  None: its half width, so a bulge begins at the top and no base already on the trunk moves
    when it appears: the bases joining through it take its larger radius."""
    magnitude: float = attrs.field(default=0.0, validator=non_negative)
    """Extra radius at each peak when it appears (length units)."""
    decay: float = attrs.field(default=0.0, validator=non_negative)
    """Each magnitude falls as ``exp(−decay·(t − its start))``."""
    G: float | None = attrs.field(default=None, validator=optional(non_negative))
    """Growth constant at each peak once it is there; None keeps the base law's."""

    def on(self, lattice) -> tuple[Bulge, ...]:
        """The series' bulges on a trunk whose bases follow ``lattice``: at fixed heights and times."""
        offset = self.half_width if self.offset is None else self.offset
        starts = self.first + self.every * np.arange(self.count)
        return tuple(Bulge(z=max(0.0, float(lattice.top(t)) + offset), half_width=self.half_width,
                           magnitude=self.magnitude, decay=self.decay, G=self.G, start=float(t))
                     for t in starts)


@attrs.frozen(kw_only=True)
class BulgeGrowth(Growth):
    """Another growth law plus bulges (paper, "Growth simulation" and "Integrative model")::

        r(t, z) = r_base(t, z) + Σ_b s_b(z) · e_b(t),   e_b = 0 before the bulge's start t_b, then
        e_b(t) = A_b · exp(−λ_b (t − t_b)) + [r_base,G_b − r_base](t, z) − [r_base,G_b − r_base](t_b, z)

    with ``s_b`` each bulge's ``sin²`` profile, ``r_base,G_b`` the base law with the bulge's own
    growth constant, ``A_b`` its magnitude and ``λ_b`` its decay.  Each bulge is a region of the
    trunk, ``bulge``, weighted by its profile once it is there (``regions_at``): the breaker sets the
    thresholds of springs made in it (``[breaker] regions = { bulge = 0.006 }``).  Bulges are given where they are (``bulges``) or as series made
    below the apical dome as the trunk grows (``series``), placed when the law is put on a lattice
    (``on``).
    """

    base: Growth = attrs.field(factory=SqrtGrowth, converter=_base)
    """The law the bulges sit on (any growth strategy; a scene gives it as a table)."""
    bulges: tuple[Bulge, ...] = attrs.field(default=(), converter=_tables_of(Bulge, "bulges", "bulge"))
    """The bulges at given heights (a scene gives them as an array of tables)."""
    series: tuple[BulgeSeries, ...] = attrs.field(default=(), converter=_tables_of(BulgeSeries, "series", "bulge series"))
    """Bulges made one after another below the apical dome (:class:`BulgeSeries`; ``[[growth.series]]``)."""

    @bulges.validator
    @series.validator
    def _own_growth_constant(self, attribute, value) -> None:
        for i, b in enumerate(value):
            if b.G is not None and "G" not in attrs.fields_dict(type(self.base)):
                raise BarkError("{0}: the law the bulges sit on has no growth constant G to vary",
                                Ref(None, f"{attribute.name}[{i}].G", b.G))

    provides: ClassVar[tuple[Effect, ...]] = (
        Effect("bulges", "bulges raise the trunk locally ([growth] name = 'bulge')", ("secondary-growth",)),)

    def without(self, effect: str) -> Growth:
        """Without its bulges, the law they sit on: the bulge code is never built."""
        return self.base

    def on(self, lattice) -> "BulgeGrowth":
        """The law with its series' bulges placed on ``lattice``'s trunk (``BulgeSeries.on``), after
        the bulges given where they are."""
        if not self.series:
            return self
        return attrs.evolve(self, bulges=self.bulges + tuple(b for s in self.series for b in s.on(lattice)), series=())

    def part(self) -> GrowthPart | None:
        """The bulges on the part of the law they sit on, when that law has one that is uniform (the
        same radius at every height) and its variants with the bulges' own G are the same work on
        other numbers; else ``None``: the radius is then taken in Python, one step a call."""
        self._placed()
        base = self.base.part_
        if base is None or not base.uniform or base.inner is not None:
            return None
        variants = [base if b.G is None else attrs.evolve(self.base, G=b.G).part_ for b in self.bulges]
        if any(v is None or (v.radius, v.time, v.params.size) != (base.radius, base.time, base.params.size) for v in variants):
            return None
        rows = [[b.z, b.half_width, b.magnitude, b.decay, 0.0 if b.G is None else 1.0, b.start] for b in self.bulges]
        params = [base.params.size, *base.params, len(rows), *np.ravel(rows), *(x for v in variants for x in v.params)]
        return GrowthPart(radius=bulge_radius, params=params, time=bulge_time, weights=bulge_weights,
                          radii=bulge_radii, inner=base)

    def radius(self, t: float, z: np.ndarray) -> np.ndarray:
        """The base law's radius plus each bulge's at heights ``z`` (from the part where the base law has one,
        the same bits)."""
        z = np.asarray(z, dtype=float)
        part = self.part_
        if part is not None:  # the part, as every law that has one is evaluated
            if z.ndim == 0:  # one height (the top of the trunk): the profile's scalar path, the same bits
                return np.asarray(part.radius_at(t, float(z)), dtype=float)
            # heights: q[0] + w_0(z) q[1] + ..., the kernel's sum to the bit
            return weighted_radius(part.at(t), bulge_weights(z, part.params)).reshape(z.shape)
        self._placed()
        base = np.broadcast_to(self.base.radius(t, z), z.shape).astype(float)
        r = base.copy()
        for b in self.bulges:
            if t < b.start:
                continue
            extra = b.magnitude * math.exp(-b.decay * (t - b.start))
            if b.G is not None:
                own = attrs.evolve(self.base, G=b.G)
                extra = extra + np.broadcast_to(own.radius(t, z), z.shape) - base
                extra = extra - (np.broadcast_to(own.radius(b.start, z), z.shape)
                                 - np.broadcast_to(self.base.radius(b.start, z), z.shape))
            r = r + b.profile(z) * extra
        return r

    def _placed(self) -> None:
        if self.series:
            raise BarkError("{0}: a bulge series is placed on a trunk before the law is used "
                            "(BulgeGrowth.on(lattice); a simulation does it when it is built)",
                            Ref(None, "series", [attrs.asdict(s) for s in self.series]))

    def region(self, z: np.ndarray) -> np.ndarray:
        """``bulge`` within a bulge's reach (``|z − peak| < half_width``), ``straight`` elsewhere (the
        paper's two kinds of trunk section, Table 1)."""
        z = np.asarray(z, dtype=float)
        inside = np.zeros(z.shape, dtype=bool)
        for b in self.bulges:
            inside |= np.abs(z - b.z) < b.half_width
        return np.where(inside, "bulge", "straight").astype(object)

    def regions_at(self, t: float, z: np.ndarray) -> list[tuple[str, np.ndarray]]:
        """A ``bulge`` for each bulge there at time ``t``, weighted by its profile at heights ``z``."""
        self._placed()
        there = [b for b in self.bulges if t >= b.start]
        if not there:
            return []
        weights = profiles(z, np.array([b.z for b in there]), np.array([b.half_width for b in there]))
        return [("bulge", w.reshape(np.shape(z))) for w in weights]
