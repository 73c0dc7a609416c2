"""Drawing a run's pictures without making the user wait for matplotlib.

Importing matplotlib takes longer than a short run itself (``benchmarks/whole_process.py`` shows it).  When a scene asks for a
picture, ``Painter`` forks a drawing process at the start of the command: it imports matplotlib on
the machine's other core while the simulation runs, then forks a second (where the command may use
two cores) and both wait.  At the end the runner hands them the pictures as plain arrays
(``PatternData``, ...), each taken by whichever is free; they draw and write the files (atomically)
and say how it went.  Signals belong to the command, not to the painters (they ignore them); a
signal while they draw stops them at once (the data are already written).  Where ``fork`` is not
available the pictures are drawn in the command's own process.
"""

from __future__ import annotations

import atexit
import importlib
import math
import multiprocessing
import os
import queue
import signal
import sys
import threading
from pathlib import Path

import attrs
import numpy as np

from bark.errors import one_line
from bark.units import unwrap
from bark.engine.stepping import cores
from bark.units import metres
from bark_cli import matplotlib_folder

LEAVES_CUT_DEG = 55.0
"""tree.png's cut-away: the leaves that leave the plant in front of the trunk within this angle of
the line of sight (either side) are not drawn, so that the bark they would hide shows."""

@attrs.frozen
class PatternData:
    """What ``pattern.png`` shows, as plain arrays: the unwrapped positions, the patch labels, the
    intact springs, and the figures of its title."""

    uv: np.ndarray
    labels: np.ndarray
    colours: np.ndarray
    """RGB (uint8) per base: neighbouring patches never share one (``bark.analysis.pattern.patch_colours``)."""
    springs: np.ndarray
    cracks: np.ndarray
    """The broken springs' ends: drawn where the springs are too many to draw (the crevices)."""
    n_bases: int
    radius: float
    t: float
    n_patches: int
    n_broken: int

    @classmethod
    def of(cls, sim, min_size: int) -> "PatternData":
        """What pattern.png shows of ``sim`` now, patches of at least ``min_size`` bases coloured."""
        s, r = sim.state, sim.radius
        from bark.analysis.pattern import simulation_colours

        return cls(uv=unwrap(s.x, r), labels=sim.patch_labels(), colours=simulation_colours(sim, min_size),
                   springs=np.asarray(s.pairs[s.intact]), cracks=np.asarray(s.pairs[~s.intact]),
                   n_bases=s.n_bases, radius=r, t=s.t, n_patches=sim.patch_count(min_size), n_broken=sim.n_broken)

    @classmethod
    def of_state(cls, path, min_size: int) -> "PatternData":
        """The pattern of a run's ``state.npz`` (or a run's folder), without its simulation."""
        from bark.analysis.pattern import patch_colours
        from bark.model.components import count_patches

        path = Path(path)
        with np.load(path / "state.npz" if path.is_dir() else path, allow_pickle=False) as d:
            x, labels, pairs, intact, t = d["x"], d["labels"], d["pairs"], d["intact"], float(d["t"])
        r = float(np.mean(np.hypot(x[:, 0], x[:, 1])))
        return cls(uv=unwrap(x, r), labels=labels, colours=patch_colours(labels, min_size, pairs, intact),
                   springs=pairs[intact], cracks=pairs[~intact], n_bases=len(x), radius=r, t=t,
                   n_patches=count_patches(labels, min_size), n_broken=int((~intact).sum()))


