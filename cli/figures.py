"""The paper's statistical figures, drawn from ``bark.analysis.pattern`` / ``bark.analysis.compare`` objects.

* ``plot_radial``: orientation × anisotropy per patch on a polar plot (Fig. 6B / 7B): angle =
  orientation (90° = up the trunk), radius = anisotropy 0–1, each patch drawn at θ and θ + 180° (an
  axis has two ends), colour = patch size in leaf bases; mean, SD and SE printed.
* ``plot_histogram``: the orientations in 10 bins of 18° (Fig. 6C / 7C) centred on 0°, 18°, ..., 90°,
  ..., bar length = patches.
* ``plot_regions``: ``plot_radial``'s view for each region of the trunk side by side (near bulges,
  away from them, grown during the run): the comparison of Fig. 11.
* ``plot_quartets``: the quartet diagrams (Fig. 8D–G): four boxes, Hellinger distances with the two
  shortest edges blue and solid, the third orange and dashed, the three longest grey and dotted; and
  the d_P edges, each box's smallest outgoing d_P blue and bold.

Matplotlib's object API on the Agg canvas (no pyplot), files written atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.colors import LogNorm, Normalize
from matplotlib.ticker import MaxNLocator, NullFormatter

from bark.analysis.compare import QUANTITIES, Comparison
from bark.analysis.pattern import PatternStatistics
from bark.units import metres, years
from bark_cli.options import value_text
from bark_cli.plot import new_figure, patches, save_figure

BINS = 10
NEAR, THIRD = "#0072B2", "#D55E00"
"""The quartet figure's two meanings (Okabe and Ito's blue and vermillion, told apart by dichromats),
each with its own line style too."""
"""Histogram bins over [0°, 180°): 18° each, as in the paper."""


def _caption(s: PatternStatistics) -> str:
    o, a = s.orientation, s.anisotropy
    text = f"μθ = {o.mean_deg:.1f}°  SD {o.sd_deg:.1f}°  SE {o.se_deg:.2f}°"
    if a is not None:
        text += f"\nμR = {a.mean:.3f}  SD {a.sd:.3f}  SE {a.se:.4f}"
    return text + f"\n{patches(s.n_patches)}"


def draw_radial(ax, stats: PatternStatistics):
    """Fig. 6B / 7B for ``stats`` (which must have its patches) into ``ax``, a polar axes (a notebook's
    ``fig.add_subplot(projection="polar")``); returns the scatter (for a colour bar of patch sizes)."""
    table = stats.patches
    theta = np.radians(table.orientation_deg)
    size = table.size.astype(float)
    both = np.concatenate([theta, theta + np.pi])
    lo = float(size.min()) if size.size else 1.0  # the smallest patch drawn (``initial`` would count as one)
    hi = float(size.max()) if size.size else lo
    norm = LogNorm(lo, hi) if hi > 10 * lo else Normalize(lo, max(hi, lo + 1))  # a few huge patches: log scale
    art = ax.scatter(both, np.concatenate([table.anisotropy] * 2), c=np.concatenate([size] * 2), cmap="viridis",
                     norm=norm, s=18, edgecolors="k", linewidths=0.3)
    mean = np.radians(stats.orientation.mean_deg)
    if np.isfinite(mean):
        ax.plot([mean, mean + np.pi], [1, 1], color="crimson", lw=1.2, label="mean axis")
    ax.set_ylim(0, 1)
    ax.set_yticks(np.linspace(0.1, 1.0, 10), labels=[""] * 9 + ["1"], fontsize=7)
    ax.set_xticks(np.radians(np.arange(0, 360, 45)))
    ax.tick_params(labelsize=7)
    ax.set_title(f"{stats.name}: orientation (angle, 90° = up the trunk) × anisotropy (radius)", fontsize=8)
    return art


def plot_radial(stats: PatternStatistics, path: str | Path) -> Path:
    """Fig. 6B / 7B for ``stats`` (which must have its patches) into ``path`` (``draw_radial``)."""
    fig = new_figure(figsize=(5.6, 5.0), dpi=130)
    ax = fig.add_subplot(projection="polar")
    cb = fig.colorbar(draw_radial(ax, stats), ax=ax, shrink=0.7, pad=0.1)
    cb.set_label("patch size (leaf bases)", fontsize=8)
    fig.text(0.02, 0.02, _caption(stats), fontsize=7, family="monospace")
    return save_figure(fig, path)


def plot_regions(data, path: str | Path, min_size: int = 7) -> Path:
    """regions.png: for each region of the trunk (``bark_cli.pictures.RegionsData``) its patches'
    orientation (angle, 90° = up the trunk) against anisotropy (radius), as Fig. 6B, with the mean
    axis and the region's statistics — the comparison of the paper's Fig. 11, region by region."""
    k = len(data.names)
    fig = new_figure(figsize=(3.6 * k, 4.4), dpi=130)
    for i, (name, deg, aniso, s) in enumerate(zip(data.names, data.orientation, data.anisotropy, data.summaries)):
        ax = fig.add_subplot(1, k, i + 1, projection="polar")
        theta = np.radians(deg)
        ax.scatter(np.concatenate([theta, theta + np.pi]), np.concatenate([aniso, aniso]), s=6, color="tab:blue",
                   edgecolors="none", alpha=0.6)
        mean = s.get("mean_orientation_deg")
        if mean is not None and np.isfinite(mean):
            ax.plot([np.radians(mean), np.radians(mean) + np.pi], [1, 1], color="crimson", lw=1.2)
        ax.set_ylim(0, 1)
        ax.set_yticks(np.linspace(0.25, 1.0, 4), labels=["", "", "", "1"], fontsize=6)
        ax.set_xticks(np.radians(np.arange(0, 360, 45)))
        ax.tick_params(labelsize=6)
        ax.set_title(f"{name}: {patches(len(deg))} of ≥ {min_size} bases", fontsize=8)
        share = s.get("largest_patch_share")
        lines = [f"mean {mean:.1f}°, SD {s['circular_sd_deg']:.1f}°" if len(deg) else "no patches",
                 f"anisotropy {s['mean_anisotropy']:.2f}" if len(deg) else "",
                 f"largest patch: {100 * share:.1f} % of its bases" if share is not None else ""]
        ax.text(0.5, -0.16, "\n".join(x for x in lines if x), transform=ax.transAxes, ha="center", va="top", fontsize=7)
    fig.suptitle(f"Patches by region of the trunk at {years(data.t):.1f} years: orientation (angle; 90° up the trunk) "
                 "× anisotropy (radius); red: the mean axis", fontsize=8)
    fig.subplots_adjust(bottom=0.22, top=0.82, wspace=0.35)
    return save_figure(fig, path)


def orientation_counts(deg) -> np.ndarray:
    """Patches per bin of orientation, ``BINS`` bins of 180°/BINS centred on 0°, 18°, ..., 162° (the
    first wraps round: 171°–180° and 0°–9°), so that one bar holds the patches near vertical (90°)
    on either side of it."""
    width = 180.0 / BINS
    return np.histogram(np.mod(np.asarray(deg, float) + width / 2, 180.0), bins=BINS, range=(0.0, 180.0))[0]


def draw_histogram(ax, stats: PatternStatistics) -> None:
    """Fig. 6C / 7C for ``stats`` into ``ax``, a polar axes: patches per 18° bin of orientation
    (``orientation_counts``)."""
    counts = orientation_counts(stats.patches.orientation_deg)
    width = 180.0 / BINS
    centres = np.arange(BINS) * width  # the bins centred on 0°, 18°, ..., 90°, ...: vertical patches in one bar
    for at in (centres, [180.0]):  # the horizontal bin is drawn at both ends of the half circle (axial angles)
        ax.bar(np.radians(at), counts[: len(at)], width=np.radians(width), align="center", color="#0072B2",
               edgecolor="k", linewidth=0.5)
    ax.set_thetamin(0)
    ax.set_thetamax(180)
    top = max(int(counts.max(initial=0)), 1)
    step = max(1, int(np.ceil(top / 5)))
    ax.set_yticks(np.arange(step, top + 1, step))
    ax.tick_params(labelsize=7)
    ax.set_title(f"{stats.name}: patches (bar length) per 18° of orientation (0° horizontal, 90° up the trunk)",
                 fontsize=8)


def plot_histogram(stats: PatternStatistics, path: str | Path) -> Path:
    """Fig. 6C / 7C for ``stats`` into ``path`` (``draw_histogram``)."""
    fig = new_figure(figsize=(5.6, 3.4), dpi=130)
    draw_histogram(fig.add_subplot(projection="polar"), stats)
    fig.text(0.02, 0.02, _caption(stats), fontsize=7, family="monospace")
    return save_figure(fig, path)


_CORNERS = np.array([[0.0, 1.0], [1.0, 1.0], [0.0, 0.0], [1.0, 0.0]])  # P top left, Q top right, R, S


def _boxes(ax, names) -> None:
    for (x, y), name in zip(_CORNERS, names):
        ax.text(x, y, name, ha="center", va="center", fontsize=7, wrap=True,
                bbox={"boxstyle": "round", "fc": "lightyellow", "ec": "0.3"})
    ax.set_xlim(-0.35, 1.35)
    ax.set_ylim(-0.25, 1.25)
    ax.set_axis_off()


def draw_quartet(ax, comparison: Comparison, quantity: str) -> None:
    """Fig. 8D or E into ``ax``: the quartet of four patterns by the Hellinger distances of
    ``quantity`` (``orientation`` or ``anisotropy``): the two shortest edges, the third, the three
    longest, and whether the pairing they infer is valid.  ``comparison``: of four patterns
    (``bark.analysis.compare.compare``)."""
    q = comparison.quartets[quantity]
    _boxes(ax, comparison.names)
    if q is None:
        ax.set_title(f"{quantity}: no quartet (a pattern does not give it)", fontsize=8)
        return
    for rank, (i, j, dist) in enumerate(q.edges):
        (x0, y0), (x1, y1) = _CORNERS[i], _CORNERS[j]
        style = {0: (NEAR, "-"), 1: (NEAR, "-"), 2: (THIRD, "--")}.get(rank, ("0.6", ":"))
        ax.plot([x0, x1], [y0, y1], color=style[0], ls=style[1], lw=2 if rank < 3 else 1, zorder=0)
        t = 0.5 if (i, j) not in ((0, 3), (1, 2)) else (0.35 if (i, j) == (0, 3) else 0.65)
        ax.text(x0 + t * (x1 - x0), y0 + t * (y1 - y0), f"{dist:.3f}", fontsize=7, ha="center", va="center",
                color=style[0], bbox={"fc": "white", "ec": "none", "pad": 0.5})
    verdict = "valid" if q.valid else "not valid"
    ax.set_title(f"{quantity}, Hellinger distance: quartet {verdict}" + (" (tie)" if q.tied else ""), fontsize=8)


def draw_pairing(ax, comparison: Comparison, quantity: str) -> None:
    """Fig. 8F or G into ``ax``: each of four patterns' nearest by ``d_P`` of ``quantity`` (the
    difference of means in standard errors of the arrow's tail), and whether they pair up."""
    dp, p = comparison.d_p[quantity], comparison.pairings[quantity]
    _boxes(ax, comparison.names)
    if p is None:
        ax.set_title(f"{quantity}: no d_P pairing (a pattern does not give it)", fontsize=8)
        return
    for i in range(4):
        for j in range(4):
            if i == j:
                continue
            (x0, y0), (x1, y1) = _CORNERS[i], _CORNERS[j]
            colour = NEAR if p.nearest[i] == j else "0.55"
            normal = np.array([y1 - y0, x0 - x1]) * 0.03  # the two directions of a pair side by side
            a = np.array([x0, y0]) + normal + 0.18 * np.array([x1 - x0, y1 - y0])
            b = np.array([x0, y0]) + normal + 0.82 * np.array([x1 - x0, y1 - y0])
            ax.annotate("", xy=b, xytext=a, arrowprops={"arrowstyle": "->", "color": colour, "lw": 2.0 if colour == NEAR else 1.0})
            label = a + 0.12 * (b - a) / max(np.hypot(*(b - a)), 1e-9) + normal * 2.5
            ax.text(*label, f"{dp[i, j]:.2g}", fontsize=6, color=colour, ha="center", va="center")
    ax.set_title(f"{quantity}, d_P (SE of the arrow's tail): pairing {'valid' if p.valid else 'not valid'}", fontsize=8)


