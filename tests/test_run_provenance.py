"""What a run says made it: summary.json's provenance and JSON Schema, scene.toml beside it
(tests/test_provenance.py: how each strategy is recorded)."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
from click.testing import CliRunner

from bark.engine.scene import SHIPPED
from bark.units import COLUMN_UNITS
from bark_cli.main import cli

UNITS_IN = {"statistics.csv": ("t_tu", "radius_lu"), "breaks.csv": ("t_tu", "tension_fu"),
            "fracture.csv": ("t_tu", "dissipation_fu_lu_per_tu"), "patches.csv": ("z_lu", "lambda1_lu2", "lambda2_lu2")}
SCHEMA = json.loads((SHIPPED.parent / "schemas" / "summary.schema.json").read_text())


def _summary(folder: Path) -> dict:
    return json.loads((folder / "summary.json").read_text())


def test_the_schema_is_a_valid_json_schema():
    jsonschema.Draft202012Validator.check_schema(SCHEMA)


@pytest.mark.parametrize("args", [
    [],  # the default scene
    ["--scene", "whole-tree-small", "--until-time", "3"],  # regions, windows, phyllotaxis at transition
    ["--scene", "everything", "--until-time", "20"],  # every effect: fracture history, ...
    ["--scene", "stiff", "--until-time", "0.5"],  # the implicit integrator: no stability limit
    ["--growth", "linear", "--until-time", "5", "--set", "effects.want=['secondary-growth']"],  # no fracture at all
])
def test_every_summary_json_validates_against_the_shipped_schema(tmp_path, args):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["simulate", *args, "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    jsonschema.Draft202012Validator(SCHEMA).validate(_summary(out))
    for table in out.glob("*.csv"):  # and every CSV names the units of its columns
        header = table.read_text().splitlines()[0].split(",")
        assert not set(header) & set(COLUMN_UNITS), f"{table.name}: {header}"
        assert set(UNITS_IN.get(table.name, ())) <= set(header), f"{table.name}: {header}"


def test_a_run_records_its_version_commit_command_and_start_and_a_resume_adds_itself(tmp_path):
    from bark.version import __version__, source_commit

    out = tmp_path / "out"
    first = CliRunner().invoke(cli, ["simulate", "--until-time", "40", "--out", str(out), "--quiet"])
    assert first.exit_code == 0, first.output
    made = _summary(out)["provenance"]
    assert made["bark_version"] == __version__ == _summary(out)["bark_version"]
    assert (made["commit"], made["dirty"]) == source_commit()
    command = f"bark simulate --until-time 40 --out {out} --quiet"
    assert [s["command"] for s in made["sessions"]] == [command] and made["sessions"][0]["started"].endswith("+00:00")
    (out / "summary.json").unlink()  # its outputs not all written: --resume writes them, and says it ran
    again = CliRunner().invoke(cli, ["simulate", "--resume", str(out), "--quiet"])
    assert again.exit_code == 0, again.output
    assert [s["command"] for s in _summary(out)["provenance"]["sessions"]] == [command, f"bark simulate --resume {out} --quiet"]


@pytest.mark.slow  # two whole runs: seconds: the quick subset (-m "not slow") leaves it out
def test_scene_toml_reruns_the_run_to_the_same_bits(tmp_path):
    """scene.toml beside summary.json holds every setting resolved: `--scene out/scene.toml` runs the
    same run again, to the bit."""
    first, again = tmp_path / "first", tmp_path / "again"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "whole-tree-small", "--until-time", "4", "--seed", "3",
                                      "--set", "mechanics.f_max=0.004", "--out", str(first), "--quiet"])
    assert result.exit_code == 0, result.output
    result = CliRunner().invoke(cli, ["simulate", "--scene", str(first / "scene.toml"), "--out", str(again), "--quiet"])
    assert result.exit_code == 0, result.output
    for name in ("state.npz", "breaks.csv", "patches.csv", "scene.toml"):
        assert (first / name).read_bytes() == (again / name).read_bytes(), name
    assert _summary(again)["settings"] == _summary(first)["settings"]
