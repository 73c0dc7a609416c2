"""A threaded kernel not yet compiled is compiled alongside the run, in a process of its own: the
run's calls take the serial kernel (the same bits) until it is in the cache, then every thread; a
compile that fails is said in one line and done in the run's process; a compile still running when
the run's process leaves ends with it, and one left by a killed run ends itself."""

from __future__ import annotations

import errno
import json
import logging
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

numba = pytest.importorskip("numba")

from bark import Stop  # noqa: E402
from bark.engine.kernels import numba_alongside, numba_backend  # noqa: E402
from bark.engine.kernels.numba_backend import NumbaBackend  # noqa: E402
from bark.model.lattice import Lattice  # noqa: E402
from bark_plugins.breakers import ProbabilisticBreaker  # noqa: E402
from bark_plugins.growth import SqrtGrowth  # noqa: E402
from conftest import build_sim  # noqa: E402

pytestmark = pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="numba may use one thread here")


class _Job:
    """A compile alongside that is done after ``polls`` questions, well or not."""

    def __init__(self, polls: int, ok: bool) -> None:
        self.polls, self.ok, self.asked = polls, ok, 0

    def done(self):
        self.asked += 1
        return None if self.asked <= self.polls else self.ok

    def why(self) -> str:
        return "it ran out of memory"


def _sim(threads: int, horizon: float | None = None):
    """Bases joining and springs breaking, in blocks of 16 (several blocks per thread): the sqrt case
    of tests/test_frames.py, whose threaded kernel those tests compile too."""
    lattice = Lattice(n_bases=2000, n_start=1500, join_rate=150.0, join_every=0.1, jitter=0.05)
    sim = build_sim(G=0.08, dt=0.05, seed=2, stepping="fixed", backend="numba", fmax_spread=0.05,
                    growth=SqrtGrowth(G=0.08), lattice=lattice, breakers=[ProbabilisticBreaker()], threads=threads)
    sim.horizon = horizon  # the run's expected length, as a run that builds itself takes it from its stop
    sim.build().backend.block = 16
    return sim


@pytest.fixture
def calls(monkeypatch):
    """The threads of every kernel call, and a compile alongside that is never found on disk."""
    seen = []
    call = NumbaBackend.call

    def counted(self, *args):
        made = call(self, *args)
        seen.append(self.threads)
        return made

    monkeypatch.setattr(NumbaBackend, "call", counted)
    monkeypatch.setattr(numba_backend, "ALONGSIDE", True)
    monkeypatch.setattr(numba_backend, "runs_many", lambda: True)  # its runs are short: as a fit's worker's
    monkeypatch.setattr(numba_backend, "_compiled_before", lambda path: False)
    monkeypatch.setattr(numba_backend, "_WAITING", {})
    monkeypatch.setattr(numba_backend, "_BY_PARTS", {})
    monkeypatch.setattr(numba_backend, "_SPECIALIZED", {})
    return seen


@pytest.mark.parametrize("ok", [True, False])
def test_a_threaded_run_takes_one_thread_until_its_kernel_is_ready_with_the_same_bits(calls, monkeypatch, caplog, ok):
    serial = _sim(1)
    serial.run(Stop(until_time=4.0))
    started = []
    monkeypatch.setattr(numba_alongside, "job", lambda path: None)
    monkeypatch.setattr(numba_alongside, "start", lambda path, types, helpers: started.append((path, types)) or _Job(5, ok))
    calls.clear()
    shared = _sim(2)
    with caplog.at_level(logging.INFO, logger="bark"):
        shared.run(Stop(until_time=4.0))
    assert len(started) == 1 and "parallel=True" in started[0][0].read_text()  # the threaded kernel's module
    arguments = numba_backend._steps_kernel.py_func.__code__.co_argcount - len(numba_backend._PARTS)
    assert len(started[0][1]) == arguments and all(isinstance(t, numba.types.Type) for t in started[0][1])
    assert calls[:5] == [1] * 5 and calls[5:] and set(calls[5:]) == {2}  # asked at each call; then threads
    said = [r.getMessage() for r in caplog.records]
    assert sum("alongside, in a process of its own" in m for m in said) == 1
    assert sum("could not be compiled alongside (it ran out of memory)" in m for m in said) == (not ok)
    assert shared.n_broken > 100 and shared.state.n_bases > 1500
    for name in ("x", "v", "anchor", "intact"):
        assert (getattr(serial.state, name) == getattr(shared.state, name)).all(), name


