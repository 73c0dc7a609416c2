"""Writing a run's results: atomically, without plotting, readable without pickle.

Every file is written to a temporary name in the same folder and moved into place with
``os.replace``, so a reader (or a crash) never sees half a file.  Files of one run:

* ``patches.csv`` — one row per patch of ≥ min_size bases (from the patch analyzer).
* ``breaks.csv`` — the break log: spring, i, j, step, t, tension, in the order of breaking.
* ``summary.json`` — every setting, the seed, bark's version, the stop condition and why the run
  stopped, t and radius at the end, counts and pattern statistics, degenerate events.
* ``state.npz`` — the mechanical state at the end (x, v, anchor, pairs, rest, fmax, intact, patch
  labels, t, and ``field_<name>`` for each field a strategy declares); ``np.load(path)`` reads it
  with ``allow_pickle=False``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bark.contract.strategies import pattern_of
from bark.io.files import atomic_write, attempt, write_columns, write_csv, write_json, write_npz
from bark.units import headed, metres

__all__ = ["run_summary", "write_run", "write_graphml"]


PATCH_COLUMNS = ["patch", "size", "theta_deg", "z", "orientation_deg", "anisotropy", "lambda1", "lambda2"]
"""patches.csv's columns for a pattern on the trunk; a pattern in a plane has ``x, y`` in place of
``theta_deg, z`` (``patch_columns``)."""


def patch_columns(rows: list[dict]) -> list[str]:
    """patches.csv's columns for ``rows``: the centroid as the rows give it (``theta_deg, z`` on the
    trunk, ``x, y`` in a plane), then any further columns a custom analyzer added, none dropped."""
    if not rows:
        return PATCH_COLUMNS
    first = rows[0]
    where = ["theta_deg", "z"] if "theta_deg" in first else ["x", "y"] if "x" in first else []
    known = ["patch", "size", *where, "orientation_deg", "anisotropy", "lambda1", "lambda2"]
    return [c for c in known if c in first] + [c for c in first if c not in known]


PATTERN_KEYS = ("mean_orientation_deg", "circular_sd_deg", "orientation_se_deg", "mean_anisotropy", "anisotropy_sd",
                "anisotropy_se", "fraction_within_45_deg")
"""The pattern statistics summary.json takes from the analyzer's summary (``bark.analysis.patches.pattern_summary``)."""


YOUNG = "young"
"""The region of the bases that joined after the run began (primary growth at the top): the trunk
that grew during the run, stretched for less of it than the trunk it began with."""


def joined_later(state) -> np.ndarray:
    """Which bases joined after the run began (born after the first): the trunk grown since."""
    return state.born > (state.born.min() if state.born.size else 0.0)


def base_regions(sim) -> np.ndarray:
    """Each base's region: the growth law's region of its site (``Growth.region``), or
    :data:`YOUNG` for a base that joined during the run."""
    names = np.asarray(sim.growth.region(sim.state.anchor[:, 2]), dtype=object).copy()
    names[joined_later(sim.state)] = YOUNG
    return names


def trunk_regions(sim) -> np.ndarray | None:
    """The names of the trunk's regions (``base_regions``), or ``None`` when it has one region."""
    every = np.unique(base_regions(sim))
    return every if len(every) >= 2 else None


def largest_share(labels: np.ndarray) -> float | None:
    """The share of the bases ``labels`` (each base's patch) that the largest patch holds, fragments
    counted: near 1 for bark that has not come apart (``None`` for no bases)."""
    return float(np.bincount(labels).max() / labels.size) if labels.size else None


def patch_regions(sim, rows: list[dict], labels: np.ndarray) -> np.ndarray:
    """The region of each patch of ``rows``: :data:`YOUNG` when most of its bases joined during the
    run, else the growth law's region of its centroid's height (near bulges and away from them);
    ``labels`` is every base's patch, as ``rows`` number them."""
    z = np.array([r["z"] for r in rows], dtype=float)
    names = np.asarray(sim.growth.region(z), dtype=object).copy()
    if len(rows):
        counts = np.bincount(labels, minlength=int(labels.max(initial=-1)) + 1)
        share = np.bincount(labels, weights=joined_later(sim.state), minlength=counts.size) / np.maximum(counts, 1)
        names[share[np.array([r["patch"] for r in rows], dtype=np.int64)] > 0.5] = YOUNG
    return names


