"""Drawing a run's pictures without making the user wait for matplotlib.

Importing matplotlib takes about 0.4 s, more than a short run itself.  When a scene asks for a
picture, ``Painter`` forks a drawing process at the start of the command: it imports matplotlib on
the machine's other core while the simulation runs, then waits.  At the end the runner hands it the
pattern as plain arrays (``PatternData``), it draws and writes the file (atomically), and says how it
went.  Signals belong to the command, not to the painter (it ignores them); a signal while it draws
stops it at once (the data are already written).  Where ``fork`` is not available the pictures are
drawn in the command's own process.
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import queue
import signal
import sys
import threading
from pathlib import Path

import attrs
import numpy as np

from bark.output import unwrap
from bark.units import metres


@attrs.frozen
class PatternData:
    """What ``pattern.png`` shows, as plain arrays: the unwrapped positions, the patch labels, the
    intact springs, and the figures of its title."""

    uv: np.ndarray
    labels: np.ndarray
    colours: np.ndarray
    """RGB (uint8) per base: neighbouring patches never share one (``bark.pattern.patch_colours``)."""
    springs: np.ndarray
    n_bases: int
    radius: float
    t: float
    n_patches: int
    n_broken: int

    @classmethod
    def of(cls, sim, min_size: int) -> "PatternData":
        s, r = sim.state, sim.radius
        from bark.pattern import simulation_colours

        return cls(uv=unwrap(s.x, r), labels=sim.patch_labels(), colours=simulation_colours(sim, min_size),
                   springs=np.asarray(s.pairs[s.intact]),
                   n_bases=s.n_bases, radius=r, t=s.t, n_patches=sim.patch_count(min_size), n_broken=sim.n_broken)


@attrs.frozen
class TreeData:
    """What tree.png shows, as plain arrays (sent to the drawing process)."""

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
    n_broken: int

    @classmethod
    def of(cls, sim, min_size: int, dome) -> "TreeData":
        from bark.mesh import leaf_quads
        from bark.pattern import simulation_colours
        from bark.tree import Apex

        quads = leaf_quads(sim)
        depth = quads[..., 1].mean(axis=1)  # towards the viewer
        shown = np.flatnonzero(depth > 0.0)
        shown = shown[np.argsort(depth[shown])]  # far (small y) first
        polygons = metres(quads[shown][..., [0, 2]])
        colours = simulation_colours(sim, min_size)[shown]
        z = sim.state.anchor[:, 2]
        zs = np.linspace(float(z.min()), float(z.max()), 400)
        r = np.broadcast_to(sim.growth.radius(sim.state.t, zs), zs.shape)
        top_r = float(r[-1])
        apex = Apex(dome=dome, lattice=sim.lattice)
        top = float(apex.top(sim.state.t))
        rho, u = dome.curve(200)
        profile = np.column_stack([rho * top_r, top + u * top_r])
        _, organs = apex.organs(sim.state.t, top_r)
        organs = organs[organs[:, 1] > 0.0]
        organs = organs[np.argsort(organs[:, 1])][:, [0, 2]]
        return cls(polygons=polygons, colours=colours, outline=metres(np.column_stack([zs, r])), dome=metres(profile),
                   organs=metres(organs),
                   t=sim.state.t, n_bases=sim.state.n_bases, n_patches=sim.patch_count(min_size), n_broken=sim.n_broken)


def _draw(kind: str, data, path: str, min_size: int) -> None:
    if kind == "pattern":
        from bark_cli.plot import plot_pattern

        plot_pattern(data, path, min_size)
    elif kind == "fracture":
        from bark_cli.figures import plot_fracture_history

        plot_fracture_history(data, path)
    elif kind == "tree":
        from bark_cli.tree_picture import plot_tree

        plot_tree(data, path, min_size)
    else:
        from bark_cli.animation import write_gif

        write_gif(data, path, min_size)


def _serve(jobs, replies, command_ends) -> None:
    """The painter: ready matplotlib, then draw what it is sent until told to stop — or until the
    command is gone (its end of the pipe closes: the painter holds no copy of it, so it sees that)."""
    for end in command_ends:
        end.close()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)  # the command decides; it kills the painter if it must
    for module in ("bark_cli.plot", "bark_cli.animation", "bark_cli.tree_picture", "bark_cli.figures"):  # matplotlib, now: this is the point
        importlib.import_module(module)

    while True:
        try:
            job = jobs.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        try:
            _draw(*job)
            replies.send(None)
        except Exception as err:  # reported by the command, one line
            replies.send(f"{type(err).__name__}: {str(err).splitlines()[0][:200] if str(err) else ''}")


class Painter:
    """A drawing process started now (see the module's docstring), or drawing in this process.
    Pictures are handed over by a thread of the command (a picture's data are megabytes, more than a
    pipe holds, and the painter reads them only when it has drawn the one before), so the command
    goes on with its own outputs meanwhile."""

    def __init__(self) -> None:
        self._proc = self._conn = None
        if "fork" in multiprocessing.get_all_start_methods() and sys.platform.startswith("linux"):
            ctx = multiprocessing.get_context("fork")
            jobs, self._jobs = ctx.Pipe(duplex=False)
            self._conn, replies = ctx.Pipe(duplex=False)
            self._proc = ctx.Process(target=_serve, args=(jobs, replies, (self._jobs, self._conn)), daemon=True)
            self._proc.start()
            jobs.close()
            replies.close()
            self._outbox: queue.SimpleQueue = queue.SimpleQueue()
            self._sender = threading.Thread(target=self._send, name="bark-painter-sender", daemon=True)
            self._sender.start()

    def _send(self) -> None:
        """The sending thread: the jobs in order, then ``None`` (stop), to the painter."""
        while True:
            job = self._outbox.get()
            try:
                self._jobs.send(job)
            except (OSError, ValueError):  # the painter is gone (killed): its waits say so
                return
            if job is None:
                return

    def submit(self, kind: str, data, path: Path, min_size: int):
        """Hand ``data`` (``PatternData``, ``TreeData``, ``Frames``, ...) to the drawing process and
        return at once with a ``wait()`` that ends when the
        picture is written (call the waits in the order of submission): the command writes its other
        outputs meanwhile.  ``wait`` raises what drawing raised (a ``RuntimeError`` naming it), or
        ``KeyboardInterrupt`` if a signal stopped it.  Without a drawing process, draws now."""
        if self._proc is None:
            _draw(kind, data, str(path), min_size)
            return lambda stop=False: None
        self._outbox.put((kind, data, str(path), min_size))
        return self._wait

    def _wait(self, stop: bool = False) -> None:
        """The next picture's outcome; with ``stop``, unless it is ready, the drawing is stopped now."""
        try:
            if stop and not self._conn.poll(0):
                raise KeyboardInterrupt
            failure = self._conn.recv()
        except KeyboardInterrupt:
            self.close(kill=True)
            raise
        except (EOFError, OSError):  # OSError: closed already (a signal stopped an earlier one)
            raise RuntimeError("the drawing process ended unexpectedly") from None
        if failure is not None:
            raise RuntimeError(failure)

    def close(self, kill: bool = False) -> None:
        if self._proc is None:
            return
        if kill:
            os.kill(self._proc.pid, signal.SIGKILL)
        self._outbox.put(None)
        self._sender.join(timeout=5)
        self._proc.join(timeout=5)
        if self._proc.is_alive():
            self._proc.kill()
        self._jobs.close()
        self._conn.close()
        self._proc = None
