"""Parameter sweeps: a grid over scene settings, one run per point and seed, each result committed
to an SQLite table the moment it arrives::

    from bark.studies.sweep import Axis, Sweep, run_sweep
    sweep = Sweep(base=read_toml("reticulate"),
                  axes=(Axis("growth.G", (0.007, 0.011, 0.014)), Axis("mechanics.f_max", (0.0028, 0.005, 0.008))),
                  seeds=(0, 1))
    run_sweep(sweep, "sweep.sqlite", workers=2)           # or client=distributed.Client(address)

**One table** (``runs`` in the database file; ``sqlite3`` from the standard library, read by pandas
``read_sql("select * from runs", con)`` or any SQL client): a row per run — its key, point and seed,
a column per swept setting (named like ``growth.G``), the end state and the pattern statistics
(``bark.analysis.pattern``), the stop reason, the wall time, the full scene as JSON.  A second table,
``patterns``, holds each run's final pattern (unwrapped positions and patch labels, for montages).

**Resumable**: a run's key is a digest of its full scene and seed.  Its rows in both tables are
written in one transaction, so a run is in the database whole or not at all; a rerun of the same
sweep skips every key already there.  A worker or a sweep killed at any moment loses only the runs
in flight.

**Where runs go**: local worker processes (``workers``), or a Dask distributed cluster (``client``, an
existing ``distributed.Client``: Dask schedules, bark only submits ``run_point`` and commits what
comes back).  A run is a pure function of its scene and seed, so both give the same table.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import hashlib
import itertools
import json
import math
import sqlite3
import time
import warnings
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import attrs
import numpy as np

from bark.errors import BarkError, BarkWarning, Ref
from bark.io.files import json_text
from bark.io.output import PATTERN_KEYS
from bark.studies.pool import LocalPool, WorkerDied

__all__ = ["WorkerDied", "Axis", "Sweep", "Point", "SweepTable", "run_point", "run_sweep", "check_fits", "FIG9_AXES", "RESULT_COLUMNS"]

FIG9_AXES = (("growth.G", (0.007, 0.011, 0.014)), ("mechanics.f_max", (0.0028, 0.005, 0.008)))
"""The paper's Fig. 9 grid: G across (columns), f_max up (rows), Table 2's three values each."""

IDENTITY = ("key", "point", "seed", "scene")
"""The columns that make a ``runs`` table a sweep's (the others are added as bark grows)."""
RESULT_COLUMNS = {
    "n_bases": "INTEGER", "t": "REAL", "radius": "REAL", "steps": "INTEGER", "n_broken": "INTEGER",
    "n_patches": "INTEGER", "largest_patch_share": "REAL", **dict.fromkeys(PATTERN_KEYS, "REAL"), "stop_reason": "TEXT", "first_break_t": "REAL",
    "initial_fractures": "INTEGER", "dissipation_rate": "REAL", "growth_dissipation": "REAL", "regions": "TEXT",
    "size_mean": "REAL", "powerlaw_alpha": "REAL", "lognormal_mu": "REAL", "lognormal_sigma": "REAL",
    "size_favoured": "TEXT", "n_bar": "REAL", "v_bar": "REAL", "t_fraction": "REAL", "nematic_order": "REAL",
    "crack_director_deg": "REAL",
}
"""What the table holds of each run besides its identity, by SQLite type: the keys of the run's
summary (summary.json) of these names, of its ``fracture`` part (the ``fracture-history`` effect;
else empty) and of its ``network`` part (the statistics beyond the paper's); ``regions`` is
summary.json's per-region statistics as JSON text (none for a trunk without regions), read in SQL
by ``json_extract(regions, '$.straight.circular_sd_deg')``."""


MAX_RUNS = 1_000_000
"""Most runs one sweep (one table) may hold: every point is checked before the first runs, and a
million runs of even a second are eleven days of one core."""