def region_summaries(sim, rows: list[dict], every: np.ndarray, labels: np.ndarray, shares: bool = True
                     ) -> dict[str, dict]:
    """Pattern statistics per region ``every`` (``trunk_regions``) of the trunk, each patch counted in
    its region (``patch_regions``).  With ``shares`` each region also has its bases (``n_bases``) and
    the largest share of them that one patch holds (``largest_patch_share``, fragments counted): near
    1 when the region has not come apart."""
    from bark.analysis.patches import pattern_summary

    names = patch_regions(sim, rows, labels)
    where = base_regions(sim) if shares else None
    out = {}
    for name in every:
        out[str(name)] = pattern_summary([r for r, n in zip(rows, names) if n == name])
        if shares:
            inside = labels[where == name]
            out[str(name)].update(n_bases=int(inside.size), largest_patch_share=largest_share(inside))
    return out


def window_summaries(sim, every: np.ndarray, min_size: int, window: float) -> dict[str, Any]:
    """Pattern statistics per region as photographs of the trunk would give them: patches cut at the
    borders of ``window``-sized windows (``bark.analysis.patches.window_labels``), each counted in the region
    of its centroid; and (``initial_trunk``, when bases joined during the run) the same over the
    patches of bases that were there from the start, the trunk whose growth the whole run stretched."""
    from bark.analysis.patches import patch_statistics, window_labels

    s = sim.state
    labels = window_labels(s.x, s.pairs, s.intact, window)
    rows = patch_statistics(s.x, labels, min_size)
    joined = joined_later(s)  # grew on the trunk the run began with
    initial = np.bincount(labels, weights=joined) == 0  # per window patch: none of its bases joined later
    old = [r for r in rows if initial[r["patch"]]] if joined.any() else None
    return {"window": window, "window_m": metres(window), "regions": region_summaries(sim, rows, every, labels, False),
            "initial_trunk": None if old is None else region_summaries(sim, old, every[every != YOUNG], labels, False)}


def network_summary(sim, min_size: int) -> dict | None:
    """The pattern's statistics beyond the paper's (``bark.analysis.network.measure``, as the network
    analyzer and ``bark analyze`` take them): its patch sizes, its crack network's junctions and their
    angles, the cracks' alignment and their bias to the lattice's springs — on the trunk unrolled at
    its mean radius; ``None`` for a lattice without two offsets."""
    from bark.analysis.network import measure

    if len(sim.lattice.offsets) != 2:
        return None
    s = sim.state
    return measure(s.x, sim.patch_labels(), min_size, s.pairs, s.intact, tuple(sim.lattice.offsets))


LAST_JOINED = 2000
"""Bases that joined last, on which summary.json's ``phyllotaxis.last_joined`` is measured."""


def _phyllotaxis(sim) -> dict | None:
    """The paper's checks of the leaf-base pattern (``bark.analysis.phyllotaxis``) on the whole trunk
    now, and as the bases crossed from the dome (``at_transition``): on the trunk of the start
    (``initial_trunk``) and on the last ``LAST_JOINED`` bases to join (``last_joined``, for a run in
    which bases joined), each at the radius and rise it joined at; ``None`` for a lattice without two
    spring offsets."""
    from bark.analysis.phyllotaxis import phyllotaxis
    from bark.model.tree import join_radii

    lattice, n = sim.lattice, sim.state.n_bases
    least = max(lattice.offsets) + sum(lattice.partition_offsets()) if len(lattice.offsets) == 2 else None
    if least is None or n <= least:
        return None
    s = sim.state
    radii, rise = join_radii(sim), sim.packing.rise_of(np.arange(n))
    out = phyllotaxis(lattice, s.anchor, radii, rise)
    sites = np.column_stack([radii[:, None] * s.anchor_dir, s.anchor[:, 2]])  # where each base joined, as it joined
    first = min(lattice.initial, n)
    groups = {"initial_trunk": slice(0, first), "last_joined": slice(max(first, n - LAST_JOINED), n)}
    out["at_transition"] = {name: phyllotaxis(lattice, sites[at], radii[at], rise[at]) if at.stop - at.start > least else None
                            for name, at in groups.items()}
    return out


