"""``auto``'s choice of backend for a lone run: numpy where numba would first have to compile the
run's kernel and the run is too short to repay it; numba where the kernel is ready, the run long,
the process one of a study's workers, or numba asked for.  The results are the same to the bit
either way (tests/test_frames.py and the backend tests); only the time differs."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys

import pytest

pytest.importorskip("numba")

from bark.engine import kernels  # noqa: E402
from bark.engine.kernels.numba_backend import NumbaBackend, compiled, specialized  # noqa: E402
from bark.engine.scene import Scene  # noqa: E402
from bark.studies import runner  # noqa: E402

SHORT = {"lattice": {"n_bases": 600}, "growth": {"G": 0.03}, "run": {"until_time": 400.0}}
"""Long enough for ``auto`` to take numba in a process that has loaded it, far below the compile's worth."""


@pytest.fixture
def not_compiled(monkeypatch):
    asked = []
    monkeypatch.setattr(NumbaBackend, "ready", lambda self, kernel: asked.append(kernel) or False)
    monkeypatch.setattr(kernels, "_MANY", [False])
    return asked


def _backend(settings: dict) -> str:
    sim = runner.run(Scene.from_dict({**SHORT, "run": {**SHORT["run"], **settings}}), None).sim
    return sim.backend.name


def test_a_lone_short_run_with_its_kernel_not_compiled_runs_on_numpy_and_says_why(not_compiled, caplog):
    with caplog.at_level(logging.INFO, logger="bark"):
        assert _backend({}) == "numpy"
    kernel = not_compiled[-1]  # the run's own parts were asked about
    assert kernel.integrator is not None and kernel.breaker is not None and kernel.growth is not None
    assert kernel.n_bases == 600 and kernel.columns == ()
    said = [r.getMessage() for r in caplog.records if "running on numpy" in r.getMessage()]
    assert len(said) == 1 and "bark compile" in said[0] and "\n" not in said[0]


@pytest.mark.parametrize("why", ["numba asked for", "a study's worker", "a long run"])
def test_numba_is_kept_where_its_compile_is_asked_for_or_repaid(not_compiled, monkeypatch, why):
    settings = {"backend": "numba"} if why == "numba asked for" else {}
    if why == "a study's worker":
        monkeypatch.setattr(kernels, "_MANY", [True])
    if why == "a long run":
        monkeypatch.setattr(kernels, "AUTO_COMPILE_WORK", 1.0)
    assert _backend(settings) == "numba"


def test_a_ready_kernel_is_used(monkeypatch):
    monkeypatch.setattr(NumbaBackend, "ready", lambda self, kernel: True)
    monkeypatch.setattr(kernels, "_MANY", [False])
    assert _backend({}) == "numba"


def test_a_kernel_compiled_in_this_process_is_ready_and_another_combination_is_not(monkeypatch, tmp_path):
    sim = runner.run(Scene.from_dict({**SHORT, "run": {**SHORT["run"], "until_time": 5.0, "backend": "numba"}}), None).sim
    parts = (sim.integrator.part_, None, sim.growth.part_)
    from bark.engine.stepping import breaking_part

    breaker = breaking_part(sim.breakers)
    specialized(parts[0], breaker, parts[2])  # what the run used: known to this process
    assert compiled(parts[0], breaker, parts[2])
    monkeypatch.setenv("BARK_CACHE_DIR", str(tmp_path / "empty"))
    assert not compiled(parts[0], breaker, parts[2], parallel=True)  # never made here, nothing on disk


def test_a_kernel_is_found_again_by_its_parts_and_the_parts_seen_are_bounded():
    """The same part objects find the same kernel without building its key; equal parts made anew
    (a fit's worker, every run) find it by the key, and the parts kept for the lookup stay few."""
    import attrs

    from bark.engine.kernels import numba_backend
    from bark.engine.stepping import breaking_part

    sim = runner.run(Scene.from_dict({**SHORT, "run": {**SHORT["run"], "until_time": 5.0, "backend": "numba"}}), None).sim
    integrator, growth, breaker = sim.integrator.part_, sim.growth.part_, breaking_part(sim.breakers)
    kernel = specialized(integrator, breaker, growth)
    assert specialized(integrator, breaker, growth) is kernel
    for _ in range(3 * numba_backend.BY_PARTS_KEPT):
        assert specialized(attrs.evolve(integrator), attrs.evolve(breaker), attrs.evolve(growth)) is kernel
    assert len(numba_backend._BY_PARTS) <= numba_backend.BY_PARTS_KEPT


