"""Checkpoints: a run written down so that it can go on later, bit for bit as if never stopped.

A checkpoint is one ``checkpoint.npz`` (numpy arrays, stored uncompressed so that writing one is
fast; ``np.load(..., allow_pickle=False)`` reads it) holding:

* the state, every field of it (``bark.model.state.BASE_FIELDS`` and ``SPRING_FIELDS``): positions,
  velocities, anchors and their directions (the sites), birth times; the springs' ends, rest
  lengths, thresholds and ``intact`` mask — the topology, so that a run whose bases joined along
  the way is restored as it was, not rebuilt from the scene;
* the fields the strategies declare (``field_<name>``, with meta's ``declared`` saying which are
  per spring and which per base);
* the break log so far (``breaks_*`` columns);
* what was recorded along the way (``rec_series_*``: the statistics series; ``rec_frames_*``: the
  animation's frames; ``rec_trees_*``: the tree series' ages), so that a resumed run's files are the whole run's;
* ``meta``, a JSON text: checkpoint format, bark's version, the whole scene (every setting, as in
  summary.json), the stop conditions, the clock (full step, tick count, adaptive stepping's current
  level), the step count, the random generator's state, the events so far, why it was written
  (``periodic``, ``interrupted`` or ``end``), and a checksum of every array.

**A run's first checkpoint is its start record** (``start``): ``meta`` alone — format, version, the
whole scene and the stop conditions — written before the first step.  It is small (a few kB: it
fits where the state does not, on a nearly full disk or under a file-size limit) and it is enough,
because a run is determined by its scene: resuming from it runs again from t = 0, to the same bits.
So a run that could write no checkpoint of its state (a disk too full, a ``kill -9`` before the
first periodic one) is still resumable, and a fresh run never replaces it unasked.  The first
checkpoint of the state replaces it (it is not kept as the previous one).

**Trust.**  Nothing in a checkpoint is used before all of it is verified: every array against its
checksum, the types and shapes of the parts against one another (the break log's columns, the
springs against the bases), positions finite, the random generator's state valid, and the format
and bark version it was written by.  A damaged file is one line naming what is wrong.

**Never the only copy.**  A new checkpoint is written to a temporary file, read back and verified,
and only then moved into place; the one it replaces is kept as ``checkpoint.prev.npz``.  If the
newest is damaged (a disk fault, a crash in the middle of the move), resuming falls back to the
previous one, and says so.

The leaf-base graph is not stored: it is the state's bases and intact springs, made again from them.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
import zlib
from pathlib import Path
from typing import Any, Callable

import attrs
import numpy as np

from bark.engine.simulation import Snapshot
from bark.errors import BarkError
from bark.io.files import write_npz
from bark.paths import is_zip, open_regular
from bark.model.state import BASE_FIELDS, SPRING_FIELDS
from bark.model.tree import Packing

__all__ = ["FORMAT", "CHECKPOINT_NAME", "PREVIOUS_NAME", "REASONS", "save", "save_start", "load", "read", "read_meta",
           "Damaged"]

FORMAT = 3
CHECKPOINT_NAME = "checkpoint.npz"
PREVIOUS_NAME = "checkpoint.prev.npz"
REASONS = ("start", "periodic", "interrupted", "end")
"""Why a checkpoint was written: the start record, along the way, on a signal, or at the run's end."""

STATE = {name: (dtype, 1 + len(shape)) for name, (shape, dtype) in {**BASE_FIELDS, **SPRING_FIELDS}.items()}
BREAKS = {"spring": "int64", "i": "int64", "j": "int64", "step": "int64", "t": "float64", "tension": "float64"}
META_KEYS = ("format", "bark_version", "reason", "scene", "stop", "t", "h_last", "clock", "step_count", "events", "rng",
             "checksums")
START_KEYS = ("format", "bark_version", "reason", "scene", "stop", "checksums")
"""What a start record holds (a run's scene and stop conditions: no state)."""


class Damaged(BarkError):
    """A checkpoint that cannot be trusted; the message names the file and what is wrong."""


def digest(a: np.ndarray) -> str:
    """Checksum of an array's type, shape and bytes (BLAKE2b, 128 bits)."""
    a = np.ascontiguousarray(a)
    h = hashlib.blake2b(digest_size=16)
    h.update(f"{a.dtype.str}{a.shape}".encode())
    h.update(memoryview(a).cast("B") if a.size else b"")
    return h.hexdigest()


