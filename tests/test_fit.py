"""bark fit: priors and statistics checked, the same posterior for the same seed wherever the runs go,
a fit stopped and run again, the posterior's summaries, and the command's bad input."""

from __future__ import annotations

import importlib.util
import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from bark.engine.scene import merge, read_toml
from bark.errors import BarkError
from bark.studies import fit as F
from bark.studies.fit import Fit, Observed, Prior, compared, load_fit, run_fit, weighted_quantiles
from bark_cli.main import cli
from conftest import REPO_ROOT, assert_clean_outcome

pytest.importorskip("pyabc")

TINY_SET = ["--set", "lattice.n_bases=400", "--set", "run.until_patches=10"]
"""Runs of a twentieth of a second: the reticulate scene on 400 bases, stopped at 10 patches."""
TINY = {"lattice": {"n_bases": 400}, "run": {"until_patches": 10}}
PRIORS = (Prior("growth.G", 0.007, 0.014), Prior("mechanics.f_max", 0.0028, 0.008))
OBSERVED = Observed(name="made up", values={"orientation": 140.0, "sd": 20.0, "anisotropy": 0.65})
SUMMARY = Path(__file__).resolve().parent.parent / "examples" / "paper" / "observed-reticulate.toml"


def _fit(**kw) -> Fit:
    return Fit(**{"observed": OBSERVED, "base": merge(read_toml("reticulate"), TINY), "priors": PRIORS,
                  "population": 6, "generations": 2, "seed": 3, **kw})


# -- what a fit is made of ----------------------------------------------------------------------------
@pytest.mark.parametrize("make,message", [
    (lambda: Prior("G", 0.0, 1.0), "expected SECTION.KEY"),
    (lambda: Prior("growth.G", 0.02, 0.01), "LOW < HIGH"),
    (lambda: Prior("growth.G", 0.01, 0.01), "LOW < HIGH"),
    (lambda: Prior("growth.G", float("nan"), 0.01), "finite"),
    (lambda: Prior("growth.G", 0.0, float("inf")), "finite"),
    (lambda: Prior("growth.G", -1e308, 1e308), None),
    (lambda: Prior("growth.G", 0.0, 0.01, log=True), "LOW > 0"),
    (lambda: Prior("run.seed", 0, 10), "not a setting to fit"),
    (lambda: _fit(priors=()), "at least one prior"),
    (lambda: _fit(priors=(PRIORS[0], PRIORS[0])), "given twice"),
    (lambda: _fit(statistics=("nonsense",)), "no statistic 'nonsense'"),
    (lambda: _fit(statistics=("n_bar",)), "has no n_bar"),
    (lambda: _fit(observed=Observed(name="x", values={})), "none of the statistics"),
    (lambda: _fit(population=1), "population"),
    (lambda: _fit(generations=0), "generations"),
    (lambda: _fit(min_acceptance=1.0), "acceptance"),
    (lambda: _fit(seed=-1), "seed"),
    (lambda: _fit(priors=(Prior("growth.G", -0.01, 0.01),)).check(), "G"),
    (lambda: _fit(priors=(Prior("mechanics.nonsense", 0.1, 0.2),)).check(), "nonsense"),
])
def test_bad_priors_and_fits_are_one_line(make, message):
    if message is None:  # a wide prior is allowed: what it makes of a scene is the scene's to check
        make()
        return
    with pytest.raises(BarkError, match=message):
        make()


def test_orientation_is_compared_as_an_axis_and_a_missing_statistic_as_nan():
    near = compared({"orientation": 1.0}, ["orientation"])
    far = compared({"orientation": 179.0}, ["orientation"])
    assert math.dist(near.values(), far.values()) == pytest.approx(2 * math.sin(math.radians(2)), rel=1e-12)
    assert list(compared({"orientation": 90.0, "sd": 5.0}, ["orientation", "sd"])) == ["orientation_cos2", "orientation_sin2", "sd"]
    assert math.isnan(compared({"sd": None}, ["sd"])["sd"])


