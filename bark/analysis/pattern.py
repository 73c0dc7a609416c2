"""A bark pattern on its own: leaf-base positions and patch ids, whatever made them.

A :class:`Pattern` is a value — points and the patch each belongs to — made from a simulation, a
run's output folder, a state file (``state.npz``) or a CSV of leaf-base centres digitised from a
photograph.  :meth:`Pattern.statistics` measures it as the paper does ("Pattern characterization",
eqs. 10–11) into a typed :class:`PatternStatistics`; a published pattern whose points are not
available is a :class:`PatternStatistics` made from its summary (:func:`read` of a TOML file).

Conventions are bark's (``bark.analysis.patches``): orientation in degrees from horizontal in ``[0, 180)``,
90 = along the trunk axis (up the image for a photograph); anisotropy ``2A − 1`` in ``[0, 1]``.

**The photograph CSV format** (``Pattern.from_csv``)::

    # bark leaf-base centres, digitised from IMG_0412.jpg      <- lines starting with # are comments
    # pixels_per_metre: 1850                                    <- optional: lengths in metres, not pixels
    x,y,patch
    412.5,133.0,1
    430.0,171.5,1
    ...

``x`` and ``y`` are the centre of a leaf base in the image, in pixels, ``y`` pointing *down* (as
every image tool measures it: bark turns it up); ``patch`` names the patch it belongs to (any label:
``1``, ``A``, ``left-strip``).  Columns may come in any order; other columns are ignored.  A CSV with
columns ``x, y, z, patch`` is a pattern on the trunk (bark's 3-D coordinates, trunk axis = z), like a
run's.  Any error is named by its line.
"""

from __future__ import annotations

import csv
import io
import math
import tomllib
import warnings
from pathlib import Path

import attrs
import numpy as np

from bark.analysis.circular import axial_difference, axial_mean, axial_sd, axial_se
from bark.errors import BarkError, BarkWarning
from bark.paths import is_zip, open_regular
from bark.units import headed

__all__ = ["Pattern", "PatchTable", "Axial", "Linear", "PatternStatistics", "read", "load", "springs_of", "run_min_size", "MIN_PATCH_SIZE", "patch_colours",
           "PALETTE", "FRAGMENT_GREY", "simulation_colours", "lineage_colours", "spiral_handedness"]

MIN_PATCH_SIZE = 7
"""Patches with fewer leaf bases are fragments, left out of the statistics (the paper: 7)."""


def _array(dtype, ndim):
    def convert(value):
        a = np.array(value, dtype=dtype)
        if a.ndim != ndim:
            raise ValueError(f"must be a {ndim}-D array, not {a.ndim}-D")
        a.setflags(write=False)
        return a
    return convert


