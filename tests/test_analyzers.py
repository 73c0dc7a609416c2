"""Analyzers that own their output: several per scene ([[analyzer]]), each one's summary in
summary.json under its name and each of its tables as a CSV; an analyzer may read the springs."""

from __future__ import annotations

import csv
import json
import sys

import pytest

from bark.engine.scene import Scene
from bark.errors import BarkError
from bark.io.output import analysis_file
from bark.studies import runner
from conftest import REPO_ROOT

sys.path.insert(0, str(REPO_ROOT / "examples" / "plugin"))  # the example plugin, as its author tests it

CRACKS = "bark_example_plugin.cracks:CracksByParastichy"  # how a scene names it, installed or not


def _recorded() -> str:
    """How a run records the plugin's analyzer: its entry-point name where the plugin is installed
    (its metadata on the path), else its import path."""
    from bark.contract import registry
    from bark_example_plugin.cracks import CracksByParastichy

    return registry.name_of(CracksByParastichy)
SMALL = {"lattice": {"n_bases": 400}, "growth": {"G": 0.05}, "run": {"until_time": 20.0, "backend": "numpy"},
         "effects": {"want": ["patch-statistics", "break-log", "state-snapshot"]}}


def _run(tmp_path, analyzer, name="out"):
    scene = Scene.from_dict({**SMALL, "analyzer": analyzer})
    out = tmp_path / name
    runner.run(scene, out)
    return out, json.loads((out / "summary.json").read_text())


def test_two_analyzers_each_write_under_their_name_and_the_paper_s_statistics_stay(tmp_path):
    one, alone = _run(tmp_path, {"name": "patches"}, "alone")
    two, both = _run(tmp_path, [{"name": "patches"}, {"name": CRACKS}], "both")
    assert set(both["analyses"]) == {"patches", _recorded()} and set(alone["analyses"]) == {"patches"}
    for key in ("n_patches", "mean_orientation_deg", "circular_sd_deg", "mean_anisotropy", "network", "regions"):
        assert both[key] == alone[key], key
    assert both["analyses"]["patches"] == alone["analyses"]["patches"]
    assert (two / "patches.csv").read_bytes() == (one / "patches.csv").read_bytes()
    assert (two / "breaks.csv").read_bytes() == (one / "breaks.csv").read_bytes()
    table = two / analysis_file(_recorded(), "by_parastichy")
    with table.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["offset"]) for r in rows] == [21, 34]
    assert sum(int(r["cracks"]) for r in rows) == both["n_broken"] > 0
    for r in rows:
        assert both["analyses"][_recorded()][f"cracked_share_{r['offset']}"] == pytest.approx(float(r["cracked_share"]))
    assert both["settings"]["analyzer"] == [{"name": "patches", "min_size": 7}, {"name": _recorded()}]
    assert analysis_file(CRACKS, "by_parastichy") == "analysis-bark_example_plugin.cracks-CracksByParastichy-by_parastichy.csv"


