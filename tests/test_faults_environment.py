"""Fault injection, the environment of a shared node: numba's variables, caches that cannot be
written or are damaged, a home that does not exist.  Each is said in one line (``bark: warning:``)
and the run goes to its end; nothing ends in a traceback."""

from __future__ import annotations

import errno
import os
import pickle
import shutil
import subprocess
import sys
import tempfile
import textwrap
import warnings
from pathlib import Path

import pytest

from bark.engine import kernels
from bark.engine.kernels import numba_env
from bark.errors import BarkError, BarkWarning

from conftest import REPO_ROOT, as_a_user_who_cannot_write, slow_cases

numba_backend = pytest.importorskip("bark.engine.kernels.numba_backend")


def _bark(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bark_cli", *args], cwd=REPO_ROOT, capture_output=True,
                          text=True, env={**os.environ, **(env or {})}, timeout=900)


def _assert_ran_to_the_end(proc: subprocess.CompletedProcess, out: Path) -> list[str]:
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.splitlines()
    assert all(line.startswith("bark: ") for line in lines), proc.stderr
    assert (out / "summary.json").exists() and (out / "state.npz").exists()
    return lines


@pytest.mark.parametrize("value", ["0", "abc", *slow_cases("-1", "1.5", "", " ")])
def test_a_thread_count_numba_would_fail_on_is_ignored_in_one_line(value, tmp_path):
    out = tmp_path / "run"
    proc = _bark("simulate", "--backend", "numba", "--until-time", "5", "--quiet", "--out", str(out),
                 env={"NUMBA_NUM_THREADS": value})
    lines = _assert_ran_to_the_end(proc, out)
    assert [line for line in lines if "NUMBA_NUM_THREADS" in line] == [line for line in lines if "warning" in line]
    assert len([line for line in lines if "NUMBA_NUM_THREADS" in line]) == 1, proc.stderr


def test_the_default_run_goes_to_its_end_with_numba_num_threads_zero(tmp_path):
    out = tmp_path / "run"
    proc = _bark("simulate", "--quiet", "--out", str(out), env={"NUMBA_NUM_THREADS": "0"})
    _assert_ran_to_the_end(proc, out)


def test_a_valid_thread_count_is_kept_and_says_nothing(monkeypatch):
    monkeypatch.setenv("NUMBA_NUM_THREADS", "3")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert numba_env.thread_count() == 3
    assert os.environ["NUMBA_NUM_THREADS"] == "3"


@pytest.mark.parametrize("make", ["file", "missing-parent-file", "proc", "sys"])
def test_an_unusable_numba_cache_dir_is_ignored_in_one_line(make, tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    given = {"file": str(blocker), "missing-parent-file": str(blocker / "sub"), "proc": "/proc/bark-cache",
             "sys": "/sys/bark-cache"}[make]
    monkeypatch.setenv("NUMBA_CACHE_DIR", given)
    with pytest.warns(BarkWarning, match="NUMBA_CACHE_DIR"):
        numba_env._numba_cache()
    assert os.environ.get("NUMBA_CACHE_DIR") != given


def _unset(monkeypatch, name: str) -> None:
    """``name`` removed from the environment for this test, and whatever the code under test sets it
    to undone afterwards (``delenv`` of a variable that is not set records nothing to undo)."""
    monkeypatch.setenv(name, "")
    monkeypatch.delenv(name)


def test_with_nowhere_numba_would_cache_the_cache_moves_to_bark_s_folder(tmp_path, monkeypatch):
    _unset(monkeypatch, "NUMBA_CACHE_DIR")
    monkeypatch.setenv("BARK_CACHE_DIR", str(tmp_path / "bark-cache"))
    monkeypatch.setattr(numba_env, "writable", lambda folder: str(folder).startswith(str(tmp_path)))
    with pytest.warns(BarkWarning, match="caching it in"):
        numba_env._numba_cache()
    assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "bark-cache" / "numba")


def test_with_no_folder_at_all_auto_runs_on_numpy_and_numba_is_refused_in_one_line(monkeypatch):
    real = kernels.importlib.import_module

    def unloadable(name, *args):
        if name.endswith("numba_backend"):
            raise OSError("no writable folder for numba's cache")
        return real(name, *args)

    monkeypatch.setattr(kernels.importlib, "import_module", unloadable)
    monkeypatch.setattr(kernels, "resolve", lambda name, work=None: "numba")
    with pytest.warns(BarkWarning, match="running on numpy"):
        assert kernels.load("auto").name == "numpy"
    with pytest.raises(BarkError, match="cannot be loaded here"):
        kernels.load("numba")


