"""The shipped whole-tree scenes: Table 1 values, bases joining at the top, bulges, the 3-D mesh,
and a run interrupted and resumed ending bit for bit where the uninterrupted one ends."""

from __future__ import annotations

import json
import math
import tomllib

import attrs
import meshio
import numpy as np
import pytest
from click.testing import CliRunner

from bark.studies import runner
from bark.engine.scene import Scene
from bark.model.tree import Packing
from bark.units import metres, years
from bark_cli.main import cli
from conftest import REPO_ROOT

SCENES = REPO_ROOT / "bark" / "scenes"


def test_the_whole_tree_scene_has_table_1s_values_and_the_papers_calibration():
    scene = Scene.from_toml(SCENES / "whole-tree.toml")
    lat, mech, growth = scene.lattice, scene.mechanics, scene.simulation().growth
    assert (lat.rise, lat.offsets, lat.partition_offsets()) == (0.00012, (55, 89), (34, 144))
    assert (mech.k, mech.m, mech.f_max) == (1.0, 1.0, 0.005)
    assert (mech.c, mech.b) == (0.1, 5.0)  # Table 2's, not Table 1's 0.03 and 2 (docs/model.md: The whole tree)
    assert (growth.base.r0, growth.base.G) == (0.35, 0.04)
    static = [b for b in growth.bulges if b.start == 0.0]  # on the trunk of the start: Table 1's bulge values
    assert len(static) == 2 and all(b.G == 0.02 for b in static)
    assert scene.strategies["breaker"].regions == {"bulge": 0.006}  # Table 1's f_max in bulges
    t_end = scene.run.until_time
    made = [b for b in growth.bulges if b.start > 0.0]  # and one below the apical dome every 10 years, fading
    assert [years(b.start) for b in made] == pytest.approx([5.0, 15.0, 25.0, 35.0, 45.0], rel=2e-3)
    for b in made:  # its lower edge at the top of the trunk when it appears; a G between its two
        assert b.z - b.half_width == pytest.approx(float(lat.top(b.start)), abs=1e-12)
        assert 0.02 <= b.G < 0.04 and 100 * metres(b.magnitude) == pytest.approx(3.0)
        at_end = growth.radius(t_end, np.array([b.z]))[0] - growth.base.radius(t_end, 0.0)
        assert -0.02 < at_end < b.magnitude  # faded, and no deep constriction
    assert years(t_end) == pytest.approx(60.0, rel=2e-3)
    # Ridley's packing: 25,000 leaves on a trunk without bulges (the paper's 70,000), 780 more in the
    # bulges made on the way (wider, they hold more to their height); every one has joined at the end
    plain = Packing.of(attrs.evolve(lat, n_bases=80000), growth.without("bulges"))
    assert plain.bases_at(t_end) == pytest.approx(70000, abs=5)
    assert Packing.of(lat, growth).bases_at(t_end) == lat.n_bases == 70780 == \
        Packing.of(attrs.evolve(lat, n_bases=80000), growth).bases_at(t_end)
    assert metres(lat.initial * lat.rise) == pytest.approx(1.62) and metres(float(lat.top(t_end))) == pytest.approx(2.52, abs=0.005)
    assert 100 * metres(growth.base.radius(0.0, 0.0)) == pytest.approx(10.5)
    assert 100 * metres(growth.base.radius(t_end, 0.0)) == pytest.approx(29.4, abs=0.1)
    assert (lat.join_rate / years(1.0)) == pytest.approx(412.5, rel=0.02)  # leaves a year (paper's calibration)


def test_the_small_variant_is_the_same_tree_cut_down():
    big = tomllib.loads((SCENES / "whole-tree.toml").read_text())
    small = tomllib.loads((SCENES / "whole-tree-small.toml").read_text())
    for section in ("mechanics", "effects"):
        assert {k: v for k, v in small[section].items() if not k.endswith("_every")} == \
               {k: v for k, v in big[section].items() if not k.endswith("_every")}
    same = ("rise", "offsets", "partition", "join_rate", "join_every", "jitter")
    assert {k: small["lattice"][k] for k in same} == {k: big["lattice"][k] for k in same}
    assert small["growth"]["base"] == big["growth"]["base"]


