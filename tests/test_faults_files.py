"""Fault injection, files: damaged checkpoints, odd and unusable output folders, two runs at once,
folders that hold another run, and temporary files left by a run killed in the middle of a write."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from bark.io import checkpoint
from bark.studies import runner
from bark.errors import BarkError
from bark.io.folder import OutputFolder
from bark.engine.scene import Scene
from bark_cli.main import cli

from conftest import REPO_ROOT, as_a_user_who_cannot_write, assert_clean_outcome

SMALL = ["--n-bases", "300", "-G", "0.05", "--until-time", "6", "--quiet"]


def _simulate(*args):
    return CliRunner().invoke(cli, ["simulate", *args])


@pytest.fixture(scope="module")
def interrupted_run(tmp_path_factory):
    """A folder holding a run stopped at t = 3 of 6 (as a signal stops it), and the uninterrupted run."""
    scene = Scene.from_dict({"lattice": {"n_bases": 300}, "growth": {"G": 0.05}, "run": {"until_time": 6.0}})
    whole = tmp_path_factory.mktemp("whole")
    runner.run(scene, whole)
    part = tmp_path_factory.mktemp("part")
    stop_at_3 = lambda: None  # noqa: E731
    sim_t = []
    runner.run(scene, part, observe=lambda sim, stop: sim_t.append(sim.state.t), checkpoint_every=1e-9,
               interrupted=lambda: "interrupted" if sim_t and sim_t[-1] >= 3.0 else stop_at_3())
    assert checkpoint.read_meta(part / checkpoint.CHECKPOINT_NAME)["reason"] == "interrupted"
    return whole, part


def _copy(src: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "run"
    shutil.copytree(src, dst)
    return dst


def _resume(folder: Path):
    return _simulate("--resume", str(folder), "--quiet")


def test_resume_of_the_intact_copy_is_bit_identical(interrupted_run, tmp_path):
    whole, part = interrupted_run
    folder = _copy(part, tmp_path)
    result = _resume(folder)
    assert result.exit_code == 0, result.output
    for name in ("breaks.csv", "state.npz"):
        assert (folder / name).read_bytes() == (whole / name).read_bytes(), name


# -- damaged checkpoints: one line, exit 2, never a traceback or "interrupted" -------------------


def _rewrite(path: Path, change) -> None:
    """Rewrite the checkpoint with ``change(arrays, meta)`` applied, checksums recomputed unless the
    change says otherwise (so that the consistency checks, not only the checksums, are exercised)."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays.pop("meta")))
    keep_sums = change(arrays, meta)
    if not keep_sums:
        meta["checksums"] = {k: checkpoint.digest(v) for k, v in arrays.items()}
    path.unlink()
    from bark.io.files import write_npz

    write_npz(path, compress=False, meta=np.array(json.dumps(meta)), **arrays)