def test_the_observed_pattern_brings_the_statistics_it_has(tmp_path):
    summary = Observed.read(SUMMARY)
    assert summary.available() == ("orientation", "sd")
    assert summary.values["orientation"] == 47.0 and summary.values["sd"] == 34.4
    assert Observed.read(SUMMARY, mirror=True).values["orientation"] == pytest.approx(133.0)
    r = CliRunner().invoke(cli, ["simulate", "--scene", "reticulate", *TINY_SET, "--out", str(tmp_path / "run"), "--quiet"])
    assert r.exit_code == 0, r.output
    run = Observed.read(tmp_path / "run")
    summary_json = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert run.values["orientation"] == pytest.approx(summary_json["mean_orientation_deg"], abs=1e-9)
    assert run.values["sd"] == pytest.approx(summary_json["circular_sd_deg"], abs=1e-9)
    assert run.values["nematic_order"] == pytest.approx(summary_json["network"]["nematic_order"], abs=1e-9)
    assert {"orientation", "sd", "anisotropy", "size_mean", "nematic_order"} <= set(run.available())


def test_a_photographs_csv_brings_its_pattern_and_patch_sizes_not_a_network(tmp_path):
    """A photograph (leaf-base centres and patches, no springs): orientation, SD, anisotropy and
    patch sizes to fit on; none of the crack network's statistics."""
    from bark.engine.scene import Scene
    from bark.units import unwrap

    scene = merge(read_toml("reticulate"), {**TINY, "run": {**TINY["run"], "seed": 2}})
    sc = Scene.from_dict(scene)
    sim = sc.simulation()
    sim.run(sc.stop())
    uv, labels = unwrap(sim.state.x, sim.radius), sim.patch_labels()
    lines = ["# digitised from a made-up photograph", "x,y,patch", *(f"{float(u)!r},{float(v)!r},{int(k)}" for (u, v), k in zip(uv, labels))]
    (tmp_path / "photo.csv").write_text("\n".join(lines) + "\n")
    photo = Observed.read(tmp_path / "photo.csv")
    assert photo.available() == ("orientation", "sd", "anisotropy", "size_mean")
    run = F.simulate_statistics(scene, ("sd", "size_mean"))
    assert photo.values["size_mean"] == pytest.approx(run["size_mean"])
    with pytest.raises(BarkError, match="has no n_bar"):
        _fit(observed=photo, statistics=("orientation", "n_bar"))


def test_a_run_of_the_fit_measures_what_the_run_folder_says(tmp_path):
    """The statistics a fit's run measures in memory are those ``bark simulate`` writes for the same scene."""
    scene = merge(read_toml("reticulate"), {**TINY, "run": {**TINY["run"], "seed": 5}})
    got = F.simulate_statistics(scene, F.STATISTICS)
    r = CliRunner().invoke(cli, ["simulate", "--scene", "reticulate", *TINY_SET, "--seed", "5", "--out", str(tmp_path / "r"),
                                 "--quiet"])
    assert r.exit_code == 0, r.output
    want = Observed.read(tmp_path / "r").values
    assert got.keys() == want.keys()
    for k in got:
        assert (got[k] is None and want[k] is None) or got[k] == pytest.approx(want[k], rel=1e-9, abs=1e-12), k


NO_LAW = r"""
import json, sys
from bark.engine.scene import merge, read_toml
from bark.studies.fit import STATISTICS, Observed, simulate_statistics
observed = Observed.read(sys.argv[2])
got = simulate_statistics(merge(read_toml("reticulate"), json.loads(sys.argv[1])), STATISTICS)
print(json.dumps([observed.values, got, "scipy.optimize" in sys.modules]))
"""