@attrs.frozen
class Axis:
    """One swept setting: ``key`` is ``section.name`` as in ``--set`` (``growth.G``), ``values`` its values.
    The name may reach into a table or an array of tables, a dotted part each, arrays indexed from 0:
    ``breaker.regions.bulge``, ``growth.bulges.0.magnitude`` (the first bulge's)."""

    key: str
    values: tuple = attrs.field(converter=tuple)

    def __attrs_post_init__(self) -> None:
        section, dot, name = self.key.partition(".")
        if not dot or not section or not name:
            raise BarkError(f"sweep axis {self.key!r}: expected SECTION.KEY, e.g. growth.G")
        if not self.values:
            raise BarkError(f"sweep axis {self.key}: no values")

    @property
    def section(self) -> str:
        """The scene section the axis sets (``mechanics`` of ``mechanics.c``)."""
        return self.key.partition(".")[0]

    @property
    def name(self) -> str:
        """The key within that section (``c`` of ``mechanics.c``)."""
        return self.key.partition(".")[2]


@attrs.frozen
class Point:
    """One run of a sweep: where on the grid (``index``, one per axis), its settings, its seed, and
    the key that identifies it in the table."""

    index: tuple[int, ...]
    settings: dict
    seed: int
    scene: dict
    key: str
    checked: object = attrs.field(default=None, eq=False, repr=False)
    """The scene, validated (``Scene.from_dict``) when the point was made: what its checks ask."""


def _quoted(name: str) -> str:
    """A column name as SQL takes it (``"growth.G"``)."""
    return '"' + name.replace('"', '""') + '"'


def _canonical(obj) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=True)


@attrs.frozen
class Sweep:
    """A grid (the product of ``axes``) over the scene ``base`` (a scene dict, as ``read_toml``
    gives it), each point run once per seed — or, ``listed``, the points the axes' values give side
    by side (the k-th point takes each axis' k-th value: a list of points, a random or Latin-hypercube
    design, :func:`design`)."""

    base: dict
    axes: tuple[Axis, ...] = attrs.field(converter=tuple)
    seeds: tuple[int, ...] = attrs.field(default=(0,), converter=tuple)
    listed: bool = False
    """The axes' values are the points, side by side (all of one length), not a grid's."""

    def __attrs_post_init__(self) -> None:
        keys = [a.key for a in self.axes]
        if len(set(keys)) != len(keys):
            raise BarkError(f"sweep: an axis is given twice ({', '.join(keys)})")
        if self.listed and len({len(a.values) for a in self.axes}) > 1:
            raise BarkError("sweep: a list of points gives every setting a value at every point")
        for a in () if self.listed else self.axes:  # a grid's axis: each value once (a list may repeat one)
            if len(set(map(repr, a.values))) != len(a.values):
                raise BarkError(f"sweep axis {a.key}: a value is given twice")
        if "run.seed" in keys:
            raise BarkError("sweep: seeds are not an axis; give them as the sweep's seeds")
        if not self.seeds or len(set(self.seeds)) != len(self.seeds):
            raise BarkError("sweep: the seeds must be distinct, and at least one")
        runs = self.runs
        if runs > MAX_RUNS:
            raise BarkError(f"sweep: {runs:,} runs ({' × '.join(map(str, self.shape))} points × {len(self.seeds)} "
                            f"seed{'s' if len(self.seeds) > 1 else ''}); at most {MAX_RUNS:,} in one table: split "
                            "the grid into several sweeps")

    @property
    def shape(self) -> tuple[int, ...]:
        """The grid's shape; a list of points has one dimension, its length."""
        return (len(self.axes[0].values) if self.axes else 1,) if self.listed else tuple(len(a.values) for a in self.axes)

    @property
    def runs(self) -> int:
        """How many runs the sweep is: its points times its seeds (known before any is built)."""
        return math.prod(self.shape) * len(self.seeds)

    def points(self) -> list[Point]:
        """Every run, grid point by grid point (the first axis slowest), seeds innermost; each scene
        checked (``Scene.from_dict``) so a bad value stops the sweep before any run.  Built once a
        sweep (a few ms a point), however often asked."""
        return list(self._points)

    @functools.cached_property
    def _points(self) -> tuple[Point, ...]:
        from bark.engine.scene import Scene, merge

        out = []
        for index in itertools.product(*(range(n) for n in self.shape)):
            at = [index[0]] * len(self.axes) if self.listed else index  # each axis' value of this point
            settings = {a.key: a.values[i] for a, i in zip(self.axes, at)}
            overrides: dict = {}
            for a, i in zip(self.axes, at):
                if "." not in a.name:
                    overrides.setdefault(a.section, {})[a.name] = a.values[i]
            here = merge(self.base, overrides)
            for a, i in zip(self.axes, at):
                if "." in a.name:  # a key inside a table or an array of tables: growth.bulges.0.magnitude
                    _put(here, a, a.values[i])
            for seed in self.seeds:
                scene = merge(here, {"run": {"seed": seed}})
                checked = Scene.from_dict(scene)  # a bad value: one line, before anything runs
                key = hashlib.sha256(_canonical({"scene": scene, "seed": seed}).encode()).hexdigest()[:20]
                out.append(Point(index=index, settings=settings, seed=seed, scene=scene, key=key, checked=checked))
        return tuple(out)


