"""bark sweep: grids, the SQLite table, resuming after a killed worker or sweep, Dask."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from bark.errors import BarkError
from bark.studies.sweep import Axis, Sweep, SweepTable, run_sweep
from bark_cli.main import cli

TINY = {"lattice": {"n_bases": 300}, "run": {"until_time": 20.0}}
"""Runs of a fraction of a second (300 bases; the default scene's mechanics)."""
TINY_SET = ["--set", "lattice.n_bases=300", "--set", "run.until_time=20"]
SLOW_SET = ["--set", "lattice.n_bases=3000", "--set", "run.backend='numpy'", "--set", "run.stepping='fixed'",
            "--set", "run.dt=0.01", "--set", "run.until_time=40"]
"""Runs of about a second each: long enough to stop a sweep in the middle."""
VOLATILE = ("wall_s", "finished")


def _rows(db) -> list[dict]:
    with SweepTable(db) as t:
        return [{k: v for k, v in r.items() if k not in VOLATILE} for r in t.rows()]


BULGED = {**TINY, "growth": {"name": "bulge", "base": {"name": "sqrt", "G": 0.014},
                              "bulges": [{"z": 0.07, "half_width": 0.03, "magnitude": 0.01}]},
          "breaker": {"name": "threshold", "regions": {"bulge": 0.004}}}
"""TINY with one bulge: settings inside its tables and arrays of tables to sweep."""


def _grid(n=2):
    return (Axis("growth.G", [0.01 + 0.01 * i for i in range(n)]), Axis("mechanics.f_max", (0.003, 0.006)))


# -- the grid ---------------------------------------------------------------------------------------
def test_points_cover_the_grid_and_seeds_with_distinct_keys():
    points = Sweep(base=TINY, axes=_grid(3), seeds=(0, 1)).points()
    assert len(points) == 3 * 2 * 2
    assert len({p.key for p in points}) == len(points)
    assert points[0].settings == {"growth.G": 0.01, "mechanics.f_max": 0.003} and points[0].seed == 0
    assert points[1].seed == 1 and points[1].scene["run"]["seed"] == 1
    again = Sweep(base=TINY, axes=_grid(3), seeds=(0, 1)).points()
    assert [p.key for p in again] == [p.key for p in points]  # the key is the scene's, not the order's


@pytest.mark.parametrize("make,message", [
    (lambda: Axis("G", (1.0,)), "expected SECTION.KEY"),
    (lambda: Axis("growth.G", ()), "no values"),
    (lambda: Sweep(base={}, axes=(Axis("growth.G", (1.0, 1.0)),)), "given twice"),
    (lambda: Sweep(base={}, axes=(Axis("growth.G", (1.0,)), Axis("growth.G", (2.0,)))), "an axis is given twice"),
    (lambda: Sweep(base={}, axes=(Axis("run.seed", (1, 2)),)), "seeds are not an axis"),
    (lambda: Sweep(base={}, axes=(Axis("growth.G", (0.01, -1.0)),)).points(), "G"),
    (lambda: Sweep(base={}, axes=(Axis("growth.G", (0.01, float("nan"))),)).points(), "G"),
    (lambda: Sweep(base={}, axes=(Axis("mechanics.nonsense", (1.0,)),)).points(), "nonsense"),
    (lambda: Sweep(base=BULGED, axes=(Axis("growth.bulges.1.magnitude", (0.1,)),)).points(),
     "growth.bulges is an array of 1 table; give an index from 0 to 0"),
    (lambda: Sweep(base=BULGED, axes=(Axis("growth.bulges.first.magnitude", (0.1,)),)).points(), "give an index"),
    (lambda: Sweep(base=BULGED, axes=(Axis("growth.base.G.x", (0.1,)),)).points(), "growth.base.G is not a table"),
    (lambda: Sweep(base=BULGED, axes=(Axis("growth.bulges.0.magnitude", (-0.1,)),)).points(), "magnitude"),
])
def test_a_bad_grid_is_one_line_before_any_run(make, message):
    with pytest.raises(BarkError) as err:
        make()
    assert message in str(err.value) and "\n" not in str(err.value)


def test_an_axis_reaches_into_tables_and_arrays_of_tables_and_changes_only_its_value():
    plan = Sweep(base=BULGED, axes=(Axis("growth.bulges.0.magnitude", (0.0, 0.02)), Axis("breaker.regions.bulge", (0.005,)),
                                    Axis("growth.base.G", (0.011,))), seeds=(0,))
    points = plan.points()
    assert [p.scene["growth"]["bulges"][0]["magnitude"] for p in points] == [0.0, 0.02]
    for p in points:
        assert p.scene["growth"]["bulges"][0]["half_width"] == 0.03 and p.scene["breaker"]["regions"] == {"bulge": 0.005}
        assert p.scene["growth"]["base"] == {"name": "sqrt", "G": 0.011}
        assert p.checked.strategies["growth"].bulges[0].magnitude == p.settings["growth.bulges.0.magnitude"]
    assert BULGED["growth"]["bulges"][0]["magnitude"] == 0.01  # the base scene is not changed
    flat = Sweep(base=TINY, axes=_grid(2)).points()  # keys of sweeps without such axes are those of before
    assert [p.scene for p in flat] == [{**TINY, "growth": {"G": g}, "mechanics": {"f_max": f}, "run": {**TINY["run"], "seed": 0}}
                                       for g in (0.01, 0.02) for f in (0.003, 0.006)]


def test_a_grid_inside_an_array_of_tables_runs_and_is_named_as_typed(tmp_path):
    scene = tmp_path / "bulged.toml"
    scene.write_text('[lattice]\nn_bases = 300\n[growth]\nname = "bulge"\nbase = { name = "sqrt" }\n'
                     'bulges = [{ z = 0.07, half_width = 0.03 }]\n[run]\nuntil_time = 20.0\n')
    out = CliRunner().invoke(cli, ["sweep", "--scene", str(scene), "--grid", "growth.bulges.0.magnitude=0,0.02",
                                   "--out", str(tmp_path / "s"), "--quiet"])
    assert out.exit_code == 0, out.output
    con = sqlite3.connect(tmp_path / "s" / "sweep.sqlite")
    assert sorted(v for (v,) in con.execute('SELECT "growth.bulges.0.magnitude" FROM runs')) == [0.0, 0.02]
    bad = CliRunner().invoke(cli, ["sweep", "--scene", str(scene), "--grid", "growth.bulges.2.magnitude=0.1",
                                   "--out", str(tmp_path / "t"), "--quiet"])
    assert bad.exit_code != 0 and "growth.bulges.2.magnitude" in bad.output and not (tmp_path / "t").exists()


# -- the table and resuming -------------------------------------------------------------------------
def test_a_sweep_run_again_runs_nothing_again(tmp_path):
    db = tmp_path / "s.sqlite"
    plan = Sweep(base=TINY, axes=_grid(2))
    first = run_sweep(plan, db, workers=2)
    assert first == {"total": 4, "skipped": 0, "ran": 4}
    assert run_sweep(plan, db, workers=2) == {"total": 4, "skipped": 4, "ran": 0}
    bigger = Sweep(base=TINY, axes=_grid(3))  # one more column of points: only those run
    assert run_sweep(bigger, db, workers=1) == {"total": 6, "skipped": 4, "ran": 2}
    con = sqlite3.connect(db)  # any SQL client reads it
    got = con.execute('SELECT "growth.G", "mechanics.f_max", n_patches, n_broken FROM runs ORDER BY 1, 2').fetchall()
    con.close()
    assert len(got) == 6 and all(r[3] >= 0 for r in got)


@pytest.mark.slow
def test_the_table_does_not_depend_on_the_number_of_workers(tmp_path):
    plan = Sweep(base=TINY, axes=_grid(2), seeds=(0, 1))
    run_sweep(plan, tmp_path / "one.sqlite", workers=1)
    run_sweep(plan, tmp_path / "two.sqlite", workers=2)
    assert _rows(tmp_path / "one.sqlite") == _rows(tmp_path / "two.sqlite")


@pytest.mark.slow  # seconds of whole processes: the quick subset (-m "not slow") leaves it out
def test_the_same_sweep_on_dask_gives_the_same_table(tmp_path):
    distributed = pytest.importorskip("distributed")
    plan = Sweep(base=TINY, axes=_grid(2), seeds=(0, 1))
    run_sweep(plan, tmp_path / "local.sqlite", workers=2)
    grid = [*TINY_SET, "--grid", "growth.G=0.01,0.02", "--grid", "mechanics.f_max=0.003,0.006", "--seeds", "2", "--quiet"]
    r = CliRunner().invoke(cli, ["sweep", *grid, "--workers", "2", "--out", str(tmp_path / "cli-local")])
    assert r.exit_code == 0, r.output
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        counts = run_sweep(plan, tmp_path / "dask.sqlite", client=client)
        assert counts["ran"] == 8
        r = CliRunner().invoke(cli, ["sweep", *grid, "--dask", cluster.scheduler_address, "--out", str(tmp_path / "cli-dask")])
        assert r.exit_code == 0, r.output
    assert _rows(tmp_path / "local.sqlite") == _rows(tmp_path / "dask.sqlite")
    assert _rows(tmp_path / "cli-local" / "sweep.sqlite") == _rows(tmp_path / "cli-dask" / "sweep.sqlite")
    assert len(_rows(tmp_path / "cli-dask" / "sweep.sqlite")) == 8


@pytest.mark.slow  # a Dask cluster started: seconds
def test_a_dask_sweep_with_no_worker_left_says_so_instead_of_waiting(tmp_path):
    """Every worker gone, a sweep waited without a word until Ctrl-C; now it says so within a few
    seconds (a warning: made an error here, by the suite's filter, so the wait ends)."""
    from bark.errors import BarkWarning

    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        with pytest.raises(BarkWarning, match=f"no Dask worker is left at {cluster.scheduler_address}: 2 runs wait"):
            run_sweep(Sweep(base=TINY, axes=_grid(1)), tmp_path / "s.sqlite", client=client)
    assert _rows(tmp_path / "s.sqlite") == []


def test_a_damaged_database_is_one_line(tmp_path):
    db = tmp_path / "s.sqlite"
    db.write_bytes(b"this is not sqlite, but long enough to look like a file header" * 4)
    with pytest.raises(BarkError, match="not a sweep database"):
        run_sweep(Sweep(base=TINY, axes=_grid(1)), db)


def test_each_row_holds_the_run_s_largest_patch_share_and_its_regions_as_json(tmp_path):
    """A trunk with a bulge: the row's ``regions`` is summary.json's per-region statistics, strict
    JSON that SQLite's ``json_extract`` reads; a trunk of one region has none."""
    from bark.engine.scene import Scene, merge
    from bark.io.files import json_text
    from bark.studies import runner

    bulge = merge(TINY, {"growth": {"name": "bulge", "bulges": [{"z": 0.07, "half_width": 0.03, "magnitude": 0.01}]}})
    db = tmp_path / "s.sqlite"
    run_sweep(Sweep(base=bulge, axes=(Axis("mechanics.f_max", (0.002, 0.003)),)), db)
    with SweepTable(db) as table:
        rows = table.rows()
        got = table.con.execute("SELECT json_extract(regions, '$.straight.n_bases'), "
                                "json_extract(regions, '$.bulge.largest_patch_share') FROM runs").fetchall()
    plan = Sweep(base=bulge, axes=(Axis("mechanics.f_max", (0.002,)),)).points()[0]
    summary = runner.run(Scene.from_dict(plan.scene), None).summary
    row = next(r for r in rows if r["key"] == plan.key)
    assert row["largest_patch_share"] == summary["largest_patch_share"] and 0 < row["largest_patch_share"] <= 1
    assert json.loads(row["regions"]) == json.loads(json_text(summary["regions"]))
    assert all(n == summary["regions"]["straight"]["n_bases"] for n, _ in got) and all(0 < s <= 1 for _, s in got)
    run_sweep(Sweep(base=TINY, axes=(Axis("mechanics.f_max", (0.002,)),)), tmp_path / "plain.sqlite")
    with SweepTable(tmp_path / "plain.sqlite") as table:
        assert [r["regions"] for r in table.rows()] == [None]


def test_a_table_of_an_earlier_bark_gets_the_columns_added_since(tmp_path):
    import sqlite3

    from bark.studies.sweep import RESULT_COLUMNS, SweepTable

    db = tmp_path / "old.sqlite"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE runs (key TEXT PRIMARY KEY, point TEXT NOT NULL, seed INTEGER NOT NULL, n_patches INTEGER, "
                "wall_s REAL, finished TEXT, bark_version TEXT, scene TEXT NOT NULL)")
    con.commit()
    con.close()
    with SweepTable(db) as table:
        assert set(RESULT_COLUMNS) <= set(table.columns())
    plan = Sweep(base=TINY, axes=_grid(1))
    run_sweep(plan, db)
    assert len(_rows(db)) == len(plan.points())


def _made(tmp_path) -> Path:
    """A sweep table of two finished runs."""
    db = tmp_path / "s.sqlite"
    run_sweep(Sweep(base=TINY, axes=(Axis("growth.G", (0.02, 0.03)),)), db)
    return db


def _edit(db: Path, sql: str, *args) -> None:
    con = sqlite3.connect(db)
    with con:
        con.execute(sql, args)
    con.close()


@pytest.mark.parametrize("damage, says", [
    (lambda db: _edit(db, "UPDATE runs SET n_patches = 'many'"), "its n_patches is 'many', not a number"),
    (lambda db: _edit(db, "UPDATE runs SET mean_orientation_deg = 'north'"), "not a number"),
    (lambda db: _edit(db, "UPDATE patterns SET uv = ?", b"short"), "pattern of run"),
    (lambda db: _edit(db, "UPDATE patterns SET n = n + 1"), "pattern of run"),
    (lambda db: _edit(db, "UPDATE patterns SET labels = 'text'"), "pattern of run"),
])
def test_a_table_edited_into_nonsense_is_one_line_when_read(damage, says, tmp_path):
    db = _made(tmp_path)
    damage(db)
    with SweepTable(db) as table, pytest.raises(BarkError, match=says):
        table.rows()
        for key in table.done():
            table.pattern(key)


def test_a_damaged_page_is_one_line_and_the_command_says_it(tmp_path):
    out = tmp_path / "s"
    args = ["sweep", *TINY_SET, "--grid", "growth.G=0.02,0.03", "--out", str(out), "--quiet"]
    assert CliRunner().invoke(cli, args).exit_code == 0
    con = sqlite3.connect(out / "sweep.sqlite")
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    con.close()
    raw = bytearray((out / "sweep.sqlite").read_bytes())
    raw[4096:8192] = os.urandom(4096)  # a page of the table's b-tree
    (out / "sweep.sqlite").write_bytes(bytes(raw))
    r = CliRunner().invoke(cli, args)
    assert r.exit_code in (1, 2), r.output
    assert "Traceback" not in r.output and r.stderr.count("\n") == 1 and "sweep.sqlite" in r.stderr, r.stderr


def test_another_program_s_runs_table_is_refused_untouched(tmp_path):
    db = tmp_path / "theirs.sqlite"
    _edit(db, "CREATE TABLE runs (id INTEGER PRIMARY KEY, title TEXT)")
    with pytest.raises(BarkError, match="another's"):
        run_sweep(Sweep(base=TINY, axes=_grid(1)), db)
    con = sqlite3.connect(db)
    assert [r[1] for r in con.execute("PRAGMA table_info(runs)")] == ["id", "title"]
    assert [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")] == ["runs"]
    con.close()


def test_ten_thousand_points_are_checked_at_once_and_a_hundred_million_refused():
    """Every point's scene is checked before the first runs: ten thousand of them take a fraction of
    what the entry-point scans per point took (6 ms each: a minute); a grid beyond MAX_RUNS is refused
    before a point is made."""
    from bark.contract import registry
    from bark.studies.sweep import MAX_RUNS

    registry.refresh()
    scans = []
    real = registry.entry_points
    registry.entry_points = lambda **kw: (scans.append(kw), real(**kw))[1]
    try:
        points = Sweep(base=TINY, axes=(Axis("growth.G", tuple(0.01 + i * 1e-6 for i in range(10_000))),)).points()
    finally:
        registry.entry_points = real
    assert len(points) == 10_000 and len(scans) <= len(registry.GROUPS) + 1  # once a group, not once a point
    with pytest.raises(BarkError, match="100,000,000 runs"):
        Sweep(base=TINY, axes=(Axis("growth.G", tuple(range(1, 10_001))), Axis("mechanics.f_max", tuple(range(1, 10_001)))))
    assert MAX_RUNS < 10**8


@pytest.mark.slow  # the deadline: 15 s
def test_dask_pointed_at_a_web_server_is_one_line_within_its_deadline(tmp_path):
    import http.server
    import threading

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        out = tmp_path / "s"
        args = [sys.executable, "-m", "bark_cli", "sweep", *TINY_SET, "--grid", "growth.G=0.02", "--quiet",
                "--dask", f"tcp://127.0.0.1:{server.server_address[1]}", "--out", str(out)]
        proc = subprocess.run(args, capture_output=True, text=True, timeout=60)
    finally:
        server.shutdown()
        server.server_close()
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("bark: error: --dask") and proc.stderr.count("\n") == 1, proc.stderr
    assert not out.exists()


def test_a_stop_in_the_middle_of_a_commit_ends_the_workers_at_once(tmp_path):
    """A signal that lands while a result is committed (in the caller, not in the wait for workers)
    closes the local workers then, not at the interpreter's exit, which would wait for them."""
    import multiprocessing

    def stop_after_the_first(done, total, point):
        if point is not None:
            raise KeyboardInterrupt

    plan = Sweep(base=TINY, axes=(Axis("growth.G", tuple(0.01 + 0.001 * i for i in range(40))),))
    with pytest.raises(KeyboardInterrupt):
        run_sweep(plan, tmp_path / "s.sqlite", workers=2, progress=stop_after_the_first)
    deadline = time.monotonic() + 60
    while multiprocessing.active_children():  # the workers end (terminated): an observable state, not a wait
        assert time.monotonic() < deadline, multiprocessing.active_children()
        time.sleep(0.02)
    assert len(_rows(tmp_path / "s.sqlite")) >= 1


def test_a_sweep_folder_holds_one_sweep_at_a_time(tmp_path):
    from bark.io.folder import held_folder

    out = tmp_path / "s"
    with held_folder(out):  # a sweep writing there
        r = CliRunner().invoke(cli, ["sweep", *TINY_SET, "--grid", "growth.G=0.02", "--out", str(out), "--quiet"])
    assert r.exit_code == 2 and f"(process {os.getpid()}) is writing there" in r.stderr, r.output
    assert not (out / "sweep.sqlite").exists()


# -- the command ------------------------------------------------------------------------------------
def test_sweep_command_writes_its_table_and_montage(tmp_path):
    out = tmp_path / "s"
    r = CliRunner().invoke(cli, ["sweep", *TINY_SET, "--grid", "growth.G=0.01:0.03:3", "--grid", "mechanics.f_max=0.003,0.006",
                                 "--workers", "2", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in out.iterdir() if not p.name.endswith(("-wal", "-shm"))) == ["montage.png", "sweep.sqlite"]
    rows = _rows(out / "sweep.sqlite")
    assert sorted({r["growth.G"] for r in rows}) == [0.01, 0.02, 0.03]
    assert json.loads(rows[0]["scene"])["lattice"]["n_bases"] == 300
    assert "6 run now, 0 already there" in r.output


@pytest.mark.parametrize("args,message", [
    (["--grid", "growth.G=-1,0.01"], "--grid growth.G=-1"),
    (["--grid", "growth.G"], "expected SECTION.KEY=V1,V2"),
    (["--grid", "growth.G=1:2:x"], "START:STOP:N"),
    (["--grid", "growth.G=1:inf:3"], "must be finite"),
    (["--grid", "growth.G=0.01,0.01"], "given twice"),
    (["--workers", "2", "--dask", "tcp://127.0.0.1:1"], "not both"),
    pytest.param(["--dask", "tcp://127.0.0.1:1"], "--dask tcp://127.0.0.1:1: no Dask scheduler",
                 marks=pytest.mark.slow),  # Dask's connection timeout: 10 s
    (["--set", "lattice.n_bases=-5"], "--set lattice.n_bases=-5"),
])
def test_bad_sweep_options_are_one_line_and_write_nothing(tmp_path, args, message):
    out = tmp_path / "s"
    r = CliRunner().invoke(cli, ["sweep", *args, "--out", str(out), "--quiet"])
    assert r.exit_code == 2, r.output
    assert message in r.output and r.output.count("\n") == 1
    assert not out.exists()


def _children(pid: int) -> list[int]:
    kids = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        kids += [int(k) for k in (task / "children").read_text().split()]
    return kids


def _start_slow_sweep(out: Path, workers: int) -> subprocess.Popen:
    args = [sys.executable, "-m", "bark_cli", "sweep", *SLOW_SET, "--grid", "growth.G=0.010:0.020:6",
            "--grid", "mechanics.f_max=0.003", "--workers", str(workers), "--out", str(out), "--quiet"]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def _wait_for_runs(db: Path, at_least: int, proc: subprocess.Popen, limit_s: float = 240.0) -> int:
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        if db.exists():
            try:
                n = len(_rows(db))
            except BarkError:
                n = 0
            if n >= at_least:
                return n
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    raise AssertionError("the sweep did not get going")


@pytest.mark.slow  # seconds of whole processes: the quick subset (-m "not slow") leaves it out
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc to find the worker processes")
def test_a_killed_worker_loses_no_finished_run_and_the_rerun_finishes(tmp_path):
    out = tmp_path / "s"
    proc = _start_slow_sweep(out, workers=2)
    try:
        _wait_for_runs(out / "sweep.sqlite", 1, proc)
        workers = [k for k in _children(proc.pid) if "python" in Path(f"/proc/{k}/cmdline").read_bytes().decode(errors="replace")]
        os.kill(workers[-1], signal.SIGKILL)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    done = len(_rows(out / "sweep.sqlite"))
    assert proc.returncode == 1, err
    assert "worker died" in err and err.count("\n") == 1
    assert 1 <= done < 6
    r = CliRunner().invoke(cli, ["sweep", *SLOW_SET, "--grid", "growth.G=0.010:0.020:6", "--grid", "mechanics.f_max=0.003",
                                 "--out", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    assert f"({6 - done} run now, {done} already there)" in r.output
    assert len(_rows(out / "sweep.sqlite")) == 6


def _die_while_sending() -> None:
    """In a local worker: what a kill in the middle of sending a run's result leaves — the result
    pipe's lock held and a message begun but not ended (a sweep's results, patterns of some 100 kB,
    take more than the pipe holds) — and then the kill."""
    import struct

    frame = sys._getframe()
    while frame.f_code.co_name != "_process_worker":
        frame = frame.f_back
    results = frame.f_locals["result_queue"]
    results._wlock.acquire()
    results._writer._send(struct.pack("!i", 1 << 20) + b"x" * 1000)
    os.kill(os.getpid(), signal.SIGKILL)


@pytest.mark.slow  # worker processes started: seconds
@pytest.mark.skipif(sys.platform != "linux", reason="the executor's pipes and locks as Linux has them")
def test_a_worker_killed_while_it_sends_a_result_is_a_death_not_a_hang():
    """The executor's reader waited for the rest of the message for ever, the other worker for the
    lock, and the sweep with them (seen once in 25–150 killed workers under load). Now the pool
    sees the dead worker, and the runs in flight fail as a worker's death."""
    import threading

    from bark.studies.pool import LocalPool

    pool = LocalPool(2, "test")
    got: list = []
    try:
        dying, other = pool.submit(_die_while_sending), pool.submit(os.getpid)
        waiting = threading.Thread(target=lambda: got.append(pool.wait_any({dying})), daemon=True)
        waiting.start()
        waiting.join(240)  # a bound for a failure, not a time the test waits
        assert got, "the wait never ended"
        assert pool.died(dying.exception(timeout=240))
        other.exception(timeout=240)  # ended too: its result or the death
    finally:
        pool.close()
    manager = getattr(pool.pool, "_executor_manager_thread", None)
    assert manager is None or not manager.is_alive()  # nothing left to hold the process at its exit


@pytest.mark.slow  # seconds of whole processes: the quick subset (-m "not slow") leaves it out
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_a_sweep_stopped_halfway_goes_on_without_running_a_finished_point_again(tmp_path, sig):
    out = tmp_path / "s"
    proc = _start_slow_sweep(out, workers=1)
    try:
        _wait_for_runs(out / "sweep.sqlite", 2, proc)
        (os.killpg if sig == signal.SIGKILL else os.kill)(proc.pid, sig)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    if sig == signal.SIGTERM:
        assert proc.returncode == 128 + signal.SIGTERM and "stopped by SIGTERM" in err and err.count("\n") == 1
    done = len(_rows(out / "sweep.sqlite"))
    assert 2 <= done < 6
    r = CliRunner().invoke(cli, ["sweep", *SLOW_SET, "--grid", "growth.G=0.010:0.020:6", "--grid", "mechanics.f_max=0.003",
                                 "--out", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    assert f"({6 - done} run now, {done} already there)" in r.output


@pytest.mark.parametrize("preset", [None, "5"])
def test_a_local_worker_takes_its_share_of_the_cores_unless_the_user_set_it(monkeypatch, preset):
    from bark.studies import pool

    monkeypatch.setattr(signal, "signal", lambda *a: None)  # the worker's set-up, not this process's
    environment = {k: v for k, v in os.environ.items() if k != "NUMBA_NUM_THREADS"}
    monkeypatch.setattr(os, "environ", {**environment, **({"NUMBA_NUM_THREADS": preset} if preset else {})})
    pool.worker_start(3)
    assert os.environ["NUMBA_NUM_THREADS"] == (preset or "3")


@pytest.mark.parametrize("args, says", [
    (["--grid", "lattice.n_bases=1000,50000000"], "a run this size needs about"),
    (["--grid", "lattice.n_bases=1000,4000000", "--workers", "8"], "--workers: 2 runs of 4,000,000 bases at once need about"),
])
def test_a_point_too_big_for_this_machine_is_refused_before_any_runs(args, says, tmp_path, monkeypatch):
    """Every point fits in memory, with as many at once as there are workers, before anything is
    written (this machine's memory stated, so the test does not depend on it)."""
    from bark.engine import scene

    monkeypatch.setattr(scene, "available_memory", lambda: 16 * 2**30)
    out = tmp_path / "s"
    r = CliRunner().invoke(cli, ["sweep", *args, "--set", "run.until_time=1", "--quiet", "--out", str(out)])
    assert r.exit_code == 2, r.output
    assert says in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert ("--grid lattice.n_bases=" in r.stderr) == ("--workers" not in args), r.stderr  # what is too much, as typed
    assert not out.exists()


def test_the_montage_draws_each_trunk_to_scale(tmp_path, monkeypatch):
    """Each cell keeps its trunk's aspect (equal scales, in metres: a 45° crack looks 45°) and says
    its size; the sheet is sized to the cells, not the cells stretched to the sheet."""
    import bark_cli.figures as figures

    drawn = []
    monkeypatch.setattr(figures, "save_figure", lambda fig, path: drawn.append(fig) or path)
    out = tmp_path / "s"
    r = CliRunner().invoke(cli, ["sweep", *TINY_SET, "--grid", "growth.G=0.01,0.03", "--out", str(out)])
    assert r.exit_code == 0, r.output
    (fig,) = drawn
    cells = [ax for ax in fig.axes if ax.images]
    assert len(cells) == 2
    for ax in cells:
        assert ax.get_aspect() == 1.0 and "cm" in ax.get_title()
        x0, x1, y0, y1 = ax.images[0].get_extent()
        assert x1 < 2.0 and y1 - y0 < 2.0  # metres: a 300-base segment, not model units


# -- lists of points and designs ----------------------------------------------------------------------
def test_a_latin_hypercube_puts_one_point_in_each_stratum_and_the_same_seed_draws_the_same_points():
    from bark.studies.sweep import design

    ranges = {"growth.G": (0.005, 0.02, False), "mechanics.f_max": (0.002, 0.01, True)}
    axes = design("lhs", ranges, 8, seed=3)
    assert [a.key for a in axes] == list(ranges) and all(len(a.values) == 8 for a in axes)
    g = np.array(axes[0].values)
    assert sorted(np.floor((g - 0.005) / (0.015 / 8)).astype(int).tolist()) == list(range(8))  # one a stratum
    f = np.log(np.array(axes[1].values))  # log-uniform: the strata are even in the logarithm
    assert sorted(np.floor((f - np.log(0.002)) / ((np.log(0.01) - np.log(0.002)) / 8)).astype(int).tolist()) == list(range(8))
    assert design("lhs", ranges, 8, seed=3) == axes and design("lhs", ranges, 8, seed=4) != axes
    rand = design("random", ranges, 50, seed=0)
    assert all(0.005 <= v <= 0.02 for v in rand[0].values) and all(0.002 <= v <= 0.01 for v in rand[1].values)


def test_a_list_of_points_runs_each_row_once(tmp_path):
    csv = tmp_path / "points.csv"
    csv.write_text("# growth constants and thresholds\ngrowth.G,mechanics.f_max\n0.01,0.004\n0.014,0.004\n0.01,0.004\n")
    out = tmp_path / "s"
    r = CliRunner().invoke(cli, ["sweep", *TINY_SET, "--points", str(csv), "--out", str(out), "--run-folders"])
    assert r.exit_code == 0, r.output
    rows = _rows(out / "sweep.sqlite")
    assert sorted((row["growth.G"], row["mechanics.f_max"]) for row in rows) == [(0.01, 0.004), (0.014, 0.004)]  # twice = once
    assert not (out / "montage.png").exists() and "no montage for a list of points" in r.output
    for row in rows:  # each run's own folder, its outputs as bark simulate writes them
        summary = json.loads((out / "runs" / row["key"] / "summary.json").read_text())
        assert summary["settings"]["growth"]["G"] == row["growth.G"] and summary["n_patches"] == row["n_patches"]


@pytest.mark.parametrize("args, message", [
    (["--grid", "growth.G=0.01,0.02", "--design", "lhs"], "--grid and --design"),
    (["--design", "lhs", "--samples", "4"], "needs --samples N and at least one --range"),
    (["--samples", "4"], "are for a --design"),
    (["--design", "random", "--samples", "4", "--range", "growth.G=0.02:0.01"], "finite LOW < HIGH"),
    (["--design", "random", "--samples", "4", "--range", "growth.G=0:0.01:log"], "both > 0 for :log"),
    (["--design", "random", "--samples", "4", "--range", "growth.G=a:b"], "must be numbers"),
    (["--design", "random", "--samples", "4", "--range", "growth.G=-1:0.01"], "growth.G"),
])
def test_bad_designs_are_one_line(tmp_path, args, message):
    r = CliRunner().invoke(cli, ["sweep", *TINY_SET, *args, "--out", str(tmp_path / "s"), "--quiet"])
    assert r.exit_code == 2 and message in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("text, message", [
    ("growth.G\n", "a row a point"),
    ("G,mechanics.f_max\n0.01,0.004\n", "column 'G' is not a scene key"),
    ("growth.G,mechanics.f_max\n0.01\n", "row 2: 1 values for 2 columns"),
    ("growth.G\nabc\n", "growth.G"),
])
def test_bad_point_files_are_one_line(tmp_path, text, message):
    csv = tmp_path / "p.csv"
    csv.write_text(text)
    r = CliRunner().invoke(cli, ["sweep", *TINY_SET, "--points", str(csv), "--out", str(tmp_path / "s"), "--quiet"])
    assert r.exit_code == 2 and message in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.parametrize("argv, runs", [(["--design", "random", "--samples", "150000", "--range", "growth.G=0.01:0.02"],
                                         "150,000"),
                                        (["--grid", "growth.G=0.01:0.02:400", "--grid", "mechanics.f_max=0.002:0.004:300"],
                                         "120,000"),
                                        (["--design", "lhs", "--samples", "60000", "--range", "growth.G=0.01:0.02",
                                          "--seeds", "2"], "120,000")])
def test_a_sweep_over_its_bound_is_refused_before_anything_is_built(argv, runs, tmp_path):
    """--samples 1000000 built a million scenes for a quarter of an hour without a word; a sweep of
    more runs than --max-runs is one line, at once, and raising the bound is the way on."""
    out = tmp_path / "s"
    result = CliRunner().invoke(cli, ["sweep", *argv, "--out", str(out), "--quiet"])
    assert result.exit_code == 2, result.output
    assert f"a sweep of {runs} runs, more than --max-runs 100000" in result.stderr and "raise --max-runs" in result.stderr
    assert len(result.stderr.splitlines()) == 1 and not out.exists()


@pytest.mark.parametrize("quiet", [True, False])
def test_the_resource_tracker_says_nothing_of_what_a_dead_worker_left(quiet):
    """A killed worker leaves its semaphores to multiprocessing's resource tracker, which warns of
    each on the command's stderr as it removes it; a pool's tracker runs with those warnings off
    (the control, without, shows the lines the user would otherwise see)."""
    script = ("from multiprocessing import resource_tracker\n"
              "from bark.studies.pool import quiet_resource_tracker\n"
              f"quiet_resource_tracker() if {quiet} else resource_tracker.ensure_running()\n"
              "resource_tracker.register('/mp-bark-test-gone', 'semaphore')  # left, and already gone\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0
    assert ("resource_tracker" in done.stderr) is not quiet, done.stderr


def _sleep_for(seconds: float) -> float:
    import time as clock

    clock.sleep(seconds)  # a run in flight when the pool is closed; the test waits on no clock
    return seconds


@pytest.mark.slow  # spawns a worker process: a second or more of start-up
def test_a_closed_pool_leaves_no_thread_to_race_python_s_exit():
    """Closing a local pool mid-run (a signal, a dead worker) ends the executor's manager thread
    before close returns: left running, it closes its wake-up pipe while Python's exit hook writes
    to it, and an ``OSError: [Errno 9] Bad file descriptor`` traceback followed bark's one line
    (CPython gh-125451, on 3.11; seen once in CI on a SIGTERM-stopped sweep)."""
    from bark.studies.pool import LocalPool

    pool = LocalPool(1, "test")
    future = pool.submit(_sleep_for, 600.0)
    manager = pool.pool._executor_manager_thread
    assert manager is not None and manager.is_alive()
    pool.close()
    assert not manager.is_alive() and future.done()
