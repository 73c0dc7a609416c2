"""Fault injection, file systems that refuse to write: a file-size limit (``ulimit -f``), a full disk
(ENOSPC, injected), ``/dev/full`` and closed standard streams.  Each refused output is one line and
exit status 1; every other output, and the last good checkpoint, is kept; nothing half-written or
stale is left; a run's state is never lost to a full standard output.  Also: every command's folder
holds only that call's files."""

from __future__ import annotations

import errno
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from bark.io import checkpoint, files
from bark.io.folder import RUN_FILES, run_files
from bark_cli.main import cli

from conftest import REPO_ROOT, assert_clean_outcome, slow_cases

SMALL = ["--n-bases", "300", "-G", "0.05", "--until-time", "6"]
PATTERNED = ["--n-bases", "800", "--until-time", "200"]
"""A run that ends with patches (19): analyze and compare then draw their pictures."""


@pytest.fixture(scope="module")
def patterned(tmp_path_factory):
    runs = []
    for seed in range(4):
        run = tmp_path_factory.mktemp(f"patterned{seed}")
        result = CliRunner().invoke(cli, ["simulate", *PATTERNED, "--seed", str(seed), "--quiet", "--out", str(run)])
        assert result.exit_code == 0, result.output
        runs.append(run)
    return runs


def _bark(*args: str, limit: int | None = None, stdout=subprocess.PIPE, stderr=subprocess.PIPE):
    """``bark ARGS`` in a process of its own, its files limited to ``limit`` bytes (``ulimit -f``)."""
    def cap():
        if limit is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run([sys.executable, "-m", "bark_cli", *args], cwd=REPO_ROOT, preexec_fn=cap, stdout=stdout,
                          stderr=stderr, text=True, timeout=600)


def _lines(text: str | None) -> list[str]:
    lines = (text or "").splitlines()
    assert "Traceback" not in (text or ""), text
    assert all(line.startswith("bark: ") for line in lines), text
    return lines


def _no_temporaries(folder: Path) -> None:
    assert not [p.name for p in folder.iterdir() if p.name.endswith(files.TMP_SUFFIX)]


@pytest.mark.parametrize("limit", [30_000, *slow_cases(2_000, 120_000)])
def test_a_file_size_limit_costs_only_the_files_it_refuses(limit, tmp_path):
    out = tmp_path / "run"
    proc = _bark("simulate", *SMALL, "--quiet", "--out", str(out), limit=limit)
    lines = _lines(proc.stderr)
    if "the run's start record could not be written" in proc.stderr:  # below a few kB: refused before it began
        assert proc.returncode == 2 and len(lines) == 1 and "nothing was run" in lines[0], proc.stderr
        assert not run_files(out)
        return
    refused = sorted({line.split(": ")[2] for line in lines if "could not be written" in line})
    assert proc.returncode == (1 if refused else 0), proc.stderr
    present = {p.name for p in out.iterdir()}
    assert not (set(refused) - {"checkpoint.npz"}) & present  # a refused file is not there half-written ...
    assert present <= set(RUN_FILES)   # ... and what is there is the run's
    if "checkpoint.npz" in refused:    # the last good checkpoint stays: here the start record
        assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "start"
    assert all((out / name).stat().st_size <= limit for name in present)
    if refused:
        assert "summary.json" not in present  # the folder does not claim a complete run
    _no_temporaries(out)


