"""Fault injection, signals: SIGINT, SIGTERM and SIGKILL at random points of a real `bark simulate`
process, then `--resume`: the outputs are byte-identical to the run that was never stopped.  And
signals at the end: during the final writes (they wait), and while a picture is drawn (it stops)."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from bark.io import checkpoint
from bark.studies import runner
from bark_cli.main import cli

from conftest import REPO_ROOT, assert_clean_outcome

# the diamond regime with the paper's integration (fixed dt = 0.01), smaller: about 2 s of stepping
LONG = ["--scene", "diamond", "--n-bases", "1500", "--dt", "0.01", "--stepping", "fixed",
        "--until-patches", "60", "--quiet"]
COMPARED = ("breaks.csv", "state.npz", "patches.csv")


def _start(out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "bark_cli", "simulate", *LONG, *extra, "--out", str(out)],
                            cwd=REPO_ROOT, stderr=subprocess.PIPE, text=True)


def _resume(out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bark_cli", "simulate", "--resume", str(out), "--quiet"],
                          cwd=REPO_ROOT, capture_output=True, text=True)


def _wait_for(path: Path, proc: subprocess.Popen, limit_s: float = 120.0) -> None:
    deadline = time.monotonic() + limit_s
    while not path.exists():
        assert proc.poll() is None, "the run ended before its first checkpoint: " + proc.stderr.read()
        assert time.monotonic() < deadline, "no checkpoint appeared"
        time.sleep(0.02)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("uninterrupted") / "out"
    proc = _start(out)
    _, err = proc.communicate()  # (communicate: reads stderr to its end and closes it)
    assert proc.returncode == 0, err
    return out


def _wait_for_time(out: Path, proc: subprocess.Popen, t: float, limit_s: float = 240.0) -> float:
    """Wait until the run's checkpoint says it has reached simulated time ``t`` (an observable state
    of the run, not a moment of the clock: the machine's speed does not matter); its time."""
    deadline = time.monotonic() + limit_s
    while True:
        assert proc.poll() is None, "the run ended before time %g: %s" % (t, proc.stderr.read())
        try:
            reached = float(checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["t"])
        except (FileNotFoundError, checkpoint.Damaged):
            reached = -1.0
        if reached >= t:
            return reached
        assert time.monotonic() < deadline, f"the run did not reach time {t:g}"
        time.sleep(0.02)


# a few random points of the run, as fractions of its simulated time (seeded: a failure names its
# point); at most 0.7, so that a good part of the run is left when the signal comes
POINTS = random.Random(20261122).sample([0.025 * k for k in range(1, 29)], 4)
CASES = [(signal.SIGINT, POINTS[0]), (signal.SIGTERM, POINTS[1]), (signal.SIGKILL, POINTS[2]), (signal.SIGKILL, POINTS[3])]