def _put(scene: dict, axis: Axis, value) -> None:
    """``value`` set at ``axis``'s path in ``scene`` (changed in place): each dotted part after the
    section names a key of a table, or the index (from 0) of an element of an array of tables.  A
    table on the way that is not there is made; an element that is not there is refused in one line."""
    parts = axis.name.split(".")
    where = scene.setdefault(axis.section, {})
    for depth, part in enumerate(parts[:-1]):
        if isinstance(where, list):
            if not part.isdigit() or int(part) >= len(where):
                raise BarkError(f"sweep axis {axis.key}: {'.'.join([axis.section, *parts[:depth]])} is an array of "
                                f"{len(where)} table{'s' if len(where) != 1 else ''}; give an index from 0 to {len(where) - 1}")
            where = where[int(part)]
        elif isinstance(where, dict):
            where = where.setdefault(part, {})
        else:
            raise BarkError(f"sweep axis {axis.key}: {'.'.join([axis.section, *parts[:depth]])} is a value, not a table")
    if not isinstance(where, dict):
        raise BarkError(f"sweep axis {axis.key}: {'.'.join([axis.section, *parts[:-1]])} is not a table")
    where[parts[-1]] = value


DESIGNS = ("random", "lhs")
"""Designs of sampled points (:func:`design`): uniform random, and Latin hypercube."""


def design(kind: str, ranges: dict[str, tuple[float, float, bool]], n: int, seed: int = 0) -> tuple[Axis, ...]:
    """``n`` points drawn in ``ranges`` (a scene key → ``(low, high, log)``; ``log``: uniform in the
    logarithm), by ``kind``: ``random`` (independent uniform draws) or ``lhs`` (a Latin hypercube,
    ``scipy.stats.qmc``: each range cut in ``n`` equal strata, one point in each), from ``seed`` —
    as the axes of a listed :class:`Sweep`.  Values to 12 digits, as a scene file would hold them."""
    from scipy.stats import qmc

    if kind not in DESIGNS:
        raise BarkError(f"design {kind!r}: one of {', '.join(DESIGNS)}")
    keys = list(ranges)
    unit = (qmc.LatinHypercube(d=len(keys), seed=seed).random(n) if kind == "lhs"
            else np.random.default_rng(seed).random((n, len(keys))))
    axes = []
    for j, key in enumerate(keys):
        lo, hi, log = ranges[key]
        values = np.exp(np.log(lo) + unit[:, j] * (np.log(hi) - np.log(lo))) if log else lo + unit[:, j] * (hi - lo)
        axes.append(Axis(key, tuple(float(f"{v:.12g}") for v in values)))
    return tuple(axes)


def run_point(scene: dict, key: str, folder: str | None = None) -> dict[str, Any]:
    """Run one point (in whatever process: a local worker or a Dask worker) and return its row and
    its final pattern.  Pure: the same scene gives the same row, wherever it runs.  With ``folder``
    the run also writes its outputs there, as ``bark simulate --out folder`` would (pictures drawn
    in the worker)."""
    from bark.engine import kernels
    from bark.studies import runner
    from bark.units import unwrap
    from bark.analysis.pattern import simulation_colours
    from bark.engine.scene import Scene

    kernels.expect_many()  # a worker's runs (local or Dask) share its kernels' compile
    sc = Scene.from_dict(scene)
    start = time.perf_counter()
    outcome = runner.run(sc, folder, overwrite=True, checkpoint_every=0) if folder is not None else runner.run(sc, None)
    wall = time.perf_counter() - start
    sim = outcome.sim
    found = {**outcome.summary, **(outcome.summary.get("fracture") or {}),  # fracture: with the fracture-history effect
             **(outcome.summary.get("network") or {})}
    row = {k: found.get(k) for k in RESULT_COLUMNS}  # the run's own summary: its analyzer's statistics
    row["regions"] = json_text(row["regions"]) if row["regions"] is not None else None
    return {"key": key, "row": row, "wall_s": wall, "uv": unwrap(sim.state.x, sim.radius).astype(np.float32),
            "labels": sim.patch_labels().astype(np.int32), "colours": simulation_colours(sim, sc.run.min_patch_size)}


