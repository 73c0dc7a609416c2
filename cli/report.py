"""``bark report DIR``: one self-contained HTML page for a run (or a sweep) — its settings and
provenance, its statistics, every picture it drew, an interactive 3-D view of the trunk coloured by
patch and the statistics along the run — that opens in any browser without a network (plotly's
bundle is inlined, the pictures are data URIs).  Written atomically into DIR as ``report.html``.
"""

from __future__ import annotations

import base64
import csv
import html
import json
import math
import sqlite3
from pathlib import Path

import click
import numpy as np

from bark.errors import BarkError
from bark.io.files import atomic_write
from bark.units import METRES_PER_LENGTH_UNIT, years


CONTEXT = {"help_option_names": ["-h", "--help"]}
MAX_POINTS = 80_000
"""Most leaf bases the 3-D view shows (a larger trunk is shown by an even sample of them)."""
PICTURES = ("tree.png", "tree-series.png", "regions.png", "pattern.png", "fracture.png", "montage.png",
            "development.gif")
"""The pictures a run or a sweep may have drawn, in the order the page shows them."""
STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 72em; color: #222; }
h1 { font-size: 1.6em; } h2 { font-size: 1.2em; margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.9em; } td, th { padding: 0.2em 0.8em; text-align: left; }
tr:nth-child(even) { background: #f4f4f4; } figure { margin: 1em 0; } figcaption { color: #555; }
img { max-width: 100%; border: 1px solid #ddd; } pre { background: #f7f7f7; padding: 1em; overflow-x: auto; }
.plot { width: 100%; height: 42em; }
"""


WATCH = """
window.barkErrors = [];
window.addEventListener("error", function (e) { window.barkErrors.push(String(e.message)); });
(function () { var error = console.error; console.error = function () {
  window.barkErrors.push(Array.prototype.join.call(arguments, " ")); error.apply(console, arguments); }; })();
window.addEventListener("load", function () {
  document.body.setAttribute("data-errors", JSON.stringify(window.barkErrors));
  document.body.setAttribute("data-loaded", "yes"); });
"""
"""The page notes its own script errors (any uncaught error and console.error) in its body's
``data-errors`` once loaded (``data-loaded``): what a check in a browser reads."""


@click.command(context_settings=CONTEXT)
@click.argument("folder", type=click.Path(file_okay=False))
def report(folder):
    """Write FOLDER/report.html: one page for the run (or sweep) in FOLDER — settings, provenance,
    statistics, every picture, the trunk in 3-D coloured by patch, the statistics along the run —
    that opens offline in a browser."""
    try:
        import plotly  # noqa: F401
    except ImportError:
        raise BarkError("bark report needs plotly, for its interactive views: pip install 'bark-grasstree[report]'") \
            from None
    from bark.io.folder import held_folder

    path = Path(folder)
    if not path.is_dir():
        raise BarkError(f"{str(path)!r} is not a folder of a bark run or sweep")
    with held_folder(path):  # no run or sweep is writing there meanwhile, and no other report
        page = _sweep_page(path) if (path / "sweep.sqlite").is_file() else _run_page(path)
        target = atomic_write(path / "report.html", lambda fh: fh.write(page.encode()))
    click.echo(f"bark: report in {target}")


def _run_page(path: Path) -> str:
    summary_file = path / "summary.json"
    if not summary_file.is_file():
        raise BarkError(f"{str(path)!r} holds no finished run (no summary.json): nothing to report")
    try:
        summary = json.loads(summary_file.read_text())
    except (OSError, ValueError) as err:
        raise BarkError(f"{str(summary_file)!r} cannot be read ({err})") from None
    if not isinstance(summary, dict) or not isinstance(summary.get("settings", {}), dict):
        raise BarkError(f"{str(summary_file)!r} is not a run's summary (a JSON object with its settings)")
    scene = summary.get("settings", {}).get("scene", {})
    scene = scene if isinstance(scene, dict) else {}
    name, what = str(scene.get("name") or path.name), str(scene.get("description", ""))
    parts = [f"<h1>bark run: {html.escape(name)}</h1>", f"<p>{html.escape(what)}</p>",
             _provenance(summary), _statistics(summary), _trunk(path, summary), _series(path), _pictures(path),
             _settings(path, summary)]
    return _page(f"bark: {name}", parts)


def _sweep_page(path: Path) -> str:
    from bark.io.files import sqlite_reader

    try:
        with sqlite_reader(path / "sweep.sqlite") as con:  # read only, and no -wal or -shm left beside it
            cursor = con.execute("SELECT * FROM runs ORDER BY point, seed LIMIT 1000")
            columns = [d[0] for d in cursor.description]
            rows = cursor.fetchall()
            total = con.execute("SELECT count(*) FROM runs").fetchone()[0]
    except sqlite3.Error as err:
        raise BarkError(f"{str(path / 'sweep.sqlite')!r} cannot be read as a sweep ({err})") from None
    shown = [c for c in columns if c not in ("scene", "key", "regions")]
    table = "<table><tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in shown) + "</tr>" + "".join(
        "<tr>" + "".join(f"<td>{html.escape(_cell(r[columns.index(c)]))}</td>" for c in shown) + "</tr>" for r in rows
    ) + "</table>"
    maps = _sweep_maps(columns, rows)
    parts = [f"<h1>bark sweep: {html.escape(path.name)}</h1>", _pictures(path), maps,
             f"<h2>Runs</h2><p>{total} runs{' (the first 1000 shown)' if total > 1000 else ''}; every column is in "
             "sweep.sqlite's table <code>runs</code>.</p>" + table]
    return _page(f"bark sweep: {path.name}", parts, plotly=bool(maps))


SWEEP_MAPS = (("n_patches", "patches"), ("mean_orientation_deg", "mean orientation (°)"),
              ("circular_sd_deg", "circular SD (°)"), ("mean_anisotropy", "anisotropy"))
"""The statistics a sweep's page maps over its two swept settings (or draws along its one)."""


def _sweep_maps(columns: list[str], rows: list) -> str:
    """A heat map per statistic over a sweep's two settings, each cell the mean of its seeds (the
    orientation's an axial mean), or a line along its one; nothing for a list of points or more axes."""
    from bark.analysis.circular import axial_mean

    points = [json.loads(r[columns.index("point")]) for r in rows]
    keys = list(points[0]) if points else []
    if not 1 <= len(keys) <= 2 or any(list(p) != keys for p in points):
        return ""
    values = [sorted({p[k] for p in points}, key=float) for k in keys]
    if math.prod(len(v) for v in values) != len({tuple(p.values()) for p in points}):
        return ""  # not a grid (a list of points, a design): a table, not a map
    import plotly.graph_objects as go
    import plotly.io as pio
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=1, cols=len(SWEEP_MAPS), subplot_titles=[label for _, label in SWEEP_MAPS],
                        horizontal_spacing=0.08)
    for k, (name, _) in enumerate(SWEEP_MAPS):
        col = columns.index(name)

        def mean(cell):
            got = np.array([float(r[col]) for r, p in zip(rows, points) if tuple(p.values()) == cell
                            and r[col] is not None], float)
            return None if not got.size else float(axial_mean(got)) if name == "mean_orientation_deg" else float(got.mean())

        if len(keys) == 1:
            fig.add_trace(go.Scatter(x=values[0], y=[mean((v,)) for v in values[0]], mode="lines+markers"), row=1, col=k + 1)
            fig.update_xaxes(title_text=keys[0], row=1, col=k + 1)
        else:
            z = [[mean((a, b)) for a in values[0]] for b in values[1]]
            fig.add_trace(go.Heatmap(x=[str(v) for v in values[0]], y=[str(v) for v in values[1]], z=z,
                                     colorscale="Viridis", showscale=False, texttemplate="%{z:.3g}"), row=1, col=k + 1)
            fig.update_xaxes(title_text=keys[0], row=1, col=k + 1)
            fig.update_yaxes(title_text=keys[1], row=1, col=k + 1)
    fig.update_layout(showlegend=False, margin={"t": 40})
    return ("<h2>Statistics over the sweep</h2><p>Each cell the mean over its seeds (the orientation's, an axial "
            "mean).</p>" + pio.to_html(fig, include_plotlyjs=False, full_html=False, div_id="sweep-maps",
                                       default_height="22em"))


def _page(title: str, parts: list[str], plotly: bool = True) -> str:
    """The page, plotly's bundle inlined once where a part plots (a sweep's page without a map needs none)."""
    script = ""
    if plotly:
        from plotly.offline import get_plotlyjs

        script = f"<script>{get_plotlyjs()}</script>"
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{STYLE}</style><script>{WATCH}</script>"
            f"{script}</head><body>\n" + "\n".join(p for p in parts if p) + "\n</body></html>\n")


