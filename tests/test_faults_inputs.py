"""Fault injection, inputs that could hang a command or be believed: FIFOs and devices where a file
is expected, foreign bytes named .npz, checkpoints that claim another lattice, extreme lattice
timings; and messages that must name what the user typed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from bark import Lattice
from bark.errors import BarkError
from bark_cli.main import cli

from conftest import REPO_ROOT, assert_clean_outcome

SMALL = ["--n-bases", "300", "-G", "0.05", "--until-time", "6", "--quiet"]


def _bark(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """In a process of its own, bounded: a command that waited on a FIFO would fail the test, not hang it."""
    return subprocess.run([sys.executable, "-m", "bark_cli", *args], cwd=cwd, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")])})


def _one_line(proc: subprocess.CompletedProcess, status: int = 2) -> str:
    assert proc.returncode == status, proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.splitlines()) == 1, proc.stderr
    assert proc.stderr.startswith("bark: error: "), proc.stderr
    return proc.stderr


@pytest.mark.parametrize("args, name", [
    (["analyze", "p.npz"], "p.npz"),
    (["analyze", "p.csv"], "p.csv"),
    (["analyze", "p.toml"], "p.toml"),
    (["simulate", "--scene", "p.toml", "--out", "out"], "p.toml"),
    (["simulate", "--resume", "run"], "checkpoint.npz"),
    (["compare", "p.npz", "p.csv"], "p.npz"),
])
def test_a_fifo_where_a_file_is_expected_is_one_line_at_once(args, name, tmp_path):
    (tmp_path / "run").mkdir()
    for fifo in ("p.npz", "p.csv", "p.toml", "run/checkpoint.npz"):
        os.mkfifo(tmp_path / fifo)
    err = _one_line(_bark(*args, cwd=tmp_path))
    assert name in err and "FIFO" in err, err


@pytest.mark.parametrize("content", [b"\x89PNG\r\n\x1a\n" + bytes(200), os.urandom(3000), b"", b"PK"])
def test_foreign_bytes_named_npz_are_refused_without_numpy_s_pickle_advice(content, tmp_path):
    (tmp_path / "state.npz").write_bytes(content)
    run = tmp_path / "run"
    run.mkdir()
    (run / "checkpoint.npz").write_bytes(content)
    for args in (["analyze", str(tmp_path / "state.npz"), "--out", str(tmp_path / "a")],
                 ["simulate", "--resume", str(run)]):
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 2, result.output
        assert_clean_outcome(result)
        assert "pickle" not in result.stderr and "allow_pickle" not in result.stderr, result.stderr


def test_a_device_where_a_pattern_is_expected_is_refused(tmp_path):
    _one_line(_bark("analyze", "/dev/zero", cwd=tmp_path))


@pytest.mark.parametrize("n_bases", [2_000_000, 200, 301])
def test_a_checkpoint_claiming_another_number_of_bases_is_refused(n_bases, tmp_path):
    import json

    from bark.io import checkpoint
    from bark.io.files import write_npz

    run = tmp_path / "run"
    result = CliRunner().invoke(cli, ["simulate", *SMALL, "--until-time", "6", "--out", str(run)])
    assert result.exit_code == 0, result.output
    path = run / checkpoint.CHECKPOINT_NAME
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays.pop("meta")))
    meta["scene"]["lattice"]["n_bases"] = n_bases
    meta["reason"] = "interrupted"
    path.unlink()
    write_npz(path, compress=False, meta=np.array(json.dumps(meta)), **arrays)
    again = CliRunner().invoke(cli, ["simulate", "--resume", str(run)])
    assert again.exit_code == 2, again.output
    assert "300 bases" in again.stderr and str(n_bases) in again.stderr, again.stderr


@pytest.mark.parametrize("join_every", [1e-12, 3.7e-9, 1e-6, 1.0, 1e12])
def test_joins_come_at_once_whatever_their_spacing(join_every):
    """The next join time is found in a few steps, not one per join_every (1e11 at 1e-12)."""
    lattice = Lattice(n_bases=3000, n_start=1500, join_rate=15.0, join_every=join_every)
    t = lattice.next_join(0.0, 1500)
    assert lattice.bases_at(t) > 1500
    assert lattice.bases_at(t - join_every) <= 1500 or t - join_every <= 0.0


def test_next_join_is_the_first_multiple_that_adds_a_base():
    lattice = Lattice(n_bases=100, n_start=10, join_rate=0.7, join_every=0.5)
    for present in range(10, 100):
        t = lattice.next_join(0.0, present)
        k = round(t / 0.5)
        assert lattice.bases_at(t) > present and lattice.bases_at((k - 1) * 0.5) <= present


@pytest.mark.parametrize("count", [17, 10_000])
def test_a_lattice_of_too_many_offsets_is_one_line(count, tmp_path):
    scene = tmp_path / "dense.toml"
    scene.write_text(f"[lattice]\noffsets = {list(range(1, count + 1))}\n")
    result = CliRunner().invoke(cli, ["simulate", "--scene", str(scene), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert_clean_outcome(result, tmp_path / "out")
    assert "at most 16" in result.stderr and len(result.stderr) < 300, result.stderr
    with pytest.raises(BarkError, match="at most 16"):
        Lattice(offsets=tuple(range(1, count + 1)))


@pytest.mark.parametrize("option, typed", [
    (["--scene", "x.toml"], "--scene"), (["--growth", "sqrt"], "--growth"), (["--breaker", "threshold"], "--breaker"),
    (["--set", "run.dt=0.1"], "--set"), (["-G", "0.02"], "-G"), (["--growth-rate", "0.02"], "-G"),
    (["--integrator", "euler-cromer"], "--integrator"), (["--dt", "0.1"], "--dt"), (["--n-bases", "5"], "--n-bases"),
])
def test_resume_names_the_option_as_it_is_typed(option, typed, tmp_path):
    result = CliRunner().invoke(cli, ["simulate", "--resume", str(tmp_path), *option])
    assert result.exit_code == 2
    assert_clean_outcome(result)
    assert f"{typed} cannot be given with it" in result.stderr, result.stderr


def test_a_csv_with_a_byte_order_mark_is_read(tmp_path):
    plain, marked = tmp_path / "plain.csv", tmp_path / "marked.csv"
    text = "x,y,patch\n" + "".join(f"{i},{(i * 7) % 5},{i // 4}\n" for i in range(24))
    plain.write_text(text, encoding="utf-8")
    marked.write_text(text, encoding="utf-8-sig")
    outs = []
    for path in (plain, marked):
        out = tmp_path / f"out-{path.stem}"
        result = CliRunner().invoke(cli, ["analyze", str(path), "--out", str(out), "--min-size", "2"])
        assert result.exit_code == 0, result.output
        outs.append((out / "patches.csv").read_text())
    assert outs[0] == outs[1]


@pytest.mark.parametrize("make, says", [
    (lambda p: (os.symlink(p.with_name("loop2"), p), os.symlink(p, p.with_name("loop2"))), "loops"),
    (lambda p: os.symlink("/nonexistent/bark-target", p), "does not exist"),
    (lambda p: (p.with_name("a-file").write_text("x"), os.symlink(p.with_name("a-file"), p)), "to a file, not a folder"),
    (lambda p: p.write_text("x"), "is a file, not a folder"),
])
def test_an_out_that_cannot_be_a_folder_says_what_it_is(make, says, tmp_path):
    out, published = tmp_path / "out", tmp_path / "published.toml"
    published.write_text("[pattern]\nn_patches = 10\nmean_orientation_deg = 90\nsd_orientation_deg = 20\n")
    make(out)
    for command in (["simulate", *SMALL, "--out", str(out)], ["analyze", str(published), "--out", str(out)]):
        result = CliRunner().invoke(cli, command)
        assert result.exit_code == 2, result.output
        assert_clean_outcome(result)
        assert says in result.stderr or "is a file" in result.stderr, result.stderr


# -- one run, one truth ------------------------------------------------------------------------


def test_one_patch_size_for_the_stop_the_pictures_and_the_statistics(tmp_path):
    import json

    out = tmp_path / "run"
    result = CliRunner().invoke(cli, ["simulate", "--n-bases", "800", "--until-time", "200", "--min-patch-size", "50",
                                      "--quiet", "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    with np.load(out / "state.npz") as state:
        labels = state["labels"]
    sizes = np.bincount(labels)
    assert summary["n_patches"] == int(np.count_nonzero(sizes >= 50)) < int(np.count_nonzero(sizes >= 7))
    assert summary["settings"]["analyzer"]["min_size"] == 50


def _refused(tmp_path: Path, text: str) -> tuple[Path, str]:
    """A scene of ``text`` run by ``bark simulate``: refused in one line, nothing written; the scene
    file and the line."""
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    result = CliRunner().invoke(cli, ["simulate", "--scene", str(scene), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert_clean_outcome(result, tmp_path / "out")
    return scene, result.stderr


def test_a_patch_size_given_twice_with_two_values_is_refused(tmp_path):
    scene, err = _refused(tmp_path, "[run]\nmin_patch_size = 9\n[analyzer]\nmin_size = 5\n")
    assert "min_patch_size" in err and "min_size" in err
    scene.write_text("[analyzer]\nmin_size = 20\n")  # one of them: it sets the other
    from bark.engine.scene import Scene, read_toml

    assert Scene.from_dict(read_toml(scene)).run.min_patch_size == 20


@pytest.mark.parametrize("sets, says", [
    (["--until-time", "5", "--set", "run.until_patches=abc"], "--set run.until_patches=abc"),
    (["--until-time", "5", "--set", "run.until_time=10"], "two values"),
    (["--until-patches", "5", "--set", "run.until_time=nan"], "--set run.until_time=nan"),
])
def test_stop_conditions_on_one_command_line_are_one_set(sets, says, tmp_path):
    result = CliRunner().invoke(cli, ["simulate", *sets, "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert_clean_outcome(result, tmp_path / "out")
    assert says in result.stderr, result.stderr


def test_a_set_stop_stays_beside_an_option_s(tmp_path):
    import json

    out = tmp_path / "run"
    result = CliRunner().invoke(cli, ["simulate", *SMALL, "--set", "run.until_patches=3", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert json.loads((out / "summary.json").read_text())["stop"]["until_patches"] == 3


def test_dome_points_with_an_ellipse_are_refused_not_ignored(tmp_path):
    _, err = _refused(tmp_path, "[dome]\nshape = 'ellipse'\npoints = [[1, 0], [0.5, 0.5], [0, 1]]\n")
    assert "shape = 'points'" in err


def test_an_unconverged_implicit_step_stops_the_run_at_the_last_good_state(tmp_path):
    out = tmp_path / "run"
    result = CliRunner().invoke(cli, ["simulate", *SMALL, "--integrator", "implicit-overdamped",
                                      "--set", "integrator.maxiter=1", "--out", str(out)])
    assert result.exit_code == 1
    assert_clean_outcome(result)
    assert "did not reach rtol" in result.stderr and "maxiter = 1" in result.stderr
    with np.load(out / "state.npz") as state:
        assert np.isfinite(state["x"]).all()


def test_a_bulge_that_meets_no_part_of_the_trunk_is_said(tmp_path):
    scene = tmp_path / "far.toml"
    scene.write_text("[growth]\nname = 'bulge'\nbulges = [{ z = 1e6, half_width = 0.3, magnitude = 0.02, decay = 0.005 }]\n")
    result = CliRunner().invoke(cli, ["simulate", "--scene", str(scene), "--n-bases", "300", "--until-time", "3",
                                      "--quiet", "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert_clean_outcome(result)
    said = [line for line in result.stderr.splitlines() if "changes nothing on this trunk" in line]
    assert len(said) == 1 and said[0].startswith("bark: warning: ") and "'bulges'" in said[0], result.stderr


def test_a_quoted_field_over_two_lines_keeps_the_line_numbers_right(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text('x,y,patch\n1,2,0\n"3\n",4,0\n5,abc,0\n')
    result = CliRunner().invoke(cli, ["analyze", str(path), "--out", str(tmp_path / "a")])
    assert result.exit_code == 2
    assert "line 5: y = 'abc'" in result.stderr, result.stderr
