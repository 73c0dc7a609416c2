"""Statistics of a bark pattern beyond the paper's orientation and anisotropy: the distribution of patch
sizes, the topology and geometry of the crack network, and how the cracks lie on the lattice.

Every statistic is defined on plain arrays — the bases' positions unrolled into a plane (arc length,
height; ``period`` the trunk's circumference, or ``None`` for a photograph), each base's patch, and,
where there are springs, their ends and intact flags and the lattice's two spring offsets — so that
simulated bark and digitised photographs are measured alike (a photograph has no springs: only its
patch sizes are measured).  Definitions (docs/patterns.md: Pattern statistics beyond the paper):

* **Patch sizes** (bases per patch, patches of at least ``s_min`` bases): mean and SD; the maximum-
  likelihood power law ``p(s) ∝ s^−α`` and log-normal ``p(s) ∝ exp(−(ln s − μ)²/2σ²)/s``, each
  truncated below at ``s_min − ½`` (the continuous approximation of Clauset, Shalizi & Newman 2009
  for integer sizes), compared by Vuong's normalised log-likelihood ratio ``R`` (> 0 favours the power
  law) and its two-sided p-value; ``favoured`` names the power law or the log-normal where p < 0.1,
  else ``neither``.
* **Junctions**: the lattice's cells — the four bases ``i, i + o₁, i + o₂, i + o₁ + o₂`` — whose bases
  belong to three or four different patches; ``v̄`` is the mean number of patches at a junction and
  ``n̄`` the mean number of junctions a patch (of at least ``s_min`` bases) touches: the (n̄, v̄) plane
  of Domokos et al. (2020, "Plato's cube"), where a mosaic of quadrangles meeting four at a corner
  sits at (4, 4), one of T-junctions (a brick wall, mud cracks) at (6, 3) and Voronoi-like ones near
  (6, 3) too.
* **Junction angles**: at a junction of three patches, three cracks meet, one between each two of
  them; each crack's direction is the mean direction, from the junction's centre, of its pieces
  between 0.3 and 1 ``radius`` away (default: five springs' length), and the junction's angles are
  those between the three directions (summing to 360°; a junction whose ring the pattern's edge cuts
  is left out).  A junction is a **T** where its largest angle is at least 150°, else a **Y** (three
  near 120°).
* **Crack alignment**: each broken spring between two patches is a piece of crack running across it,
  perpendicular to it; the nematic order ``S = |⟨exp(2iθ)⟩|`` of these pieces (1: all parallel, 0: no
  common direction; Nandakishore & Goehring 2016) and their director (degrees from horizontal, 90 =
  along the trunk).
* **Lattice bias** (Federl & Prusinkiewicz's weakness of mass-spring bark): for each spring offset,
  its share of the crack pieces against its share of all springs (what a crack blind to the
  lattice would break); ``bias`` is their ratio, 1 without bias.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["size_distribution", "crack_network", "measure", "of_state", "of_pattern", "SIZE_KEYS", "NETWORK_KEYS"]

T_ANGLE = 150.0
"""A junction of three patches whose largest angle reaches this (degrees) is a T-junction."""
SIGNIFICANT = 0.1
"""Vuong's test decides between the power law and the log-normal below this p-value (Clauset et al.)."""
SIZE_KEYS = ("size_mean", "size_sd", "powerlaw_alpha", "lognormal_mu", "lognormal_sigma", "size_loglik_ratio",
             "size_p_value", "size_favoured")
NETWORK_KEYS = ("n_junctions", "n_bar", "v_bar", "t_fraction", "y_fraction", "nematic_order", "crack_director_deg")