def plot_quartets(comparison: Comparison, path: str | Path) -> Path:
    """Fig. 8D–G for four patterns into ``path``: a row per quantity, Hellinger quartet then d_P."""
    given = [q for q in QUANTITIES if comparison.quartets[q] is not None or comparison.pairings[q] is not None]
    shown = given or list(QUANTITIES)  # a quantity no pattern's figures give has no row: a note says so
    fig = new_figure(figsize=(10.0, 4.5 * len(shown) + 0.5), dpi=120, layout="constrained")
    axes = np.atleast_2d(fig.subplots(len(shown), 2, squeeze=False))
    for row, quantity in zip(axes, shown):
        draw_quartet(row[0], comparison, quantity)
        draw_pairing(row[1], comparison, quantity)
    missing = [q for q in QUANTITIES if q not in shown]
    fig.suptitle("quartet analysis (blue, solid: the two shortest edges / each pattern's nearest, bold; orange, "
                 "dashed: the third; grey, dotted: the three longest)"
                 + (f"\nno {', '.join(missing)}: a pattern's figures do not give it" if missing else ""), fontsize=9)
    return save_figure(fig, path)


def plot_montage(plan, points, rows: dict, table, path: str | Path) -> Path | None:
    """The sweep's patterns on one sheet, like the paper's Fig. 9: the first axis across (its values
    growing to the right), the second up (growing upwards), the first seed's run in each cell,
    patches coloured, with its patch count and mean orientation.  ``None`` when no run is in the
    table yet.  ``rows``: the table's rows by key (read once); ``table`` gives the patterns.  The
    sheet stays within 16 × 16 inches whatever the grid."""
    from bark_cli.plot import raster, rgba

    first = {p.index: p for p in reversed(points)}  # the first seed of each grid point
    shape = plan.shape + (1,) * (2 - len(plan.shape))
    ncols, nrows = shape[0], shape[1]
    cell = min(2.4, 16.0 / max(ncols, nrows))
    fig = new_figure(figsize=(cell * ncols + 0.8, cell * 1.25 * nrows + 0.8), dpi=110, layout="constrained")
    axes = np.atleast_2d(fig.subplots(nrows, ncols, squeeze=False))
    drawn, tallest = 0, 0.0  # the cells' largest height / width: the sheet is sized to it once they are drawn
    for index, p in first.items():
        i, j = (index + (0, 0))[:2]
        ax = axes[nrows - 1 - j, i]  # the second axis grows upwards
        ax.set_xticks([])
        ax.set_yticks([])
        got = table.pattern(p.key)
        row = rows.get(p.key)  # the table's rows by key, read once
        if got is None or row is None:
            ax.text(0.5, 0.5, "not run", ha="center", va="center", fontsize=7, color="0.5")
            continue
        uv, _, colours = got
        width = 2 * np.pi * row["radius"]
        z_lo, z_hi = float(uv[:, 1].min()), float(uv[:, 1].max())
        ax.imshow(raster(uv, rgba(colours), width, z_lo, z_hi), origin="lower",  # to scale: a 45° crack looks 45°
                  extent=metres(np.array([0, width, z_lo, z_hi])), interpolation="nearest", aspect="equal")
        tallest = max(tallest, (z_hi - z_lo) / width)
        mean = row["mean_orientation_deg"]
        count = row["n_patches"]
        ax.set_title(f"{count} patch{'' if count == 1 else 'es'}" + ("" if mean is None else f", {mean:.0f}°")
                     + f"; {100 * metres(width):.0f} × {100 * metres(z_hi - z_lo):.0f} cm", fontsize=6)
        drawn += 1
    for i, v in enumerate(plan.axes[0].values):
        axes[-1, i].set_xlabel(f"{plan.axes[0].key} = {value_text(v)}", fontsize=7)
    if len(plan.axes) == 2:
        for j, v in enumerate(plan.axes[1].values):
            axes[nrows - 1 - j, 0].set_ylabel(f"{plan.axes[1].key} = {value_text(v)}", fontsize=7)
    fig.suptitle("bark sweep: the unwrapped trunk of each run, to scale (arc length across, height up, the size "
                 "in each title; patches coloured, fragments grey)", fontsize=8)
    if drawn:
        fig.set_size_inches(cell * ncols + 0.8, cell * min(max(tallest, 0.2), 4.0) * nrows + 1.0)
    return save_figure(fig, path) if drawn else None


