"""Running a scene to its result: the one library call behind ``bark simulate``.

    from bark.studies.runner import run, resume
    outcome = run(scene, "runs/a")            # builds, runs, writes what the scene's effects ask for
    outcome = resume("runs/a")                # goes on from the checkpoint in runs/a

A run, in order:

1. **Before anything is written**: the scene is built (``Scene.simulation``, which refuses a run
   too large for this machine's memory), the numerics checked against the stop conditions
   (``Simulation.prepare``), and the output folder opened (``bark.io.folder``: checked, created,
   locked, cleaned).  Bad input stops here, with nothing written.
2. **The loop**, ``Simulation.run``, with the along-the-way recorders the scene's effects ask for
   (statistics series, animation frames), a checkpoint every ``checkpoint_every`` seconds of wall
   time, and a look at ``interrupted()`` between steps: a signal stops the run there.
   A run that keeps checkpoints writes its start record first (``bark.io.checkpoint``: its scene,
   a few kB), so it is resumable from its first step whatever the disk does later.
3. **The end, in an order that loses nothing**: the stale summary is removed, the checkpoint is
   written (``end``, or ``interrupted``: resumable), then the data files and the pictures (drawn
   meanwhile in other processes), and last ``summary.json``, whose presence says that every output
   is there and matches the checkpoint.  A file the file system refuses, or a picture a signal
   stopped, is reported, every other output stays, and ``summary.json`` is not written: ``resume``
   writes what is missing from the checkpoint — also after a kill anywhere in these writes.  A
   picture that fails for another reason (a bug: resuming would not draw it either) is reported
   and does not hold the summary back.

Drawing is not the core's: ``pictures`` maps an effect (``pattern-image``, ``animation``) to the
file it writes and a function ``draw(sim, scene, recorded, path)``.  Left out, the writers are those
installed under the ``bark.pictures`` entry point (``bark_cli``'s matplotlib drawings, in this
process), so a library run draws what ``bark simulate`` draws; a picture nothing installed can
draw is reported as not drawn.  The caller owns signals: ``interrupted()`` returns the reason to stop (e.g.
``"interrupted"``) or ``None``.  ``observe(sim, stop)`` is called after every advance (a progress bar).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import attrs

from bark.contract import registry
from bark.io import checkpoint
from bark.errors import BarkError, NonFiniteStateError, Ref, one_line
from bark.io.files import attempt, write_json
from bark.io.folder import OutputFolder
from bark.io.history import History
from bark.model.effects import in_format
from bark.io.recorders import Dissipation
from bark.io.recorders import Frames, StatisticsSeries, TreeFrames
from bark.io.output import run_summary, write_run
from bark.version import provenance, session

__all__ = ["Outcome", "run", "resume", "STOPPED_BY_SIGNAL"]

STOPPED_BY_SIGNAL = ("interrupted", "terminated")
"""Stop reasons of a run stopped from outside between two steps; such a run can be resumed."""

Picture = tuple[str, Callable]


@attrs.define
class Outcome:
    """What a run left: where, the simulation at its end, why it stopped, its summary, and the
    outputs that could not be written (one line each; empty when all were)."""

    out: Path | None
    scene: object
    sim: object
    stop_reason: str
    summary: dict
    resumed: bool = False
    error: str | None = None
    """Why the state went non-finite, if it did (the last finite state was written)."""
    failed: list[str] = attrs.field(factory=list)
    drawing_stopped: bool = False
    """Whether a picture was left undrawn because a signal stopped the drawing."""


def run(scene, out: str | Path | None = None, *, overwrite: bool = False, checkpoint_every: float = 60.0,
        observe: Callable | None = None, interrupted: Callable[[], str | None] | None = None,
        pictures: dict[str, Picture] | None = None, warn: Callable[[str], None] | None = None,
        notice: Callable[[str], None] | None = None, command: str | None = None) -> Outcome:
    """Run ``scene`` into the folder ``out`` (see the module's docstring; ``None``: in memory only,
    for studies and sweeps that read the outcome, not files).  ``warn`` receives what a
    user must hear (a run with no time bound, a fallback to an older checkpoint), ``notice`` what is
    merely worth saying (an earlier run's files replaced); ``command``, the command line that ran it,
    for summary.json's provenance (default: the process's)."""
    _check_every(checkpoint_every)
    sim, stop = scene.simulation(), scene.stop()
    sim.prepare(stop)
    sessions = [session(command)]
    if out is None:  # in memory: nothing written, nothing drawn, no checkpoints
        return _drive(scene, sim, stop, None, {}, 0.0, False, 0.0, observe, interrupted, None, sessions=sessions)
    _check_history(scene, stop, Path(out))
    with OutputFolder.open(out, fresh=True, overwrite=overwrite, notice=notice) as folder:
        if scene.has("checkpoints"):  # the run is resumable from its first step on, whatever the disk does later
            refused: list[str] = []
            if not attempt(checkpoint.CHECKPOINT_NAME, lambda: checkpoint.save_start(folder.path, scene, stop, {
                    "stop_reason": None, "wall_time_s": 0.0, "sessions": sessions}), refused):
                raise BarkError("{0}: the run's start record " + refused[0].partition(": ")[2] + "; nothing was run",
                                Ref(None, "out", str(out)))
        if stop.until_time is None and warn is not None:
            conds = [f"radius {stop.until_radius:g}" if stop.until_radius is not None else None,
                     f"{stop.until_patches} patches" if stop.until_patches is not None else None]
            warn(f"no time bound: this run ends only at {' or '.join(c for c in conds if c)}; "
                 "a signal (Ctrl-C) stops it with a checkpoint")
        return _drive(scene, sim, stop, folder.path, {}, 0.0, False, checkpoint_every, observe, interrupted, pictures,
                      warn, sessions)


def resume(out: str | Path, *, checkpoint_every: float = 60.0, observe: Callable | None = None,
           interrupted: Callable[[], str | None] | None = None, pictures: dict[str, Picture] | None = None,
           warn: Callable[[str], None] | None = None, notice: Callable[[str], None] | None = None,
           command: str | None = None) -> Outcome:
    """Go on with the run in ``out`` from its checkpoint (every setting comes from there).  A run
    that had ended but whose outputs were not all written gets them written.  ``command`` as for
    :func:`run`."""
    _check_every(checkpoint_every)
    with OutputFolder.open(out, fresh=False, key="resume") as folder:
        scene, sim, stop, meta, recorded, _ = checkpoint.load(folder.path, warn=warn)
        wall = float(meta.get("wall_time_s") or 0.0)
        sessions = [*meta.get("sessions", []), session(command)]
        if meta["reason"] == "start" and warn is not None:
            warn("no checkpoint of the run's state was written (a full disk, or a stop before the first one): "
                 "it runs again from its start, to the same result")
        if meta["reason"] == "end":
            if _outputs_complete(folder.path, meta):
                raise BarkError(f"the run in {str(folder.path)!r} has ended ({meta.get('stop_reason')}): nothing to resume")
            if warn is not None:
                warn("the run had ended, but not all of its outputs were written: writing them now")
            recorders = _recorders(scene, sim, recorded)
            return _finish(scene, sim, stop, folder.path, recorders, meta.get("stop_reason") or "time", wall, True,
                           None, pictures, sessions, save=False)
        return _drive(scene, sim, stop, folder.path, recorded, wall, True, checkpoint_every, observe, interrupted, pictures,
                      warn, sessions)


def _check_history(scene, stop, out: Path) -> None:
    """Refuse, in one line and before anything is written, a history whose files would not fit on
    the disk of ``out`` or whose record would not fit in this machine's memory
    (``Scene.history_estimate``): a tiny ``frame_every`` made one of 22 GB that ran until the disk
    was full."""
    import shutil

    from bark.engine.scene import available_memory

    estimate = scene.history_estimate(stop)
    if estimate is None:
        return
    frames, on_disk, in_memory = estimate
    where = next((p for p in (out, *out.parents) if p.exists()), Path("."))
    try:
        free = shutil.disk_usage(where).free
    except OSError:
        free = None
    have = available_memory()
    for need, room, what in ((on_disk, free, f"free on the disk of {str(out)!r}"), (in_memory, have, "of memory available")):
        if room is not None and need > room:
            raise BarkError(f"{{0}}: the history would be about {need / 2**30:.3g} GiB ({frames:,} frames of up to "
                            f"{scene.lattice.n_bases:,} bases), more than the {room / 2**30:.3g} GiB {what}: raise "
                            "it, or leave the history out", Ref("effects", "frame_every", scene.frame_every))


def _check_every(seconds) -> None:
    if not (isinstance(seconds, (int, float)) and 0 <= seconds <= 1e9):
        raise BarkError("{0}: must be a number of seconds in [0, 1e+09] (0: only at the end and on a signal)",
                        Ref(None, "checkpoint_every", seconds))


def _outputs_complete(folder: Path, meta: dict) -> bool:
    """Whether summary.json is there and describes the checkpoint's state (written last, so all is)."""
    import json

    try:
        summary = json.loads((folder / "summary.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(summary, dict) and summary.get("steps") == meta["step_count"]


def _record_end(sim, scene, recorders: list) -> dict:
    """The state at the stop recorded, once, by every recorder, each finished (what it makes of its
    record: the fracture history); the recorders by name."""
    for rec in recorders:
        rec.record(sim)
        rec.finish(sim, scene.run.min_patch_size)
    return {rec.name: rec for rec in recorders}


def _extra(by_name: dict) -> dict:
    """What the recorders add to summary.json."""
    return {k: v for rec in by_name.values() for k, v in rec.summary().items()}


def _recorders(scene, sim, recorded: dict) -> list:
    """The along-the-way recorders the scene asks for, on their triggers, with what a checkpoint
    recorded restored and their triggers brought up to the simulation's time."""
    from bark.engine.triggers import Every

    wanted = [(StatisticsSeries, "statistics-series", lambda: scene.series_every),
              (Frames, "animation", lambda: scene.frame_every), (Dissipation, "fracture-history", lambda: scene.history_every),
              (TreeFrames, "tree-series", lambda: scene.tree_interval), (History, "history", lambda: scene.frame_every)]
    recorders = []
    for cls, effect, every in wanted:
        if not scene.has(effect):
            continue
        rec, trigger = cls(), Every(every())
        if rec.name in recorded:
            rec.load(recorded[rec.name])
            trigger.fires(sim)  # past due times were acted on before the checkpoint
        elif rec.from_start:
            rec.record(sim)
            trigger.fires(sim)  # its due time 0 is this sample
        sim.add_action(trigger, rec.record)
        recorders.append(rec)
    return recorders


def _drive(scene, sim, stop, out: Path, recorded: dict, wall_before: float, resumed: bool, checkpoint_every: float,
           observe, interrupted, pictures, warn=None, sessions: list | None = None) -> Outcome:
    recorders = _recorders(scene, sim, recorded)
    t0 = time.perf_counter()
    last_save = t0
    keep = scene.has("checkpoints")
    refusals: list[str] = []

    def look(s) -> None:
        nonlocal last_save
        if observe is not None:
            observe(s, stop)
        why = interrupted() if interrupted is not None else None
        if why is not None:
            s.stop_reason = why
        elif keep and out is not None and checkpoint_every and time.perf_counter() - last_save >= checkpoint_every:
            wall = wall_before + time.perf_counter() - t0
            refused: list[str] = []
            if not attempt(checkpoint.CHECKPOINT_NAME, lambda: checkpoint.save(
                    out, sim, scene, stop, "periodic", {"stop_reason": None, "wall_time_s": wall, "sessions": sessions},
                    recorders), refused) \
                    and warn is not None and not refusals:
                kept = (out / checkpoint.CHECKPOINT_NAME).exists()
                warn(f"{refused[0]}: the run goes on; " + ("the last checkpoint written is kept" if kept else
                     "it has no checkpoint yet, so a stop before its end cannot be resumed") + " (said once)")
            refusals.extend(refused)
            last_save = time.perf_counter()

    error = None
    try:
        reason = sim.run(stop, look)
    except NonFiniteStateError as err:
        reason, error = "non-finite", str(err)
    return _finish(scene, sim, stop, out, recorders, reason, wall_before + time.perf_counter() - t0, resumed, error,
                   pictures, sessions)


def _pictures_begun(pictures: dict | None, sim, scene, recorded: dict, out: Path) -> list:
    """Start the scene's pictures: ``[(file name, wait)]``.  A picture writer may return a ``wait()``
    that ends when its file is written (it draws in another process meanwhile), or draw at once and
    return ``None``; what it raised is kept, to be reported in its turn.  ``pictures=None``: the
    installed writers (``registry.picture_writers``, looked up only when the scene asks for a
    picture); a picture the scene asks for that nothing draws is reported as not drawn."""
    drawn_by = {effect: e.drawn for effect, e in scene.known_effects.items() if e.drawn and scene.has(effect)}
    if pictures is None and drawn_by:
        pictures = registry.picture_writers() or {}
    begun = []
    for effect, files in drawn_by.items():
        if effect not in (pictures or {}):
            for name in files:
                begun.append((in_format(name, scene.picture_format),
                              BarkError(f"nothing installed draws {effect!r} (bark_cli's bark.pictures entry point)")))
    for effect, (name, draw) in (pictures or {}).items():
        if not scene.has(effect):
            continue
        name = in_format(name, scene.picture_format)  # pattern.png, or pattern.pdf ...
        try:
            wait = draw(sim, scene, recorded, out / name)
        except Exception as err:
            wait = err
        begun.append((name, wait if wait is not None else (lambda: None)))
    return begun


def _finish(scene, sim, stop, out: Path | None, recorders: list, reason: str, wall: float, resumed: bool, error,
            pictures, sessions: list | None = None, save: bool = True) -> Outcome:
    made = {"provenance": provenance(sessions or [])}
    if out is None:
        by_name = _record_end(sim, scene, recorders)
        summary = run_summary(sim, scene, sim.analyze(), reason, wall, {**_extra(by_name), **made})
        return Outcome(out=None, scene=scene, sim=sim, stop_reason=reason, summary=summary, error=error)
    (out / "summary.json").unlink(missing_ok=True)  # stale from here on: written again last
    unsaved: list[str] = []  # a checkpoint the disk refused: the one before it stays
    if save and scene.has("checkpoints"):
        why = "interrupted" if reason in STOPPED_BY_SIGNAL else "end"
        attempt(checkpoint.CHECKPOINT_NAME, lambda: checkpoint.save(
            out, sim, scene, stop, why, {"stop_reason": reason, "wall_time_s": wall, "sessions": sessions}, recorders),
            unsaved)
    by_name = _record_end(sim, scene, recorders)  # after the checkpoint: a resumed run records only what
    failed: list[str] = []                         # the uninterrupted run would
    for rec in recorders:
        if rec.file is not None:
            attempt(rec.file, lambda: rec.write(out / rec.file), failed, (out / rec.file,))
    waits = _pictures_begun(pictures, sim, scene, by_name, out)  # drawn beside the data's writing
    summary = write_run(sim, scene, out, reason, wall, {**_extra(by_name), **made}, failed, summary=False)
    outcome = Outcome(out=out, scene=scene, sim=sim, stop_reason=reason, summary=summary, resumed=resumed, error=error,
                      failed=unsaved + failed)
    missing = _wait_for_pictures(waits, outcome, out)
    if not (unsaved or failed or missing):  # last: its presence says every output is there
        attempt("summary.json", lambda: write_json(out / "summary.json", summary), outcome.failed)
    return outcome


def _wait_for_pictures(waits: list, outcome: Outcome, out: Path) -> bool:
    """Wait for each picture begun, saying in ``outcome.failed`` what was not drawn; whether one is
    missing that ``resume`` can draw (a full disk, a signal while drawing: not a picture that fails)."""
    missing = False
    for name, wait in waits:
        if outcome.drawing_stopped:
            outcome.failed.append(f"{name}: not drawn (stopped by a signal while drawing)")
            continue
        try:
            if isinstance(wait, BaseException):
                raise wait
            wait()
        except KeyboardInterrupt:
            outcome.failed.append(f"{name}: not drawn (stopped by a signal while drawing)")
            outcome.drawing_stopped = missing = True
        except OSError as err:  # a full disk, a file-size limit: as for the data files
            outcome.failed.append(f"{name}: could not be written ({err.strerror or err})")
            (out / name).unlink(missing_ok=True)  # an earlier state's picture is not left beside this one's
            missing = True
        except BarkError as err:  # nothing to draw it with
            outcome.failed.append(f"{name}: not drawn ({err})")
        except Exception as err:  # a picture never costs the data: say what failed, keep the rest
            outcome.failed.append(f"{name}: could not be drawn ({one_line(err)})")
    return missing