def _cell(value) -> str:
    return f"{value:.4g}" if isinstance(value, float) else "" if value is None else str(value)


def _provenance(summary: dict) -> str:
    made = summary.get("provenance") or {}
    rows = [("bark", made.get("bark_version") or summary.get("bark_version")),
            ("commit", (made.get("commit") or "unknown") + (" (with uncommitted changes)" if made.get("dirty") else "")),
            *((f"session {i + 1}", f"{s.get('started')}: {s.get('command')}") for i, s in enumerate(made.get("sessions", []))),
            ("seed", summary.get("seed")), ("stopped by", summary.get("stop_reason")),
            ("wall time", f"{summary.get('wall_time_s') or 0:.1f} s")]
    return "<h2>Provenance</h2>" + _table(rows)


def _table(rows) -> str:
    return "<table>" + "".join(f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(_cell(v))}</td></tr>"
                               for k, v in rows) + "</table>"


def _statistics(summary: dict) -> str:
    keys = ("t", "radius", "steps", "n_bases", "n_broken", "n_patches", "largest_patch_share", "mean_orientation_deg",
            "circular_sd_deg", "orientation_se_deg", "mean_anisotropy", "fraction_within_45_deg")
    out = "<h2>Statistics at the end</h2>" + _table([(k, summary.get(k)) for k in keys])
    out += f"<p>t = {_cell(summary.get('t'))} time units = {years(summary.get('t') or 0.0):.1f} years; radius in " \
           f"length units (1 = {METRES_PER_LENGTH_UNIT} m); orientation in degrees from horizontal, 90 = up the trunk.</p>"
    regions = summary.get("regions")
    if regions:
        cols = ("n_bases", "n_patches", "largest_patch_share", "mean_orientation_deg", "circular_sd_deg", "mean_anisotropy")
        out += "<h2>By region of the trunk</h2><table><tr><th>region</th>" + "".join(f"<th>{c}</th>" for c in cols) + \
            "</tr>" + "".join(f"<tr><th>{html.escape(n)}</th>" + "".join(f"<td>{_cell(r.get(c))}</td>" for c in cols) +
                              "</tr>" for n, r in regions.items()) + "</table>"
    return out


