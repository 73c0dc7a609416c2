"""``bark`` — the command line.

    bark simulate --growth sqrt --breaker threshold      # the default scene (vertical regime)
    bark simulate --scene diamond --out runs/diamond
    bark strategies                                      # what is installed, by kind
    bark bench speed                                     # steps per second

The CLI parses and reports; running a scene to its outputs is the library's (``bark.studies.runner``).
Errors in what the user typed (an option value, a scene key, a file) print one line naming the
option or scene key as the user gave it, and exit with status 2, before anything is written.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import logging
import os
import shlex
import signal
import sys
import threading
import warnings

import click

from bark.errors import BarkError, BarkWarning
from bark.engine.scene import DEFAULT_STRATEGIES, Scene, merge, read_toml
from bark.contract.strategies import KINDS
from bark_cli import REASONS, Interrupted
from bark_cli.options import (NAMER, SCENE_RULE, LazyHelpOption, Provenance, name_ref, overrides_from, seconds,
                              parameter_options, setting_value, split_setting)

CONTEXT = {"help_option_names": ["-h", "--help"]}


COMMAND_LINE: contextvars.ContextVar[str | None] = contextvars.ContextVar("command_line", default=None)
"""The command line as typed (summary.json's provenance records it)."""


class BarkGroup(click.Group):
    """A click group whose failures are one line on stderr, never a traceback or a usage dump."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        """Run the command with bark's warnings shown as one line each, once, whatever the caller's warning
        filters."""
        with warnings.catch_warnings():  # the command shows the library's warnings its way, whatever the
            warnings.simplefilter("default", BarkWarning)  # caller's filters (-W error): one line each, once
            warnings.showwarning = _show_warning
            return self._main(args, prog_name, complete_var, **extra)

    def _main(self, args, prog_name, complete_var, **extra):
        # bark's commands draw into files only: matplotlib's Agg, whatever MPLBACKEND a user set for
        # their own sessions (a window backend, or a mistyped one, broke every picture)
        os.environ["MPLBACKEND"] = "agg"
        token = NAMER.set(None)
        COMMAND_LINE.set(shlex.join(["bark", *(sys.argv[1:] if args is None else args)]))
        _listen_to_the_library()
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.exceptions.NoArgsIsHelpError as err:  # `bark` alone: its help, as `bark --help` gives it
            click.echo(err.ctx.get_help())
            sys.exit(0)
        except click.ClickException as err:
            click.echo(f"bark: error: {err.format_message()}", err=True)
            sys.exit(err.exit_code)
        except BarkError as err:
            click.echo(f"bark: error: {err.render(name_ref)}", err=True)
            sys.exit(2)
        except StoppedBeforeStart as stop:
            click.echo(f"bark: {REASONS[stop.signum]} before the run began: nothing was run", err=True)
            sys.exit(128 + int(stop.signum))
        except OSError as err:  # the file system refused what no command says itself: one line, status 1
            where = f"{err.filename}: " if err.filename else ""
            click.echo(f"bark: error: {where}{err.strerror or err}", err=True)
            sys.exit(1)
        except (click.Abort, KeyboardInterrupt) as err:  # click makes a KeyboardInterrupt an Abort (its cause)
            signum = getattr(err.__cause__ if isinstance(err, click.Abort) else err, "signum", signal.SIGINT)
            click.echo(f"bark: {REASONS[signum]}", err=True)
            sys.exit(128 + int(signum))
        finally:
            NAMER.reset(token)
        sys.exit(rv if isinstance(rv, int) else 0)


@click.group(cls=BarkGroup, context_settings=CONTEXT)
@click.version_option(package_name="bark-grasstree")
def cli():
    """Grow a virtual grasstree trunk and let its layer of leaf bases crack."""


def _strategy_option(kind: str):
    def text() -> str:
        from bark.contract import registry

        return (f"{kind.capitalize()} strategy, by name: {', '.join(registry.available(kind)) or 'none installed'} "
                f"(`bark strategies` shows their parameters). [default: {DEFAULT_STRATEGIES[kind]}]")

    return click.option(f"--{kind}", f"{kind}_name", cls=LazyHelpOption, lazy_help=text, default=None, metavar="NAME")


def _parse_set(items: tuple[str, ...]) -> tuple[dict, dict]:
    """``--set growth.G=0.01`` → ``{"growth": {"G": 0.01}}`` (values parsed as TOML), and the text
    of each item by (section, key), for messages."""
    out: dict = {}
    raw: dict = {}
    for item in items:
        parts = split_setting(item)
        if parts is None:
            raise BarkError(f"--set {shlex.quote(item)}: expected SECTION.KEY=VALUE, e.g. --set growth.G=0.011")
        section, name, text = parts
        out.setdefault(section, {})[name] = setting_value(text)
        raw[(section, name)] = shlex.quote(item)
    return out, raw


def resolve_scene(scene_file, strategies: dict, shortcuts: dict, sets: tuple, kwargs: dict,
                  pictures: dict | None = None) -> Scene:
    """The scene a command runs: file (or defaults) ← strategy names ← --set ← explicit options.

    A strategy named on the command line comes before ``--set``, so that ``--growth linear --set
    growth.G=0.05`` runs the linear law with G = 0.05 (a new strategy drops the parameters the scene
    file gave the old one, never those given here).  Errors from here on name settings as given."""
    prov = Provenance(aliases={("effects", "picture_format"): "--format", ("effects", "picture_dpi"): "--dpi"})
    NAMER.set(prov.name)
    sets, prov.set_items = _parse_set(sets)
    names = {s: {"name": n} for s, n in strategies.items() if n is not None}
    for section, table in names.items():
        given = sets.get(section, {}).get("name")
        if given is not None and given != table["name"]:
            raise BarkError(f"--{section} {table['name']} and --set {section}.name={given} name two different strategies")
    data = prov.add(f"file:{scene_file}", read_toml(scene_file)) if scene_file else {}
    options = overrides_from(kwargs)
    set_stops = _command_line_stops(sets, options)
    for source, layer in (("option", names), ("--set", sets),
                          ("option", {section: {k: v for k, v in given.items() if v is not None}
                                      for section, given in shortcuts.items() if any(v is not None for v in given.values())}),
                          ("option", options),
                          ("option", {"effects": {k: v for k, v in (pictures or {}).items() if v is not None}})):
        data = merge(data, prov.add(source, layer))
    data.setdefault("run", {}).update(set_stops)  # beside the options' stop conditions, not replaced by them
    return Scene.from_dict(data)


def _command_line_stops(sets: dict, options: dict) -> dict:
    """The stop conditions ``--set run.until_*`` gives that an ``--until-*`` option on the same line
    would otherwise replace (stop conditions on the command line replace the scene file's, and are
    one set); the same one given both ways with two values is refused."""
    from bark.engine.scene import STOP_KEYS

    given = {k: v for k, v in options.get("run", {}).items() if k in STOP_KEYS}
    by_set = {k: v for k, v in sets.get("run", {}).items() if k in STOP_KEYS}
    for key in given.keys() & by_set.keys():
        if given[key] != by_set[key]:
            raise BarkError(f"--{key.replace('_', '-')} {given[key]} and --set run.{key}={by_set[key]} give two values "
                            "for one stop condition: give one")
    return {k: v for k, v in by_set.items() if k not in given} if given else {}


class StoppedBeforeStart(Exception):
    """A signal came while the scene was still being built: exit 128 + signal, nothing run."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


class Signals:
    """SIGINT (Ctrl-C), SIGTERM (``kill``, ``timeout``, schedulers) and SIGHUP stop a run between two
    steps: the handler only notes the signal, which the runner reads after each advance, so a step
    and the final writes are never cut.  Before the first step (building a large scene) and while a
    picture is drawn (the data are already written), a signal stops at once; pictures are drawn in
    another process beside the final writes, and one that came meanwhile stops them once those are
    done (a picture already drawn is kept)."""

    def __init__(self) -> None:
        self.received: int | None = None
        self.count = 0
        """Signals received so far."""
        self.drawing = False
        self.started = False
        self._previous: dict = {}

    def _handle(self, signum, frame) -> None:
        self.count += 1
        if self.received is None:
            self.received = signum
        if self.drawing or not self.started:  # a picture, or a run not yet begun: nothing to lose
            raise Interrupted(signum)

    def reason(self) -> str | None:
        """The runner asks after every advance: from the first, a signal waits for the step to end."""
        self.started = True
        return None if self.received is None else REASONS[self.received]

    @contextlib.contextmanager
    def draw(self):
        """While the body runs a picture is being drawn: a signal then stops the command at once (the data are
        already written)."""
        self.drawing = True
        try:
            yield
        finally:
            self.drawing = False

    def __enter__(self) -> "Signals":
        if threading.current_thread() is threading.main_thread():
            for sig in REASONS:
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


def _pictures(signals: Signals, painter) -> dict:
    """The runner's picture writers, drawn by ``painter`` (``bark_cli.pictures``: matplotlib is
    imported only when a scene asks for a picture, and then beside the run, not after it).  Each
    hands its picture's data to the painter and returns the wait for it (``runner``: the data are
    written meanwhile); a signal while waiting stops the drawing at once."""
    from bark_cli.pictures import PICTURES

    def submitted(kind, data_of):
        def draw(sim, scene, recorded, path):
            wait, before = painter().submit(kind, data_of(sim, scene, recorded), path, scene.run.min_patch_size,
                                            scene.picture_dpi), signals.count

            def waited():  # a signal since it was handed over came while it was drawn: stop it now
                with signals.draw():
                    wait(stop=signals.count > before)
            return waited
        return draw

    return {effect: (name, submitted(kind, data_of)) for effect, (name, kind, data_of) in PICTURES.items()}


def _painter(scene=None):
    """A painter that imports ahead what draws the pictures ``scene`` asks for (every kind: none given)."""
    from bark_cli.pictures import PICTURES, Painter

    drawn = None if scene is None else [PICTURES[name][1] for name in PICTURES if scene.has(name)]
    return Painter(kinds=drawn)


class _Lazy:
    """``make()`` called once, on first use."""

    def __init__(self, make) -> None:
        self._make, self.made = make, None

    def __call__(self):
        if self.made is None:
            self.made = self._make()
        return self.made


def _typed(option: click.Parameter) -> str:
    """An option as a user types it: its long form (``--scene``, ``--set``), or its short one if it
    has no other (``-G`` has both: ``-G``, the one the help shows first)."""
    return option.opts[0] if option.opts else option.name


def _warn(message: str) -> None:
    click.echo(f"bark: warning: {message}", err=True)


_python_show_warning = warnings.showwarning


class _Notices(logging.Handler):
    """The library's notices (logger ``bark``, level INFO: a first compilation) as ``bark: ...`` lines."""

    def emit(self, record: logging.LogRecord) -> None:
        _notice(record.getMessage())


def _listen_to_the_library(quiet: bool = False) -> None:
    log = logging.getLogger("bark")
    if not any(isinstance(h, _Notices) for h in log.handlers):
        log.addHandler(_Notices())
        log.propagate = False
    log.setLevel(logging.WARNING if quiet else logging.INFO)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """The library's warnings (:class:`~bark.errors.BarkWarning`) as one line, ``bark: warning: ...``."""
    if issubclass(category, BarkWarning):
        _warn(str(message))
    else:
        _python_show_warning(message, category, filename, lineno, file, line)


def _notice(message: str) -> None:
    click.echo(f"bark: {message}", err=True)


def scene_of(params: dict) -> Scene:
    """The scene ``bark simulate`` runs for its parsed options ``params`` (one-line BarkError if bad)."""
    strategies = {kind: params[f"{kind}_name"] for kind in KINDS}
    settings = {k: v for k, v in params.items() if "__" in k}  # the options generated from scene fields
    shortcuts = {"growth": {"r0": params["r0"], "G": params["G"]},
                 "breaker": {"spread": params["fmax_spread"], "weibull_shape": params["fmax_weibull_shape"]}}
    return resolve_scene(params["scene_file"], strategies, shortcuts, params["sets"],
                         settings, {"picture_format": params["picture_format"], "picture_dpi": params["dpi"]})


@cli.command(context_settings=CONTEXT)
@click.option("--scene", "scene_file", default=None, metavar="SCENE",
              help=f"A scene: the name of one {SCENE_RULE}. Options given here override it.")
@_strategy_option("growth")
@_strategy_option("integrator")
@_strategy_option("breaker")
@_strategy_option("resin")
@_strategy_option("analyzer")
@click.option("--r0", type=float, default=None, help="Initial trunk radius r_i of the growth law, length units (1 = 0.3 m). [default: 0.2]")
@click.option("-G", "--growth-rate", "G", type=float, default=None,
              help="Growth constant G of the growth law (sqrt: length / time^½; linear: length / time). [default: 0.014]")
@click.option("--fmax-spread", type=float, default=None,
              help="Relative spread of the springs' breaking thresholds about f_max (log-normal; the breaker's "
                   "spread). [default: 0]")
@click.option("--fmax-weibull-shape", type=float, default=None,
              help="Instead, draw each threshold from a Weibull law of this shape, mean f_max (the breaker's "
                   "weibull_shape).")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE",
              help="Set any scene key, e.g. a plugin's parameter: --set breaker.nu=50 (repeatable).")
