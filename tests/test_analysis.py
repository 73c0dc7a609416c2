"""Pattern statistics on synthetic point sets (no simulation needed)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from bark.analysis.circular import axial_difference, axial_mean, axial_sd, principal_axes, tangent_plane
from bark.analysis.patches import patch_statistics, pattern_summary, window_labels
from bark_plugins.analyzers import PatchAnalyzer


def _line(angle_deg: float, n: int = 21, length: float = 2.0) -> np.ndarray:
    s = np.linspace(-length / 2, length / 2, n)
    a = math.radians(angle_deg)
    return np.column_stack([s * math.cos(a), s * math.sin(a)])


def _axis_close(a: float, b: float, tol: float = 1e-6) -> bool:
    return abs(float(axial_difference(a, b))) < tol


# -- principal axes ----------------------------------------------------------------------------


def test_vertical_line_is_90_degrees():
    pts = np.column_stack([np.zeros(11), np.linspace(0, 1, 11)])
    orientation, anisotropy, l1, l2 = principal_axes(pts)
    assert orientation == pytest.approx(90.0, abs=1e-9)
    assert anisotropy == pytest.approx(1.0, abs=1e-12)
    assert l1 > 0 and l2 == pytest.approx(0.0, abs=1e-15)


def test_horizontal_line_is_0_degrees():
    pts = np.column_stack([np.linspace(-3, 5, 9), np.full(9, 2.0)])
    orientation, anisotropy, _, _ = principal_axes(pts)
    assert _axis_close(orientation, 0.0, 1e-9)
    assert 0.0 <= orientation < 180.0
    assert anisotropy == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("angle", [45.0, 135.0, 30.0, 120.0])
def test_diagonal_lines(angle):
    orientation, anisotropy, _, _ = principal_axes(_line(angle))
    assert orientation == pytest.approx(angle, abs=1e-9)
    assert anisotropy == pytest.approx(1.0, abs=1e-9)


@given(st.floats(0.0, 180.0, exclude_max=True), st.floats(0.2, 5.0), st.floats(-10, 10), st.floats(-10, 10))
def test_orientation_of_any_line_in_0_180(angle, length, dx, dy):
    pts = _line(angle, length=length) + np.array([dx, dy])
    orientation, anisotropy, _, _ = principal_axes(pts)
    assert 0.0 <= orientation < 180.0
    assert _axis_close(orientation, angle, 1e-6)
    assert anisotropy == pytest.approx(1.0, abs=1e-6)


@given(st.floats(0.0, 180.0, exclude_max=True), st.floats(1.5, 10.0))
def test_ellipse_orientation_and_anisotropy(angle, aspect):
    """A square grid stretched by ``aspect`` and rotated: orientation = long axis, 2A − 1 from λ1/λ2."""
    g = np.linspace(-1, 1, 15)
    u, w = np.meshgrid(g, g)
    u, w = u.ravel() * aspect, w.ravel()
    a = math.radians(angle)
    pts = np.column_stack([u * math.cos(a) - w * math.sin(a), u * math.sin(a) + w * math.cos(a)])
    orientation, anisotropy, l1, l2 = principal_axes(pts)
    assert _axis_close(orientation, angle, 1e-6)
    assert l1 == pytest.approx(aspect**2 * l2, rel=1e-9)
    assert anisotropy == pytest.approx((aspect**2 - 1) / (aspect**2 + 1), rel=1e-9)


def test_isotropic_square_grid_has_zero_anisotropy():
    g = np.arange(5.0)
    pts = np.column_stack([a.ravel() for a in np.meshgrid(g, g)])
    _, anisotropy, l1, l2 = principal_axes(pts)
    assert anisotropy == pytest.approx(0.0, abs=1e-12)
    assert l1 == pytest.approx(l2)


@given(st.integers(3, 30), st.floats(0.0, 2 * math.pi), st.floats(0.1, 10.0))
def test_regular_polygon_is_isotropic(n, phase, r):
    a = phase + 2 * math.pi * np.arange(n) / n
    _, anisotropy, _, _ = principal_axes(np.column_stack([r * np.cos(a), r * np.sin(a)]))
    assert anisotropy == pytest.approx(0.0, abs=1e-9)


# -- tangent plane -----------------------------------------------------------------------------


@given(st.floats(-math.pi, math.pi), st.floats(0.05, 2.0), st.floats(-5, 5))
def test_tangent_plane_increasing_theta_is_increasing_u(theta_c, r, z0):
    """Seen from outside the trunk, θ increases to the right, and so must u."""
    theta = theta_c + np.linspace(-0.2, 0.2, 9)
    z = np.full(9, z0)  # a horizontal row of points
    pts = np.column_stack([r * np.cos(theta), r * np.sin(theta), z])
    uw = tangent_plane(pts)
    assert np.all(np.diff(uw[:, 0]) > 0)
    np.testing.assert_allclose(uw[:, 1], 0.0, atol=1e-12)
    assert uw[:, 0].mean() == pytest.approx(0.0, abs=1e-9)


@given(st.floats(-math.pi, math.pi), st.floats(0.05, 2.0))
def test_tangent_plane_w_is_height(theta_c, r):
    z = np.linspace(-1.0, 1.0, 7)
    pts = np.column_stack([np.full(7, r * math.cos(theta_c)), np.full(7, r * math.sin(theta_c)), z])
    uw = tangent_plane(pts)
    np.testing.assert_allclose(uw[:, 1], z - z.mean(), atol=1e-12)
    np.testing.assert_allclose(uw[:, 0], 0.0, atol=1e-12)


def test_tangent_plane_across_the_theta_seam():
    """A patch straddling θ = ±π keeps its order (circular mean of θ, not arithmetic)."""
    theta = np.pi + np.linspace(-0.1, 0.1, 5)  # wraps past π
    pts = np.column_stack([np.cos(theta), np.sin(theta), np.zeros(5)])
    uw = tangent_plane(pts)
    assert np.all(np.diff(uw[:, 0]) > 0)
    assert np.ptp(uw[:, 0]) == pytest.approx(2 * math.sin(0.1), rel=1e-9)


def test_patch_on_cylinder_along_axis_is_vertical_and_across_is_horizontal():
    r = 0.3
    vertical = np.column_stack([np.full(10, r), np.zeros(10), np.linspace(0, 0.5, 10)])
    theta = np.linspace(1.0, 1.4, 10)
    horizontal = np.column_stack([r * np.cos(theta), r * np.sin(theta), np.full(10, 0.2)])
    pts = np.vstack([vertical, horizontal])
    labels = np.repeat([4, 9], 10)
    rows = {row["patch"]: row for row in patch_statistics(pts, labels, min_size=7)}
    assert rows[4]["orientation_deg"] == pytest.approx(90.0, abs=1e-6)
    assert _axis_close(rows[9]["orientation_deg"], 0.0)
    assert rows[9]["theta_deg"] == pytest.approx(math.degrees(1.2), abs=1e-6)
    assert rows[4]["z"] == pytest.approx(0.25)


def test_rising_helix_patch_orientation_sign():
    """Points rising to the right (seen from outside) are at 0–90°, rising to the left at 90–180°."""
    r = 0.5
    s = np.linspace(-0.1, 0.1, 11)
    right = np.column_stack([r * np.cos(s / r), r * np.sin(s / r), s])  # dz/du > 0
    left = np.column_stack([r * np.cos(s / r), r * np.sin(s / r), -s])
    o_right, _, _, _ = principal_axes(tangent_plane(right))
    o_left, _, _, _ = principal_axes(tangent_plane(left))
    assert 40.0 < o_right < 50.0
    assert 130.0 < o_left < 140.0


# -- axial statistics --------------------------------------------------------------------------


def test_axial_mean_wraps_around():
    m = axial_mean(np.array([170.0, 10.0]))
    assert 0.0 <= m < 180.0
    assert _axis_close(m, 0.0, 1e-9)
    assert _axis_close(axial_mean(np.array([175.0, 15.0])), 5.0, 1e-9)
    assert axial_mean(np.array([80.0, 100.0])) == pytest.approx(90.0)


@given(st.floats(0.0, 180.0, exclude_max=True), st.lists(st.floats(-30.0, 30.0), min_size=1, max_size=10))
def test_axial_mean_of_symmetric_spread(centre, offsets):
    deg = (centre + np.concatenate([offsets, -np.array(offsets)])) % 180.0
    m = axial_mean(deg)
    assert 0.0 <= m < 180.0
    assert _axis_close(m, centre, 1e-6)


def test_axial_sd_zero_for_identical_and_positive_for_spread():
    assert axial_sd(np.array([30.0, 30.0, 30.0])) == pytest.approx(0.0, abs=1e-6)
    assert axial_sd(np.array([170.0, 10.0])) == pytest.approx(axial_sd(np.array([80.0, 100.0])), rel=1e-9)
    assert axial_sd(np.array([0.0, 45.0, 90.0])) > axial_sd(np.array([40.0, 45.0, 50.0])) > 0


@given(st.floats(-720, 720), st.floats(-720, 720))
def test_axial_difference_range(a, b):
    d = float(axial_difference(a, b))
    assert -90.0 <= d < 90.0
    assert _axis_close((b + d) % 180.0, a % 180.0, 1e-6)


# -- patches from digitised points -------------------------------------------------------------


def _digitised_pattern():
    """Three 2-D patches: a vertical strip (10 points), a horizontal strip (8), a tiny one (3)."""
    vertical = np.column_stack([np.zeros(10), np.linspace(0, 9, 10)])
    horizontal = np.column_stack([np.linspace(20, 27, 8), np.full(8, 3.0)])
    tiny = np.array([[50.0, 50.0], [51.0, 50.0], [50.0, 51.0]])
    points = np.vstack([vertical, tiny, horizontal])
    labels = np.concatenate([np.full(10, 7), np.full(3, 2), np.full(8, 100)])
    return points, labels


def test_patch_statistics_on_2d_points_drops_small_patches():
    points, labels = _digitised_pattern()
    rows = patch_statistics(points, labels, min_size=7)
    assert sorted(r["patch"] for r in rows) == [7, 100]
    by = {r["patch"]: r for r in rows}
    assert by[7]["size"] == 10 and by[100]["size"] == 8
    assert by[7]["orientation_deg"] == pytest.approx(90.0)
    assert _axis_close(by[100]["orientation_deg"], 0.0)
    assert by[7]["x"] == pytest.approx(0.0) and by[7]["y"] == pytest.approx(4.5)
    assert by[100]["x"] == pytest.approx(23.5) and by[100]["y"] == pytest.approx(3.0)
    assert "theta_deg" not in by[7]
    assert len(patch_statistics(points, labels, min_size=3)) == 3
    assert len(patch_statistics(points, labels, min_size=9)) == 1
    assert patch_statistics(points, labels, min_size=11) == []


def test_patch_statistics_interleaved_labels():
    """Members of a patch need not be contiguous in the input."""
    points, labels = _digitised_pattern()
    order = np.random.default_rng(0).permutation(len(labels))
    rows = {r["patch"]: r for r in patch_statistics(points[order], labels[order], min_size=7)}
    assert rows[7]["orientation_deg"] == pytest.approx(90.0)
    assert rows[7]["size"] == 10


def test_patch_analyzer_on_digitised_points():
    points, labels = _digitised_pattern()
    result = PatchAnalyzer(min_size=7).analyze(points, labels)
    assert result.summary["n_patches"] == 2
    assert len(result.patches) == 2


def test_pattern_summary_fraction_within_45():
    rows = [{"orientation_deg": d, "anisotropy": a} for d, a in [(90, 0.8), (100, 0.6), (80, 0.7), (0, 0.1)]]
    s = pattern_summary(rows)
    assert s["n_patches"] == 4
    assert _axis_close(s["mean_orientation_deg"], 90.0, 1e-6)
    assert s["fraction_within_45_deg"] == pytest.approx(0.75)
    assert s["mean_anisotropy"] == pytest.approx(0.55)
    assert s["circular_sd_deg"] > 0


def test_pattern_summary_wraps_around_for_horizontal_patches():
    rows = [{"orientation_deg": d, "anisotropy": 0.5} for d in (175.0, 5.0, 170.0, 10.0, 90.0)]
    s = pattern_summary(rows)
    assert _axis_close(s["mean_orientation_deg"], 0.0, 1e-6)
    assert s["fraction_within_45_deg"] == pytest.approx(0.8)


def test_pattern_summary_empty():
    s = pattern_summary([])
    assert s["n_patches"] == 0
    assert math.isnan(s["mean_orientation_deg"]) and math.isnan(s["fraction_within_45_deg"])


# -- on a simulated pattern --------------------------------------------------------------------


def test_analyze_a_simulated_pattern(broken_sim):
    results = broken_sim.analyze()
    assert list(results) == []  # the factory builds simulations without analyzers
    labels = broken_sim.patch_labels()
    analysis = PatchAnalyzer(min_size=7).analyze(broken_sim.state.x, labels)
    rows = analysis.patches
    assert len(rows) == broken_sim.patch_count(7) == analysis.summary["n_patches"]
    assert sum(r["size"] for r in rows) == np.sum(np.bincount(labels)[np.bincount(labels) >= 7])
    for r in rows:
        assert 0.0 <= r["orientation_deg"] < 180.0
        assert 0.0 <= r["anisotropy"] <= 1.0
        assert 0.0 <= r["theta_deg"] < 360.0


# -- pattern comparison (paper, eqs. 12–15) ---------------------------------------------------


def test_hellinger_matches_the_paper_formula():
    from bark.analysis.circular import hellinger

    assert hellinger(3.0, 2.0, 3.0, 2.0) == 0.0
    # eqs. 12–14 by hand: β = √(2·1·2/(1+4)) = √0.8, γ = −¼·(0−1)²/5 = −0.05
    assert hellinger(0.0, 1.0, 1.0, 2.0) == pytest.approx(np.sqrt(1 - np.sqrt(0.8) * np.exp(-0.05)))
    assert hellinger(0.0, 1.0, 100.0, 1.0) == pytest.approx(1.0, abs=1e-12)  # far apart: 1
    assert hellinger(0.0, 1.0, 1.0, 2.0) == hellinger(1.0, 2.0, 0.0, 1.0)  # symmetric


def test_orientation_hellinger_treats_orientations_as_axes():
    from bark.analysis.circular import orientation_hellinger

    from bark.analysis.circular import axial_sd

    near_horizontal = np.array([175.0, 178.0, 2.0, 5.0])  # around 0° ≡ 180°
    sd = axial_sd(near_horizontal)
    # the same set turned by 1° (across the wrap): equal SDs, means 1° apart as axes, so β = 1 and
    # d = √(1 − exp(−¼ · 1 / (2 sd²)))
    turned = (near_horizontal + 1.0) % 180.0
    expected = np.sqrt(1.0 - np.exp(-0.25 / (2.0 * sd * sd)))
    assert orientation_hellinger(near_horizontal, turned) == pytest.approx(expected, rel=1e-9)
    assert orientation_hellinger(near_horizontal, (near_horizontal + 90.0) % 180.0) > 0.99


def test_standard_error_difference_is_eq_15_and_asymmetric():
    from bark.analysis.circular import standard_error_difference

    assert standard_error_difference(10.0, 2.0, 16.0) == pytest.approx(3.0)
    assert standard_error_difference(16.0, 0.5, 10.0) == pytest.approx(12.0)
    assert standard_error_difference(178.0, 2.0, 4.0, axial=True) == pytest.approx(3.0)  # 6° apart as axes
    # a pattern known without error: the same mean is no distance, another is infinitely far
    assert standard_error_difference(10.0, 0.0, 10.0) == 0.0
    assert standard_error_difference(10.0, 0.0, 10.5) == math.inf


@given(
    centre=st.floats(0.0, 180.0),
    spread=st.floats(0.01, 40.0),  # wider, and the mean axis of a few samples is ill-conditioned
    n=st.integers(2, 60),
    seed=st.integers(0, 2**32 - 1),
)
def test_axial_statistics_are_scipys(centre, spread, n, seed):
    """bark computes the doubled-angle mean and SD itself (importing scipy.stats costs every run
    0.8 s); they are scipy.stats.circmean/circstd with low=0, high=180, also near the 0°/180° wrap."""
    from scipy import stats

    deg = np.random.default_rng(seed).normal(centre, spread, n) % 180.0
    mean, ref = axial_mean(deg), float(stats.circmean(deg, high=180.0, low=0.0)) % 180.0
    assert min(abs(mean - ref), 180.0 - abs(mean - ref)) < 1e-9
    assert axial_sd(deg) == pytest.approx(float(stats.circstd(deg, high=180.0, low=0.0)), rel=1e-9, abs=1e-7)  # √(−2 ln R) cancels as R → 1


def _strands(n_strands: int = 12, length: int = 60, radius: float = 1.0, rise: float = 0.05):
    """Vertical strands of bases round a trunk, each a chain of springs, joined to the next strand
    by one bridge at the top only: one network, whose strands a window shows apart."""
    theta = np.repeat(np.arange(n_strands) * 2 * np.pi / n_strands, length)
    z = np.tile(np.arange(length) * rise, n_strands)
    points = np.column_stack([radius * np.cos(theta), radius * np.sin(theta), z])
    ids = np.arange(n_strands * length).reshape(n_strands, length)
    chain = np.column_stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()])
    bridges = np.column_stack([ids[:, -1], np.roll(ids[:, -1], -1)])
    return points, np.concatenate([chain, bridges])


def test_windows_show_a_network_of_vertical_strands_as_vertical_patches():
    points, pairs = _strands()
    intact = np.ones(len(pairs), bool)
    whole = patch_statistics(points, np.zeros(len(points), int), 7)
    assert len(whole) == 1  # one connected network round the trunk
    rows = patch_statistics(points, window_labels(points, pairs, intact, 0.5), 7)
    assert len(rows) >= 12
    assert all(abs(r["orientation_deg"] - 90.0) < 1e-6 and r["anisotropy"] > 0.99 for r in rows)


@given(st.integers(0, 2**32 - 1), st.floats(0.05, 3.0))
def test_window_patches_refine_the_patches_and_stay_in_one_window(seed, size):
    rng = np.random.default_rng(seed)
    n = 200
    theta, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 2.0, n)
    r = rng.uniform(0.5, 1.5, n)
    points = np.column_stack([r * np.cos(theta), r * np.sin(theta), z])
    pairs = rng.integers(0, n, size=(400, 2))
    intact = rng.random(400) < 0.7
    labels = window_labels(points, pairs, intact, size)
    p = pairs[intact]
    joined = labels[p[:, 0]] == labels[p[:, 1]]
    whole = window_labels(points, pairs, intact, 1e9)  # one window: the patches themselves
    for label in np.unique(labels):  # every window patch lies inside one whole patch
        assert len(np.unique(whole[labels == label])) == 1
    rows = np.floor((z - z.min()) / size)
    assert np.all(rows[p[joined, 0]] == rows[p[joined, 1]])  # never across a row of windows