@attrs.frozen
class TreeData:
    """What tree.png shows (and each picture of the tree series), as plain arrays (sent to the drawing
    process)."""

    polygons: np.ndarray
    """Projected rhomboids (x, z) of the bases facing the viewer, far first, ``(n, 4, 2)``, metres."""
    colours: np.ndarray
    outline: np.ndarray
    """(z, r) of the trunk's outline, metres."""
    dome: np.ndarray
    """(x, z) of the dome's profile (right half), metres."""
    organs: np.ndarray
    """(x, z) of the leaf bases on the dome facing the viewer (Ridley's placement), far first, metres."""
    t: float
    n_bases: int
    n_patches: int
    n_broken: int | None
    leaves: np.ndarray = np.empty((0, 2, 2))
    """The leaves' axes projected (x, z), ``(n, points, 2)``, metres, far first (``leaves`` effect)."""
    leaf_widths: np.ndarray = np.empty((0, 1))
    """Each segment's width, ``(n, points − 1)``, metres."""
    leaf_colours: np.ndarray = np.empty((0, 3))
    leaf_front: np.ndarray = np.empty(0, bool)
    """Whether each leaf is on the viewer's side of the trunk (drawn over it).  The leaves in front
    within :data:`LEAVES_CUT_DEG` of the line of sight are cut away: the bark shows through."""

    @classmethod
    def of(cls, sim, min_size: int, dome, leaves=None) -> "TreeData":
        """The tree at the end of the run (``leaves``: the ``[leaves]`` settings, or ``None``: no leaves)."""
        from bark.analysis.pattern import simulation_colours

        return cls.at(sim, sim.state.t, sim.state.x, simulation_colours(sim, min_size), sim.patch_count(min_size),
                      sim.n_broken, dome, leaves)

    @classmethod
    def at(cls, sim, t: float, x: np.ndarray, colours: np.ndarray, n_patches: int, n_broken: int | None, dome,
           leaves=None) -> "TreeData":
        """The tree at time ``t`` of ``sim``'s run, its bases at ``x`` then, coloured ``colours``."""
        from bark.io.mesh import leaf_quads
        from bark.model.tree import Apex

        quads = leaf_quads(sim, t, x)
        depth = quads[..., 1].mean(axis=1)  # towards the viewer
        shown = np.flatnonzero(depth > 0.0)
        shown = shown[np.argsort(depth[shown])]  # far (small y) first
        polygons = metres(quads[shown][..., [0, 2]])
        z = x[:, 2]
        zs = np.linspace(float(z.min()), float(z.max()), 400)
        r = np.broadcast_to(sim.growth.radius(t, zs), zs.shape)
        top_r = float(r[-1])
        apex = Apex(dome=dome, packing=sim.packing)
        top = float(apex.top(t))
        rho, u = dome.curve(200)
        profile = np.column_stack([rho * top_r, top + u * top_r])
        _, organs = apex.organs(t, top_r)
        organs = organs[organs[:, 1] > 0.0]
        organs = organs[np.argsort(organs[:, 1])][:, [0, 2]]
        drawn = {}
        if leaves is not None:
            from bark.model.leaves import plant_leaves

            plant = plant_leaves(leaves, apex, sim.growth, t, x)
            base = plant.axes[:, 0]  # where each leaf leaves the plant: in front of the trunk within the cut, not drawn
            kept = ~((base[:, 1] > 0.0) & (np.abs(base[:, 0]) < base[:, 1] * math.tan(math.radians(LEAVES_CUT_DEG))))
            order = np.flatnonzero(kept)[np.argsort(plant.axes[kept, :, 1].mean(axis=1))]  # far first
            segments = 0.5 * (plant.widths[:, 1:] + plant.widths[:, :-1])
            drawn = {"leaves": metres(plant.axes[order][..., [0, 2]]), "leaf_widths": metres(segments[order]),
                     "leaf_colours": plant.colours[order], "leaf_front": plant.axes[order, 0, 1] > 0.0}
        return cls(polygons=polygons, colours=colours[shown], outline=metres(np.column_stack([zs, r])),
                   dome=metres(profile), organs=metres(organs), t=t, n_bases=len(x), n_patches=n_patches,
                   n_broken=n_broken, **drawn)


@attrs.frozen
class SeriesData:
    """What tree-series.png shows: the tree at several ages (``TreeData`` each)."""

    trees: tuple

    @classmethod
    def of(cls, sim, scene, frames) -> "SeriesData":
        """What tree-series.png shows of ``sim``'s run under ``scene``, from its recorded ``frames``
        (:class:`~bark.io.recorders.TreeFrames`)."""
        from bark.analysis.pattern import rgb
        from bark.model.components import count_patches

        min_size = scene.run.min_patch_size
        leaves = scene.leaves if scene.has("leaves") else None
        trees = []
        for k, (t, x, labels) in enumerate(frames.frames):
            trees.append(TreeData.at(sim, t, np.asarray(x, dtype=float), rgb(frames.colour_index(k, min_size)),
                                     count_patches(labels, min_size), None, scene.dome, leaves))
        return cls(trees=tuple(trees))


