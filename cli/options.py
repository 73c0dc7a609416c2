"""Command-line options generated from the parameter classes, so options and fields never drift.

Every init field of :class:`~bark.lattice.Lattice`, :class:`~bark.forces.Mechanics` and
:class:`~bark.scene.RunSettings` becomes ``--field-name`` (underscores → dashes), with the field's
docstring-free help taken from the scene table it belongs to.  An option left out is ``None`` and
leaves the scene's value alone.
"""

from __future__ import annotations

from typing import Any

import attrs
import click

from bark.forces import Mechanics
from bark.lattice import Lattice
from bark.scene import RunSettings

SECTIONS = {"lattice": Lattice, "mechanics": Mechanics, "run": RunSettings}


class OffsetsType(click.ParamType):
    name = "INT,INT,..."

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        try:
            return tuple(int(v) for v in str(value).split(","))
        except ValueError:
            self.fail(f"{value!r} is not a comma-separated list of integers (e.g. 21,34)", param, ctx)


def _click_type(field: attrs.Attribute):
    if field.name == "offsets":
        return OffsetsType()
    if field.validator is not None and "one_of" in getattr(field.validator, "__qualname__", ""):
        return click.STRING
    ann = str(field.type)
    if "int" in ann:
        return click.INT
    if "float" in ann:
        return click.FLOAT
    return click.STRING


def option_name(field_name: str) -> str:
    return "--" + field_name.replace("_", "-")


def parameter_options(func):
    """Decorate a click command with one option per model and run parameter."""
    for section, cls in reversed(SECTIONS.items()):
        for field in reversed(attrs.fields(cls)):
            default = field.default if not isinstance(field.default, attrs.Factory) else None
            func = click.option(
                option_name(field.name),
                f"{section}__{field.name}",
                type=_click_type(field),
                default=None,
                help=f"[{section}] {field.name} (default {default!r}).",
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