@parameter_options
@click.option("--out", "out", default="bark-out", show_default=True,
              help="Output folder (created; '' is the current folder). A finished run's files in it are replaced; "
                   "an unfinished run's are kept unless --overwrite.")
@click.option("--overwrite", is_flag=True, help="Discard an unfinished run in --out (its checkpoint) instead of refusing.")
@click.option("--resume", "resume", default=None, metavar="FOLDER",
              help="Go on with the interrupted run in this folder (its checkpoint has every setting).")
@click.option("--checkpoint-every", type=click.FloatRange(0, 1e9), default=60.0, show_default=True,
              help="Seconds of wall time between checkpoints (0: only at the end and on a signal).")
@click.option("--quiet", is_flag=True, help="No progress, no summary table, no notices (warnings and errors stay).")
@click.option("--progress-every", type=click.FloatRange(0, 1e9), default=30.0, show_default=True, callback=seconds,
              help="Where stderr is not a terminal (a batch job's log): seconds of wall time between two progress "
                   "lines (0: one a step).")
@click.option("--json", "as_json", is_flag=True, help="Print the run's summary as JSON on stdout (summary.json's "
              "content) instead of the table.")
@click.option("--format", "picture_format", type=click.Choice(["png", "pdf", "svg"]), default=None,
              help="Format of the still pictures (pattern.pdf, ...; the animation stays a GIF). [default: png]")