def _truncate(p):
    p.write_bytes(p.read_bytes()[: len(p.read_bytes()) // 2])


def _zero(p):
    p.write_bytes(b"")


def _overwrite_bytes(p):
    data = bytearray(p.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 64] = bytes(64)
    p.write_bytes(bytes(data))


def _garbage(p):
    p.write_bytes(os.urandom(4096))


DAMAGE = {
    "truncated": _truncate,
    "zero bytes": _zero,
    "bytes overwritten": _overwrite_bytes,
    "not a zip file": _garbage,
    "member missing": lambda p: _rewrite(p, lambda a, m: (a.pop("v"), True)[1]),
    "member missing, checksums redone": lambda p: _rewrite(p, lambda a, m: a.pop("fmax") is None),
    "meta key missing": lambda p: _rewrite(p, lambda a, m: m.pop("clock") is None),
    "clock disagrees with time": lambda p: _rewrite(p, lambda a, m: m["clock"].__setitem__("ticks", m["clock"]["ticks"] + 1)),
    "rest lengths not finite": lambda p: _rewrite(p, lambda a, m: a["rest"].__setitem__(0, np.inf)),
    "a spring to a base that is not there": lambda p: _rewrite(p, lambda a, m: a["pairs"].__setitem__((0, 1), 10**6)),
    "meta not json": lambda p: _rewrite_meta_text(p, "{not json"),
    "wrong dtype": lambda p: _rewrite(p, lambda a, m: a.__setitem__("x", a["x"].astype(np.float32))),
    "wrong shape": lambda p: _rewrite(p, lambda a, m: a.__setitem__("v", a["v"][:-1])),
    "break log columns disagree": lambda p: _rewrite(p, lambda a, m: a.__setitem__("breaks_t", a["breaks_t"][:-5])),
    "break log disagrees with intact": lambda p: _rewrite(p, lambda a, m: a.__setitem__("intact", np.ones_like(a["intact"]))),
    "invalid rng state": lambda p: _rewrite(p, lambda a, m: m.__setitem__("rng", {"bit_generator": "PCG64", "state": 3})),
    "rng of another kind": lambda p: _rewrite(p, lambda a, m: m["rng"].__setitem__("bit_generator", "MT19937")),
    "non-finite positions": lambda p: _rewrite(p, lambda a, m: a["x"].__setitem__((0, 0), np.nan)),
    "infinite velocity": lambda p: _rewrite(p, lambda a, m: a["v"].__setitem__((3, 2), np.inf)),
    "checksum wrong": lambda p: _rewrite(p, lambda a, m: (m["checksums"].__setitem__("x", "0" * 32), True)[1]),
    "other format": lambda p: _rewrite(p, lambda a, m: m.__setitem__("format", 99)),
    "other bark version": lambda p: _rewrite(p, lambda a, m: m.__setitem__("bark_version", "0.0.1")),
    "negative step count": lambda p: _rewrite(p, lambda a, m: m.__setitem__("step_count", -4)),
    "time not a number": lambda p: _rewrite(p, lambda a, m: m.__setitem__("t", "soon")),
    "scene invalid": lambda p: _rewrite(p, lambda a, m: m["scene"]["mechanics"].__setitem__("k", -1)),
    "springs of another scene": lambda p: _rewrite(p, lambda a, m: m["scene"]["lattice"].__setitem__("offsets", [13, 21])),
    "claims 2,000,000 bases": lambda p: _rewrite(p, lambda a, m: m["scene"]["lattice"].__setitem__("n_bases", 2_000_000)),
    "claims fewer bases": lambda p: _rewrite(p, lambda a, m: m["scene"]["lattice"].__setitem__("n_bases", 200)),
    "unknown reason": lambda p: _rewrite(p, lambda a, m: m.__setitem__("reason", "holiday")),
    "a directory": lambda p: (p.unlink(), p.mkdir()),
}


def _rewrite_meta_text(path: Path, text: str) -> None:
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["meta"] = np.array(text)
    path.unlink()
    from bark.io.files import write_npz

    write_npz(path, compress=False, **arrays)


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_a_damaged_checkpoint_with_no_previous_one_is_one_line_and_exit_2(interrupted_run, tmp_path, damage):
    _, part = interrupted_run
    folder = _copy(part, tmp_path)
    (folder / checkpoint.PREVIOUS_NAME).unlink(missing_ok=True)
    DAMAGE[damage](folder / checkpoint.CHECKPOINT_NAME)
    before = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    result = _resume(folder)
    assert result.exit_code == 2, (result.exit_code, result.output)
    assert_clean_outcome(result)
    assert "checkpoint" in result.stderr
    assert {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()} == before  # nothing written


@pytest.mark.parametrize("damage", ["truncated", "bytes overwritten", "break log columns disagree", "non-finite positions"])
def test_a_damaged_newest_checkpoint_falls_back_to_the_previous_one(interrupted_run, tmp_path, damage):
    whole, part = interrupted_run
    folder = _copy(part, tmp_path)
    assert (folder / checkpoint.PREVIOUS_NAME).exists()  # kept when the newest was written
    DAMAGE[damage](folder / checkpoint.CHECKPOINT_NAME)
    result = _resume(folder)
    assert result.exit_code == 0, result.output
    assert "previous checkpoint" in result.stderr
    for name in ("breaks.csv", "state.npz"):  # the previous one is an earlier state of the same run
        assert (folder / name).read_bytes() == (whole / name).read_bytes(), name


def test_a_missing_newest_checkpoint_falls_back_to_the_previous_one(interrupted_run, tmp_path):
    whole, part = interrupted_run
    folder = _copy(part, tmp_path)
    (folder / checkpoint.CHECKPOINT_NAME).unlink()  # as a crash between the two renames leaves it
    result = _resume(folder)
    assert result.exit_code == 0 and "previous checkpoint" in result.stderr, result.output
    assert (folder / "breaks.csv").read_bytes() == (whole / "breaks.csv").read_bytes()


def test_a_checkpoint_is_verified_before_it_replaces_the_last_one(interrupted_run, tmp_path, monkeypatch):
    """A checkpoint whose written bytes do not read back is refused, and the last good one stays."""
    _, part = interrupted_run
    folder = _copy(part, tmp_path)
    good = (folder / checkpoint.CHECKPOINT_NAME).read_bytes()
    scene, sim, stop, *_ = checkpoint.load(folder)
    real_read = checkpoint.read

    def corrupt_then_read(path):
        _overwrite_bytes(Path(path))
        return real_read(path)

    monkeypatch.setattr(checkpoint, "read", corrupt_then_read)
    with pytest.raises(BarkError):
        checkpoint.save(folder, sim, scene, stop, "periodic")
    assert (folder / checkpoint.CHECKPOINT_NAME).read_bytes() == good
    assert not [p.name for p in folder.iterdir() if p.name.endswith(".tmp")]


def test_break_log_can_never_be_cut_silently(interrupted_run, tmp_path):
    """A checkpoint whose break-log columns disagree is refused, not resumed into a short breaks.csv."""
    _, part = interrupted_run
    folder = _copy(part, tmp_path)
    for name in (checkpoint.CHECKPOINT_NAME, checkpoint.PREVIOUS_NAME):
        DAMAGE["break log columns disagree"](folder / name)
    result = _resume(folder)
    assert result.exit_code == 2 and "break log" in result.stderr


# -- output folders -------------------------------------------------------------------------------


def test_a_file_as_parent_a_long_name_proc_and_sys_are_one_line(tmp_path):
    parent = tmp_path / "file"
    parent.write_text("keep")
    for out in (parent / "sub", tmp_path / ("x" * 300), Path("/proc/bark-out"), Path("/sys/bark-out"),
                tmp_path / "a" / ("y" * 256) / "b"):
        result = _simulate(*SMALL, "--out", str(out))
        assert result.exit_code == 2, (out, result.output)
        assert_clean_outcome(result)
        assert "--out" in result.stderr
    assert parent.read_text() == "keep"
    assert not (tmp_path / "a").exists()  # folders made for a refused run are removed again


def test_an_unwritable_folder_is_refused_before_the_run():
    """As a user who cannot write there: root writes into read-only folders, so as root the command
    runs as ``nobody`` (``conftest.as_a_user_who_cannot_write``)."""
    prefix = as_a_user_who_cannot_write()
    work = Path(tempfile.mkdtemp(prefix="bark-readonly-"))  # pytest's own folders are root's alone
    folder = work / "ro"
    folder.mkdir()
    work.chmod(0o777)
    folder.chmod(0o555)
    try:
        for out, says in ((folder / "out", "--out"), (folder, "cannot write")):
            proc = subprocess.run([*prefix, sys.executable, "-m", "bark_cli", "simulate", *SMALL, "--out", str(out)],
                                  cwd=REPO_ROOT, capture_output=True, text=True, timeout=600,
                                  env={**{k: v for k, v in os.environ.items() if not k.startswith("XDG_")},
                                       "HOME": str(work)})  # a home of its own: only the folder is refused
            assert proc.returncode == 2 and says in proc.stderr, proc.stderr
            assert len(proc.stderr.splitlines()) == 1 and proc.stderr.startswith("bark: error: "), proc.stderr
        assert not any(folder.iterdir())
    finally:
        folder.chmod(0o755)
        shutil.rmtree(work, ignore_errors=True)


def test_empty_out_is_the_current_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = _simulate(*SMALL, "--out", "")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "summary.json").is_file()


@pytest.mark.slow  # seconds of whole processes: the quick subset (-m "not slow") leaves it out
@settings(max_examples=25, deadline=None)
@given(name=st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="/\0"), min_size=1, max_size=300))
def test_any_folder_name(tmp_path_factory, name):
    """Any name a user might type (spaces, unicode, emoji, dots, dashes, very long): the run is written
    there, or refused in one line before anything runs."""
    base = tmp_path_factory.mktemp("names")
    if name in (".", ".."):
        return
    result = _simulate("--n-bases", "200", "--until-time", "0.6", "--quiet", "--checkpoint-every", "0",
                       "--out", str(base / name))
    assert_clean_outcome(result)
    if result.exit_code == 0:
        assert (base / name / "summary.json").is_file()
    else:  # nothing made (asked by listing: stat() itself refuses a name over the system's limit)
        assert list(base.iterdir()) == []


