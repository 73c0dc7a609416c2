"""Patterns on their own (bark.analysis.pattern), their comparison (bark.analysis.compare), and the commands over them
(bark analyze, bark compare)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from bark.analysis.circular import hellinger
from bark.analysis.compare import compare, d_p, distances, pairing, quartet
from bark.errors import BarkError, BarkWarning
from bark.io.output import patch_columns
from bark.io.files import write_csv
from bark.analysis.pattern import Pattern, PatternStatistics, axial_se, read, wrapped_normal_se
from bark_cli.main import cli

finite = st.floats(-50, 50, allow_nan=False)
sds = st.floats(0.05, 20)


# -- Hellinger distance -----------------------------------------------------------------------------
@settings(max_examples=60, deadline=None)
@given(finite, sds, finite, sds)
def test_hellinger_is_one_minus_the_bhattacharyya_integral(mp, sp, mq, sq):
    """H² = 1 − ∫ √(p q) for two normals, the integral done numerically (scipy.integrate.quad) over
    where √(p q) lives: it is a normal's shape, of centre c and SD s below, so 40 s either side of
    c holds all of it (a range set by p and q alone can miss a narrow peak between breakpoints)."""
    from scipy import integrate, stats

    c = (mp * sq**2 + mq * sp**2) / (sp**2 + sq**2)
    s = math.sqrt(2.0 * sp**2 * sq**2 / (sp**2 + sq**2))
    bc, _ = integrate.quad(lambda x: math.sqrt(stats.norm.pdf(x, mp, sp) * stats.norm.pdf(x, mq, sq)), c - 40 * s,
                           c + 40 * s, points=[c], limit=200, epsabs=1e-12, epsrel=1e-10)
    expected = math.sqrt(max(0.0, 1.0 - bc))
    assert hellinger(mp, sp, mq, sq) == pytest.approx(expected, abs=2e-6)


def test_hellinger_is_zero_for_identical_and_tends_to_one_far_apart():
    assert hellinger(3.0, 2.0, 3.0, 2.0) == 0.0
    assert hellinger(0.0, 1.0, 1e3, 1.0) == pytest.approx(1.0, abs=1e-12)
    assert hellinger(0.0, 1.0, 0.0, 1e6) > 0.99  # same mean, very different spread
    far = [hellinger(0.0, 1.0, d, 1.0) for d in (0.5, 1.0, 2.0, 4.0, 8.0)]
    assert far == sorted(far) and far[-1] > 0.999


# -- circular statistics ----------------------------------------------------------------------------
def _wrapped_normal(rng, centre, sd_deg, n):
    """Axial orientations whose doubled angles are wrapped normal with circular SD ``sd_deg`` (axes)."""
    return (centre + rng.normal(0.0, sd_deg, n)) % 180.0


@pytest.mark.parametrize("centre", [0.5, 90.0, 179.5])
def test_axial_standard_error_is_the_spread_of_the_mean_over_samples(centre):
    """Fisher's SE of the axial mean agrees with the spread of means over repeated samples (Monte
    Carlo, 4000 samples of 40 orientations; near the 0°/180° wrap too)."""
    from bark.analysis.circular import axial_difference, axial_mean

    rng = np.random.default_rng(7)
    samples = [_wrapped_normal(rng, centre, 20.0, 40) for _ in range(4000)]
    means = np.array([axial_mean(s) for s in samples])
    spread = float(np.sqrt(np.mean(axial_difference(means, centre) ** 2)))
    se = float(np.mean([axial_se(s) for s in samples]))
    assert se == pytest.approx(spread, rel=0.06)
    assert wrapped_normal_se(20.0, 40) == pytest.approx(spread, rel=0.06)


def test_axial_standard_error_of_one_orientation_is_unknown():
    assert math.isnan(axial_se([30.0]))
    assert axial_se([30.0, 30.0, 30.0]) == 0.0
    assert axial_se([0.0, 90.0]) == math.inf  # opposite axes: no mean axis


# -- PCA of synthetic patches -----------------------------------------------------------------------
@settings(max_examples=50, deadline=None)
@given(st.floats(0, 179.9), st.floats(1.2, 8.0))
def test_statistics_of_ellipse_patches_with_a_known_axis(angle, aspect):
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    a = np.radians(angle)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    pts = (np.column_stack([aspect * np.cos(t), np.sin(t)]) @ rot.T)
    p = Pattern(points=np.vstack([pts, pts + 100]), patches=np.repeat([0, 1], 64), units="m")
    s = p.statistics()
    assert s.n_patches == 2
    assert np.allclose(((s.patches.orientation_deg - angle + 90) % 180) - 90, 0.0, atol=1e-6)
    assert np.allclose(s.patches.anisotropy, (aspect**2 - 1) / (aspect**2 + 1), atol=1e-9)
    assert s.orientation.sd_deg == pytest.approx(0.0, abs=1e-5)
    assert s.anisotropy.mean == pytest.approx((aspect**2 - 1) / (aspect**2 + 1), abs=1e-9)


def test_a_patch_across_the_theta_seam_measures_as_away_from_it():
    """A vertical strip of bases at θ = −3°..3° on the trunk (across the seam of arctan2) has the
    same statistics as the same strip at θ = 87°..93°."""
    r = 1.0
    th = np.radians(np.linspace(-3, 3, 4))
    z = np.linspace(0, 1.5, 12)
    T, Z = np.meshgrid(th, z)
    def strip(turn):
        return np.column_stack([r * np.cos(T.ravel() + turn), r * np.sin(T.ravel() + turn), Z.ravel()])
    seam = Pattern(points=strip(0.0), patches=np.zeros(T.size, int)).statistics()
    away = Pattern(points=strip(np.pi / 2), patches=np.zeros(T.size, int)).statistics()
    assert seam.patches.orientation_deg[0] == pytest.approx(90.0, abs=1e-9)
    assert seam.patches.anisotropy[0] == pytest.approx(away.patches.anisotropy[0], abs=1e-12)
    assert seam.patches.rows()[0]["theta_deg"] == pytest.approx(0.0, abs=1e-9) or \
        seam.patches.rows()[0]["theta_deg"] == pytest.approx(360.0, abs=1e-9)


# -- quartets ---------------------------------------------------------------------------------------
def _matrix(pairs: dict) -> np.ndarray:
    d = np.zeros((4, 4))
    for (i, j), v in pairs.items():
        d[i, j] = d[j, i] = v
    return d


def test_a_quartet_whose_two_closest_pairs_are_disjoint_is_valid():
    d = _matrix({(0, 1): 0.1, (2, 3): 0.2, (0, 2): 0.5, (0, 3): 0.6, (1, 2): 0.7, (1, 3): 0.8})
    q = quartet(d)
    assert q.valid and q.pairing == ((0, 1), (2, 3)) and not q.tied
    assert [e[:2] for e in q.edges] == [(0, 1), (2, 3), (0, 2), (0, 3), (1, 2), (1, 3)]


def test_a_quartet_whose_two_closest_pairs_share_a_pattern_is_not_valid():
    d = _matrix({(0, 1): 0.1, (0, 2): 0.2, (2, 3): 0.3, (0, 3): 0.6, (1, 2): 0.7, (1, 3): 0.8})
    q = quartet(d)
    assert not q.valid and q.pairing is None


@settings(max_examples=100, deadline=None)
@given(st.permutations(range(4)), st.lists(st.floats(0.01, 1.0), min_size=6, max_size=6, unique=True))
def test_quartet_verdict_does_not_depend_on_how_the_patterns_are_numbered(perm, values):
    pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    d = _matrix(dict(zip(pairs, values)))
    p = np.array(perm)
    assert quartet(d).valid == quartet(d[np.ix_(p, p)]).valid


def test_d_p_pairing_is_valid_when_nearest_pointers_are_mutual():
    d = np.array([[0, 1, 5, 6], [2, 0, 7, 8], [5, 6, 0, 1], [9, 9, 3, 0]], float)
    assert pairing(d).valid and pairing(d).nearest == (1, 0, 3, 2)
    d[3, 2], d[3, 0] = 9.0, 0.5
    assert not pairing(d).valid


def test_a_pattern_with_no_spread_still_gets_a_pairing():
    """A standard error of zero makes a d_P infinite (every other mean infinitely far), not missing:
    the four patterns are still paired — that one has no nearest, so no pairing is valid."""
    s = [PatternStatistics.of_summary(str(i), 10, 10.0 * i, 0.0 if i == 3 else 5.0) for i in range(4)]
    c = compare(s)
    assert np.isinf(c.d_p["orientation"][3, :3]).all()
    assert c.pairings["orientation"] is not None and not c.pairings["orientation"].valid
    assert c.pairings["orientation"].nearest[3] == -1  # none: every other mean is infinitely far
    assert c.pairings["anisotropy"] is None  # no pattern gives it
    with pytest.raises(BarkError, match="lacks"):
        pairing(c.d_p["anisotropy"])


def test_d_p_is_in_standard_errors_of_the_first_pattern():
    a = PatternStatistics.of_summary("a", 16, 47.0, 34.4)
    b = PatternStatistics.of_summary("b", 9, 90.0, 9.3)
    m = d_p([a, b])
    assert m[0, 1] == pytest.approx(43.0 / a.orientation.se_deg)
    assert m[1, 0] == pytest.approx(43.0 / b.orientation.se_deg)
    h = distances([a, b])
    assert h[0, 1] == h[1, 0] == pytest.approx(hellinger(47.0, 34.4, 90.0, 9.3))


def test_orientations_across_the_wrap_are_close():
    a = PatternStatistics.of_summary("a", 20, 2.0, 5.0)
    b = PatternStatistics.of_summary("b", 20, 178.0, 5.0)
    assert distances([a, b])[0, 1] == pytest.approx(hellinger(0.0, 5.0, 4.0, 5.0))


def test_compare_without_anisotropy_gives_no_anisotropy_quartet():
    s = [PatternStatistics.of_summary(str(i), 10, 10.0 * i, 5.0 + i) for i in range(4)]
    c = compare(s)
    assert c.quartets["orientation"] is not None and c.quartets["anisotropy"] is None
    assert np.isnan(c.hellinger["anisotropy"][0, 1])
    with pytest.raises(BarkError, match="at least two"):
        compare(s[:1])


# -- the photograph CSV -----------------------------------------------------------------------------
def _csv(tmp_path, text, name="bark.csv"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def _strip(x0, y_down, n=10, dx=0.0, dy=1.0, label="A"):
    return "".join(f"{x0 + i * dx + (i % 2) * 0.01},{y_down + i * dy},{label}\n" for i in range(n))


def test_image_y_down_is_turned_up(tmp_path):
    """A strip drawn straight down the image is vertical (90°); one running down to the right in
    the image runs down to the right on the bark too (135°)."""
    p = _csv(tmp_path, "x,y,patch\n" + _strip(10, 0, label="v") + _strip(50, 0, dx=1.0, dy=1.0, label="d"))
    s = read(p)
    rows = {r["patch"]: r for r in s.patches.rows()}
    assert s.patches.columns[2:4] == ["x", "y"]
    assert rows[1]["orientation_deg"] == pytest.approx(90.0, abs=0.2)  # 'v' is label 1 ('d' sorts first)
    assert rows[0]["orientation_deg"] == pytest.approx(135.0, abs=0.1)
    assert rows[0]["y"] < 0  # up is positive: below the image's top edge


def test_pixel_scale_gives_metres(tmp_path):
    p = _csv(tmp_path, "# digitised\n# pixels_per_metre: 100\nX, Y ,Patch,extra\n"
             + "".join(f"{i}.0,{2 * i}.0,1,whatever\n" for i in range(8)))
    pattern = Pattern.from_csv(p)
    assert pattern.units == "m"
    assert pattern.points[:, 0].max() == pytest.approx(0.07)
    assert pattern.points[:, 1].min() == pytest.approx(-0.14)


def test_three_columns_on_the_trunk(tmp_path):
    th = np.linspace(0, 0.2, 9)
    text = "x,y,z,patch\n" + "".join(f"{np.cos(t)},{np.sin(t)},{0.3 * t},7\n" for t in th)
    pattern = Pattern.from_csv(_csv(tmp_path, text))
    assert pattern.on_trunk and pattern.statistics().patches.columns[2:4] == ["theta_deg", "z"]


BAD_CSV = [
    ("x,y,patch\n1,2,A\n1,abc,A\n", "line 3: y = 'abc' is not a number"),
    ("x,y,patch\n1,2,A\nnan,2,A\n", "line 3: x = nan is not a finite number"),
    ("x,y,patch\n1,2,A\n1,-inf,A\n", "line 3: y = -inf is not a finite number"),
    ("x,y,patch\n1,1e309,A\n", "line 2: y = 1e309 is not a finite number"),
    ("x,y,patch\n1,2\n", "line 2: 2 values, the header names 3"),
    ("x,y,patch\n1,2,A,4\n", "line 2: 4 values, the header names 3"),
    ("x,y,patch\n1,2, \n", "line 2: patch is empty"),
    ("# only a comment\nx,patch\n1,A\n", "line 2: the header has no column y"),
    ("x,y,x,patch\n1,2,3,A\n", "line 1: a column is named twice"),
    ("x,y,patch\n", "a header but no leaf bases"),
    ("", "no header and no rows"),
    ("# pixels_per_metre: -3\nx,y,patch\n1,2,A\n", "line 1: pixels_per_metre must be > 0"),
    ("# pixels_per_metre: lots\nx,y,patch\n1,2,A\n", "line 1: pixels_per_metre = 'lots' is not a number"),
]


@pytest.mark.parametrize("text,message", BAD_CSV)
def test_csv_errors_name_their_line(tmp_path, text, message):
    with pytest.raises(BarkError) as err:
        Pattern.from_csv(_csv(tmp_path, text))
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_binary_file_is_not_a_csv(tmp_path):
    p = tmp_path / "photo.csv"
    p.write_bytes(b"\xff\xd8\xff\xe0JFIF\x00")
    with pytest.raises(BarkError, match="not a text file"):
        read(p)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(allow_nan=True, allow_infinity=True), st.floats(allow_nan=True, allow_infinity=True),
                          st.text(min_size=0, max_size=4)), min_size=0, max_size=12))
def test_any_csv_is_read_or_refused_in_one_line(tmp_path_factory, rows):
    """Whatever the values (NaN, ±inf, 1e±308, odd labels), a CSV gives a pattern or one BarkError;
    a patch without extent (its points at one place) has no orientation, and a one-line warning
    says it is left out."""
    import csv
    import io
    import warnings

    from bark.errors import BarkWarning

    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["x", "y", "patch"])
    for x, y, label in rows:
        w.writerow([repr(x), repr(y), label])
    p = tmp_path_factory.mktemp("csv") / "p.csv"
    p.write_text(buf.getvalue(), encoding="utf-8")
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        try:
            s = read(p)
        except BarkError as err:
            assert "\n" not in str(err)
            s = None
    assert all(issubclass(w.category, BarkWarning) and "\n" not in str(w.message) for w in said), said
    if s is not None:
        finite = np.isfinite(s.patches.orientation_deg)
        assert finite.all() or any("no extent" in str(w.message) for w in said)


# -- summaries and files ----------------------------------------------------------------------------
def test_the_papers_observed_summaries_read():
    ret = read("examples/paper/observed-reticulate.toml")
    elo = read("examples/paper/observed-elongated.toml")
    assert (ret.n_patches, ret.orientation.mean_deg, ret.orientation.sd_deg) == (16, 47.0, 34.4)
    assert (elo.n_patches, elo.orientation.sd_deg) == (9, 9.3)
    assert ret.patches is None and ret.anisotropy is None


@pytest.mark.parametrize("body,message", [
    ("[pattern]\nn_patches = 3\nmean_orientation_deg = 1.0\n", "has no sd_orientation_deg"),
    ("[pattern]\nn_patches = 0\nmean_orientation_deg = 1.0\nsd_orientation_deg = 1.0\n", "at least 1"),
    ("[pattern]\nn_patches = 3\nmean_orientation_deg = nan\nsd_orientation_deg = 1.0\n", "a finite number"),
    ("[pattern]\nn_patches = 3\nmean_orientation_deg = 1.0\nsd_orientation_deg = -1.0\n", "must be >= 0"),
    ("[pattern]\nn_patches = 3.5\nmean_orientation_deg = 1.0\nsd_orientation_deg = 1.0\n", "a whole number"),
    ("[pattern]\nn_patches = 3\nmean_orientation_deg = 1.0\nsd_orientation_deg = 1.0\nmean = 2\n", "unknown"),
    ("[other]\n", "no [pattern] table"),
    ("[pattern\n", "not valid TOML"),
])
def test_summary_errors(tmp_path, body, message):
    p = tmp_path / "s.toml"
    p.write_text(body)
    with pytest.raises(BarkError, match=message.replace("[", r"\[")):
        read(p)


def test_patches_csv_keeps_the_columns_of_a_pattern_in_a_plane(tmp_path):
    pts = np.random.default_rng(1).normal(size=(20, 2))
    rows = Pattern(points=pts, patches=np.zeros(20, int)).patch_table().rows()
    path = write_csv(tmp_path / "patches.csv", rows, patch_columns(rows))
    header = path.read_text().splitlines()[0].split(",")
    assert header == ["patch", "size", "x", "y", "orientation_deg", "anisotropy", "lambda1", "lambda2"]
    extra = [{**r, "colour": "red"} for r in rows]
    assert patch_columns(extra)[-1] == "colour"


def test_a_state_file_and_its_run_folder_give_the_same_statistics(broken_run):
    a = read(broken_run)
    b = read(broken_run / "state.npz", min_size=a_min(broken_run))
    assert a.n_patches == b.n_patches > 0
    assert a.orientation == b.orientation


def a_min(folder):
    return json.loads((folder / "summary.json").read_text())["settings"]["run"]["min_patch_size"]


@pytest.mark.parametrize("bytes_", [b"", b"PK\x03\x04garbage", b"not a zip at all"])
def test_a_damaged_state_file_is_one_line(tmp_path, bytes_):
    p = tmp_path / "state.npz"
    p.write_bytes(bytes_)
    with pytest.raises(BarkError) as err:
        read(p)
    assert "state file" in str(err.value) and "\n" not in str(err.value)


# -- the commands -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def broken_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "small"
    r = CliRunner().invoke(cli, ["simulate", "--n-bases", "600", "-G", "0.014", "--until-patches", "12", "--until-time", "400", "--quiet",
                                 "--out", str(out)])
    assert r.exit_code == 0, r.output
    return out


def test_analyze_writes_its_table_and_figures(broken_run, tmp_path):
    out = tmp_path / "a"
    r = CliRunner().invoke(cli, ["analyze", str(broken_run), "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in out.iterdir()) == ["histogram.png", "patches.csv", "radial.png", "statistics.json"]
    stats = json.loads((out / "statistics.json").read_text())
    assert stats["n_patches"] == read(broken_run).n_patches
    assert "orientation mean" in r.output


def test_compare_four_patterns_with_a_summary(broken_run, tmp_path):
    out = tmp_path / "c"
    csv = _csv(tmp_path, "x,y,patch\n" + _strip(0, 0, label="a") + _strip(30, 0, dx=0.2, label="b"))
    r = CliRunner().invoke(cli, ["compare", str(broken_run), str(csv), "examples/paper/observed-reticulate.toml",
                                 "examples/paper/observed-elongated.toml", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in out.iterdir()) == ["comparison.json", "quartets.png"]
    report = json.loads((out / "comparison.json").read_text())
    assert "quartet" in report["orientation"] and "quartet" not in report["anisotropy"]
    assert "quartet (orientation):" in r.output


@pytest.mark.parametrize("bad", ["missing-folder", "nowhere.csv", "pattern.txt"])
def test_compare_with_a_bad_pattern_writes_nothing(broken_run, tmp_path, bad):
    out = tmp_path / "c"
    (tmp_path / "pattern.txt").write_text("x")
    r = CliRunner().invoke(cli, ["compare", str(broken_run), str(tmp_path / bad), "--out", str(out)])
    assert r.exit_code == 2
    assert r.output.count("\n") == 1 and r.output.startswith("bark: error: ")
    assert not out.exists()


def test_analyze_a_run_without_its_state(tmp_path):
    run = tmp_path / "r"
    run.mkdir()
    r = CliRunner().invoke(cli, ["analyze", str(run), "--out", str(tmp_path / "a")])
    assert r.exit_code == 2 and "state-snapshot" in r.output and not (tmp_path / "a").exists()


def test_analyze_refuses_an_out_that_is_a_file(broken_run, tmp_path):
    f = tmp_path / "file"
    f.write_text("")
    r = CliRunner().invoke(cli, ["analyze", str(broken_run), "--out", str(f)])
    assert r.exit_code == 2 and "--out" in r.output


def test_names_given_twice_are_numbered(broken_run, tmp_path):
    r = CliRunner().invoke(cli, ["compare", str(broken_run), str(broken_run), "--out", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    report = json.loads((tmp_path / "c" / "comparison.json").read_text())
    assert [p["name"] for p in report["patterns"]] == ["1:small", "2:small"]
    assert report["orientation"]["hellinger"][0][1] == 0.0


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.booleans())
def test_mirroring_the_statistics_is_measuring_the_mirrored_pattern(seed, on_trunk):
    rng = np.random.default_rng(seed)
    n = 60
    if on_trunk:
        th, z = rng.uniform(-np.pi, np.pi, n), rng.uniform(0, 2, n)
        pts = np.column_stack([np.cos(th), np.sin(th), z])
    else:
        pts = rng.normal(size=(n, 2)) * [3.0, 1.0]
    p = Pattern(points=pts, patches=rng.integers(0, 4, n))
    a, b = p.statistics().mirrored(), p.mirrored().statistics()
    assert np.allclose(((a.patches.orientation_deg - b.patches.orientation_deg + 90) % 180) - 90, 0, atol=1e-7)
    assert float(((a.orientation.mean_deg - b.orientation.mean_deg + 90) % 180) - 90) == pytest.approx(0, abs=1e-7)
    assert a.orientation.sd_deg == pytest.approx(b.orientation.sd_deg, abs=1e-9)
    assert np.allclose(a.patches.centroid, b.patches.centroid)
    assert np.all((a.patches.orientation_deg >= 0) & (a.patches.orientation_deg < 180))


def test_compare_mirror_flips_one_pattern(broken_run, tmp_path):
    r = CliRunner().invoke(cli, ["compare", "examples/paper/observed-reticulate.toml",
                                 "examples/paper/observed-elongated.toml", "--mirror", "1", "--out", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    report = json.loads((tmp_path / "c" / "comparison.json").read_text())
    assert report["patterns"][0]["mean_orientation_deg"] == pytest.approx(133.0)
    assert report["patterns"][0]["name"] == "observed reticulate (mirrored)"
    r = CliRunner().invoke(cli, ["compare", str(broken_run), str(broken_run), "--mirror", "3", "--out", str(tmp_path / "d")])
    assert r.exit_code == 2 and "--mirror 3" in r.output and not (tmp_path / "d").exists()


# -- colours ----------------------------------------------------------------------------------------
def _neighbours_differ(labels, pairs, intact, rgb, min_size):
    sizes = np.bincount(labels)
    a, b = labels[pairs[~intact, 0]], labels[pairs[~intact, 1]]
    across = (a != b) & (sizes[a] >= min_size) & (sizes[b] >= min_size)
    i, j = pairs[~intact][across].T
    return bool((rgb[i] != rgb[j]).any(axis=1).all()), int(across.sum())


def test_no_two_neighbouring_patches_of_a_run_share_a_colour(broken_run):
    from bark.analysis.pattern import patch_colours

    with np.load(broken_run / "state.npz") as d:
        labels, pairs, intact = d["labels"], d["pairs"], d["intact"]
    rgb = patch_colours(labels, 7, pairs, intact)
    differ, n_across = _neighbours_differ(labels, pairs, intact, rgb, 7)
    assert differ and n_across > 50
    assert len({tuple(c) for c in rgb}) <= 10  # a map needs few colours (and fragments are grey)


# Machado, Oliveira & Fernandes (2009), severity 1: the colours a deuteranope and a protanope see, on linear RGB
DICHROMATS = {"normal": np.eye(3),
              "deuteranopia": np.array([[0.367322, 0.860646, -0.227968], [0.280085, 0.672501, 0.047413],
                                        [-0.011820, 0.042940, 0.968881]]),
              "protanopia": np.array([[0.152286, 1.052583, -0.204868], [0.114503, 0.786281, 0.099216],
                                      [-0.003882, -0.048116, 1.051998]])}


def _lab(rgb8: np.ndarray, vision: np.ndarray) -> np.ndarray:
    """CIELAB (D65) of sRGB colours ``rgb8`` as seen with ``vision`` (a matrix on linear RGB)."""
    c = rgb8 / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4) @ vision.T
    xyz = np.clip(linear, 0, 1) @ np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722],
                                             [0.0193, 0.1192, 0.9505]]).T / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[:, 1] - 16, 500 * (f[:, 0] - f[:, 1]), 200 * (f[:, 1] - f[:, 2])], axis=1)


@pytest.mark.parametrize("vision", list(DICHROMATS))
def test_the_patch_colours_stay_apart_for_colour_blind_eyes(vision):
    """Every two patch colours, and each against the fragments' grey, at least 15 ΔE*ab apart with
    normal vision and simulated deuteranopia and protanopia; the palette bark had before passes only
    with normal vision (its orange and green 4.6 apart for a protanope)."""
    from itertools import combinations

    from bark.analysis.pattern import FRAGMENT_GREY, PALETTE

    def closest(colours) -> float:
        lab = _lab(np.vstack([colours, FRAGMENT_GREY]).astype(float), DICHROMATS[vision])
        return min(np.linalg.norm(lab[i] - lab[j]) for i, j in combinations(range(len(lab)), 2))

    assert closest(PALETTE) >= 15.0, (vision, closest(PALETTE))
    old = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75),
           (227, 119, 194), (188, 189, 34), (23, 190, 207)]  # matplotlib's tab10 less its grey, bark's before
    assert (closest(old) >= 15.0) == (vision == "normal")  # orange and green merge for a dichromat


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.05, 0.6), st.integers(1, 9))
def test_greedy_patch_colouring_on_random_cracks(seed, broken, min_size):
    """Any lattice with any springs broken: neighbouring patches (joined by a broken spring) never
    share a colour, and fragments are grey."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from bark.analysis.pattern import FRAGMENT_GREY, patch_colours

    rng = np.random.default_rng(seed)
    n = 400
    pairs = np.array([(i, i + d) for d in (1, 20, 21) for i in range(n - d)])
    intact = rng.random(len(pairs)) > broken
    p = pairs[intact]
    labels = connected_components(coo_matrix((np.ones(len(p)), (p[:, 0], p[:, 1])), shape=(n, n)), directed=False)[1]
    rgb = patch_colours(labels, min_size, pairs, intact)
    assert _neighbours_differ(labels, pairs, intact, rgb, min_size)[0]
    small = np.bincount(labels)[labels] < min_size
    assert (rgb[small] == FRAGMENT_GREY).all() and not (rgb[~small] == FRAGMENT_GREY).all(axis=1).any()


