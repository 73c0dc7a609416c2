"""The documentation site builds, warnings as errors, its gallery executed: the user guide (docs/*.md),
the API reference from the docstrings and the examples, as `sphinx-build -W -b html docs OUT` makes it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from conftest import REPO_ROOT

pytest.importorskip("sphinx")


@pytest.mark.slow  # a whole site: every page, the API and the gallery's runs
def test_the_site_builds_with_no_warning_and_runs_its_gallery(tmp_path):
    source = tmp_path / "docs"  # a copy: sphinx-gallery writes its pages beside the sources
    shutil.copytree(REPO_ROOT / "docs", source, ignore=shutil.ignore_patterns("_build", "auto_examples", "sg_execution_times.rst"))
    out = tmp_path / "html"
    build = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(source), str(out)],
                           capture_output=True, text=True, env={**os.environ, "MPLBACKEND": "Agg"})
    assert build.returncode == 0, build.stderr[-3000:]
    for page in ("index", "running", "numerics", "patterns", "studies", "model", "departures", "plugins", "api"):
        assert (out / f"{page}.html").is_file(), page
    api = (out / "api.html").read_text()
    assert "bark.run" in api and "draw_pattern" in api and "draw_quartet" in api and "Declared" in api  # docstrings
    for example in ("plot_regimes", "plot_small_tree", "plot_quartets", "plot_montage", "plot_resin_law"):  # executed
        html = (out / "auto_examples" / f"{example}.html").read_text()
        assert "sphx_glr_" in html and list((out / "_images").glob(f"sphx_glr_{example}_*.png")), example
