"""bark from a notebook: DataFrames of its tables, one-line reprs, and drawings into an axes of one's own."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from bark.analysis.pattern import Pattern
from bark.engine.scene import Scene
from bark.studies import runner


@pytest.fixture(scope="module")
def done():
    scene = Scene.from_toml("vertical", {"lattice": {"n_bases": 1200}, "run": {"until_patches": 40},
                                         "effects": {"want": ["patch-statistics", "statistics-series", "break-log"]}})
    return runner.run(scene, None)


def test_tables_come_as_data_frames(done):
    sim = done.sim
    stats = Pattern.of_simulation(sim).statistics(7)
    patches = stats.patches.to_pandas()
    assert isinstance(patches, pd.DataFrame) and list(patches.columns) == stats.patches.header
    assert len(patches) == stats.n_patches == done.summary["n_patches"]
    breaks = sim.breaks.to_pandas()
    assert list(breaks.columns) == ["spring", "i", "j", "step", "t_tu", "tension_fu"] and len(breaks) == sim.n_broken
    assert (np.diff(breaks["t_tu"]) >= 0).all()


def test_pattern_statistics_print_in_one_short_line(done):
    stats = Pattern.of_simulation(done.sim).statistics(7)
    text = repr(stats)
    assert "\n" not in text and len(text) < 200 and f"{stats.n_patches} patches" in text and "°" in text


def test_the_notebook_api_is_bark_s_own_and_loaded_when_first_used():
    import subprocess
    import sys

    from bark.engine.scene import Scene
    from bark.studies.runner import resume, run

    from bark import Scene as S, resume as R, run as F  # noqa: N811  (the names a notebook uses)

    assert (S, F, R) == (Scene, run, resume)
    import bark

    assert {"Scene", "run", "resume"} <= set(dir(bark)) and {"Scene", "run", "resume"} <= set(bark.__all__)
    with pytest.raises(AttributeError, match="no attribute 'Scena'"):
        bark.Scena  # noqa: B018
    probe = ("import sys, bark; before = {m for m in ('bark.studies.runner', 'matplotlib') if m in sys.modules}; "
             "bark.run; print(sorted(before), 'bark.studies.runner' in sys.modules, 'matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["[]", "True", "False"], out  # nothing until asked for; never matplotlib


def test_every_drawing_goes_into_an_axes_of_one_s_own(done):
    from bark_cli.draw import PatternData, draw_histogram, draw_pattern, draw_radial
    from bark_cli.plot import new_figure

    stats = Pattern.of_simulation(done.sim).statistics(7)
    fig = new_figure(figsize=(9, 3))
    flat, radial, rose = fig.add_subplot(1, 3, 1), fig.add_subplot(1, 3, 2, projection="polar"), \
        fig.add_subplot(1, 3, 3, projection="polar")
    draw_pattern(flat, PatternData.of(done.sim, 7))
    sizes = draw_radial(radial, stats)
    draw_histogram(rose, stats)
    assert flat.collections and radial.collections and rose.patches  # drawn where they were asked to be
    assert len(fig.axes) == 3  # and nowhere else: no figure of their own
    assert sizes.norm.vmin == stats.patches.size.min() >= 7  # the colour scale of the patches drawn, none under 7


def test_the_statistics_series_comes_as_a_data_frame(done):
    from bark.io.recorders import SERIES_COLUMNS, StatisticsSeries

    series = StatisticsSeries()
    series.record(done.sim)
    frame = series.to_pandas()
    assert list(frame.columns) == ["t_tu", "radius_lu", *SERIES_COLUMNS[2:]] and len(frame) == 1
    assert frame["n_patches"].iloc[0] == done.summary["n_patches"]