def test_the_resume_hint_is_shell_quoted(tmp_path):
    out = tmp_path / "ü 🌳 $(x)"
    scene = Scene.from_dict({"lattice": {"n_bases": 300}, "growth": {"G": 0.05}, "run": {"until_time": 6.0}})
    runner.run(scene, out, interrupted=lambda: "interrupted")
    meta = checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)
    assert meta["reason"] == "interrupted"
    from bark_cli.main import _report

    import shlex

    outcome = runner.Outcome(out=out, scene=scene, sim=checkpoint.load(out)[1], stop_reason="interrupted",
                             summary=json.loads((out / "summary.json").read_text()))
    with CliRunner().isolation() as (_, err, *_rest):
        _report(outcome, quiet=True)
    hint = err.getvalue().decode().split("go on with: ")[1].strip()
    assert shlex.split(hint) == ["bark", "simulate", "--resume", str(out)]


def test_two_runs_into_one_folder_at_once(tmp_path):
    out = tmp_path / "out"
    with OutputFolder.open(out, fresh=True):  # another run holds it
        result = _simulate(*SMALL, "--out", str(out))
        held = f"(process {os.getpid()}) is writing there"
        assert result.exit_code == 2 and held in result.stderr, result.stderr
        result = _simulate("--resume", str(out))
        assert result.exit_code == 2 and held in result.stderr, result.stderr
    assert _simulate(*SMALL, "--out", str(out)).exit_code == 0  # released


