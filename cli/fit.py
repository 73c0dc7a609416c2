"""``bark fit``: which scene settings could have grown an observed bark (ABC-SMC, ``bark.studies.fit``),
with the posterior drawn (corner.png), checked against the observation (predictive.png) and
summarised (fit.json, posterior.csv)."""

from __future__ import annotations

import math
import shlex
import signal
import sys
import time

import click

from bark.errors import BarkError
from bark_cli.options import SCENE_RULE, json_option, progress_option
from bark_cli.patterns import in_formats, picture_options, pictured

CONTEXT = {"help_option_names": ["-h", "--help"]}
FIT_FILES = ("fit.json", "posterior.csv", "corner.png", "predictive.png")
"""The files ``bark fit`` writes into --out beside its database (fit.db)."""


def parse_marks(items: tuple[str, ...], keys: tuple[str, ...]) -> dict[str, dict]:
    """``--mark "vertical:growth.G=0.014,mechanics.f_max=0.0028"`` → ``{label: {key: value}}``, every
    fitted setting given."""
    from bark_cli.options import split_setting

    out = {}
    for item in items:
        label, colon, rest = item.partition(":")
        point = {}
        for part in rest.split(",") if colon else []:
            setting = split_setting(part.strip())
            try:
                value = float(setting[2]) if setting is not None else math.nan
            except ValueError:
                value = math.nan
            if setting is None or not math.isfinite(value):
                point = None
                break
            point[f"{setting[0]}.{setting[1]}"] = value
        if not label.strip() or not point:
            raise BarkError(f"--mark {shlex.quote(item)}: expected LABEL:SECTION.KEY=VALUE,..., e.g. "
                            "--mark vertical:growth.G=0.014,mechanics.f_max=0.0028")
        if set(point) != set(keys):
            raise BarkError(f"--mark {shlex.quote(item)}: give a value for each fitted setting ({', '.join(keys)}), "
                            "and no other")
        out[label.strip()] = point
    return out


@click.command(context_settings=CONTEXT)
@click.argument("observed", type=click.Path(), metavar="OBSERVED")
@click.option("--scene", "scene_file", default=None, metavar="SCENE",
              help=f"Scene every run starts from: the name of one {SCENE_RULE}. [default: the default scene]")
@click.option("--prior", "priors", multiple=True, metavar="SECTION.KEY=LOW:HIGH[:log]",
              help="A fitted setting and its uniform prior (:log: uniform in its logarithm); repeatable. "
                   "[default: --prior growth.G=0.005:0.016 --prior mechanics.f_max=0.002:0.01]")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE", help="Any other scene setting, for every run.")
@click.option("--statistics", default=None, metavar="NAME,...",
              help="The statistics compared: orientation, sd, anisotropy, size_mean, n_bar, v_bar, t_fraction, "
                   "nematic_order. [default: every one OBSERVED has]")
@click.option("--population", type=click.IntRange(2, 100_000), default=100, show_default=True,
              help="Accepted runs per generation.")
@click.option("--generations", type=click.IntRange(1, 1000), default=5, show_default=True,
              help="Generations (each with a smaller tolerance); a fit run again with more goes on.")
@click.option("--min-acceptance", type=click.FloatRange(0, 1, max_open=True), default=0.0, show_default=True,
              help="Stop once a generation accepts fewer than this share of its runs.")
@click.option("--seed", type=click.IntRange(0, 2**63 - 1), default=0, show_default=True,
              help="Seed of every draw: the same seed gives the same posterior, on any number of workers.")
@click.option("--mirror", is_flag=True,
              help="Fit OBSERVED seen in a mirror held along the trunk (orientation o -> 180° - o): for a tree "
                   "whose spiral turns the other way from the scene's.")
@click.option("--min-size", type=click.IntRange(1, 10**9), default=None,
              help="Patches of OBSERVED with fewer leaf bases are left out. [default: its run's own, else 7]")
@click.option("--predictive", type=click.IntRange(0, 10_000), default=40, show_default=True,
              help="Runs drawn from the posterior for predictive.png (0: none).")
@click.option("--mark", "marks", multiple=True, metavar="LABEL:SECTION.KEY=VALUE,...",
              help="A point to mark on corner.png and place in the posterior (fit.json: its highest-density level); "
                   "repeatable.")
@click.option("--workers", type=click.IntRange(1, 4096), default=None, help="Local worker processes. [default: 1]")
@click.option("--dask", "dask_address", default=None, metavar="ADDRESS",
              help="Run on the Dask distributed cluster whose scheduler is at ADDRESS (tcp://host:8786) instead.")