def test_a_fits_runs_and_its_observed_pattern_fit_no_size_law(tmp_path):
    """A fit compares the patch sizes' mean, never a law of them: neither its observed pattern nor
    its runs fit one, so scipy's optimiser is never imported (half a second of every worker's
    start) — and the statistics are those of the run's folder."""
    r = CliRunner().invoke(cli, ["simulate", "--scene", "reticulate", *TINY_SET, "--seed", "5", "--out", str(tmp_path / "r"),
                                 "--quiet"])
    assert r.exit_code == 0, r.output
    scene = merge(TINY, {"run": {"seed": 5, "backend": "numpy"}})
    done = subprocess.run([sys.executable, "-c", NO_LAW, json.dumps(scene), str(tmp_path / "r")], capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    observed, got, optimiser = json.loads(done.stdout.strip().splitlines()[-1])
    assert not optimiser
    assert observed == Observed.read(tmp_path / "r").values  # as this process reads it
    assert got.keys() == observed.keys() and got["size_mean"] is not None and got["n_bar"] is not None, got
    for k in got:
        assert (got[k] is None and observed[k] is None) or got[k] == pytest.approx(observed[k], rel=1e-9, abs=1e-12), k


def test_a_statistic_a_run_lacks_makes_it_far_not_undefined():
    import pyabc

    distance = F._distance_class()(p=1)
    x0 = {"a": 1.0, "b": 2.0}
    pyabc.PNormDistance.initialize(distance, t=0, get_sample=lambda: None, x_0=x0, total_sims=0)  # no scales fitted
    distance.scale_weights[0] = np.array([1.0, 1.0])
    assert distance({"a": 1.5, "b": 2.0}, x0, t=0) == pytest.approx(0.5)
    assert distance({"a": 1.5, "b": math.nan}, x0, t=0) == pytest.approx(0.5 + F.MISSING)
    distance.scale_weights[0] = np.array([1.0, 0.0])  # a statistic every run has alike weighs nothing, missing or not
    assert distance({"a": 1.5, "b": math.nan}, x0, t=0) == pytest.approx(0.5)


def test_weighted_quantiles_and_the_highest_density_level():
    x = np.arange(1.0, 101.0)
    w = np.ones_like(x)
    assert weighted_quantiles(x, w, (0.5,))[0] == pytest.approx(50.5)
    assert weighted_quantiles(x, w, (0.05, 0.95)) == pytest.approx([5.5, 95.5])
    w2 = np.where(x > 50, 3.0, 1.0)  # three quarters of the weight above 50
    assert weighted_quantiles(x, w2, (0.25,))[0] == pytest.approx(50.5, abs=0.6)


# -- a fit run ----------------------------------------------------------------------------------------
@pytest.mark.slow  # worker processes started: seconds
def test_the_same_seed_gives_the_same_posterior_on_any_number_of_workers_and_after_a_stop(tmp_path):
    one = run_fit(_fit(), tmp_path / "one.db", workers=1)
    assert one.stop_reason == "generations" and [g.t for g in one.generations] == [0, 1]
    assert all(g.accepted == 6 and g.runs >= 6 for g in one.generations)
    first = run_fit(_fit(generations=1), tmp_path / "two.db", workers=2)  # stopped after its first generation ...
    assert first.ran == 1
    two = run_fit(_fit(), tmp_path / "two.db", workers=2)  # ... and run again: only the second is run
    assert two.ran == 1
    assert two.generations == one.generations
    for a, b in zip(one.posterior(), two.posterior()):
        np.testing.assert_array_equal(a, b)
    again = run_fit(_fit(), tmp_path / "two.db", workers=2)
    assert again.ran == 0
    other = run_fit(_fit(seed=4), tmp_path / "three.db", workers=1)
    assert not np.array_equal(other.posterior()[0], one.posterior()[0])
    est = one.estimates()
    for p in PRIORS:
        lo, hi = est[p.key]["ci90"]
        assert p.low <= lo <= est[p.key]["median"] <= hi <= p.high
    x, w = one.posterior()
    assert x.shape == (6, 2) and w.sum() == pytest.approx(1.0)
    best = x[np.argmax(w)]
    assert one.hpd_level(dict(zip(one.fit.keys, best))) < 0.5
    assert one.hpd_level({"growth.G": 1.0, "mechanics.f_max": 1.0}) == pytest.approx(1.0)


class _HereAndNow:
    """A pool that runs what it is given at once, in the caller's thread, which keeps its turn: a fit's
    runs one at a time, none of pyabc's draws of one between another's."""

    slots = 1

    def submit(self, fn, *args):
        from concurrent.futures import Future

        done = Future()
        done.set_result(fn(*args))
        return done

    @staticmethod
    def died(error) -> bool:
        return False


HAS_PYABC = "'pyabc' in __import__('sys').modules"
"""Asked of a worker by ``eval`` (a function of this module would import it there, and pyabc with it)."""


@pytest.mark.slow  # worker processes started: seconds
def test_runs_that_take_turns_draw_what_each_draws_alone_and_workers_need_no_pyabc(tmp_path):
    """pyabc's code for each run draws from numpy's global generator in the fit's process while the
    runs are away on the workers, in whatever order they come back: the posterior is the one of runs
    made one at a time; and the workers, which run bark only, never import pyabc."""
    from bark.studies.pool import LocalPool

    alone = run_fit(_fit(), tmp_path / "alone.db", pool=_HereAndNow())
    pool = LocalPool(2, "test")
    try:
        together = run_fit(_fit(), tmp_path / "together.db", pool=pool)
        assert not any(pool.submit(eval, HAS_PYABC).result(timeout=240) for _ in range(4))
    finally:
        pool.close()
    assert together.generations == alone.generations
    for a, b in zip(alone.posterior(), together.posterior()):
        np.testing.assert_array_equal(a, b)


class _HeldBack:
    """A pool that keeps every run it is given until ``let_go``, then lets them come back in reverse."""

    slots = 2

    def __init__(self) -> None:
        import threading

        self.given, self.changed = [], threading.Condition()

    def submit(self, fn, *args):
        from concurrent.futures import Future

        with self.changed:
            self.given.append(Future())
            self.changed.notify_all()
            return self.given[-1]

    def let_go(self, count: int) -> None:
        with self.changed:  # the bound is for a failure, not a time the test waits
            assert self.changed.wait_for(lambda: len(self.given) == count, timeout=240), "the runs never came"
        for future in reversed(self.given):
            future.set_result({})


def test_a_run_draws_what_it_draws_alone_before_and_after_its_simulation():
    """Each run's draws from numpy's and Python's global generators, before its simulation and after
    it, are those it makes alone, however the runs taking turns come back; no two runs are in their
    draws at once; and after the generation the generators are the caller's again."""
    import random
    import threading

    inside, most, count = [0], [0], threading.Lock()

    def draws(turns):  # one at a time, so that another thread could come between any two
        with count:
            inside[0] += 1
            most[0] = max(most[0], inside[0])
        assert turns.lock.locked()  # only in its turn
        out = [(np.random.random(), random.random()) for _ in range(300)]
        with count:
            inside[0] -= 1
        return out

    def simulate_one():  # as pyabc's: draws, the model's run, draws again
        before = draws(F._AWAY.turns)
        F._AWAY.turns.run({}, ())
        return before, draws(F._AWAY.turns)

    def alone(k):
        state = np.random.SeedSequence([5, 2, k]).generate_state(4)
        np.random.seed(state)
        random.seed(int(state[0]))
        return ([(np.random.random(), random.random()) for _ in range(300)],
                [(np.random.random(), random.random()) for _ in range(300)])

    np.random.seed(11)
    random.seed(11)
    callers = np.random.get_state(), random.getstate()
    pool = _HeldBack()
    turns = F._Turns(pool, 5, 1)
    was = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # threads switched as often as the interpreter can: any two runs' draws would mix
    try:
        runs = [F._in_thread(turns.one, simulate_one, k) for k in range(4)]
        pool.let_go(4)
        got = [r.result(timeout=240) for r in runs]
    finally:
        sys.setswitchinterval(was)
        turns.close()
    after = np.random.random(), random.random()
    np.random.set_state(callers[0])
    random.setstate(callers[1])
    assert after == (np.random.random(), random.random())  # the caller's generators, as it left them
    assert most[0] == 1
    assert got == [alone(k) for k in range(4)]


def test_a_database_of_other_settings_or_of_another_program_is_refused(tmp_path):
    import sqlite3

    con = sqlite3.connect(tmp_path / "other.db")
    con.execute("PRAGMA journal_mode=WAL")  # another program's, in WAL mode: reading it made -wal and -shm
    with con:
        con.execute("CREATE TABLE runs (x INTEGER)")
    con.close()
    with pytest.raises(BarkError, match="not a fit's database"):
        run_fit(_fit(), tmp_path / "other.db")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.db"]  # left as it was found
    (tmp_path / "junk.db").write_bytes(b"not sqlite at all, just some bytes" * 100)
    with pytest.raises(BarkError, match="not a fit's database"):
        run_fit(_fit(), tmp_path / "junk.db")


@pytest.mark.slow  # a fit of a few generations on worker processes
def test_a_settings_change_is_refused_and_a_dask_cluster_gives_the_local_posterior(tmp_path):
    distributed = pytest.importorskip("distributed")
    local = run_fit(_fit(), tmp_path / "local.db", workers=2)
    with pytest.raises(BarkError, match="other settings"):
        run_fit(_fit(population=7), tmp_path / "local.db")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        dask = run_fit(_fit(), tmp_path / "dask.db", client=client)
    assert dask.generations == local.generations
    for a, b in zip(local.posterior(), dask.posterior()):
        np.testing.assert_array_equal(a, b)


# -- the command --------------------------------------------------------------------------------------
CLI_FIT = ["--scene", "reticulate", *TINY_SET, "--population", "6", "--generations", "2", "--predictive", "4", "--quiet"]


@pytest.mark.slow  # a whole fit with its pictures
def test_bark_fit_writes_its_summary_posterior_and_pictures(tmp_path):
    out = tmp_path / "fit"
    r = CliRunner().invoke(cli, ["fit", str(SUMMARY), *CLI_FIT, "--mirror", "--mark", "reticulate:growth.G=0.011,mechanics.f_max=0.005",
                                 "--out", str(out), "--json"])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in out.iterdir()) == ["corner.png", "fit.db", "fit.json", "posterior.csv", "predictive.png"]
    report = json.loads((out / "fit.json").read_text())
    assert json.loads(r.stdout) == report  # --json: fit.json's content, alone on stdout
    assert report["statistics"] == ["orientation", "sd"]
    assert report["observed"]["statistics"]["orientation"] == pytest.approx(133.0)
    assert [g["t"] for g in report["generations"]] == [0, 1]
    assert report["runs"] == sum(g["runs"] for g in report["generations"])
    assert set(report["posterior"]) == {"growth.G", "mechanics.f_max"}
    assert 0.0 <= report["marks"]["reticulate"]["hpd_level"] <= 1.0
    assert len(report["predictive"]) == 4 and set(report["predictive"][0]["statistics"]) == {"orientation", "sd"}
    lines = (out / "posterior.csv").read_text().splitlines()
    assert lines[0] == "growth.G,mechanics.f_max,weight" and len(lines) == 7
    assert sum(float(line.split(",")[2]) for line in lines[1:]) == pytest.approx(1.0)