@click.option("--dpi", type=click.IntRange(30, 1200), default=None, help="Resolution of the pictures, dots per inch. [default: 150]")
@click.pass_context
def simulate(ctx, scene_file, growth_name, integrator_name, breaker_name, resin_name, analyzer_name, r0, G, fmax_spread,
             fmax_weibull_shape, sets, out, overwrite,
             resume, checkpoint_every, quiet, progress_every, as_json, picture_format, dpi, **kwargs):
    """Grow the trunk and let the bark crack; write what the scene's effects ask for (by default
    pattern.png, patches.csv, breaks.csv, summary.json, state.npz, checkpoint.npz) to --out.
    Any --until-* option replaces the scene's stop conditions.  Ctrl-C or SIGTERM stops between
    steps, writes the outputs and a checkpoint, and prints the command that goes on."""
    from bark.studies import runner

    _listen_to_the_library(quiet)
    if resume is not None:
        given = [p for p, v in ctx.params.items()
                 if ctx.get_parameter_source(p) == click.core.ParameterSource.COMMANDLINE
                 and p not in ("resume", "quiet", "checkpoint_every", "progress_every", "as_json")]
        if given:
            option = next(p for p in ctx.command.params if p.name == given[0])
            raise BarkError(f"--resume goes on with the settings in its checkpoint: {_typed(option)} cannot be given "
                            "with it")
    else:
        scene = scene_of(ctx.params)
    bar = None
    if not quiet:  # progress on stderr: a bar on a terminal, plain lines in a log
        from bark_cli.progress import ProgressBar, ProgressLog

        bar = ProgressBar() if _is_terminal(sys.stderr) else ProgressLog(progress_every)
    painter = _Lazy(functools.partial(_painter, None if resume is not None else scene))  # resuming: any picture
    if resume is None and any(e.drawn and scene.has(name) for name, e in scene.known_effects.items()):
        painter()  # start it now: matplotlib loads on the other core while the run goes on
    with Signals() as signals:
        hooks = dict(checkpoint_every=checkpoint_every, observe=bar, interrupted=signals.reason,
                     pictures=_pictures(signals, painter), warn=_warn, notice=None if quiet else _notice,
                     command=COMMAND_LINE.get())
        try:
            if resume is not None:
                outcome = runner.resume(resume, **hooks)
            else:
                outcome = runner.run(scene, out, overwrite=overwrite, **hooks)
        except KeyboardInterrupt:  # only raised before the first step (Signals): nothing ran, nothing to save
            raise StoppedBeforeStart(signals.received or signal.SIGINT) from None
        finally:
            try:
                if bar is not None:
                    bar.close()
            finally:  # whatever closing the bar met: no drawing process outlives the command
                if painter.made:
                    painter().close()
    return _report(outcome, quiet, signals.received, as_json)