@given(st.lists(st.integers(0, 60), max_size=300), st.integers(1, 9))
def test_label_colours_index_the_colours_that_follow_the_labels(labels, min_size):
    """The animation colours a frame by palette index (``label_colours``): the same colours as
    ``patch_colours`` without springs gives, fragments grey."""
    from bark.analysis.pattern import FRAGMENT_GREY, PALETTE, label_colours, patch_colours

    labels = np.array(labels, dtype=np.int64)
    index = label_colours(labels, min_size)
    assert index.dtype == np.uint8 and index.shape == labels.shape
    np.testing.assert_array_equal(np.vstack([PALETTE, FRAGMENT_GREY])[index], patch_colours(labels, min_size))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), frames=st.integers(1, 6), min_size=st.integers(1, 9))
def test_the_frames_of_a_run_keep_their_colours_and_end_on_the_pattern_s(seed, frames, min_size):
    """``lineage_colours`` on a run's frames (bases appended, springs only breaking): the last frame
    is coloured as ``patch_colours`` colours the end, fragments are grey in every frame, a frame
    nothing broke since keeps its colours, and neighbouring patches of a frame differ."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from bark.analysis.pattern import FRAGMENT_GREY, PALETTE, lineage_colours, patch_colours, rgb

    rng = np.random.default_rng(seed)
    n = 400
    pairs = np.array([(i, i + d) for d in (1, 20, 21) for i in range(n - d)])
    broke = np.sort(rng.uniform(0, 1, len(pairs)) ** 0.5)[rng.permutation(len(pairs))]  # when each breaks
    times = np.sort(rng.uniform(0.3, 1.0, frames))
    counts = np.sort(rng.integers(200, n + 1, frames))
    counts[-1] = n
    for k in range(frames - 1, 0, -1):
        if rng.random() < 0.3:  # a frame the next repeats: nothing broke or joined between them
            times[k - 1], counts[k - 1] = times[k], counts[k]
    labels_along, intact_along = [], []
    for t, m in zip(times, counts):
        intact = broke > t
        keep = intact & (pairs < m).all(axis=1)
        p = pairs[keep]
        labels_along.append(connected_components(coo_matrix((np.ones(len(p)), (p[:, 0], p[:, 1])), shape=(m, m)),
                                                  directed=False)[1])
        intact_along.append(intact)
    colours = lineage_colours(labels_along, min_size, pairs, intact_along[-1])
    np.testing.assert_array_equal(rgb(colours[-1]), patch_colours(labels_along[-1], min_size, pairs, intact_along[-1]))
    for k, (labels, index) in enumerate(zip(labels_along, colours)):
        small = np.bincount(labels)[labels] < min_size
        assert (index[small] == len(PALETTE)).all() and (index[~small] < len(PALETTE)).all()
        inside = (pairs < labels.size).all(axis=1)
        differ = _neighbours_differ(labels, pairs[inside], intact_along[k][inside], rgb(index), min_size)[0]
        if not differ:  # only where a patch's neighbours hold every colour
            broken = pairs[inside & ~intact_along[k]]
            sizes, across = np.bincount(labels), labels[broken]
            counted = (sizes[across] >= min_size).all(axis=1)  # two fragments, both grey, are no clash
            clash = across[(across[:, 0] != across[:, 1]) & counted & (index[broken[:, 0]] == index[broken[:, 1]])]
            for a in (min(pair, key=lambda q: (sizes[q], q)) for pair in clash.tolist()):  # the one recoloured
                around = np.concatenate([across[across[:, 0] == a, 1], across[across[:, 1] == a, 0]])
                assert len({int(index[labels == q][0]) for q in around if sizes[q] >= min_size}) == len(PALETTE)
        if k and labels.size == labels_along[k - 1].size and (labels == labels_along[k - 1]).all():
            np.testing.assert_array_equal(index, colours[k - 1])
    assert (rgb(colours[0])[np.bincount(labels_along[0])[labels_along[0]] < min_size] == FRAGMENT_GREY).all()


def test_a_split_leaves_the_larger_piece_its_colour():
    from bark.analysis.pattern import lineage_colours

    pairs = np.array([(i, i + 1) for i in range(29)])
    intact = np.ones(29, bool)
    intact[9] = False  # bases 0-9 and 10-29 at the end; one patch before
    colours = lineage_colours([np.zeros(30, np.int64), np.r_[np.zeros(10, np.int64), np.ones(20, np.int64)]], 7,
                              pairs, intact)
    assert (colours[0] == colours[1][15]).all() and colours[1][0] != colours[1][15]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), patches=st.integers(1, 40), on_trunk=st.booleans(),
       min_size=st.integers(1, 9))
def test_the_patch_table_is_its_definitions_patch_by_patch(seed, patches, on_trunk, min_size):
    """The table takes every patch's centroid and PCA in a few array passes; the definitions are
    ``tangent_plane`` and ``principal_axes`` on each patch alone: the same values to rounding."""
    from bark.analysis.circular import principal_axes, tangent_plane

    rng = np.random.default_rng(seed)
    labels = rng.integers(0, patches, int(rng.integers(1, 400))) * 7 - 3  # any ids, interleaved
    n = len(labels)
    if on_trunk:  # patches spread round the trunk (some across θ = ±π) and stretched any way
        theta = np.repeat(rng.uniform(-math.pi, math.pi), n) + rng.normal(0, 0.05, n) + (labels % 5) * 0.7
        z = rng.normal(0, rng.uniform(0.001, 0.2), n) + labels * 0.01
        r = rng.uniform(0.1, 2.0)
        points = np.column_stack([r * np.cos(theta), r * np.sin(theta), z])
    else:
        points = rng.normal(0, 1, (n, 2)) @ rng.normal(0, 1, (2, 2)) + labels[:, None]
    table = Pattern(points=points, patches=labels).patch_table(min_size)
    ids, counts = np.unique(labels, return_counts=True)
    assert list(table.patch) == list(ids[counts >= min_size])
    for k, pid in enumerate(table.patch):
        mine = points[labels == pid]
        assert table.size[k] == len(mine)
        np.testing.assert_allclose(table.centroid[k], mine.mean(axis=0), rtol=1e-12, atol=1e-12)
        if len(mine) < 2:  # no extent: no orientation, no anisotropy
            assert (table.lambda1[k], table.lambda2[k]) == (0, 0)
            assert np.isnan(table.anisotropy[k]) and np.isnan(table.orientation_deg[k])
            continue
        o, a, l1, l2 = principal_axes(tangent_plane(mine) if on_trunk else mine)
        scale = max(l1, 1e-300)
        assert table.lambda1[k] == pytest.approx(l1, rel=1e-9, abs=1e-12 * scale)
        assert table.lambda2[k] == pytest.approx(l2, rel=1e-9, abs=1e-9 * scale)
        assert table.anisotropy[k] == pytest.approx(a, abs=1e-9)
        if l1 - l2 > 1e-6 * scale:  # an axis to compare (near-isotropic patches have none to speak of)
            assert abs((table.orientation_deg[k] - o + 90.0) % 180.0 - 90.0) < 1e-6
            assert 0.0 <= table.orientation_deg[k] < 180.0


def test_the_orientation_histogram_keeps_near_vertical_patches_in_one_bar():
    """Bins of 18° centred on 0°, 18°, ..., 90°: 89.96° and 90.04° fall in one bar (at an edge they
    were two), 179° and 1° in the horizontal bar, and every patch is counted once."""
    from bark_cli.figures import BINS, orientation_counts

    counts = orientation_counts([89.96, 90.04, 81.0, 98.99, 179.0, 1.0, 9.01, 45.0])
    assert counts.sum() == 8 and len(counts) == BINS == 10
    assert counts[5] == 4 and counts[0] == 2 and counts[1] == 1 and counts[2] + counts[3] == 1



@pytest.mark.parametrize("on_trunk", [False, True])
def test_a_patch_whose_points_are_all_at_one_place_has_no_orientation(on_trunk):
    """Digitised so (every base of a patch at one point) a patch read as "at 90°, SD 0, anisotropy
    0" and was fitted so; now it has none, is left out of the statistics, and a warning says so."""
    rng = np.random.default_rng(3)
    spread = rng.normal(0, 0.01, (20, 3 if on_trunk else 2)) + ([1.0, 0.0, 0.5] if on_trunk else [0.0, 0.0])
    spread[:, 2 if on_trunk else 1] *= 4.0  # elongated up the trunk
    stacked = np.tile([1.0, 0.0, 0.9] if on_trunk else [3.0, 3.0], (10, 1))
    pattern = Pattern(points=np.vstack([spread, stacked]), patches=np.r_[np.zeros(20, int), np.ones(10, int)])
    table = pattern.patch_table(7)
    assert np.isnan(table.orientation_deg[1]) and np.isnan(table.anisotropy[1])
    with pytest.warns(BarkWarning, match="1 of its 2 patches have no extent"):
        stats = pattern.statistics(7)
    assert stats.n_patches == 1 and stats.orientation.mean_deg == pytest.approx(table.orientation_deg[0])
    assert math.isfinite(stats.anisotropy.mean)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(0, 5), min_size=1, max_size=30), st.lists(st.tuples(st.integers(0, 29), st.integers(0, 29)),
                                                                       max_size=20), st.integers(1, 3))
