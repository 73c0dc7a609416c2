"""Writing a run's results: atomically, without plotting, readable without pickle.

Every file is written to a temporary name in the same folder and moved into place with
``os.replace``, so a reader (or a crash) never sees half a file.  Files of one run:

* ``patches.csv`` — one row per patch of ≥ min_size bases (from the patch analyzer).
* ``breaks.csv`` — the break log: spring, i, j, step, t, tension, in the order of breaking.
* ``summary.json`` — every setting, the seed, bark's version, the stop condition and why the run
  stopped, t and radius at the end, counts and pattern statistics, degenerate events.
* ``state.npz`` — the mechanical state at the end (x, v, anchor, pairs, rest, fmax, intact, patch
  labels, t); ``np.load(path)`` reads it with ``allow_pickle=False``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np

from bark.units import metres

__all__ = ["atomic_write", "write_csv", "write_columns", "write_json", "write_npz", "run_summary", "write_run"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _umask()


TMP_SUFFIX = ".tmp"


def temp_name_prefix(name: str) -> str:
    """The prefix of the temporary files :func:`atomic_write` makes for a file called ``name``."""
    return f".{name}."


def atomic_write(path: str | Path, write: Callable[[io.BufferedWriter], None], *,
                 verify: Callable[[Path], None] | None = None, keep: str | Path | None = None,
                 by_name: bool = False) -> Path:
    """Call ``write(fh)`` on a temporary file beside ``path``, then move it onto ``path``.

    ``by_name``: ``write`` is given the temporary file's path instead (for writers that open files
    themselves, like meshio's VTU writer).  ``verify(tmp)``, if given, is called on the written
    temporary file before it replaces anything (it raises to refuse it).  ``keep``, if given, is where
    the file being replaced goes (moved, not copied), so that the previous version survives until the
    new one is whole and verified."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=temp_name_prefix(path.name), suffix=TMP_SUFFIX, dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the usual permissions
        if by_name:
            os.close(fd)
            write(Path(tmp))
            fd = os.open(tmp, os.O_RDONLY)
        with os.fdopen(fd, "rb" if by_name else "wb") as fh:
            if not by_name:
                write(fh)
                fh.flush()
            os.fsync(fh.fileno())
        if verify is not None:
            verify(Path(tmp))
        if keep is not None and path.exists():
            os.replace(path, keep)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _sync_folder(path.parent)
    return path


def _sync_folder(folder: Path) -> None:
    """Make the renames in ``folder`` durable (a crash after this keeps them)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_csv(path: str | Path, rows: list[dict[str, Any]], columns: list[str]) -> Path:
    """A CSV of ``rows`` (dicts; keys not in ``columns`` left out, missing ones empty)."""
    return _write_rows(path, columns, ([row.get(c, "") for c in columns] for row in rows))


def write_columns(path: str | Path, columns: dict[str, list]) -> Path:
    """A CSV of equal-length ``columns`` (name: values), as :func:`write_csv` writes the same rows,
    with no dict made per row (a break log has tens of thousands)."""
    return _write_rows(path, list(columns), zip(*columns.values()))


def _write_rows(path: str | Path, header: list[str], rows) -> Path:
    def write(fh):
        text = io.TextIOWrapper(fh, encoding="utf-8", newline="")
        w = csv.writer(text)
        w.writerow(header)
        w.writerows(rows)
        text.flush()
        text.detach()

    return atomic_write(path, write)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(path: str | Path, obj: Any) -> Path:
    data = json.dumps(_jsonable(obj), indent=2, allow_nan=False).encode() + b"\n"
    return atomic_write(path, lambda fh: fh.write(data))


def _fast_deflate(info: zipfile.ZipInfo) -> None:
    """Deflate level 1: on float arrays about as small as the default level 6 and 1.7x faster
    (measured at 2 million bases), which is what a large run's final write waits on."""
    if hasattr(info, "compress_level"):  # Python >= 3.13
        info.compress_level = 1
    else:
        info._compresslevel = 1


