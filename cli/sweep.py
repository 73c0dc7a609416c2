"""``bark sweep``: a grid over scene settings, run on local processes or a Dask cluster, into one
SQLite table, with a montage of the patterns laid out like the paper's Fig. 9."""

from __future__ import annotations

import math
import shlex
from pathlib import Path
import signal
import sys

import click

from bark.errors import BarkError
from bark_cli.options import SCENE_RULE, json_option, progress_option, setting_value, split_setting, value_text
from bark_cli.patterns import in_formats, picture_options, pictured

CONTEXT = {"help_option_names": ["-h", "--help"]}
MONTAGE_CELLS = 400
"""Most grid points montage.png draws (a cell each: beyond, a sheet of unreadable specks that takes
minutes to draw)."""
DASK_TIMEOUT_S = 10
"""Seconds a Dask scheduler has to answer --dask (and five more for what is not one)."""
TABLE_ROWS = 200
"""Most runs the closing table prints; the rest are in sweep.sqlite."""


def parse_grid(items: tuple[str, ...]):
    """``--grid growth.G=0.007,0.011,0.014`` or ``--grid growth.G=0.005:0.015:5`` (5 values from
    0.005 to 0.015) → :class:`bark.studies.sweep.Axis` es, and the tables they touch (for messages)."""
    import numpy as np

    from bark.studies.sweep import Axis

    axes, layer = [], {}
    for item in items:
        setting = split_setting(item)
        if setting is None or not setting[2].strip():
            raise BarkError(f"--grid {shlex.quote(item)}: expected SECTION.KEY=V1,V2,... or SECTION.KEY=START:STOP:N, "
                            "e.g. --grid growth.G=0.007,0.011,0.014")
        section, name, text = setting
        parts = text.split(":")
        if len(parts) == 3:
            try:
                start, stop, n = float(parts[0]), float(parts[1]), int(parts[2])
            except ValueError:
                raise BarkError(f"--grid {shlex.quote(item)}: START:STOP:N needs two numbers and a whole number") from None
            if not (np.isfinite(start) and np.isfinite(stop)) or not 1 <= n <= 10_000:
                raise BarkError(f"--grid {shlex.quote(item)}: START and STOP must be finite, N from 1 to 10000")
            # to 12 digits: 0.01:0.03:3 is 0.01, 0.02, 0.03 as typed, not linspace's 0.019999999999999997
            values = [float(f"{v:.12g}") for v in np.linspace(start, stop, n)] if n > 1 else [start]
        else:
            values = [setting_value(word) for word in text.split(",")]
        axis = Axis(f"{section}.{name}", tuple(values))
        axes.append(axis)
        layer.setdefault(axis.section, {})[axis.name.partition(".")[0]] = list(values)  # nested: its top key
    return axes, layer


def parse_points(path: str):
    """``--points FILE``: a CSV whose header names scene keys (``growth.G``, ...) and whose rows are
    the points (values as ``--set`` takes them) → the axes of a listed sweep, and the tables they touch."""
    import csv

    from bark.paths import NotARegularFile, open_regular
    from bark.studies.sweep import Axis

    try:
        with open_regular(Path(path)) as raw:
            text = raw.read().decode("utf-8-sig")
    except FileNotFoundError:
        raise BarkError(f"--points {shlex.quote(path)}: no such file") from None
    except (NotARegularFile, OSError, UnicodeDecodeError) as err:
        raise BarkError(f"--points {shlex.quote(path)}: cannot be read ({err})") from None
    rows = [r for r in csv.reader(line for line in text.splitlines() if line.strip() and not line.startswith("#"))]
    if len(rows) < 2:
        raise BarkError(f"--points {shlex.quote(path)}: expected a header of scene keys (growth.G,...) and a row a point")
    keys, values = rows[0], rows[1:]
    layer = {}
    for k in keys:
        if split_setting(f"{k}=0") is None:
            raise BarkError(f"--points {shlex.quote(path)}: column {k!r} is not a scene key (SECTION.KEY, e.g. growth.G)")
    for line, row in enumerate(values, start=2):
        if len(row) != len(keys):
            raise BarkError(f"--points {shlex.quote(path)} row {line}: {len(row)} values for {len(keys)} columns")
    axes = [Axis(k, tuple(setting_value(row[j]) for row in values)) for j, k in enumerate(keys)]
    for a in axes:
        layer.setdefault(a.section, {})[a.name.partition(".")[0]] = list(a.values)
    return axes, layer


