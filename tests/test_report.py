"""`bark report`: one self-contained page for a run or a sweep, checked in a real browser (headless
Chromium) where one is installed."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner

from bark_cli.main import cli

BROWSER = next((shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--virtual-time-budget=20000"]


@pytest.fixture(scope="module")
def reported(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "run"
    want = '["bulges", "anchors", "damping", "patch-statistics", "statistics-series", "pattern-image", "tree-image", ' \
           '"state-snapshot", "region-image"]'
    result = CliRunner().invoke(cli, ["simulate", "--scene", "whole-tree-small", "--until-time", "12", "--quiet",
                                      "--set", f"effects.want={want}", "--set", "effects.series_every=2.0", "--out", str(out)])
    assert result.exit_code == 0, result.output
    result = CliRunner().invoke(cli, ["report", str(out)])
    assert result.exit_code == 0, result.output
    return out


def _loaded_from(page: str) -> list[str]:
    """Every address the page's tags load something from (scripts, styles, images, frames)."""
    from html.parser import HTMLParser

    found = []

    class Tags(HTMLParser):
        def handle_starttag(self, tag, attrs):
            a = dict(attrs)
            for key in ("src", "href") if tag in ("script", "img", "link", "iframe", "source", "video") else ():
                if a.get(key):
                    found.append(a[key])

    Tags().feed(page)
    return found


def test_the_page_holds_everything_and_needs_no_network(reported):
    page = (reported / "report.html").read_text()
    assert all(src.startswith("data:") for src in _loaded_from(page))  # nothing fetched: plotly inlined
    assert page.count("<script>") >= 3  # the page's watch, plotly's bundle, the figures
    assert sum(src.startswith("data:image/png;base64,") for src in _loaded_from(page)) == 3  # tree, pattern, regions
    for words in ("Provenance", "Statistics at the end", "By region of the trunk", "The trunk in 3-D", "Along the run",
                  "Settings", "whole-tree-small"):
        assert words in page, words
    summary = json.loads((reported / "summary.json").read_text())
    assert summary["provenance"]["sessions"][0]["command"] in page.replace("&#x27;", "'").replace("&quot;", '"')