@attrs.frozen(eq=False)
class Pattern:
    """Leaf-base positions and their patches.

    ``points`` are ``(n, 3)`` positions on the trunk (axis = z; each patch is measured in the plane
    tangent to the trunk at its centroid) or ``(n, 2)`` positions in a plane ``(horizontal, vertical
    up)``, e.g. a photograph.  ``patches`` gives each point's patch id."""

    points: np.ndarray = attrs.field(converter=_array(float, 2))
    patches: np.ndarray = attrs.field(converter=_array(np.int64, 1))
    name: str = ""
    units: str = "length units"
    """What a length is: ``"length units"`` (bark's, 1 = 0.3 m), ``"m"`` or ``"px"``."""
    handedness: str | None = None
    """Which way the phyllotactic spiral of the lattice that grew it turns (``"right"`` or ``"left"``,
    ``bark.model.lattice.Lattice.handedness``); ``None`` where it is not known (a photograph)."""

    def __attrs_post_init__(self) -> None:
        n, dim = self.points.shape
        if dim not in (2, 3):
            raise BarkError(f"{self.name or 'pattern'}: points must have 2 or 3 coordinates, not {dim}")
        if self.patches.shape != (n,):
            raise BarkError(f"{self.name or 'pattern'}: {n} points but {self.patches.shape[0]} patch ids")
        if not np.isfinite(self.points).all():
            raise BarkError(f"{self.name or 'pattern'}: a point is NaN or infinite")

    @property
    def on_trunk(self) -> bool:
        """Whether the points are 3-D positions on the trunk (else 2-D in a plane)."""
        return self.points.shape[1] == 3

    # -- made from ------------------------------------------------------------------------------
    @classmethod
    def of_simulation(cls, sim, name: str = "") -> "Pattern":
        """The pattern of a simulation now: its bases' positions, patches = connected components of
        the intact springs."""
        return cls(points=sim.state.x, patches=sim.patch_labels(), name=name, handedness=sim.lattice.handedness)

    @classmethod
    def from_state(cls, path: str | Path, name: str | None = None) -> "Pattern":
        """A run's ``state.npz`` (positions ``x`` and patch ``labels``); its handedness read off the
        positions, which are in lattice order (:func:`spiral_handedness`)."""
        path = Path(path)
        try:
            with open_regular(path) as fh:
                if not is_zip(fh):
                    raise BarkError(f"{path}: not a bark state file (not an .npz archive)")
                with np.load(fh, allow_pickle=False) as data:
                    missing = [k for k in ("x", "labels") if k not in data.files]
                    if missing:
                        raise BarkError(f"{path}: not a bark state file (no {' or '.join(missing)} in it)")
                    x, labels = data["x"], data["labels"]
        except BarkError:
            raise
        except OSError as err:
            raise BarkError(f"{path}: cannot be read ({err.strerror or err})") from None
        except Exception as err:  # a damaged or foreign file: zip, pickle or format errors
            raise BarkError(f"{path}: not a readable state file ({type(err).__name__}: {err})") from None
        if x.ndim != 2 or x.shape[1] != 3 or labels.shape != (x.shape[0],):
            raise BarkError(f"{path}: x must be n × 3 and labels n long (they are {x.shape} and {labels.shape})")
        return cls(points=x, patches=labels, name=path.parent.name if name is None else name,
                   handedness=spiral_handedness(x))

    @classmethod
    def from_csv(cls, path: str | Path, name: str | None = None) -> "Pattern":
        """Leaf-base centres from a CSV (the photograph format in this module's docstring)."""
        path = Path(path)
        scale = None
        try:
            with io.TextIOWrapper(open_regular(path), encoding="utf-8-sig", newline="") as fh:  # a BOM is no column
                lines = list(enumerate(fh, start=1))
        except OSError as err:
            raise BarkError(f"{path}: cannot be read ({err.strerror or err})") from None
        except UnicodeDecodeError:
            raise BarkError(f"{path}: not a text file (not UTF-8)") from None
        body = []
        for number, line in lines:
            text = line.strip()
            if text.startswith("#"):
                key, sep, value = text[1:].partition(":")
                if not sep:
                    key, sep, value = text[1:].partition("=")
                if sep and key.strip().lower() == "pixels_per_metre":
                    scale = _number(value.strip(), path, number, "pixels_per_metre")
                    if not scale > 0:
                        raise BarkError(f"{path} line {number}: pixels_per_metre must be > 0, not {value.strip()}")
            elif text:
                body.append((number, line))
        if not body:
            raise BarkError(f"{path}: no header and no rows (a header x,y,patch and a row per leaf base)")
        records = list(_records(body, path))
        numbers = [n for n, _ in records]
        header = [h.strip().lower() for h in records[0][1]]
        three = "z" in header
        need = ["x", "y", "z", "patch"] if three else ["x", "y", "patch"]
        missing = [c for c in need if c not in header]
        if missing:
            raise BarkError(f"{path} line {numbers[0]}: the header has no column {', '.join(missing)} "
                            f"(it has: {', '.join(header) or 'nothing'}; needs {', '.join(need)})")
        if len(set(header)) != len(header):
            raise BarkError(f"{path} line {numbers[0]}: a column is named twice ({', '.join(header)})")
        at = [header.index(c) for c in need]
        coords, ids = [], []
        for number, row in records[1:]:
            if len(row) != len(header):
                raise BarkError(f"{path} line {number}: {len(row)} values, the header names {len(header)}")
            values = [row[i].strip() for i in at]
            coords.append([_number(v, path, number, c) for v, c in zip(values[:-1], need[:-1])])
            if not values[-1]:
                raise BarkError(f"{path} line {number}: patch is empty")
            ids.append(values[-1])
        if not coords:
            raise BarkError(f"{path}: a header but no leaf bases")
        points = np.array(coords, dtype=float)
        units = "length units" if three else "px"
        if not three:
            points[:, 1] = -points[:, 1]  # image y points down; bark's vertical points up
            if scale is not None:
                points /= scale
                units = "m"
        _, patches = np.unique(np.array(ids, dtype=object).astype(str), return_inverse=True)
        return cls(points=points, patches=patches, name=path.stem if name is None else name, units=units)

    def mirrored(self) -> "Pattern":
        """The pattern seen in a mirror held along the trunk: left and right swapped (θ → −θ on the
        trunk, x → −x in a plane), so every orientation ``o`` becomes ``180° − o``.  A phyllotactic
        spiral turns either way on real trees; this compares patterns of opposite handedness."""
        return attrs.evolve(self, points=_mirrored_points(self.points), name=f"{self.name} (mirrored)",
                            handedness=_other_hand(self.handedness))

    # -- measured -------------------------------------------------------------------------------
    def patch_table(self, min_size: int = MIN_PATCH_SIZE) -> "PatchTable":
        """Per patch of at least ``min_size`` points: size, centroid, orientation, anisotropy (PCA in
        the patch's tangent plane for points on the trunk, in the plane for 2-D points)."""
        ids, inverse, counts = np.unique(self.patches, return_inverse=True, return_counts=True)
        kept = counts >= min_size
        rank = np.cumsum(kept) - 1  # a kept patch's row
        at = kept[inverse.reshape(-1)]
        points, row, size = np.asarray(self.points, dtype=float)[at], rank[inverse.reshape(-1)][at], counts[kept]
        centroid, axes = _patch_axes(points, row, size, self.on_trunk)
        return PatchTable(patch=ids[kept].astype(np.int64), size=size.astype(np.int64), centroid=centroid,
                          orientation_deg=axes[:, 0], anisotropy=axes[:, 1], lambda1=axes[:, 2], lambda2=axes[:, 3],
                          units=self.units)

    def statistics(self, min_size: int = MIN_PATCH_SIZE) -> "PatternStatistics":
        """The pattern's statistics over its patches of at least ``min_size`` points."""
        return attrs.evolve(PatternStatistics.of_table(self.patch_table(min_size), name=self.name),
                            handedness=self.handedness)