KINDS = {"png": "image/png", "gif": "image/gif", "svg": "image/svg+xml", "pdf": "application/pdf"}
"""The media type of each picture format a run may draw in (``--format``) and of the animation."""


def _pictures(path: Path) -> str:
    """Every picture the run drew, in whichever format it drew it (PNG, SVG or PDF; a PDF as the
    browser's own viewer shows it, with a link to save it)."""
    from bark.model.effects import PICTURE_FORMATS, in_format

    shown = []
    for base in PICTURES:
        for name in dict.fromkeys(in_format(base, fmt) for fmt in PICTURE_FORMATS):
            file = path / name
            if not file.is_file():
                continue
            try:
                data = base64.b64encode(file.read_bytes()).decode()
            except OSError as err:
                shown.append(f"<p>{html.escape(name)} cannot be read ({html.escape(err.strerror or str(err))}).</p>")
                continue
            uri = f"data:{KINDS[name.rpartition('.')[2]]};base64,{data}"
            picture = (f"<object data=\"{uri}\" type=\"application/pdf\" class=\"plot\"><a download=\"{name}\" "
                       f"href=\"{uri}\">{name}</a></object>" if name.endswith(".pdf") else f"<img alt=\"{name}\" src=\"{uri}\">")
            shown.append(f"<figure>{picture}<figcaption>{name}</figcaption></figure>")
    return "<h2>Pictures</h2>" + "".join(shown) if shown else ""


