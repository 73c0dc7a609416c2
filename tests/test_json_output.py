"""``--json`` on the commands that print a result: the document the command writes, alone on stdout
(what was written said on stderr), for a script to read; with ``--quiet`` too."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from bark_cli.main import cli

TINY = ["--set", "lattice.n_bases=300", "--set", "run.until_time=20"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two small runs to measure and compare."""
    folder = tmp_path_factory.mktemp("runs")
    for seed in (0, 1):
        r = CliRunner().invoke(cli, ["simulate", "--n-bases", "600", "--until-time", "150", "-G", "0.03", "--seed", str(seed),
                                     "--quiet", "--out", str(folder / f"run{seed}")])
        assert r.exit_code == 0, r.output
    return folder


@pytest.mark.parametrize("quiet", [[], ["--quiet"]])
def test_sweep_json_is_every_run_and_the_counts(tmp_path, quiet):
    out = tmp_path / "s"
    r = CliRunner().invoke(cli, ["sweep", *TINY, "--grid", "growth.G=0.01,0.02", "--seeds", "2", "--out", str(out), "--json", *quiet])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert (doc["total"], doc["ran"], doc["skipped"]) == (4, 4, 0) and doc["table"] == str(out / "sweep.sqlite")
    assert [(run["growth.G"], run["seed"]) for run in doc["runs"]] == [(0.01, 0), (0.01, 1), (0.02, 0), (0.02, 1)]
    assert all(set(run) >= {"key", "n_patches", "mean_orientation_deg", "t", "wall_s"} for run in doc["runs"])
    assert "runs in" in r.stderr  # what was written: on stderr


@pytest.mark.parametrize("command,written", [("analyze", "statistics.json"), ("compare", "comparison.json")])
def test_analyze_and_compare_json_is_the_document_they_write(runs, tmp_path, command, written):
    patterns = [str(runs / "run0")] + ([str(runs / "run1")] if command == "compare" else [])
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, [command, *patterns, "--out", str(out), "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout) == json.loads((out / written).read_text())
    assert r.stderr.startswith("wrote ") and "patterns (orientation" not in r.stdout  # no table with --json
