"""The plant's leaves (``leaves`` effect) and the tree at several ages (``tree-series``): geometry, scene
settings, the pictures and the mesh."""

from __future__ import annotations

import json
import math

import meshio
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from bark.errors import BarkError
from bark.engine.scene import Scene
from bark.model.leaves import Leaves, leaf_faces, leaf_rings, leaves_at, plant_leaves
from bark.model.tree import Apex
from conftest import REPO_ROOT

SCENES = REPO_ROOT / "bark" / "scenes"


def _one(age=None, down=None, **kw):
    """One leaf on a base at (0.4, 0, 1), ``age`` after it reached the trunk, or ``down`` the dome."""
    return leaves_at(Leaves(**kw), 0.0, np.array([7]), np.array([[0.4, 0.0, 1.0]]),
                     np.array([0.0 if age is None else age]), np.array([np.nan if down is None else down]))


@settings(max_examples=60, deadline=None)
@given(down=st.one_of(st.none(), st.floats(0.0, 1.0)), age=st.floats(0.0, 8.0), length=st.floats(0.1, 5.0),
       droop=st.floats(0.0, 1.0))
def test_a_leaf_starts_at_its_base_keeps_its_plane_and_only_turns_down(down, age, length, droop):
    leaf = _one(age=age, down=down, length=length, droop=droop)
    axis = leaf.axes[0]
    assert axis[0] == pytest.approx([0.4, 0.0, 1.0])
    assert np.all(axis[:, 1] == 0.0) and np.all(np.diff(axis[:, 0]) >= -1e-15)  # outward, in its plane
    step = np.diff(axis, axis=0)
    elevation = np.arctan2(step[:, 2], step[:, 0])
    assert np.all(np.diff(elevation) <= 1e-12)  # gravity only turns it down
    if down is None or down >= 0.25:  # grown: its length (the youngest, at the dome's tip, are still growing)
        assert np.linalg.norm(step, axis=1).sum() == pytest.approx(length)
    else:
        assert 0.5 * length * (1 - 1e-12) <= np.linalg.norm(step, axis=1).sum() < length * (1 + 1e-12)
    w = leaf.widths[0]
    assert w[-1] == 0.0 and 0.0 < w[0] < w.max() <= Leaves().width  # narrowing to both ends


def test_a_leaf_ages_from_green_to_brown_and_droops_more():
    young, old, dead = _one(age=0.5), _one(age=8.0), _one(age=9.0, kept=1.0)
    greenness = [leaf.colours[0, 1] - leaf.colours[0, 0] for leaf in (young, old, dead)]  # green over red
    assert greenness[0] > 0 > greenness[1] > greenness[2]
    assert young.axes[0, -1, 2] > old.axes[0, -1, 2] > dead.axes[0, -1, 2]  # its tip lower


def test_the_fires_leave_a_share_of_the_dead_leaves_and_none_of_the_old_ones():
    n = 20000
    ids = np.arange(n)
    base = np.column_stack([0.4 * np.cos(ids * 2.4), 0.4 * np.sin(ids * 2.4), np.zeros(n)])
    s = Leaves(lifespan=4.0, kept=0.15)
    for age, share in ((3.0, 1.0), (6.0, 0.15), (9.0, 0.0)):
        got = leaves_at(s, 0.0, ids, base, np.full(n, age), np.full(n, np.nan))
        assert len(got) / n == pytest.approx(share, abs=0.01)
    later = leaves_at(s, 0.0, ids, base, np.full(n, 7.0), np.full(n, np.nan))
    earlier = leaves_at(s, 0.0, ids, base, np.full(n, 5.0), np.full(n, np.nan))
    assert np.array_equal(later.ids, earlier.ids)  # the same leaves kept at every age


def test_the_diamond_cross_section_is_the_leaf_s_width_across_and_its_thickness_in_its_plane():
    leaf = _one(age=1.0, width=0.02)
    rings = leaf_rings(leaf, 0.5)
    assert rings.shape == (1, 9, 4, 3)
    axis, widths = leaf.axes[0], leaf.widths[0]
    for j in range(9):
        d = np.linalg.norm(rings[0, j] - axis[j], axis=1)
        assert d == pytest.approx([widths[j] / 2, widths[j] / 4, widths[j] / 2, widths[j] / 4])
        assert (rings[0, j, 0] - axis[j])[1] == pytest.approx(widths[j] / 2)  # across: around the trunk (y here)


def test_each_face_joins_two_sides_of_the_diamond_on_two_successive_rings():
    faces = leaf_faces(3, 8)
    assert faces.shape == (3 * 8 * 4, 4) and faces.max() == 3 * 9 * 4 - 1
    leaf, rest = np.divmod(faces, 36)
    ring, corner = np.divmod(rest, 4)
    assert (leaf == leaf[:, :1]).all()  # a face within one leaf
    assert (ring[:, 0] == ring[:, 1]).all() and (ring[:, 2] == ring[:, 3]).all() and (ring[:, 2] == ring[:, 0] + 1).all()
    assert ((corner[:, 1] - corner[:, 0]) % 4 == 1).all() and (corner[:, 2] == corner[:, 1]).all() and (corner[:, 3] == corner[:, 0]).all()
    assert len({tuple(sorted(f)) for f in faces.tolist()}) == len(faces)  # none twice


