"""The example plugin (examples/plugin/) round trip: install, list, select, run.

Installed with ``pip install --target`` into a temporary folder put on PYTHONPATH, from a copy of
the plugin's folder (a build writes ``build/`` and ``*.egg-info`` beside its sources), so the test
leaves the environment and the checkout as it found them; entry points are found from that folder's
dist-info exactly as from site-packages.
"""

from __future__ import annotations

import csv
import os
import shutil
import subprocess
import sys
from collections import Counter

import pytest

from conftest import REPO_ROOT

PLUGIN = REPO_ROOT / "examples" / "plugin"


@pytest.fixture(scope="module")
def plugin_path(tmp_path_factory):
    target = tmp_path_factory.mktemp("plugin-site")
    source = tmp_path_factory.mktemp("plugin-source") / "plugin"
    shutil.copytree(PLUGIN, source, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    # build with the setuptools the test extra installs: no download, no isolated build environment
    cmd = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--target", str(target), str(source)]
    result = subprocess.run(cmd, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return target


def _bark(plugin_path, *args, env=None, **kw):
    env = {**os.environ, **(env or {}), "PYTHONPATH": os.pathsep.join([str(plugin_path), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "bark_cli", *args], env=env, capture_output=True, text=True, **kw)


def test_example_plugin_is_listed(plugin_path):
    result = _bark(plugin_path, "strategies", env={"COLUMNS": "200"})
    assert result.returncode == 0, result.stderr
    rows = {line.split("│")[2].strip(): line for line in result.stdout.splitlines() if line.count("│") > 4}
    assert "max_per_step" in rows["most-overloaded"] and "select in Python" in rows["most-overloaded"]
    assert "eps=0.05" in rows["strain"] and rows["strain"].rstrip(" │").endswith("compiled")
    assert "a=0.5" in rows["power-law"] and rows["power-law"].rstrip(" │").endswith("compiled")


def test_example_plugin_is_selected_and_runs(plugin_path, tmp_path):
    out = tmp_path / "run"
    result = _bark(plugin_path, "simulate", "--breaker", "most-overloaded", "--set", "breaker.max_per_step=1",
                   "--stepping", "fixed", "--dt", "0.05", "--n-bases", "400", "-G", "0.05", "--until-time", "8",
                   "--out", str(out), "--quiet")
    assert result.returncode == 0, result.stderr
    per_step = Counter(row["step"] for row in csv.DictReader((out / "breaks.csv").read_text().splitlines()))
    assert sum(per_step.values()) > 20  # it cracked ...
    assert max(per_step.values()) == 1  # ... one spring per step, as the plugin's rule says


def test_threshold_breaker_breaks_batches_where_the_plugin_does_not(tmp_path):
    """The same run with the built-in breaker breaks several springs in some step: the plugin's
    one-per-step result above is its own doing."""
    from click.testing import CliRunner

    from bark_cli.main import cli

    out = tmp_path / "run"
    result = CliRunner().invoke(cli, ["simulate", "--stepping", "fixed", "--dt", "0.05", "--n-bases", "400", "-G", "0.05",
                                      "--until-time", "8", "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    per_step = Counter(row["step"] for row in csv.DictReader((out / "breaks.csv").read_text().splitlines()))
    assert max(per_step.values()) > 1
