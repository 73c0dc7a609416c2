"""Checkpoints: resumed runs end bit-identical to uninterrupted ones; Ctrl-C and SIGKILL are survivable."""

from __future__ import annotations

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


# Real signals in a real process, and damaged checkpoints: tests/test_faults_signals.py, tests/test_faults_files.py.