_FULL = ("SQLITE_FULL", "SQLITE_IOERR")
"""SQLite's words for a file system that refuses to write (a full disk or quota, a file-size limit)."""


def _table_error(path: Path, err: sqlite3.DatabaseError) -> Exception:
    """What SQLite's ``err`` means for the sweep table at ``path``: a file system that refused to
    write (an ``OSError``, status 1: the rows committed stay, the same command goes on later), or a
    file that is not a sweep table, or is damaged (a one-line ``BarkError``)."""
    name = getattr(err, "sqlite_errorname", "") or ""
    if name.startswith(_FULL):
        return OSError(errno.ENOSPC, f"could not be written ({err}); the runs committed stay, and the same "
                       "command goes on once there is room", str(path))
    return BarkError(f"{path}: not a sweep database, or a damaged one ({err})")


class SweepTable:
    """The sweep's SQLite file: ``runs`` (a row per finished run) and ``patterns``."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        new = not self.path.exists()
        try:
            self.con = sqlite3.connect(self.path, timeout=60.0)
            self.con.execute("PRAGMA journal_mode=WAL")  # readers (pandas, a second look) never block a commit
            self.con.execute("PRAGMA synchronous=FULL")  # a committed run survives a power cut
            self._check_ours()  # before anything is added to another program's tables
            with self.con:
                self.con.execute(
                    "CREATE TABLE IF NOT EXISTS runs (key TEXT PRIMARY KEY, point TEXT NOT NULL, seed INTEGER NOT NULL, "
                    + ", ".join(f"{c} {t}" for c, t in RESULT_COLUMNS.items())
                    + ", wall_s REAL, finished TEXT, bark_version TEXT, scene TEXT NOT NULL)")
                self.con.execute("CREATE TABLE IF NOT EXISTS patterns (key TEXT PRIMARY KEY REFERENCES runs(key), "
                                 "n INTEGER NOT NULL, uv BLOB NOT NULL, labels BLOB NOT NULL, colours BLOB NOT NULL)")
                self._add_columns(RESULT_COLUMNS)  # a table of an earlier bark: the columns added since
        except sqlite3.DatabaseError as err:
            if new:  # what this call began to make: nothing of it is left
                for part in ("", "-wal", "-shm", "-journal"):
                    Path(f"{self.path}{part}").unlink(missing_ok=True)
            raise _table_error(self.path, err) from None

    def _check_ours(self) -> None:
        """Refuse, in one line and before changing it, a database whose ``runs`` or ``patterns`` table
        is not a sweep's (another program's tables of those names)."""
        for table, needed in (("runs", IDENTITY), ("patterns", ("key", "n", "uv", "labels", "colours"))):
            have = {r[1] for r in self.con.execute(f"PRAGMA table_info({table})")}
            if have and not set(needed) <= have:
                lacking = ", ".join(c for c in needed if c not in have)
                self.con.close()
                raise BarkError(f"{self.path}: not a sweep database: its {table!r} table is another's (it has no "
                                f"{lacking}); give the sweep a folder of its own")

    def _read(self, sql: str, args: tuple = ()) -> list[tuple]:
        """The rows of a query; a damaged file is one line (``_table_error``)."""
        try:
            return self.con.execute(sql, args).fetchall()
        except sqlite3.DatabaseError as err:
            raise _table_error(self.path, err) from None

    def close(self) -> None:
        """Close the table's database."""
        self.con.close()

    def __enter__(self) -> "SweepTable":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def columns(self) -> list[str]:
        """The columns of the runs table, in order."""
        return [r[1] for r in self._read("PRAGMA table_info(runs)")]

    def add_axes(self, axes: Iterable[Axis]) -> None:
        """A column per swept setting (``"growth.G"``), added to an older table as needed."""
        with self.con:
            self._add_columns({a.key: "" for a in axes})

    def _add_columns(self, columns: dict[str, str]) -> None:
        """The columns (name: SQLite type, or none) the table lacks, added."""
        have = set(self.columns())
        for name, kind in columns.items():
            if name not in have:
                self.con.execute(f'ALTER TABLE runs ADD COLUMN "{name}" {kind}')

    def done(self) -> set[str]:
        """The keys of the runs already in the table (a resumed sweep skips them)."""
        return {k for (k,) in self._read("SELECT key FROM runs")}

    def commit(self, point: Point, result: dict) -> None:
        """The run's row and its pattern, in one transaction: whole, or not at all."""
        from bark.version import __version__

        row = {"key": point.key, "point": _canonical(point.settings), "seed": point.seed, **result["row"],
               "wall_s": result["wall_s"], "finished": time.strftime("%Y-%m-%dT%H:%M:%S"),
               "bark_version": __version__, "scene": _canonical(point.scene), **point.settings}
        row = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()}
        names = ", ".join(f'"{k}"' for k in row)
        try:
            self._insert(names, row, point, result)
        except sqlite3.DatabaseError as err:  # the transaction is rolled back: the table is as it was
            raise _table_error(self.path, err) from None

    def _insert(self, names: str, row: dict, point: Point, result: dict) -> None:
        with self.con:
            self.con.execute(f"INSERT OR REPLACE INTO runs ({names}) VALUES ({', '.join('?' * len(row))})",
                             list(row.values()))
            self.con.execute("INSERT OR REPLACE INTO patterns VALUES (?, ?, ?, ?, ?)",
                             (point.key, int(result["labels"].shape[0]), result["uv"].tobytes(), result["labels"].tobytes(),
                              np.ascontiguousarray(result["colours"], dtype=np.uint8).tobytes()))

    def rows(self, keys: Sequence[str] | None = None) -> list[dict]:
        """The table's rows as dicts (those of ``keys`` in that order, else all, by key)."""
        names = self.columns()
        rows = {r[names.index("key")]: self._checked(dict(zip(names, r)))
                for r in self._read(f"SELECT {', '.join(_quoted(n) for n in names)} FROM runs ORDER BY key")}
        return [rows[k] for k in keys if k in rows] if keys is not None else list(rows.values())

    def _checked(self, row: dict) -> dict:
        """A row whose result columns hold what bark writes there (numbers, or none), or one line
        naming the first that does not: a table edited by hand or by another program."""
        for name, kind in RESULT_COLUMNS.items():
            value = row.get(name)
            if kind in ("INTEGER", "REAL") and value is not None and (isinstance(value, (str, bytes)) or isinstance(value, bool)):
                raise BarkError(f"{self.path}: run {row.get('key')!r} is damaged: its {name} is {value!r}, not a number")
        return row

    def pattern(self, key: str) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """A run's final pattern: unwrapped positions (arc length, height; float32), patch labels and
        colours (RGB uint8, ``bark.analysis.pattern.patch_colours``)."""
        got = self._read("SELECT n, uv, labels, colours FROM patterns WHERE key = ?", (key,))
        if not got:
            return None
        n, uv, labels, colours = got[0]
        sizes = {"uv": (uv, 8), "labels": (labels, 4), "colours": (colours, 3)}
        if not (isinstance(n, int) and n >= 0) or any(not isinstance(b, bytes) or len(b) != n * w for b, w in sizes.values()):
            raise BarkError(f"{self.path}: the pattern of run {key!r} is damaged (its arrays are not of its {n!r} bases)")
        return (np.frombuffer(uv, np.float32).reshape(n, 2), np.frombuffer(labels, np.int32),
                np.frombuffer(colours, np.uint8).reshape(n, 3))