REGION_ORDER = ("straight", "bulge", "young")
"""The regions of a trunk in the order regions.png shows them (the paper's Fig. 11 compares the first two)."""


@attrs.frozen
class RegionsData:
    """What regions.png shows: per region of the trunk (one, ``trunk``, when it has no regions), its
    patches' orientations and anisotropies and its statistics (summary.json's ``regions``)."""

    names: tuple[str, ...]
    orientation: tuple[np.ndarray, ...]
    anisotropy: tuple[np.ndarray, ...]
    summaries: tuple[dict, ...]
    t: float

    @classmethod
    def of(cls, sim, min_size: int) -> "RegionsData":
        """What regions.png shows of ``sim`` now, patches of at least ``min_size`` bases counted."""
        from bark.analysis.patches import pattern_summary
        from bark.contract.strategies import pattern_of
        from bark.io.output import base_regions, largest_share, patch_regions, trunk_regions

        measured = pattern_of(sim.analyze().values())
        rows = measured.patches if measured is not None else []
        labels = sim.patch_labels()
        every = trunk_regions(sim)  # summary.json's regions, or one: the whole trunk
        if every is None:
            present, names, where = ["trunk"], np.full(len(rows), "trunk", dtype=object), np.full(labels.size, "trunk")
        else:
            present = sorted(map(str, every), key=lambda n: (REGION_ORDER + (n,)).index(n))
            names, where = patch_regions(sim, rows, labels), base_regions(sim)
        picked = [[r for r, n in zip(rows, names) if n == name] for name in present]
        summaries = [pattern_summary(chosen) for chosen in picked]
        for name, summary in zip(present, summaries):
            summary["largest_patch_share"] = largest_share(labels[where == name])
        return cls(names=tuple(present), summaries=tuple(summaries), t=sim.state.t,
                   orientation=tuple(np.array([r["orientation_deg"] for r in chosen], float) for chosen in picked),
                   anisotropy=tuple(np.array([r["anisotropy"] for r in chosen], float) for chosen in picked))


PICTURES = {
    "pattern-image": ("pattern.png", "pattern", lambda sim, scene, recorded: PatternData.of(sim, scene.run.min_patch_size)),
    "animation": ("development.gif", "animation", lambda sim, scene, recorded: recorded["frames"]),
    "tree-image": ("tree.png", "tree", lambda sim, scene, recorded: TreeData.of(
        sim, scene.run.min_patch_size, scene.dome, scene.leaves if scene.has("leaves") else None)),
    "tree-series": ("tree-series.png", "tree-series", lambda sim, scene, recorded: SeriesData.of(sim, scene, recorded["trees"])),
    "fracture-history": ("fracture.png", "fracture", lambda sim, scene, recorded: recorded["dissipation"].result),
    "region-image": ("regions.png", "regions", lambda sim, scene, recorded: RegionsData.of(sim, scene.run.min_patch_size)),
}
"""Per effect: its picture's file, the kind of drawing, and the data it is drawn from."""
DRAWN_BY = {"pattern": "bark_cli.plot", "animation": "bark_cli.animation", "tree": "bark_cli.tree_picture",
            "tree-series": "bark_cli.tree_picture", "fracture": "bark_cli.figures", "regions": "bark_cli.figures"}
"""Per kind of drawing, the module that draws it (what a drawing process imports ahead)."""


def writers() -> dict:
    """The pictures as ``bark.studies.runner`` takes them, drawn in this process when asked for (the
    ``bark.pictures`` entry point: what a library run draws; ``bark simulate`` draws the same
    pictures beside the run, in a ``Painter``'s processes)."""
    def writer(kind, data_of):
        def draw(sim, scene, recorded, path):
            _draw(kind, data_of(sim, scene, recorded), str(path), scene.run.min_patch_size, scene.picture_dpi)
        return draw

    return {effect: (name, writer(kind, data_of)) for effect, (name, kind, data_of) in PICTURES.items()}


def _draw(kind: str, data, path: str, min_size: int, dpi: int | None = None) -> None:
    """Draw ``data`` as the picture ``kind`` into ``path`` (its suffix the format), at ``dpi``."""
    from bark_cli.plot import picture_dpi

    with picture_dpi(dpi):
        _draw_kind(kind, data, path, min_size)