def _is_terminal(stream) -> bool:
    try:
        return stream is not None and stream.isatty()
    except (ValueError, OSError):  # closed
        return False


def _report(outcome, quiet: bool, signum: int | None = None, as_json: bool = False) -> int:
    """Say how the run ended (stderr for what went wrong, the summary table on stdout) and choose
    the exit status: 0, 1 (non-finite state or an output not written), 128 + signal (stopped by a
    signal between steps, or while drawing).  A signal during the final data writes waits for them:
    the run is whole, and ends with its own status."""
    out, summary, sim = outcome.out, outcome.summary, outcome.sim
    code = 0
    if outcome.error is not None:
        click.echo(f"bark: error: {outcome.error}; that state is written to {out}", err=True)
        code = 1
    for event in summary["degenerate_events"]:
        click.echo(
            f"bark: warning: degenerate event at t = {event['t']:.4g}: one step broke {event['n_springs']} springs "
            f"({100 * event['fraction']:.0f}% of all): the lattice is too regular (raise --jitter or --fmax-spread) "
            f"or the thresholds are far below the loads",
            err=True,
        )
    for problem in outcome.failed:
        click.echo(f"bark: error: {problem}; every other output is in {out}", err=True)
        code = code or (128 + signum if outcome.drawing_stopped and signum is not None else 1)
    unwritten = [p for p in outcome.failed if "could not be written" in p]
    if (unwritten or outcome.drawing_stopped) and (out / "checkpoint.npz").exists():
        how = "goes on from the last checkpoint written" if any(p.startswith("checkpoint.npz") for p in unwritten) \
            else "writes what is missing"
        when = "once there is room, " if unwritten else ""
        click.echo(f"bark: {when}bark simulate --resume {shlex.quote(str(out))} {how}", err=True)
    if as_json or not quiet:
        from bark_cli.progress import print_summary

        try:
            if as_json:
                from bark.io.files import json_text

                click.echo(json_text(summary, indent=2))
            else:
                print_summary(summary, out)
        except OSError as err:  # a full or closed standard output: the run and its files stand
            click.echo(f"bark: warning: the summary could not be printed ({err.strerror or err}); it is in "
                       f"{out / 'summary.json'}", err=True)
    if outcome.stop_reason in ("interrupted", "terminated"):
        signum = {"interrupted": signal.SIGINT, "terminated": signal.SIGTERM}[outcome.stop_reason]
        click.echo(f"bark: {outcome.stop_reason} at t = {sim.state.t:.6g}; outputs of that state and a checkpoint "
                   f"are in {out}; go on with: bark simulate --resume {shlex.quote(str(out))}", err=True)
        code = 128 + int(signum)
    elif outcome.resumed and not quiet:
        click.echo(f"bark: resumed run ended ({outcome.stop_reason}) at t = {sim.state.t:.6g}", err=True)
    return code