def run_sweep(sweep: Sweep, database: str | Path, *, workers: int = 1, client=None,
              progress: Callable[[int, int, Point | None], None] | None = None, run_folders: str | Path | None = None
              ) -> dict:
    """Run every point of ``sweep`` not yet in ``database``; commit each as it finishes.  ``client``:
    a ``distributed.Client`` (Dask) to run on; else ``workers`` local processes.  ``progress(done,
    total, point)`` is called at the start (point ``None``) and after each commit.  With
    ``run_folders`` each run also writes its outputs into a folder of its own there, named by its key
    (the table's ``key``).  Returns counts: ``total``, ``skipped`` (already in the table), ``ran``."""
    points = sweep.points()
    if workers < 1:
        raise BarkError("{0}: must be at least 1", Ref(None, "workers", workers))
    if client is None:  # this machine runs them, so many at once: each point fits, before anything is written
        check_fits(sweep, workers)
    with SweepTable(database) as table:
        table.add_axes(sweep.axes)
        done = table.done()
        todo = [p for p in points if p.key not in done]
        counts = {"total": len(points), "skipped": len(points) - len(todo), "ran": 0}
        if progress:
            progress(counts["skipped"], len(points), None)
        by_key = {p.key: p for p in todo}
        # closing: a stop in the middle of a commit closes the runs' source at once (its workers end),
        # not when it is collected at the interpreter's exit, which would wait for them
        folders = {p.key: None if run_folders is None else str(Path(run_folders) / p.key) for p in todo}
        with contextlib.closing(_on_dask(client, todo, folders) if client is not None else _local(todo, workers, folders)) \
                as results:
            for result in results:
                table.commit(by_key[result["key"]], result)
                counts["ran"] += 1
                if progress:
                    progress(counts["skipped"] + counts["ran"], len(points), by_key[result["key"]])
    return counts


