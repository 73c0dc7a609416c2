"""Command-line options generated from the parameter classes, so options and fields never drift —
and the way back: naming a scene setting in the terms the user typed it.

Every init field of :class:`~bark.model.lattice.Lattice`, :class:`~bark.model.forces.Mechanics` and
:class:`~bark.engine.scene.RunSettings` becomes ``--field-name`` (underscores → dashes).  Its help is the
field's docstring (meaning and units), read only when help is shown; a field validated by ``one_of``
lists its choices.  An option left out is ``None`` and leaves the scene's value alone.

:class:`Provenance` records where each setting of a resolved scene came from (the scene file,
``--set``, a strategy option, an option), so that an error about it names what the user wrote:
``--dt 1e+308: must be <= 1e+12``, not ``[run] dt = 1e+308``.
"""

from __future__ import annotations

import ast
import contextvars
import functools
import inspect
import shlex
import textwrap
from typing import Any

import attrs
import click

from bark.errors import Ref, show
from bark.model.forces import Mechanics
from bark.model.lattice import Lattice
from bark.engine.scene import RUN_FIELDS, STRATEGY_SECTIONS, RunSettings

SECTIONS = {"lattice": Lattice, "mechanics": Mechanics, "run": RunSettings}
SHORTCUTS = {("growth", "r0"): "--r0", ("growth", "G"): "-G", ("breaker", "spread"): "--fmax-spread",
             ("breaker", "weibull_shape"): "--fmax-weibull-shape", (None, "out"): "--out", (None, "resume"): "--resume",
             (None, "overwrite"): "--overwrite", (None, "checkpoint_every"): "--checkpoint-every"}
"""Options for settings that are not a parameter class's field: the default growth law's
parameters (beside ``--set growth.KEY=VALUE``) and the run's own (output folder, checkpoints)."""


class OffsetsType(click.ParamType):
    """A click type: lattice offsets typed as comma-separated integers (``--offsets 21,34``)."""

    name = "INT,INT,..."

    def convert(self, value, param, ctx):
        """``21,34`` → ``(21, 34)``; anything else is click's one-line usage error."""
        if isinstance(value, tuple):
            return value
        try:
            return tuple(int(v) for v in str(value).split(","))
        except ValueError:
            self.fail(f"{value!r} is not a comma-separated list of integers (e.g. 21,34)", param, ctx)


def _allowed(validator) -> tuple[str, ...] | None:
    """The choices of a ``one_of`` validator (also inside ``optional``), else ``None``."""
    while validator is not None:
        if hasattr(validator, "allowed"):
            return validator.allowed
        validator = getattr(validator, "inner", None)
    return None


def _click_type(field: attrs.Attribute):
    if field.name in ("offsets", "partition"):
        return OffsetsType()
    choices = _allowed(field.validator)
    if choices:
        return click.Choice(choices)
    ann = str(field.type)
    if "int" in ann:
        return click.INT
    if "float" in ann:
        return click.FLOAT
    return click.STRING


def option_name(field_name: str) -> str:
    """The command-line option of a scene field: ``--`` and its name with dashes (``n_bases`` → ``--n-bases``)."""
    return "--" + field_name.replace("_", "-")


@functools.cache
def field_docs(cls: type) -> dict[str, str]:
    """The docstring under each field of an attrs class (parsed from its source, on first use)."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = tree.body[0].body
    docs = {}
    for node, after in zip(body, body[1:]):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str)):
            docs[node.target.id] = " ".join(after.value.value.split()).replace("``", "")
    return docs


def _in_option_terms(doc: str, cls: type) -> str:
    """A field's docstring as command-line help: other fields named by their options (``f_max`` →
    ``--f-max``); names without an underscore are plain words (``dt``) and stay."""
    import re

    for name in sorted((f.name for f in attrs.fields(cls) if "_" in f.name), key=len, reverse=True):
        doc = re.sub(rf"(?<![\w-]){re.escape(name)}(?!\w)", option_name(name), doc)
    return doc


class FieldOption(click.Option):
    """An option for one field of a parameter class; its help is the field's docstring, read lazily."""

    def __init__(self, *args, field_cls: type, field: attrs.Attribute, scene_default, **kwargs):
        super().__init__(*args, **kwargs)
        self.field_cls, self.field, self.scene_default = field_cls, field, scene_default

    def get_help_record(self, ctx):
        """The option's help, made when first shown: the field's own docstring in option terms and the scene's
        default."""
        if self.help is None:
            default = self.scene_default if not isinstance(self.scene_default, attrs.Factory) else None
            doc = _in_option_terms(field_docs(self.field_cls).get(self.field.name, ""), self.field_cls)
            shown = "none" if default is None else ",".join(map(str, default)) if isinstance(default, tuple) else f"{default:g}" if isinstance(default, float) else str(default)
            self.help = f"{doc} [default: {shown}]"
        return super().get_help_record(ctx)


