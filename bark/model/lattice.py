"""The phyllotactic lattice of leaf bases on a cylinder (paper: "Fracture simulation", Table 2).

Leaf base ``i`` sits at angle ``i·φ`` and height ``i·h`` (``−i·φ`` for a left-handed lattice).  Springs join it to the bases at the
index offsets ``±o`` for each ``o`` in ``offsets`` (Table 2: ±21, ±34), giving each interior base
four neighbours.  The exact lattice is degenerate (every spring of one offset has the
same length and reaches its threshold in the same step), so the lattice carries an explicit,
seeded position jitter; ``jitter=0`` keeps the exact lattice available.

Units: lengths in model length units (1 = 0.3 m), angles in radians inside the code and degrees in
parameters that a person types (``divergence_deg``).
"""

from __future__ import annotations

import math

import attrs
import numpy as np

from bark.validators import INT_MAX, in_range, non_negative, one_of, optional, positive, positive_int
from bark.errors import BarkError, Ref

__all__ = ["GOLDEN_ANGLE_DEG", "Lattice"]

#: The golden angle 360°·(2 − φ) ≈ 137.5078°, the divergence angle of grasstree seedlings.
GOLDEN_ANGLE_DEG = 360.0 * (2.0 - (1.0 + math.sqrt(5.0)) / 2.0)


def _offsets(value):
    """Lists become tuples, a single integer a 1-tuple; anything else is left for the validator."""
    if isinstance(value, (list, tuple)):
        return tuple(value)
    if isinstance(value, int) and not isinstance(value, bool):
        return (value,)
    return value


def _distinct_offsets(value, count: int | None = None) -> bool:
    """Whether ``value`` is a tuple of distinct integer offsets >= 1 (``count`` of them, if given)."""
    return (isinstance(value, tuple) and len(value) > 0 and (count is None or len(value) == count)
            and all(isinstance(o, int) and not isinstance(o, bool) and 1 <= o <= INT_MAX for o in value)
            and len(set(value)) == len(value))


MAX_OFFSETS = 16
"""Most spring offsets a lattice may have: each is two neighbours a base (the paper's lattice: two
offsets, four neighbours); more make a dense network whose steps and pictures grow with the square
of the bases, not a bark."""


def _check_offsets(instance, attribute, value) -> None:
    if not _distinct_offsets(value):
        raise BarkError("{0}: must be distinct integers >= 1 (e.g. 21 and 34)", Ref(None, attribute.name, value))
    if len(value) > MAX_OFFSETS:
        raise BarkError(f"{{0}}: {len(value)} offsets; at most {MAX_OFFSETS} (each joins a base to two neighbours; "
                        "Table 2 has two)", Ref(None, attribute.name, _shown(value)))


def _shown(value: tuple) -> list | str:
    """A long list of offsets as its head and length (a message is one line)."""
    return list(value) if len(value) <= 8 else f"[{', '.join(map(str, value[:4]))}, ... ({len(value)} in all)]"


def _check_partition(instance, attribute, value) -> None:
    if not _distinct_offsets(value, 2):
        raise BarkError("{0}: must be two distinct integers >= 1 (Table 1: 34 and 144)", Ref(None, attribute.name, value))


