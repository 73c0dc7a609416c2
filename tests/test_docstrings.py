"""The public API documents itself: every public module, class, function, method and property of
``bark``, ``bark_plugins`` and ``bark_cli`` has its own docstring (an override too: it says what it
does differently), and the examples in them run as doctests."""

from __future__ import annotations

import doctest
import importlib
import inspect
import pkgutil
import sys
import textwrap
import types

import pytest

import bark
import bark_cli
import bark_plugins

PACKAGES = (bark, bark_plugins, bark_cli)


def _public_modules() -> list[str]:
    names = []
    for package in PACKAGES:
        names.append(package.__name__)
        for module in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            if not any(part.startswith("_") for part in module.name.split(".")[1:]):
                names.append(module.name)
    return names


MODULES = _public_modules()


def _own_public(module) -> list[tuple[str, object]]:
    """The classes and functions ``module`` defines and makes public (its ``__all__``, else its own
    names not starting with ``_``)."""
    names = getattr(module, "__all__", None)
    if names is None:
        names = [n for n in vars(module) if not n.startswith("_")]
    return [(n, v) for n in names if (inspect.isclass(v := getattr(module, n)) or inspect.isfunction(v))
            and getattr(v, "__module__", None) == module.__name__]


def _undocumented(module) -> list[str]:
    missing = [] if (inspect.getdoc(module) or "").strip() else [module.__name__]
    for name, value in _own_public(module):
        own = vars(value).get("__doc__") if inspect.isclass(value) else value.__doc__  # a class says what it is itself
        if not (own or "").strip():
            missing.append(f"{module.__name__}.{name}")
        if not inspect.isclass(value):
            continue
        for member, raw in vars(value).items():
            if member.startswith("_"):
                continue
            if isinstance(raw, property):
                doc = raw.__doc__  # its getter's, or the one given to property()
            elif inspect.isfunction(function := getattr(raw, "__func__", getattr(raw, "func", raw))):
                doc = function.__doc__  # its own: an override says what it does differently
            else:
                continue  # data: attrs fields and constants are documented where they are declared
            if not (doc or "").strip():
                missing.append(f"{module.__name__}.{name}.{member}")
    return missing


def test_the_public_api_is_found():
    assert {"bark", "bark.contract", "bark.engine.simulation", "bark_plugins.breakers", "bark_cli.draw"} <= set(MODULES)
    assert len(MODULES) > 60


@pytest.mark.parametrize("name", MODULES)
def test_every_public_module_class_and_function_has_a_docstring(name):
    assert _undocumented(importlib.import_module(name)) == []


def test_an_undocumented_method_or_class_is_found(monkeypatch):
    module = types.ModuleType("fake_api", "A module.")
    exec(textwrap.dedent('''
        class Quiet:
            """Documented."""

            def loud(self):
                """Documented."""

            def quiet(self):
                pass

        class Inheriting(Quiet):  # a class and an override each say what they are themselves
            def loud(self):
                pass

            @property
            def size(self):
                return 1
    '''), module.__dict__)
    monkeypatch.setitem(sys.modules, "fake_api", module)
    assert _undocumented(module) == ["fake_api.Quiet.quiet", "fake_api.Inheriting", "fake_api.Inheriting.loud",
                                     "fake_api.Inheriting.size"]


@pytest.mark.parametrize("name", MODULES)
def test_the_examples_in_the_docstrings_run(name):
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for test in finder.find(module, name):  # each in a copy of its module's globals
        runner.run(test)
    failed, _ = runner.summarize(verbose=False)
    assert failed == 0, f"{failed} example(s) of {name} failed (python -m doctest -v shows which)"


def test_the_docstrings_hold_examples():
    finder = doctest.DocTestFinder(exclude_empty=True)
    examples = sum(len(t.examples) for name in MODULES for t in finder.find(importlib.import_module(name), name))
    assert examples >= 25
