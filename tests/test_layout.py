"""The layout holds the architecture: ARCHITECTURE.md's dependency rule, read from the code's imports.

Every import in ``bark/`` counts, those inside functions included (only ``if TYPE_CHECKING:`` blocks,
which never run, are left out), so a lazy import cannot hide a cycle or a layer broken.
"""

from __future__ import annotations

import ast
import sys
from importlib.metadata import entry_points
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1]
CORE = ROOT / "bark"

BASE = {"bark.errors", "bark.paths", "bark.units", "bark.validators", "bark.version"}
"""Modules every layer may import."""
LAYERS = {  # a layer -> the layers it may import (besides itself and BASE)
    "model": set(),
    "contract": {"model"},
    "engine": {"model", "contract"},
    "analysis": {"model"},
    "io": {"model", "contract", "engine", "analysis"},
    "studies": {"model", "contract", "engine", "analysis", "io"},
}
TOP = {"bark", "bark.__main__", "bark.testing"}
"""The package's front (``import bark``, ``python -m bark``) and the contract kit: they may import anything of bark."""


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(CORE.rglob("*.py"))}


def layer(module: str) -> str:
    if module in BASE:
        return "base"
    if module in TOP:
        return "top"
    return module.split(".")[1]


def _runtime_nodes(tree: ast.AST):
    """Every node of ``tree`` but those under ``if TYPE_CHECKING:``."""
    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                todo.extend(child.orelse)
                continue
            todo.append(child)


def imports(module: str) -> set[str]:
    """The bark modules ``module`` imports (a name imported from a package that is a module of its
    own counts as that module)."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in _runtime_nodes(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.split(".")[0] == "bark")
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            if base.split(".")[0] != "bark":
                continue
            for a in node.names:
                sub = f"{base}.{a.name}"
                found.add(sub if sub in MODULES else base)
    found.discard(module)
    return {m for m in found if not module.startswith(m + ".")}  # a module's own packages are not a dependency


GRAPH = nx.DiGraph((m, d) for m in MODULES for d in imports(m))
GRAPH.add_nodes_from(MODULES)


def test_every_import_names_a_module_of_bark():
    unknown = sorted((m, d) for m, d in GRAPH.edges if d not in MODULES)
    assert not unknown


def test_no_import_cycles():
    cycles = [sorted(c) for c in nx.strongly_connected_components(GRAPH) if len(c) > 1]
    assert not cycles, f"import cycles: {cycles}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if layer(m) not in ("top",)))
def test_the_dependency_rule(module):
    own = layer(module)
    allowed = {"base"} | ({own} | LAYERS[own] if own != "base" else set())
    wrong = sorted(d for d in GRAPH.successors(module) if layer(d) not in allowed)
    assert not wrong, f"{module} ({own}) may not import {wrong}"


def test_every_module_sits_in_a_layer():
    assert {layer(m) for m in MODULES} <= {"base", "top", *LAYERS}


def test_the_core_imports_no_plugin_and_no_front_end():
    """``bark/`` never imports the built-in plugins, the CLI, click, rich or matplotlib."""
    banned = ("bark_plugins", "bark_cli", "click", "rich", "matplotlib")
    for module, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            hit = [n for n in names if n.split(".")[0] in banned]
            assert not hit, f"{module} imports {hit}"


def builtin_names() -> set[str]:
    """The entry-point names of bark's own strategies (those that bark_plugins provides)."""
    groups = ("bark.growth", "bark.integrator", "bark.breaker", "bark.resin", "bark.analyzer")
    return {ep.name for g in groups for ep in entry_points(group=g) if ep.value.startswith("bark_plugins.")}


DEFAULTS = ("bark.engine.scene", "DEFAULT_STRATEGIES")
"""The one place the core names built-ins: the strategies a scene gets when it names none."""
HOMONYMS = {("bark.engine.simulation", "patches"): "a stop reason (the run reached its patch count), not the analyzer",
            **{(module, "hookean"): "the paper's spring law as a function (eq. 1), exported by name, not the resin"
               for module in ("bark.model.physics", "bark.contract")}}
"""Strings that are a built-in's name by chance, with what they are."""


def test_the_core_names_no_built_in_strategy():
    """No string in the core's code is a built-in strategy's name, but the scene's defaults: the
    core treats a built-in as it treats a third party's strategy."""
    names = builtin_names()
    assert {"sqrt", "bulge", "threshold"} <= names
    for module, path in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip: set[int] = set()
        for node in ast.walk(tree):
            if module == DEFAULTS[0] and isinstance(node, (ast.Assign, ast.AnnAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                if any(isinstance(t, ast.Name) and t.id == DEFAULTS[1] for t in targets):
                    skip.update(id(n) for n in ast.walk(node))
        hits = sorted({n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)
                       and n.value in names and id(n) not in skip and (module, n.value) not in HOMONYMS})
        assert not hits, f"{module} names the built-in strategies {hits}"


def test_the_rule_is_the_one_architecture_states():
    """ARCHITECTURE.md's table of layers says what this test enforces."""
    text = (ROOT / "ARCHITECTURE.md").read_text(encoding="utf-8")
    for name, may in LAYERS.items():
        line = next((ln for ln in text.splitlines() if ln.startswith(f"| `bark/{name}/`")), None)
        assert line is not None, f"ARCHITECTURE.md has no row for bark/{name}/"
        said = {w.strip("`/ ").removeprefix("bark/") for w in line.split("|")[2].split(",") if w.strip() not in ("", "—")}
        assert said == may, f"bark/{name}/: ARCHITECTURE.md says it may import {said}, the test holds {may}"


def test_the_loop_architecture_shows_is_run_s_docstring_literally():
    """ARCHITECTURE.md says ``Simulation.run``'s docstring is the loop, literally, and shows it: the
    two are the same lines (indentation aside), so that one cannot change without the other."""
    import inspect
    import textwrap

    from bark.engine.simulation import Simulation

    doc = inspect.getdoc(Simulation.run)
    shown = textwrap.dedent(doc.split("::\n", 1)[1].lstrip("\n").split("\n\n", 1)[0])
    text = (ROOT / "ARCHITECTURE.md").read_text(encoding="utf-8")
    said = text.split("`Simulation.run`'s docstring is the loop, literally", 1)[1].split("```\n", 2)[1]
    assert said.rstrip("\n") == shown.rstrip("\n")


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