def size_distribution(sizes, s_min: int, law: bool = True) -> dict:
    """The patch-size statistics of ``sizes`` (bases per patch) of at least ``s_min`` (module
    docstring).  ``law=False``: the mean and SD only, the laws' keys ``None`` — what asks for no law
    (a fit compares the mean) pays neither their fit nor scipy's optimiser."""
    s = np.asarray(sizes, dtype=float)
    s = s[s >= s_min]
    n = s.size
    out = dict.fromkeys(SIZE_KEYS)
    if n == 0:
        return out
    out.update(size_mean=float(s.mean()), size_sd=float(s.std(ddof=1)) if n > 1 else None)
    if not law or n < 3 or np.all(s == s[0]):
        return out
    from scipy.optimize import minimize  # only where there is a law to fit: a run with one patch never pays it
    from scipy.special import erfc, log_ndtr
    cut = s_min - 0.5
    logs, log_cut = np.log(s), math.log(cut)
    alpha = 1.0 + n / float(np.sum(logs - log_cut))
    pl = math.log(alpha - 1.0) - log_cut - alpha * (logs - log_cut)  # ln p for each size

    def ln_lognormal(params):
        mu, ln_sigma = params
        sigma = math.exp(ln_sigma)
        z = (logs - mu) / sigma
        return -0.5 * z * z - logs - math.log(sigma * math.sqrt(2.0 * math.pi)) - log_ndtr(-(log_cut - mu) / sigma)

    fit = minimize(lambda p: -float(np.sum(ln_lognormal(p))), x0=[float(logs.mean()), math.log(max(logs.std(), 1e-3))],
                   method="Nelder-Mead", options={"xatol": 1e-8, "fatol": 1e-10, "maxiter": 4000})
    ln = ln_lognormal(fit.x)
    diff = pl - ln
    ratio, spread = float(diff.sum()), float(diff.std())
    p = float(erfc(abs(ratio) / (spread * math.sqrt(2.0 * n)))) if spread > 0 else 0.0
    favoured = "neither" if p >= SIGNIFICANT else ("power law" if ratio > 0 else "log-normal")
    out.update(powerlaw_alpha=alpha, lognormal_mu=float(fit.x[0]), lognormal_sigma=float(math.exp(fit.x[1])),
               size_loglik_ratio=ratio, size_p_value=p, size_favoured=favoured)
    return out


def _delta(a: np.ndarray, b: np.ndarray, period: float | None) -> np.ndarray:
    """``b − a`` in the plane, the first coordinate the nearest way round a ``period``."""
    d = b - a
    if period is not None:
        d[..., 0] -= period * np.round(d[..., 0] / period)
    return d


def crack_network(points: np.ndarray, labels: np.ndarray, pairs: np.ndarray, intact: np.ndarray,
                  offsets: tuple[int, int], s_min: int = 7, period: float | None = None,
                  radius: float | None = None) -> dict:
    """The crack network's statistics (module docstring) of a pattern whose bases are at ``points``
    (``(n, 2)``: arc length, height; ``period`` the circumference, ``None`` for a plane), in patches
    ``labels``, joined by the springs ``pairs`` (``intact`` or broken) at the lattice's two ``offsets``.
    ``radius`` of the rings that measure junction angles: default five times the median spring."""
    points = np.asarray(points, dtype=float)
    labels = np.asarray(labels, dtype=np.int64)
    pairs = np.asarray(pairs, dtype=np.int64)
    intact = np.asarray(intact, dtype=bool)
    n = len(points)
    o1, o2 = sorted(offsets)[:2]
    out: dict = dict.fromkeys(NETWORK_KEYS)
    # -- junctions: lattice cells whose four bases are in three or four patches
    first = np.arange(max(n - o1 - o2, 0))
    corners = np.stack([first, first + o1, first + o1 + o2, first + o2], axis=1)
    cell_labels = np.sort(labels[corners], axis=1)
    distinct = 1 + (np.diff(cell_labels, axis=1) != 0).sum(axis=1)
    cells = corners[distinct >= 3]
    if len(cells) and len(pairs):  # a cell is a small quadrilateral: none whose corners lie far apart (a lattice's edge)
        reach = np.linalg.norm(_delta(points[cells[:, :1]], points[cells], period), axis=2).max(axis=1)
        typical = float(np.median(np.linalg.norm(_delta(points[pairs[:, 0]], points[pairs[:, 1]], period), axis=1)))
        cells = cells[reach <= 3.0 * typical]
    sizes = np.bincount(labels, minlength=int(labels.max(initial=-1)) + 1)
    out["n_junctions"] = 0
    if len(cells):
        # cells that share a base are one junction (where three patches meet, two cells may hold it):
        # the components of cells joined to their bases, the cells numbered first, so their
        # components are numbered first, in order of each one's first cell
        from bark.model.components import components

        m = len(cells)
        ties = np.column_stack([np.repeat(np.arange(m), 4), m + cells.ravel()])
        which = components(m + n, ties, np.ones(len(ties), bool))[:m].astype(np.int64)
        count = int(which.max()) + 1
        who = np.unique(np.column_stack([np.repeat(which, 4), labels[cells].ravel()]), axis=0)  # (junction, patch)
        per_junction = np.bincount(who[:, 0], minlength=count)
        touched = np.bincount(who[:, 1], minlength=sizes.size)
        big = (sizes >= s_min) & (touched > 0)
        out.update(n_junctions=int(count), v_bar=float(per_junction.mean()),
                   n_bar=float(touched[big].mean()) if big.any() else None)
        out.update(_junction_angles(points, labels, pairs, intact, cells, which, who, per_junction, period, radius))
    # -- crack pieces: the broken springs between two patches, each across its spring
    broken = pairs[~intact]
    broken = broken[labels[broken[:, 0]] != labels[broken[:, 1]]]
    if len(broken):
        d = _delta(points[broken[:, 0]], points[broken[:, 1]], period)
        theta = np.arctan2(d[:, 1], d[:, 0]) + 0.5 * math.pi  # the crack runs perpendicular to the spring
        mean = np.exp(2j * theta).mean()
        out["nematic_order"] = float(abs(mean))
        out["crack_director_deg"] = float(np.degrees(0.5 * np.angle(mean)) % 180.0)
    family = pairs[:, 1] - pairs[:, 0]
    broken_family = family[~intact][labels[pairs[~intact, 0]] != labels[pairs[~intact, 1]]]
    bias = {}
    for o in sorted(set(family.tolist())):
        expected = float(np.mean(family == o))
        observed = float(np.mean(broken_family == o)) if broken_family.size else None
        bias[str(o)] = {"crack_share": observed, "spring_share": expected,
                        "bias": None if observed is None else observed / expected}
    out["lattice_bias"] = bias
    return out


