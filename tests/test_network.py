"""The statistics beyond the paper's (bark.analysis.network), each on a pattern whose values are known."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bark.analysis.network import crack_network, size_distribution

W = 48  # a lattice of W bases round the trunk: base i at (i mod W, i / W), springs to i + 1 and i + W


def _lattice(rows: int):
    i = np.arange(W * rows)
    points = np.column_stack([i % W, i / W]).astype(float)
    pairs = np.concatenate([np.column_stack([i[:-1], i[:-1] + 1]), np.column_stack([i[:-W], i[:-W] + W])])
    return points, pairs


def _cut(labels, pairs):
    """The springs between two patches broken, the others intact."""
    return labels[pairs[:, 0]] == labels[pairs[:, 1]]


def test_a_power_law_and_a_log_normal_are_told_apart_and_fitted():
    rng = np.random.default_rng(1)
    power = np.rint(6.5 * rng.random(4000) ** (-1 / 1.5))  # alpha = 2.5 above 6.5, as integers >= 7
    got = size_distribution(power, 7)
    assert got["powerlaw_alpha"] == pytest.approx(2.5, abs=0.08)
    assert got["size_favoured"] != "log-normal"  # a log-normal of wide spread can mimic a power law (Clauset et al.)
    logn = np.rint(np.exp(rng.normal(3.0, 0.6, 20000)))
    logn = logn[logn >= 7][:4000]
    got = size_distribution(logn, 7)
    assert got["size_favoured"] == "log-normal" and got["size_loglik_ratio"] < 0 and got["size_p_value"] < 0.1
    assert (got["lognormal_mu"], got["lognormal_sigma"]) == (pytest.approx(3.0, abs=0.1), pytest.approx(0.6, abs=0.06))
    assert got["size_mean"] == pytest.approx(logn.mean()) and got["size_sd"] == pytest.approx(logn.std(ddof=1))
    assert size_distribution([7, 7, 7], 7)["powerlaw_alpha"] is None  # nothing to fit
    assert size_distribution([], 7)["size_mean"] is None


@settings(max_examples=60)
@given(sizes=st.lists(st.integers(1, 400), max_size=60), s_min=st.integers(1, 9))
def test_without_the_law_the_sizes_mean_and_sd_are_the_same_and_no_law_is_fitted(sizes, s_min):
    """``law=False`` (what a fit asks) gives the mean and SD bits the whole measure gives, and every
    law's key ``None``."""
    whole, plain = size_distribution(sizes, s_min), size_distribution(sizes, s_min, law=False)
    assert plain.keys() == whole.keys()
    assert (plain["size_mean"], plain["size_sd"]) == (whole["size_mean"], whole["size_sd"])
    assert all(plain[k] is None for k in plain if k not in ("size_mean", "size_sd"))


