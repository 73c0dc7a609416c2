"""Simulation-based calibration of bark fit: the draws, the rank of a truth in a weighted posterior,
the summary's histogram, chi-square and coverage, and a study stopped and run again."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bark.engine.scene import merge, read_toml
from bark.errors import BarkError
from bark.studies import sbc as S
from bark.studies.fit import Prior
from bark.studies.sbc import Calibration, run_calibration, summarise

KEYS = ("growth.G", "mechanics.f_max")
TINY = {"lattice": {"n_bases": 400}, "run": {"until_patches": 10}}


def _rows(ranks, levels=None) -> list[dict]:
    levels = ranks if levels is None else levels
    return [{"draw": i, "rank": dict.fromkeys(KEYS, float(u)), "hpd_level": float(h)}
            for i, (u, h) in enumerate(zip(ranks, levels))]


def test_the_draws_come_from_the_priors_and_depend_only_on_the_seed_and_their_number():
    cal = Calibration(base={}, priors=(Prior("growth.G", 0.005, 0.016), Prior("mechanics.f_max", 1e-4, 1e-1, log=True)))
    draws = [cal.truth(i) for i in range(200)]
    assert draws[7] == cal.truth(7) and draws[7] != draws[8]
    g = np.array([d[0]["growth.G"] for d in draws])
    f = np.array([d[0]["mechanics.f_max"] for d in draws])
    assert 0.005 <= g.min() and g.max() <= 0.016
    assert 1e-4 <= f.min() and f.max() <= 1e-1
    assert np.mean(f < 1e-2) == pytest.approx(2 / 3, abs=0.12)  # uniform in the logarithm: two decades of three
    assert len({d[1] for d in draws}) == 200
    assert Calibration(base={}, seed=1).truth(7) != cal.truth(7)


def test_the_rank_is_the_posteriors_weight_below_the_truth_ties_counted_half():
    x, w = np.array([1.0, 2.0, 3.0, 4.0]), np.array([0.1, 0.2, 0.3, 0.4])
    assert S._rank(x, w, 0.5) == 0.0
    assert S._rank(x, w, 9.0) == pytest.approx(1.0)
    assert S._rank(x, w, 2.5) == pytest.approx(0.3)
    assert S._rank(x, w, 3.0) == pytest.approx(0.3 + 0.15)


def test_calibrated_ranks_are_uniform_and_cover_each_level():
    n = 200
    s = summarise(_rows((np.arange(n) + 0.5) / n), KEYS, bins=10)
    for key in (*KEYS, "joint"):
        assert s[key]["counts"] == [20] * 10 and s[key]["chi2_p"] == pytest.approx(1.0)
        for q in S.LEVELS:
            cover = s[key]["coverage"][f"{q:g}"]
            assert cover["covered"] == pytest.approx(q, abs=1 / n)
            assert cover["expected"][0] < q < cover["expected"][1]
    assert s["draws"] == n and s["skipped"] == 0


@pytest.mark.parametrize("rank,level,central,joint", [
    (0.5, 0.0, 1.0, 1.0),  # every truth in the middle: a posterior wider than it needs to be
    (0.0, 1.0, 0.0, 0.0),  # every truth below the posterior, least probable: a biased, overconfident one
    (1.0, 1.0, 0.0, 0.0),
])
def test_miscalibration_shows_in_the_coverage_and_the_chi_square(rank, level, central, joint):
    s = summarise(_rows([rank] * 60, [level] * 60), KEYS)
    assert s["bins"] == 6 and sum(s["growth.G"]["counts"]) == 60
    assert s["growth.G"]["chi2_p"] < 1e-6 and s["joint"]["chi2_p"] < 1e-6
    for q in S.LEVELS:
        assert s["mechanics.f_max"]["coverage"][f"{q:g}"]["covered"] == central
        assert s["joint"]["coverage"][f"{q:g}"]["covered"] == joint


def test_draws_without_a_pattern_are_counted_and_left_out_and_none_is_one_line():
    rows = _rows([0.2, 0.7]) + [{"draw": 2, "skipped": "no patch"}]
    s = summarise(rows, KEYS)
    assert s["draws"] == 2 and s["skipped"] == 1 and s["bins"] == 2
    with pytest.raises(BarkError, match="no draw has a fitted posterior"):
        summarise([{"draw": 0, "skipped": "no patch"}], KEYS)


@pytest.mark.parametrize("draws", [0, -1, 1.5, math.nan])
def test_a_study_of_no_draws_is_refused(draws):
    with pytest.raises((TypeError, ValueError)):
        Calibration(base={}, draws=draws)


def test_a_pattern_without_statistics_is_recorded_and_not_fitted(tmp_path, monkeypatch):
    monkeypatch.setattr(S, "simulate_statistics", lambda scene, names: dict.fromkeys(names))
    monkeypatch.setattr(S, "run_fit", lambda *a, **k: pytest.fail("a pattern without statistics was fitted"))
    cal = Calibration(base=merge(read_toml("reticulate"), TINY), draws=2, population=4, generations=1)
    rows = run_calibration(cal, tmp_path)
    assert [r["draw"] for r in rows] == [0, 1] and all("skipped" in r and "rank" not in r for r in rows)
    assert json.loads((tmp_path / "draw-001.json").read_text())["truth"] == rows[1]["truth"]


@pytest.mark.slow  # worker processes started and fits run: tens of seconds
def test_a_study_stopped_and_run_again_redoes_only_the_draws_not_finished(tmp_path):
    pytest.importorskip("pyabc")
    base = merge(read_toml("reticulate"), TINY)
    done: list[int] = []
    cal = Calibration(base=base, statistics=("orientation", "sd", "anisotropy"), draws=2, population=4, generations=1)
    first = run_calibration(cal, tmp_path, draw_done=lambda r: done.append(r["draw"]))
    assert done == [0, 1]
    for r in first:
        assert set(r["rank"]) == set(KEYS) and all(0.0 <= u <= 1.0 for u in r["rank"].values())
        assert 0.0 <= r["hpd_level"] <= 1.0 and r["runs"] >= 4
    (tmp_path / "draw-001.json").unlink()  # stopped before draw 1's row was written: its fit is in its database
    more = run_calibration(Calibration(**{**_fields(cal), "draws": 3}), tmp_path,
                           draw_done=lambda r: done.append(r["draw"]))
    assert done == [0, 1, 1, 2]
    assert more[:2] == first
    s = summarise(more, cal.keys)
    assert s["draws"] == 3 and sum(s["joint"]["counts"]) == 3


def _fields(cal: Calibration) -> dict:
    import attrs

    return attrs.asdict(cal, recurse=False)