def parse_ranges(items: tuple[str, ...], option: str = "--range") -> dict:
    """``--range growth.G=0.005:0.02`` (``:log`` for log-uniform; or any ``option`` of that form) →
    ``{key: (low, high, log)}``."""
    import math as m

    out = {}
    for item in items:
        setting = split_setting(item)
        parts = setting[2].split(":") if setting is not None else []
        if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] != "log"):
            raise BarkError(f"{option} {shlex.quote(item)}: expected SECTION.KEY=LOW:HIGH or SECTION.KEY=LOW:HIGH:log")
        try:
            lo, hi = float(parts[0]), float(parts[1])
        except ValueError:
            raise BarkError(f"{option} {shlex.quote(item)}: LOW and HIGH must be numbers") from None
        log = len(parts) == 3
        if not (m.isfinite(lo) and m.isfinite(hi) and lo < hi) or (log and lo <= 0):
            raise BarkError(f"{option} {shlex.quote(item)}: needs finite LOW < HIGH" + (", both > 0 for :log" if log else ""))
        key = f"{setting[0]}.{setting[1]}"
        if key in out:
            raise BarkError(f"{option} {key}: given twice")
        out[key] = (lo, hi, log)
    return out


@click.command(context_settings=CONTEXT)
@click.option("--scene", "scene_file", default=None, metavar="SCENE",
              help=f"The scene each point starts from: the name of one {SCENE_RULE} [default: the default scene, "
                   "Table 2's vertical regime].")
@click.option("--grid", "grids", multiple=True, metavar="SECTION.KEY=V1,V2,...",
              help="A swept setting and its values (or START:STOP:N); repeat for more axes. "
                   "[default: the paper's Fig. 9: --grid growth.G=0.007,0.011,0.014 --grid mechanics.f_max=0.0028,0.005,0.008]")
@click.option("--points", "points_file", default=None, metavar="FILE.csv",
              help="The points themselves, instead of a grid: a CSV whose header names scene keys and whose rows are the points.")
@click.option("--design", type=click.Choice(["random", "lhs"]), default=None,
              help="Points drawn instead of a grid: random (uniform) or lhs (a Latin hypercube), --samples of them "
                   "in the --range of each setting.")
@click.option("--samples", type=click.IntRange(1, 1_000_000), default=None, help="Points a --design draws.")
@click.option("--range", "ranges", multiple=True, metavar="SECTION.KEY=LOW:HIGH[:log]",
              help="A setting a --design draws, and its range (:log: uniform in its logarithm); repeatable.")
@click.option("--design-seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True,
              help="Seed of the --design's draws (the same seed, the same points).")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE", help="Any other scene setting, for every point.")
@click.option("--seeds", type=click.IntRange(1, 10_000), default=1, show_default=True, help="Runs per point, seeds 0, 1, ...")
@click.option("--max-runs", type=click.IntRange(1, 1_000_000), default=100_000, show_default=True,
              help="The most runs (points times seeds) a sweep may be; a larger one is refused before anything is "
                   "built, since every point's scene is built and checked before the first run. Raise it to run more.")
@click.option("--workers", type=click.IntRange(1, 4096), default=None,
              help="Local worker processes. [default: 1]")
@click.option("--dask", "dask_address", default=None, metavar="ADDRESS",
              help="Run on the Dask distributed cluster whose scheduler is at ADDRESS (tcp://host:8786) instead.")
@click.option("--out", default="bark-sweep", show_default=True, type=click.Path(file_okay=False),
              help="Folder for sweep.sqlite (the table) and montage.png. A sweep run again into it goes on where it stopped.")
@click.option("--run-folders", is_flag=True,
              help="Each run also writes its outputs (as bark simulate does) into --out/runs/KEY, KEY its row's key.")