def test_a_refused_output_is_written_by_resume_once_there_is_room(tmp_path, monkeypatch):
    """The end checkpoint fits, state.npz does not: exit 1, and ``--resume`` writes it (the bits of
    an uninterrupted run) once the file system takes it."""
    whole, out = tmp_path / "whole", tmp_path / "out"
    assert CliRunner().invoke(cli, ["simulate", *SMALL, "--quiet", "--out", str(whole)]).exit_code == 0
    real = files.write_npz

    def full(path, **kwargs):
        if Path(path).name == "state.npz":
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(path, **kwargs)

    monkeypatch.setattr("bark.io.output.write_npz", full)
    result = CliRunner().invoke(cli, ["simulate", *SMALL, "--quiet", "--out", str(out)])
    assert result.exit_code == 1
    assert_clean_outcome(result)
    assert "state.npz: could not be written (No space left on device)" in result.stderr
    assert "--resume" in result.stderr
    assert not (out / "state.npz").exists() and not (out / "summary.json").exists()
    monkeypatch.undo()
    again = CliRunner().invoke(cli, ["simulate", "--resume", str(out), "--quiet"])
    assert again.exit_code == 0, again.output
    for name in ("state.npz", "breaks.csv", "patches.csv"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name


def test_a_refused_periodic_checkpoint_is_said_once_and_the_run_goes_on(tmp_path, monkeypatch):
    out = tmp_path / "out"
    real = checkpoint.save
    tries = []

    def full(folder, sim, scene, stop, reason, *args, **kwargs):
        if reason == "periodic":
            tries.append(sim.state.t)
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(folder, sim, scene, stop, reason, *args, **kwargs)

    monkeypatch.setattr(checkpoint, "save", full)
    result = CliRunner().invoke(cli, ["simulate", *SMALL, "--quiet", "--checkpoint-every", "0.000001", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert_clean_outcome(result)
    warned = [line for line in result.stderr.splitlines() if "checkpoint.npz: could not be written" in line]
    assert len(tries) > 1 and len(warned) == 1, (tries, result.stderr)
    assert "the run goes on" in warned[0]
    assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "end"
    assert (out / "summary.json").exists()


def test_a_refused_end_checkpoint_keeps_the_last_good_one(tmp_path, monkeypatch):
    out = tmp_path / "out"
    real = checkpoint.save

    def full_at_the_end(folder, sim, scene, stop, reason, *args, **kwargs):
        if reason == "end":
            raise OSError(errno.EFBIG, "File too large")
        return real(folder, sim, scene, stop, reason, *args, **kwargs)

    monkeypatch.setattr(checkpoint, "save", full_at_the_end)
    result = CliRunner().invoke(cli, ["simulate", *SMALL, "--quiet", "--checkpoint-every", "0.000001", "--out", str(out)])
    assert result.exit_code == 1
    assert_clean_outcome(result)
    assert "checkpoint.npz: could not be written (File too large)" in result.stderr
    assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "periodic"
    assert {"state.npz", "breaks.csv"} <= {p.name for p in out.iterdir()}
    assert not (out / "summary.json").exists()  # it would describe a state no checkpoint holds
    monkeypatch.undo()
    again = CliRunner().invoke(cli, ["simulate", "--resume", str(out), "--quiet"])
    assert again.exit_code == 0, again.output
    assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "end"
    assert (out / "summary.json").exists()


@pytest.mark.parametrize("command", ["simulate", "analyze", "compare", "strategies", *slow_cases("sweep")])
def test_a_full_standard_output_costs_nothing_of_the_run(command, tmp_path):
    """The output a command prints is one of its outputs: refused, it is one line and status 1;
    the files are written all the same."""
    out, run = tmp_path / "out", tmp_path / "run"
    if command in ("analyze", "compare"):
        assert CliRunner().invoke(cli, ["simulate", *SMALL, "--quiet", "--out", str(run)]).exit_code == 0
    args = {"simulate": ["simulate", *SMALL, "--out", str(out)], "analyze": ["analyze", str(run), "--out", str(out)],
            "compare": ["compare", str(run), str(run), "--out", str(out)],
            "sweep": ["sweep", "--grid", "growth.G=0.05", "--set", "lattice.n_bases=300", "--set", "run.until_time=6",
                      "--out", str(out)], "strategies": ["strategies"]}[command]
    with open("/dev/full", "w") as full:
        proc = _bark(*args, stdout=full)
    lines = _lines(proc.stderr)
    assert proc.returncode == 1, proc.stderr
    assert [line for line in lines if "could not be written" in line] == [
        "bark: warning: the command's output could not be written (No space left on device); its files are written "
        "all the same"], proc.stderr
    if command != "strategies":
        assert any(out.iterdir())
    if command == "simulate":
        assert json.loads((out / "summary.json").read_text())["steps"] > 0


@pytest.mark.parametrize("closed", ["1>&- 2>&-", *slow_cases("1>&-", "2>&-")])
def test_closed_standard_streams_cost_nothing_of_the_run(closed, tmp_path):
    out = tmp_path / "run"
    command = f"{sys.executable} -m bark_cli simulate {' '.join(SMALL)} --out {out} {closed}"
    proc = subprocess.run(["bash", "-c", command], cwd=REPO_ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert (out / "summary.json").exists() and (out / "state.npz").exists()


@pytest.mark.parametrize("limit", [1_000, 20_000])
def test_analyze_says_each_refused_file_and_leaves_none_half_written(limit, patterned, tmp_path):
    out = tmp_path / "analysis"
    proc = _bark("analyze", str(patterned[0]), "--out", str(out), limit=limit)
    refused = [line for line in _lines(proc.stderr) if "could not be written" in line]
    assert proc.returncode == (1 if refused else 0) and refused, proc.stderr
    names = {line.split(": ")[2] for line in refused}
    assert not names & {p.name for p in out.iterdir()}
    _no_temporaries(out)


def test_a_fresh_run_leaves_nothing_of_an_earlier_one(tmp_path):
    """Every file an effect writes is one a fresh run removes (``Effect.files``): the fracture
    history's too."""
    out = tmp_path / "out"
    scene = tmp_path / "history.toml"
    scene.write_text("[effects]\nwant = ['fracture-history', 'checkpoints']\nhistory_every = 1.0\n")
    first = CliRunner().invoke(cli, ["simulate", *SMALL, "--quiet", "--scene", str(scene), "--out", str(out)])
    assert first.exit_code == 0, first.output
    assert (out / "fracture.csv").exists()
    again = CliRunner().invoke(cli, ["simulate", *SMALL, "--quiet", "--overwrite", "--out", str(out)])
    assert again.exit_code == 0, again.output
    assert not (out / "fracture.csv").exists() and not (out / "fracture.png").exists()


def test_every_file_a_run_writes_is_one_a_fresh_run_removes(tmp_path):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["simulate", "--scene", str(REPO_ROOT / "bark/scenes/everything.toml"),
                                      "--n-bases", "300", "--until-time", "12", "--quiet", "--out", str(out)])
    assert result.exit_code == 0, result.output
    written = {p for p in out.rglob("*") if p.is_file()}
    assert written == set(run_files(out))  # every file, in the folders a run writes into too
    assert {"fracture.csv", "tree.vtu", "development.gif", "graph.graphml", "tree.pvd", "history.nc"} <= \
        {p.name for p in written} and any(p.parent.name == "history" for p in written)


def test_analyze_leaves_no_picture_of_an_earlier_pattern(patterned, tmp_path):
    toml, out = tmp_path / "published.toml", tmp_path / "analysis"
    assert CliRunner().invoke(cli, ["analyze", str(patterned[0]), "--out", str(out)]).exit_code == 0
    assert (out / "radial.png").exists()
    toml.write_text("[pattern]\nn_patches = 10\nmean_orientation_deg = 90\nsd_orientation_deg = 20\n")
    result = CliRunner().invoke(cli, ["analyze", str(toml), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert {p.name for p in out.iterdir()} == {"statistics.json"}


def test_compare_of_two_after_four_leaves_no_quartet_diagram(patterned, tmp_path):
    runs = [str(run) for run in patterned]
    out = tmp_path / "compare"
    assert CliRunner().invoke(cli, ["compare", *runs, "--out", str(out)]).exit_code == 0
    assert (out / "quartets.png").exists()
    assert CliRunner().invoke(cli, ["compare", *runs[:2], "--out", str(out)]).exit_code == 0
    assert {p.name for p in out.iterdir()} == {"comparison.json"}


def test_a_full_disk_under_a_sweep_keeps_what_was_committed(tmp_path, monkeypatch):
    """SQLite itself says the disk is full (its page limit, set after the first row): one line, exit
    1, the committed row kept, and the same command goes on to the end once there is room."""
    from bark.studies import sweep

    out = tmp_path / "sweep"
    args = ["sweep", "--grid", "growth.G=0.04,0.05,0.06", "--set", "lattice.n_bases=300", "--set", "run.until_time=6",
            "--quiet", "--out", str(out)]
    real = sweep.SweepTable._insert

    def full_after_one(self, *a):
        real(self, *a)
        pages = self.con.execute("PRAGMA page_count").fetchone()[0]
        self.con.execute(f"PRAGMA max_page_count = {pages}")  # no room for another row's pattern

    monkeypatch.setattr(sweep.SweepTable, "_insert", full_after_one)
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1, result.output
    assert_clean_outcome(result)
    assert "could not be written (database or disk is full)" in result.stderr
    monkeypatch.undo()
    with sweep.SweepTable(out / "sweep.sqlite") as table:
        assert len(table.done()) == 1
    again = CliRunner().invoke(cli, args)
    assert again.exit_code == 0, again.output
    with sweep.SweepTable(out / "sweep.sqlite") as table:
        assert len(table.done()) == 3


@pytest.fixture
def small_disk(tmp_path):
    """A file system of 400 kB (tmpfs), mounted for the test where this process may mount one (root
    with the right to): a real full disk, ENOSPC from the kernel; skipped elsewhere."""
    import shutil

    where = tmp_path / "disk"
    where.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a small file system needs root")
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=400k", "tmpfs", str(where)], capture_output=True)
    if made.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {made.stderr.decode().strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", str(where)], check=True)


def test_a_full_disk_costs_only_the_files_it_refuses_and_resume_writes_them(small_disk, tmp_path):
    """The default scene on 400 kB: its end checkpoint alone is over 500 kB, so only the start
    record is there; with room made, ``--resume`` runs it again to the bits of a run with room."""
    out, whole = small_disk / "run", tmp_path / "whole"
    proc = _bark("simulate", "--quiet", "--out", str(out))
    lines = _lines(proc.stderr)
    refused = {line.split(": ")[2] for line in lines if "could not be written (No space left on device)" in line}
    assert proc.returncode == 1 and "checkpoint.npz" in refused, proc.stderr
    present = {p.name for p in out.iterdir()}
    assert not refused - {"checkpoint.npz"} & present and present <= set(RUN_FILES) and "summary.json" not in present
    assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "start"
    assert f"bark simulate --resume {out}" in proc.stderr
    _no_temporaries(out)
    subprocess.run(["mount", "-o", "remount,size=64m", str(small_disk)], check=True)  # room made
    again = _bark("simulate", "--resume", str(out), "--quiet")
    assert again.returncode == 0, again.stderr
    assert _bark("simulate", "--quiet", "--out", str(whole)).returncode == 0
    assert {p.name for p in whole.iterdir()} <= {p.name for p in out.iterdir()}
    for name in ("breaks.csv", "state.npz", "patches.csv", "scene.toml"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name


@pytest.mark.parametrize("limit", [15_000, *slow_cases(9_000)])
def test_a_run_whose_state_never_fits_is_resumed_from_its_start(limit, tmp_path):
    """Under ``ulimit -f`` below every checkpoint of the state, the start record (the scene: a few
    kB) is written before the first step, so once the limit is gone ``--resume`` runs again from
    t = 0 and ends as a run never refused; a fresh run into the folder is refused meanwhile."""
    out, whole = tmp_path / "out", tmp_path / "whole"
    proc = _bark("simulate", *SMALL, "--quiet", "--out", str(out), limit=limit)
    _lines(proc.stderr)
    assert proc.returncode == 1 and "checkpoint.npz: could not be written (File too large)" in proc.stderr, proc.stderr
    assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "start"
    fresh = _bark("simulate", *SMALL, "--quiet", "--out", str(out))
    assert fresh.returncode == 2 and "holds an unfinished run (stopped at its start" in fresh.stderr, fresh.stderr
    again = _bark("simulate", "--resume", str(out), "--quiet")
    assert again.returncode == 0, again.stderr
    assert "runs again from its start" in again.stderr
    assert _bark("simulate", *SMALL, "--quiet", "--out", str(whole)).returncode == 0
    for name in ("breaks.csv", "state.npz", "patches.csv", "scene.toml"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    assert json.loads((out / "summary.json").read_text())["steps"] == json.loads((whole / "summary.json").read_text())["steps"]


@pytest.mark.slow  # a run, stopped and resumed: seconds: the quick subset (-m "not slow") leaves it out
def test_a_resume_onto_a_size_limit_leaves_no_output_of_the_earlier_state(tmp_path):
    """Stopped at t = 3 of 6, then resumed under ``ulimit -f``: the outputs refused are gone (not
    the stopped state's left beside the end's), the last checkpoint is kept, and a resume with room
    ends as the run that was never stopped."""
    from bark.engine.scene import Scene
    from bark.studies import runner

    scene = Scene.from_dict({"lattice": {"n_bases": 300}, "growth": {"G": 0.05}, "run": {"until_time": 6.0}})
    whole, out, seen = tmp_path / "whole", tmp_path / "out", []
    runner.run(scene, whole)
    runner.run(scene, out, observe=lambda sim, stop: seen.append(sim.state.t), checkpoint_every=1e-9,
               interrupted=lambda: "interrupted" if seen and seen[-1] >= 3.0 else None)
    proc = _bark("simulate", "--resume", str(out), "--quiet", limit=20_000)
    refused = {line.split(": ")[2] for line in _lines(proc.stderr) if "could not be written" in line}
    assert proc.returncode == 1 and "state.npz" in refused, proc.stderr
    assert not refused - {"checkpoint.npz"} & {p.name for p in out.iterdir()}
    assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] in ("interrupted", "end")
    again = _bark("simulate", "--resume", str(out), "--quiet")
    assert again.returncode == 0, again.stderr
    for name in ("breaks.csv", "state.npz", "patches.csv"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name


@pytest.fixture
def held(tmp_path):
    """A folder held by another process as a bark command holds its --out (the lock its writes take)."""
    folder = tmp_path / "held"
    code = ("import sys\nfrom bark.io.folder import held_folder\nh = held_folder(sys.argv[1])\n"
            "print('held', flush=True)\nsys.stdin.read()\n")
    proc = subprocess.Popen([sys.executable, "-c", code, str(folder)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline().strip() == "held"
    yield folder, proc.pid
    proc.stdin.close()
    proc.wait(timeout=60)
    proc.stdout.close()


@pytest.mark.parametrize("command", ["analyze", "compare"])
def test_a_folder_another_command_writes_is_refused_naming_it(command, patterned, held):
    """Two analyses into one --out both said they wrote; now the second is refused in one line
    that names the process holding the folder, and writes nothing."""
    folder, pid = held
    patterns = [str(patterned[0])] if command == "analyze" else [str(p) for p in patterned[:2]]
    result = CliRunner().invoke(cli, [command, *patterns, "--out", str(folder)])
    assert result.exit_code == 2, result.output
    assert_clean_outcome(result)
    assert f"--out {folder}: {Path(sys.executable).name} -c import sys" in result.stderr, result.stderr
    assert f"(process {pid}) is writing there" in result.stderr
    assert list(folder.iterdir()) == []


def test_an_analysis_into_a_runs_folder_is_refused_and_the_run_kept(patterned, tmp_path):
    run = tmp_path / "run"
    assert CliRunner().invoke(cli, ["simulate", *SMALL, "--quiet", "--out", str(run)]).exit_code == 0
    before = {p.name: p.read_bytes() for p in run.iterdir()}
    result = CliRunner().invoke(cli, ["analyze", str(patterned[0]), "--out", str(run)])
    assert result.exit_code == 2 and "holds a run of bark simulate" in result.stderr, result.output
    assert_clean_outcome(result)
    assert {p.name: p.read_bytes() for p in run.iterdir()} == before


def test_a_refused_report_names_report_html_not_its_temporary(patterned, tmp_path):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(patterned[0], run)
    proc = _bark("report", str(run), limit=200_000)  # the page inlines plotly: megabytes
    lines = _lines(proc.stderr)
    assert proc.returncode == 1 and lines == [f"bark: error: {run / 'report.html'}: File too large"], proc.stderr
    assert not (run / "report.html").exists()
    _no_temporaries(run)


HISTORY = ["--n-bases", "3000", "--until-time", "300", "--set",
           'effects.want=["anchors", "damping", "patch-statistics", "history"]', "--quiet"]


@pytest.mark.parametrize("short", ["disk", "memory"])
def test_a_history_that_would_not_fit_is_refused_before_the_run(short, tmp_path, monkeypatch):
    """``frame_every = 0.001`` with the history: 22 GB were due and the run wrote until the disk was
    full. The history's size is estimated first; over the disk's free space or the memory
    available, one line names the setting as typed, and nothing is written."""
    import collections
    import shutil

    from bark.engine import scene

    if short == "disk":
        usage = collections.namedtuple("usage", "total used free")
        monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(2**40, 2**40 - 2**30, 2**30))
        room = "1 GiB free on the disk of"
    else:
        monkeypatch.setattr(scene, "available_memory", lambda: 2**30)
        room = "1 GiB of memory available"
    out = tmp_path / "run"
    result = CliRunner().invoke(cli, ["simulate", *HISTORY, "--set", "effects.frame_every=0.01", "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert_clean_outcome(result)
    assert result.stderr.startswith("bark: error: --set effects.frame_every=0.01: the history would be about ")
    assert "(30,001 frames of up to 3,000 bases)" in result.stderr and room in result.stderr
    assert not out.exists()