def test_a_scene_file_with_analyzer_tables_reads_back_as_it_was_written(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text('[lattice]\nn_bases = 400\n\n[run]\nuntil_time = 5.0\n\n[[analyzer]]\nname = "patches"\n\n[[analyzer]]\n'
                    f'name = "{CRACKS}"\n')
    scene = Scene.from_toml(path)
    assert [type(a).__name__ for a in scene.components()["analyzers"]] == ["PatchAnalyzer", "CracksByParastichy"]
    again = tmp_path / "again.toml"
    again.write_text(scene.to_toml())
    assert Scene.from_toml(again).to_dict() == scene.to_dict()


def test_a_fresh_run_removes_the_tables_an_earlier_run_left(tmp_path):
    out, _ = _run(tmp_path, [{"name": "patches"}, {"name": CRACKS}], "same")
    scene = Scene.from_dict({**SMALL, "analyzer": {"name": "patches"}})
    runner.run(scene, out)
    assert not list(out.glob("analysis-*.csv"))


@pytest.mark.parametrize("analyzer, message", [
    ([{"name": "patches"}, {"name": "patches"}], "two analyzers 'patches'"),
    ([{"name": "patches"}, {"min_size": 3}], "each \\[\\[analyzer\\]\\] table names its analyzer"),
    ([{"name": "patches"}, {"name": "nosuch"}], "nosuch"),
    ([{"name": "patches"}, {"name": CRACKS, "x": 1}], "not a setting"),
    ([], "must be a table"),
    ([1, 2], "must be a table"),
])
def test_bad_analyzer_tables_are_one_line(analyzer, message):
    with pytest.raises(BarkError, match=message) as err:
        Scene.from_dict({**SMALL, "analyzer": analyzer})
    assert "\n" not in str(err.value)


def test_a_photograph_gives_an_analyzer_that_reads_springs_none():
    import numpy as np

    from bark_example_plugin.cracks import CracksByParastichy

    points = np.random.default_rng(0).random((50, 2))
    assert CracksByParastichy().analyze(points, np.zeros(50, int), None).summary == {}


def _invoke(*args):
    from click.testing import CliRunner

    from bark_cli.main import cli

    return CliRunner().invoke(cli, [str(a) for a in args])


def _photograph(run, path):
    """The run's pattern as a photograph gives it: leaf-base centres in a plane, a patch each, no springs."""
    import numpy as np

    with np.load(run / "state.npz") as d:
        x, labels = d["x"], d["labels"]
    r = np.hypot(x[:, 0], x[:, 1]).mean()
    rows = "".join(f"{float(a)!r},{float(b)!r},{c}\n" for a, b, c in zip(r * np.mod(np.arctan2(x[:, 1], x[:, 0]), 2 * np.pi), x[:, 2], labels))
    path.write_text("x,y,patch\n" + rows)
    return path


def test_the_network_statistics_are_an_analyzer_with_the_run_s_numbers_and_its_table(tmp_path):
    out, summary = _run(tmp_path, [{"name": "patches"}, {"name": "crack-network"}])
    mine, core = summary["analyses"]["crack-network"], summary["network"]
    assert mine == {k: v for k, v in core.items() if k != "lattice_bias"} and mine["n_junctions"] > 0
    with (out / analysis_file("crack-network", "lattice_bias")).open(newline="") as fh:
        rows = {r["offset"]: r for r in csv.DictReader(fh)}
    assert set(rows) == set(core["lattice_bias"]) == {"21", "34"}
    for offset, row in rows.items():
        assert float(row["bias"]) == pytest.approx(core["lattice_bias"][offset]["bias"])


def test_bark_analyze_runs_a_scene_s_analyzers_on_a_run_and_on_a_photograph(tmp_path):
    out, summary = _run(tmp_path, [{"name": "patches"}, {"name": "crack-network"}, {"name": CRACKS}])
    scene = tmp_path / "analyzers.toml"
    scene.write_text(f'[[analyzer]]\nname = "patches"\n\n[[analyzer]]\nname = "crack-network"\n\n[[analyzer]]\nname = "{CRACKS}"\n')
    result = _invoke("analyze", out, "--scene", scene, "--out", tmp_path / "a")
    assert result.exit_code == 0, result.output
    again = json.loads((tmp_path / "a" / "statistics.json").read_text())["analyses"]
    assert again["crack-network"] == summary["analyses"]["crack-network"]  # from its files, the run's own numbers
    assert again[_recorded()] == summary["analyses"][_recorded()]
    for name in (analysis_file("crack-network", "lattice_bias"), analysis_file(_recorded(), "by_parastichy")):
        assert (tmp_path / "a" / name).read_bytes() == (out / name).read_bytes()
    photo = _photograph(out, tmp_path / "photo.csv")
    result = _invoke("analyze", photo, "--scene", scene, "--out", tmp_path / "a")  # the same folder: its tables go
    assert result.exit_code == 0, result.output
    seen = json.loads((tmp_path / "a" / "statistics.json").read_text())["analyses"]
    assert seen[_recorded()] == {} and "n_junctions" not in seen["crack-network"]  # no springs: the sizes alone
    assert seen["crack-network"]["size_mean"] == pytest.approx(summary["analyses"]["crack-network"]["size_mean"])
    assert not list((tmp_path / "a").glob("analysis-*.csv"))


@pytest.mark.parametrize("pattern, scene, message", [
    ("summary.toml", "analyzers.toml", "a published summary has no leaf bases"),
    ("photo.csv", "nosuch.toml", "scene file 'nosuch.toml' does not exist"),
    ("photo.csv", "bad.toml", "nosuch"),
])
def test_bark_analyze_with_a_bad_scene_or_pattern_says_one_line_and_writes_nothing(tmp_path, pattern, scene, message):
    (tmp_path / "summary.toml").write_text("[pattern]\nn_patches = 10\nmean_orientation_deg = 80.0\nsd_orientation_deg = 10.0\n")
    (tmp_path / "photo.csv").write_text("x,y,patch\n" + "".join(f"{i % 10},{i // 10},{i // 20}\n" for i in range(100)))
    (tmp_path / "analyzers.toml").write_text('[[analyzer]]\nname = "crack-network"\n')
    (tmp_path / "bad.toml").write_text('[[analyzer]]\nname = "nosuch"\n')
    result = _invoke("analyze", tmp_path / pattern, "--scene", tmp_path / scene if scene != "nosuch.toml" else scene,
                     "--out", tmp_path / "out")
    assert result.exit_code != 0 and message in result.output and result.output.count("\n") == 1, result.output
    assert not (tmp_path / "out").exists()