def _small_tree_at_its_start():
    """The small whole tree built, its apex and its plant's leaves at t = 0."""
    scene = Scene.from_toml(SCENES / "whole-tree-small.toml")
    sim = scene.simulation()
    sim.build()
    apex = Apex(dome=scene.dome, packing=sim.packing)
    return scene, sim, apex, plant_leaves(scene.leaves, apex, sim.growth, 0.0, sim.state.x)


def test_the_plant_has_leaves_on_the_dome_and_on_the_young_trunk():
    scene, sim, apex, plant = _small_tree_at_its_start()
    organs, _ = apex.organs(0.0, float(sim.growth.radius(0.0, float(sim.packing.top(0.0)))))
    assert set(organs) <= set(plant.ids)  # every organ on the dome has its leaf
    on_trunk = plant.ids[plant.ids < sim.state.n_bases]
    lifespan_bases = scene.leaves.lifespan * sim.lattice.join_rate
    # alive: the last lifespan's worth of the trunk's bases; then a kept share of the dead; none older
    assert on_trunk.min() >= sim.state.n_bases - 2 * lifespan_bases - 1
    assert np.count_nonzero(on_trunk >= sim.state.n_bases - lifespan_bases) == pytest.approx(lifespan_bases, abs=2)


def test_the_side_view_cuts_away_the_leaves_in_front_of_the_trunk_and_keeps_the_others():
    from bark_cli.pictures import LEAVES_CUT_DEG, TreeData

    scene, sim, _, plant = _small_tree_at_its_start()
    base = plant.axes[:, 0]
    azimuth = np.degrees(np.abs(np.arctan2(base[:, 0], base[:, 1])))  # 0: towards the viewer
    data = TreeData.of(sim, 7, scene.dome, scene.leaves)
    drawn = np.count_nonzero(azimuth >= LEAVES_CUT_DEG)
    assert len(data.leaves) == drawn and 0 < drawn < len(base)  # the cut ones, and only they, are left out
    assert np.count_nonzero(data.leaf_front) == np.count_nonzero((azimuth >= LEAVES_CUT_DEG) & (base[:, 1] > 0))


def test_leaves_ask_for_the_tree_and_their_settings_are_checked_in_one_line():
    scene = Scene.from_toml(SCENES / "whole-tree-small.toml", {"effects": {"want": ["leaves"]}})
    assert scene.has("tree-image") and scene.effects["tree-image"] == "needed by leaves"
    with pytest.raises(BarkError) as err:
        Scene.from_toml(SCENES / "whole-tree-small.toml", {"leaves": {"length": -1.0}})
    assert "length" in str(err.value) and "\n" not in str(err.value)


def test_a_tree_series_without_a_time_needs_its_interval_in_one_line():
    with pytest.raises(BarkError) as err:
        Scene.from_dict({"run": {"until_patches": 10}, "effects": {"want": ["tree-series"]}})
    assert "tree_every" in str(err.value) and "until_time" in str(err.value) and "\n" not in str(err.value)
    scene = Scene.from_dict({"run": {"until_time": 8.0}, "effects": {"want": ["tree-series"]}})
    assert scene.tree_interval == 2.0


@pytest.mark.slow
def test_the_small_tree_with_leaves_a_series_and_a_mesh_resumed_ends_bit_for_bit(tmp_path):
    """tree.png and tree-series.png are drawn (five ages), the mesh carries the leaves, and a run stopped
    halfway and resumed writes the same files as the run that went through."""
    from PIL import Image

    from bark.io import checkpoint
    from bark.studies import runner

    want = ["bulges", "anchors", "damping", "patch-statistics", "leaves", "tree-series", "mesh", "checkpoints"]
    scene = Scene.from_toml(SCENES / "whole-tree-small.toml", {"effects": {"want": want}})
    whole, part = tmp_path / "whole", tmp_path / "part"
    assert runner.run(scene, whole).failed == []
    with Image.open(whole / "tree-series.png") as image:
        assert image.size[0] > 2 * image.size[1]  # five trees side by side
    trees = checkpoint.load(whole)[4]["trees"]
    assert trees["t"].tolist() == pytest.approx([0.0, 18.5625, 37.125, 55.6875, 74.25])
    mesh = meshio.read(whole / "tree.vtu")
    leaf = mesh.cell_data["leaf"][0] == 1
    assert leaf.any() and (mesh.cell_data["patch"][0][leaf] == -1).all()
    assert (~leaf).sum() == json.loads((whole / "summary.json").read_text())["n_bases"]
    seen = []
    stopped = runner.run(scene, part, checkpoint_every=1e-9, observe=lambda s, stop: seen.append(s.state.t),
                         interrupted=lambda: "interrupted" if seen and seen[-1] >= 27.0 else None)
    assert stopped.stop_reason == "interrupted"
    runner.resume(part)
    for name in ("tree.vtu", "tree.ply", "patches.csv"):
        assert (part / name).read_bytes() == (whole / name).read_bytes(), name
    assert np.array_equal(checkpoint.load(part)[4]["trees"]["x"], trees["x"])