def test_a_fresh_run_removes_an_earlier_report(reported, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(reported, out)
    assert CliRunner().invoke(cli, ["simulate", "--until-time", "1", "--quiet", "--out", str(out)]).exit_code == 0
    assert not (out / "report.html").exists()


@pytest.mark.parametrize("make, words", [(lambda p: None, "no finished run"),
                                         (lambda p: (p / "summary.json").write_text("{oops"), "cannot be read")])
def test_a_folder_without_a_run_is_one_line(tmp_path, make, words):
    make(tmp_path)
    result = CliRunner().invoke(cli, ["report", str(tmp_path)])
    assert result.exit_code == 2 and words in result.stderr and len(result.stderr.splitlines()) == 1


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("small") / "run"
    want = '["anchors", "damping", "patch-statistics", "statistics-series", "state-snapshot"]'
    result = CliRunner().invoke(cli, ["simulate", "--n-bases", "600", "--until-time", "60", "--quiet", "--set",
                                      f"effects.want={want}", "--set", "effects.series_every=10.0", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


def _state_without(key: str):
    def damage(p):
        with np.load(p / "state.npz") as d:
            kept = {k: d[k] for k in d.files if k != key}
        np.savez(p / "state.npz", **kept)
    return damage


def _state_of_another_run(p):
    other = p.parent / "other"
    assert CliRunner().invoke(cli, ["simulate", "--n-bases", "400", "--until-time", "5", "--quiet", "--out",
                                    str(other)]).exit_code == 0
    shutil.copy(other / "state.npz", p / "state.npz")


@pytest.mark.parametrize("damage, words", [
    (lambda p: (p / "state.npz").write_bytes(b"garbage, not an archive"), "state.npz cannot be shown"),
    (lambda p: (p / "state.npz").write_bytes((p / "state.npz").read_bytes()[:5000]), "state.npz cannot be shown"),
    (_state_without("labels"), "state.npz cannot be shown"),
    (_state_of_another_run, "state.npz is not this run's: its n_bases is 400, the summary's 600"),
    (lambda p: (p / "statistics.csv").write_text("t_tu,n_patches\n1.0,lots\n"),
     "statistics.csv cannot be shown: row 1 holds &#x27;lots&#x27; in column n_patches"),
    (lambda p: (p / "statistics.csv").write_text("time,n_patches\n1.0,3\n"), "it has no column t_tu"),
    (lambda p: (p / "statistics.csv").write_bytes(b"t_tu\n\xff\xfe\n"), "statistics.csv cannot be read"),
])
def test_a_damaged_or_foreign_file_is_said_on_the_page_and_the_rest_shown(small_run, tmp_path, damage, words):
    out = tmp_path / "run"
    shutil.copytree(small_run, out)
    damage(out)
    result = CliRunner().invoke(cli, ["report", str(out)])
    assert result.exit_code == 0, result.output
    page = (out / "report.html").read_text()
    assert words in page
    assert "Statistics at the end" in page and "Settings" in page


@pytest.mark.parametrize("text", ["[1, 2, 3]", '"a run"', "null", '{"settings": [1]}'])
def test_a_summary_that_is_not_a_runs_is_one_line(small_run, tmp_path, text):
    out = tmp_path / "run"
    shutil.copytree(small_run, out)
    (out / "summary.json").write_text(text)
    result = CliRunner().invoke(cli, ["report", str(out)])
    assert result.exit_code == 2 and "is not a run's summary" in result.stderr, result.output
    assert len(result.stderr.splitlines()) == 1 and not (out / "report.html").exists()


@pytest.mark.parametrize("fmt, kind", [("svg", "data:image/svg+xml;base64,"), ("pdf", "data:application/pdf;base64,")])
def test_pictures_drawn_as_svg_or_pdf_are_on_the_page(tmp_path, fmt, kind):
    out = tmp_path / "run"
    result = CliRunner().invoke(cli, ["simulate", "--n-bases", "600", "--until-time", "60", "--quiet", "--format", fmt,
                                      "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert CliRunner().invoke(cli, ["report", str(out)]).exit_code == 0
    page = (out / "report.html").read_text()
    assert kind in page and f"pattern.{fmt}" in page


def test_a_sweep_gets_a_page_with_its_runs(tmp_path):
    out = tmp_path / "sweep"
    result = CliRunner().invoke(cli, ["sweep", "--grid", "mechanics.f_max=0.004,0.005", "--set", "lattice.n_bases=300",
                                      "--set", "run.until_time=20", "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    before = {p.name for p in out.iterdir()}
    assert CliRunner().invoke(cli, ["report", str(out)]).exit_code == 0
    page = (out / "report.html").read_text()
    assert "bark sweep" in page and "2 runs" in page and "mechanics.f_max" in page
    assert {p.name for p in out.iterdir()} == before | {"report.html"}  # no sweep.sqlite-wal or -shm left
    assert 'id="sweep-maps"' in page and page.count("plotly.js v") == 1  # its statistics plotted, plotly once


def test_a_sweep_s_page_maps_its_two_settings_and_a_list_of_points_loads_no_plotly(tmp_path):
    out = tmp_path / "grid"
    assert CliRunner().invoke(cli, ["sweep", "--grid", "mechanics.f_max=0.004,0.005", "--grid", "growth.G=0.01,0.02",
                                    "--seeds", "2", "--set", "lattice.n_bases=300", "--set", "run.until_time=20",
                                    "--out", str(out), "--quiet"]).exit_code == 0
    assert CliRunner().invoke(cli, ["report", str(out)]).exit_code == 0
    page = (out / "report.html").read_text()
    assert 'id="sweep-maps"' in page and page.count('"texttemplate":"%{z:.3g}"') == 4  # one map a statistic
    points = tmp_path / "points.csv"
    points.write_text("growth.G,mechanics.f_max\n0.01,0.004\n0.02,0.005\n")
    listed = tmp_path / "listed"
    assert CliRunner().invoke(cli, ["sweep", "--points", str(points), "--set", "lattice.n_bases=300", "--set",
                                    "run.until_time=20", "--out", str(listed), "--quiet"]).exit_code == 0
    assert CliRunner().invoke(cli, ["report", str(listed)]).exit_code == 0
    small = (listed / "report.html").read_text()
    assert 'id="sweep-maps"' not in small and "plotly.js v" not in small and len(small) < 100_000


@pytest.mark.slow
@pytest.mark.skipif(BROWSER is None, reason="no headless browser installed (Debian: apt-get install chromium)")
def test_headless_chromium_loads_the_page_without_errors_and_shows_the_trunk(reported, tmp_path):
    from PIL import Image

    from bark.analysis.pattern import PALETTE

    url = (reported / "report.html").as_uri()
    dom = subprocess.run([BROWSER, *FLAGS, f"--user-data-dir={tmp_path / 'a'}", "--dump-dom", url],
                         capture_output=True, text=True, timeout=180)
    assert dom.returncode == 0, dom.stderr[-2000:]
    assert 'data-loaded="yes"' in dom.stdout and 'data-errors="[]"' in dom.stdout, dom.stdout[:300]
    shot = tmp_path / "shot.png"
    done = subprocess.run([BROWSER, *FLAGS, f"--user-data-dir={tmp_path / 'b'}", "--window-size=1200,2200",
                           f"--screenshot={shot}", url], capture_output=True, text=True, timeout=180)
    assert done.returncode == 0 and shot.is_file(), done.stderr[-2000:]
    with Image.open(shot) as image:
        pixels = np.asarray(image.convert("RGB"), dtype=int).reshape(-1, 3)
    near = np.abs(pixels[:, None, :] - PALETTE[None, :, :].astype(int)).max(axis=2) <= 12
    assert near.any(axis=1).sum() > 2000  # the trunk's leaf bases, drawn in the patches' colours by WebGL


@pytest.mark.parametrize("y,gaps_after", [
    ([170.0, 175.0, 5.0, 10.0], [1]),            # wraps past 180: a gap, no line across the plot
    ([80.0, 95.0, 100.0], []),                   # no wrap
    ([5.0, 178.0, 2.0, None, 179.0], [0, 1]),    # each wrap, either way; a missing value stays one
])
def test_the_orientation_series_breaks_where_it_wraps_as_axial_data_does(y, gaps_after):
    from bark_cli.report import axial_gaps

    x = list(range(len(y)))
    xs, ys = axial_gaps(x, y)
    assert [v for v in ys if v is not None] == [v for v in y if v is not None]  # every point kept, in order
    real = [k for k, v in enumerate(xs) if v is not None]
    gaps = [xs[k - 1] for k in range(1, len(xs)) if xs[k] is None]
    assert gaps == gaps_after and len(real) == len(x)
    for k in range(1, len(ys)):  # no segment drawn between two points more than 90° apart
        if ys[k] is not None and ys[k - 1] is not None:
            assert abs(ys[k] - ys[k - 1]) <= 90.0