@pytest.mark.slow  # seconds of whole processes: the quick subset (-m "not slow") leaves it out
@pytest.mark.parametrize("sig, at", CASES, ids=[f"{signal.Signals(s).name}-at-{a:.3f}" for s, a in CASES])
def test_a_signal_mid_run_then_resume_is_byte_identical(tmp_path, uninterrupted, sig, at):
    out = tmp_path / "out"
    end = json.loads((uninterrupted / "summary.json").read_text())["t"]
    proc = _start(out, "--checkpoint-every", "0.05")
    _wait_for_time(out, proc, at * end)
    proc.send_signal(sig)
    _, err = proc.communicate()
    code = proc.returncode
    assert "Traceback" not in err, err
    assert code != 0, f"the run ended before the signal at {at:.3f} of its time"
    if sig == signal.SIGKILL:
        assert code == -signal.SIGKILL
    else:
        assert code == 128 + sig, (code, err)
        assert f"go on with: bark simulate --resume {out}" in err
        assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "interrupted"
        summary = json.loads((out / "summary.json").read_text())  # the outputs of that state, written
        assert summary["stop_reason"] in ("interrupted", "terminated")
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")] or sig == signal.SIGKILL
    resumed = _resume(out)
    assert resumed.returncode == 0, resumed.stderr
    assert "Traceback" not in resumed.stderr
    for name in COMPARED:
        assert (out / name).read_bytes() == (uninterrupted / name).read_bytes(), name
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.slow  # seconds of whole processes: the quick subset (-m "not slow") leaves it out
def test_stopped_twice_and_resumed_twice_is_byte_identical(tmp_path, uninterrupted):
    out = tmp_path / "out"
    proc = _start(out, "--checkpoint-every", "0.05")
    _wait_for(out / checkpoint.CHECKPOINT_NAME, proc)
    proc.send_signal(signal.SIGTERM)
    proc.communicate()
    assert proc.returncode == 143
    stopped_at = float(checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["t"])
    again = subprocess.Popen([sys.executable, "-m", "bark_cli", "simulate", "--resume", str(out), "--quiet",
                              "--checkpoint-every", "0.05"], cwd=REPO_ROOT, stderr=subprocess.PIPE, text=True)
    end = json.loads((uninterrupted / "summary.json").read_text())["t"]
    _wait_for_time(out, again, stopped_at + 0.25 * (end - stopped_at))  # it has gone on: stop it again
    again.send_signal(signal.SIGINT)
    again.communicate()
    assert again.returncode == 130
    assert _resume(out).returncode in (0, 2)  # 2: it had already ended
    for name in COMPARED:
        assert (out / name).read_bytes() == (uninterrupted / name).read_bytes(), name


SMALL = ["--n-bases", "300", "-G", "0.05", "--until-time", "6", "--quiet"]


def test_a_signal_during_the_final_writes_waits_for_them(tmp_path, monkeypatch):
    """SIGTERM while the outputs are written: they are all written, and summary and checkpoint agree.
    The pictures, drawn meanwhile in another process, are stopped unless already drawn (and say so)."""
    real = runner.write_run

    def write_with_a_signal(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)  # the CLI's handler notes it; nothing stops
        return real(*args, **kwargs)

    monkeypatch.setattr(runner, "write_run", write_with_a_signal)
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["simulate", *SMALL, "--out", str(out)])
    assert_clean_outcome(result)
    assert (out / "breaks.csv").exists() and (out / "state.npz").exists()
    if not (out / "pattern.png").exists():  # stopped while drawing: the folder does not claim a whole run
        assert result.exit_code == 143 and "pattern.png: not drawn (stopped by a signal while drawing)" in result.stderr
        assert f"bark simulate --resume {out} writes what is missing" in result.stderr
        assert not (out / "summary.json").exists()
        monkeypatch.undo()
        assert CliRunner().invoke(cli, ["simulate", "--resume", str(out), "--quiet"]).exit_code == 0
    else:  # drawn before the command waited for it
        assert result.exit_code == 0
    assert (out / "pattern.png").exists()
    summary = json.loads((out / "summary.json").read_text())
    meta = checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)
    assert (summary["stop_reason"], summary["steps"], summary["t"]) == (meta["stop_reason"], meta["step_count"], meta["t"])


def test_a_signal_while_drawing_stops_the_drawing_and_keeps_the_data(tmp_path, monkeypatch):
    import bark_cli.plot

    command = os.getpid()  # the picture may be drawn in a process of its own: the signal goes to the command

    def slow_picture(*args, **kwargs):
        os.kill(command, signal.SIGINT)
        time.sleep(30)  # a huge picture; the signal must cut it short
        raise AssertionError("the drawing was not stopped")

    monkeypatch.setattr(bark_cli.plot, "plot_pattern", slow_picture)
    out = tmp_path / "out"
    t0 = time.monotonic()
    result = CliRunner().invoke(cli, ["simulate", *SMALL, "--out", str(out)])
    assert time.monotonic() - t0 < 20
    assert_clean_outcome(result)
    assert result.exit_code == 130
    assert "pattern.png: not drawn" in result.stderr
    assert {"breaks.csv", "state.npz", "checkpoint.npz"} <= {p.name for p in out.iterdir()}
    assert not (out / "summary.json").exists()  # written last, once every picture is there
    assert not (out / "pattern.png").exists()