def test_a_compile_alongside_that_cannot_start_is_done_in_the_runs_process(calls, monkeypatch, caplog):
    def refused(path, types, helpers):
        raise OSError(errno.EAGAIN, "Resource temporarily unavailable")

    monkeypatch.setattr(numba_alongside, "job", lambda path: None)
    monkeypatch.setattr(numba_alongside, "start", refused)
    with caplog.at_level(logging.INFO, logger="bark"):
        _sim(2).run(Stop(until_time=0.5))
    assert set(calls) == {2}
    said = [r.getMessage() for r in caplog.records if "alongside" in r.getMessage()]
    assert len(said) == 1 and "cannot be compiled alongside (Resource temporarily unavailable)" in said[0], said


def test_with_alongside_off_a_threaded_run_is_threaded_from_its_first_call(calls, monkeypatch):
    monkeypatch.setattr(numba_backend, "ALONGSIDE", False)
    monkeypatch.setattr(numba_alongside, "start", lambda path, types, helpers: pytest.fail("compiled alongside"))
    _sim(2).run(Stop(until_time=0.5))
    assert set(calls) == {2}


@pytest.mark.parametrize("many", [False, True])
def test_a_run_expected_to_end_before_its_threaded_kernel_compiles_keeps_to_one_thread(calls, monkeypatch, caplog, many,
                                                                                       tmp_path):
    """No compile alongside that the run would end unused as it leaves (and the next short run start
    again): a run expected to be shorter than the compile (its base-steps at the serial kernel's
    speed, against the last threaded compile timed here, else a minute) takes one thread throughout,
    the same bits, and says so once; a process that runs many (a worker, ``bark compile``) starts
    the compile whatever one run's length; so does a run whose length is not known."""
    monkeypatch.setattr(numba_backend, "runs_many", lambda: many)
    monkeypatch.setattr(numba_backend, "compile_record", lambda: tmp_path / "compile-seconds.json")
    started = []
    monkeypatch.setattr(numba_alongside, "job", lambda path: None)
    monkeypatch.setattr(numba_alongside, "start", lambda path, types, helpers: started.append(path) or _Job(10**6, True))
    sim = _sim(2, 4.0)  # 2000 bases for 4 time units at a step of 0.05: 160,000 base-steps (ms on one thread)
    with caplog.at_level(logging.INFO, logger="bark"):
        sim.run(Stop(until_time=4.0))
    said = [r.getMessage() for r in caplog.records if "running on one thread" in r.getMessage()]
    assert sim.backend.expected_work == pytest.approx(160_000) and set(calls) == {1}
    assert (len(started), len(said)) == ((1, 0) if many else (0, 1)), (started, said)
    if not many:
        assert "before its threaded kernel would compile (minutes)" in said[0] and "`bark compile`" in said[0]
        # the same run judged long enough (one timed here in a tenth of its length): compiled alongside
        (tmp_path / "compile-seconds.json").write_text(json.dumps({"threaded": 160_000 * numba_backend.SERIAL_BASE_STEP_S / 10}))
        calls.clear()
        _sim(2, 4.0).run(Stop(until_time=4.0))
        assert len(started) == 1 and set(calls) == {1}
        unknown = _sim(2)  # a run without a time bound, or built before it was given one
        (tmp_path / "compile-seconds.json").unlink()
        numba_backend._WAITING.clear()
        unknown.run(Stop(until_time=0.5))
        assert len(started) == 2


class _Running:
    """A compile alongside that has run ``seconds``, still ``running`` or ended."""

    def __init__(self, seconds: float, running: bool) -> None:
        self.seconds, self.running = seconds, running

    def done(self) -> bool | None:
        return None if self.running else True

    def running_for(self) -> float:
        return self.seconds