def _junction_angles(points, labels, pairs, intact, cells, which, who, per_junction, period, radius) -> dict:
    """Angles at the junctions of three patches, the T and Y shares and a histogram (module docstring):
    ``which`` is each cell's junction, ``who`` the (junction, patch) pairs."""
    from scipy.spatial import cKDTree

    threes = np.flatnonzero(per_junction == 3)
    none = {"t_fraction": None, "y_fraction": None, "junction_angle_counts": None}
    if not threes.size:
        return none
    spring = np.linalg.norm(_delta(points[pairs[:, 0]], points[pairs[:, 1]], period), axis=1)
    if radius is None:
        radius = 5.0 * float(np.median(spring))
    inner = 0.3 * radius
    corner = points[cells]
    middle = corner[:, 0] + _delta(corner[:, :1], corner, period).mean(axis=1)  # each cell's middle, across the seam
    ref = np.zeros((per_junction.size, 2))
    ref[which] = middle  # a cell of each junction: the others are taken relative to it, across the seam
    offsets = _delta(ref[which], middle, period)
    centre = ref + np.stack([np.bincount(which, weights=offsets[:, k], minlength=per_junction.size)
                             for k in (0, 1)], axis=1) / np.bincount(which, minlength=per_junction.size)[:, None]
    centre = centre[threes]
    lo, hi = points.min(axis=0), points.max(axis=0)  # a ring the pattern's edge cuts measures no angle
    whole = (centre[:, 1] - radius >= lo[1]) & (centre[:, 1] + radius <= hi[1])
    if period is None:
        whole &= (centre[:, 0] - radius >= lo[0]) & (centre[:, 0] + radius <= hi[0])
    threes, centre = threes[whole], centre[whole]
    broken = pairs[~intact]
    broken = broken[labels[broken[:, 0]] != labels[broken[:, 1]]]
    if not threes.size or not len(broken):
        return none
    mid = points[broken[:, 0]] + 0.5 * _delta(points[broken[:, 0]], points[broken[:, 1]], period)  # crack pieces
    ends = np.sort(labels[broken], axis=1)
    if period is not None:
        low = min(points[:, 1].min(), mid[:, 1].min())
        box = [period, 2.0 * (max(points[:, 1].max(), mid[:, 1].max()) - low + radius) + 1.0]
        tree = cKDTree(np.column_stack([mid[:, 0] % period, mid[:, 1] - low]), boxsize=box)
        near = tree.query_ball_point(np.column_stack([centre[:, 0] % period, centre[:, 1] - low]), radius)
    else:
        near = cKDTree(mid).query_ball_point(centre, radius)
    trios = _trios(who, threes)
    angles = []
    for j, c, ids in zip(threes, centre, near):
        ids = np.asarray(ids, dtype=np.int64)
        d = _delta(np.broadcast_to(c, (ids.size, 2)), mid[ids], period)
        far = np.hypot(d[:, 0], d[:, 1]) >= inner  # the branches away from the centre, where they point
        t = trios[j]
        branch = []
        for a, b in ((t[0], t[1]), (t[0], t[2]), (t[1], t[2])):
            on = far & (ends[ids, 0] == a) & (ends[ids, 1] == b)
            if on.any():
                unit = d[on] / np.hypot(d[on, 0], d[on, 1])[:, None]
                branch.append(math.atan2(unit[:, 1].sum(), unit[:, 0].sum()))
        if len(branch) == 3:
            direction = np.sort(np.mod(np.degrees(branch), 360.0))
            angles.append(np.sort(np.diff(np.append(direction, direction[0] + 360.0))))
    if not angles:
        return none
    angles = np.array(angles)
    t = angles[:, 2] >= T_ANGLE
    counts, _ = np.histogram(angles.ravel(), bins=24, range=(0.0, 360.0))
    return {"t_fraction": float(t.mean()), "y_fraction": float(1.0 - t.mean()),
            "junction_angle_counts": counts.tolist()}