def test_a_brick_wall_has_t_junctions_three_patches_each_and_six_a_brick():
    """Bricks 8 wide and 4 high, each row shifted by 4: every junction a T of three bricks (angles 180°,
    90°, 90°), six on each brick (Domokos et al.'s (6, 3))."""
    points, pairs = _lattice(48)
    x, y = points[:, 0], points[:, 1]  # y rises 1/W a base: rows that wind on round the trunk, no seam
    row = (y // 4).astype(int)
    labels = row * 100 + ((x + 4 * (row % 2)) // 8 % 6).astype(int)
    got = crack_network(points, labels, pairs, _cut(labels, pairs), (1, W), s_min=7, period=W)
    assert got["v_bar"] == pytest.approx(3.0) and got["t_fraction"] == pytest.approx(1.0)
    bricks_inside = got["n_bar"]  # the top and bottom rows of bricks touch fewer: the mean is a little under 6
    assert 5.0 < bricks_inside <= 6.0
    angles = np.repeat(np.arange(0, 360, 15) + 7.5, got["junction_angle_counts"])
    assert np.mean(np.abs(angles - 90) < 25) == pytest.approx(2 / 3, abs=0.05)  # two right angles ...
    assert np.mean(np.abs(angles - 180) < 25) == pytest.approx(1 / 3, abs=0.05)  # ... and a straight one a junction


def test_a_grid_of_squares_meets_four_at_a_corner():
    points, pairs = _lattice(48)
    x, y = points[:, 0], points[:, 1]
    labels = (y // 8).astype(int) * 100 + (x // 8).astype(int)
    got = crack_network(points, labels, pairs, _cut(labels, pairs), (1, W), s_min=7, period=W)
    assert got["v_bar"] == pytest.approx(4.0) and got["t_fraction"] is None  # no junction of three
    assert 3.0 < got["n_bar"] <= 4.0  # four corners a square (the top and bottom rows touch two)


def test_three_sectors_at_120_degrees_meet_in_a_y():
    """A plane cut into three sectors of 120° round its middle: one junction, a Y, its three angles
    within a few degrees of 120°."""
    side = 60
    i = np.arange(side * side)
    points = np.column_stack([i % side, i // side]).astype(float)
    pairs = np.concatenate([np.column_stack([i[:-1], i[:-1] + 1]), np.column_stack([i[:-side], i[:-side] + side])])
    angle = np.degrees(np.arctan2(points[:, 1] - 29.5, points[:, 0] - 29.5))
    labels = np.floor(((angle + 90.0) % 360.0) / 120.0).astype(int)
    got = crack_network(points, labels, pairs, _cut(labels, pairs), (1, side), s_min=7)
    assert got["v_bar"] == pytest.approx(3.0) and got["y_fraction"] == pytest.approx(1.0)
    angles = np.repeat(np.arange(0, 360, 15) + 7.5, got["junction_angle_counts"])
    assert len(angles) == 3 and np.all(np.abs(angles - 120) < 15)


def test_vertical_cracks_are_in_order_and_all_across_the_round_springs():
    """Strips 4 bases wide up the trunk: every crack vertical (order 1, director 90°, up to the lattice's
    1/W rise), and every broken spring one of offset 1: twice its share of the springs."""
    points, pairs = _lattice(40)
    labels = (points[:, 0] // 4).astype(int)
    got = crack_network(points, labels, pairs, _cut(labels, pairs), (1, W), s_min=7, period=W)
    assert got["nematic_order"] == pytest.approx(1.0, abs=1e-9)
    assert got["crack_director_deg"] == pytest.approx(90.0 + math.degrees(math.atan2(1 / W, 1)), abs=1e-6)  # across the spring
    bias = got["lattice_bias"]
    assert bias["1"]["crack_share"] == 1.0 and bias[str(W)]["crack_share"] == 0.0
    assert bias["1"]["bias"] == pytest.approx(1 / bias["1"]["spring_share"]) and bias["1"]["bias"] == pytest.approx(2.0, abs=0.05)


def test_a_pattern_of_one_patch_has_no_junction_and_no_crack():
    points, pairs = _lattice(10)
    got = crack_network(points, np.zeros(len(points), int), pairs, np.ones(len(pairs), bool), (1, W), period=W)
    assert got["n_junctions"] == 0 and got["v_bar"] is None and got["nematic_order"] is None


def test_a_run_reports_them_in_its_summary_its_analysis_and_its_sweep_row(tmp_path):
    import json
    import sqlite3

    from click.testing import CliRunner

    from bark_cli.main import cli

    out = tmp_path / "run"
    args = ["--n-bases", "1200", "--until-patches", "40", "--quiet"]
    assert CliRunner().invoke(cli, ["simulate", *args, "--out", str(out)]).exit_code == 0
    net = json.loads((out / "summary.json").read_text())["network"]
    assert net["n_junctions"] > 0 and 3.0 <= net["v_bar"] <= 4.0 and 0.0 <= net["t_fraction"] <= 1.0
    assert net["size_mean"] > 7 and set(net["lattice_bias"]) == {"21", "34"}
    result = CliRunner().invoke(cli, ["analyze", str(out), "--out", str(tmp_path / "analysis")])
    assert result.exit_code == 0 and "beyond the paper" in result.output
    again = json.loads((tmp_path / "analysis" / "statistics.json").read_text())["network"]
    for key in ("size_mean", "size_sd", "powerlaw_alpha", "size_favoured", "n_junctions", "n_bar", "v_bar"):
        assert again[key] == pytest.approx(net[key]), key  # the same pattern, measured from its files
    sweep = tmp_path / "sweep"
    assert CliRunner().invoke(cli, ["sweep", "--grid", "mechanics.f_max=0.004", "--set", "lattice.n_bases=1200",
                                    "--set", "run.until_patches=40", "--out", str(sweep), "--quiet"]).exit_code == 0
    row = sqlite3.connect(sweep / "sweep.sqlite").execute("SELECT n_bar, v_bar, size_favoured FROM runs").fetchone()
    assert row[1] is not None and row[2] in ("power law", "log-normal", "neither")
