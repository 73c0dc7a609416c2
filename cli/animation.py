"""The development animation: the unwrapped pattern through time, like the paper's videos S1–S3.

Frames are recorded along the way (``bark.io.recorders.Frames``, an action on ``Every(frame_every)``),
only when a scene asks for the ``animation`` effect; this module draws them into a GIF with
Pillow (matplotlib's own image dependency), with the figure bounded as ``pattern.png``'s is.

The axes, ticks and labels are drawn once by matplotlib.  A small pattern's frames are its bases
as dots, drawn over them by matplotlib; a large pattern's (a raster, as ``pattern.png`` draws it)
are composed as palette images directly: the axes quantized once to the colours they use, the
raster's cells placed into the axes' pixels in the patch palette's colours, the title written by
Pillow in matplotlib's font — no drawing, resampling or quantizing per frame (the whole tree's 21
frames in about half the time).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from bark.model.components import count_patches
from bark.io.recorders import Frames
from bark.io.files import atomic_write
from bark.analysis.pattern import rgb
from bark.units import metres
from bark_cli.plot import MAX_ASPECT, MIN_ASPECT, SPRINGS_UP_TO, new_figure, patches, raster_values, rgba


def write_gif(frames: Frames, path: str | Path, min_size: int = 7, fps: int = 8) -> Path:
    """Write ``frames`` (:class:`~bark.io.recorders.Frames`) as the development animation at ``path``: each frame
    the unwrapped pattern at its time on common axes in metres, patches of at least ``min_size`` bases
    coloured, ``fps`` frames a second; returns the path."""
    if not frames.frames:
        raise ValueError("no frames recorded")
    width = metres(max(2 * np.pi * r for _, r, _, _ in frames.frames))
    z = metres(np.concatenate([uv[:, 1] for _, _, uv, _ in frames.frames]))
    height = float(np.ptp(z)) or width
    aspect = height / width
    shown = min(max(aspect, MIN_ASPECT), MAX_ASPECT)
    fig = new_figure(figsize=(7.0, 7.0 * shown + 0.6), dpi=90)
    ax = fig.add_subplot()
    ax.set_xlim(0, width)
    ax.set_ylim(z.min() - 0.01 * height, z.max() + 0.01 * height)
    ax.set_aspect(shown / aspect)
    ax.set_xlabel("arc length r·θ (m)")
    ax.set_ylabel("height z (m)")
    title = ax.set_title(" ", fontsize=9)
    n = max(uv.shape[0] for _, _, uv, _ in frames.frames)
    draw = _dots if n <= SPRINGS_UP_TO else _cells
    images = draw(fig, ax, title, frames, n, min_size)
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
    return atomic_write(path, lambda fh: fh.write(buf.getvalue()))


def _caption(t: float, r: float, labels: np.ndarray, min_size: int) -> str:
    from bark.units import metres, years

    return (f"t = {t:.1f} ({years(t):.1f} years)   r = {r:.3f} ({100 * metres(r):.1f} cm)   "
            f"{patches(count_patches(labels, min_size))}")


def _dots(fig, ax, title, frames: Frames, n: int, min_size: int) -> list[Image.Image]:
    """Each frame's bases as dots, drawn by matplotlib over the axes drawn once."""
    points = ax.scatter([], [], s=float(np.clip(3.0 * 3000 / n, 0.05, 3.0)), linewidths=0)
    fig.canvas.draw()  # the axes, their ticks and labels, once: each frame draws only its pattern and title over them
    background = fig.canvas.copy_from_bbox(fig.bbox)
    images = []
    for k, (t, r, uv, labels) in enumerate(frames.frames):
        points.set_offsets(metres(uv))
        points.set_color(rgba(rgb(frames.colour_index(k, min_size))))
        title.set_text(_caption(t, r, labels, min_size))
        fig.canvas.restore_region(background)
        for artist in (points, *ax.spines.values(), title):  # the spines over the pattern, as a full draw has them
            ax.draw_artist(artist)
        shot = Image.fromarray(np.asarray(fig.canvas.buffer_rgba())).convert("RGB")
        images.append(shot.quantize(colors=128, method=Image.Quantize.FASTOCTREE))  # far faster than median cut
    return images


