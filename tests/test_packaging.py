"""How bark is installed: entry points, import hygiene of the core, top-level names."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from importlib import metadata

import pytest

from bark.contract import registry, strategies

BUILTINS = {
    "bark.growth": {"sqrt": strategies.Growth, "linear": strategies.Growth},
    "bark.integrator": {"euler-cromer": strategies.Integrator},
    "bark.breaker": {"threshold": strategies.Breaker},
    "bark.resin": {"hookean": strategies.Resin, "maxwell": strategies.Resin, "plastic": strategies.Resin,
                   "nonlinear": strategies.Resin},
    "bark.analyzer": {"patches": strategies.Analyzer},
}


@pytest.mark.parametrize("group", list(BUILTINS))
def test_builtins_are_registered_as_entry_points(group):
    eps = {ep.name: ep for ep in metadata.entry_points(group=group)}
    for name, base in BUILTINS[group].items():
        assert name in eps, f"{name} not registered under {group}"
        assert eps[name].dist is None or eps[name].dist.name == "bark-grasstree"
        assert eps[name].value.startswith("bark_plugins.")
        cls = eps[name].load()
        assert isinstance(cls, type) and issubclass(cls, base)
        assert cls.kind == group.split(".", 1)[1]
        assert cls() is not None  # instantiable with defaults


@pytest.mark.parametrize("kind", strategies.KINDS)
def test_registry_uses_the_same_entry_points(kind):
    group = f"bark.{kind}"
    assert registry.GROUPS[kind] == group
    assert set(BUILTINS[group]) <= set(registry.available(kind))
    for name in BUILTINS[group]:
        assert registry.load(kind, name) is metadata.entry_points(group=group)[name].load()


def _run(code: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=120)


def test_core_never_imports_click_rich_or_matplotlib(tmp_path):
    code = (
        "import bark, bark.engine.scene, bark.engine.simulation, bark.io.output, bark.analysis.patches, bark.contract.registry, sys\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('click', 'rich', 'matplotlib'))\n"
        "assert not bad, bad\n"
    )
    proc = _run(code, tmp_path)
    assert proc.returncode == 0, proc.stderr


def test_the_import_check_can_fail(tmp_path):
    """The same check flags the command line, which does import click (so the check is live)."""
    code = (
        "import bark_cli.main, sys\n"
        "assert not any(m.split('.')[0] in ('click', 'rich', 'matplotlib') for m in sys.modules)\n"
    )
    assert _run(code, tmp_path).returncode != 0


_TOP_LEVEL_CODE = r"""
import json
from importlib import metadata
from pathlib import PurePosixPath

dist = metadata.distribution("bark-grasstree")
names = set()
for f in dist.files or []:
    parts = PurePosixPath(str(f)).parts
    if not parts or parts[0] in ("..", "__pycache__") or parts[0].endswith((".dist-info", ".egg-info")):
        continue
    if len(parts) > 1:  # a package folder in site-packages
        names.add(parts[0])
    elif parts[0].endswith(".py") and not parts[0].startswith("__editable__"):
        names.add(parts[0][:-3])
