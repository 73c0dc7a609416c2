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

__all__ = ["atomic_write", "write_csv", "write_json", "write_npz", "run_summary", "write_run"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _umask()


def atomic_write(path: str | Path, write: Callable[[io.BufferedWriter], None]) -> Path:
    """Call ``write(fh)`` on a temporary file beside ``path``, then move it onto ``path``."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the usual permissions
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_csv(path: str | Path, rows: list[dict[str, Any]], columns: list[str]) -> Path:
    def write(fh):
        text = io.TextIOWrapper(fh, encoding="utf-8", newline="")
        w = csv.DictWriter(text, fieldnames=columns, extrasaction="ignore")
        w.writeheader()
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


def write_npz(path: str | Path, **arrays: np.ndarray) -> Path:
    """``np.savez_compressed`` layout, but byte-for-byte reproducible: every member carries the same
    fixed timestamp, so two identical states give identical files (``cmp`` can compare runs)."""

    def write(fh):
        with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            for name, value in arrays.items():
                value = np.asanyarray(value)
                if not value.flags.c_contiguous:  # files are row-major whatever the layout in memory
                    value = np.ascontiguousarray(value)
                info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                with zf.open(info, "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, value, allow_pickle=False)

    return atomic_write(path, write)


PATCH_COLUMNS = ["patch", "size", "theta_deg", "z", "orientation_deg", "anisotropy", "lambda1", "lambda2"]


def run_summary(sim, scene, analyses: dict, stop_reason: str | None, wall_time_s: float | None = None) -> dict[str, Any]:
    """Everything summary.json holds about a finished (or stopped) run; ``analyses`` from ``sim.analyze()``."""
    from bark import __version__

    stats = next((a.summary for a in analyses.values() if "n_patches" in a.summary), {})
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
        "dt": sim.dt,
        "h": sim.h,
        "stability_limit": sim.stability_limit,
        "t": sim.state.t,
        "steps": sim.step_count,
        "radius": sim.radius,
        "n_bases": sim.state.n_bases,
        "n_springs": sim.state.n_springs,
        "n_broken": sim.n_broken,
        "n_patches": stats.get("n_patches", sim.patch_count(scene.run.min_patch_size) if "fracture" in effects else None),
        "mean_orientation_deg": stats.get("mean_orientation_deg"),
        "circular_sd_deg": stats.get("circular_sd_deg"),
        "mean_anisotropy": stats.get("mean_anisotropy"),
        "fraction_within_45_deg": stats.get("fraction_within_45_deg"),
        "degenerate_events": [e for e in sim.events if e["kind"] == "degenerate"],
        "wall_time_s": wall_time_s,
        "conventions": "orientation: degrees from horizontal in [0, 180), 90 = along the trunk axis; "
        "horizontal = increasing theta seen from outside; anisotropy = 2A - 1",
    }


def write_run(sim, scene, out_dir: str | Path, stop_reason: str | None, wall_time_s: float | None = None) -> dict:
    """Write what the scene's effects ask for into ``out_dir``: summary.json always; patches.csv
    (patch-statistics), breaks.csv (break-log), state.npz (state-snapshot), graph.graphml (graphml)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    analyses = sim.analyze()
    if scene.has("patch-statistics"):
        rows = next((a.tables["patches"] for a in analyses.values() if "patches" in a.tables), [])
        write_csv(out / "patches.csv", rows, PATCH_COLUMNS)
    if scene.has("break-log"):
        log = sim.breaks.arrays()
        write_csv(
            out / "breaks.csv",
            [dict(zip(log, vals)) for vals in zip(*(v.tolist() for v in log.values()))],
            list(log),
        )
    s = sim.state
    if scene.has("state-snapshot"):
        write_npz(
            out / "state.npz",
            x=s.x, v=s.v, anchor=s.anchor, pairs=s.pairs, rest=s.rest, fmax=s.fmax, intact=s.intact,
            labels=sim.patch_labels(), t=np.float64(s.t),
        )
    if scene.has("graphml"):
        write_graphml(out / "graph.graphml", sim)
    summary = run_summary(sim, scene, analyses, stop_reason, wall_time_s)
    write_json(out / "summary.json", summary)
    return summary


def write_graphml(path: str | Path, sim) -> Path:
    """The leaf-base graph of record (intact springs) as GraphML, for networkx, Gephi, ParaView …:
    nodes carry their initial site (theta0, z0), position now (x, y, z) and patch id; edges their
    spring id, rest length and threshold."""
    import networkx as nx

    g = sim.graph.copy()
    s, labels = sim.state, sim.patch_labels()
    for node, data in g.nodes(data=True):
        data.update(x=float(s.x[node, 0]), y=float(s.x[node, 1]), z=float(s.x[node, 2]), patch=int(labels[node]))
    for _, _, data in g.edges(data=True):
        data.update(rest=float(s.rest[data["spring"]]), fmax=float(s.fmax[data["spring"]]))

    def write(fh):
        nx.write_graphml(g, fh)

    return atomic_write(path, write)


SERIES_COLUMNS = ["t", "radius", "step", "n_broken", "n_patches", "mean_orientation_deg", "circular_sd_deg",
                  "mean_anisotropy", "fraction_within_45_deg"]


class StatisticsSeries:
    """The patch statistics along a run: an action for ``Simulation.add_action`` (on a trigger, e.g.
    ``Every(series_every)``) that runs the simulation's analyzers and keeps one row per call."""

    def __init__(self) -> None:
        self.rows: list[dict[str, Any]] = []

    def record(self, sim) -> None:
        if self.rows and self.rows[-1]["step"] == sim.step_count:
            return
        stats = next((a.summary for a in sim.analyze().values() if "n_patches" in a.summary), {})
        self.rows.append({"t": sim.state.t, "radius": sim.radius, "step": sim.step_count, "n_broken": sim.n_broken,
                          **{k: stats.get(k) for k in SERIES_COLUMNS[4:]}})

    def write(self, path: str | Path) -> Path:
        return write_csv(path, self.rows, SERIES_COLUMNS)