@pytest.mark.parametrize("held, running, kept", [
    (0.1, True, 30.0),  # a record too short (a load timed as a compile): the time it has run, at least
    (None, True, 30.0),  # no record
    (90.0, True, 90.0),  # a longer record stands
    (0.1, False, 0.1),  # a compile that has ended was recorded by its own process
])
def test_a_compile_alongside_ended_unfinished_is_recorded_as_the_least_a_compile_takes(monkeypatch, held, running,
                                                                                        kept):
    """A threaded compile alongside still running as the run's process leaves has taken at least as
    long as it ran: the record of threaded compiles (what decides whether the next run starts one)
    is raised to that, never lowered, so that runs that never outlast it stop starting it."""
    monkeypatch.setattr(numba_backend, "_WAITING", {("parts",): (None, None, None, None, _Running(30.0, running))})
    if held is not None:
        numba_backend.compile_record().write_text(json.dumps({"serial": 20.0, "threaded": held}))
    numba_backend._unfinished_compiles()
    assert numba_backend.compile_seconds().get("threaded") == kept
    assert numba_backend.compile_seconds().get("serial") == (20.0 if held is not None else None)


def _env(tmp_path) -> dict:
    return {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache"), "BARK_CACHE_DIR": str(tmp_path / "bark-cache"),
            "NUMBA_NUM_THREADS": "2"}


SCENE = """
[lattice]
n_bases = 2000
n_start = 1500
join_rate = 150.0
join_every = 0.1
jitter = 0.05
[growth]
name = "bulge"
base = { name = "sqrt", G = 0.08 }
[[growth.bulges]]
z = 0.4
half_width = 0.2
magnitude = 0.01
G = 0.03
[breaker]
name = "threshold"
spread = 0.05
[run]
backend = "numba"
threads = 2
dt = 0.3
stepping = "adaptive"
until_time = 4.0
seed = 2
"""
"""Threaded, bases joining and springs breaking in the kernel at per-base radii; its growth law's
part calls helpers of its own (the bulges' profile), which the compiling process must make jitable
as the run's process does."""