@cli.command(context_settings=CONTEXT)
@click.argument("scene_file", metavar="[SCENE]", required=False)
def plan(scene_file):
    """Show what SCENE (default: the default scene) will simulate and write, and why each effect is
    there: asked for by the scene, or needed by another effect.  Nothing is built or run."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    from bark.engine.scene import available_memory

    prov = Provenance()
    NAMER.set(prov.name)
    scene = Scene.from_dict(prov.add(f"file:{scene_file}", read_toml(scene_file)) if scene_file else {})
    resolved = scene.effects
    parts = scene.components()  # what would be built, without building it
    table = Table("effect", "in the run", "why", "what it does", title=f"bark plan — {scene.name or scene_file or 'default scene'}")
    for name, effect in scene.known_effects.items():
        on = name in resolved
        table.add_row(name, "yes" if on else "no", resolved.get(name, "not asked for"), escape(effect.does),
                      style=None if on else "dim")
    console = Console(width=140)
    console.print(table)
    built = [f"growth: {type(parts['growth']).__name__}", f"integrator: {type(parts['integrator']).__name__}",
             f"breakers: {[type(b).__name__ for b in parts['breakers']] or 'none'}",
             f"analyzers: {[type(a).__name__ for a in parts['analyzers']] or 'none'}",
             f"anchors c = {parts['mechanics'].c:g}", f"damping b = {parts['mechanics'].b:g}",
             f"break log: {'kept' if parts['record_breaks'] else 'not kept'}"]
    console.print(escape("built: " + "; ".join(built)))
    have = available_memory()
    console.print(f"memory: about {scene.memory_estimate() / 2**20:.0f} MiB"
                  + (f" (available now: {have / 2**20:.0f} MiB)" if have is not None else ""))
    stop = scene.stop()
    if stop.until_time is None:
        console.print("[yellow]no time bound[/yellow]: the run ends only when its radius or patch condition holds")



def _default(field) -> str:
    """A field's default as ``bark strategies`` shows it: a factory's product (a nested strategy with
    its own defaults), not the factory."""
    import attrs

    default = field.default
    if isinstance(default, attrs.Factory):
        return "(from the other fields)" if default.takes_self else repr(default.factory())
    return repr(default)


@cli.command(context_settings=CONTEXT)
def strategies():
    """List the installed strategies of every kind (built-in and plugins alike)."""
    import attrs
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    from bark.contract import registry
    from bark.contract.parts import how_it_runs

    table = Table("kind", "name", "class", "parameters", "runs")
    for column in table.columns[:3]:  # names whole, whatever the width: a reader greps and copies them
        column.no_wrap = True
    for kind in KINDS:
        for name, ep in registry.available(kind).items():
            runs = ""
            try:
                cls = registry.load(kind, name)
                params = ", ".join(f"{a.alias}={_default(a)}" for a in attrs.fields(cls) if a.init)
            except Exception as err:  # a broken plugin must not hide the others
                params = f"(cannot load: {err})"
            else:
                try:
                    runs = how_it_runs(registry.create(kind, name))
                except Exception:  # noqa: BLE001 (a strategy with required parameters: known once given)
                    runs = "(once its parameters are given)"
            table.add_row(kind, name, ep.value, escape(params), escape(runs))
    Console(width=None if _is_terminal(sys.stdout) else 240).print(table)  # piped: wide, nothing cut


@cli.command(context_settings=CONTEXT)
def scenes():
    """List the scenes bark ships: each runs by its name (bark simulate --scene NAME)."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    from bark.engine.scene import SHIPPED, read_toml, shipped_scenes

    table = Table("name", "what it is", caption=escape(f"files: {SHIPPED}/NAME.toml"), caption_justify="left")
    table.columns[0].no_wrap = True
    for name, path in shipped_scenes().items():
        table.add_row(name, escape(str(read_toml(path).get("scene", {}).get("description", ""))))
    Console().print(table)