def _patch_axes(points: np.ndarray, row: np.ndarray, size: np.ndarray, on_trunk: bool) -> tuple[np.ndarray, np.ndarray]:
    """Centroids and ``principal_axes`` of the tangent-plane (or 2-D) coordinates of every patch at
    once: ``points`` with their patch's ``row`` (patches of ``size`` points).  The definitions are
    ``tangent_plane`` and ``principal_axes``, patch by patch; here their sums go through ``bincount``
    and the 2 × 2 eigenproblem is solved in closed form (the same values to rounding; an exactly
    isotropic patch is at 90° as ``eigh`` puts it), so the statistics of a series of thousands of
    patches cost a few array passes.  A patch without extent (one point, or all its points at one
    place: λ1 = λ2 = 0) has no orientation and no anisotropy: NaN, left out of the statistics."""
    k = len(size)

    def mean(values):
        return np.bincount(row, weights=values, minlength=k) / size

    centroid = np.column_stack([mean(points[:, d]) for d in range(points.shape[1])]).reshape(k, points.shape[1])
    if on_trunk:
        angle = np.arctan2(points[:, 1], points[:, 0])
        theta = np.arctan2(mean(np.sin(angle)), mean(np.cos(angle)))  # each patch's circular mean
        rel = points - centroid[row]
        u = rel[:, 0] * -np.sin(theta)[row] + rel[:, 1] * np.cos(theta)[row]
        w = rel[:, 2]
    else:
        u, w = points[:, 0], points[:, 1]
    u, w = u - mean(u)[row], w - mean(w)[row]
    a, b, c = (np.bincount(row, weights=p, minlength=k) / np.maximum(size - 1, 1) for p in (u * u, u * w, w * w))
    mid, half = 0.5 * (a + c), np.hypot(0.5 * (a - c), b)
    l1, l2 = np.maximum(mid + half, 0.0), np.maximum(mid - half, 0.0)
    orientation = np.where(half > 0.0, np.degrees(0.5 * np.arctan2(2.0 * b, a - c)) % 180.0, 90.0)
    total = l1 + l2
    anisotropy = np.divide(l1 - l2, total, out=np.full(k, np.nan), where=total > 0)
    orientation = np.where(total > 0, orientation, np.nan)
    return centroid, np.column_stack([orientation, anisotropy, l1, l2]).reshape(k, 4)


def _mirrored_points(points: np.ndarray) -> np.ndarray:
    """Points seen in a mirror held along the trunk: y → −y for 3-D points on the trunk (θ → −θ), x → −x
    for 2-D points in a plane."""
    flip = np.ones(points.shape[1])
    flip[1 if points.shape[1] == 3 else 0] = -1.0
    return points * flip


def spiral_handedness(x: np.ndarray) -> str | None:
    """The handedness of the lattice whose bases sit at ``x`` (``(n, 3)``, trunk axis z, in lattice
    order): ``"right"`` where base i + 1 lies mostly counter-clockwise of base i seen from above (the
    angle from one to the next, wrapped to (−180°, 180°], has a positive median), ``"left"`` where
    clockwise; ``None`` with fewer than two bases or a median turn of 0 or 180° (no direction)."""
    if x.shape[0] < 2:
        return None
    theta = np.arctan2(x[:, 1], x[:, 0])
    turn = float(np.median(np.remainder(np.diff(theta) + math.pi, 2.0 * math.pi) - math.pi))
    if not (1e-9 < abs(turn) < math.pi - 1e-9):
        return None
    return "right" if turn > 0 else "left"


def _other_hand(handedness: str | None) -> str | None:
    """The handedness of a mirror image."""
    return {"right": "left", "left": "right"}.get(handedness)


def _mirror(deg):
    """``180° − o`` in ``[0, 180)``: an axis seen in a mirror held along the trunk."""
    out = (180.0 - np.asarray(deg, dtype=float)) % 180.0
    return np.where(out >= 180.0, 0.0, out)