def save(folder: str | Path, sim, scene, stop, reason: str, extra: dict[str, Any] | None = None,
         recorders=()) -> Path:
    """Write ``sim``'s checkpoint into ``folder``: verified before it replaces the last one, which
    is kept as ``checkpoint.prev.npz``.  ``recorders`` (objects with ``name`` and ``arrays()``)
    are saved with it."""
    from bark.version import __version__

    snap = sim.snapshot()
    arrays, meta = dict(snap.arrays), snap.meta
    for rec in recorders:
        arrays.update({f"rec_{rec.name}_{k}": v for k, v in rec.arrays().items()})
    meta = {
        "format": FORMAT, "bark_version": __version__, "reason": reason, "scene": scene.to_dict(),
        "stop": attrs.asdict(stop), **meta, **(extra or {}),
        "checksums": {name: digest(a) for name, a in arrays.items()},
    }
    folder = Path(folder)
    keep = None if _is_start(folder / CHECKPOINT_NAME) else folder / PREVIOUS_NAME  # a start record is replaced
    return write_npz(folder / CHECKPOINT_NAME, compress=False, verify=read, keep=keep, meta=np.array(json.dumps(meta)),
                     **arrays)


def _is_start(path: Path) -> bool:
    try:
        return read_meta(path).get("reason") == "start"
    except (OSError, Damaged):
        return False


def save_start(folder: str | Path, scene, stop, extra: dict[str, Any] | None = None) -> Path:
    """Write the start record of a run into ``folder`` (see the module's docstring), verified."""
    from bark.version import __version__

    meta = {"format": FORMAT, "bark_version": __version__, "reason": "start", "scene": scene.to_dict(),
            "stop": attrs.asdict(stop), "t": 0.0, **(extra or {}), "checksums": {}}
    return write_npz(Path(folder) / CHECKPOINT_NAME, compress=False, verify=read, meta=np.array(json.dumps(meta)))


def read_meta(path: str | Path) -> dict:
    """Only the meta record of a checkpoint (cheap: the arrays are not read); :class:`Damaged` if unreadable."""
    path = Path(path)
    try:
        with open_regular(path) as raw, zipfile.ZipFile(raw) as zf, zf.open("meta.npy") as fh:
            meta = json.loads(str(np.lib.format.read_array(fh, allow_pickle=False)))
    except FileNotFoundError:
        raise
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as err:
        raise Damaged(f"checkpoint {str(path)!r} is damaged: its meta record cannot be read ({_why(err)})") from None
    if not isinstance(meta, dict):
        raise Damaged(f"checkpoint {str(path)!r} is damaged: its meta record is not a table")
    return meta


def _why(err: Exception) -> str:
    text = str(err).splitlines()[0] if str(err) else type(err).__name__
    return text[:200]


