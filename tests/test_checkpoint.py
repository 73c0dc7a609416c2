"""Checkpoints: resumed runs end bit-identical to uninterrupted ones; Ctrl-C and SIGKILL are survivable."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from bark.io import checkpoint
from bark_cli.main import cli
from conftest import slow_cases

SMALL = ["--n-bases", "600", "-G", "0.03", "--until-time", "40", "--quiet"]


def _files_equal(a, b, names=("breaks.csv", "state.npz")):
    return all((a / n).read_bytes() == (b / n).read_bytes() for n in names)


@pytest.mark.parametrize("extra", [[], ["--integrator", "implicit-overdamped", "--dt", "1"],
                                   *slow_cases(["--breaker", "probabilistic"], ["--stepping", "fixed", "--dt", "0.02"])])
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


def test_a_resumed_run_goes_on_with_the_backend_it_had(tmp_path, monkeypatch):
    """``auto`` decides by the process (is numba loaded?) and the time left, and the backends' own
    transcendental functions may differ in the last bit: a resumed run keeps the backend the run was
    on, so it ends bit for bit where the uninterrupted run ends."""
    from bark.engine import kernels
    from bark.studies import runner
    from bark.engine.scene import Scene

    scene = Scene.from_dict({"lattice": {"n_bases": 600}, "growth": {"G": 0.03}, "run": {"until_time": 20.0}})
    assert scene.run.backend == "auto"
    monkeypatch.setattr(kernels, "resolve", lambda name, work=None: "numpy")  # what a fresh process may choose
    seen = []
    out = runner.run(scene, tmp_path / "part", checkpoint_every=1e-9, observe=lambda s, stop: seen.append(s.state.t),
                     interrupted=lambda: "interrupted" if seen and seen[-1] >= 8.0 else None)
    assert out.stop_reason == "interrupted" and out.sim.backend.name == "numpy"
    assert checkpoint.read_meta(tmp_path / "part" / "checkpoint.npz")["backend"] == "numpy"
    monkeypatch.undo()
    assert kernels.resolve("auto", None) == "numba"  # left to itself, auto would now take numba
    resumed = runner.resume(tmp_path / "part")
    assert resumed.sim.backend.name == "numpy" and resumed.summary["backend"] == "numpy"