def test_a_first_run_on_empty_caches_starts_at_once_with_the_same_results(tmp_path):
    """A whole process on new, empty caches, of a run long enough that ``auto`` would take numba had
    it its kernel (``AUTO_WORK``): it runs on numpy, says so on stderr in one line, and writes the same
    break log as a run on the numba backend."""
    env = {**os.environ, **{k: str(tmp_path / k) for k in ("NUMBA_CACHE_DIR", "BARK_CACHE_DIR", "XDG_CACHE_HOME")}}
    args = [sys.executable, "-m", "bark_cli", "simulate", "--set", "run.until_time=250"]  # the default scene: 3000 bases
    first = subprocess.run([*args, "--out", str(tmp_path / "first")], env=env, capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    assert first.stderr.count("running on numpy") == 1
    assert json.loads((tmp_path / "first" / "summary.json").read_text())["backend"] == "numpy"
    again = subprocess.run([*args, "--backend", "numba", "--out", str(tmp_path / "numba")], capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert (tmp_path / "first" / "breaks.csv").read_bytes() == (tmp_path / "numba" / "breaks.csv").read_bytes()


@pytest.fixture
def record(monkeypatch, tmp_path):
    """The compile record in a folder of the test's own."""
    from bark.engine.kernels import numba_backend

    path = tmp_path / "kernels" / "compile-seconds.json"
    monkeypatch.setattr(numba_backend, "compile_record", lambda: path)
    return path


def test_a_first_compile_is_timed_and_the_next_ones_notice_says_how_long(record, monkeypatch, caplog):
    """The notice before a kernel's first compile says how long it takes: a range where this machine
    has compiled none yet, then the seconds the last one took here (its first call, timed)."""
    from bark.engine.kernels import numba_backend

    for round_ in range(2):
        monkeypatch.setattr(numba_backend, "_compiled_before", lambda path: False)  # as on a new machine
        monkeypatch.setattr(numba_backend, "_SPECIALIZED", {})
        monkeypatch.setattr(numba_backend, "_BY_PARTS", {})
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="bark"):
            runner.run(Scene.from_dict({**SHORT, "run": {**SHORT["run"], "until_time": 5.0, "backend": "numba"}}), None)
        said = [r.getMessage() for r in caplog.records if r.getMessage().startswith("compiling the stepping kernel")]
        kept = json.loads(record.read_text())
        assert set(kept) == {"serial"} and kept["serial"] > 0
        if round_ == 0:
            assert len(said) == 1 and "(once, tens of seconds: later runs load it from" in said[0], said
            first = kept["serial"]
        else:
            expected = f"(once, about {max(1, round(first))} s here the last time: later"
            assert len(said) == 1 and expected in said[0], said
    assert not numba_backend._FIRST_CALL  # each timed once, at its first call


@pytest.mark.parametrize("held", [b"", b"{", b"[1, 2]", b'"serial"', b'{"serial": "20"}', b'{"serial": NaN}',
                                  b'{"serial": Infinity}', b'{"serial": -3}', b'{"serial": 0}', b'{"serial": true}',
                                  b'{"serial": null}', b'{"serial": [20]}', b"\xff\xfe{}", None])
def test_a_damaged_compile_record_gives_a_range_and_is_written_anew(record, held):
    """Whatever the record holds (or a folder in its place: ``None``), the notice gives a range and
    nothing is raised; a file is replaced by the next compile's seconds."""
    from bark.engine.kernels import numba_backend

    record.parent.mkdir()
    if held is None:
        record.mkdir()
    else:
        record.write_bytes(held)
    assert numba_backend.compile_seconds() == {}
    assert numba_backend._how_long("serial") == "tens of seconds" and numba_backend._how_long("threaded") == "minutes"
    numba_backend.record_compile("threaded", 61.04)
    assert numba_backend.compile_seconds() == ({} if held is None else {"threaded": 61.0})


@pytest.mark.parametrize("seconds", [float("nan"), float("inf"), -1.0, 0.0])
def test_a_compile_time_that_is_not_a_time_is_not_kept(record, seconds):
    from bark.engine.kernels import numba_backend

    numba_backend.record_compile("serial", seconds)
    assert not record.exists()


def test_a_compile_record_that_cannot_be_written_is_skipped_in_silence(monkeypatch, tmp_path):
    from bark.engine.kernels import numba_backend

    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.setattr(numba_backend, "compile_record", lambda: blocker / "compile-seconds.json")
    numba_backend.record_compile("serial", 20.0)  # its folder is a file: not written, no error
    assert numba_backend.compile_seconds() == {}