def _number(text: str, path: Path, line: int, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise BarkError(f"{path} line {line}: {column} = {text!r} is not a number") from None
    if not math.isfinite(value):
        raise BarkError(f"{path} line {line}: {column} = {text} is not a finite number")
    return value


@attrs.frozen(eq=False)
class PatchTable:
    """One entry per patch (arrays of equal length).  ``centroid`` is ``(n, 3)`` on the trunk or
    ``(n, 2)`` in a plane, in ``units``."""

    patch: np.ndarray
    size: np.ndarray
    centroid: np.ndarray
    orientation_deg: np.ndarray
    anisotropy: np.ndarray
    lambda1: np.ndarray
    lambda2: np.ndarray
    units: str = "length units"

    def __len__(self) -> int:
        return int(self.patch.shape[0])

    def mirrored(self) -> "PatchTable":
        """The table of the mirrored pattern (``Pattern.mirrored``)."""
        return attrs.evolve(self, centroid=_mirrored_points(self.centroid), orientation_deg=_mirror(self.orientation_deg))

    @property
    def columns(self) -> list[str]:
        """The CSV columns of :meth:`rows`: the centroid as ``theta_deg, z`` on the trunk, ``x, y`` in a plane."""
        where = ["theta_deg", "z"] if self.centroid.shape[1] == 3 else ["x", "y"]
        return ["patch", "size", *where, "orientation_deg", "anisotropy", "lambda1", "lambda2"]

    @property
    def header(self) -> list[str]:
        """patches.csv's header: :attr:`columns` with their units on the trunk (``z_lu``,
        ``lambda1_lu2``: ``bark.units.headed``); in a plane the input's own units, unnamed."""
        return patch_header(self.columns)

    def to_pandas(self):
        """The table as a ``pandas.DataFrame``, a row per patch, patches.csv's columns (:attr:`header`;
        pandas is not a dependency of bark: install it to use this)."""
        from bark.units import data_frame

        return data_frame(self.rows(), self.columns, self.header)

    def rows(self) -> list[dict]:
        """One dict per patch, keyed by :attr:`columns`."""
        c = self.centroid
        if c.shape[1] == 3:
            where = {"theta_deg": np.degrees(np.arctan2(c[:, 1], c[:, 0])) % 360.0, "z": c[:, 2]}
        else:
            where = {"x": c[:, 0], "y": c[:, 1]}
        cols = {"patch": self.patch, "size": self.size, **where, "orientation_deg": self.orientation_deg,
                "anisotropy": self.anisotropy, "lambda1": self.lambda1, "lambda2": self.lambda2}
        names = self.columns
        return [dict(zip(names, vals)) for vals in zip(*(cols[k].tolist() for k in names))]


@attrs.frozen
class Axial:
    """A distribution of orientations (axes, degrees in ``[0, 180)``): its axial circular mean, SD
    and the standard error of the mean (Fisher 1993, §4.4 on doubled angles; ``bark.analysis.patches``)."""

    n: int
    mean_deg: float
    sd_deg: float
    se_deg: float


@attrs.frozen
class Linear:
    """A distribution on the line (anisotropy): mean, sample SD and standard error ``SD / √n``."""

    n: int
    mean: float
    sd: float
    se: float


def wrapped_normal_se(sd_deg: float, n: int) -> float:
    """:func:`axial_se` from a circular SD alone (a published summary without its patches), taking
    the orientations as wrapped normal: ``R̄ = exp(−σ²/2)`` and ``ρ₂ = R̄⁴`` on the doubled circle."""
    if n < 2 or not math.isfinite(sd_deg):
        return float("nan")
    sigma = math.radians(2.0 * sd_deg)
    r = math.exp(-0.5 * sigma * sigma)
    delta = (1.0 - r ** 4) / (2.0 * r * r)
    return math.degrees(math.sqrt(delta / n)) / 2.0


def _linear(values: np.ndarray) -> Linear:
    n = int(values.size)
    if n == 0:
        return Linear(0, math.nan, math.nan, math.nan)
    sd = float(np.std(values, ddof=1)) if n > 1 else math.nan
    return Linear(n, float(np.mean(values)), sd, sd / math.sqrt(n))


def patch_header(columns: list[str]) -> list[str]:
    """A patch table's header for its ``columns``: their units on the trunk (centroid ``theta_deg,
    z``: ``z_lu``, ``lambda1_lu2``); a pattern in a plane is in the input's own units, unnamed."""
    return headed(columns) if "theta_deg" in columns else columns


@attrs.frozen(eq=False, repr=False)
class PatternStatistics:
    """What the paper reports of a pattern (Fig. 6B, 7B): the number of patches, the distribution of
    their orientations and of their anisotropies, and the patches themselves (``None`` for a pattern
    known only by its published summary)."""

    name: str
    n_patches: int
    orientation: Axial
    anisotropy: Linear | None
    """``None`` where a published summary does not give it."""
    patches: PatchTable | None = None
    fraction_within_45: float | None = None
    """Share of patches whose orientation is within 45° of the mean axis (NaN with no patches; ``None``
    where a published summary does not give it)."""
    source: str = ""
    """Where the figures come from, in words (a file, or the publication of a summary)."""
    handedness: str | None = None
    """The handedness of the pattern's lattice (``Pattern.handedness``); ``None`` where unknown."""

    @classmethod
    def of_table(cls, table: PatchTable, name: str = "", source: str = "") -> "PatternStatistics":
        """The statistics of the patches in ``table`` (:class:`~bark.analysis.patches.PatchTable`), named
        ``name``, from ``source``."""
        return cls.of_values(table.orientation_deg, table.anisotropy, name=name, patches=table, source=source)

    @classmethod
    def of_values(cls, orientation_deg: np.ndarray, anisotropy: np.ndarray, name: str = "",
                  patches: PatchTable | None = None, source: str = "") -> "PatternStatistics":
        """The statistics of patches with these orientations and anisotropies (one each).  A patch
        without extent (NaN: its points all at one place) has no orientation: it is left out, and a
        warning says how many were (a photograph digitised so is not a pattern of such patches)."""
        deg, ani = np.asarray(orientation_deg, dtype=float), np.asarray(anisotropy, dtype=float)
        measured = np.isfinite(deg)
        if not measured.all():
            gone = int((~measured).sum())
            warnings.warn(f"{name or 'pattern'}: {gone} of its {deg.size} patches have no extent (their points all at "
                          f"one place), so no orientation: left out of its statistics", BarkWarning, stacklevel=2)
            deg, ani = deg[measured], ani[measured]
        n = int(deg.size)
        aniso = _linear(ani)
        if n == 0:  # no patches: every statistic undefined (NaN), as summary.json writes it (null)
            nan = math.nan
            return cls(name=name, n_patches=0, orientation=Axial(0, nan, nan, nan), anisotropy=aniso,
                       patches=patches, fraction_within_45=nan, source=source)
        mean = axial_mean(deg)
        return cls(name=name, n_patches=n, orientation=Axial(n, mean, axial_sd(deg), axial_se(deg)),
                   anisotropy=aniso, patches=patches,
                   fraction_within_45=float(np.mean(np.abs(axial_difference(deg, mean)) <= 45.0)), source=source)

    @classmethod
    def of_summary(cls, name: str, n_patches: int, mean_orientation_deg: float, sd_orientation_deg: float,
                   mean_anisotropy: float | None = None, sd_anisotropy: float | None = None,
                   source: str = "") -> "PatternStatistics":
        """A pattern known only by its summary (a published figure): standard errors from the SDs,
        the orientations taken as wrapped normal (:func:`wrapped_normal_se`)."""
        n = n_patches
        orientation = Axial(n, mean_orientation_deg % 180.0, sd_orientation_deg, wrapped_normal_se(sd_orientation_deg, n))
        aniso = None
        if mean_anisotropy is not None:
            sd = math.nan if sd_anisotropy is None else sd_anisotropy
            aniso = Linear(n, mean_anisotropy, sd, sd / math.sqrt(n))
        return cls(name=name, n_patches=n, orientation=orientation, anisotropy=aniso, source=source)

    def mirrored(self) -> "PatternStatistics":
        """The statistics of the mirrored pattern (``Pattern.mirrored``): orientations ``o → 180° − o``,
        spreads and anisotropy unchanged."""
        o = self.orientation
        return attrs.evolve(self, name=f"{self.name} (mirrored)", orientation=attrs.evolve(o, mean_deg=float(_mirror(o.mean_deg))),
                            patches=None if self.patches is None else self.patches.mirrored(),
                            handedness=_other_hand(self.handedness))

    def __repr__(self) -> str:
        """One line: the name, the patches, the orientation (mean ± SE, SD) and the anisotropy (mean ± SE)."""
        o, a = self.orientation, self.anisotropy
        text = f"PatternStatistics({self.name!r}: {self.n_patches} patches, orientation {o.mean_deg:.1f}° ± {o.se_deg:.1f}° " \
               f"(SD {o.sd_deg:.1f}°)"
        return text + ("" if a is None else f", anisotropy {a.mean:.3f} ± {a.se:.3f}") + \
            ("" if self.patches is None else ", with its patch table") + ")"

    def as_dict(self) -> dict:
        """The figures as plain values (for JSON and tables); no per-patch rows."""
        a = self.anisotropy
        return {"name": self.name, "n_patches": self.n_patches,
                "mean_orientation_deg": self.orientation.mean_deg, "circular_sd_deg": self.orientation.sd_deg,
                "orientation_se_deg": self.orientation.se_deg,
                "mean_anisotropy": None if a is None else a.mean, "anisotropy_sd": None if a is None else a.sd,
                "anisotropy_se": None if a is None else a.se, "fraction_within_45_deg": self.fraction_within_45,
                "handedness": self.handedness, "source": self.source}


def _records(body: list[tuple[int, str]], path: Path):
    """``(line number, fields)`` of each CSV record in ``body`` (its ``(line number, line)`` pairs):
    a record's number is that of the line it begins on, though a quoted field may run over several."""
    at = [0]

    def lines():
        while at[0] < len(body):
            at[0] += 1
            yield body[at[0] - 1][1]

    reader = csv.reader(lines())
    while True:
        start = at[0]
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as err:
            raise BarkError(f"{path} line {body[start][0]}: not CSV ({err})") from None
        yield body[start][0], row


_SUMMARY_KEYS = {"name": str, "n_patches": int, "mean_orientation_deg": float, "sd_orientation_deg": float,
                 "mean_anisotropy": float, "sd_anisotropy": float, "source": str}


def _summary_file(path: Path) -> PatternStatistics:
    """A published pattern's summary from a TOML file's ``[pattern]`` table."""
    try:
        with open_regular(path) as fh:
            table = tomllib.load(fh)
    except OSError as err:
        raise BarkError(f"{path}: cannot be read ({err.strerror or err})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise BarkError(f"{path}: not valid TOML ({err})") from None
    p = table.get("pattern")
    if not isinstance(p, dict):
        raise BarkError(f"{path}: no [pattern] table (a summary: n_patches, mean_orientation_deg, sd_orientation_deg, ...)")
    for key, value in p.items():
        want = _SUMMARY_KEYS.get(key)
        if want is None:
            raise BarkError(f"{path}: [pattern] {key}: unknown (known: {', '.join(_SUMMARY_KEYS)})")
        ok = isinstance(value, str) if want is str else (
            isinstance(value, int) and not isinstance(value, bool) if want is int else
            isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value))
        if not ok:
            raise BarkError(f"{path}: [pattern] {key} = {value!r}: must be {'text' if want is str else 'a whole number' if want is int else 'a finite number'}")
    for key in ("n_patches", "mean_orientation_deg", "sd_orientation_deg"):
        if key not in p:
            raise BarkError(f"{path}: [pattern] has no {key}")
    if p["n_patches"] < 1:
        raise BarkError(f"{path}: [pattern] n_patches = {p['n_patches']}: must be at least 1")
    for key in ("sd_orientation_deg", "sd_anisotropy"):
        if key in p and p[key] < 0:
            raise BarkError(f"{path}: [pattern] {key} = {p[key]!r}: must be >= 0")
    if "sd_anisotropy" in p and "mean_anisotropy" not in p:
        raise BarkError(f"{path}: [pattern] sd_anisotropy without mean_anisotropy")
    return PatternStatistics.of_summary(
        name=p.get("name", path.stem), n_patches=p["n_patches"], mean_orientation_deg=float(p["mean_orientation_deg"]),
        sd_orientation_deg=float(p["sd_orientation_deg"]),
        mean_anisotropy=None if "mean_anisotropy" not in p else float(p["mean_anisotropy"]),
        sd_anisotropy=None if "sd_anisotropy" not in p else float(p["sd_anisotropy"]),
        source=p.get("source", str(path)))


def _run_folder(path: Path) -> Pattern:
    state = path / "state.npz"
    if state.is_file():
        return Pattern.from_state(state, name=path.name)
    raise BarkError(f"{path}: the run kept no state.npz (its leaf-base positions); run it with "
                    "'state-snapshot' among its effects")


def read(path: str | Path, min_size: int | None = None) -> PatternStatistics:
    """The statistics of the pattern at ``path``: a run's output folder (its ``state.npz``), a state
    file (``.npz``), a CSV of leaf-base centres (``.csv``) or a published summary (``.toml``, a
    ``[pattern]`` table).  ``min_size`` defaults to the run's own for a run folder, else 7."""
    path = Path(path)
    if path.suffix.lower() == ".toml" and path.exists():
        return _summary_file(path)
    pattern = load(path)
    if min_size is None:
        min_size = run_min_size(path) if path.is_dir() else MIN_PATCH_SIZE
    return attrs.evolve(pattern.statistics(min_size), source=str(path))


def load(path: str | Path) -> Pattern:
    """The leaf bases and patches of the pattern at ``path``: a run's output folder (its ``state.npz``),
    a state file (``.npz``) or a CSV of leaf-base centres (``.csv``)."""
    path = Path(path)
    if not path.exists():
        raise BarkError(f"{path}: no such file or folder")
    suffix = path.suffix.lower()
    if path.is_dir():
        return _run_folder(path)
    if suffix == ".npz":
        return Pattern.from_state(path)
    if suffix == ".csv":
        return Pattern.from_csv(path)
    if suffix == ".toml":
        raise BarkError(f"{path}: a published summary has no leaf bases to measure (give a run folder, a state .npz "
                        "or a .csv of leaf-base centres)")
    raise BarkError(f"{path}: not a pattern (a run folder, a state .npz, a .csv of leaf-base centres or a .toml summary)")


def springs_of(path: str | Path) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]] | None:
    """The springs of the pattern at ``path``: a run folder's or state file's ``(pairs, intact,
    offsets)``, its offsets those of its springs, commonest first (what an analyzer that reads springs
    is given, ``bark.contract.strategies.Springs``); ``None`` for a pattern without them (a
    photograph's CSV, a state file that kept none)."""
    path = Path(path)
    state = path / "state.npz" if path.is_dir() else path if path.suffix.lower() == ".npz" else None
    if state is None:
        return None
    with np.load(state, allow_pickle=False) as d:
        if not {"pairs", "intact"} <= set(d.files):
            return None
        pairs, intact, n = d["pairs"], d["intact"], len(d["x"]) if "x" in d.files else 0
    if pairs.ndim != 2 or pairs.shape[1:] != (2,) or intact.shape != (len(pairs),) or (
            pairs.size and (pairs.min() < 0 or pairs.max() >= n)):
        raise BarkError(f"{state}: its springs are damaged (pairs {pairs.shape}, intact {intact.shape}, {n} bases)")
    pairs, intact = pairs.astype(np.int64), intact.astype(bool)
    family, counts = np.unique(pairs[:, 1] - pairs[:, 0], return_counts=True)
    return pairs, intact, tuple(int(o) for o in family[np.argsort(-counts, kind="stable")])