@click.option("--quiet", is_flag=True, help="No progress and no table.")
@progress_option
@json_option
@picture_options
def sweep(scene_file, grids, points_file, design, samples, ranges, design_seed, sets, seeds, max_runs, workers,
          dask_address, out, run_folders, quiet, progress_every, as_json, picture_format, dpi):
    """Run a grid of scenes, one run per point and seed, each result committed to --out/sweep.sqlite
    (table `runs`) as it finishes; then draw montage.png (the first two axes as columns and rows).
    Killed or stopped, the same command goes on without running a finished point again."""
    from bark.io.folder import held_folder
    from bark.engine.scene import merge, read_toml
    from bark.studies.sweep import FIG9_AXES, Axis, Sweep, check_fits, design as design_axes
    from bark_cli.main import _parse_set
    from bark_cli.options import NAMER, Provenance

    prov = Provenance(aliases={(None, "out"): "--out", (None, "workers"): "--workers"})
    NAMER.set(prov.name)
    if dask_address is not None and workers is not None:
        raise BarkError("--workers and --dask: local processes or a Dask cluster, not both")
    set_layer, prov.set_items = _parse_set(sets)
    base = prov.add(f"file:{scene_file}", read_toml(scene_file)) if scene_file else {}
    base = merge(base, prov.add("--set", set_layer))
    chosen = [name for name, given in (("--grid", grids), ("--points", points_file), ("--design", design)) if given]
    if len(chosen) > 1:
        raise BarkError(f"{' and '.join(chosen)}: a sweep is a grid, a list of points or a design, one of them")
    if (samples is not None or ranges) and design is None:
        raise BarkError("--samples and --range are for a --design (random or lhs)")
    if design is not None:
        if samples is None or not ranges:
            raise BarkError(f"--design {design} needs --samples N and at least one --range SECTION.KEY=LOW:HIGH")
        axes = list(design_axes(design, parse_ranges(ranges), samples, design_seed))
        layer = {}
        for a in axes:
            layer.setdefault(a.section, {})[a.name.partition(".")[0]] = list(a.values)
        source = "--range"
    elif points_file is not None:
        axes, layer = parse_points(points_file)
        source = "--points"
    elif grids:
        axes, layer = parse_grid(grids)
        source = "--grid"
    else:
        axes, layer = [Axis(k, v) for k, v in FIG9_AXES], {}
        for k, v in FIG9_AXES:
            layer.setdefault(k.partition(".")[0], {})[k.partition(".")[2]] = list(v)
        source = "--grid"
    prov.add(source, layer)
    plan = Sweep(base=base, axes=axes, seeds=range(seeds), listed=design is not None or points_file is not None)
    if plan.runs > max_runs:
        given = {"--range": f"--samples {samples}", "--points": f"--points {points_file}"}.get(source, source)
        raise BarkError(f"{given} with --seeds {seeds} is a sweep of {plan.runs:,} runs, more than --max-runs {max_runs}: "
                        "every point's scene is built and checked before the first run; raise --max-runs to run it")
    if plan.runs > 10_000 and not quiet:
        click.echo(f"bark: checking the {plan.runs:,} runs' scenes before the first run", err=True)
    plan.points()  # every point checked: a bad value is one line before anything is written
    if dask_address is None:  # and on this machine, that it fits in memory, so many at once
        check_fits(plan, workers or 1)
    client = _dask_client(dask_address) if dask_address is not None else None
    with held_folder(out) as held:  # one sweep at a time in a folder
        _sweep(plan, held.path, workers, client, quiet, held.path / "runs" if run_folders else None, (picture_format, dpi),
               progress_every, as_json)


def _sweep(plan, folder, workers, client, quiet: bool, run_folders=None, pictures=("png", 150), every_s: float = 30.0,
           as_json: bool = False) -> None:
    from bark.studies.sweep import WorkerDied, run_sweep
    from bark_cli.main import Signals
    from bark_cli.progress import Tally

    tally = Tally("sweep", "runs", every_s, quiet)

    def progress(done: int, total: int, point) -> None:
        last = "" if point is None else "last " + ", ".join(f"{k}={value_text(v)}" for k, v in point.settings.items()) \
            + f", seed {point.seed}"
        tally.update(done, total, last if len(last) <= 100 else last[:99] + "…")

    with Signals() as signals:  # SIGTERM and SIGHUP stop a sweep as Ctrl-C does: a run is in the table whole or not at all
        try:
            counts = run_sweep(plan, folder / "sweep.sqlite", workers=workers or 1, client=client,
                               progress=progress, run_folders=run_folders)
        except WorkerDied as err:
            tally.close()
            click.echo(f"bark: {err}", err=True)
            sys.exit(1)
        except KeyboardInterrupt:
            from bark.studies.sweep import SweepTable

            tally.close()
            with SweepTable(folder / "sweep.sqlite") as table:
                n = len(table.done() & {p.key for p in plan.points()})
            signum = signals.received or signal.SIGINT
            click.echo(f"bark: sweep stopped by {signal.Signals(signum).name}: {n} of {len(plan.points())} runs are in "
                       f"{folder / 'sweep.sqlite'}; the same command goes on", err=True)
            sys.exit(128 + int(signum))
        finally:
            tally.close()
            if client is not None:
                client.close()
    _finish(plan, folder, counts, quiet, pictures, as_json)


