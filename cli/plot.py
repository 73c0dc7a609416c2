"""The pattern image: the trunk surface unwrapped, patches coloured, intact springs drawn (Fig. 7A); a
pattern too large for its springs to be drawn is a raster of its patches with its broken springs,
the crevices, drawn on it.

Horizontal axis: arc length ``r·θ`` with θ increasing to the right as seen from outside the trunk;
vertical axis: height ``z``.  Patches of at least ``min_size`` bases get a colour each, smaller
fragments are grey.  Uses matplotlib's object API with the Agg canvas (no pyplot, no global state).
"""

from __future__ import annotations

import contextlib
import contextvars
import io
from pathlib import Path

import numpy as np

from bark_cli import matplotlib_folder

matplotlib_folder()  # before matplotlib looks for its own

import matplotlib  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from bark.io.files import atomic_write


def patches(n: int) -> str:
    """``n`` patches, in words: "1 patch", "3 patches"."""
    return f"{n:,} patch" if n == 1 else f"{n:,} patches"


def new_figure(**kwargs) -> Figure:
    """A matplotlib figure (``Figure(**kwargs)``) on the Agg canvas: the object API, no pyplot and
    no global state."""
    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


MAX_ASPECT = 2.0
"""Tallest figure, as height / width: a longer trunk is drawn with its height axis compressed (said
in the title), so the image stays bounded (at most 1050 × 2100 pixels) whatever the scene."""
MIN_ASPECT = 0.4
SPRINGS_UP_TO = 50_000
"""Bases up to which the intact springs are drawn; beyond, the springs would be a solid mat of lines
(and the drawing the slowest part of a run's end), so the patch colours alone show the pattern."""


def plot_pattern(data, path: str | Path, min_size: int = 7, title: str | None = None) -> Path:
    """Draw ``data`` (a ``bark_cli.pictures.PatternData``) into ``path`` (``draw_pattern``), on a
    figure sized to the trunk's aspect within ``MIN_ASPECT`` .. ``MAX_ASPECT``."""
    width = 2 * np.pi * data.radius
    height = float(data.uv[:, 1].max() - data.uv[:, 1].min()) or width
    shown = min(max(height / width, MIN_ASPECT), MAX_ASPECT)
    fig = new_figure(figsize=(7.0, 7.0 * shown + 0.6), dpi=150)
    draw_pattern(fig.add_subplot(), data, min_size, title)
    return save_figure(fig, path)


def draw_pattern(ax, data, min_size: int = 7, title: str | None = None) -> None:
    """Draw ``data`` (a ``bark_cli.pictures.PatternData``; ``PatternData.of(sim, min_size)``) into the
    matplotlib axes ``ax`` — a notebook's, or ``plot_pattern``'s: lengths in metres, time in years (the
    model's units beside them), neighbouring patches in different colours, fragments in the grey the
    legend names."""
    from matplotlib.patches import Patch

    from bark.analysis.pattern import FRAGMENT_GREY
    from bark.units import METRES_PER_LENGTH_UNIT, years

    uv, r = data.uv * METRES_PER_LENGTH_UNIT, data.radius * METRES_PER_LENGTH_UNIT  # metres from here on
    colours = rgba(data.colours)  # neighbouring patches never share a colour
    width = 2 * np.pi * r
    z_lo, z_hi = float(uv[:, 1].min()), float(uv[:, 1].max())
    height = (z_hi - z_lo) or width
    aspect = height / width
    shown = min(max(aspect, MIN_ASPECT), MAX_ASPECT)
    pad = 0.01 * height
    if data.n_bases <= SPRINGS_UP_TO:
        p = data.springs
        seg = np.stack([uv[p[:, 0]], uv[p[:, 1]]], axis=1)
        seg = seg[np.abs(seg[:, 0, 0] - seg[:, 1, 0]) < np.pi * r]  # drop springs across the seam
        ax.add_collection(LineCollection(seg, colors="0.15", alpha=0.6, linewidths=0.4))
        per_base = (72 * 7.0) ** 2 * shown / data.n_bases  # points² of figure per base: a small dot each
        ax.scatter(uv[:, 0], uv[:, 1], s=float(min(4.0, 0.04 * per_base)), c=colours, linewidths=0)
    else:  # too many bases for dots and springs: the patches as a raster, and the crevices drawn on it
        ax.imshow(raster(uv, colours, width, z_lo, z_hi), origin="lower", extent=(0, width, z_lo, z_hi),
                  interpolation="nearest", aspect="auto")
        p = data.cracks
        seg = np.stack([uv[p[:, 0]], uv[p[:, 1]]], axis=1)
        seg = seg[np.abs(seg[:, 0, 0] - seg[:, 1, 0]) < np.pi * r]
        ax.add_collection(LineCollection(seg, colors="0.1", alpha=0.55, linewidths=0.25))
    if (np.bincount(data.labels)[data.labels] < min_size).any():
        ax.legend(handles=[Patch(color=FRAGMENT_GREY / 255.0, label=f"fragments (< {min_size} bases)")],
                  loc="upper right", fontsize=7, framealpha=0.9)
    ax.set_xlim(0, width)
    ax.set_ylim(z_lo - pad, z_hi + pad)
    ax.set_aspect(shown / aspect)
    ax.set_xlabel(f"arc length r·θ (m; 1 length unit = {METRES_PER_LENGTH_UNIT} m; θ increases to the right seen from outside)",
                  fontsize=8)
    ax.set_ylabel("height z (m)" + ("" if shown == aspect else f", scale ×{shown / aspect:.3g} of the horizontal"), fontsize=8)
    ax.set_title(title or f"{years(data.t):.1f} years (t = {data.t:.4g}), radius {100 * r:.1f} cm ({data.radius:.4g} length "
                 f"units), {patches(data.n_patches)} of ≥ {min_size} bases, {data.n_broken} broken springs", fontsize=8)