# a signal while the simulation is built: sent by the process to itself as Simulation.build begins
_SIGNAL_WHILE_BUILDING = """
import os, signal, sys
from bark.engine.simulation import Simulation
build = Simulation.build
def build_after_a_signal(self, *args, **kwargs):
    os.kill(os.getpid(), signal.SIGTERM)
    return build(self, *args, **kwargs)
Simulation.build = build_after_a_signal
sys.argv = ["bark", "simulate", "--n-bases", "1500000", "--until-time", "1", "--quiet", "--out", sys.argv[1]]
from bark_cli.__main__ import main
main()
"""


def test_a_signal_while_a_large_scene_is_built_stops_at_once(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-c", _SIGNAL_WHILE_BUILDING, str(out)], cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=60)
    assert (proc.returncode, proc.stderr) == (143, "bark: terminated before the run began: nothing was run\n"), proc.stderr
    assert not out.exists()


# a signal while Python loads the program: a finder that raises it when `bark_cli.main` is looked up
_SIGNAL_WHILE_LOADING = """
import os, signal, sys
class Finder:
    def find_spec(self, name, path=None, target=None):
        if name == "bark_cli.main":
            os.kill(os.getpid(), signal.{sig})
        return None
sys.meta_path.insert(0, Finder())
sys.argv = ["bark", "simulate", "--quiet", "--out", sys.argv[1]]
from bark_cli.__main__ import main
main()
"""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=lambda s: signal.Signals(s).name)
def test_a_signal_while_the_program_loads_is_one_line(tmp_path, sig):
    out = tmp_path / "out"
    code = _SIGNAL_WHILE_LOADING.format(sig=signal.Signals(sig).name)
    proc = subprocess.run([sys.executable, "-c", code, str(out)], cwd=REPO_ROOT, capture_output=True, text=True)
    reason = "interrupted" if sig == signal.SIGINT else "terminated"
    assert (proc.returncode, proc.stderr) == (128 + sig, f"bark: {reason} before the run began: nothing was run\n")
    assert not out.exists()


# a signal raised inside code that a string `exec` runs (importing scipy and numba runs such code),
# under `python -m`: a finder, installed by a sitecustomize, raises it when a module is looked up —
# while the program loads (bark_cli.main), between loading and the run's own handlers (bark.studies.runner),
# and while the scene is built (the numba backend)
_SIGNAL_IN_EXEC = """
import os, signal, sys
class _Finder:
    def find_spec(self, name, path=None, target=None):
        if name == {module!r}:
            exec("os.kill(os.getpid(), signal.{sig})\\nfor _ in range(100000): pass")
        return None
sys.meta_path.insert(0, _Finder())
"""
BEFORE_THE_RUN = " before the run began: nothing was run"


@pytest.mark.parametrize("module, said", [("bark_cli.main", BEFORE_THE_RUN), ("bark.studies.runner", ""),
                                          ("bark.engine.kernels.numba_backend", BEFORE_THE_RUN)],
                         ids=["loading", "between", "building"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: signal.Signals(s).name)
def test_a_signal_stopping_code_run_by_exec_exits_with_its_status(tmp_path, module, said, sig):
    """CPython ends a `python -m` program by SIGINT at exit (status −2, whatever it asked for) when an
    exact KeyboardInterrupt has left such code; bark's handlers raise their own subclass."""
    hook, out = tmp_path / "hook", tmp_path / "out"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(_SIGNAL_IN_EXEC.format(module=module, sig=signal.Signals(sig).name))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(hook), os.environ.get("PYTHONPATH")])))
    proc = subprocess.run([sys.executable, "-m", "bark_cli", "simulate", "--quiet", "--out", str(out)], cwd=REPO_ROOT,
                          env=env, capture_output=True, text=True)
    reason = "interrupted" if sig == signal.SIGINT else "terminated"
    # (click writes an empty line first when a KeyboardInterrupt reaches it, in the command itself)
    assert (proc.returncode, proc.stderr.lstrip("\n")) == (128 + sig, f"bark: {reason}{said}\n")
    assert not out.exists()


