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
import signal
import sys
from pathlib import Path

import attrs
import numpy as np

from bark.output import unwrap


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


def _serve(conn, commands_end) -> None:
    """The painter: ready matplotlib, then draw what it is sent until told to stop — or until the
    command is gone (its end of the pipe closes: the painter holds no copy of it, so it sees that)."""
    commands_end.close()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)  # the command decides; it kills the painter if it must
    for module in ("bark_cli.plot", "bark_cli.animation", "bark_cli.tree_picture", "bark_cli.figures"):  # matplotlib, now: this is the point
        importlib.import_module(module)

    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        try:
            _draw(*job)
            conn.send(None)
        except Exception as err:  # reported by the command, one line
            conn.send(f"{type(err).__name__}: {str(err).splitlines()[0][:200] if str(err) else ''}")


class Painter:
    """A drawing process started now (see the module's docstring), or drawing in this process."""

    def __init__(self) -> None:
        self._proc = self._conn = None
        if "fork" in multiprocessing.get_all_start_methods() and sys.platform.startswith("linux"):
            ctx = multiprocessing.get_context("fork")
            self._conn, child = ctx.Pipe()
            self._proc = ctx.Process(target=_serve, args=(child, self._conn), daemon=True)
            self._proc.start()
            child.close()

    def draw(self, kind: str, data, path: Path, min_size: int) -> None:
        """Draw ``data`` (``PatternData`` or ``Frames``) into ``path``; raises what drawing raised
        (a ``RuntimeError`` naming it), or ``KeyboardInterrupt`` if a signal stopped it."""
        if self._proc is None:
            return _draw(kind, data, str(path), min_size)
        try:
            self._conn.send((kind, data, str(path), min_size))
            failure = self._conn.recv()
        except KeyboardInterrupt:
            self.close(kill=True)
            raise
        except (EOFError, OSError):
            raise RuntimeError("the drawing process ended unexpectedly") from None
        if failure is not None:
            raise RuntimeError(failure)

    def close(self, kill: bool = False) -> None:
        if self._proc is None:
            return
        if kill:
            os.kill(self._proc.pid, signal.SIGKILL)
        else:
            try:
                self._conn.send(None)
            except OSError:
                pass
        self._proc.join(timeout=5)
        if self._proc.is_alive():
            self._proc.kill()
        self._conn.close()
        self._proc = None