def test_a_fresh_run_never_mixes_with_an_unfinished_one(interrupted_run, tmp_path):
    _, part = interrupted_run
    folder = _copy(part, tmp_path)
    (folder / "notes.txt").write_text("mine")
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    result = _simulate(*SMALL, "--out", str(folder))
    assert result.exit_code == 2 and "unfinished run" in result.stderr and "--overwrite" in result.stderr
    assert "--resume" in result.stderr
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    result = _simulate(*SMALL, "--n-bases", "250", "--out", str(folder), "--overwrite")
    assert result.exit_code == 0, result.output
    assert (folder / "notes.txt").read_text() == "mine"  # not bark's: left alone
    assert not (folder / checkpoint.PREVIOUS_NAME).exists()  # the old run's files are all gone
    assert checkpoint.load(folder)[1].state.n_bases == 250
    assert json.loads((folder / "summary.json").read_text())["n_bases"] == 250


def test_a_fresh_run_replaces_a_finished_run_whole(tmp_path):
    out = tmp_path / "out"
    scene = tmp_path / "s.toml"
    scene.write_text("[effects]\nwant = ['fracture', 'graphml', 'checkpoints']\n")
    assert _simulate(*SMALL, "--scene", str(scene), "--out", str(out)).exit_code == 0
    assert (out / "graph.graphml").exists()
    result = _simulate(*SMALL, "--out", str(out))
    assert result.exit_code == 0, result.output
    assert not (out / "graph.graphml").exists()  # nothing of the earlier run is left beside the new one