def test_the_drawing_process_does_not_outlive_a_killed_command(tmp_path):
    """The painter (a process that readies matplotlib beside the run) ends when the command is gone,
    even by SIGKILL: it holds no copy of the command's end of their pipe, so it sees it close."""
    out = tmp_path / "out"
    proc = _start(out, "--checkpoint-every", "0.2")
    _wait_for(out / checkpoint.CHECKPOINT_NAME, proc)
    proc.send_signal(signal.SIGKILL)
    proc.wait()

    def left() -> list[int]:
        found = []
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit():
                try:
                    if str(out).encode() in (entry / "cmdline").read_bytes():
                        found.append(int(entry.name))
                except OSError:
                    pass
        return found

    deadline = time.monotonic() + 10
    while left() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert left() == []
    proc.communicate()  # and nothing holds the command's stderr open (this reads it to its end)


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] not in "ZX"
    except OSError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the drawing processes are forked on Linux only")
@pytest.mark.parametrize("kill", [False, True])
def test_two_drawing_processes_share_the_pictures_and_end_together(tmp_path, make_sim, kill):
    """Two drawing processes (the second forked by the first once matplotlib is ready) draw a run's
    pictures as each becomes free: every picture is written, by both; closed, or killed as a signal
    kills them, neither outlives the painter."""
    from bark_cli.pictures import PatternData, Painter

    sim = make_sim(n_bases=300, seed=1)
    sim.run(__import__("bark").Stop(until_time=3.0))
    data = PatternData.of(sim, 7)
    painter = Painter(workers=2)
    waits = [painter.submit("pattern", data, tmp_path / f"p{i}.png", 7) for i in range(4)]
    waits[0]()
    first = painter._proc.pid
    siblings = _children(first)
    assert len(siblings) == 1 and _alive(siblings[0])
    if kill:
        painter.close(kill=True)  # what a wait stopped by a signal does
    else:
        for wait in waits:
            wait()
        assert all((tmp_path / f"p{i}.png").read_bytes()[:4] == b"\x89PNG" for i in range(4))
        painter.close()
    deadline = time.monotonic() + 10
    while (_alive(first) or _alive(siblings[0])) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(first) and not _alive(siblings[0])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the drawing processes are forked on Linux only")
def test_a_picture_whose_data_cannot_be_sent_fails_alone(tmp_path, make_sim):
    """A picture's data that cannot be handed to a drawing process (not picklable) fails that picture
    in one line; the pictures after it are drawn, by the same processes."""
    from bark_cli.pictures import PatternData, Painter

    sim = make_sim(n_bases=300, seed=1)
    data = PatternData.of(sim, 7)
    painter = Painter(workers=2)
    try:
        bad = painter.submit("pattern", lambda: None, tmp_path / "bad.png", 7)
        good = [painter.submit("pattern", data, tmp_path / f"p{i}.png", 7) for i in range(3)]
        with pytest.raises(RuntimeError, match="pickle"):
            bad()
        for wait in good:
            wait()
    finally:
        painter.close()
    assert not (tmp_path / "bad.png").exists() and all((tmp_path / f"p{i}.png").exists() for i in range(3))


@pytest.mark.parametrize("argv, code, out, err", [
    (["--version"], 0, "version", ""),
    (["simulate", "--nosuch"], 2, "", "No such option"),
    (["simulate", "--n-bases", "-5", "--until-time", "1"], 2, "", "--n-bases -5"),
])
def test_the_command_leaves_with_its_status_its_output_and_its_exit_handlers(argv, code, out, err):
    """The command leaves without Python's teardown (``bark_cli.__main__._leave``), but as
    ``sys.exit`` would: the same status, all of its output (through pipes, as a shell gives them),
    and the exit handlers run."""
    program = ("import atexit, sys\n"
               "atexit.register(lambda: print('exit handler ran', flush=True))\n"
               f"sys.argv = ['bark', *{argv!r}]\n"
               "from bark_cli.__main__ import main\n"
               "main()\n"
               "print('never here')\n")
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    assert done.returncode == code, done.stderr
    assert out in done.stdout and done.stdout.rstrip().endswith("exit handler ran")
    assert err in done.stderr and "Traceback" not in done.stderr and "never here" not in done.stdout