def _draw_kind(kind: str, data, path: str, min_size: int) -> None:
    if kind == "pattern":
        from bark_cli.plot import plot_pattern

        plot_pattern(data, path, min_size)
    elif kind == "fracture":
        from bark_cli.figures import plot_fracture_history

        plot_fracture_history(data, path)
    elif kind == "tree":
        from bark_cli.tree_picture import plot_tree

        plot_tree(data, path, min_size)
    elif kind == "regions":
        from bark_cli.figures import plot_regions

        plot_regions(data, path, min_size)
    elif kind == "tree-series":
        from bark_cli.tree_picture import plot_tree_series

        plot_tree_series(data, path, min_size)
    else:
        from bark_cli.animation import write_gif

        write_gif(data, path, min_size)


def _serve(jobs, replies, command_ends, siblings=(), modules=tuple(DRAWN_BY.values())) -> None:
    """The painter: ready matplotlib, then draw what it is sent until told to stop — or until the
    command is gone (its end of the pipe closes: the painter holds no copy of it, so it sees that).
    Once ready — ``modules`` imported: those of the pictures the run will draw — it forks a sibling
    for each pipe pair in ``siblings`` (they share the imports: the pictures of one run are then
    drawn side by side), and waits for them when it ends."""
    for end in command_ends:
        end.close()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)  # the command decides; it kills the painter if it must
    for module in dict.fromkeys(modules):  # matplotlib, now: this is the point
        importlib.import_module(module)
    children, painter = [], os.getpid()
    for mine in siblings:
        pid = os.fork()
        if pid == 0:  # the sibling: dies with the painter (a command that kills the painter kills both)
            try:
                _die_with_parent()
                if os.getppid() == painter:  # else it is gone already
                    for other in (jobs, replies, *(end for pair in siblings if pair is not mine for end in pair)):
                        other.close()
                    _draw_jobs(*mine)
            finally:
                os._exit(0)  # never back into the painter's code
        children.append(pid)
        for end in mine:
            end.close()
    _draw_jobs(jobs, replies)
    for pid in children:
        os.waitpid(pid, 0)


def _die_with_parent() -> None:
    """Ask Linux to kill this process when its parent ends (``prctl(PR_SET_PDEATHSIG, SIGKILL)``)."""
    import ctypes

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # not Linux's C library: the sibling still ends when the command's pipe closes
        pass


def _draw_jobs(jobs, replies) -> None:
    """Draw each job received, answering ``None`` or the failure in one line, until ``None`` or the
    command's end of the pipe is gone."""
    while True:
        try:
            job = jobs.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        try:
            _draw(*job)
            reply = None
        except OSError as err:  # the file system refused the file: the command says it could not be written
            reply = (err.errno, err.strerror or str(err))
        except Exception as err:  # reported by the command, one line
            reply = one_line(err)
        try:
            replies.send(reply)
        except OSError:  # the command is gone
            return


@attrs.define(eq=False)
class _Job:
    """One picture handed over: its outcome (``None``, a failure's line, or ``_LOST``) once ``done``."""

    args: tuple
    done: threading.Event = attrs.field(factory=threading.Event)
    outcome: object = None


_LOST = object()