@pytest.mark.parametrize("args,message", [
    (["--prior", "growth.G=0.01"], "--prior growth.G=0.01: expected SECTION.KEY=LOW:HIGH"),
    (["--prior", "growth.G=a:b"], "must be numbers"),
    (["--prior", "growth.G=0.02:0.01"], "finite LOW < HIGH"),
    (["--prior", "growth.G=nan:0.01"], "finite LOW < HIGH"),
    (["--prior", "growth.G=-1e308:1e308", "--prior", "growth.G=0:1"], "given twice"),
    (["--prior", "growth.G=0:0.01:log"], "both > 0"),
    (["--prior", "growth.G=0.01:0.02", "--set", "growth.G=0.01"], "fitted or set, not both"),
    (["--prior", "run.seed=0:5"], "not a setting to fit"),
    (["--prior", "growth.G=-1:0.02"], "G"),
    (["--prior", "mechanics.f_max=-0.01:0.01"], "--prior mechanics.f_max=-0.01:0.01 (at -0.01): must be > 0"),
    (["--prior", "nosuch.key=0:1"], "--prior nosuch.key=0:1 (at 0.0): there is no table [nosuch] in a scene"),
    (["--prior", "mechanics.nosuch=0:1"], "--prior mechanics.nosuch=0:1 (at 0.0): not a setting of [mechanics]"),
    (["--statistics", "sd,bogus"], "no statistic 'bogus'"),
    (["--statistics", "anisotropy"], "has no anisotropy"),
    (["--mark", "nolabel"], "--mark nolabel: expected LABEL:"),
    (["--mark", "a:growth.G=0.01"], "give a value for each fitted setting"),
    (["--mark", "a:growth.G=inf,mechanics.f_max=0.005"], "expected LABEL:"),
    (["--workers", "2", "--dask", "tcp://127.0.0.1:1"], "not both"),
    (["--population", "1"], "--population"),
    (["--min-acceptance", "1"], "--min-acceptance"),
])
def test_bad_input_to_bark_fit_is_one_line_and_writes_nothing(tmp_path, args, message):
    out = tmp_path / "fit"
    r = CliRunner().invoke(cli, ["fit", str(SUMMARY), *TINY_SET, *args, "--out", str(out)])
    assert_clean_outcome(r, out)
    assert r.exit_code == 2 and message in r.stderr, r.stderr