@pytest.mark.slow
def test_bark_compile_waits_for_the_threaded_kernel_and_a_later_run_loads_both(tmp_path):
    """On empty caches: ``bark compile`` takes its step on the serial kernel while the threaded one
    compiles alongside, waits for it, and a later run in a new process loads the threaded kernel
    from the cache (the types the compile was given are the call's, the helpers made jitable: no
    compile of its own) — in blocks of 16 bases or springs shared between two threads, to the bits
    of the serial kernel in its usual blocks (``tests/test_frames.py`` checks this of a uniform
    radius, breaks judged in Python; here per-base radii and breaks in the kernel): with bases
    joining, and in long calls without joins, where the threaded base pass copies each block before
    it moves it and a refused step is taken back from those copies inside the call (some calls
    halve a step and go on).  The threaded kernel is this test's, compiled once for both."""
    (tmp_path / "scene.toml").write_text(SCENE)
    env = _env(tmp_path)
    done = subprocess.run([sys.executable, "-m", "bark_cli", "compile", str(tmp_path / "scene.toml")], cwd=tmp_path,
                          env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    out = done.stdout + done.stderr
    assert "alongside" in out and "ready (" in out and "did not compile" not in out, out
    timed = json.loads((tmp_path / "bark-cache" / "kernels" / "compile-seconds.json").read_text())
    assert set(timed) == {"serial", "threaded"} and min(timed.values()) > 0, timed  # what the next notices say
    check = textwrap.dedent(f"""
        import json, sys
        import numpy as np
        from bark import Stop
        from bark.engine.scene import Scene, merge, read_toml
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from conftest import recorded_calls
        data = read_toml({str(tmp_path / 'scene.toml')!r})

        def pair(data, until):
            shared = Scene.from_dict(data).simulation()
            shared.build().backend.block = 16
            shared.run(Stop(until_time=until))
            serial = Scene.from_dict(merge(data, {{"run": {{"threads": 1}}}})).simulation()
            serial.run(Stop(until_time=until))
            return shared, serial

        def same(shared, serial):
            return [name for name in ("x", "v", "anchor", "intact", "rest", "fmax")
                    if np.array_equal(getattr(shared.state, name), getattr(serial.state, name))]

        shared, serial = pair(data, 4.0)
        with recorded_calls() as calls:  # long calls: no joins, so that the kernel takes refused steps back itself
            long_shared, long_serial = pair(merge(data, {{"lattice": {{"n_start": 2000}}}}), 6.0)
        from bark.engine.kernels import numba_backend
        threaded = [k for k in numba_backend._SPECIALIZED.values() if k.targetoptions.get("parallel")]
        print(json.dumps({{"threads": (shared.backend.threads, serial.backend.threads), "kernels": len(threaded),
                           "hits": sum(k.stats.cache_hits.get(s, 0) for k in threaded for s in k.stats.cache_hits),
                           "misses": sum(k.stats.cache_misses.get(s, 0) for k in threaded for s in k.stats.cache_misses),
                           "same": same(shared, serial), "broken": shared.n_broken, "joined": shared.state.n_bases > 1500,
                           "long_same": same(long_shared, long_serial) if long_shared.step_count == long_serial.step_count
                           else "steps differ", "long_broken": long_shared.n_broken,
                           "halved": any(c.halved and not c.undone for c in calls),
                           "long_threads": (long_shared.backend.threads, long_serial.backend.threads)}}))
    """)
    later = subprocess.run([sys.executable, "-c", check], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert later.returncode == 0, later.stderr
    got = json.loads(later.stdout.splitlines()[-1])
    assert got["broken"] > 100 and got["joined"], got  # breaks, and joins, happened
    assert got["long_broken"] > 20 and got["halved"], got  # refused steps taken back inside calls that went on
    del got["broken"], got["joined"], got["long_broken"], got["halved"]
    every = ["x", "v", "anchor", "intact", "rest", "fmax"]
    assert got == {"threads": [2, 1], "kernels": 1, "hits": 1, "misses": 0, "same": every,
                   "long_same": every, "long_threads": [2, 1]}, (got, later.stderr)


def _alive(pid: int) -> bool:
    """Whether process ``pid`` is still a compile alongside (not gone, nor another process since)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return b"numba_alongside" in fh.read()
    except FileNotFoundError:
        return False


NEVER_DONE = ("from bark.engine.kernels import numba_alongside as a; import pickle, sys, threading; "
              "_, _, _, _, parent = pickle.load(sys.stdin.buffer); {then}")
"""A compile alongside that never ends on its own (the run's exit hook must end it), or that only its
watch over the run's process ends."""


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads /proc")
@pytest.mark.parametrize("how", ["leaves", "is killed"])
def test_a_compile_alongside_ends_with_the_run_that_started_it(tmp_path, how):
    """A run's process that leaves while its compile alongside is running ends it (the exit hook);
    one killed outright leaves it to end itself (it watches that process)."""
    then = "threading.Event().wait()" if how == "leaves" else "a.ORPHAN_CHECK_S = 0.05; a._orphaned(parent)"
    code = textwrap.dedent(f"""
        import os, signal, sys
        from pathlib import Path
        from bark.engine.kernels import numba_alongside
        numba_alongside.CODE = {NEVER_DONE.format(then=then)!r}
        job = numba_alongside.start(Path("steps.py"), (), [])
        print(job.process.pid, flush=True)
        if {how == "is killed"}:
            os.kill(os.getpid(), signal.SIGKILL)
    """)
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    pid = int(done.stdout.split()[0])
    if how == "leaves":
        assert done.returncode == 0, done.stderr
        assert not _alive(pid)  # ended and reaped before the run's process was gone
    else:
        assert done.returncode == -9
        guard = time.monotonic() + 600  # a bound on a hang, not a timing: it ends within a tenth of a second
        while _alive(pid):  # until it has gone (or is a zombie left to init): a state, not a time
            assert time.monotonic() < guard, "the compile alongside outlived its run"
            os.sched_yield()


HOLDS = textwrap.dedent("""
    import os, pathlib, threading
    from bark.engine.kernels import numba_alongside as a
    path, _, _ = a.read_order()
    folder = pathlib.Path(path).parent
    with a.alone(path):
        (folder / f"in-{os.getpid()}").write_text("")
        while not (folder / "go").exists():
            threading.Event().wait(0.01)
""")
"""A compile alongside that holds its kernel's lock until the test lets it go."""


def _blocked_on(lock) -> bool:
    """Whether a process waits for a ``flock`` on ``lock`` (``/proc/locks``: a waiter's line has ``->``)."""
    ino = os.stat(lock).st_ino
    with open("/proc/locks") as fh:
        return any("->" in line and line.split()[-3].endswith(f":{ino}") for line in fh)


@pytest.mark.skipif(not os.path.exists("/proc/locks"), reason="reads /proc/locks")
def test_compiles_alongside_of_one_kernel_take_turns(tmp_path, monkeypatch):
    """Two processes that compile the same kernel alongside (two runs' that started together): the
    second waits, without compiling, until the first has ended (then it finds the kernel in numba's
    cache); both end well."""
    monkeypatch.setattr(numba_alongside, "CODE", HOLDS)
    monkeypatch.setattr(numba_alongside, "_JOBS", {})
    path = tmp_path / "bark_steps_x.py"
    path.write_text("")
    guard = time.monotonic() + 600  # a bound on a hang, not a timing

    def until(state, job) -> None:
        while not state():
            assert job.done() is None, job.why()
            assert time.monotonic() < guard
            os.sched_yield()

    first = numba_alongside.start(path, (), [])
    jobs = [first]
    try:
        until(lambda: (tmp_path / f"in-{first.process.pid}").exists(), first)
        numba_alongside._JOBS.clear()  # the second as another process's
        second = numba_alongside.start(path, (), [])
        jobs.append(second)
        entered = tmp_path / f"in-{second.process.pid}"
        until(lambda: entered.exists() or _blocked_on(path.with_suffix(".lock")), second)
        assert not entered.exists(), "the second compile went on while the first held the kernel"
        (tmp_path / "go").write_text("")
        assert first.process.wait() == 0 and second.process.wait() == 0, (first.why(), second.why())
        assert entered.exists()
    finally:
        (tmp_path / "go").write_text("")
        for job in jobs:
            job.process.wait()
            job.errors.close()


@pytest.mark.skipif(not os.path.exists("/proc/locks"), reason="reads /proc/locks")
def test_a_kernels_first_call_waits_for_another_process_compiling_it(monkeypatch):
    """A run whose kernel another process is compiling (it holds the kernel's lock: a sweep's worker
    that started first) waits for it at its first call, without compiling it too, then goes on."""
    import fcntl
    import threading

    from bark.engine.stepping import breaking_part

    monkeypatch.setattr(numba_backend, "_compiled_before", lambda path: False)  # a first call, as on a new machine
    monkeypatch.setattr(numba_backend, "_SPECIALIZED", {})
    monkeypatch.setattr(numba_backend, "_BY_PARTS", {})
    monkeypatch.setattr(numba_backend, "_FIRST_CALL", {})
    monkeypatch.setattr(numba_backend, "record_compile", lambda kind, seconds: None)
    sim = _sim(1)
    combination = numba_backend._combination(sim.integrator.part_, breaking_part(sim.breakers), sim.growth.part_,
                                             False, (), sim.resin_part)
    lock = numba_backend.cache_dir() / f"{combination.file()[0]}.lock"
    held = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(held, fcntl.LOCK_EX)  # the other process's compile
    outcome = []
    run = threading.Thread(target=lambda: outcome.append((sim.run(Stop(until_time=0.5)), sim.step_count)[1]))
    try:
        run.start()
        guard = time.monotonic() + 600  # a bound on a hang, not a timing
        while not (outcome or _blocked_on(lock)) and run.is_alive():
            assert time.monotonic() < guard
            os.sched_yield()
        assert not outcome and run.is_alive(), "the run compiled the kernel another process was compiling"
    finally:
        os.close(held)  # that compile ends
        run.join()
    assert outcome and outcome[0] > 0