def plot_fracture_history(history, path: str | Path) -> Path:
    """A run's fracture history (``bark.analysis.fracture.FractureHistory``): broken springs and cracks (top),
    patches and the damping's power per base (bottom) against time in years; the initial fractures
    (the most cracks at once) and the initial fracture phase marked."""
    from bark.units import metres, years

    s = history.samples
    t = years(s["t"])
    fig = new_figure(figsize=(7.0, 5.6), dpi=130)
    top, bottom = fig.subplots(2, 1, sharex=True)
    top.plot(t, s["n_broken"], color="0.3", lw=1.2, label="broken springs")
    top.plot(t, s["n_cracks"], color=THIRD, lw=1.2, ls="--", label="cracks")
    if history.first_break_t is not None:
        for ax in (top, bottom):
            ax.axvspan(years(history.first_break_t), years(history.initial_fractures_t), color="gold", alpha=0.25, lw=0)
        top.plot([years(history.initial_fractures_t)], [history.initial_fractures], "o", color=THIRD, ms=4,
                 label=f"initial fractures: {history.initial_fractures}")
    top.set_ylabel("count")
    top.legend(fontsize=7, frameon=False)
    bottom.plot(t, s["n_patches"], color=NEAR, lw=1.2, label="patches")
    bottom.set_ylabel("patches", color=NEAR)
    bottom.yaxis.set_major_locator(MaxNLocator(integer=True))
    power = bottom.twinx()
    power.plot(t, s["dissipation"], color=THIRD, lw=1.0, ls="--", label="damping power per base")
    power.set_ylabel("damping power per base\n(force × length / time unit)", color=THIRD)
    if history.dissipation_rate is not None:
        power.axhline(history.dissipation_rate, color=THIRD, ls=":", lw=1.0,
                      label=f"its mean over the initial fracture phase: {history.dissipation_rate:.3g}")
    handles = [h for ax in (bottom, power) for h in ax.get_legend_handles_labels()[0]]
    bottom.legend(handles=handles, fontsize=7, frameon=False, loc="upper left")
    bottom.set_xlabel("time (years)")
    top.set_title("fracture history (shaded: first break to the most cracks)", fontsize=9)
    return save_figure(fig, path)