@cli.command(name="compile", context_settings=CONTEXT)
@click.argument("scene_names", nargs=-1, metavar="[SCENE]...")
def compile_kernels(scene_names):
    """Compile the kernels SCENEs run (default: every scene bark ships) into bark's cache, so that
    their first runs start at once: for a cluster whose nodes start with an empty cache, or an
    image made ahead. Each scene takes one step on the numba backend, in memory; nothing is written
    but the cache (BARK_CACHE_DIR moves it)."""
    import time as clock

    from bark.engine.kernels import expect_many, numba_alongside
    from bark.engine.kernels.numba_env import cache_dir
    from bark.engine.scene import STOP_KEYS, Scene, merge, read_toml, shipped_scenes
    from bark.studies import runner

    expect_many()  # its one-step runs are for the many after them: a threaded kernel is compiled too
    prov = Provenance()
    NAMER.set(prov.name)
    names = scene_names or tuple(shipped_scenes())
    scenes = []
    for name in names:  # every scene read and checked before the first compiles
        data = prov.add(f"file:{name}", read_toml(name))
        dt = Scene.from_dict(data).run.dt
        scenes.append((name, Scene.from_dict(merge(data, {"run": {**dict.fromkeys(STOP_KEYS), "until_time": dt,
                                                                  "backend": "numba"}}))))
    for name, scene in scenes:
        t0 = clock.perf_counter()
        runner.run(scene, None)
        failed = numba_alongside.wait()  # a threaded kernel compiling alongside the step: it is asked for too
        if failed:  # the step again: a compile alongside that failed is done in this process
            click.echo(f"bark: {name}: its threaded kernel did not compile alongside ({'; '.join(failed)}): "
                       "compiling it here")
            runner.run(scene, None)
        click.echo(f"bark: {name}: ready ({clock.perf_counter() - t0:.1f} s)")
    click.echo(f"bark: the kernels are in {cache_dir() / 'kernels'}; later runs load them")


from bark_cli.bench import bench  # noqa: E402  (registers the `bench` group)

cli.add_command(bench)

from bark_cli.patterns import analyze, compare  # noqa: E402

cli.add_command(analyze)
cli.add_command(compare)

from bark_cli.sweep import sweep  # noqa: E402

cli.add_command(sweep)

from bark_cli.fit import fit  # noqa: E402

cli.add_command(fit)

from bark_cli.report import report  # noqa: E402

cli.add_command(report)


def main() -> None:
    """The ``bark`` console script: the command-line interface (``bark --help``)."""
    cli()


if __name__ == "__main__":
    main()