def run_summary(sim, scene, analyses: dict, stop_reason: str | None, wall_time_s: float | None = None,
                extra: dict | None = None) -> dict[str, Any]:
    """Everything summary.json holds about a finished (or stopped) run; ``analyses`` from ``sim.analyze()``."""
    from bark.version import __version__

    measured = pattern_of(analyses.values())
    stats, rows = (measured.summary, measured.patches) if measured is not None else ({}, None)
    every = trunk_regions(sim) if rows is not None else None  # asked first: one region costs nothing more
    effects = scene.effects
    labels = sim.patch_labels() if rows is not None or "fracture" in effects else None
    return {
        "bark_version": __version__,
        "seed": sim.seed,
        "analyses": {name: a.summary for name, a in analyses.items()},
        "settings": scene.to_dict(),
        "effects": effects,
        "stop": {k: getattr(scene.run, k) for k in ("until_time", "until_radius", "until_patches", "min_patch_size")},
        "stop_reason": stop_reason,
        "final_state": (
            "last finite state: the step after it made the state NaN or infinite"
            if stop_reason == "non-finite" else "the state at the stop"
        ),
        "backend": sim.backend.name,
        "threads": getattr(sim.backend, "threads", 1),
        "dt": sim.numerics.dt,
        "h": sim.clock.h,
        "stability_limit": sim.stability_limit,
        "t": sim.state.t,
        "steps": sim.step_count,
        "radius": sim.radius,
        "n_bases": sim.state.n_bases,
        "n_springs": sim.state.n_springs,
        "n_broken": sim.n_broken,
        "n_patches": stats.get("n_patches", sim.patch_count(scene.run.min_patch_size) if "fracture" in effects else None),
        "largest_patch_share": largest_share(labels) if labels is not None else None,
        **{k: stats.get(k) for k in PATTERN_KEYS},
        "regions": region_summaries(sim, rows, every, labels) if every is not None else None,
        "windows": window_summaries(sim, every, scene.run.min_patch_size, scene.window) if every is not None else None,
        "phyllotaxis": _phyllotaxis(sim),
        "network": network_summary(sim, scene.run.min_patch_size) if rows is not None else None,
        "degenerate_events": [e for e in sim.events if e["kind"] == "degenerate"],
        **(extra or {}),
        "wall_time_s": wall_time_s,
        "conventions": "orientation: degrees from horizontal in [0, 180), 90 = along the trunk axis; "
        "horizontal = increasing theta seen from outside; anisotropy = 2A - 1",
    }