def _dask_client(address: str):
    try:
        from distributed import Client
    except ImportError:
        raise BarkError("--dask: Dask's distributed is not installed (pip install 'bark[dask]')") from None
    import queue
    import threading

    # Client's own timeout does not hold against a server that answers in another protocol (an HTTP
    # server: it waits forever, or reads a reply as a frame of 3 EiB): it is given a deadline here,
    # in a daemon thread that a process leaving does not wait for
    answer: queue.SimpleQueue = queue.SimpleQueue()

    def connect() -> None:
        try:
            answer.put(Client(address, timeout=f"{DASK_TIMEOUT_S}s"))
        except BaseException as err:  # noqa: BLE001 — whatever a foreign server makes the client raise
            answer.put(err)

    threading.Thread(target=connect, name="bark-dask-connect", daemon=True).start()
    try:
        got = answer.get(timeout=DASK_TIMEOUT_S + 5)
    except queue.Empty:
        raise BarkError(f"--dask {address}: nothing answered there as a Dask scheduler in {DASK_TIMEOUT_S + 5} s") from None
    if isinstance(got, BaseException):
        raise BarkError(f"--dask {address}: no Dask scheduler answers there ({type(got).__name__}: "
                        f"{str(got).splitlines()[0][:120] if str(got) else ''})") from None
    return got


JSON_COLUMNS = ("n_patches", "mean_orientation_deg", "circular_sd_deg", "mean_anisotropy", "t", "wall_s")
"""What ``bark sweep --json`` prints of each run, beside its key, settings and seed (the table's
columns; sweep.sqlite has every one)."""


def _finish(plan, folder, counts: dict, quiet: bool, pictures=("png", 150), as_json: bool = False) -> None:
    from bark.studies.sweep import SweepTable
    from bark.model.effects import in_format
    from bark_cli import write_owned
    from bark_cli.figures import plot_montage

    points = plan.points()
    with SweepTable(folder / "sweep.sqlite") as table:
        rows = table.rows([p.key for p in points])
        by_key = {r["key"]: r for r in rows}
        drawn = None
        if not plan.listed and len(plan.axes) <= 2 and math.prod(plan.shape) <= MONTAGE_CELLS:
            def montage(path):  # nothing run yet: no sheet, and none of an earlier sweep's
                if plot_montage(plan, points, by_key, table, path) is None:
                    path.unlink(missing_ok=True)

            name = in_format("montage.png", pictures[0])
            write_owned(folder, in_formats(("montage.png",)), pictured({"montage.png": montage}, *pictures))
            drawn = folder / name if (folder / name).exists() else None
        else:  # no montage for more axes or cells: none of an earlier sweep's is left to mislead
            write_owned(folder, in_formats(("montage.png",)), {})
    if as_json:  # every run, as the table shows them; what was written said on stderr
        from bark.io.files import json_text

        click.echo(json_text({
            "table": str(folder / "sweep.sqlite"), "montage": None if drawn is None else str(drawn), **counts,
            "runs": [{"key": p.key, **p.settings, "seed": p.seed, **{c: by_key[p.key][c] for c in JSON_COLUMNS}}
                     for p in points]}, indent=2))
    elif not quiet:
        from rich.console import Console
        from rich.table import Table

        t = Table(*[a.key for a in plan.axes], "seed", "patches", "orientation (°)", "SD (°)", "anisotropy", "t", "wall (s)",
                  title=f"bark sweep: {counts['ran']} runs now, {counts['skipped']} already in the table")
        for p in points[:TABLE_ROWS]:
            r = by_key[p.key]
            t.add_row(*[value_text(v) for v in p.settings.values()], str(p.seed),
                      str(r["n_patches"]), _g(r["mean_orientation_deg"]), _g(r["circular_sd_deg"]), _g(r["mean_anisotropy"]),
                      _g(r["t"]), _g(r["wall_s"]))
        if len(points) > TABLE_ROWS:
            t.caption = f"the first {TABLE_ROWS} of {len(points)} runs; every one is in sweep.sqlite"
        Console(width=150).print(t)
    click.echo(f"bark: {counts['total']} runs in {folder / 'sweep.sqlite'} ({counts['ran']} run now, "
               f"{counts['skipped']} already there)" + (f"; montage in {drawn}" if drawn else
                                                         "; no montage for a list of points" if plan.listed else
                                                         f"; no montage for more than two axes or {MONTAGE_CELLS} points"),
               err=as_json)


def _g(v) -> str:
    return "—" if v is None else f"{v:.4g}"