def read(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """``(arrays, meta)`` of a checkpoint, every part verified (see the module's docstring);
    :class:`Damaged` naming the file and the first problem found."""
    from bark.version import __version__

    path = Path(path)
    where = f"checkpoint {str(path)!r}"

    def bad(problem: str) -> Damaged:
        return Damaged(f"{where} is damaged: {problem}")

    try:
        with open_regular(path) as fh:  # our handle (numpy's own is left open on a bad zip); never a FIFO
            if not is_zip(fh):
                raise Damaged(f"{where} is damaged: it is not an .npz archive")
            with np.load(fh, allow_pickle=False) as data:
                arrays = {k: data[k] for k in data.files}
    except (FileNotFoundError, Damaged):
        raise
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as err:
        raise bad(f"it cannot be read ({_why(err)})") from None
    if "meta" not in arrays:
        raise bad("its meta record is missing")
    try:
        meta = json.loads(str(arrays.pop("meta")))
    except ValueError as err:
        raise bad(f"its meta record is not JSON ({_why(err)})") from None
    if not isinstance(meta, dict):
        raise bad("its meta record is not a table")
    missing = [k for k in (START_KEYS if meta.get("reason") == "start" else META_KEYS) if k not in meta]
    if missing:
        raise bad(f"its meta record lacks {missing[0]!r}")
    if meta["format"] != FORMAT:
        raise Damaged(f"{where} has format {meta['format']!r}; this bark reads format {FORMAT}")
    if meta["bark_version"] != __version__:
        raise Damaged(f"{where} was written by bark {meta['bark_version']}, this is bark {__version__}: "
                      f"a resumed run is bit-identical only on the version that began it")
    if meta["reason"] not in REASONS:
        raise bad(f"it was written for an unknown reason {meta['reason']!r}")
    sums = meta["checksums"]
    if not isinstance(sums, dict) or set(sums) != set(arrays):
        lost = sorted(set(sums) - set(arrays)) if isinstance(sums, dict) else []
        raise bad(f"member {lost[0]!r} is missing" if lost else "its members do not match its list of checksums")
    for name, a in arrays.items():
        if digest(a) != sums[name]:
            raise bad(f"array {name!r} does not match its checksum")
    if meta["reason"] == "start":
        if arrays:
            raise bad("it is a start record, yet it holds arrays")
        if not isinstance(meta["scene"], dict) or not isinstance(meta["stop"], dict):
            raise bad("its scene or stop record has the wrong shape")
    else:
        _check_parts(arrays, meta, bad)
    return arrays, meta


def _check_parts(arrays: dict[str, np.ndarray], meta: dict, bad: Callable[[str], Damaged]) -> None:
    """The parts of a checkpoint agree with one another (its checksums cannot see a writer's bug)."""
    for name, (dtype, ndim) in {**STATE, **{f"breaks_{k}": (v, 1) for k, v in BREAKS.items()}}.items():
        if name not in arrays:
            raise bad(f"array {name!r} is missing")
        a = arrays[name]
        if a.dtype != np.dtype(dtype) or a.ndim != ndim:
            raise bad(f"array {name!r} is {a.dtype}{list(a.shape)}, expected {dtype} with {ndim} dimension(s)")
    n, m = arrays["x"].shape[0], arrays["pairs"].shape[0]
    for name, (shape, _) in {**BASE_FIELDS, **SPRING_FIELDS}.items():
        want = ((n if name in BASE_FIELDS else m), *shape)
        if arrays[name].shape != want:
            raise bad(f"array {name!r} has shape {list(arrays[name].shape)}, expected {list(want)}")
    for name in ("x", "v", "anchor", "anchor_dir", "born", "rest", "fmax"):
        if not np.isfinite(arrays[name]).all():
            raise bad(f"array {name!r} holds NaN or infinite values")
    if m and arrays["pairs"].max() >= n:
        raise bad("a spring joins a base that does not exist")
    declared = meta.get("declared", {})
    if not isinstance(declared, dict) or not all(isinstance(k, str) and v in ("spring", "base") for k, v in declared.items()):
        raise bad("its record of declared fields has the wrong shape")
    for name, per in declared.items():  # the strategies' own fields (``field_<name>``)
        a = arrays.get(f"field_{name}")
        if a is None:
            raise bad(f"array 'field_{name}' is missing")
        if a.dtype != np.float64 or a.shape != ((n if per == "base" else m),):
            raise bad(f"array 'field_{name}' is {a.dtype}{list(a.shape)}, expected float64 with one value per {per}")
        if not np.isfinite(a).all():
            raise bad(f"array 'field_{name}' holds NaN or infinite values")
    lengths = {k: arrays[f"breaks_{k}"].shape[0] for k in BREAKS}
    if len(set(lengths.values())) != 1:
        raise bad("the break log's columns have different lengths (" + ", ".join(f"{k} {v}" for k, v in lengths.items()) + ")")
    ids = arrays["breaks_spring"]
    if ids.size and (ids.min() < 0 or ids.max() >= m or np.unique(ids).size != ids.size or arrays["intact"][ids].any()):
        raise bad("the break log names springs that are not broken, or one spring twice")
    if ids.size and ids.size != m - int(np.count_nonzero(arrays["intact"])):
        raise bad(f"the break log holds {ids.size} breaks but {m - int(np.count_nonzero(arrays['intact']))} springs are broken")
    clock = meta["clock"]
    if not isinstance(clock, dict) or set(clock) != {"h", "levels", "ticks", "halvings"}:
        raise bad("its clock record has the wrong shape")
    counts = {"step_count": meta["step_count"], **{k: clock[k] for k in ("levels", "ticks", "halvings")}}
    for key, value in counts.items():
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise bad(f"its {key} is {value!r}, not a count")
    if clock["halvings"] > clock["levels"] or clock["levels"] > 40:
        raise bad(f"its clock's halvings ({clock['halvings']}) and levels ({clock['levels']}) disagree")
    for key, value in {"t": meta["t"], "h_last": meta["h_last"], "h": clock["h"]}.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
            raise bad(f"its {key} is {value!r}, not a time")
    if not clock["h"] > 0 or meta["t"] != clock["ticks"] * (clock["h"] / (1 << clock["levels"])):
        raise bad("its time and its clock disagree")
    try:
        gen = np.random.Generator(np.random.PCG64())
        if not isinstance(meta["rng"], dict) or meta["rng"].get("bit_generator") != "PCG64":
            raise ValueError("not a PCG64 state")
        gen.bit_generator.state = meta["rng"]
    except (TypeError, ValueError, KeyError, OverflowError) as err:
        raise bad(f"its random generator state is invalid ({_why(err)})") from None
    if not isinstance(meta["events"], list) or not isinstance(meta["scene"], dict) or not isinstance(meta["stop"], dict):
        raise bad("its events, scene or stop record has the wrong shape")


def load(folder: str | Path, warn: Callable[[str], None] | None = None):
    """``(scene, simulation, stop, meta, recorded)`` restored from the checkpoint in ``folder``,
    where ``recorded`` maps a recorder's name to its arrays.  Falls back to the previous checkpoint
    (and says so through ``warn``) when the newest is missing or damaged."""
    folder = Path(folder)
    newest, previous = folder / CHECKPOINT_NAME, folder / PREVIOUS_NAME
    try:
        arrays, meta = read(newest)
        used = newest
    except (FileNotFoundError, Damaged) as first:
        if not previous.exists():
            if isinstance(first, FileNotFoundError):
                raise BarkError(f"no checkpoint in {str(folder)!r}: nothing to resume there") from None
            raise first from None
        try:
            arrays, meta = read(previous)
        except Damaged as second:
            raise (second if isinstance(first, FileNotFoundError) else first) from None
        used = previous
        if warn is not None:
            why = "is missing" if isinstance(first, FileNotFoundError) else f"cannot be used ({first})"
            warn(f"{CHECKPOINT_NAME} {why}; going on from the previous checkpoint, t = {meta['t']:.6g}")
    return (*restore(arrays, meta, used), used)


def _check_strategies(scene: dict, path: Path) -> None:
    """Refuse, in one line, to resume with a strategy that cannot be had here (a plugin not
    installed, a class whose module is not importable): never another in its place, and not a
    damaged checkpoint (the previous one records the same)."""
    from bark.contract import registry
    from bark.engine.scene import STRATEGY_SECTIONS

    for section, kind in STRATEGY_SECTIONS.items():
        tables = scene.get(section)
        for table in tables if isinstance(tables, list) else [tables]:
            name = table.get("name") if isinstance(table, dict) else None
            if not isinstance(name, str):
                continue
            try:
                registry.load(kind, name)
            except BarkError as err:
                where = repr(str(path.parent)).replace("{", "{{").replace("}", "}}")
                raise BarkError(f"cannot resume the run in {where}: " + err.template, *err.refs) from None


def restore(arrays: dict[str, np.ndarray], meta: dict, path: Path):
    """Rebuild ``(scene, simulation, stop, meta, recorded)`` from verified checkpoint parts."""
    from bark.engine.scene import Scene
    from bark.engine.simulation import Stop

    _check_strategies(meta["scene"], path)
    try:
        scene = Scene.from_dict(meta["scene"])
        stop = Stop(**meta["stop"])
    except (BarkError, TypeError) as err:
        raise Damaged(f"checkpoint {str(path)!r} is damaged: its scene is not valid ({err})") from None
    sim = scene.simulation()
    if meta["reason"] == "start":  # the run is its scene: built as a fresh run builds it
        return scene, sim.prepare(stop), stop, meta, {}
    lattice, pairs = scene.lattice, arrays["pairs"].astype(np.int64)
    n, due = arrays["x"].shape[0], Packing.of(lattice, sim.growth.on(lattice)).bases_at(float(meta["t"]))
    if n != due or not np.isin(pairs[:, 1] - pairs[:, 0], lattice.offsets).all():
        what = f"it holds {n} bases, its scene's lattice {due} at t = {meta['t']:.6g}" if n != due else \
            "its springs do not fit its scene's lattice"
        raise Damaged(f"checkpoint {str(path)!r} is damaged: {what}")
    state = {k: a for k, a in arrays.items() if not k.startswith("rec_")}
    sim.restore(Snapshot(state, meta))  # built from the checkpoint's state, not the scene's lattice
    recorded: dict[str, dict[str, np.ndarray]] = {}
    for key, a in arrays.items():
        if key.startswith("rec_"):
            name, _, column = key[4:].partition("_")
            recorded.setdefault(name, {})[column] = a
    return scene, sim, stop, meta, recorded