class LazyHelpOption(click.Option):
    """An option whose help text is computed when help is shown (e.g. the installed strategies),
    not when the command line is imported."""

    def __init__(self, *args, lazy_help, **kwargs):
        super().__init__(*args, **kwargs)
        self.lazy_help = lazy_help

    def get_help_record(self, ctx):
        """The option's help, made when first shown (it may list what is installed)."""
        if self.help is None:
            self.help = self.lazy_help()
        return super().get_help_record(ctx)


def parameter_options(func):
    """Decorate a click command with one option per model and run parameter (its help from the
    class that declares the field; its default the scene's)."""
    for section, cls in reversed(SECTIONS.items()):
        for field in reversed(attrs.fields(cls)):
            owner, declared = RUN_FIELDS[field.name] if cls is RunSettings else (cls, field)
            func = click.option(
                option_name(field.name),
                f"{section}__{field.name}",
                cls=FieldOption,
                field_cls=owner,
                field=declared,
                scene_default=field.default,
                type=_click_type(declared),
                default=None,
            )(func)
    return func


def overrides_from(kwargs: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Pop the generated options out of ``kwargs`` and return those given, as scene tables."""
    out: dict[str, dict[str, Any]] = {}
    for key in [k for k in kwargs if "__" in k]:
        value = kwargs.pop(key)
        section, name = key.split("__", 1)
        if value is not None:
            out.setdefault(section, {})[name] = value
    return out


def option_for(section: str | None, key: str) -> str | None:
    """The command-line option that sets ``[section] key``, if there is one."""
    if section in SECTIONS and key in attrs.fields_dict(SECTIONS[section]):
        return option_name(key)
    if section in STRATEGY_SECTIONS and key == "name":
        return f"--{section}"
    return SHORTCUTS.get((section, key))


def _cli_value(value: Any) -> str:
    """A value as it would be typed after its option (a very long one shortened in the middle)."""
    if isinstance(value, (list, tuple)):
        text = ",".join(str(v) for v in value)
    else:
        text = shlex.quote(value) if isinstance(value, str) else show(value)
    return text if len(text) <= 100 else f"{text[:60]}…{text[-30:]}"


@attrs.define
class Provenance:
    """Where each setting of a scene came from, in order of precedence (later wins)."""

    layers: list[tuple[str, dict]] = attrs.field(factory=list)
    """``(source, tables)``: ``source`` is ``"file:PATH"``, ``"--set"``, ``"option"``."""
    set_items: dict[tuple[str, str], str] = attrs.field(factory=dict)
    """The text of each ``--set`` item, by (section, key)."""
    prior_items: dict[tuple[str, str], str] = attrs.field(factory=dict)
    """The text of each ``--prior`` item (``bark fit``), by (section, key)."""
    aliases: dict[tuple[str | None, str], str] = attrs.field(factory=dict)
    """Options of the command at hand that set a scene key under another name (``bark bench
    accuracy --reference-dt`` sets ``[run] dt``)."""

    def add(self, source: str, tables: dict) -> dict:
        """Record ``tables`` as the next layer, from ``source``; returns them."""
        self.layers.append((source, tables))
        return tables

    def source(self, section: str | None, key: str) -> str | None:
        """Where the value of ``key`` (in ``section``; ``None``: a top-level key) came from, the last layer that
        sets it; ``None`` if none does (a default)."""
        for source, tables in reversed(self.layers):
            if section is None and key in tables:
                return source
            if isinstance(tables.get(section), dict) and key in tables[section]:
                return source
        return None

    def name(self, ref: Ref) -> str:
        """``ref`` named as the user gave it: the option, the ``--set`` item or the scene file key."""
        source = self.source(ref.section, ref.top_key)
        nested = ref.key != ref.top_key
        if source is not None and source.startswith("file:"):
            return f"{ref} in {source[5:]}"
        if source == "--set":
            item = f"--set {self.set_items[(ref.section, ref.top_key)]}"
            if not nested:
                return item
            return f"{ref.key} in {item}" if not ref.given else f"{ref.key} = {show(ref.value)} in {item}"
        if source == "--prior":  # a fitted setting: its range as typed, and the value in it that fails
            item = f"--prior {self.prior_items.get((ref.section, ref.top_key), f'{ref.section}.{ref.key}')}"
            return f"{item} (at {_cli_value(ref.value)})" if ref.given else item
        if source == "--grid":  # one value of a swept setting
            return f"--grid {ref.section}.{ref.key}={_cli_value(ref.value)}"
        if source in ("--points", "--range"):  # a listed point's value, given or drawn
            how = "a point of --points" if source == "--points" else "a point drawn in its --range"
            return f"{ref.section}.{ref.key} = {_cli_value(ref.value)} ({how})"
        option = self.aliases.get((ref.section, ref.top_key)) or option_for(ref.section, ref.top_key)
        if option is None or nested:
            return str(ref)
        if not ref.given or ref.value is True:  # a missing setting, or a flag
            return option
        default = source is None and self.layers and ref.section is not None  # nobody gave it: the scene's default
        return f"{option} {_cli_value(ref.value)}" + (" (the default)" if default else "")


NAMER: contextvars.ContextVar = contextvars.ContextVar("namer", default=None)
"""How the command being run names a scene setting in a message (a :class:`Provenance`'s ``name``)."""


def name_ref(ref: Ref) -> str:
    """``ref`` named for the command being run (its options; see :class:`Provenance`)."""
    namer = NAMER.get()
    return namer(ref) if namer is not None else Provenance().name(ref)


def seconds(ctx, param, value: float) -> float:
    """A click callback refusing NaN, which passes a ``FloatRange``'s comparisons."""
    if value != value:
        raise click.BadParameter(f"{value} is not a number of seconds.")
    return value


progress_option = click.option(
    "--progress-every", "progress_every", type=click.FloatRange(0.1, 86400), default=30.0, show_default=True,
    callback=seconds,
    metavar="SECONDS", help="With stderr not a terminal (a batch job's log): seconds between two progress lines, "
                            "whether or not a run finished; the first is written at once.")
"""The option of every long command that counts its progress (``bark_cli.progress.Tally``)."""


json_option = click.option(
    "--json", "as_json", is_flag=True,
    help="Print the result as JSON on stdout (the document the command writes) instead of the table.")
"""The option of every command that prints a result: its JSON, for a script to read."""


def split_setting(item: str) -> tuple[str, str, str] | None:
    """``SECTION.KEY=TEXT`` (``--set``, ``--grid``) → ``(section, key, text)``, the names stripped, or
    ``None`` when the item is not of that form."""
    key, sep, text = item.partition("=")
    section, dot, name = key.strip().partition(".")
    if not sep or not dot or not section or not name:
        return None
    return section.strip(), name.strip(), text


def setting_value(text: str):
    """A ``--set`` or ``--grid`` value: read as TOML (``0.01``, ``true``, ``[55, 89]``), else the bare
    word as it is (a strategy name)."""
    import tomllib

    try:
        return tomllib.loads(f"v = {text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        return text.strip()


def value_text(value) -> str:
    """A setting's value as shown to the user (tables, progress, figure labels): a float in its
    shortest form (``%g``), anything else as it is."""
    return f"{value:g}" if isinstance(value, float) else str(value)


SCENE_RULE = "bark ships (bark scenes lists them), or a TOML file: a path with a folder in it or a name ending in .toml (./vertical is a file called vertical here; vertical is the shipped scene)"
"""How a ``--scene`` value names a scene (``bark.engine.scene.find_scene``), said in every command's help."""