def check_fits(sweep: Sweep, workers: int) -> None:
    """Refuse, in one line, a sweep run here by ``workers`` local processes with a point whose runs
    side by side need more memory than this machine has available (``Scene.check_memory``): before
    any point runs, as every point's settings are checked (``Sweep.points``)."""
    from bark.engine.scene import available_memory

    have = available_memory()
    points = sweep.points()
    if have is None or not points:
        return
    for p in points:  # the scenes validated when the points were made, not built again
        p.checked.check_memory(have, min(workers, len(points)))


def _local(todo: list[Point], workers: int, folders: dict):
    """Results as they finish, from ``workers`` local worker processes (``bark.studies.pool``)."""
    if not todo:
        return
    pool = LocalPool(min(workers, len(todo)), "sweep")
    try:
        pending = {pool.submit(run_point, p.scene, p.key, folders[p.key]) for p in todo}
        while pending:
            finished = pool.wait_any(pending)
            pending -= finished
            failed = None
            for f in finished:  # every run that finished is handed on before a failure is raised
                if f.exception() is None:
                    yield f.result()
                else:
                    failed = f.exception()
            if pool.died(failed):
                raise WorkerDied("a sweep worker died (killed, or out of memory): the runs finished before are in "
                                 "the table; the same sweep run again goes on from there")
            if failed is not None:
                raise failed
    finally:  # finished, or stopped (a signal, the caller closing this generator): runs in flight are lost
        pool.close()


WORKERLESS_S = 3.0
"""How long a Dask sweep waits with no worker at its scheduler before it says so (once; again when
workers came back and went again)."""


def _on_dask(client, todo: list[Point], folders: dict):
    """Results as they finish, from the Dask cluster behind ``client``.  The scheduler is asked
    while waiting: with no worker left for ``WORKERLESS_S`` a warning says so (the runs wait for
    one; Ctrl-C stops, and what finished is in the table) instead of a silent wait."""
    if not todo:
        return
    from distributed import wait

    futures = [client.submit(run_point, p.scene, p.key, folders[p.key], key=f"bark-run-{p.key}", pure=False) for p in todo]
    pending, said = set(futures), False
    try:
        while pending:
            try:
                done, pending = wait(pending, timeout=WORKERLESS_S, return_when="FIRST_COMPLETED")
            except TimeoutError:
                if client.scheduler_info().get("workers"):
                    said = False
                elif not said:
                    warnings.warn(f"no Dask worker is left at {client.scheduler.address}: {len(pending)} runs wait for "
                                  "one (start workers, or Ctrl-C: the finished runs are in the table)", BarkWarning,
                                  stacklevel=2)
                    said = True
                continue
            for future in done:
                yield future.result()
    finally:
        client.cancel([f for f in futures if not f.done()])
