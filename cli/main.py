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
@click.option("--quiet", is_flag=True, help="No progress bar and no summary table.")
def simulate(scene_file, growth_name, integrator_name, breaker_name, analyzer_name, r0, G, sets, out, quiet, **kwargs):
    """Grow the trunk and let the bark crack; write pattern.png, patches.csv, breaks.csv,
    summary.json and state.npz to --out.  Any --until-* option replaces the scene's stop conditions."""
    strategies = {"growth": growth_name, "integrator": integrator_name, "breaker": breaker_name, "analyzer": analyzer_name}
    scene = resolve_scene(scene_file, strategies, {"r0": r0, "G": G}, sets, kwargs)
    out = Path(out)
    _check_out_dir(out)

    from bark.output import write_run
    from bark_cli.plot import plot_pattern
    from bark_cli.progress import progress_observer

    sim = scene.simulation()
    stop = scene.stop()
    show = not quiet and sys.stdout.isatty()
    reason, code = None, 0
    t0 = time.perf_counter()
    try:
        with progress_observer(sim, stop, enabled=show) as observe:
            reason = sim.run(stop, observe)
    except KeyboardInterrupt:
        reason, code = "interrupted", 130
    except NonFiniteStateError as err:
        click.echo(f"bark: error: {err}; writing that state to {out}", err=True)
        reason, code = "non-finite", 1
    wall = time.perf_counter() - t0
    summary = write_run(sim, scene, out, reason, wall)
    plot_pattern(sim, out / "pattern.png", scene.run.min_patch_size)
    for event in summary["degenerate_events"]:
        click.echo(
            f"bark: warning: degenerate event at t = {event['t']:.4g}: one step broke {event['n_springs']} springs "
            f"({100 * event['fraction']:.0f}% of all); the lattice is too regular (raise --jitter or --fmax-spread)",
            err=True,
        )
    if not quiet:
        from bark_cli.progress import print_summary

        print_summary(summary, out)
    if code:
        click.echo(f"bark: interrupted at t = {sim.state.t:.4g}; outputs of that state are in {out}", err=True)
    return code


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