def run_min_size(folder: Path) -> int:
    """The minimum patch size the run in ``folder`` used (its summary.json), else the default."""
    import json

    try:
        with (folder / "summary.json").open(encoding="utf-8") as fh:
            value = json.load(fh)["settings"]["run"]["min_patch_size"]
        return int(value) if isinstance(value, int) and value >= 1 else MIN_PATCH_SIZE
    except (OSError, ValueError, KeyError, TypeError):
        return MIN_PATCH_SIZE


PALETTE = np.array([(68, 119, 170), (102, 204, 238), (34, 136, 51), (204, 187, 68), (238, 102, 119), (170, 51, 119)],
                   dtype=np.uint8)
"""The patch colours, RGB: Paul Tol's "bright" scheme, told apart with deuteranopia and protanopia as
well as with normal colour vision (every pair, and each against the fragments' grey, is at least
15 ΔE*ab apart under the simulations of Machado et al. 2009: ``tests/test_pattern.py``).  Six are
enough for neighbouring patches never to share one: the patches of a trunk form a planar map, which
the greedy colouring in smallest-last order colours with at most six."""
FRAGMENT_GREY = np.array([179, 179, 179], dtype=np.uint8)
"""The colour of fragments (patches under the minimum size), in every picture and mesh."""


def patch_colours(labels: np.ndarray, min_size: int, pairs: np.ndarray | None = None,
                  intact: np.ndarray | None = None) -> np.ndarray:
    """An RGB colour (uint8) per base: its patch's, :data:`FRAGMENT_GREY` for fragments of fewer
    than ``min_size`` bases.  With the springs (``pairs`` and their ``intact`` mask) no two
    neighbouring patches share a colour: the patches that a broken spring joins are neighbours, and
    the graph of neighbours is coloured greedily (``networkx.greedy_color``, smallest last; a map
    needs few colours), and the colour that covers the most bases is the palette's first.  Without
    them a patch's colour follows its label, stable from frame to frame of an animation."""
    return rgb(_colour_of_label(labels, min_size, pairs, intact)[np.asarray(labels, dtype=np.int64)])


