"""The `bark` command line, through click's CliRunner (no subprocess, no network)."""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest
from click.testing import CliRunner

from bark_cli.bench import CASES
from bark_cli.main import cli

from conftest import REPO_ROOT

SUMMARY_KEYS = {
    "settings", "seed", "bark_version", "stop", "stop_reason", "t", "radius", "n_broken", "n_patches",
    "mean_orientation_deg", "circular_sd_deg", "mean_anisotropy",
}
SMALL = ["--n-bases", "300", "--until-time", "1", "--quiet"]


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    """One small simulate run shared by the output tests."""
    out = tmp_path_factory.mktemp("run") / "out"
    result = CliRunner().invoke(
        cli, ["simulate", "--n-bases", "400", "--until-time", "20", "-G", "0.03", "--out", str(out), "--quiet"]
    )
    return result, out


def _one_line(result) -> str:
    text = result.output.strip()
    assert text, "expected an error message"
    assert "\n" not in text, text
    assert "Traceback" not in text
    return text


def _names(text: str, name: str) -> bool:
    return re.search(rf"(?<![A-Za-z0-9_-]){re.escape(name)}(?![A-Za-z0-9_.])", text) is not None


# -- a successful run --------------------------------------------------------------------------


def test_simulate_writes_all_outputs(small_run):
    result, out = small_run
    assert result.exit_code == 0, result.output
    for name in ("pattern.png", "patches.csv", "breaks.csv", "summary.json", "state.npz"):
        assert (out / name).is_file(), name
    assert (out / "pattern.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # atomic writes leave no temporary files behind
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]


def test_quiet_run_prints_nothing_on_stdout(small_run):
    result, _ = small_run
    assert result.stdout == ""