def write_run(sim, scene, out_dir: str | Path, stop_reason: str | None, wall_time_s: float | None = None,
              extra: dict | None = None, failed: list[str] | None = None, summary: bool = True) -> dict:
    """Write what the scene's effects ask for into ``out_dir``: summary.json and scene.toml always; patches.csv
    (patch-statistics), breaks.csv (break-log), state.npz (state-snapshot), graph.graphml (graphml),
    tree.vtu and tree.ply (mesh).  With ``failed`` given, a file the file system refuses is said
    there and the others are written (``attempt``); summary.json, written last, is then left out, so
    that the folder does not claim a complete run (``bark simulate --resume`` writes what is
    missing).  ``summary=False``: summary.json is the caller's to write, after what else it writes
    (the runner: after the pictures).  Returns the summary."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    analyses = sim.analyze()
    if scene.has("patch-statistics"):
        measured = pattern_of(analyses.values())
        rows = measured.patches if measured is not None else []
        from bark.analysis.pattern import patch_header
        attempt("patches.csv", lambda: write_csv(out / "patches.csv", rows, patch_columns(rows), patch_header(patch_columns(rows))), failed,
                (out / "patches.csv",))
    if scene.has("break-log"):
        log = sim.breaks
        attempt("breaks.csv", lambda: write_columns(out / "breaks.csv", {name: v.tolist() for name, v in log.arrays().items()},
                                                    headed(log.COLUMNS)), failed, (out / "breaks.csv",))
    s = sim.state
    if scene.has("state-snapshot"):
        attempt("state.npz", lambda: write_npz(  # stored, not deflated: float arrays shrink by ~10 % for seconds of work at a million bases
            out / "state.npz", compress=False,
            x=s.x, v=s.v, anchor=s.anchor, pairs=s.pairs.astype(np.int64), rest=s.rest, fmax=s.fmax, intact=s.intact,
            labels=sim.patch_labels(), t=np.float64(s.t), **{f"field_{d.name}": s[d.name] for d in s.declared},
        ), failed, (out / "state.npz",))
    if scene.has("graphml"):
        attempt("graph.graphml", lambda: write_graphml(out / "graph.graphml", sim), failed, (out / "graph.graphml",))
    if scene.has("mesh"):
        from bark.io.mesh import write_mesh

        leaves = scene.leaves if scene.has("leaves") else None
        attempt("tree.vtu, tree.ply", lambda: write_mesh(sim, out, scene.run.min_patch_size, leaves, scene.dome), failed,
                (out / "tree.vtu", out / "tree.ply"))
    for name, table, rows in analysis_tables(analyses):
        path = out / analysis_file(name, table)
        attempt(path.name, lambda path=path, rows=rows: write_csv(path, rows, list(rows[0]) if rows else []), failed,
                (path,))
    attempt("scene.toml", lambda: atomic_write(out / "scene.toml", lambda fh: fh.write(scene.to_toml().encode())),
            failed, (out / "scene.toml",))
    result = run_summary(sim, scene, analyses, stop_reason, wall_time_s, extra)
    if summary and not failed:
        attempt("summary.json", lambda: write_json(out / "summary.json", result), failed)
    return result


def analysis_file(analyzer: str, table: str) -> str:
    """The file of an analyzer's table: ``analysis-<analyzer>-<table>.csv``, each name's characters
    outside letters, digits, ``.``, ``_`` and ``-`` written ``-``."""
    return f"analysis-{_safe(analyzer)}-{_safe(table)}.csv"


def _safe(name: str) -> str:
    import re

    return re.sub(r"[^A-Za-z0-9._-]", "-", name)


def analysis_tables(analyses: dict):
    """``(analyzer, table, rows)`` of every table the analyses hold (``Analysis.tables``)."""
    return [(name, table, rows) for name, a in analyses.items() for table, rows in a.tables.items()]


def write_graphml(path: str | Path, sim) -> Path:
    """The leaf-base graph as GraphML, for networkx, Gephi, ParaView …, every spring an edge: nodes
    carry their site (``theta0_deg``, degrees in (−180, 180], and ``z0``), birth time, position now
    (x, y, z) and patch id; edges their spring id, rest length, threshold, whether ``intact`` and, for
    a broken one, when it broke and its tension then (``broke_t``, ``broke_tension``: NaN for an
    intact spring, or where the run kept no break log).  The leaf-base graph of record is the edges
    with ``intact`` true.  Lengths in model length units, times in time units, forces in force units."""
    import networkx as nx

    s, labels = sim.state, sim.patch_labels()
    theta0 = np.degrees(np.arctan2(s.anchor_dir[:, 1], s.anchor_dir[:, 0]))
    log = sim.breaks.arrays()
    when, tension = np.full(s.n_springs, np.nan), np.full(s.n_springs, np.nan)
    first = np.unique(log["spring"], return_index=True)[1]  # a spring breaks once; the log keeps its first
    when[log["spring"][first]], tension[log["spring"][first]] = log["t"][first], log["tension"][first]
    g = nx.Graph()
    g.add_nodes_from((int(q), {"theta0_deg": float(theta0[q]), "z0": float(s.anchor[q, 2]), "born": float(s.born[q]),
                                "x": float(s.x[q, 0]), "y": float(s.x[q, 1]), "z": float(s.x[q, 2]),
                                "patch": int(labels[q])}) for q in range(s.n_bases))
    g.add_edges_from((int(i), int(j), {"spring": k, "rest": float(s.rest[k]), "fmax": float(s.fmax[k]),
                                       "intact": bool(s.intact[k]), "broke_t": float(when[k]),
                                       "broke_tension": float(tension[k])})
                     for k, (i, j) in enumerate(s.pairs.tolist()))

    def write(fh):
        nx.write_graphml(g, fh)

    return atomic_write(path, write)