@pytest.mark.parametrize("make", ["file", "under-a-file", "proc"])
def test_an_unusable_bark_cache_dir_falls_back_to_the_temporary_folder_in_one_line(make, tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("BARK_CACHE_DIR", {"file": str(blocker), "under-a-file": str(blocker / "x"),
                                          "proc": "/proc/bark-cache"}[make])
    text = '"""a generated kernel"""\n'
    with pytest.warns(BarkWarning, match="cannot be written"):
        path = numba_backend._write_once("bark_test_fallback", text)
    assert path.read_text() == text and not str(path).startswith(str(blocker))


@pytest.mark.parametrize("damage", [b"x\x00y", b"", "truncated"])
def test_a_damaged_generated_kernel_is_written_again(damage, tmp_path, monkeypatch):
    monkeypatch.setenv("BARK_CACHE_DIR", str(tmp_path))
    text = '"""a generated kernel"""\nVALUE = 1\n'
    path = numba_backend._write_once("bark_test_damaged", text)
    path.write_bytes(text.encode()[:10] if damage == "truncated" else damage)
    assert numba_backend._write_once("bark_test_damaged", text).read_text() == text


_CACHED = '''
import numba

@numba.njit(cache=True)
def plus_one(x):
    return x + 1
'''


@pytest.mark.parametrize("damage", ["both", *slow_cases("index", "data", "truncated-index")])
def test_a_damaged_numba_cache_entry_is_removed_and_compiled_again(damage, tmp_path):
    """numba itself stops with a traceback on a garbled cache file; bark removes such an entry, says
    so in one line, and numba compiles the function again (and caches it afresh)."""
    module = tmp_path / "cached_module.py"
    module.write_text(_CACHED)
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    env.pop("NUMBA_CACHE_DIR", None)
    use = "import cached_module; assert cached_module.plus_one(1) == 2"
    subprocess.run([sys.executable, "-c", use], env=env, check=True, timeout=300)
    cache = tmp_path / "__pycache__"
    index, data = next(cache.glob("cached_module.*.nbi")), next(cache.glob("cached_module.*.nbc"))
    targets = {"index": [index], "data": [data], "both": [index, data], "truncated-index": [index]}[damage]
    for target in targets:
        target.write_bytes(target.read_bytes()[:20] if damage == "truncated-index" else os.urandom(64))
    check = textwrap.dedent(f"""
        import warnings
        from pathlib import Path
        from bark.engine.kernels.numba_backend import _drop_damaged
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            _drop_damaged(Path({str(module)!r}))
        print(len(seen), seen[0].message if seen else "")
        {use}
    """)
    proc = subprocess.run([sys.executable, "-c", check], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("1 ") and "damaged" in proc.stdout, proc.stdout
    assert next(cache.glob("cached_module.*.nbi"), None) is not None  # cached afresh
    with open(next(cache.glob("cached_module.*.nbi")), "rb") as fh:
        pickle.load(fh)


def test_an_undamaged_cache_entry_is_kept(tmp_path):
    module = tmp_path / "kept_module.py"
    module.write_text(_CACHED)
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    env.pop("NUMBA_CACHE_DIR", None)
    subprocess.run([sys.executable, "-c", "import kept_module; kept_module.plus_one(1)"], env=env, check=True,
                   timeout=300)
    before = sorted(p.name for p in (tmp_path / "__pycache__").iterdir())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        numba_backend._drop_damaged(module)
    assert sorted(p.name for p in (tmp_path / "__pycache__").iterdir()) == before


def test_matplotlib_gets_a_writable_folder_in_one_line(tmp_path, monkeypatch):
    from bark_cli import matplotlib_folder

    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    _unset(monkeypatch, "MPLCONFIGDIR")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(blocker))
    with pytest.warns(BarkWarning, match="matplotlib"):
        matplotlib_folder()
    assert numba_env.writable(Path(os.environ["MPLCONFIGDIR"]))


@pytest.mark.slow
def test_the_default_run_goes_to_its_end_with_a_home_that_cannot_be_written(tmp_path):
    """The acceptance case: ``HOME=/nonexistent bark simulate`` as a user who cannot write there."""
    prefix = as_a_user_who_cannot_write()
    work = Path(tempfile.mkdtemp(prefix="bark-nobody-"))  # pytest's own folders are root's alone
    try:
        work.chmod(0o777)
        out = work / "run"
        env = {k: v for k, v in os.environ.items()
               if k not in ("XDG_CACHE_HOME", "XDG_CONFIG_HOME", "BARK_CACHE_DIR", "NUMBA_CACHE_DIR", "MPLCONFIGDIR")}
        proc = subprocess.run([*prefix, sys.executable, "-m", "bark_cli", "simulate", "--quiet", "--out", str(out)],
                              cwd=REPO_ROOT, capture_output=True, text=True, env={**env, "HOME": "/nonexistent"},
                              timeout=900)
        lines = _assert_ran_to_the_end(proc, out)
        assert all(line.startswith("bark: warning: ") for line in lines), proc.stderr
    finally:
        shutil.rmtree(work, ignore_errors=True)


# -- a process limit (ulimit -u) that leaves no room ---------------------------------------------


def test_a_sweep_that_cannot_start_its_workers_is_one_line(tmp_path, monkeypatch):
    from click.testing import CliRunner

    import concurrent.futures
    from bark_cli.main import cli

    def no_room(*args, **kwargs):
        raise BlockingIOError(errno.EAGAIN, "Resource temporarily unavailable")

    monkeypatch.setattr(concurrent.futures, "ProcessPoolExecutor", no_room)
    result = CliRunner().invoke(cli, ["sweep", "--grid", "growth.G=0.03,0.04", "--set", "lattice.n_bases=300",
                                      "--set", "run.until_time=5", "--workers", "2", "--quiet", "--out", str(tmp_path / "s")])
    assert result.exit_code == 1, result.output
    assert result.stderr.count("\n") == 1 and "ulimit -u" in result.stderr, result.stderr


def test_a_run_that_cannot_fork_its_painter_draws_its_pictures_itself(tmp_path, monkeypatch):
    import multiprocessing.process

    from click.testing import CliRunner

    from bark_cli.main import cli

    def no_room(self):
        raise BlockingIOError(errno.EAGAIN, "Resource temporarily unavailable")

    monkeypatch.setattr(multiprocessing.process.BaseProcess, "start", no_room)
    out = tmp_path / "run"
    result = CliRunner().invoke(cli, ["simulate", "--n-bases", "300", "-G", "0.05", "--until-time", "6", "--quiet",
                                      "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert (out / "pattern.png").exists() and (out / "summary.json").exists()


@pytest.mark.parametrize("soft, threads", [(1, "1"), (10_000_000, None)])
def test_blas_threads_are_kept_to_one_where_processes_are_few(soft, threads, monkeypatch):
    import resource

    import bark_cli.__main__ as entry

    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.setenv(name, "")
        monkeypatch.delenv(name)
    monkeypatch.setattr(resource, "getrlimit", lambda which: (soft, soft))
    entry._few_threads_where_processes_are_few()
    assert os.environ.get("OPENBLAS_NUM_THREADS") == threads


_OTHER_BARKS = {
    "a package whose import fails": {"bark/__init__.py": "import torch_that_is_not_here\n"},
    "a package that imports": {"bark/__init__.py": "SAMPLE_RATE = 24_000\n", "bark/generation.py": ""},
    "a module": {"bark.py": "def generate_audio(text): ...\n"},
}


@pytest.mark.parametrize("other", list(_OTHER_BARKS))
def test_another_projects_bark_ahead_of_ours_is_one_line(other, tmp_path):
    """The package index's "bark" (text to audio) installed over bark's package, as a plugin that
    depended on "bark" did: every command says so in one line, and how to mend it."""
    for name, text in _OTHER_BARKS[other].items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    for argv in (["strategies"], ["simulate", "--n-bases", "300", "--until-time", "1", "--out", str(tmp_path / "out")]):
        proc = subprocess.run([sys.executable, "-m", "bark_cli", *argv], cwd=tmp_path, capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(tmp_path)}, timeout=600)
        lines = proc.stderr.splitlines()
        assert proc.returncode == 1 and len(lines) == 1, proc.stderr
        assert lines[0].startswith("bark: error: ") and "bark-grasstree" in lines[0], proc.stderr
        assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("backend", ["nosuch", "qtagg", *slow_cases("tkagg", "")])
def test_any_mplbackend_leaves_the_pictures_drawn(backend, tmp_path):
    """A user's MPLBACKEND (a window backend for their own sessions, or a mistyped one) broke every
    picture with a traceback from the drawing process; bark's commands draw into files with Agg."""
    out = tmp_path / "run"
    proc = _bark("simulate", "--n-bases", "300", "--until-time", "2", "--quiet", "--out", str(out),
                 env={"MPLBACKEND": backend})
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert (out / "pattern.png").stat().st_size > 0
    proc = _bark("analyze", str(out), "--out", str(tmp_path / "analysis"), env={"MPLBACKEND": backend})
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr


@pytest.mark.parametrize("value, kept", [("nosuch", False), ("", False), ("omp ", True), ("workqueue", True),
                                         ("Safe", True), ("tbb,omp", False)])
def test_a_threading_layer_numba_does_not_know_is_ignored_in_one_line(value, kept, monkeypatch):
    """NUMBA_THREADING_LAYER=nosuch ended a threaded run with numba's ValueError at its first
    threaded step; such a value is now removed before numba is imported, said in one line."""
    monkeypatch.setenv("NUMBA_THREADING_LAYER", value)
    if kept:
        numba_env.threading_layer()
        assert os.environ["NUMBA_THREADING_LAYER"] == value
        return
    with pytest.warns(BarkWarning, match="is not a threading layer numba knows .*: ignored"):
        numba_env.threading_layer()
    assert "NUMBA_THREADING_LAYER" not in os.environ