def plot_power_law(x: np.ndarray, y: np.ndarray, groups: np.ndarray, fit, path: str | Path, group_label: str,
                   xlabel: str, check=None) -> Path:
    """Initial fractures against the dissipation rate on log–log axes, one colour and marker per value
    of ``groups`` (a swept setting), with the fitted power law ``fit`` (``bark.analysis.fracture.PowerLaw``)
    and, given, its ``check`` (``PowerLawCheck``: the F tests' p in the title)."""
    fig = new_figure(figsize=(7.8, 4.6), dpi=130)
    ax = fig.add_axes((0.1, 0.12, 0.6, 0.78))
    values = sorted(set(groups.tolist()))
    cmap = colormaps["viridis"]
    for k, g in enumerate(values):
        on = groups == g
        ax.plot(x[on], y[on], "osD^v<>p"[k % 8], ms=4, color=cmap(k / max(len(values) - 1, 1)), alpha=0.8,
                label=f"{group_label} = {g:g}")
    ok = (x > 0) & (y > 0)
    xs = np.geomspace(x[ok].min(), x[ok].max(), 50)
    lo, hi = fit.ci
    ax.plot(xs, fit.prefactor * xs**fit.exponent, "k-", lw=1.0,
            label=f"fit: exponent {fit.exponent:.3f} ({fit.level:.0%} CI {lo:.3f} to {hi:.3f}), R² {fit.r2:.3f}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_minor_formatter(NullFormatter())  # decades only: minor labels overlap
    ax.set_xlabel(xlabel, fontsize=8)
    ax.set_ylabel("initial fractures (most cracks at once)")
    if check is not None:
        ax.set_title(f"{check.decades:.1f} decades; F tests: straight in log–log p = {check.curvature_p:.2g}"
                     + ("" if check.alone_p is None else f", rate alone sets it p = {check.alone_p:.2g}"), fontsize=8)
    ax.legend(fontsize=7, frameon=False, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    return save_figure(fig, path)