def _cells(fig, ax, title, frames: Frames, n: int, min_size: int) -> list[Image.Image]:
    """Each frame's raster placed into the axes drawn once, as palette images (see the module's
    docstring): the axes' own colours first, then the patches' (``bark.analysis.pattern.PALETTE``, then the
    fragments' grey)."""
    from bark.analysis.pattern import FRAGMENT_GREY, PALETTE

    fig.canvas.draw()
    rgb = np.asarray(fig.canvas.buffer_rgba())[..., :3]
    rows = rgb.shape[0]
    ours = np.vstack([PALETTE, FRAGMENT_GREY])
    axes = Image.fromarray(rgb).quantize(colors=256 - len(ours), method=Image.Quantize.FASTOCTREE)
    background = np.asarray(axes)
    own = np.asarray(axes.getpalette()[:3 * (int(background.max()) + 1)], dtype=np.uint8).reshape(-1, 3)
    palette = np.vstack([own, ours])
    colours = palette.ravel().tolist()
    to_pixels = ax.transData.transform
    inner = ax.bbox.padded(-1.0 - max(s.get_linewidth() for s in ax.spines.values()) * fig.dpi / 72.0)  # spines stay
    font = ImageFont.truetype(_font_file(title), size=title.get_fontsize() * fig.dpi / 72.0)
    box = title.get_window_extent()
    at = ((box.x0 + box.x1) / 2, rows - box.y0)  # the title's middle and its descender line, in image rows
    above = int(np.ceil(rows - ax.bbox.y1))  # the rows above the axes, where the title is written
    ink = _grey_levels(palette, np.asarray(_rgb(title.get_color())))
    images = []
    for k, (t, r, uv, labels) in enumerate(frames.frames):
        lo, hi = float(uv[:, 1].min()), float(uv[:, 1].max())
        cells = raster_values(uv, frames.colour_index(k, min_size) + len(own), 2 * np.pi * r, lo, hi)
        frame = background.copy()
        (x0, y0), (x1, y1) = to_pixels(metres(np.array([(0.0, lo), (2 * np.pi * r, hi)])))
        cols = np.arange(int(np.ceil(max(x0, inner.x0) - 0.5)), int(np.floor(min(x1, inner.x1) - 0.5)) + 1)
        ys = np.arange(int(np.ceil(max(y0, inner.y0) - 0.5)), int(np.floor(min(y1, inner.y1) - 0.5)) + 1)
        if cols.size and ys.size and x1 > x0 and y1 > y0:  # pixel centres inside the pattern's extent take its cells
            cx = np.clip(((cols + 0.5 - x0) / (x1 - x0) * cells.shape[1]).astype(np.int64), 0, cells.shape[1] - 1)
            cy = np.clip(((ys + 0.5 - y0) / (y1 - y0) * cells.shape[0]).astype(np.int64), 0, cells.shape[0] - 1)
            frame[rows - 1 - ys[:, None], cols[None, :]] = cells[cy[:, None], cx[None, :]]
        text = Image.new("L", (frame.shape[1], above), 0)
        ImageDraw.Draw(text).text(at, _caption(t, r, labels, min_size), fill=255, font=font, anchor="md")
        coverage = np.asarray(text)
        written = coverage > 0
        frame[:above][written] = ink[coverage[written]]
        image = Image.fromarray(frame, mode="P")
        image.putpalette(colours)
        images.append(image)
    return images


def _font_file(text) -> str:
    from matplotlib.font_manager import findfont

    return findfont(text.get_fontproperties())


def _rgb(colour) -> tuple[int, int, int]:
    from matplotlib.colors import to_rgb

    return tuple(int(round(255 * c)) for c in to_rgb(colour))


def _grey_levels(palette: np.ndarray, ink: np.ndarray) -> np.ndarray:
    """For each coverage 0–255 of a glyph's pixel, the palette entry nearest the ink laid that much
    over white."""
    cover = np.arange(256)[:, None] / 255.0
    wanted = (1.0 - cover) * 255.0 + cover * ink[None, :]
    distance = ((wanted[:, None, :] - palette[None, :, :].astype(float)) ** 2).sum(axis=-1)
    return np.argmin(distance, axis=1).astype(np.uint8)
