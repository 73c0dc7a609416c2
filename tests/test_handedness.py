"""The lattice's handedness: a left-handed lattice grows the mirror image of the right-handed one of
the same seed (positions, breaks and patterns), and every reader of a pattern knows which it has."""

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, strategies as st

from bark import Lattice, Stop
from bark.analysis.pattern import Pattern, PatternStatistics, read, spiral_handedness
from bark.engine.kernels import available
from bark.errors import BarkError
from bark.model.tree import Apex, Packing, leaf_corners
from bark_cli.main import cli
from conftest import REPO_ROOT, assert_clean_outcome, build_sim

BACKENDS = ["numpy"] + (["numba"] if available("numba") else [])


def test_right_is_the_default_and_left_negates_every_site_angle():
    right, left = Lattice(n_bases=500), Lattice(n_bases=500, handedness="left")
    assert right.handedness == "right"
    (t_r, z_r), (t_l, z_l) = right.sites(0.2, np.random.default_rng(3)), left.sites(0.2, np.random.default_rng(3))
    assert np.array_equal(t_l, -t_r) and np.array_equal(z_l, z_r)
    assert left.turn == -right.turn == -math.radians(right.divergence_deg)


@pytest.mark.parametrize("value", ["up", "Right", "", 1, None, True, math.nan])
def test_a_handedness_other_than_right_or_left_is_refused(value):
    with pytest.raises(BarkError, match="handedness"):
        Lattice(handedness=value)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_left_handed_run_is_the_mirror_image_of_the_right_handed_one_to_the_bit(backend):
    """θ → −θ is y → −y: every force, position and tension is the mirror of the other run's, exactly,
    so the same springs break at the same steps and each orientation o becomes 180° − o."""
    runs = {}
    for hand in ("right", "left"):
        sim = build_sim(n_bases=600, seed=4, fmax_spread=0.05, backend=backend,
                        lattice=Lattice(n_bases=600, handedness=hand))
        sim.run(Stop(until_time=6.0))
        runs[hand] = sim
    r, l = runs["right"], runs["left"]
    assert r.n_broken > 50 and Pattern.of_simulation(r).statistics(3).n_patches > 5
    assert np.array_equal(l.state.x * [1, -1, 1], r.state.x) and np.array_equal(l.state.v * [1, -1, 1], r.state.v)
    assert np.array_equal(l.state.intact, r.state.intact)
    assert np.array_equal(l.breaks.arrays()["spring"], r.breaks.arrays()["spring"])
    s_r = Pattern.of_simulation(r).statistics(3)
    s_l = Pattern.of_simulation(l).statistics(3)
    assert (s_r.handedness, s_l.handedness) == ("right", "left")
    assert s_l.n_patches == s_r.n_patches
    assert s_l.orientation.mean_deg == pytest.approx(180.0 - s_r.orientation.mean_deg, abs=1e-9)
    assert s_l.orientation.sd_deg == pytest.approx(s_r.orientation.sd_deg, abs=1e-9)
    assert s_l.anisotropy.mean == pytest.approx(s_r.anisotropy.mean, abs=1e-12)


@given(divergence=st.floats(1.0, 179.0), hand=st.sampled_from(["right", "left"]), seed=st.integers(0, 2**32 - 1))
def test_the_handedness_is_read_back_off_the_positions(divergence, hand, seed):
    lattice = Lattice(n_bases=200, divergence_deg=divergence, handedness=hand, jitter=0.05)
    theta, z = lattice.sites(0.3, np.random.default_rng(seed))
    x = np.column_stack([0.3 * np.cos(theta), 0.3 * np.sin(theta), z])
    assert spiral_handedness(x) == hand


def test_no_handedness_where_the_spiral_has_no_direction():
    lattice = Lattice(n_bases=100, divergence_deg=180.0 - 1e-12, jitter=0.0)
    theta, z = lattice.sites(0.3, np.random.default_rng(0))
    x = np.column_stack([np.cos(theta), np.sin(theta), z])
    assert spiral_handedness(x) is None
    assert spiral_handedness(x[:1]) is None