@click.option("--out", default="bark-fit", show_default=True, type=click.Path(file_okay=False),
              help="Folder for fit.db (every generation, as it ends), fit.json, posterior.csv, corner.png and "
                   "predictive.png. A fit run again into it goes on where it stopped.")
@click.option("--quiet", is_flag=True, help="No progress and no table.")
@progress_option
@json_option
@picture_options
def fit(observed, scene_file, priors, sets, statistics, population, generations, min_acceptance, seed, mirror, min_size,
        predictive, marks, workers, dask_address, out, quiet, progress_every, as_json, picture_format, dpi):
    """Find the scene settings that grow bark like OBSERVED (a run folder, a state .npz, a leaf-base
    .csv or a .toml summary, as bark compare takes): approximate Bayesian computation by sequential
    Monte Carlo on the patterns' statistics. Each generation is kept in --out/fit.db as it ends;
    killed or stopped, the same command goes on from the last one."""
    from bark.engine.scene import merge, read_toml
    from bark.io.folder import held_folder
    from bark.studies.fit import DEFAULT_PRIORS, Fit, Observed, Prior, needs_pyabc
    from bark_cli.main import _parse_set
    from bark_cli.options import NAMER, Provenance, split_setting
    from bark_cli.sweep import _dask_client, parse_ranges

    prov = Provenance(aliases={(None, "out"): "--out", (None, "workers"): "--workers", (None, "seed"): "--seed"})
    NAMER.set(prov.name)
    needs_pyabc(load=False)  # installed; imported only once every setting is checked
    if dask_address is not None and workers is not None:
        raise BarkError("--workers and --dask: local processes or a Dask cluster, not both")
    ranges = parse_ranges(priors, "--prior") if priors else {p.key: (p.low, p.high, p.log) for p in DEFAULT_PRIORS}
    prior_layer: dict = {}
    for item in priors:  # a fitted setting is named in messages as its --prior was typed
        section, key, _ = split_setting(item) or ("", item, "")
        prior_layer.setdefault(section, {})[key] = item
        prov.prior_items[(section, key)] = item.strip()
    set_layer, prov.set_items = _parse_set(sets)
    base = prov.add(f"file:{scene_file}", read_toml(scene_file)) if scene_file else {}
    base = merge(base, prov.add("--set", set_layer))
    prov.add("--prior", prior_layer)
    clash = [k for k in ranges if k.partition(".")[2] in set_layer.get(k.partition(".")[0], {})]
    if clash:
        raise BarkError(f"--prior {clash[0]} and --set {clash[0]}: a setting is fitted or set, not both")
    names = tuple(s.strip() for s in statistics.split(",") if s.strip()) if statistics is not None else ()
    plan = Fit(observed=Observed.read(observed, min_size, mirror), base=base,
               priors=tuple(Prior(k, lo, hi, log) for k, (lo, hi, log) in ranges.items()), statistics=names,
               population=population, generations=generations, min_acceptance=min_acceptance, seed=seed)
    plan.check(None if dask_address is not None else workers or 1)  # one line before anything is written
    points = parse_marks(marks, plan.keys)
    client = _dask_client(dask_address) if dask_address is not None else None
    with held_folder(out) as held:
        _fit(plan, held.path, workers or 1, client, quiet, predictive, points, (picture_format, dpi), progress_every,
             as_json)


class _Progress:
    """A line per generation on stderr, and within one the accepted runs counted (``Tally``: a bar on
    a terminal, a line every ``every_s`` seconds in a log)."""

    def __init__(self, quiet: bool, every_s: float = 30.0) -> None:
        from bark_cli.progress import Tally

        self.quiet = quiet
        self.t0 = time.perf_counter()
        self.tally = Tally("fit", "accepted", every_s, quiet)
        self.label = None

    def runs(self, t: int, accepted: int, n: int, runs: int) -> None:
        label = "calibration" if t < 0 else f"generation {t}"
        if label != self.label:
            self.tally.restart()
            self.label = label
        self.tally.update(accepted, n, f"{label}, {runs:,} runs")

    def generation(self, g) -> None:
        if self.quiet:
            return
        self.tally.say(f"bark: generation {g.t}: {g.accepted} accepted of {g.runs} runs ({100 * g.acceptance:.1f} %), "
                       f"ε {g.epsilon:.4g}, ESS {g.ess:.0f}, {_clock(time.perf_counter() - self.t0)}")

    def close(self) -> None:
        self.tally.close()