top = dist.read_text("top_level.txt") or ""
names |= {line.strip() for line in top.splitlines() if line.strip()}
print(json.dumps(sorted(names)))
"""


def test_installed_top_level_names_start_with_bark(tmp_path):
    """The installed distribution (read away from the source tree, whose bark.egg-info lists
    source paths) puts only bark* names into site-packages."""
    proc = _run(_TOP_LEVEL_CODE, tmp_path)
    assert proc.returncode == 0, proc.stderr
    names = set(json.loads(proc.stdout))
    assert "bark" in names
    assert "cli" not in names and "plugins" not in names
    assert all(n.startswith("bark") for n in names), names


def test_no_top_level_cli_or_plugins_outside_the_repo(tmp_path):
    """Away from the source tree, only bark* names are importable from the installation."""
    code = (
        "import importlib.util as u\n"
        "assert u.find_spec('cli') is None, u.find_spec('cli')\n"
        "assert u.find_spec('plugins') is None, u.find_spec('plugins')\n"
        "for name in ('bark', 'bark_cli', 'bark_plugins'):\n"
        "    assert u.find_spec(name) is not None, name\n"
    )
    proc = _run(code, tmp_path)
    assert proc.returncode == 0, proc.stderr


def test_editable_finder_maps_only_bark_names():
    import importlib.util

    for name in ("bark_cli", "bark_plugins"):
        spec = importlib.util.find_spec(name)
        assert spec is not None and spec.origin
    finders = [m for m in sys.modules if m.startswith("__editable__") and "bark" in m]
    for mod in finders:
        mapping = getattr(sys.modules[mod], "MAPPING", {})
        assert mapping and all(k.startswith("bark") for k in mapping), mapping


def test_console_script_is_registered():
    scripts = {ep.name: ep.value for ep in metadata.entry_points(group="console_scripts") if ep.name == "bark"}
    assert scripts == {"bark": "bark_cli.__main__:main"}


@pytest.mark.slow  # a wheel built: the quick subset (-m "not slow") leaves it out
def test_a_built_wheel_has_every_module(tmp_path):
    """An editable install maps folders, so it hides a package missing from the wheel's list: build
    the real wheel, install it apart, and import every module of bark, bark_plugins and bark_cli."""
    import os

    from conftest import REPO_ROOT

    import shutil

    wheels, site, source = tmp_path / "wheels", tmp_path / "site", tmp_path / "source"
    # build from a clean copy: a build/ folder left in the checkout would fill any gap with stale files
    shutil.copytree(REPO_ROOT, source, ignore=shutil.ignore_patterns(
        "build", "dist", "*.egg-info", ".venv", ".ci-venv", "__pycache__", ".hypothesis", ".git", "bark-out*"))
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                            "-w", str(wheels), str(source)], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    (wheel,) = wheels.glob("bark_grasstree-*.whl")
    assert wheel.name.split("-")[1] == (REPO_ROOT / "VERSION").read_text().strip()  # a tree without git: VERSION's
    install = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(site), str(wheel)],
                             capture_output=True, text=True)
    assert install.returncode == 0, install.stderr
    modules = sorted(
        ".".join([pkg, *py.relative_to(REPO_ROOT / folder).with_suffix("").parts]).removesuffix(".__init__")
        for pkg, folder in [("bark", "bark"), ("bark_plugins", "plugins"), ("bark_cli", "cli")]
        for py in (REPO_ROOT / folder).rglob("*.py")
    )
    assert "bark.engine.kernels.numba_backend" in modules
    # drop the finders of an editable install, which would fill any gap from the source tree
    code = ("import importlib, sys\n"
            "sys.meta_path[:] = [f for f in sys.meta_path\n"
            "                    if not (f if isinstance(f, type) else type(f)).__module__.startswith('__editable__')]\n"
            "for m in sys.argv[1:]:\n    importlib.import_module(m)\n"
            "import bark; print(bark.__file__)")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(site)
    result = subprocess.run([sys.executable, "-c", code, *modules], capture_output=True, text=True, cwd=tmp_path, env=env)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().startswith(str(site))  # imported from the wheel, not the source tree
    # what the wheel carries besides modules: the scenes by name, the schema, the license, py.typed
    shipped = {p.name for p in (site / "bark" / "scenes").glob("*.toml")}
    assert shipped == {p.name for p in (REPO_ROOT / "bark" / "scenes").glob("*.toml")} and "whole-tree.toml" in shipped
    assert (site / "bark" / "schemas" / "summary.schema.json").is_file()
    assert all((site / pkg / "py.typed").is_file() for pkg in ("bark", "bark_plugins", "bark_cli"))
    (info,) = site.glob("bark_grasstree-*.dist-info")
    assert any(p.name == "LICENSE" for p in info.rglob("*")) and "Name: bark-grasstree" in (info / "METADATA").read_text()
    unedit = code.split("for m in")[0]  # the same finders dropped: the wheel alone
    out = tmp_path / "run"
    run = subprocess.run([sys.executable, "-c", unedit + "import runpy; runpy.run_module('bark', run_name='__main__')",
                          "simulate", "--scene", "whole-tree-small", "--until-time", "1", "--out", str(out), "--quiet"],
                         capture_output=True, text=True, cwd=tmp_path, env=env)
    assert run.returncode == 0, run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["scene"]["name"] == "whole-tree-small" and (out / "scene.toml").is_file()


def _git(repo, *args):
    done = subprocess.run(["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t", *args],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def _written(repo) -> str | None:
    code = "import sys; sys.path.insert(0, 'tools'); import bark_build; print(bark_build.written_version())"
    done = subprocess.run([sys.executable, "-c", code], cwd=repo, capture_output=True, text=True,
                          env={k: v for k, v in os.environ.items() if not k.startswith("SETUPTOOLS_SCM_PRETEND")})
    assert done.returncode == 0, done.stderr
    return None if done.stdout.strip() == "None" else done.stdout.strip()


@pytest.mark.slow  # a clone of the repository, commits and a wheel built in it
def test_the_version_is_the_release_tag_s_else_the_one_written_in_version(tmp_path):
    from conftest import REPO_ROOT

    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", "--no-tags", str(REPO_ROOT), str(clone)], check=True)
    tags = _git(clone, "tag", "-l").split()
    if tags:  # a clone carries no tag (--no-tags): as the project's own clones come
        _git(clone, "tag", "-d", *tags)
    (clone / "VERSION").write_text("0.7.2\n")
    _git(clone, "commit", "-q", "-am", "release 0.7.2")
    assert _written(clone) == "0.7.2"  # the release commit: the version written down, exactly
    (clone / "README.md").write_text("changed\n")
    assert _written(clone) == f"0.7.3.dev0+g{_git(clone, 'rev-parse', '--short', 'HEAD')}.dirty"
    _git(clone, "commit", "-q", "-am", "after the release")
    _git(clone, "commit", "-q", "--allow-empty", "-m", "and another")
    assert _written(clone) == f"0.7.3.dev2+g{_git(clone, 'rev-parse', '--short', 'HEAD')}"  # its successor, 2 on
    _git(clone, "tag", "v9.9.9")
    assert _written(clone) is None  # a release tag: setuptools-scm's version
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w",
                            str(tmp_path / "wheels"), str(clone)], capture_output=True, text=True,
                           env={k: v for k, v in os.environ.items() if not k.startswith("SETUPTOOLS_SCM_PRETEND")})
    assert build.returncode == 0, build.stderr
    assert [w.name.split("-")[1] for w in (tmp_path / "wheels").glob("*.whl")] == ["9.9.9"]