def test_stale_temporaries_are_removed_by_the_next_run(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    stale = [out / ".checkpoint.npz.abc123.tmp", out / ".summary.json.x.tmp", out / ".bark-probe.q.tmp"]
    for p in stale:
        p.write_bytes(b"half a file")
    (out / ".my-own.tmp").write_text("not bark's")
    assert _simulate(*SMALL, "--out", str(out)).exit_code == 0
    assert not any(p.exists() for p in stale)
    assert (out / ".my-own.tmp").exists()
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp") and p.name != ".my-own.tmp"]


def test_a_run_killed_during_its_final_writes_is_finished_by_resume(interrupted_run, tmp_path, monkeypatch):
    """Killed after the end checkpoint, before the summary: the folder has no summary to disagree with
    the checkpoint, and --resume writes the outputs the uninterrupted run has."""
    whole, _ = interrupted_run
    scene = Scene.from_dict({"lattice": {"n_bases": 300}, "growth": {"G": 0.05}, "run": {"until_time": 6.0}})
    out = tmp_path / "out"

    class Killed(BaseException):
        pass

    def die(*args, **kwargs):
        raise Killed

    monkeypatch.setattr(runner, "write_run", die)
    with pytest.raises(Killed):
        runner.run(scene, out)
    monkeypatch.undo()
    assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "end"
    assert not (out / "summary.json").exists()
    result = _resume(out)
    assert result.exit_code == 0, result.output
    for name in ("breaks.csv", "state.npz"):
        assert (out / name).read_bytes() == (whole / name).read_bytes()
    assert _resume(out).exit_code == 2  # now complete: nothing to resume


def test_summary_json_is_written_last_and_resume_draws_what_a_kill_left_undrawn(tmp_path):
    """Killed while a picture is drawn (after the checkpoint and the data): no summary.json, so the
    folder does not claim a whole run, and ``--resume`` draws the picture and then writes it."""
    scene = Scene.from_dict({"lattice": {"n_bases": 300}, "growth": {"G": 0.05}, "run": {"until_time": 6.0}})
    out = tmp_path / "out"

    class Killed(BaseException):
        pass

    def killed_while_drawing(sim, scene, recorded, path):
        def wait():
            raise Killed
        return wait

    def draw(sim, scene, recorded, path):
        path.write_text(f"drawn at t = {sim.state.t}")

    with pytest.raises(Killed):
        runner.run(scene, out, pictures={"pattern-image": ("pattern.png", killed_while_drawing)})
    assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "end"
    assert {"breaks.csv", "state.npz"} <= {p.name for p in out.iterdir()}
    assert not (out / "summary.json").exists() and not (out / "pattern.png").exists()
    outcome = runner.resume(out, pictures={"pattern-image": ("pattern.png", draw)})
    assert not outcome.failed
    assert (out / "pattern.png").read_text() == "drawn at t = 6.0"
    assert json.loads((out / "summary.json").read_text())["t"] == 6.0
    with pytest.raises(BarkError, match="has ended"):
        runner.resume(out, pictures={"pattern-image": ("pattern.png", draw)})


def test_a_picture_that_fails_costs_no_data(tmp_path, monkeypatch):
    import bark_cli.plot

    def broken(*args, **kwargs):
        raise ValueError("Image size of 1050x111634573 pixels is too large")

    monkeypatch.setattr(bark_cli.plot, "plot_pattern", broken)
    out = tmp_path / "out"
    result = _simulate(*SMALL, "--out", str(out))
    assert result.exit_code == 1
    assert_clean_outcome(result)
    assert "pattern.png" in result.stderr and "could not be drawn" in result.stderr
    assert {"summary.json", "breaks.csv", "state.npz", "checkpoint.npz", "patches.csv"} <= {p.name for p in out.iterdir()}
    assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "end"


@pytest.mark.parametrize("args", [["--jitter", "1e6"], ["--rise", "1e6"], ["--rise", "1e-12"], ["--n-bases", "60000"]])
def test_the_picture_stays_bounded(tmp_path, args):
    from PIL import Image

    out = tmp_path / "out"
    result = _simulate("--until-time", "0.6", "--quiet", "--checkpoint-every", "0", *args, "--out", str(out))
    assert result.exit_code == 0, result.output
    with Image.open(out / "pattern.png") as image:
        width, height = image.size
    assert width <= 1100 and height <= 2200, (width, height)


def test_zip_members_of_a_checkpoint_are_stored_not_compressed(interrupted_run):
    """Checkpoints are written often: stored, so writing one costs a copy, not a compression."""
    _, part = interrupted_run
    with zipfile.ZipFile(part / checkpoint.CHECKPOINT_NAME) as zf:
        assert {i.compress_type for i in zf.infolist()} == {zipfile.ZIP_STORED}