class Painter:
    """Drawing processes started now (see the module's docstring), or drawing in this process.

    ``workers`` processes draw (default: two where this process may use two cores or more and there are
    two pictures or more to draw, else one):
    the first imports matplotlib and forks the others, and the pictures a run hands over are shared
    among them as each becomes free (the whole tree's three pictures, one after another, took longer
    than its run's other outputs).
    The first imports ahead the modules that draw ``kinds`` (default: every kind; ``PICTURES``).
    Each has a thread of the command that hands it pictures and takes its answers (a picture's data
    are megabytes, more than a pipe holds, and a drawing process reads them only when it has drawn
    the one before), so the command goes on with its own outputs meanwhile."""

    def __init__(self, workers: int | None = None, kinds=None) -> None:
        self._proc = None
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._threads: list[threading.Thread] = []
        self._ends: list = []
        matplotlib_folder()  # here: the drawing processes inherit it, and the warning is said once, here
        if "fork" in multiprocessing.get_all_start_methods() and sys.platform.startswith("linux"):
            count = max(1, workers if workers is not None else min(2, cores(), len(DRAWN_BY if kinds is None else kinds)))
            ctx = multiprocessing.get_context("fork")
            pipes = []
            for _ in range(count):
                theirs_in, ours_out = ctx.Pipe(duplex=False)  # jobs: we send, they receive
                ours_in, theirs_out = ctx.Pipe(duplex=False)  # replies: they send, we receive
                pipes.append(((theirs_in, theirs_out), (ours_out, ours_in)))
            command_ends = tuple(end for _, ours in pipes for end in ours)
            modules = tuple(DRAWN_BY[k] for k in (DRAWN_BY if kinds is None else kinds))  # what to import ahead
            self._proc = ctx.Process(target=_serve, args=(*pipes[0][0], command_ends, tuple(p[0] for p in pipes[1:]),
                                                          modules), daemon=True)
            try:
                self._proc.start()
            except OSError:  # no process to spare (ulimit -u): the pictures are drawn here, after the data
                self._proc = None
                for pair in pipes:
                    for end in (*pair[0], *pair[1]):
                        end.close()
                return
            atexit.register(self.close, kill=True)  # runs before multiprocessing's own exit handler, which
            for theirs, ours in pipes:              # would wait for a painter that ignores its SIGTERM
                for end in theirs:
                    end.close()
                self._ends.extend(ours)
                thread = threading.Thread(target=self._hand_over, args=ours, name="bark-painter", daemon=True)
                thread.start()
                self._threads.append(thread)

    def _hand_over(self, send, receive) -> None:
        """One drawing process's thread: the next picture to it, its answer back to the job, until
        ``None``.  If the process is gone, the jobs this thread takes say so at once."""
        gone = False
        while True:
            job = self._jobs.get()
            if job is None:
                if not gone:
                    try:
                        send.send(None)
                    except (OSError, ValueError):
                        pass
                return
            job.outcome = _LOST
            try:
                if not gone:
                    send.send(job.args)
                    job.outcome = receive.recv()
            except (EOFError, OSError):  # killed (a signal stopped the drawing), or died
                gone = True
            except Exception as err:  # its data could not be sent (pickled): that picture fails, no other
                job.outcome = one_line(err)
            finally:
                job.done.set()

    def submit(self, kind: str, data, path: Path, min_size: int, dpi: int | None = None):
        """Hand ``data`` (``PatternData``, ``TreeData``, ``Frames``, ...) to a drawing process and
        return at once with a ``wait()`` that ends when the picture is written: the command writes
        its other outputs meanwhile.  ``wait`` raises what drawing raised (an ``OSError`` where the
        file system refused the file, else a ``RuntimeError`` naming it), or ``KeyboardInterrupt`` if
        a signal stopped it.  Without a drawing process, draws now."""
        if self._proc is None:
            _draw(kind, data, str(path), min_size, dpi)
            return lambda stop=False: None
        job = _Job(args=(kind, data, str(path), min_size, dpi))
        self._jobs.put(job)

        def wait(stop: bool = False) -> None:
            """The picture's outcome; with ``stop``, unless it is ready, the drawing is stopped now."""
            try:
                if stop and not job.done.is_set():
                    raise KeyboardInterrupt
                job.done.wait()
            except KeyboardInterrupt:
                self.close(kill=True)
                raise
            if job.outcome is _LOST:
                raise RuntimeError("the drawing process ended unexpectedly")
            if isinstance(job.outcome, tuple):
                raise OSError(*job.outcome)
            if job.outcome is not None:
                raise RuntimeError(job.outcome)
        return wait

    def close(self, kill: bool = False) -> None:
        """Wait for the drawing processes to finish what they were handed and end them; ``kill``: end them at
        once (a picture not yet drawn is not drawn)."""
        if self._proc is None:
            return
        atexit.unregister(self.close)
        if kill:  # its siblings die with it
            os.kill(self._proc.pid, signal.SIGKILL)
        for _ in self._threads:
            self._jobs.put(None)
        for thread in self._threads:
            thread.join(timeout=5)
        self._proc.join(timeout=5)
        if self._proc.is_alive():
            self._proc.kill()
        for end in self._ends:
            end.close()
        self._proc = None