def _clock(seconds: float) -> str:
    m, s = divmod(int(seconds), 60)
    return f"{m}m{s:02d}s" if m else f"{seconds:.1f}s"


def _fit(plan, folder, workers: int, client, quiet: bool, n_predictive: int, marks: dict, pictures,
         every_s: float = 30.0, as_json: bool = False) -> None:
    from bark.studies.fit import predictive, run_fit
    from bark.studies.pool import WorkerDied
    from bark_cli.main import Signals

    progress = _Progress(quiet, every_s)
    database = folder / "fit.db"
    with Signals() as signals:  # SIGTERM and SIGHUP stop a fit as Ctrl-C does: the finished generations stay
        try:
            result = run_fit(plan, database, workers=workers, client=client, progress=progress.runs,
                             generation_done=progress.generation)
            runs = predictive(result, n_predictive, workers=workers, client=client) if n_predictive else []
        except WorkerDied as err:
            progress.close()
            click.echo(f"bark: {err}", err=True)
            sys.exit(1)
        except KeyboardInterrupt:
            progress.close()
            signum = signals.received or signal.SIGINT
            try:  # counted for the message; a second signal meanwhile skips the count, nothing else
                from bark.studies.fit import load_fit

                n = len(load_fit(plan, database).generations)
                held = f"{n} generation{'s' if n != 1 else ''} in {database}"
            except KeyboardInterrupt:
                held = f"the generations finished are in {database}"
            click.echo(f"bark: fit stopped by {signal.Signals(signum).name}: {held}; the same command goes on", err=True)
            sys.exit(128 + int(signum))
        except Exception as err:
            why = _refused_by_the_disk(err)
            if why is None:
                raise
            progress.close()
            click.echo(f"bark: error: {database}: could not be written ({why}); the generations finished before are "
                       "kept in it: once there is room, the same command goes on", err=True)
            sys.exit(1)
        finally:
            progress.close()
            if client is not None:
                client.close()
    _finish(result, folder, runs, marks, quiet, pictures, as_json)


def _refused_by_the_disk(err: BaseException) -> str | None:
    """Why the file system refused the fit's database (a full disk, a quota, a file-size limit),
    found in ``err`` or what it wraps (SQLAlchemy's ``orig``, the exception's causes); ``None``
    when that is not what happened."""
    import errno
    import sqlite3

    seen = 0
    while err is not None and seen < 8:
        if isinstance(err, OSError) and err.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
            return err.strerror or str(err)
        if isinstance(err, sqlite3.OperationalError) and any(
                words in str(err) for words in ("disk is full", "disk I/O error", "too large")):
            return str(err)
        err, seen = getattr(err, "orig", None) or err.__cause__ or err.__context__, seen + 1
    return None


def _finish(result, folder, runs: list[dict], marks: dict, quiet: bool, pictures, as_json: bool = False) -> None:
    from bark.io.files import json_text, write_columns, write_json
    from bark.studies.fit import CREDIBLE
    from bark_cli import write_owned

    fit = result.fit
    estimates = result.estimates()
    x, w = result.posterior()
    report = {
        "observed": {"name": fit.observed.name, "source": fit.observed.source, "statistics": fit.observed.values},
        "statistics": list(fit.compared),
        "priors": [p.as_dict() for p in fit.priors],
        "population": fit.population, "seed": fit.seed, "stop_reason": result.stop_reason,
        "posterior": estimates,
        "credible": "central 90 % interval: the 5 % and 95 % weighted quantiles of the last generation",
        "generations": [{"t": g.t, "epsilon": g.epsilon, "runs": g.runs, "accepted": g.accepted,
                         "acceptance": g.acceptance, "ess": g.ess} for g in result.generations],
        "runs": sum(g.runs for g in result.generations),
        "marks": {label: {"settings": p, "hpd_level": result.hpd_level(p)} for label, p in marks.items()},
        "predictive": runs,
    }
    writers = {
        "fit.json": lambda path: write_json(path, report),
        "posterior.csv": lambda path: write_columns(path, {**{k: x[:, j].tolist() for j, k in enumerate(fit.keys)},
                                                          "weight": w.tolist()}),
        "corner.png": lambda path: plot_corner(result, marks, path),
    }
    if runs:
        writers["predictive.png"] = lambda path: plot_predictive(fit, runs, path)
    written = write_owned(folder, in_formats(FIT_FILES), pictured(writers, *pictures))
    if as_json:  # fit.json's content alone on stdout, what was written said on stderr
        click.echo(json_text(report, indent=2))
    elif not quiet:
        from rich.console import Console
        from rich.table import Table

        table = Table("setting", "prior", "posterior mean", "SD", "90 % credible interval",
                      title=f"bark fit: {fit.observed.name}, on {', '.join(fit.compared)} "
                            f"({report['runs']} runs in {len(result.generations)} generations)")
        for p in fit.priors:
            e = estimates[p.key]
            table.add_row(p.key, f"{p.low:.4g} – {p.high:.4g}" + (" (log)" if p.log else ""), f"{e['mean']:.4g}",
                          f"{e['sd']:.2g}", f"{e['ci90'][0]:.4g} – {e['ci90'][1]:.4g}")
        Console(width=150).print(table)
        for label, entry in report["marks"].items():
            level = entry["hpd_level"]
            click.echo(f"  {label}: {100 * level:.0f} % of the posterior is more probable "
                       f"({'inside' if level <= CREDIBLE else 'outside'} the 90 % highest-density region)")
    click.echo(f"wrote fit.db, {', '.join(written)} to {folder}", err=as_json)
    if len(written) != len(writers):
        sys.exit(1)


