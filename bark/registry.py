"""Finding strategies by name through entry points — the one lookup path for built-ins and plugins.

Groups: ``bark.growth``, ``bark.integrator``, ``bark.breaker``, ``bark.analyzer``.  bark's own
strategies (package ``bark_plugins``) are registered in bark's ``pyproject.toml`` under exactly
these groups, so a third-party package that declares, say::

    [project.entry-points."bark.breaker"]
    my-breaker = "my_package.breakers:MyBreaker"

is found, listed by ``bark strategies`` and selectable by ``--breaker my-breaker`` in the same way.
"""

from __future__ import annotations

from importlib.metadata import EntryPoint, entry_points
from typing import Any

from bark.validators import construct
from bark.errors import BarkError, Ref
from bark.strategies import KINDS, Strategy

__all__ = ["GROUPS", "available", "load", "create"]

GROUPS: dict[str, str] = {kind: f"bark.{kind}" for kind in KINDS}


def _check_kind(kind: str) -> None:
    if kind not in GROUPS:
        raise BarkError(f"unknown strategy kind {kind!r}: allowed are {', '.join(KINDS)}")


def available(kind: str) -> dict[str, EntryPoint]:
    """Installed strategies of ``kind``, by name, sorted."""
    _check_kind(kind)
    eps = entry_points(group=GROUPS[kind])
    return {ep.name: ep for ep in sorted(eps, key=lambda e: e.name)}


def load(kind: str, name: str) -> type[Strategy]:
    """The class registered as ``name`` for ``kind``; a one-line :class:`BarkError` if there is none."""
    eps = available(kind)
    if name not in eps:
        names = ", ".join(eps) or "(none installed)"
        raise BarkError("{0}: no " + kind + " strategy of that name; installed are " + names, Ref(kind, "name", name))
    cls = eps[name].load()
    if not (isinstance(cls, type) and issubclass(cls, Strategy) and cls.kind == kind):
        raise BarkError(f"{kind} {name!r} ({eps[name].value}) is not a bark {kind} strategy class")
    return cls


def create(kind: str, name: str, **params: Any) -> Strategy:
    """Instantiate ``name`` of ``kind`` with ``params``; an unknown, missing or bad keyword is a
    one-line :class:`BarkError` whose ref names the key (section ``kind``)."""
    cls = load(kind, name)
    return construct(cls, params, f"{kind} {name!r}")