def test_summary_json(small_run):
    _, out = small_run
    summary = json.loads((out / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(summary)
    assert summary["stop_reason"] == "time"
    assert summary["t"] == pytest.approx(20.0, abs=1e-9)
    assert summary["stop"]["until_time"] == 20.0
    assert summary["stop"]["until_patches"] is None  # --until-time replaces the default conditions
    assert summary["settings"]["lattice"]["n_bases"] == 400
    assert summary["settings"]["growth"] == {"name": "sqrt", "r0": 0.2, "G": 0.03}
    assert summary["seed"] == 0
    assert summary["radius"] == pytest.approx(0.2 + 0.03 * 20**0.5, rel=1e-12)
    assert summary["n_broken"] > 0 and summary["n_patches"] > 0
    assert 0.0 <= summary["mean_orientation_deg"] < 180.0
    assert isinstance(summary["bark_version"], str) and summary["bark_version"]


def test_state_npz_loads_without_pickle(small_run):
    _, out = small_run
    summary = json.loads((out / "summary.json").read_text())
    with np.load(out / "state.npz", allow_pickle=False) as data:
        assert {"x", "v", "anchor", "pairs", "rest", "fmax", "intact", "labels", "t"} <= set(data.files)
        assert data["x"].shape == (400, 3)
        assert data["intact"].dtype == bool
        assert int(np.count_nonzero(~data["intact"])) == summary["n_broken"]
        assert float(data["t"]) == pytest.approx(summary["t"])
        r = np.hypot(data["x"][:, 0], data["x"][:, 1])
        np.testing.assert_allclose(r, summary["radius"], rtol=1e-12)


def test_csv_tables_agree_with_summary(small_run):
    _, out = small_run
    summary = json.loads((out / "summary.json").read_text())
    with open(out / "breaks.csv", newline="") as fh:
        breaks = list(csv.DictReader(fh))
    assert len(breaks) == summary["n_broken"]
    assert set(breaks[0]) == {"spring", "i", "j", "step", "t_tu", "tension_fu"}
    assert len({row["spring"] for row in breaks}) == len(breaks)
    with open(out / "patches.csv", newline="") as fh:
        patches = list(csv.DictReader(fh))
    assert len(patches) == summary["n_patches"]
    assert all(int(row["size"]) >= 7 for row in patches)
    assert all(0.0 <= float(row["orientation_deg"]) < 180.0 for row in patches)


def test_same_seed_same_outputs(runner, tmp_path):
    outs = []
    for name in ("a", "b"):
        result = runner.invoke(cli, ["simulate", *SMALL, "-G", "0.1", "--seed", "3", "--out", str(tmp_path / name)])
        assert result.exit_code == 0, result.output
        outs.append(tmp_path / name)
    assert (outs[0] / "breaks.csv").read_bytes() == (outs[1] / "breaks.csv").read_bytes()
    with np.load(outs[0] / "state.npz") as a, np.load(outs[1] / "state.npz") as b:
        np.testing.assert_array_equal(a["x"], b["x"])


def test_scene_file_and_options_override(runner, tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text('[lattice]\nn_bases = 250\n[growth]\nname = "linear"\nG = 0.01\n[run]\nuntil_time = 0.5\n')
    out = tmp_path / "out"
    result = runner.invoke(cli, ["simulate", "--scene", str(scene), "--r0", "0.3", "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    settings = json.loads((out / "summary.json").read_text())["settings"]
    assert settings["lattice"]["n_bases"] == 250
    assert settings["growth"] == {"name": "linear", "r0": 0.3, "G": 0.01}


def test_shipped_scene_runs_shortened(runner, tmp_path):
    out = tmp_path / "out"
    scene = REPO_ROOT / "bark" / "scenes" / "diamond.toml"
    result = runner.invoke(cli, ["simulate", "--scene", str(scene), *SMALL, "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["mechanics"]["f_max"] == 0.008
    assert summary["stop_reason"] == "time"


def test_degenerate_run_warns_on_stderr(runner, tmp_path):
    out = tmp_path / "out"
    args = ["simulate", "--n-bases", "600", "--jitter", "0", "--fmax-spread", "0", "--dt", "0.05", "--until-time", "17", "--quiet"]
    result = runner.invoke(cli, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "degenerate" in result.stderr
    assert json.loads((out / "summary.json").read_text())["degenerate_events"]


def test_set_sets_a_strategy_parameter(runner, tmp_path):
    out = tmp_path / "out"
    result = runner.invoke(cli, ["simulate", *SMALL, "--set", "growth.G=0.03", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert json.loads((out / "summary.json").read_text())["settings"]["growth"]["G"] == 0.03


def test_set_then_restating_default_strategy_keeps_the_parameter(runner, tmp_path):
    """Regression: `--growth sqrt` used to drop a G given by --set (merge cleared the table)."""
    out = tmp_path / "out"
    result = runner.invoke(cli, ["simulate", *SMALL, "--set", "growth.G=0.05", "--growth", "sqrt", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert json.loads((out / "summary.json").read_text())["settings"]["growth"]["G"] == 0.05


# -- bad input: one line, status 2, nothing written --------------------------------------------


def _write(tmp_path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


BAD_INPUTS = {  # each message names the setting as the user gave it: the option, the --set item or the file's key
    "negative-k": (lambda p: ["--k", "-1"], "--k -1.0"),
    "dt-zero": (lambda p: ["--dt", "0"], "--dt 0.0"),
    "dt-negative": (lambda p: ["--dt", "-1"], "--dt -1.0"),
    "dt-above-stability-limit": (lambda p: ["--dt", "1", "--stepping", "fixed"], "--dt 1.0"),
    "unknown-growth": (lambda p: ["--growth", "nope"], "--growth nope"),
    "unknown-breaker": (lambda p: ["--breaker", "nope"], "--breaker nope"),
    "unknown-scene-key": (lambda p: ["--scene", _write(p, "k.toml", "[lattice]\nfoo = 1\n")], "foo"),
    "unknown-table": (lambda p: ["--scene", _write(p, "t.toml", "[nope]\nx = 1\n")], "nope"),
    "malformed-toml": (lambda p: ["--scene", _write(p, "bad.toml", "[lattice\nn_bases = \n")], "bad.toml"),
    "missing-scene": (lambda p: ["--scene", str(p / "missing.toml")], "missing.toml"),
    "set-no-equals": (lambda p: ["--set", "garbage"], "--set"),
    "set-no-section": (lambda p: ["--set", "G=0.1"], "--set"),
    "set-no-value-sep": (lambda p: ["--set", "growth.G"], "--set"),
    "set-unknown-key": (lambda p: ["--set", "lattice.foo=1"], "--set lattice.foo=1"),
    "set-bad-value": (lambda p: ["--set", "mechanics.k=-3"], "--set mechanics.k=-3"),
    "set-unknown-table": (lambda p: ["--set", "nosuch.key=1"], "nosuch"),
    "bad-int": (lambda p: ["--n-bases", "many"], "--n-bases"),
    "bad-offsets": (lambda p: ["--offsets", "a,b"], "--offsets"),
    "negative-G": (lambda p: ["-G", "-1"], "-G -1.0"),
    "bad-on-degenerate": (lambda p: ["--on-degenerate", "explode"], "--on-degenerate"),
    "unknown-option": (lambda p: ["--bogus"], "--bogus"),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_is_one_line_exit_2_and_writes_nothing(runner, tmp_path, case):
    make_args, name = BAD_INPUTS[case]
    out = tmp_path / "out"
    result = runner.invoke(cli, ["simulate", "--n-bases", "300", "--until-time", "1", *make_args(tmp_path), "--out", str(out), "--quiet"])
    assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
    text = _one_line(result)
    assert _names(text, name), f"{name!r} not named in {text!r}"
    assert result.stdout == ""  # the message goes to stderr
    assert not out.exists()


def test_scene_value_instead_of_table_is_one_line(runner, tmp_path):
    """Regression: `growth = "sqrt"` at the top of a scene file used to crash with a traceback."""
    scene = _write(tmp_path, "v.toml", 'growth = "sqrt"\n')
    out = tmp_path / "out"
    result = runner.invoke(cli, ["simulate", "--scene", scene, "--until-time", "1", "--out", str(out), "--quiet"])
    assert result.exit_code == 2
    assert _names(_one_line(result), "growth")
    assert not out.exists()


def test_out_that_is_a_file_is_rejected(runner, tmp_path):
    target = tmp_path / "file"
    target.write_text("keep me")
    result = runner.invoke(cli, ["simulate", *SMALL, "--out", str(target)])
    assert result.exit_code == 2
    _one_line(result)
    assert target.read_text() == "keep me"


# -- other commands ----------------------------------------------------------------------------


def test_strategies_lists_builtins(runner, monkeypatch):
    monkeypatch.setenv("COLUMNS", "250")  # rows whole, not cut to the terminal
    result = runner.invoke(cli, ["strategies"])
    assert result.exit_code == 0, result.output
    for name in ("sqrt", "linear", "euler-cromer", "threshold", "patches"):
        assert _names(result.output, name), name
    for kind in ("growth", "integrator", "breaker", "analyzer"):
        assert kind in result.output
    assert "base=SqrtGrowth(r0=0.2, G=0.014)" in result.output  # a nested strategy's default, not its factory


def test_strategies_piped_keeps_every_class_name_whole(runner, monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)  # a pipe: no terminal, no width given
    result = runner.invoke(cli, ["strategies"])
    assert result.exit_code == 0 and "…" not in result.output
    assert "bark_plugins.integrators:ImplicitOverdamped" in result.output


def test_version(runner):
    from bark import __version__

    result = runner.invoke(cli, ["--version"])
    assert result.exit_code == 0
    assert __version__ in result.output


def test_unknown_command_is_one_line(runner):
    result = runner.invoke(cli, ["grow"])
    assert result.exit_code == 2
    assert _names(_one_line(result), "grow")


def test_bench_scenes_times_the_command_as_bark_runs_it(tmp_path):
    """Each run is a fresh process through the command's entry point (how it starts and leaves
    included), its own peak memory reported as it leaves; the table has a row per scene."""
    import shlex

    scene = shlex.quote(str(REPO_ROOT / "bark" / "scenes" / "vertical.toml"))
    result = CliRunner().invoke(cli, ["bench", "scenes", f"{scene} --until-time 0.5 --n-bases 300",
                                      f"{scene} --until-time 0.5 --n-bases 600", "--repeats", "1"])
    assert result.exit_code == 0, result.output
    rows = [line for line in result.output.splitlines() if "vertical.toml" in line]
    assert len(rows) == 2
    for row in rows:  # wall s, time vs first, peak MiB, memory vs first: all measured, all positive
        figures = [float(v) for v in re.findall(r"│ ([0-9.]+) +(?=│)", row)]
        assert len(figures) == 4 and all(v > 0 for v in figures), row


def test_bench_json_is_the_table_s_rows_and_the_machine(tmp_path):
    """--json: the rows the table shows (and the measurements behind its medians) with the machine's
    facts, alone on stdout."""
    import shlex

    scene = shlex.quote(str(REPO_ROOT / "bark" / "scenes" / "vertical.toml"))
    result = CliRunner().invoke(cli, ["bench", "scenes", f"{scene} --until-time 0.5 --n-bases 300", "--repeats", "2", "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["machine"]["cores"] >= 1 and [r["time_vs_first"] for r in doc["rows"]] == [1.0]
    assert len(doc["rows"][0]["wall_s_each"]) == 2 and doc["rows"][0]["peak_MiB"] > 0
    result = CliRunner().invoke(cli, ["bench", "speed", "--n-bases", "300", "--backend", "numpy", "--phase", "quiet",
                                      "--steps", "5", "--repeats", "1", "--json"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)["rows"]
    assert {r["backend"] for r in rows} == {"numpy", "plain numpy"} and all(r["steps_per_s"] > 0 for r in rows)


@pytest.mark.parametrize("case", sorted(CASES))
def test_bench_speed_runs_every_case(case):
    """Every case ``bench speed`` offers is a scene bark accepts and steps (the bulge case once gave
    a bulge's threshold after it had moved to the breaker's regions, and stopped at its scene)."""
    result = CliRunner().invoke(cli, ["bench", "speed", "--n-bases", "300", "--backend", "numpy", "--phase", "quiet",
                                      "--case", case, "--steps", "3", "--repeats", "1", "--json"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)["rows"]
    assert {r["case"] for r in rows} == {case} and all(r["steps_per_s"] > 0 for r in rows if r["backend"] == "numpy")


@pytest.mark.slow  # whole processes: a fit and the plain runs beside it
def test_bench_fit_measures_a_fit_against_plain_processes(tmp_path):
    pytest.importorskip("pyabc")
    scene = tmp_path / "tiny.toml"
    scene.write_text((REPO_ROOT / "bark" / "scenes" / "reticulate.toml").read_text().replace("n_bases = 3000", "n_bases = 400")
                     .replace("until_patches = 115", "until_patches = 10"))
    result = CliRunner().invoke(cli, ["bench", "fit", "--scene", str(scene), "--population", "2", "--workers", "2"])
    assert result.exit_code == 0, result.output
    rows = [line for line in result.output.splitlines() if "at a time" in line or "whole process" in line]
    assert len(rows) == 3  # one at a time, two at a time, the fit
    for row in rows:
        rate, ratio = (float(v) for v in re.findall(r"│ +([0-9.]+) +(?=│)", row))
        assert rate > 0 and ratio > 0, row


@pytest.mark.slow  # a whole process
def test_a_run_whose_stderr_is_a_file_logs_its_progress_there_in_plain_lines(tmp_path):
    """stderr not a terminal (a batch job, nohup): a line at the start, then every --progress-every
    seconds (0: every step), and one at the end; stdout keeps the summary (here as JSON, --json)."""
    import json
    import subprocess
    import sys

    log = tmp_path / "log"
    with open(log, "w") as err:
        done = subprocess.run([sys.executable, "-m", "bark_cli", "simulate", "--until-time", "60", "--progress-every", "0",
                               "--out", str(tmp_path / "out"), "--json"], stdout=subprocess.PIPE, stderr=err,
                              stdin=subprocess.DEVNULL, text=True)
    assert done.returncode == 0
    lines = log.read_text().splitlines()
    assert len(lines) >= 3 and all(line.startswith("bark: t = ") and "elapsed" in line for line in lines), lines[:3]
    assert "left" in lines[1] and lines[-1].startswith("bark: t = 60 (") and "100.0 %" in lines[-1]
    assert json.loads(done.stdout) == json.loads((tmp_path / "out" / "summary.json").read_text())


def test_bark_alone_prints_its_help_not_an_error():
    """``bark`` (or ``python -m bark``) without a command printed its usage as "bark: error: Usage: ..."
    with status 2: it is a request for help."""
    result = CliRunner().invoke(cli, [])
    assert result.exit_code == 0 and result.stderr == "", result.output
    assert result.stdout.startswith("Usage: ") and "simulate" in result.stdout


def test_bark_compile_readies_a_scenes_kernels_and_writes_nothing_else(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(cli, ["compile", "vertical", "diamond"])
    assert result.exit_code == 0, result.output
    # on a cold cache each kernel first says that it compiles, and that it does so once
    lines = [line for line in result.output.splitlines() if not line.startswith("bark: compiling the stepping kernel")]
    assert lines[0].startswith("bark: vertical: ready (") and lines[1].startswith("bark: diamond: ready (")
    assert "later runs load them" in lines[-1]
    assert list(tmp_path.iterdir()) == []


def test_bark_compile_checks_every_scene_before_it_compiles_one(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(cli, ["compile", "vertical", "no-such-scene"])
    assert result.exit_code == 2 and "ready" not in result.output
    assert result.stderr.startswith("bark: error: scene file 'no-such-scene' does not exist")


def test_json_with_quiet_prints_the_json_alone(tmp_path):
    """docs/running.md: --quiet leaves out the progress, the table and the notices; --json --quiet is the JSON
    alone, for a script that reads it."""
    result = CliRunner().invoke(cli, ["simulate", "--n-bases", "300", "--until-time", "1", "--out", str(tmp_path / "o"),
                                      "--json", "--quiet"])
    assert result.exit_code == 0 and result.stderr == "", result.output
    assert json.loads(result.stdout)["t"] == 1.0