def _label(key: str) -> str:
    """An axis label with its unit, in the model's units as table columns name them (bark.units:
    lu length units of 0.3 m, tu time units of 88.5 days, fu force units)."""
    return {"growth.G": "G, growth constant (lu / tu^½, sqrt growth)", "mechanics.f_max": "f_max, breaking force (fu)",
            "mechanics.b": "b, damping (fu · tu / lu)", "mechanics.c": "c, anchor stiffness (fu / lu)",
            "mechanics.k": "k, spring stiffness (fu / lu)"}.get(key, key)


def plot_corner(result, marks: dict, path) -> None:
    """The posterior's corner plot: each setting's marginal (weighted histogram and KDE) on the
    diagonal, each pair's weighted sample and its 50 % and 90 % highest-density contours below;
    ``marks`` drawn as labelled points; the axes span the priors."""
    import numpy as np
    from scipy.stats import gaussian_kde

    from bark_cli.plot import new_figure, save_figure

    fit = result.fit
    x, w = result.posterior()
    intervals = {key: e["ci90"] for key, e in result.estimates().items()}
    d = len(fit.keys)
    fig = new_figure(figsize=(3.2 * d + 0.8, 3.2 * d + 0.4), dpi=130, layout="constrained")
    axes = fig.subplots(d, d, squeeze=False)
    colours = ["#CC3311", "#0077BB", "#009988", "#EE7733", "#33BBEE", "#EE3377", "#BBBBBB"]
    for i, pi in enumerate(fit.priors):
        for j, pj in enumerate(fit.priors):
            ax = axes[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:  # the weight per bin (equal bins in the prior's own scale), its KDE drawn to match
                bins = np.geomspace(pi.low, pi.high, 25) if pi.log else np.linspace(pi.low, pi.high, 25)
                heights, _, _ = ax.hist(x[:, i], bins=bins, weights=w, color="#4477AA", alpha=0.6)
                if len(np.unique(x[:, i])) > 1:
                    grid = np.geomspace(pi.low, pi.high, 200) if pi.log else np.linspace(pi.low, pi.high, 200)
                    density = gaussian_kde(pi.scaled(x[:, i]), weights=w)(pi.scaled(grid))
                    ax.plot(grid, density / len(heights), color="#222222", lw=1.2)  # weight per bin of 1/24 of the range
                lo, hi = intervals[pi.key]
                ax.axvspan(lo, hi, color="#4477AA", alpha=0.12, lw=0)
                ax.set_yticks([])
                for k, (label, p) in enumerate(marks.items()):
                    ax.axvline(p[pi.key], color=colours[k % len(colours)], lw=1.2, ls="--")
            else:
                ax.scatter(x[:, j], x[:, i], s=4 + 400 * w, color="#4477AA", alpha=0.5, lw=0)
                if len(x) > d + 1:
                    _contours(ax, x[:, [j, i]], w, (pj, pi))
                for k, (label, p) in enumerate(marks.items()):
                    ax.plot(p[pj.key], p[pi.key], marker="*", ms=max(6, 16 - 3 * k), color=colours[k % len(colours)],
                            mec="white", mew=0.8, ls="none", label=label)  # each smaller: marks on one point all show
                _prior_axis(ax, "y", pi)
            _prior_axis(ax, "x", pj)
            ax.tick_params(axis="x", labelrotation=30)
            if i == d - 1:
                ax.set_xlabel(_label(pj.key))
            if j == 0 and i > 0:
                ax.set_ylabel(_label(pi.key))
    if marks and d > 1:
        axes[1, 0].legend(loc="best", fontsize=8, framealpha=0.8)
    elif marks:
        for k, label in enumerate(marks):
            axes[0, 0].plot([], [], color=colours[k % len(colours)], ls="--", label=label)
        axes[0, 0].legend(fontsize=8)
    g = len(result.generations)
    fig.suptitle(f"posterior for {fit.observed.name}: {g} generation{'s' if g != 1 else ''} of {fit.population}\n"
                 "shaded: 90 % credible interval" + ("; contours: 50 % and 90 % highest density" if d > 1 else ""), fontsize=9)
    save_figure(fig, path)


def _prior_axis(ax, which: str, prior) -> None:
    """The ``x`` or ``y`` axis of ``ax`` spanning ``prior``'s range, logarithmic (four plain ticks) for ``:log``."""
    import numpy as np
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    getattr(ax, f"set_{which}lim")(prior.low, prior.high)
    if prior.log:
        getattr(ax, f"set_{which}scale")("log")
        getattr(ax, f"set_{which}ticks")(np.geomspace(prior.low, prior.high, 4))
        axis = getattr(ax, f"{which}axis")
        axis.set_major_formatter(FormatStrFormatter("%.3g"))
        axis.set_minor_formatter(NullFormatter())


def _contours(ax, xy, w, priors) -> None:
    """50 % and 90 % highest-density contours of the weighted sample ``xy`` (a KDE in the priors' scaled space)."""
    import numpy as np
    from scipy.stats import gaussian_kde

    s = np.column_stack([priors[0].scaled(xy[:, 0]), priors[1].scaled(xy[:, 1])])
    try:
        kde = gaussian_kde(s.T, weights=w)
    except (np.linalg.LinAlgError, ValueError):  # a sample on a line: no density to draw
        return
    at = kde(s.T)
    order = np.argsort(-at)
    mass = np.cumsum(w[order])
    levels = sorted({float(at[order][min(np.searchsorted(mass, q), len(at) - 1)]) for q in (0.5, 0.9)})
    g = [np.geomspace(p.low, p.high, 120) if p.log else np.linspace(p.low, p.high, 120) for p in priors]
    gx, gy = np.meshgrid(*g)
    z = kde(np.vstack([priors[0].scaled(gx.ravel()), priors[1].scaled(gy.ravel())])).reshape(gx.shape)
    if len(levels) == 2 and levels[0] < levels[1]:
        ax.contour(gx, gy, z, levels=levels, colors=["#222222", "#222222"], linewidths=[0.8, 1.4])


def plot_predictive(fit, runs: list[dict], path) -> None:
    """Each compared statistic: the runs drawn from the posterior (histogram) against the observed value (line)."""
    import numpy as np

    from bark_cli.plot import new_figure, save_figure

    names = fit.compared
    cols = min(4, len(names))
    rows = -(-len(names) // cols)
    fig = new_figure(figsize=(3.0 * cols + 0.6, 2.8 * rows + 0.4), dpi=130, layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat[len(names):]:
        ax.set_visible(False)
    units = {"orientation": "orientation (°)", "sd": "circular SD (°)"}
    for ax, name in zip(axes.flat, names):
        values = np.array([r["statistics"][name] for r in runs if r["statistics"][name] is not None], dtype=float)
        ax.hist(values, bins=min(20, max(5, len(values) // 3)), color="#4477AA", alpha=0.7,
                range=(0, 180) if name == "orientation" else None)
        ax.axvline(fit.observed.values[name], color="#CC3311", lw=2, label="observed")
        ax.set_xlabel(units.get(name, name))
        ax.set_yticks([])
        missing = len(runs) - len(values)
        if missing:
            ax.set_title(f"{missing} run{'s' if missing > 1 else ''} without it", fontsize=8)
    axes[0, 0].legend(fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel(f"{len(runs)} runs from the posterior")
    fig.suptitle(f"posterior predictive: {fit.observed.name}", fontsize=9)
    save_figure(fig, path)