def _trunk(path: Path, summary: dict) -> str:
    """The trunk's leaf bases in 3-D (metres), coloured by patch as every picture colours them; a
    state.npz that cannot be read, or that is not this run's (its bases, breaks or time are not
    the summary's), is said instead."""
    import plotly.graph_objects as go
    import plotly.io as pio

    from bark.analysis.pattern import Pattern, patch_colours, run_min_size, springs_of

    title, state = "<h2>The trunk in 3-D</h2>", path / "state.npz"
    if not state.is_file():
        return title + "<p>No state.npz (the run did not ask for <code>state-snapshot</code>).</p>"
    try:
        pattern, springs = Pattern.from_state(state), springs_of(state)
        with np.load(state, allow_pickle=False) as d:
            t = float(d["t"]) if "t" in d.files and d["t"].size == 1 else None
    except (BarkError, OSError, ValueError) as err:
        return title + f"<p>state.npz cannot be shown: {html.escape(str(err))}</p>"
    x, labels = pattern.points, pattern.patches
    pairs, intact = springs[:2] if springs is not None else (None, None)
    held = {"n_bases": len(x), "n_broken": None if intact is None else int((~intact).sum()), "t": t}
    differ = [k for k, v in held.items() if v is not None and summary.get(k) is not None and summary.get(k) != v]
    if differ:
        return title + ("<p>state.npz is not this run's: " + ", ".join(f"its {k} is {_cell(held[k])}, the summary's "
                                                                     f"{_cell(summary[k])}" for k in differ)
                        + " (not shown).</p>")
    rgb = patch_colours(labels, run_min_size(path), pairs, intact)
    keep = np.arange(len(x)) if len(x) <= MAX_POINTS else np.linspace(0, len(x) - 1, MAX_POINTS).astype(int)
    p = x[keep] * METRES_PER_LENGTH_UNIT
    colours = [f"rgb({r},{g},{b})" for r, g, b in rgb[keep]]
    fig = go.Figure(go.Scatter3d(x=p[:, 0], y=p[:, 1], z=p[:, 2], mode="markers",
                                 marker={"size": 2, "color": colours}, hovertext=[f"base {i}, patch {labels[i]}" for i in keep],
                                 hoverinfo="text"))
    fig.update_layout(scene={"aspectmode": "data", "xaxis_title": "x (m)", "yaxis_title": "y (m)", "zaxis_title": "z (m)"},
                      margin={"l": 0, "r": 0, "t": 30, "b": 0},
                      title=f"{len(x):,} leaf bases{'' if len(keep) == len(x) else f' ({len(keep):,} shown)'}, "
                            "coloured by patch (fragments grey); drag to turn, scroll to zoom")
    return "<h2>The trunk in 3-D</h2>" + pio.to_html(fig, include_plotlyjs=False, full_html=False,
                                                      div_id="trunk", default_height="42em")


def _series(path: Path) -> str:
    """The statistics along the run (statistics.csv), against years."""
    import plotly.io as pio
    from plotly.subplots import make_subplots

    file = path / "statistics.csv"
    if not file.is_file():
        return ""
    try:
        with open(file, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        return f"<h2>Along the run</h2><p>statistics.csv cannot be read ({html.escape(str(err))}).</p>"
    if not rows:
        return ""

    def column(name):
        def value(k, r):
            text = r.get(name)
            if text in (None, "", "nan"):
                return None
            try:
                return float(text)
            except ValueError:
                raise ValueError(f"row {k + 1} holds {text[:40]!r} in column {name}") from None
        return [value(k, r) for k, r in enumerate(rows)]

    try:
        if "t_tu" not in rows[0]:
            raise ValueError("it has no column t_tu (time)")
        t = [None if v is None else years(v) for v in column("t_tu")]
        columns = {name: column(name) for name in ("n_patches", "n_broken", "mean_orientation_deg")}
    except ValueError as err:
        return f"<h2>Along the run</h2><p>statistics.csv cannot be shown: {html.escape(str(err))}.</p>"
    fig = make_subplots(rows=1, cols=3, subplot_titles=("patches", "broken springs", "mean orientation (°)"))
    import plotly.graph_objects as go

    for k, name in enumerate(("n_patches", "n_broken", "mean_orientation_deg")):
        x, y = axial_gaps(t, columns[name]) if name == "mean_orientation_deg" else (t, columns[name])
        fig.add_trace(go.Scatter(x=x, y=y, mode="lines+markers", name=name), row=1, col=k + 1)
        fig.update_xaxes(title_text="years", row=1, col=k + 1)
    fig.update_yaxes(range=[0, 180], tickvals=[0, 45, 90, 135, 180], row=1, col=3)  # axial: 0 and 180 are one direction
    fig.update_layout(showlegend=False, margin={"t": 40})
    return "<h2>Along the run</h2>" + pio.to_html(fig, include_plotlyjs=False, full_html=False, div_id="series",
                                                  default_height="24em")


def axial_gaps(x: list, y: list) -> tuple[list, list]:
    """An orientation series (degrees in [0, 180), axial: 0 and 180 are the same direction) with a gap
    (``None``) wherever it wraps — two neighbours more than 90° apart are nearer the other way round —
    so that its line never jumps across the plot between 179° and 1°."""
    xs, ys = [], []
    for k, (a, b) in enumerate(zip(x, y)):
        if k and b is not None and ys and ys[-1] is not None and abs(b - ys[-1]) > 90.0:
            xs.append(None)
            ys.append(None)
        xs.append(a)
        ys.append(b)
    return xs, ys


def _settings(path: Path, summary: dict) -> str:
    scene = path / "scene.toml"
    text = scene.read_text() if scene.is_file() else json.dumps(summary.get("settings", {}), indent=2)
    return ("<h2>Settings</h2><details><summary>every setting of the run (scene.toml: <code>bark simulate --scene "
            f"{html.escape(str(scene))}</code> runs it again)</summary><pre>{html.escape(text)}</pre></details>")