NO_DATE = {"pdf": {"CreationDate": None}, "svg": {"Date": None}}
"""What keeps a PDF's or SVG's time of writing out of it: the same figure, the same file."""
DPI: contextvars.ContextVar[int | None] = contextvars.ContextVar("dpi", default=None)
"""The resolution pictures are saved at (``picture_dpi``); ``None``: each figure's own."""


@contextlib.contextmanager
def picture_dpi(dpi: int | None):
    """Pictures saved within are saved at ``dpi`` (dots per inch; ``None``: each figure's own)."""
    token = DPI.set(dpi)
    try:
        yield
    finally:
        DPI.reset(token)


def save_figure(fig: Figure, path: str | Path, fast: bool = True) -> Path:
    """Write ``fig`` to ``path`` atomically (drawn whole in memory first: no half-written picture), in
    the format its suffix names (png, pdf, svg), at ``picture_dpi``'s resolution; a PNG with
    ``fast``: zlib level 1 (``FAST_PNG``)."""
    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    dpi = DPI.get()
    buf = io.BytesIO()
    extra = {"pil_kwargs": FAST_PNG} if fast and fmt == "png" else {"metadata": NO_DATE[fmt]} if fmt in NO_DATE else {}
    with matplotlib.rc_context(EDITABLE_TEXT):
        fig.savefig(buf, format=fmt, bbox_inches="tight", dpi=dpi if dpi is not None else "figure", **extra)
    return atomic_write(path, lambda fh: fh.write(buf.getvalue()))


EDITABLE_TEXT = {"pdf.fonttype": 42, "ps.fonttype": 42, "svg.fonttype": "none"}
"""Text that a journal's tools can edit: TrueType fonts in a PDF (matplotlib's default is Type 3),
text as text in an SVG (the default draws each glyph as a path)."""

FAST_PNG = {"compress_level": 1}
"""zlib level of the pictures a run writes: the default (6) took a large share of drawing a
3000-base pattern for a file no smaller (measured when it was set)."""

RASTER_CELLS = 2_000_000
"""Most cells of the raster a large pattern is drawn as (more than the figure has pixels)."""


def raster(uv: np.ndarray, colours: np.ndarray, width: float, z_lo: float, z_hi: float) -> np.ndarray:
    """The pattern as an RGBA image (uint8) of about one cell per base (at most ``RASTER_CELLS``):
    each cell takes the colour of a base in it, and a cell with none that of the nearest base
    (``scipy.ndimage.distance_transform_edt``).  What a scatter of millions of points would show,
    in linear time."""
    return raster_values(uv, np.round(np.asarray(colours) * 255).astype(np.uint8), width, z_lo, z_hi)


