"""Checkpoints: resumed runs end bit-identical to uninterrupted ones; Ctrl-C and SIGKILL are survivable."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner

from bark import checkpoint
from bark_cli.main import cli

SMALL = ["--n-bases", "600", "-G", "0.03", "--until-time", "40", "--quiet"]


def _files_equal(a, b, names=("breaks.csv", "state.npz")):
    return all((a / n).read_bytes() == (b / n).read_bytes() for n in names)


@pytest.mark.parametrize("extra", [[], ["--breaker", "probabilistic"], ["--stepping", "fixed", "--dt", "0.02"],
                                   ["--integrator", "implicit-overdamped", "--dt", "1"]])
def test_resume_from_a_mid_run_checkpoint_is_bit_identical(tmp_path, extra):
    """Stopped between two steps as Ctrl-C stops it (stop_reason set from observe), written down,
    resumed by the CLI: the outputs equal the uninterrupted run's, byte for byte."""
    runner = CliRunner()
    whole = tmp_path / "whole"
    assert runner.invoke(cli, ["simulate", *SMALL, *extra, "--out", str(whole)]).exit_code == 0
    scene = checkpoint.load(whole)[0]  # the scene the CLI resolved, every setting
    sim, stop = scene.simulation(), scene.stop()

    def interrupt_at_17(s):
        if s.state.t >= 17.0:
            s.stop_reason = "interrupted"

    assert sim.run(stop, interrupt_at_17) == "interrupted"
    part = tmp_path / "part"
    part.mkdir()
    checkpoint.save(part, sim, scene, stop, "interrupted")
    result = runner.invoke(cli, ["simulate", "--resume", str(part), "--quiet"])
    assert result.exit_code == 0, result.output
    assert _files_equal(whole, part)


def test_resume_refuses_settings_and_ended_runs(tmp_path):
    runner = CliRunner()
    out = tmp_path / "run"
    assert runner.invoke(cli, ["simulate", *SMALL, "--out", str(out)]).exit_code == 0
    result = runner.invoke(cli, ["simulate", "--resume", str(out)])
    assert result.exit_code == 2 and "ended" in result.stderr and result.stderr.count("\n") == 1
    result = runner.invoke(cli, ["simulate", "--resume", str(out), "--k", "2"])
    assert result.exit_code == 2 and "--k" in result.stderr
    result = runner.invoke(cli, ["simulate", "--resume", str(tmp_path / "nowhere")])
    assert result.exit_code == 2 and "no such folder" in result.stderr


def test_checkpoint_holds_what_it_documents(tmp_path):
    out = tmp_path / "run"
    assert CliRunner().invoke(cli, ["simulate", *SMALL, "--breaker", "probabilistic", "--out", str(out)]).exit_code == 0
    with np.load(out / "checkpoint.npz", allow_pickle=False) as data:
        names = set(data.files)
    assert {"x", "v", "anchor", "intact", "fmax", "pairs", "meta", "breaks_spring", "breaks_tension"} <= names
    scene, sim, stop, meta, _, _ = checkpoint.load(out)
    assert meta["reason"] == "end" and meta["stop_reason"] == "time" and meta["rng"]["bit_generator"] == "PCG64"
    assert sim.graph.number_of_edges() == int(sim.state.intact.sum())  # the graph of record, rebuilt


# -- real signals, in a real process ---------------------------------------------------------

LONG = ["--scene", "examples/scenes/diamond.toml", "--n-bases", "1500", "--dt", "0.01", "--stepping", "fixed", "--quiet"]


def _start(out, *extra):
    return subprocess.Popen([sys.executable, "-m", "bark_cli.main", "simulate", *LONG, *extra, "--out", str(out)],
                            cwd=os.path.dirname(os.path.dirname(__file__)), stderr=subprocess.PIPE, text=True)


def _wait_for(path, proc, limit_s=120.0):
    """Until ``path`` exists (a periodic checkpoint was written): the signal then lands mid-run."""
    deadline = time.monotonic() + limit_s
    while not path.exists():
        assert proc.poll() is None, "the run ended before its first checkpoint"
        assert time.monotonic() < deadline, "no checkpoint appeared"
        time.sleep(0.05)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("uninterrupted")
    proc = _start(out)
    assert proc.wait() == 0, proc.stderr.read()
    return out


@pytest.mark.slow
def test_sigint_writes_a_checkpoint_and_the_resumed_run_is_identical(tmp_path, uninterrupted):
    out = tmp_path / "run"
    proc = _start(out, "--checkpoint-every", "0.3")
    _wait_for(out / "checkpoint.npz", proc)
    proc.send_signal(signal.SIGINT)
    assert proc.wait() == 130
    err = proc.stderr.read()
    assert "bark simulate --resume" in err and "Traceback" not in err
    assert checkpoint.load(out)[3]["reason"] == "interrupted"
    resumed = subprocess.run([sys.executable, "-m", "bark_cli.main", "simulate", "--resume", str(out), "--quiet"],
                             capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert _files_equal(uninterrupted, out)


@pytest.mark.slow
def test_sigkill_between_checkpoints_loses_nothing_but_time(tmp_path, uninterrupted):
    out = tmp_path / "run"
    proc = _start(out, "--checkpoint-every", "0.3")
    _wait_for(out / "checkpoint.npz", proc)
    time.sleep(0.2)  # somewhere between two checkpoints
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (out / "summary.json").exists()  # it really died mid-run
    resumed = subprocess.run([sys.executable, "-m", "bark_cli.main", "simulate", "--resume", str(out), "--quiet"],
                             capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert _files_equal(uninterrupted, out)