@pytest.mark.slow  # a small whole tree: seconds: the quick subset (-m "not slow") leaves it out
def test_the_small_whole_tree_runs_through_the_command_line(tmp_path):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["simulate", "--scene", str(SCENES / "whole-tree-small.toml"), "--quiet",
                                      "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_bases"] == 11995 and summary["stop_reason"] == "time"
    # the mean radius: Table 1's law, a little more where the bulge still stands out (0.1 - 0.01 sqrt(t))
    assert 0.35 + 0.04 * math.sqrt(74.25) < summary["radius"] < 0.35 + 0.04 * math.sqrt(74.25) + 0.0138
    assert summary["n_broken"] > 0 and summary["n_patches"] > 10  # the bark has come apart in patches
    mesh = meshio.read(out / "tree.vtu")  # each base a quad; and the leaves' (leaf = 1)
    bases = mesh.cell_data["leaf"][0] == 0
    assert bases.sum() == 11995 and mesh.cells[0].data[bases].max() == 4 * 11995 - 1
    assert (mesh.cell_data["patch"][0][~bases] == -1).all() and (~bases).sum() % (4 * 8) == 0
    assert {"tree-series.png", "tree.png", "regions.png"} <= {p.name for p in out.iterdir()}
    assert {"statistics.csv", "pattern.png", "tree.ply", "checkpoint.npz"} <= {p.name for p in out.iterdir()}
    from PIL import Image

    with Image.open(out / "tree.png") as image:  # the side view, of a bounded size
        assert 300 < image.size[0] <= 1000 and 300 < image.size[1] <= 2000
    regions = summary["regions"]  # the trunk of the start near bulges and away, and the trunk grown since
    assert set(regions) == {"bulge", "straight", "young"}
    assert sum(r["n_bases"] for r in regions.values()) == 11995 and regions["young"]["n_bases"] == 11995 - 4500
    assert sum(r["n_patches"] for r in regions.values()) == summary["n_patches"]
    windows = summary["windows"]  # the same, in photograph-sized windows; and on the trunk of the start
    assert windows["window_m"] == pytest.approx(0.15) and set(windows["initial_trunk"]) == {"bulge", "straight"}
    assert sum(w["n_patches"] for w in windows["regions"].values()) >= summary["n_patches"]
    assert summary["phyllotaxis"]["bases_side_by_side_front"] == pytest.approx(38.0, abs=0.5)


def test_the_window_of_the_statistics_is_a_scene_setting(tmp_path):
    from bark.studies import runner

    scene = Scene.from_toml(SCENES / "whole-tree-small.toml",
                            {"effects": {"want": ["bulges", "anchors", "damping", "patch-statistics"], "window": 1.0},
                             "run": {"until_time": 2.0}})
    summary = runner.run(scene, tmp_path / "out").summary
    assert summary["windows"]["window"] == 1.0 and summary["windows"]["window_m"] == pytest.approx(0.3)


@pytest.mark.slow  # a small whole tree run twice over: ten seconds: the quick subset (-m "not slow") leaves it out
def test_the_small_whole_tree_interrupted_and_resumed_ends_bit_for_bit(tmp_path):
    scene = Scene.from_toml(SCENES / "whole-tree-small.toml")
    whole, part = tmp_path / "whole", tmp_path / "part"
    runner.run(scene, whole)
    seen = []
    out = runner.run(scene, part, checkpoint_every=1e-9, observe=lambda s, stop: seen.append(s.state.t),
                     interrupted=lambda: "interrupted" if seen and seen[-1] >= 27.0 else None)
    assert out.stop_reason == "interrupted" and 4500 < out.sim.state.n_bases < 11995
    resumed = runner.resume(part)
    assert resumed.sim.state.n_bases == 11995
    for name in ("breaks.csv", "state.npz", "patches.csv", "statistics.csv", "tree.vtu", "tree.ply"):
        assert (part / name).read_bytes() == (whole / name).read_bytes(), name


def test_the_regions_picture_shows_each_region_s_patches_and_its_summary_json_figures():
    """regions.png's data: a panel per region of the trunk, in summary.json's figures; a trunk of one
    region gets one panel, ``trunk``."""
    from bark_cli.pictures import RegionsData

    scene = Scene.from_toml(SCENES / "whole-tree-small.toml", {"effects": {"want": ["bulges", "anchors", "damping",
                                                                                    "patch-statistics"]}})
    done = runner.run(scene, None)
    data = RegionsData.of(done.sim, scene.run.min_patch_size)
    regions = done.summary["regions"]
    assert data.names == ("straight", "bulge", "young") and set(data.names) == set(regions)
    for name, deg, summary in zip(data.names, data.orientation, data.summaries):
        assert len(deg) == regions[name]["n_patches"]
        for key in ("mean_orientation_deg", "circular_sd_deg", "mean_anisotropy", "largest_patch_share"):
            assert summary[key] == pytest.approx(regions[name][key], rel=1e-12, nan_ok=True), (name, key)
    plain = runner.run(Scene.from_dict({"run": {"until_time": 60.0}}), None)
    one = RegionsData.of(plain.sim, 7)
    assert one.names == ("trunk",) and len(one.orientation[0]) == plain.summary["n_patches"]
