"""The development animation: the unwrapped pattern through time, like the paper's videos S1–S3.

Frames are recorded along the way by an action on a trigger (``Every(frame_every)``), only when a
scene asks for the ``animation`` effect; each frame keeps the unwrapped positions and patch labels
(float32/int32), and the GIF is drawn at the end with matplotlib's Pillow writer.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from bark.output import atomic_write
from bark_cli.plot import patch_colours, unwrap


class Frames:
    def __init__(self) -> None:
        self.frames: list[tuple[float, float, np.ndarray, np.ndarray]] = []

    def record(self, sim) -> None:
        if self.frames and self.frames[-1][0] == sim.state.t:
            return
        r = sim.radius
        self.frames.append((sim.state.t, r, unwrap(sim.state.x, r).astype(np.float32), sim.patch_labels().astype(np.int32)))

    def write(self, path: str | Path, min_size: int = 7, fps: int = 8) -> Path:
        if not self.frames:
            raise ValueError("no frames recorded")
        width = max(2 * np.pi * r for _, r, _, _ in self.frames)
        z = np.concatenate([uv[:, 1] for _, _, uv, _ in self.frames])
        fig = Figure(figsize=(7.0, max(3.0, 7.0 * float(np.ptp(z) or 1.0) / width) + 0.6), dpi=90)
        FigureCanvasAgg(fig)
        ax = fig.add_subplot()
        ax.set_xlim(0, width)
        ax.set_ylim(z.min() - 0.01, z.max() + 0.01)
        ax.set_aspect("equal")
        ax.set_xlabel("arc length r·θ")
        ax.set_ylabel("height z")
        points = ax.scatter([], [], s=3, linewidths=0)

        def draw(i):
            t, r, uv, labels = self.frames[i]
            points.set_offsets(uv)
            points.set_color(patch_colours(labels, min_size))
            n = int(np.count_nonzero(np.bincount(labels) >= min_size))
            ax.set_title(f"t = {t:.1f}   r = {r:.3f}   {n} patches", fontsize=9)
            return (points,)

        anim = FuncAnimation(fig, draw, frames=len(self.frames), blit=False)
        tmp = Path(path).with_suffix(".tmp.gif")
        anim.save(tmp, writer=PillowWriter(fps=fps))
        data = tmp.read_bytes()
        tmp.unlink()
        return atomic_write(path, lambda fh: fh.write(data))