def rgb(index: np.ndarray) -> np.ndarray:
    """The RGB colours (uint8) of colour indices into ``PALETTE`` followed by ``FRAGMENT_GREY``."""
    return np.vstack([PALETTE, FRAGMENT_GREY])[np.asarray(index, dtype=np.int64)]


def label_colours(labels: np.ndarray, min_size: int) -> np.ndarray:
    """Each base's colour as an index (uint8) into ``PALETTE`` followed by ``FRAGMENT_GREY``: what
    :func:`patch_colours` gives without the springs (the colour follows the label), as indices."""
    return _colour_of_label(labels, min_size)[np.asarray(labels, dtype=np.int64)]


def _colour_of_label(labels: np.ndarray, min_size: int, pairs: np.ndarray | None = None,
                     intact: np.ndarray | None = None) -> np.ndarray:
    """Each label's colour (uint8) as an index into ``PALETTE`` followed by ``FRAGMENT_GREY``, the
    grey's for fragments (see :func:`patch_colours`)."""
    labels = np.asarray(labels, dtype=np.int64)
    sizes = np.bincount(labels) if labels.size else np.zeros(0, np.int64)
    index = (np.arange(sizes.size) % len(PALETTE)).astype(np.uint8)
    if pairs is not None and labels.size:
        pairs = np.asarray(pairs, dtype=np.int64)
        nodes = np.flatnonzero(sizes >= min_size)
        edges = _neighbouring(labels, sizes, pairs[~np.asarray(intact, dtype=bool)], min_size)
        if not len(edges):  # no two patches touch: greedy colouring gives each the first colour
            index[nodes] = 0
        else:
            import networkx as nx

            graph = nx.Graph()
            graph.add_nodes_from(nodes.tolist())
            graph.add_edges_from(edges.tolist())
            for label, colour in nx.greedy_color(graph, strategy="smallest_last").items():  # planar: <= 6
                index[label] = colour % len(PALETTE)
            index[nodes] = _by_share(index[nodes], sizes[nodes])
    index[sizes < min_size] = len(PALETTE)
    return index


