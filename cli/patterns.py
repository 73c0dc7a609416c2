"""``bark analyze`` and ``bark compare``: patterns measured and compared as in the paper.

A PATTERN argument is a run's output folder (its state.npz), a state file (.npz), a CSV of leaf-base
centres (simulated, or digitised from a photograph: the format is in ``bark.analysis.pattern``) or a TOML
summary of a published pattern (``[pattern]``: n_patches, mean_orientation_deg, sd_orientation_deg,
optionally mean_anisotropy and sd_anisotropy).  Every argument is read and checked before anything
is written.
"""

from __future__ import annotations

import math
from pathlib import Path

import click

from bark_cli.options import SCENE_RULE, json_option

CONTEXT = {"help_option_names": ["-h", "--help"]}
ANALYZE_FILES = ("statistics.json", "patches.csv", "radial.png", "histogram.png")
"""Every file ``bark analyze`` may write into its --out (the folder holds only this call's)."""
COMPARE_FILES = ("comparison.json", "quartets.png")
"""Every file ``bark compare`` may write into its --out."""


def picture_options(command):
    """``--format`` and ``--dpi``: the format and resolution of a command's pictures."""
    command = click.option("--dpi", type=click.IntRange(30, 1200), default=150, show_default=True,
                           help="Resolution of the pictures, dots per inch.")(command)
    return click.option("--format", "picture_format", type=click.Choice(["png", "pdf", "svg"]), default="png",
                        show_default=True, help="Format of the pictures.")(command)


def in_formats(names: tuple) -> tuple:
    """``names`` with every picture in every format: what a command owns, whichever it writes now."""
    from bark.model.effects import PICTURE_FORMATS, in_format

    return tuple(dict.fromkeys(in_format(n, fmt) for n in names for fmt in PICTURE_FORMATS))


def pictured(writers: dict, picture_format: str, dpi: int) -> dict:
    """``writers`` with each picture's name in ``picture_format`` and drawn at ``dpi``."""
    from bark.model.effects import in_format
    from bark_cli.plot import picture_dpi

    def at_dpi(write):
        def draw(path):
            with picture_dpi(dpi):
                return write(path)
        return draw

    return {in_format(name, picture_format): at_dpi(write) if name.endswith(".png") else write
            for name, write in writers.items()}


def _wrote(folder, owned: tuple, writers: dict, document: dict | None = None) -> int:
    """``write_owned``, then say what was written (on stderr when the result goes to stdout as JSON,
    ``document``: --json); exit status 1 if a file could not be."""
    from bark.io.files import json_text
    from bark_cli import write_owned

    written = write_owned(folder, in_formats(owned), writers)
    if written:
        click.echo(f"wrote {', '.join(written)} to {folder}", err=document is not None)
    if document is not None:
        click.echo(json_text(document, indent=2))
    return 0 if len(written) == len(writers) else 1


def _held(out: str, run_files_kept: bool = False):
    """``--out`` checked, created and locked for this command (``bark.io.folder.held_folder``: one
    bark command writes there at a time, a second is told which holds it).  ``run_files_kept``:
    refuse a folder that holds a run of ``bark simulate``, whose files of the same names (its
    patches.csv) are that run's."""
    from bark.errors import BarkError, Ref
    from bark.io.folder import held_folder, holds_a_run

    held = held_folder(out)
    if run_files_kept and holds_a_run(held.path):
        held.close()
        raise BarkError("{0}: holds a run of bark simulate, whose patches.csv is that run's; write the analysis "
                        "to another folder", Ref(None, "out", out))
    return held


def _namer() -> None:
    from bark_cli.options import NAMER, Provenance

    NAMER.set(Provenance(aliases={(None, "out"): "--out"}).name)


def _read_all(paths, min_size):
    from bark.analysis.pattern import read

    return [read(p, min_size) for p in paths]


