"""``bark`` — the command line.

    bark simulate --growth sqrt --breaker threshold      # the default scene (vertical regime)
    bark simulate --scene examples/scenes/diamond.toml --out runs/diamond
    bark strategies                                      # what is installed, by kind
    bark bench speed                                     # steps per second

Errors in what the user typed (an option value, a scene key, a file) print one line and exit with
status 2, before anything is written.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import click

from bark import registry
from bark.errors import BarkError, NonFiniteStateError
from bark.scene import DEFAULT_STRATEGIES, Scene, merge, read_toml
from bark.strategies import KINDS
from bark_cli.options import overrides_from, parameter_options


class BarkGroup(click.Group):
    """A click group whose failures are one line on stderr, never a traceback or a usage dump."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.ClickException as err:
            click.echo(f"bark: error: {err.format_message()}", err=True)
            sys.exit(err.exit_code)
        except BarkError as err:
            click.echo(f"bark: error: {err}", err=True)
            sys.exit(2)
        except (click.Abort, KeyboardInterrupt):
            click.echo("bark: interrupted", err=True)
            sys.exit(130)
        sys.exit(rv if isinstance(rv, int) else 0)


@click.group(cls=BarkGroup)
@click.version_option(package_name="bark")
def cli():
    """Grow a virtual grasstree trunk and let its layer of leaf bases crack."""


def _strategy_option(kind: str):
    return click.option(
        f"--{kind}",
        f"{kind}_name",
        default=None,
        metavar="NAME",
        help=f"{kind} strategy (default {DEFAULT_STRATEGIES[kind]!r}; `bark strategies` lists them).",
    )