def _by_share(colour: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """The colours ``colour`` of patches of ``sizes`` bases renamed so that the colour covering the
    most bases is ``PALETTE[0]``, the next ``PALETTE[1]``, … (ties: the lower colour first): the same
    colouring (a renaming keeps neighbours apart), the trunk's bulk in the first colour, not in
    whatever the greedy order left it (a green trunk among green leaves)."""
    share = np.bincount(colour, weights=sizes, minlength=len(PALETTE))
    rank = np.empty(len(share), np.uint8)
    rank[np.lexsort((np.arange(len(share)), -share))] = np.arange(len(share), dtype=np.uint8)
    return rank[colour]


def lineage_colours(labels_along: list[np.ndarray], min_size: int, pairs: np.ndarray,
                    intact: np.ndarray) -> list[np.ndarray]:
    """The colours of a run's frames (each base's index into ``PALETTE`` followed by
    ``FRAGMENT_GREY``), one array per frame of ``labels_along``, the last frame the run's end with
    its springs ``pairs`` and their ``intact`` mask.  The last frame is coloured as
    :func:`patch_colours` colours the end (so an animation ends on ``pattern.png``); an earlier
    patch takes the colour of the patch at the end that most of its bases belong to, so a patch
    keeps its colour from frame to frame and a split leaves the larger piece its colour.  Where two
    neighbouring patches of a frame come to share one, the smaller takes the first colour none of
    its neighbours has.  Bases only join a run (a frame's bases are the first of the end's), and a
    spring joining two patches of a frame is broken by then."""
    last = np.asarray(labels_along[-1], dtype=np.int64)
    end = _colour_of_label(last, min_size, pairs, intact)
    counted = np.bincount(last, minlength=1) >= min_size  # the end's patches (fragments have no colour to pass on)
    pairs = np.asarray(pairs, dtype=np.int64)
    out = []
    for labels in labels_along:
        labels = np.asarray(labels, dtype=np.int64)
        index = _colour_of_label(labels, min_size)  # what no patch at the end gives: the label's own
        if labels.size:
            sizes, later = np.bincount(labels), last[:labels.size]
            keep = counted[later] & (sizes[labels] >= min_size)
            span = int(last.max()) + 1
            key, counts = np.unique(labels[keep] * span + later[keep], return_counts=True)
            was, becomes = np.divmod(key, span)
            order = np.lexsort((-counts, was))  # per patch of the frame, the end's patch with most of its bases first
            was, becomes = was[order], becomes[order]
            first = np.r_[True, was[1:] != was[:-1]] if was.size else np.zeros(0, bool)
            index[was[first]] = end[becomes[first]]
            _separate_neighbours(index, labels, sizes, pairs[(pairs < labels.size).all(axis=1)], min_size)
        out.append(index[labels])
    return out


def _separate_neighbours(index: np.ndarray, labels: np.ndarray, sizes: np.ndarray, pairs: np.ndarray,
                         min_size: int) -> None:
    """Recolour (in ``index``, a colour per label) the smaller of any two neighbouring patches of
    ``labels`` sharing a colour with the first colour none of its neighbours has, smaller patches
    first, and again while a pass recoloured one: a patch whose neighbours held every colour may
    find one free once a neighbour has changed.  A recolouring ends a clash and makes none, so the
    clashes only fall and the passes end."""
    import networkx as nx

    across = _neighbouring(labels, sizes, pairs, min_size)
    if not across.size:
        return
    graph = nx.Graph(across.tolist())
    changed = True
    while changed:
        changed = False
        clashes = sorted({min(a, b, key=lambda q: (sizes[q], q)) for a, b in graph.edges if index[a] == index[b]},
                         key=lambda q: (sizes[q], q))
        for label in clashes:
            taken = {int(index[q]) for q in graph[label]}
            free = [c for c in range(len(PALETTE)) if c not in taken]
            if int(index[label]) in taken and free:
                index[label], changed = free[0], True


def _neighbouring(labels: np.ndarray, sizes: np.ndarray, pairs: np.ndarray, min_size: int) -> np.ndarray:
    """The pairs of patches (labels, each pair once, smaller first) of at least ``min_size`` bases
    that springs ``pairs`` join: neighbours, where the springs are broken ones."""
    across = labels[pairs]
    across = across[(across[:, 0] != across[:, 1]) & (sizes[across] >= min_size).all(axis=1)]
    return np.unique(np.sort(across, axis=1), axis=0)


def simulation_colours(sim, min_size: int) -> np.ndarray:
    """:func:`patch_colours` of a simulation's patches now, neighbours never sharing a colour."""
    return patch_colours(sim.patch_labels(), min_size, sim.state.pairs, sim.state.intact)
