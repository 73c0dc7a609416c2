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