def _fmt(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    if isinstance(value, float) and math.isinf(value):
        return "∞"
    return f"{value:.{digits}g}" if isinstance(value, float) else str(value)


def _statistics_table(stats):
    from rich.table import Table

    table = Table("pattern", "spiral", "patches", "orientation mean (°)", "SD (°)", "SE (°)", "within 45°",
                  "anisotropy mean", "SD", "SE", title="patterns (orientation: 0° horizontal, 90° up the trunk; "
                  "spiral: the lattice's handedness, — where not known)")
    for s in stats:
        a = s.anisotropy
        table.add_row(s.name, s.handedness or "—", str(s.n_patches), _fmt(s.orientation.mean_deg, 4), _fmt(s.orientation.sd_deg),
                      _fmt(s.orientation.se_deg), _fmt(s.fraction_within_45, 2), *(
                          ("—", "—", "—") if a is None else (_fmt(a.mean), _fmt(a.sd), _fmt(a.se))))
    return table


@click.command(context_settings=CONTEXT)
@click.argument("pattern", type=click.Path(), metavar="PATTERN")
@click.option("--min-size", type=click.IntRange(1, 10**9), default=None,
              help="Patches with fewer leaf bases are left out. [default: the run's own, else 7]")
@click.option("--scene", "scene_file", default=None, metavar="SCENE",
              help=f"Also run this scene's analyzers ([analyzer] or [[analyzer]]; the name of one {SCENE_RULE}) "
                   "on PATTERN: their summaries in statistics.json under 'analyses', each table as "
                   "analysis-<analyzer>-<table>.csv. A pattern without springs (a photograph) gives them none.")
@click.option("--out", default="bark-analysis", show_default=True, type=click.Path(file_okay=False),
              help="Folder for statistics.json, patches.csv, radial.png and histogram.png.")
@json_option
@picture_options
def analyze(pattern, min_size, scene_file, out, as_json, picture_format, dpi):
    """Measure PATTERN (a run folder, a state .npz, a leaf-base .csv or a .toml summary): per-patch orientation and anisotropy (PCA), their
    means, SDs and standard errors; draws the radial plot and the orientation histogram (the
    paper's Fig. 6B, C / 7B, C)."""
    _namer()
    (stats,) = _read_all([pattern], min_size)
    analyses = None if scene_file is None else _scene_analyses(Path(pattern), scene_file)
    with _held(out, run_files_kept=True) as held:
        return _analyze(pattern, stats, analyses, min_size, held.path, picture_format, dpi, as_json)


def _analyze(pattern, stats, analyses, min_size, folder, picture_format, dpi, as_json: bool = False) -> int:
    from rich.console import Console

    from bark.io.files import write_csv, write_json

    console = Console(width=150, quiet=as_json)  # --json: the document alone on stdout
    console.print(_statistics_table([stats]))
    network = _network(Path(pattern), stats, min_size)
    if network is not None:
        console.print("  beyond the paper: " + _network_line(network))
    document = {**stats.as_dict(), "network": network}
    writers = {}
    owned = (*ANALYZE_FILES, *(p.name for p in folder.glob("analysis-*.csv")))
    if analyses is not None:
        from bark.io.output import analysis_file, analysis_tables

        document["analyses"] = {name: a.summary for name, a in analyses.items()}
        for name, table, rows in analysis_tables(analyses):
            writers[analysis_file(name, table)] = lambda path, rows=rows: write_csv(path, rows, list(rows[0]) if rows else [])
        console.print(f"  analyzers: {', '.join(analyses)}")
    writers["statistics.json"] = lambda path: write_json(path, document)
    if stats.patches is not None:
        writers["patches.csv"] = lambda path: write_csv(path, stats.patches.rows(), stats.patches.columns, stats.patches.header)
        if stats.n_patches:
            from bark_cli.figures import plot_histogram, plot_radial

            writers.update({"radial.png": lambda path: plot_radial(stats, path),
                            "histogram.png": lambda path: plot_histogram(stats, path)})
    return _wrote(folder, owned, pictured(writers, picture_format, dpi), document if as_json else None)


def _scene_analyzers_of(scene_file) -> list:
    """The analyzers of the scene ``scene_file`` names (validated as ``bark simulate`` takes it)."""
    from bark.engine.scene import Scene

    scene = Scene.from_toml(scene_file)
    return [scene.strategies["analyzer"], *scene.more_analyzers]


def _scene_analyses(path: Path, scene_file) -> dict:
    """The scene's analyzers run on the pattern at ``path``: results by each one's recorded name; one
    that reads springs gets the pattern's, or ``None`` where it has none (a photograph)."""
    from bark.analysis.pattern import load, springs_of
    from bark.contract.registry import name_of
    from bark.contract.strategies import Springs

    analyzers = _scene_analyzers_of(scene_file)
    pattern, given = load(path), springs_of(path)
    springs = None if given is None else Springs(pairs=given[0], intact=given[1], offsets=given[2])
    return {name_of(a): a.analyze(pattern.points, pattern.patches, springs) if a.reads_springs
            else a.analyze(pattern.points, pattern.patches) for a in analyzers}


def _network(path: Path, stats, min_size: int | None) -> dict | None:
    """The statistics beyond the paper's of the pattern at ``path`` (``bark.analysis.network.of_pattern``);
    ``None`` for a published summary, which has no patches."""
    from bark.analysis.network import of_pattern

    return None if stats.patches is None else of_pattern(path, stats.patches.size, min_size)


def _network_line(net: dict) -> str:
    text = f"sizes {_fmt(net['size_mean'])} ± {_fmt(net['size_sd'])} bases, best fit {net['size_favoured'] or '—'}"
    if "n_bar" in net:
        text += (f"; junctions {net['n_junctions']}, n̄ {_fmt(net['n_bar'])}, v̄ {_fmt(net['v_bar'])}, T "
                 f"{_fmt(net['t_fraction'], 2)}; crack order {_fmt(net['nematic_order'], 2)} at {_fmt(net['crack_director_deg'])}°")
    return text


@click.command(context_settings=CONTEXT)
@click.argument("patterns", nargs=-1, required=True, type=click.Path(), metavar="PATTERN...")
@click.option("--min-size", type=click.IntRange(1, 10**9), default=None,
              help="Patches with fewer leaf bases are left out. [default: each run's own, else 7]")
@click.option("--mirror", "mirror", multiple=True, type=click.IntRange(1, None), metavar="N",
              help="Compare the N-th PATTERN seen in a mirror held along the trunk (orientation o -> 180° - o): "
                   "for trees whose phyllotactic spiral turns the other way. Repeatable.")
@click.option("--out", default="bark-compare", show_default=True, type=click.Path(file_okay=False),
              help="Folder for comparison.json and, for four patterns, quartets.png.")
@json_option
@picture_options
def compare(patterns, min_size, mirror, out, as_json, picture_format, dpi):
    """Compare two or more PATTERNs (each a run folder, a state .npz, a leaf-base .csv or a .toml
    summary): Hellinger distances and
    d_P of orientation and of anisotropy (the paper's eqs. 12–15); for four, the quartet analyses
    and their diagram (Fig. 8)."""
    import attrs

    from bark.analysis.compare import compare as compare_all
    from bark.errors import BarkError

    _namer()
    if len(patterns) < 2:
        raise BarkError(f"compare needs at least two patterns, given {len(patterns)}")
    if mirror and max(mirror) > len(patterns):
        raise BarkError(f"--mirror {max(mirror)}: there are only {len(patterns)} patterns")
    stats = [s.mirrored() if i + 1 in mirror else s for i, s in enumerate(_read_all(patterns, min_size))]
    names = [s.name for s in stats]
    if len(set(names)) != len(names):  # two runs both called "out": number them as given
        stats = [attrs.evolve(s, name=f"{i + 1}:{s.name}") for i, s in enumerate(stats)]
        names = [s.name for s in stats]
    result = compare_all(stats)
    with _held(out) as held:
        return _compare(stats, names, result, held.path, picture_format, dpi, as_json)


def _compare(stats, names, result, folder, picture_format, dpi, as_json: bool = False) -> int:
    from rich.console import Console
    from rich.table import Table

    from bark.analysis.compare import QUANTITIES
    from bark.io.files import write_json

    console = Console(width=150, quiet=as_json)  # --json: the document alone on stdout
    console.print(_statistics_table(stats))
    hands = {s.handedness for s in stats} - {None}
    if len(hands) > 1:
        console.print("  these patterns grew on lattices of both handedness (spiral): --mirror N compares the N-th "
                      "in a mirror, as if its spiral turned the other way")
    report = {"patterns": [s.as_dict() for s in stats]}
    for quantity in QUANTITIES:
        h, dp = result.hellinger[quantity], result.d_p[quantity]
        table = Table("", *names, title=f"{quantity}: Hellinger distance (upper right) | d_P in SE of the row (lower left)")
        for i, name in enumerate(names):
            table.add_row(name, *("·" if i == j else _fmt(float(h[i, j] if j > i else dp[i, j]))
                                  for j in range(len(names))))
        console.print(table)
        if len(names) > 2:
            console.print(f"  d_P of the upper right: {', '.join(f'{names[i]}→{names[j]} {_fmt(float(dp[i, j]))}' for i in range(len(names)) for j in range(i + 1, len(names)))}")
        entry = {"hellinger": h.tolist(), "d_p": dp.tolist()}
        q, p = result.quartets[quantity], result.pairings[quantity]
        if q is not None:
            pairs = q.pairing
            verdict = (f"valid: {names[pairs[0][0]]} with {names[pairs[0][1]]}, {names[pairs[1][0]]} with {names[pairs[1][1]]}"
                       if pairs else f"not valid: the two closest pairs share {_shared(q, names)}")
            console.print(f"  quartet ({quantity}): {verdict}" + ("  [yellow](second and third distances tie)[/yellow]" if q.tied else ""))
            entry["quartet"] = {"edges": [[names[i], names[j], d] for i, j, d in q.edges], "valid": q.valid, "tied": q.tied}
        if p is not None:
            console.print(f"  d_P pairing ({quantity}): {'valid' if p.valid else 'not valid'} — nearest: "
                          + ", ".join(f"{names[i]}→{names[j] if j >= 0 else 'none'}" for i, j in enumerate(p.nearest)))
            entry["d_p_pairing"] = {"nearest": [names[j] if j >= 0 else None for j in p.nearest], "valid": p.valid}
        report[quantity] = entry
    writers = {"comparison.json": lambda path: write_json(path, report)}
    if len(stats) == 4:
        from bark_cli.figures import plot_quartets

        writers["quartets.png"] = lambda path: plot_quartets(result, path)
    return _wrote(folder, COMPARE_FILES, pictured(writers, picture_format, dpi), report if as_json else None)


def _shared(q, names) -> str:
    (a, b, _), (c, d, _) = q.edges[:2]
    return names[({a, b} & {c, d}).pop()]
