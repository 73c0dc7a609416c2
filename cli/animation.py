"""The development animation: the unwrapped pattern through time, like the paper's videos S1–S3.

Frames are recorded along the way (``bark.output.Frames``, an action on ``Every(frame_every)``),
only when a scene asks for the ``animation`` effect; this module draws them into a GIF with
Pillow (matplotlib's own image dependency), with the figure bounded as ``pattern.png``'s is.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image

from bark.analysis import count_patches
from bark.output import Frames, atomic_write
from bark_cli.plot import MAX_ASPECT, MIN_ASPECT, SPRINGS_UP_TO, new_figure, patch_colours, raster


def write_gif(frames: Frames, path: str | Path, min_size: int = 7, fps: int = 8) -> Path:
    if not frames.frames:
        raise ValueError("no frames recorded")
    width = max(2 * np.pi * r for _, r, _, _ in frames.frames)
    z = np.concatenate([uv[:, 1] for _, _, uv, _ in frames.frames])
    height = float(np.ptp(z)) or width
    aspect = height / width
    shown = min(max(aspect, MIN_ASPECT), MAX_ASPECT)
    fig = new_figure(figsize=(7.0, 7.0 * shown + 0.6), dpi=90)
    ax = fig.add_subplot()
    ax.set_xlim(0, width)
    ax.set_ylim(z.min() - 0.01 * height, z.max() + 0.01 * height)
    ax.set_aspect(shown / aspect)
    ax.set_xlabel("arc length r·θ")
    ax.set_ylabel("height z")
    n = max(uv.shape[0] for _, _, uv, _ in frames.frames)
    if n <= SPRINGS_UP_TO:
        points = ax.scatter([], [], s=float(np.clip(3.0 * 3000 / n, 0.05, 3.0)), linewidths=0)
    else:  # a large pattern as a raster (as pattern.png draws it): 5x faster a frame than 70,000 dots
        cells = ax.imshow(np.zeros((1, 1, 4), np.uint8), origin="lower", interpolation="nearest", aspect="auto")

    title = ax.set_title(" ", fontsize=9)
    fig.canvas.draw()  # the axes, their ticks and labels, once: each frame draws only its pattern and title over them
    background = fig.canvas.copy_from_bbox(fig.bbox)
    shapes = points if n <= SPRINGS_UP_TO else cells

    def draw(i):
        t, r, uv, labels = frames.frames[i]
        colours = patch_colours(labels, min_size)
        if n <= SPRINGS_UP_TO:
            points.set_offsets(uv)
            points.set_color(colours)
        else:
            lo, hi = float(uv[:, 1].min()), float(uv[:, 1].max())
            cells.set_data(raster(uv, colours, 2 * np.pi * r, lo, hi))
            cells.set_extent((0.0, 2 * np.pi * r, lo, hi))
        count = count_patches(labels, min_size)
        title.set_text(f"t = {t:.1f}   r = {r:.3f}   {count} patches")

    images = []
    for i in range(len(frames.frames)):
        draw(i)
        fig.canvas.restore_region(background)
        for artist in (shapes, *ax.spines.values(), title):  # the spines over the pattern, as a full draw has them
            ax.draw_artist(artist)
        rgb = Image.fromarray(np.asarray(fig.canvas.buffer_rgba())).convert("RGB")
        images.append(rgb.quantize(colors=128, method=Image.Quantize.FASTOCTREE))  # 5x median cut's speed
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
    return atomic_write(path, lambda fh: fh.write(buf.getvalue()))
