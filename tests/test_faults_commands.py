"""Fault injection, the other commands: `bark bench` refuses bad arguments before any work, `bark plan`
builds nothing, and help lists what each option means and allows."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from bark.engine import simulation
from bark_cli.main import cli

from conftest import assert_clean_outcome


@pytest.mark.parametrize("args, named", [
    (["bench", "speed", "--n-bases", "0"], "--n-bases"),
    (["bench", "speed", "--repeats", "0"], "--repeats"),
    (["bench", "speed", "--steps", "-5"], "--steps"),
    (["bench", "speed", "--n-bases", "400000000"], "--n-bases"),
    (["bench", "accuracy", "--reference-dt", "0"], "--reference-dt"),
    (["bench", "accuracy", "--reference-dt", "0.9"], "--reference-dt 0.9"),
    (["bench", "accuracy", "--seeds", "0"], "--seeds"),
    (["bench", "accuracy", "--seeds", "1"], "--seeds"),
    (["bench", "accuracy", "--until-time", "nan"], "--until-time"),
    (["bench", "accuracy", "--out", "/proc/nope"], "--out"),
    (["bench", "scenes", "nosuch.toml"], "nosuch.toml"),
    (["bench", "scenes", "bark/scenes/vertical.toml", "--repeats", "0"], "--repeats"),
    (["bench", "fit", "--scene", "nosuch.toml"], "nosuch.toml"),
    (["bench", "fit", "--population", "1"], "--population"),
    (["bench", "fit", "--workers", "0"], "--workers"),
    (["plan", "nosuch.toml"], "nosuch.toml"),
])
def test_bench_and_plan_refuse_bad_arguments_before_any_work(args, named, monkeypatch):
    def no_work(*a, **k):
        raise AssertionError("work started before the arguments were checked")

    monkeypatch.setattr(simulation.Simulation, "run", no_work)
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 2, result.output
    assert_clean_outcome(result)
    assert named in result.stderr, result.stderr


def test_plan_builds_nothing(tmp_path, monkeypatch):
    """A scene of five million bases is planned without building its simulation."""
    def no_build(*a, **k):
        raise AssertionError("bark plan built a simulation")

    monkeypatch.setattr(simulation.Simulation, "build", no_build)
    scene = tmp_path / "huge.toml"
    scene.write_text("[lattice]\nn_bases = 5000000\n[run]\nuntil_time = 10\n[effects]\nwant = ['patch-statistics']\n")
    result = CliRunner().invoke(cli, ["plan", str(scene)])
    assert result.exit_code == 0, result.output
    assert "memory: about" in result.output and "PatchAnalyzer" in result.output


def test_plan_says_when_a_run_has_no_time_bound(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text("[run]\nuntil_patches = 50\n")
    result = CliRunner().invoke(cli, ["plan", str(scene)])
    assert result.exit_code == 0 and "no time bound" in result.output


def test_help_gives_meaning_units_and_choices():
    for flag in ("-h", "--help"):
        result = CliRunner().invoke(cli, ["simulate", flag])
        assert result.exit_code == 0
    text = " ".join(result.output.split())
    assert "[fixed|auto|adaptive]" in text and "[auto|numpy|numba]" in text and "[warn|stop]" in text
    assert "time units (1 = 88.5 days)" in text and "length units" in text
    assert "Stiffness of the springs between neighbouring bases (force / length)" in text
    assert "[lattice]" not in text and "[mechanics]" not in text  # meanings, not scene table names
    for command in (["-h"], ["bench", "-h"], ["bench", "speed", "-h"], ["plan", "-h"], ["strategies", "-h"]):
        assert CliRunner().invoke(cli, command).exit_code == 0, command


def test_no_message_a_user_sees_cites_a_file_they_do_not_have():
    from conftest import REPO_ROOT

    shipped = [*REPO_ROOT.glob("bark/**/*.py"), *REPO_ROOT.glob("cli/*.py"), *REPO_ROOT.glob("plugins/*.py"),
               *REPO_ROOT.glob("examples/**/*.toml"), *REPO_ROOT.glob("docs/*.md"), REPO_ROOT / "README.md",
               REPO_ROOT / "ARCHITECTURE.md"]
    assert not [p.name for p in shipped if "NOTES.md" in p.read_text()]
    assert (REPO_ROOT / "docs" / "numerics.md").is_file()  # what messages cite instead


def test_bench_speed_runs_small(tmp_path):
    """The benchmark itself runs (tiny sizes: a smoke test, never a timing)."""
    out = tmp_path / "speed.csv"
    result = CliRunner().invoke(cli, ["bench", "speed", "--n-bases", "200", "--steps", "5", "--repeats", "1",
                                      "--phase", "quiet", "--csv", str(out)])
    assert result.exit_code == 0, result.output
    assert "speed_vs_plain_numpy" in out.read_text() and "plain numpy" in out.read_text()