def test_a_mirror_image_has_the_other_handedness_and_a_photograph_none():
    stats = PatternStatistics.of_values([30.0, 40.0, 50.0], [0.5, 0.6, 0.7])
    assert stats.handedness is None and stats.mirrored().handedness is None
    right = Pattern(points=[[1.0, 0.0, 0.0], [1.0, 0.0, 0.1], [0.995, 0.1, 0.3]], patches=[0, 0, 0], handedness="right")
    assert right.mirrored().handedness == "left" and right.mirrored().mirrored().handedness == "right"
    assert right.statistics(1).handedness == "right" and right.statistics(1).mirrored().handedness == "left"


def test_the_dome_and_the_leaf_bases_are_mirrored_too():
    right = Lattice(n_bases=70000, n_start=45000, join_rate=101.0, rise=0.00012, offsets=(55, 89))
    left = Lattice(n_bases=70000, n_start=45000, join_rate=101.0, rise=0.00012, offsets=(55, 89), handedness="left")
    (ids_r, x_r), (ids_l, x_l) = Apex(packing=Packing.of(right)).organs(12.3, 0.5), Apex(packing=Packing.of(left)).organs(12.3, 0.5)
    assert np.array_equal(ids_r, ids_l) and np.array_equal(x_l * [1, -1, 1], x_r)
    c_r, c_l = leaf_corners(right, np.full(5, 0.4)), leaf_corners(left, np.full(5, 0.4))
    # each rhomboid mirrored (arc length negated), its corners still counter-clockwise seen from outside
    assert {tuple(p) for p in (c_l[0] * [-1, 1]).round(15)} == {tuple(p) for p in c_r[0].round(15)}
    area = lambda c: 0.5 * np.sum(c[:, 0] * np.roll(c[:, 1], -1) - np.roll(c[:, 0], -1) * c[:, 1])
    assert area(c_l[0]) == pytest.approx(area(c_r[0])) and area(c_r[0]) > 0


@pytest.mark.slow
def test_the_command_line_records_compares_and_mirrors_handedness(tmp_path):
    runner = CliRunner()
    small = ["--scene", str(REPO_ROOT / "bark" / "scenes" / "reticulate.toml"), "--n-bases", "800",
             "--until-patches", "12", "--until-time", "400", "--seed", "2", "--quiet", "--backend", "numpy"]
    for hand in ("right", "left"):
        result = runner.invoke(cli, ["simulate", *small, "--set", f"lattice.handedness={hand}", "--out", str(tmp_path / hand)])
        assert result.exit_code == 0, result.output
        summary = json.loads((tmp_path / hand / "summary.json").read_text())
        assert summary["settings"]["lattice"]["handedness"] == hand
    r, l = read(tmp_path / "right"), read(tmp_path / "left")
    assert (r.handedness, l.handedness) == ("right", "left") and r.n_patches == 12
    assert l.orientation.mean_deg == pytest.approx(180.0 - r.orientation.mean_deg, abs=1e-9)

    result = runner.invoke(cli, ["compare", str(tmp_path / "right"), str(tmp_path / "left"), "--out", str(tmp_path / "c")])
    assert result.exit_code == 0, result.output
    assert "both handedness" in result.output
    report = json.loads((tmp_path / "c" / "comparison.json").read_text())
    assert [p["handedness"] for p in report["patterns"]] == ["right", "left"]
    assert report["orientation"]["hellinger"][0][1] > 0.5
    result = runner.invoke(cli, ["compare", str(tmp_path / "right"), str(tmp_path / "left"), "--mirror", "2",
                                 "--out", str(tmp_path / "m")])
    report = json.loads((tmp_path / "m" / "comparison.json").read_text())
    assert [p["handedness"] for p in report["patterns"]] == ["right", "right"]
    assert report["orientation"]["hellinger"][0][1] == pytest.approx(0.0, abs=1e-6)
    assert "both handedness" not in result.output

    result = runner.invoke(cli, ["simulate", *small, "--handedness", "up", "--out", str(tmp_path / "bad")])
    assert_clean_outcome(result, tmp_path / "bad")
    assert result.exit_code == 2 and "--handedness" in result.stderr
    result = runner.invoke(cli, ["simulate", *small, "--set", "lattice.handedness=1", "--out", str(tmp_path / "bad")])
    assert_clean_outcome(result, tmp_path / "bad")
    assert result.exit_code == 2 and "lattice.handedness" in result.stderr