@attrs.frozen(kw_only=True)
class Lattice:
    """Where the leaf bases start and which of them are joined by springs.

    Every parameter is a validated keyword; a value outside its range is one line naming it:

    >>> lattice = Lattice(n_bases=600)
    >>> lattice.offsets, lattice.n_springs
    ((21, 34), 1145)
    >>> lattice.pairs()[:2].tolist()   # base i joined to base i + 21 and i + 34
    [[0, 21], [1, 22]]
    >>> Lattice(n_bases=0)
    Traceback (most recent call last):
    bark.errors.BarkError: n_bases = 0: must be an integer >= 1
    """

    n_bases: int = attrs.field(default=3000, validator=positive_int)
    """Number of leaf bases on the trunk segment (Table 2: 3000)."""
    divergence_deg: float = attrs.field(default=GOLDEN_ANGLE_DEG, validator=in_range(0.0, 360.0, lo_open=True, hi_open=True))
    """Divergence angle φ between successive bases, degrees (default: the golden angle)."""
    handedness: str = attrs.field(default="right", validator=one_of("right", "left"))
    """Which way the generative spiral (base i to base i + 1) turns: right, a right-handed helix up the
    trunk (θ grows by φ, counter-clockwise seen from above); left, its mirror image (θ falls by φ).
    Real trees come in both; a left-handed lattice grows the mirror image of a right-handed one of the
    same seed, each orientation o as 180° − o."""
    rise: float = attrs.field(default=0.0005, validator=positive)
    """Vertical displacement h between successive bases, length units (1 = 0.3 m; Table 2: 0.0005)."""
    offsets: tuple[int, ...] = attrs.field(default=(21, 34), converter=_offsets, validator=_check_offsets)
    """Index offsets to neighbouring bases; each offset o joins base i to base i+o (Table 2: 21, 34)."""
    jitter: float = attrs.field(default=0.05, validator=non_negative)
    """Standard deviation of the Gaussian jitter of each base's initial angle and height, as a
    fraction of the base spacing √(2π r h).  0 gives the exact (degenerate) lattice."""
    n_start: int | None = attrs.field(default=None, validator=optional(positive_int))
    """Bases on the trunk at t = 0 (none: all n_bases).  The others join during the run, at the top
    (primary growth), at join_rate."""
    join_rate: float = attrs.field(default=0.0, validator=non_negative)
    """Bases joining per time unit after t = 0, continuing the phyllotactic order up the trunk (needed
    when n_start is below n_bases)."""
    join_every: float = attrs.field(default=1.0, validator=positive)
    """Time between two joinings: the bases due by then join together (time units)."""
    partition: tuple[int, ...] | None = attrs.field(default=None, converter=_offsets, validator=optional(_check_partition))
    """Index offsets p, q to the bases whose midpoints with a base are the corners of its rhomboid
    leaf-base shape, drawn in 3-D output (Table 1: 34, 144); none: o2 − o1 and o1 + o2 from the
    two spring offsets (21, 34 give 13, 55; 55, 89 give 34, 144)."""
    organ_area: float | None = attrs.field(default=None, validator=optional(in_range(1e-12, 1e6)))
    """Surface area one leaf takes on the apical dome as the run begins, length units² (1 = 0.09 m²;
    the paper's ≈ 30 mm² is 0.000333): Ridley's packing places the bases that join during the run
    this far apart in area.  None: the area of one base of the trunk of the start, 2π·r·rise, so the
    packing goes on as the trunk began."""
    area_exponent: float = attrs.field(default=1.0, validator=in_range(0.0, 3.0))
    """How the leaves' area follows the trunk as it widens: ``organ_area · (R/R₀)^p``, R the trunk's
    radius at the dome's base.  0: a fixed leaf size; 1: a fixed rise per leaf (Table 1's h: the
    paper's leaf counts and heights); 2: a fixed shape of the lattice (its parastichy angle)."""

    def __attrs_post_init__(self) -> None:
        if self.n_start is not None and self.n_start > self.n_bases:
            raise BarkError("{0} is more than {1}", Ref(None, "n_start", self.n_start), Ref(None, "n_bases", self.n_bases))
        if self.initial < self.n_bases and not self.join_rate > 0:
            raise BarkError("{0} below {1} needs {2} > 0: the other bases never join",
                            Ref(None, "n_start", self.n_start), Ref(None, "n_bases", self.n_bases),
                            Ref(None, "join_rate", self.join_rate))
        if self.initial >= self.n_bases and (self.organ_area is not None or self.area_exponent != 1.0):
            ref = Ref(None, "organ_area", self.organ_area) if self.organ_area is not None else \
                Ref(None, "area_exponent", self.area_exponent)
            raise BarkError("{0} sizes the leaves that join during the run, and this trunk has none: give {1} below "
                            "{2} and a {3}, or leave it out", ref, Ref(None, "n_start", self.n_start),
                            Ref(None, "n_bases", self.n_bases), Ref(None, "join_rate", self.join_rate))

    @property
    def keeps_rise(self) -> bool:
        """Whether the bases that join keep the trunk's rise whatever its radius (the default leaf size
        following the trunk's radius), so that no growth law is needed to place them."""
        return self.organ_area is None and self.area_exponent == 1.0

    @property
    def initial(self) -> int:
        """Bases on the trunk at t = 0."""
        return self.n_bases if self.n_start is None else self.n_start

    def bases_at(self, t: float) -> int:
        """How many bases the trunk has at time ``t`` (joins happen at multiples of join_every)."""
        if self.initial >= self.n_bases:
            return self.n_bases
        joined_until = math.floor(t / self.join_every + 1e-9) * self.join_every
        return min(self.n_bases, self.initial + int(math.floor(self.join_rate * joined_until + 1e-9)))

    def next_join(self, t: float, present: int) -> float | None:
        """When bases next join after time ``t`` (``present`` on the trunk), or ``None``: all are there."""
        if present >= self.n_bases:
            return None
        k = math.floor(t / self.join_every + 1e-9) + 1
        # the first k with initial + floor(rate · k · join_every) > present, in closed form (a loop
        # over k would take ~1e11 turns at join_every = 1e-12), then made exact by bases_at itself
        k = max(k, math.floor((present + 1 - self.initial - 1e-9) / (self.join_rate * self.join_every)) - 1)
        while self.bases_at(k * self.join_every) <= present:
            k += 1
        return k * self.join_every

    @property
    def turn(self) -> float:
        """The signed angle from one base to the next, radians: ``φ``, or ``−φ`` when left-handed."""
        return math.radians(self.divergence_deg) * (1.0 if self.handedness == "right" else -1.0)

    def top_index(self, t) -> np.ndarray:
        """The (fractional) index of the base at the top of the trunk at time ``t``: primary growth
        adds ``join_rate`` a time unit."""
        return self.initial - 1 + self.join_rate * np.asarray(t, dtype=float)

    def top(self, t) -> np.ndarray:
        """Height of the top of the trunk (where the apical dome begins) at time ``t``: the site of
        its youngest base, primary growth making it rise steadily at ``join_rate · rise``."""
        return self.rise * self.top_index(t)

    def spacing(self, radius: float) -> float:
        """Typical distance between neighbouring bases: the side of the area 2πr·h one base covers."""
        return math.sqrt(2.0 * math.pi * radius * self.rise)

    def sites(self, radius: float, rng: np.random.Generator, first: int = 0, count: int | None = None,
              z: np.ndarray | None = None, rise: np.ndarray | float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Angle θ (radians) and height z of bases ``first`` .. ``first + count − 1`` (default: the
        initial ones) on a cylinder of ``radius``: base i at ``i·φ`` and ``i·h`` (or at heights ``z``,
        where each one's ``rise`` is given: what Ridley's packing makes of the bases that join later,
        ``bark.model.tree.Packing``), jittered by the spacing √(2π·r·rise); a left-handed lattice's
        angles are those of the right-handed one negated (its mirror image, jitter and all).

        The jitter is drawn from ``rng`` (the simulation's one seeded generator) even when it is
        zero, so that the generator's later draws do not depend on whether jitter is on."""
        count = self.initial if count is None else count
        i = np.arange(first, first + count, dtype=float)
        noise = rng.standard_normal((2, count))
        sigma = self.jitter * (self.spacing(radius) if rise is None else np.sqrt(2.0 * math.pi * radius * rise))
        theta = i * math.radians(self.divergence_deg) + noise[0] * (sigma / radius)
        z = (i * self.rise if z is None else z) + noise[1] * sigma
        return (theta if self.handedness == "right" else -theta), z

    def partition_offsets(self) -> tuple[int, int]:
        """The two index offsets whose midpoints make a base's rhomboid (``partition``, or from ``offsets``)."""
        if self.partition is not None:
            return self.partition
        if len(self.offsets) != 2:
            raise BarkError("{0} is needed for leaf-base shapes when {1} are not two", Ref(None, "partition", None),
                            Ref(None, "offsets", self.offsets))
        o1, o2 = sorted(self.offsets)
        return (o2 - o1, o1 + o2)

    @property
    def n_springs(self) -> int:
        """Number of springs of the whole lattice."""
        return sum(max(self.n_bases - o, 0) for o in self.offsets)

    def pairs(self) -> np.ndarray:
        """Spring end points of the whole lattice as an ``(m, 2)`` array, ordered by offset then by base."""
        return self.new_pairs(np.arange(self.n_bases), range(self.n_bases))

    def new_pairs(self, new: np.ndarray, present) -> np.ndarray:
        """The springs bases ``new`` (ids in lattice order) make with the bases ``present`` (a
        container of ids, e.g. the leaf-base graph; it includes ``new``): ``(i, i + o)`` for each offset
        ``o`` where one end is new and both are present.  Ordered by offset, then by base — for a
        whole lattice, ``(i, i + o)`` for i = 0, 1, ... in each offset's block."""
        new = np.asarray(new, dtype=np.int64)
        if isinstance(present, range) or hasattr(present, "has_bases"):
            count = len(present) if isinstance(present, range) and present.start == 0 and present.step == 1 else \
                getattr(present, "number_of_nodes", lambda: -1)()
            if new.size and count >= 0 and new[-1] < count and (np.diff(new) == 1).all():  # ids a, a + 1, ...
                return self._pairs_of_range(int(new[0]), int(new[-1]) + 1, count)
        blocks = []
        for o in self.offsets:
            below = new - o  # springs down to a base that is present (new or not)
            below = below[below >= 0]
            below = below[_present(present, below)]
            above = new + o  # springs up to a base that was there before
            above = above[np.isin(above, new, invert=True)]
            above = above[_present(present, above)]
            ends = np.concatenate([below, above - o])
            blocks.append(np.column_stack([np.sort(ends), np.sort(ends) + o]))
        return np.concatenate(blocks).astype(np.uint32) if blocks else np.empty((0, 2), np.uint32)

    def _pairs_of_range(self, a: int, b: int, count: int) -> np.ndarray:
        """``new_pairs`` for the new bases ``a .. b − 1`` among the bases ``0 .. count − 1``: for each
        offset the springs down from a new base (first ends ``a − o .. b − o − 1``, those from 0 on)
        then those up from one to a base after ``b`` — ranges, no set arithmetic (what each join asks)."""
        blocks = []
        for o in self.offsets:
            ends = np.concatenate([np.arange(max(a - o, 0), max(b - o, 0)), np.arange(max(a, b - o), min(b, count - o))])
            blocks.append(np.column_stack([ends, ends + o]))
        return np.concatenate(blocks).astype(np.uint32) if blocks else np.empty((0, 2), np.uint32)


def _present(present, ids: np.ndarray) -> np.ndarray:
    """Which of ``ids`` are in ``present``: a range or the leaf-base graph (``has_bases``) at once,
    any other container one id at a time."""
    if isinstance(present, range) and present.step == 1:
        return (ids >= present.start) & (ids < present.stop)
    has = getattr(present, "has_bases", None)
    if has is not None:
        return has(ids)
    return np.fromiter((int(j) in present for j in ids), bool, ids.size)