def _parse_set(items: tuple[str, ...]) -> dict:
    """``--set growth.G=0.01`` → ``{"growth": {"G": 0.01}}`` (values parsed as TOML)."""
    import tomllib

    out: dict = {}
    for item in items:
        key, sep, raw = item.partition("=")
        section, dot, name = key.strip().partition(".")
        if not sep or not dot or not section or not name:
            raise BarkError(f"--set {item!r}: expected SECTION.KEY=VALUE, e.g. --set growth.G=0.011")
        try:
            value = tomllib.loads(f"v = {raw.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw.strip()  # a bare word, e.g. a strategy name
        out.setdefault(section, {})[name.strip()] = value
    return out


def resolve_scene(scene_file, strategies: dict, shortcuts: dict, sets: tuple, kwargs: dict) -> Scene:
    """The scene a command runs: file (or defaults) ← --set ← strategy names ← explicit options."""
    data = read_toml(scene_file) if scene_file else {}
    data = merge(data, _parse_set(sets))
    data = merge(data, {s: {"name": n} for s, n in strategies.items() if n is not None})
    data = merge(data, {"growth": {k: v for k, v in shortcuts.items() if v is not None}})
    data = merge(data, overrides_from(kwargs))
    return Scene.from_dict(data)


def _check_out_dir(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise BarkError(f"--out {str(out)!r} exists and is not a directory")


@cli.command()
@click.option("--scene", "scene_file", type=click.Path(dir_okay=False), default=None, help="Scene TOML file; options given here override it.")
@_strategy_option("growth")
@_strategy_option("integrator")
@_strategy_option("breaker")
@_strategy_option("analyzer")
@click.option("--r0", type=float, default=None, help="[growth] initial trunk radius r_i (default 0.2).")
@click.option("-G", "--growth-rate", "G", type=float, default=None, help="[growth] growth constant G (default 0.014).")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE", help="Set any scene key, e.g. a plugin's parameter.")
@parameter_options
@click.option("--out", "out", type=click.Path(file_okay=False), default="bark-out", show_default=True, help="Output folder.")
@click.option("--resume", "resume", type=click.Path(file_okay=False), default=None,
              help="Go on with the interrupted run in this folder (its checkpoint has every setting).")
@click.option("--checkpoint-every", type=float, default=60.0, show_default=True,
              help="Write a checkpoint every this many seconds of wall time (0: only at the end and on Ctrl-C).")
@click.option("--quiet", is_flag=True, help="No progress bar and no summary table.")
@click.pass_context
def simulate(ctx, scene_file, growth_name, integrator_name, breaker_name, analyzer_name, r0, G, sets, out, resume,
             checkpoint_every, quiet, **kwargs):
    """Grow the trunk and let the bark crack; write pattern.png, patches.csv, breaks.csv,
    summary.json, state.npz and checkpoint.npz to --out.  Any --until-* option replaces the scene's
    stop conditions.  Ctrl-C stops between steps, writes a checkpoint, and says how to resume."""
    from bark import checkpoint

    if checkpoint_every < 0:
        raise BarkError(f"--checkpoint-every = {checkpoint_every:g}: must be >= 0")
    if resume is not None:
        given = [p for p, v in ctx.params.items()
                 if ctx.get_parameter_source(p) == click.core.ParameterSource.COMMANDLINE
                 and p not in ("resume", "quiet", "checkpoint_every")]
        if given:
            name = given[0].split("__")[-1].replace("_", "-")
            raise BarkError(f"--resume goes on with the settings in its checkpoint: --{name} cannot be given with it")
        out = Path(resume)
        scene, sim, stop, meta = checkpoint.load(out / checkpoint.CHECKPOINT_NAME)
        if meta["reason"] not in ("periodic", "interrupted"):
            raise BarkError(f"the run in {str(out)!r} has ended ({meta.get('stop_reason')}): nothing to resume")
        wall_before = float(meta.get("wall_time_s", 0.0))
    else:
        strategies = {"growth": growth_name, "integrator": integrator_name, "breaker": breaker_name, "analyzer": analyzer_name}
        scene = resolve_scene(scene_file, strategies, {"r0": r0, "G": G}, sets, kwargs)
        out = Path(out)
        _check_out_dir(out)
        sim, stop, wall_before = scene.simulation(), scene.stop(), 0.0
    return _run(sim, scene, stop, out, quiet, checkpoint_every, wall_before, resumed=resume is not None)


def _run(sim, scene, stop, out: Path, quiet: bool, checkpoint_every: float, wall_before: float, resumed: bool) -> int:
    import signal

    from bark import checkpoint
    from bark.output import write_run
    from bark_cli.progress import progress_observer

    out.mkdir(parents=True, exist_ok=True)
    ckpt = out / checkpoint.CHECKPOINT_NAME
    if not scene.has("checkpoints"):
        checkpoint_every = 0.0
    show = not quiet and sys.stdout.isatty()
    series = None
    if scene.has("statistics-series"):  # the analyzers along the way, on their trigger
        from bark.output import StatisticsSeries
        from bark.triggers import Every

        series = StatisticsSeries()
        sim.add_action(Every(scene.series_every), series.record)
    frames = None
    if scene.has("animation"):  # frames along the way: only when asked for
        from bark.triggers import Every
        from bark_cli.animation import Frames

        frames = Frames()
        sim.add_action(Every(scene.frame_every), frames.record)
    interrupted = []
    t0 = time.perf_counter()
    last_save = [t0]

    def on_sigint(signum, frame):  # stop between steps, never inside one
        interrupted.append(True)

    def save(reason: str, stop_reason=None):
        if not scene.has("checkpoints"):
            return
        wall = wall_before + time.perf_counter() - t0
        checkpoint.save(ckpt, sim, scene, stop, reason, {"stop_reason": stop_reason, "wall_time_s": wall})

    previous = signal.signal(signal.SIGINT, on_sigint)
    reason, code = None, 0
    try:
        with progress_observer(sim, stop, enabled=show) as show_progress:

            def observe(s):
                if show_progress is not None:
                    show_progress(s)
                if interrupted:
                    s.stop_reason = "interrupted"
                elif checkpoint_every and time.perf_counter() - last_save[0] >= checkpoint_every:
                    save("periodic")
                    last_save[0] = time.perf_counter()

            reason = sim.run(stop, observe)
    except NonFiniteStateError as err:
        click.echo(f"bark: error: {err}; writing that state to {out}", err=True)
        reason, code = "non-finite", 1
    finally:
        signal.signal(signal.SIGINT, previous)
    if reason == "interrupted":
        code = 130
    wall = wall_before + time.perf_counter() - t0
    summary = write_run(sim, scene, out, reason, wall)
    if scene.has("pattern-image"):
        from bark_cli.plot import plot_pattern  # matplotlib is imported only when an image is asked for

        plot_pattern(sim, out / "pattern.png", scene.run.min_patch_size)
    if series is not None:
        series.record(sim)
        series.write(out / "statistics.csv")
    if frames is not None:
        frames.record(sim)
        frames.write(out / "development.gif", scene.run.min_patch_size)
    save("interrupted" if code == 130 else "end", reason)
    for event in summary["degenerate_events"]:
        click.echo(
            f"bark: warning: degenerate event at t = {event['t']:.4g}: one step broke {event['n_springs']} springs "
            f"({100 * event['fraction']:.0f}% of all): the lattice is too regular (raise --jitter or --fmax-spread) "
            f"or the thresholds are far below the loads",
            err=True,
        )
    if not quiet:
        from bark_cli.progress import print_summary

        print_summary(summary, out)
    if code == 130:
        click.echo(f"bark: interrupted at t = {sim.state.t:.6g}; outputs of that state and a checkpoint are in {out}; "
                   f"go on with: bark simulate --resume {out}", err=True)
    elif resumed and not quiet:
        click.echo(f"bark: resumed run ended ({reason}) at t = {sim.state.t:.6g}", err=True)
    return code


@cli.command()
@click.argument("scene_file", type=click.Path(dir_okay=False), required=False)
def plan(scene_file):
    """Show what SCENE (default: the default scene) will simulate and write, and why each effect is
    there: asked for by the scene, or needed by another effect.  Nothing is run."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    from bark.effects import EFFECTS

    scene = Scene.from_dict(read_toml(scene_file) if scene_file else {})
    resolved = scene.effects
    sim = scene.simulation()  # composed, not run: shows what is built
    table = Table("effect", "in the run", "why", "what it does", title=f"bark plan — {scene.name or scene_file or 'default scene'}")
    for name, effect in EFFECTS.items():
        on = name in resolved
        table.add_row(name, "yes" if on else "no", resolved.get(name, "not asked for"), escape(effect.does),
                      style=None if on else "dim")
    console = Console(width=140)
    console.print(table)
    built = [f"growth: {type(sim.growth).__name__}", f"integrator: {type(sim.integrator).__name__}",
             f"breakers: {[type(b).__name__ for b in sim.breakers] or 'none'}",
             f"analyzers: {[type(a).__name__ for a in sim.analyzers] or 'none'}",
             f"anchors c = {sim.mechanics.c:g}", f"damping b = {sim.mechanics.b:g}",
             f"break log: {'kept' if sim.record_breaks else 'not kept'}"]
    console.print("built: " + "; ".join(built))


@cli.command()
def strategies():
    """List the installed strategies of every kind (built-in and plugins alike)."""
    from rich.console import Console
    from rich.table import Table

    table = Table("kind", "name", "class", "parameters")
    for kind in KINDS:
        for name, ep in registry.available(kind).items():
            try:
                cls = registry.load(kind, name)
                import attrs

                params = ", ".join(f"{a.name}={a.default!r}" for a in attrs.fields(cls) if a.init)
            except Exception as err:  # a broken plugin must not hide the others
                params = f"(cannot load: {err})"
            table.add_row(kind, name, ep.value, params)
    Console().print(table)


from bark_cli.bench import bench  # noqa: E402  (registers the `bench` group)

cli.add_command(bench)


def main() -> None:
    cli()


if __name__ == "__main__":
    main()