def test_without_pyabc_bark_fit_says_how_to_install_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyabc", None)  # as if it were not installed
    r = CliRunner().invoke(cli, ["fit", str(SUMMARY), "--out", str(tmp_path / "fit")])
    assert_clean_outcome(r, tmp_path / "fit")
    assert r.exit_code == 2 and "pip install 'bark-grasstree[fit]'" in r.stderr, r.stderr


@pytest.mark.parametrize("observed", ["missing.csv", "folder-without-a-run", "odd name ünï.toml"])
def test_an_observed_pattern_that_is_not_one_is_one_line(tmp_path, observed):
    (tmp_path / "folder-without-a-run").mkdir()
    (tmp_path / "odd name ünï.toml").write_text("[pattern]\nn_patches = 'many'\n")
    r = CliRunner().invoke(cli, ["fit", str(tmp_path / observed), "--out", str(tmp_path / "fit")])
    assert_clean_outcome(r, tmp_path / "fit")
    assert r.exit_code == 2


def _generation_line(proc) -> str:
    """The first line of stderr that is not a progress line (``bark: fit: ...``): the first generation's."""
    for line in proc.stderr:
        if not line.startswith("bark: fit:"):
            return line
    return ""


@pytest.mark.slow  # a fit of whole processes, stopped from outside
def test_a_fit_stopped_by_a_signal_goes_on_from_its_last_generation(tmp_path):
    out = tmp_path / "fit"
    args = [sys.executable, "-m", "bark_cli", "fit", str(SUMMARY), *[a for a in CLI_FIT if a != "--quiet"],
            "--generations", "3", "--predictive", "0", "--out", str(out)]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        line = _generation_line(proc)  # the first generation's line: it is in fit.db
        assert line.startswith("bark: generation 0:"), line + proc.communicate()[1]
        os.kill(proc.pid, signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    if proc.returncode == 0:  # it had finished before the signal came: nothing to test on this machine
        pytest.skip("the fit ended before the signal")
    assert proc.returncode == 128 + signal.SIGTERM and "stopped by SIGTERM" in err and "the same command goes on" in err, err
    kept = len(load_fit(None, out / "fit.db").generations)
    assert 1 <= kept < 3
    r = CliRunner().invoke(cli, ["fit", str(SUMMARY), *CLI_FIT, "--generations", "3", "--predictive", "0", "--out", str(out)])
    assert r.exit_code == 0, r.output
    whole = CliRunner().invoke(cli, ["fit", str(SUMMARY), *CLI_FIT, "--generations", "3", "--predictive", "0",
                                     "--out", str(tmp_path / "whole")])
    assert whole.exit_code == 0, whole.output
    a, b = (json.loads((p / "fit.json").read_text()) for p in (out, tmp_path / "whole"))
    assert a["generations"] == b["generations"] and a["posterior"] == b["posterior"]


def _note_start(folder: str, fail: bool) -> None:
    """A worker's warm-up that leaves its process id in ``folder``, then fails if asked to."""
    Path(folder, str(os.getpid())).write_text("warm")
    if fail:
        raise RuntimeError("a warm-up that fails")


@pytest.mark.slow  # worker processes started: seconds
@pytest.mark.parametrize("fail", [False, True])
def test_a_warm_pool_starts_every_worker_at_once_and_a_failed_warm_up_breaks_nothing(tmp_path, fail):
    """Each worker of a pool given a warm-up runs it as the pool starts, before any run is handed
    out (the fit's start-up and its workers' go on side by side); a warm-up that fails leaves the
    worker to its runs, which report what they meet."""
    import time

    from bark.studies.pool import LocalPool

    pool = LocalPool(2, "test", (_note_start, (str(tmp_path), fail)))
    try:
        deadline = time.monotonic() + 240.0  # a bound for a failure, not a time the test waits
        while len(list(tmp_path.iterdir())) < 2:
            assert time.monotonic() < deadline, "the workers did not start until a run was handed out"
            time.sleep(0.05)
        started = {int(p.name) for p in tmp_path.iterdir()}
        assert {pool.submit(os.getpid).result(timeout=240) for _ in range(4)} <= started
    finally:
        pool.close()


WARM_CHILD = r"""
import json, sys
from bark.engine import kernels
from bark.engine.scene import merge, read_toml
from bark.studies.fit import simulate_statistics, warm_worker
kernels.expect_many()  # as a worker says
taken, load = [], kernels.load
kernels.load = lambda *a, **k: taken.append(load(*a, **k)) or taken[-1]
base = merge(read_toml("reticulate"), json.loads(sys.argv[1]))
warm_worker(base)
simulate_statistics(base, ("orientation",))
print(json.dumps([b.name for b in taken]))
"""


@pytest.mark.slow  # a process of its own: its first choice of backend is the one to see
def test_a_fit_worker_warms_up_on_the_backend_its_runs_take():
    """The warm-up builds the scene for its own stop, so ``auto`` chooses as it will for the runs:
    one step alone would be short enough for numpy, and the runs' kernel would still load at the
    first run."""
    done = subprocess.run([sys.executable, "-c", WARM_CHILD, json.dumps(TINY)], capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stderr
    warm, run = json.loads(done.stdout.strip().splitlines()[-1])
    assert warm == run == ("numba" if importlib.util.find_spec("numba") else "numpy")


@pytest.mark.slow  # whole processes
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc to find the worker processes")
def test_a_killed_fit_worker_is_one_line_and_the_rerun_goes_on(tmp_path):
    from test_sweep import _children

    out = tmp_path / "fit"
    args = [sys.executable, "-m", "bark_cli", "fit", str(SUMMARY), *[a for a in CLI_FIT if a != "--quiet"],
            "--generations", "3", "--predictive", "0", "--workers", "2", "--out", str(out)]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        line = _generation_line(proc)  # a generation is in fit.db, and the workers are running the next
        assert line.startswith("bark: generation 0:"), line + proc.communicate()[1]
        workers = [k for k in _children(proc.pid) if "python" in Path(f"/proc/{k}/cmdline").read_bytes().decode(errors="replace")]
        os.kill(workers[-1], signal.SIGKILL)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    if proc.returncode == 0:
        pytest.skip("the fit ended before its worker was killed")
    said = [line for line in err.splitlines() if not line.startswith("bark: fit: ")]  # less the progress lines
    assert proc.returncode == 1 and len(said) == 1 and "fit worker died" in said[0], err
    r = CliRunner().invoke(cli, ["fit", str(SUMMARY), *CLI_FIT, "--generations", "3", "--predictive", "0", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert [g["t"] for g in json.loads((out / "fit.json").read_text())["generations"]] == [0, 1, 2]


@pytest.mark.slow  # whole processes: the quick subset (-m "not slow") leaves it out
def test_a_fit_the_disk_refuses_is_one_line_and_goes_on_once_there_is_room(tmp_path):
    """Under ``ulimit -f`` fit.db could not grow: SQLAlchemy's 117-line traceback. Now one line, the
    folder holds no journal beside fit.db, and the same command with room ends the fit."""
    import resource

    out = tmp_path / "fit"
    argv = [sys.executable, "-m", "bark_cli", "fit", str(SUMMARY), *TINY_SET, "--population", "20", "--generations", "3",
            "--out", str(out), "--quiet"]

    def cap():
        resource.setrlimit(resource.RLIMIT_FSIZE, (40_000, 40_000))

    refused = subprocess.run(argv, cwd=REPO_ROOT, capture_output=True, text=True, timeout=600, preexec_fn=cap)
    assert refused.returncode == 1, refused.stderr
    assert refused.stderr.splitlines() == [line for line in refused.stderr.splitlines() if line.startswith("bark: ")]
    assert f"bark: error: {out / 'fit.db'}: could not be written (" in refused.stderr, refused.stderr
    assert "Traceback" not in refused.stderr and {p.name for p in out.iterdir()} == {"fit.db"}
    again = subprocess.run(argv, cwd=REPO_ROOT, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert (out / "fit.json").exists() and (out / "posterior.csv").exists()


def test_a_second_signal_while_a_fit_stops_is_no_traceback(tmp_path, monkeypatch):
    """Ctrl-C stops a fit; a second one while it counts the generations kept (for its message)
    ended in a traceback. Now the count is left out and the stop is said as before."""
    def first(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(F, "run_fit", first)
    monkeypatch.setattr(F, "load_fit", first)  # the second signal, while counting
    out = tmp_path / "fit"
    r = CliRunner().invoke(cli, ["fit", str(SUMMARY), *TINY_SET, "--out", str(out), "--quiet"])
    assert r.exit_code == 130, r.output
    assert r.stderr == f"bark: fit stopped by SIGINT: the generations finished are in {out / 'fit.db'}; " \
                       "the same command goes on\n"