def raster_values(uv: np.ndarray, values: np.ndarray, width: float, z_lo: float, z_hi: float) -> np.ndarray:
    """:func:`raster` of any value per base (``values``: one row per base, e.g. RGBA, or a palette
    index): ``(rows, columns, ...)``, row 0 at ``z_lo``."""
    n = uv.shape[0]
    aspect = (z_hi - z_lo) / width or 1.0
    cells = min(n, RASTER_CELLS)
    nx = int(np.clip(np.sqrt(cells / aspect), 16, 8192))
    ny = int(np.clip(cells / nx, 16, 8192))
    ix = np.clip((uv[:, 0] / width * nx).astype(np.int64), 0, nx - 1)
    iy = np.clip(((uv[:, 1] - z_lo) / ((z_hi - z_lo) or 1.0) * ny).astype(np.int64), 0, ny - 1)
    values = np.asarray(values)
    image = np.zeros((ny, nx, *values.shape[1:]), values.dtype)
    image[iy, ix] = values
    empty = np.ones((ny, nx), bool)
    empty[iy, ix] = False
    if empty.any():
        from scipy.ndimage import distance_transform_edt  # here: only a pattern too large for its springs pays

        _, (jy, jx) = distance_transform_edt(empty, return_indices=True)
        image = image[jy, jx]
    return image


def rgba(rgb: np.ndarray) -> np.ndarray:
    """RGB uint8 (``bark.analysis.pattern.patch_colours``) as matplotlib's RGBA floats."""
    rgb = np.asarray(rgb)
    return np.column_stack([rgb / 255.0, np.ones(len(rgb))])


MARKERS = ("o", "s", "^", "D", "v", "P", "X")
DASHES = ("-", "--", ":", "-.")
"""Each method's marker and line style beside its colour: series told apart in grey and with any
colour vision (tab10's green and red look alike under deuteranopia)."""


def plot_work_precision(pos_rows, orders, pat_rows, spread, path, highlight=None, title=""):
    """Work-precision diagram: log-log error against wall time, one line per method, one marker per
    dt or tolerance; the pattern panels shade the seed-to-seed spread (below it: not an error)."""
    from bark.studies.accuracy import METRICS

    fig = new_figure(figsize=(13, 9.5), dpi=120, layout="constrained")
    axes = fig.subplots(2, 2).ravel()
    names = {  # each panel's title and its error axis' label
        "error": ("(a) positions, no breaking: against the reference solution", "max position error (length units)"),
        "broken_rel_diff": ("(b) broken springs, against the fine-dt reference", "|Δ broken springs| / reference"),
        "patch_count_diff": ("(c) patch count, against the fine-dt reference (0 drawn at 0.1)", "|Δ patches of ≥ 7 bases|"),
        "hellinger": ("(d) orientations, against the fine-dt reference", "Hellinger distance of the orientations"),
    }

    methods = list(dict.fromkeys(r["method"] for r in [*pos_rows, *pat_rows]))
    colour = {m: f"C{i % 10}" for i, m in enumerate(methods)}  # one colour per method, in every panel, and
    style = {m: (MARKERS[i % len(MARKERS)], DASHES[i % len(DASHES)]) for i, m in enumerate(methods)}  # apart in grey too

    def lines(ax, rows, key, floor):
        for method in dict.fromkeys(r["method"] for r in rows):
            mine = [r for r in rows if r["method"] == method and np.isfinite(r[key])]
            if not mine:
                continue
            x = [r["wall_s"] for r in mine]
            y = [max(r[key], floor) for r in mine]
            label = method + (f" (order {orders[method]:.2f})" if key == "error" and method in orders else "")
            marker, dashes = style[method]
            (line,) = ax.plot(x, y, marker=marker, ls=dashes, label=label, ms=5, color=colour[method])
            for r, xi, yi in zip(mine, x, y):
                ax.annotate(f"{r['param']:g}", (xi, yi), textcoords="offset points", xytext=(4, 3), fontsize=7,
                            color=line.get_color())
                if highlight and (r["method"], r["param"]) == tuple(highlight):
                    ax.plot([xi], [yi], "*", ms=16, color=line.get_color(), mec="k", label="default")

    lines(axes[0], pos_rows, "error", 1e-12)
    for ax, key in zip(axes[1:], METRICS):
        floor = 1e-4 if key != "patch_count_diff" else 0.1
        lines(ax, pat_rows, key, floor)
        if np.isfinite(spread[key]) and spread[key] > floor:  # the seeds' own spread: a line, not a band over the panel
            ax.axhline(spread[key], color="0.35", ls="--", lw=1.0, zorder=0,
                       label=f"seed-to-seed spread ({spread[key]:.3g}): below it, no error that matters")
    from matplotlib.ticker import NullFormatter

    for ax, key in zip(axes, ["error", *METRICS]):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())  # the minor labels of a short decade ran into each other
        ax.set_xlabel("wall time (s)")
        ax.set_title(names[key][0], fontsize=10)
        ax.set_ylabel(names[key][1], fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.suptitle(f"bark work-precision — {title}; markers: dt (fixed) or overshoot tolerance (adaptive)", fontsize=11)
    return save_figure(fig, path, fast=False)