def test_a_message_given_to_sys_exit_is_written_and_the_status_is_1():
    program = "from bark_cli.__main__ import _leave\n_leave('bark: gone')\n"
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, cwd=REPO_ROOT, timeout=60)
    assert (done.returncode, done.stderr) == (1, "bark: gone\n")


# a third party's resin law and breaker, each with a declared field (the Zener arm, the quenched
# thresholds), by import path from a folder on PYTHONPATH, on a segment whose bases join as it runs
PLUGINS = ["--scene", "growing", "--n-bases", "1200", "--set", "lattice.n_start=900",
           "--resin", "bark_example_plugin.zener:Zener", "--set", "resin.tau=20",
           "--breaker", "bark_example_plugin.disorder:ParastichyWeibull", "--until-time", "40", "--quiet"]


def _plugin_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "bark_cli", "simulate", *args]


@pytest.mark.slow  # seconds of whole processes: the quick subset (-m "not slow") leaves it out
def test_a_plugin_run_with_declared_fields_stopped_by_sigint_resumes_to_the_same_bits(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT / "examples" / "plugin")}
    whole = tmp_path / "whole"
    done = subprocess.run(_plugin_command(*PLUGINS, "--out", str(whole)), cwd=REPO_ROOT, env=env,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    with np.load(whole / "state.npz") as data:
        assert {"field_arm", "field_threshold"} <= set(data.files)
    out = tmp_path / "out"
    proc = subprocess.Popen(_plugin_command(*PLUGINS, "--checkpoint-every", "0.05", "--out", str(out)),
                            cwd=REPO_ROOT, env=env, stderr=subprocess.PIPE, text=True)
    _wait_for_time(out, proc, 20.0)  # bases still joining, springs breaking
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate()
    assert proc.returncode == 130 and "Traceback" not in err, err
    resumed = subprocess.run(_plugin_command("--resume", str(out), "--quiet"), cwd=REPO_ROOT, env=env,
                             capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    for name in ("breaks.csv", "state.npz"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name


def _session_members(sid: int) -> list[int]:
    """The processes of session ``sid`` still alive (``/proc``: field 6 of stat is the session)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rpartition(")")[2].split()
            except OSError:  # gone meanwhile
                continue
            if int(fields[3]) == sid and fields[0] != "Z":
                found.append(int(entry.name))
    return found


@pytest.mark.slow  # seconds of whole processes: the quick subset (-m "not slow") leaves it out
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="a pseudo-terminal and /proc")
def test_a_run_whose_terminal_goes_away_stops_leaves_no_process_and_resumes(uninterrupted, tmp_path):
    """The run's terminal hangs up mid-run (a tmux session killed, an ssh connection lost): the
    kernel sends SIGHUP and every later write to the terminal fails (EIO).  The run stops between
    two steps with a checkpoint, no process of it is left (its drawing processes included), and
    ``--resume`` ends as the run never stopped."""
    import fcntl
    import pty
    import termios

    out = tmp_path / "out"
    master, slave = pty.openpty()

    def own_terminal():  # a session of its own, the pseudo-terminal its controlling terminal
        fcntl.ioctl(0, termios.TIOCSCTTY, 0)

    argv = [a for a in LONG if a != "--quiet"]  # the progress bar on the terminal, as a user has it
    proc = subprocess.Popen([sys.executable, "-m", "bark_cli", "simulate", *argv, "--out", str(out)], cwd=REPO_ROOT,
                            stdin=slave, stdout=slave, stderr=slave, start_new_session=True, preexec_fn=own_terminal,
                            env={**os.environ, "TERM": "tmux-256color"})  # a terminal that shows the bar as it goes
    os.close(slave)
    shown = b""
    while shown.count(b"t=") < 3:  # the bar's third showing: the run is well on its way
        try:
            chunk = os.read(master, 4096)
        except OSError:  # the command ended and closed the terminal
            chunk = b""
        assert chunk, f"the run ended before it showed its progress: {shown.decode(errors='replace')}"
        shown += chunk
    os.close(master)  # the terminal goes away
    try:
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 128 + signal.SIGHUP or proc.returncode == 128 + signal.SIGTERM, proc.returncode
    deadline = time.monotonic() + 30  # the drawing processes see the command's pipe close
    while _session_members(proc.pid):
        assert time.monotonic() < deadline, f"processes of the run left behind: {_session_members(proc.pid)}"
        time.sleep(0.05)
    assert checkpoint.read_meta(out / checkpoint.CHECKPOINT_NAME)["reason"] == "interrupted"
    again = _resume(out)
    assert again.returncode == 0, again.stderr
    for name in COMPARED:
        assert (out / name).read_bytes() == (uninterrupted / name).read_bytes(), name


# The final writes of whole-tree-small, in the order they become visible: the end checkpoint, the
# data files, the pictures (drawn meanwhile in other processes, so their order may vary) and last
# summary.json.  A SIGKILL to the whole process group as each appears lands spread over those writes
# (all eleven: checkpoint.npz, breaks.csv, state.npz, statistics.csv, tree.vtu, tree.ply, pattern.png,
# development.gif, tree-series.png, regions.png, summary.json; six here, to keep CI's time).
FINAL_WRITES = ("checkpoint.npz", "state.npz", "tree.ply", "pattern.png", "development.gif", "summary.json")
TREE = ["--scene", "whole-tree-small", "--quiet"]


@pytest.fixture(scope="module")
def whole_tree_small(tmp_path_factory):
    out = tmp_path_factory.mktemp("tree") / "out"
    proc = subprocess.run([sys.executable, "-m", "bark_cli", "simulate", *TREE, "--out", str(out)], cwd=REPO_ROOT,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return out


def _ended(out: Path, name: str) -> bool:
    """Whether the run's final write of ``name`` is visible: the end checkpoint, or the file there."""
    if name != checkpoint.CHECKPOINT_NAME:
        return (out / name).exists()
    try:
        return checkpoint.read_meta(out / name).get("reason") == "end"
    except (OSError, checkpoint.Damaged):
        return False


@pytest.mark.slow  # seconds of whole processes: the quick subset (-m "not slow") leaves it out
@pytest.mark.parametrize("instant", FINAL_WRITES)
def test_a_kill_anywhere_in_the_final_writes_is_finished_by_resume(instant, whole_tree_small, tmp_path):
    """SIGKILL (the command and its drawing processes) as each of the final writes appears, then
    ``--resume``: every file of the uninterrupted run is there, the data byte-identical."""
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "bark_cli", "simulate", *TREE, "--out", str(out)], cwd=REPO_ROOT,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + 600
    while not _ended(out, instant) and proc.poll() is None:
        assert time.monotonic() < deadline, f"{instant} never appeared"
        time.sleep(0.005)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    if (out / "summary.json").exists():  # it had finished: summary.json is written last
        assert {p.name for p in whole_tree_small.iterdir()} <= {p.name for p in out.iterdir()}
    again = _resume(out)
    assert again.returncode in (0, 2), again.stderr  # 2: it had ended whole ("nothing to resume")
    assert {p.name for p in whole_tree_small.iterdir()} <= {p.name for p in out.iterdir()}
    for name in ("breaks.csv", "state.npz", "patches.csv", "statistics.csv", "tree.vtu", "tree.ply", "scene.toml"):
        assert (out / name).read_bytes() == (whole_tree_small / name).read_bytes(), name