def write_npz(path: str | Path, *, compress: bool = True, verify=None, keep=None, **arrays: np.ndarray) -> Path:
    """``np.savez_compressed`` layout (``compress=False``: ``np.savez``'s), but byte-for-byte
    reproducible: every member carries the same fixed timestamp, so two identical states give
    identical files (``cmp`` can compare runs).  ``verify`` and ``keep`` as in :func:`atomic_write`."""
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED

    def write(fh):
        with zipfile.ZipFile(fh, "w", compression=method) as zf:
            for name, value in arrays.items():
                value = np.asanyarray(value)
                if not value.flags.c_contiguous:  # files are row-major whatever the layout in memory
                    value = np.ascontiguousarray(value)
                info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = method
                _fast_deflate(info)
                with zf.open(info, "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, value, allow_pickle=False)

    return atomic_write(path, write, verify=verify, keep=keep)


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
"""The pattern statistics summary.json takes from the analyzer's summary (``bark.analysis.pattern_summary``)."""


def trunk_regions(sim) -> np.ndarray | None:
    """The names of the trunk's regions (``Growth.region`` of every base's site), or ``None`` when it
    has one region."""
    every = np.unique(sim.growth.region(sim.state.anchor[:, 2]))
    return every if len(every) >= 2 else None


def region_summaries(sim, rows: list[dict], every: np.ndarray) -> dict[str, dict]:
    """Pattern statistics per region ``every`` (``trunk_regions``) of the trunk: each patch counted
    in the region of its centroid's height (near bulges and away from them)."""
    from bark.analysis import pattern_summary

    names = sim.growth.region(np.array([r["z"] for r in rows], dtype=float))
    return {str(name): pattern_summary([r for r, n in zip(rows, names) if n == name]) for name in every}


def window_summaries(sim, every: np.ndarray, min_size: int, window: float) -> dict[str, Any]:
    """Pattern statistics per region as photographs of the trunk would give them: patches cut at the
    borders of ``window``-sized windows (``bark.analysis.window_labels``), each counted in the region
    of its centroid; and (``initial_trunk``, when bases joined during the run) the same over the
    patches of bases that were there from the start, the trunk whose growth the whole run stretched."""
    from bark.analysis import patch_statistics, window_labels

    s = sim.state
    labels = window_labels(s.x, s.pairs, s.intact, window)
    rows = patch_statistics(s.x, labels, min_size)
    joined = s.born > s.born.min()  # grew on the trunk the run began with
    initial = np.bincount(labels, weights=joined) == 0  # per window patch: none of its bases joined later
    old = [r for r in rows if initial[r["patch"]]] if joined.any() else None
    return {"window": window, "window_m": metres(window), "regions": region_summaries(sim, rows, every),
            "initial_trunk": None if old is None else region_summaries(sim, old, every)}


def _phyllotaxis(sim) -> dict | None:
    """The paper's checks of the leaf-base pattern now (``bark.tree.phyllotaxis``), or ``None`` for a
    lattice without two spring offsets."""
    from bark.tree import join_radii, phyllotaxis

    if len(sim.lattice.offsets) != 2 or sim.state.n_bases <= max(sim.lattice.offsets) + sum(sim.lattice.partition_offsets()):
        return None
    return phyllotaxis(sim.lattice, sim.state.anchor, join_radii(sim))


def run_summary(sim, scene, analyses: dict, stop_reason: str | None, wall_time_s: float | None = None,
                extra: dict | None = None) -> dict[str, Any]:
    """Everything summary.json holds about a finished (or stopped) run; ``analyses`` from ``sim.analyze()``."""
    from bark import __version__

    stats = next((a.summary for a in analyses.values() if "n_patches" in a.summary), {})
    rows = next((a.tables["patches"] for a in analyses.values() if "patches" in a.tables), None)
    every = trunk_regions(sim) if rows is not None else None  # asked first: one region costs nothing more
    effects = scene.effects
    return {
        "bark_version": __version__,
        "seed": sim.seed,
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
        **{k: stats.get(k) for k in PATTERN_KEYS},
        "regions": region_summaries(sim, rows, every) if every is not None else None,
        "windows": window_summaries(sim, every, scene.run.min_patch_size, scene.window) if every is not None else None,
        "phyllotaxis": _phyllotaxis(sim),
        "degenerate_events": [e for e in sim.events if e["kind"] == "degenerate"],
        **(extra or {}),
        "wall_time_s": wall_time_s,
        "conventions": "orientation: degrees from horizontal in [0, 180), 90 = along the trunk axis; "
        "horizontal = increasing theta seen from outside; anisotropy = 2A - 1",
    }


def write_run(sim, scene, out_dir: str | Path, stop_reason: str | None, wall_time_s: float | None = None,
              extra: dict | None = None) -> dict:
    """Write what the scene's effects ask for into ``out_dir``: summary.json always; patches.csv
    (patch-statistics), breaks.csv (break-log), state.npz (state-snapshot), graph.graphml (graphml),
    tree.vtu and tree.ply (mesh)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    analyses = sim.analyze()
    if scene.has("patch-statistics"):
        rows = next((a.tables["patches"] for a in analyses.values() if "patches" in a.tables), [])
        write_csv(out / "patches.csv", rows, patch_columns(rows))
    if scene.has("break-log"):
        write_columns(out / "breaks.csv", {name: v.tolist() for name, v in sim.breaks.arrays().items()})
    s = sim.state
    if scene.has("state-snapshot"):
        write_npz(  # stored, not deflated: float arrays shrink by ~10 % for seconds of work at a million bases
            out / "state.npz", compress=False,
            x=s.x, v=s.v, anchor=s.anchor, pairs=s.pairs.astype(np.int64), rest=s.rest, fmax=s.fmax, intact=s.intact,
            labels=sim.patch_labels(), t=np.float64(s.t),
        )
    if scene.has("graphml"):
        write_graphml(out / "graph.graphml", sim)
    if scene.has("mesh"):
        from bark.mesh import write_mesh

        write_mesh(sim, out, scene.run.min_patch_size)
    summary = run_summary(sim, scene, analyses, stop_reason, wall_time_s, extra)
    write_json(out / "summary.json", summary)
    return summary


def write_graphml(path: str | Path, sim) -> Path:
    """The leaf-base graph of record (intact springs) as GraphML, for networkx, Gephi, ParaView …:
    nodes carry their site (theta0 in (−π, π], z0), birth time, position now (x, y, z) and patch id;
    edges their spring id, rest length and threshold (all read from the state's arrays)."""
    import networkx as nx

    s, labels = sim.state, sim.patch_labels()
    theta0 = np.arctan2(s.anchor_dir[:, 1], s.anchor_dir[:, 0])
    g = nx.Graph()
    g.add_nodes_from((int(q), {"theta0": float(theta0[q]), "z0": float(s.anchor[q, 2]), "born": float(s.born[q]),
                                "x": float(s.x[q, 0]), "y": float(s.x[q, 1]), "z": float(s.x[q, 2]),
                                "patch": int(labels[q])}) for q in sim.graph.nodes)
    spring = {tuple(p): k for k, p in enumerate(s.pairs.tolist())}
    g.add_edges_from((i, j, {"spring": spring[(i, j)], "rest": float(s.rest[spring[(i, j)]]),
                             "fmax": float(s.fmax[spring[(i, j)]])})
                     for i, j in (sorted(e) for e in sim.graph.edges))

    def write(fh):
        nx.write_graphml(g, fh)

    return atomic_write(path, write)


SERIES_COLUMNS = ["t", "radius", "step", "n_broken", "n_patches", "mean_orientation_deg", "circular_sd_deg",
                  "mean_anisotropy", "fraction_within_45_deg"]


class Recorder:
    """What a run records along the way: an action for ``Simulation.add_action`` (on a trigger, e.g.
    ``Every(series_every)``) whose ``record(sim)`` keeps a sample; ``arrays``/``load`` carry the samples
    through a checkpoint (under ``name``), so a resumed run's record is whole.  At the run's end
    ``finish`` makes what is made of them, ``write`` puts them in the run's file ``file`` (if any),
    and ``summary`` is what they add to summary.json."""

    name = ""
    file: str | None = None

    def finish(self, sim, min_size: int) -> None:
        """At the end of the run, after its last sample (``min_size``: the smallest patch that counts)."""

    def summary(self) -> dict:
        return {}


class StatisticsSeries(Recorder):
    """The patch statistics along a run: the simulation's analyzers run, one row a call."""

    name = "series"
    file = "statistics.csv"

    def __init__(self) -> None:
        self.rows: list[dict[str, Any]] = []

    def record(self, sim) -> None:
        if self.rows and self.rows[-1]["step"] == sim.step_count:
            return
        stats = next((a.summary for a in sim.analyze().values() if "n_patches" in a.summary), {})
        self.rows.append({"t": sim.state.t, "radius": sim.radius, "step": sim.step_count, "n_broken": sim.n_broken,
                          **{k: stats.get(k) for k in SERIES_COLUMNS[4:]}})

    def arrays(self) -> dict[str, np.ndarray]:
        return {c: np.array([np.nan if r[c] is None else r[c] for r in self.rows], dtype=float) for c in SERIES_COLUMNS}

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        ints = ("step", "n_broken", "n_patches")
        cols = [[int(v) if c in ints and np.isfinite(v) else (None if not np.isfinite(v) else float(v))
                 for v in arrays[c].tolist()] for c in SERIES_COLUMNS]
        self.rows = [dict(zip(SERIES_COLUMNS, vals)) for vals in zip(*cols)]

    def write(self, path: str | Path) -> Path:
        return write_csv(path, self.rows, SERIES_COLUMNS)


class Frames(Recorder):
    """Frames of the unwrapped pattern along a run, for the development animation: per call, the time,
    the mean radius, each base's unwrapped position (float32) and patch label (int32).  Drawing them
    is the CLI's (``bark_cli.animation``)."""

    name = "frames"

    def __init__(self) -> None:
        self.frames: list[tuple[float, float, np.ndarray, np.ndarray]] = []

    def record(self, sim) -> None:
        if self.frames and self.frames[-1][0] == sim.state.t:
            return
        r = sim.radius
        self.frames.append((sim.state.t, r, unwrap(sim.state.x, r).astype(np.float32), sim.patch_labels().astype(np.int32)))

    def arrays(self) -> dict[str, np.ndarray]:
        f = self.frames
        return {
            "t": np.array([x[0] for x in f], dtype=float), "r": np.array([x[1] for x in f], dtype=float),
            "count": np.array([x[2].shape[0] for x in f], dtype=np.int64),
            "uv": np.concatenate([x[2] for x in f]) if f else np.empty((0, 2), np.float32),
            "labels": np.concatenate([x[3] for x in f]) if f else np.empty(0, np.int32),
        }

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        ends = np.cumsum(arrays["count"])
        starts = ends - arrays["count"]
        self.frames = [(float(t), float(r), arrays["uv"][a:b], arrays["labels"][a:b])
                       for t, r, a, b in zip(arrays["t"], arrays["r"], starts, ends)]


def unwrap(x: np.ndarray, radius: float) -> np.ndarray:
    """``(arc length, height)`` of 3-D points on the trunk, arc length ``r·θ`` in ``[0, 2πr)`` with θ
    increasing to the right as seen from outside the trunk (bark's convention)."""
    theta = np.mod(np.arctan2(x[:, 1], x[:, 0]), 2 * np.pi)
    return np.column_stack([radius * theta, x[:, 2]])