def _trios(who: np.ndarray, junctions: np.ndarray) -> dict:
    """The patches of each of ``junctions`` (from the sorted (junction, patch) pairs ``who``)."""
    starts = np.searchsorted(who[:, 0], junctions)
    return {j: who[a:a + 3, 1] for j, a in zip(junctions, starts)}


def measure(points: np.ndarray, labels: np.ndarray, s_min: int, pairs=None, intact=None,
            offsets: tuple[int, ...] | None = None, law: bool = True) -> dict:
    """Every statistic of this module of a pattern: the patch sizes always, the crack network where it
    has springs (``pairs``, ``intact``) on a lattice of two offsets.  ``points`` are 3-D positions on
    the trunk (unrolled at their mean radius, a period round it) or 2-D ones in a plane (no period);
    ``offsets`` the lattice's, else the two commonest among the springs; ``law`` as for
    :func:`size_distribution`.  What a run writes in summary.json, ``bark analyze`` finds in its
    files and the network analyzer measures: one function."""
    labels = np.asarray(labels)
    sizes = np.unique(labels, return_counts=True)[1] if labels.size else np.empty(0, np.int64)
    out = size_distribution(sizes, s_min, law)
    if pairs is None or len(pairs) == 0:
        return out
    pairs = np.asarray(pairs, dtype=np.int64)
    if offsets is None:
        family, counts = np.unique(pairs[:, 1] - pairs[:, 0], return_counts=True)
        offsets = tuple(int(o) for o in family[np.argsort(-counts, kind="stable")][:2])
    if len(offsets) != 2:
        return {**out, **dict.fromkeys(NETWORK_KEYS)}
    points = np.asarray(points, dtype=float)
    period = None
    if points.shape[1] == 3:
        from bark.units import unwrap

        r = float(np.mean(np.hypot(points[:, 0], points[:, 1])))
        points, period = unwrap(points, r), 2.0 * np.pi * r
    _, dense = np.unique(labels, return_inverse=True)
    out.update(crack_network(points, dense.reshape(-1), pairs, intact, tuple(offsets), s_min, period=period))
    return out


def of_state(x: np.ndarray, labels: np.ndarray, pairs: np.ndarray, intact: np.ndarray, s_min: int) -> dict:
    """:func:`measure` of a run's state: positions ``x`` on the trunk (3-D), its springs, the lattice's
    two offsets taken as the two commonest among them."""
    return measure(x, labels, s_min, pairs, intact)


def of_pattern(path, patch_sizes, min_size: int | None, law: bool = True) -> dict:
    """The statistics beyond the paper's of the pattern at ``path`` (as ``bark.analysis.pattern.read``
    takes it) whose patches have ``patch_sizes`` bases: the sizes' statistics always, and the crack
    network's where the pattern has springs (a run's folder or state file).  ``min_size`` ``None``:
    the run's own (the summary.json beside it), else the default; ``law`` as for
    :func:`size_distribution`."""
    from pathlib import Path

    from bark.analysis.pattern import run_min_size

    path = Path(path)
    state = path / "state.npz" if path.is_dir() else path if path.suffix.lower() == ".npz" else None
    if min_size is None:  # the run's own, as the statistics took it
        min_size = run_min_size(path if path.is_dir() else path.parent)
    if state is not None:
        with np.load(state, allow_pickle=False) as d:
            if {"x", "labels", "pairs", "intact"} <= set(d.files):
                return measure(d["x"], d["labels"], min_size, d["pairs"], d["intact"], law=law)
    return size_distribution(patch_sizes, min_size, law)