def test_patch_colours_are_networkx_greedy_colouring_of_touching_patches(labels, pairs, min_size):
    """Patches that touch (a broken spring between them) get different colours — networkx's greedy
    colouring of the patches' graph, its colours renamed so that the one covering the most bases is
    the palette's first — and, where none touch, every patch the first colour (what that colouring
    gives an edgeless graph, without importing networkx)."""
    import networkx as nx

    from bark.analysis.pattern import PALETTE, _colour_of_label, _neighbouring

    labels = np.unique(np.asarray(labels), return_inverse=True)[1]  # labels 0 .. k − 1, as components gives them
    pairs = np.array([(i % labels.size, j % labels.size) for i, j in pairs], dtype=np.int64).reshape(-1, 2)
    intact = np.zeros(len(pairs), bool)
    got = _colour_of_label(labels, min_size, pairs, intact)
    sizes = np.bincount(labels)
    graph = nx.Graph()
    graph.add_nodes_from(np.flatnonzero(sizes >= min_size).tolist())
    graph.add_edges_from(_neighbouring(labels, sizes, pairs, min_size).tolist())
    greedy = nx.greedy_color(graph, strategy="smallest_last")
    for label, colour in greedy.items():  # the same colouring, its colours renamed (one to one)
        assert all((got[label] == got[other]) == (colour == greedy[other]) for other in greedy)
    shares = [sizes[[k for k in greedy if got[k] == c]].sum() for c in range(len(PALETTE))]
    assert shares == sorted(shares, reverse=True)  # the colour covering the most bases first
    assert (got[sizes < min_size] == len(PALETTE)).all()
