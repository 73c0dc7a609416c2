"""Finding strategies by name through entry points — the one lookup path for built-ins and plugins.

Groups: ``bark.growth``, ``bark.integrator``, ``bark.breaker``, ``bark.analyzer``.  bark's own
strategies (package ``bark_plugins``) are registered in bark's ``pyproject.toml`` under exactly
these groups, so a third-party package that declares, say::

    [project.entry-points."bark.breaker"]
    my-breaker = "my_package.breakers:MyBreaker"

is found, listed by ``bark strategies`` and selectable by ``--breaker my-breaker`` in the same way.

A strategy defined elsewhere (a script, a notebook, a module not registered) is named by its import
path, ``module:Class``: a scene may say ``name = "my_module:MyGrowth"``, and summaries and
checkpoints record every strategy by its entry-point name or, for one not registered, that path
(``name_of``), so a resumed run continues with the very class it ran, or refuses to.
"""

from __future__ import annotations

import functools
import importlib
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Callable

from bark.validators import construct
from bark.errors import BarkError, Ref
from bark.contract.strategies import KINDS, Strategy

__all__ = ["GROUPS", "PICTURES", "available", "load", "create", "name_of", "import_path", "picture_writers", "refresh"]

GROUPS: dict[str, str] = {kind: f"bark.{kind}" for kind in KINDS}
PICTURES = "bark.pictures"
"""The entry-point group of what draws a run's pictures: a callable returning, per effect, the file
name and a writer ``draw(sim, scene, recorded, path)`` (bark's own: ``bark_cli.pictures:writers``,
the same pictures ``bark simulate`` draws, drawn in the calling process)."""


def _check_kind(kind: str) -> None:
    if kind not in GROUPS:
        raise BarkError(f"unknown strategy kind {kind!r}: allowed are {', '.join(KINDS)}")


def available(kind: str) -> dict[str, EntryPoint]:
    """Installed strategies of ``kind``, by name, sorted."""
    _check_kind(kind)
    return dict(_installed(GROUPS[kind]))


@functools.lru_cache(maxsize=None)
def _installed(group: str) -> tuple[tuple[str, EntryPoint], ...]:
    """The entry points of ``group``, by name: read from the installed packages' metadata once a
    process (a scan of every installed distribution, which a sweep paid per point and strategy
    kind).  :func:`refresh` reads them again."""
    return tuple((ep.name, ep) for ep in sorted(entry_points(group=group), key=lambda e: e.name))


def refresh() -> None:
    """Forget the entry points read so far: a plugin installed into a running process (a notebook)
    is found at the next lookup."""
    _installed.cache_clear()


def load(kind: str, name: str) -> type[Strategy]:
    """The class registered as ``name`` for ``kind``, or at the import path ``module:Class``; a
    one-line :class:`BarkError` if there is none."""
    if ":" in name:
        cls, where = _imported(kind, name), name
    else:
        eps = available(kind)
        if name not in eps:
            names = ", ".join(eps) or "(none installed)"
            raise BarkError("{0}: no " + kind + " strategy of that name; installed are " + names
                            + " (or give an import path, module:Class)", Ref(kind, "name", name))
        cls, where = eps[name].load(), eps[name].value
    if not (isinstance(cls, type) and issubclass(cls, Strategy) and cls.kind == kind):
        raise BarkError(f"{kind} {name!r} ({where}) is not a bark {kind} strategy class")
    return cls


def _imported(kind: str, path: str):
    module, _, qualname = path.partition(":")
    try:
        obj = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except Exception as err:  # noqa: BLE001 (any failure to import is the user's to hear, in one line)
        where = ("it was defined in the script or notebook that ran it: resume it from there "
                 "(bark.studies.runner.resume), or move the class into a module on PYTHONPATH") if module == "__main__" \
            else "put its module on PYTHONPATH (or install its package)"
        raise BarkError("{0}: cannot be imported (" + f"{type(err).__name__}: {err}".replace("{", "{{").replace("}", "}}")
                        + "); " + where, Ref(kind, "name", path)) from None
    return obj


def import_path(cls: type) -> str:
    """``module:Class`` for ``cls`` (``__main__`` for a class of the script or notebook that runs)."""
    return f"{cls.__module__}:{cls.__qualname__}"


def name_of(strategy) -> str:
    """How ``strategy`` (or its class) is recorded: the entry-point name its class is registered
    under, else its import path (:func:`import_path`)."""
    return _name_of_class(strategy if isinstance(strategy, type) else type(strategy))


@functools.lru_cache(maxsize=None)
def _name_of_class(cls: type) -> str:
    path = import_path(cls)
    for name, ep in available(cls.kind).items():
        if ep.value == path:
            return name
    return path


def create(kind: str, name: str, **params: Any) -> Strategy:
    """Instantiate ``name`` (an entry-point name or ``module:Class``) of ``kind`` with ``params``; an
    unknown, missing or bad keyword is a one-line :class:`BarkError` whose ref names the key
    (section ``kind``)."""
    cls = load(kind, name)
    return construct(cls, params, f"{kind} {name!r}")


def find(test: Callable[[type], bool]) -> list[tuple[str, str]]:
    """``(kind, name)`` of every installed strategy whose class passes ``test``; one that cannot be
    loaded passes nothing (it is reported when a scene names it)."""
    found = []
    for kind in KINDS:
        for name, ep in available(kind).items():
            try:
                cls = ep.load()
            except Exception:  # noqa: BLE001
                continue
            if isinstance(cls, type) and issubclass(cls, Strategy) and test(cls):
                found.append((kind, name))
    return found


def providers(effect: str) -> list[tuple[str, str]]:
    """``(kind, name)`` of every installed strategy that provides the effect ``effect`` (``Strategy.provides``)."""
    return find(lambda cls: any(e.name == effect for e in cls.provides))


def picture_writers() -> dict | None:
    """The picture writers installed (the ``bark.pictures`` entry point first by name), or ``None``
    where none is: the core itself draws nothing and imports no plotting library."""
    eps = _installed(PICTURES)
    return eps[0][1].load()() if eps else None
