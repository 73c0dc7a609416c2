"""Leaf-base shapes and the 3-D mesh (``mesh`` effect): rhomboids that partition the trunk, written
with meshio and read back."""

from __future__ import annotations

import math

import meshio
import numpy as np
import pytest

from bark.studies import runner
from bark.model.lattice import Lattice
from bark.io.mesh import leaf_quads
from bark.analysis.pattern import FRAGMENT_GREY, patch_colours, simulation_colours
from bark.engine.scene import Scene
from bark.model.tree import leaf_corners


def shoelace(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(x @ np.roll(y, -1) - y @ np.roll(x, -1))


@pytest.mark.parametrize("lattice", [Lattice(n_bases=70000, rise=0.00012, offsets=(55, 89)),  # Table 1
                                     Lattice(),  # Table 2: 21, 34 give 13, 55
                                     Lattice(n_bases=5000, rise=0.0003, offsets=(34, 55), partition=(21, 89))])
@pytest.mark.parametrize("radius", [0.2, 0.35, 0.97])
def test_each_rhomboid_has_one_bases_area_and_neighbours_share_corners(lattice, radius):
    """Counter-clockwise, of area 2πRh, and the corner towards base i + p is the corner of base i + p
    towards base i: on the exact lattice the rhomboids partition the cylinder."""
    corners = leaf_corners(lattice, np.full(3, radius))
    assert [shoelace(c) for c in corners] == pytest.approx([2 * math.pi * radius * lattice.rise] * 3, rel=1e-12)
    phi = math.radians(lattice.divergence_deg)
    for o in lattice.partition_offsets():
        step = np.array([radius * math.remainder(o * phi, 2 * math.pi), o * lattice.rise])  # centre of base i + o
        towards = corners[0][np.argmin(np.linalg.norm(corners[0] - step / 2, axis=1))]
        back = corners[0][np.argmin(np.linalg.norm(corners[0] + step / 2, axis=1))]
        assert towards == pytest.approx(step / 2, abs=1e-15) and step + back == pytest.approx(towards, abs=1e-15)


def test_the_partition_follows_from_the_springs_or_is_given():
    assert Lattice(offsets=(55, 89)).partition_offsets() == (34, 144)
    assert Lattice(offsets=(21, 34)).partition_offsets() == (13, 55)
    assert Lattice(offsets=(55, 89), partition=[21, 144]).partition_offsets() == (21, 144)


@pytest.mark.parametrize("bad", [[34], [34, 34], [0, 5], [1, 2, 3], "x", [1.5, 2]])
def test_a_bad_partition_is_refused_in_one_line(bad):
    from bark.errors import BarkError

    with pytest.raises(BarkError) as err:
        Lattice(partition=bad)
    assert "partition" in str(err.value) and "\n" not in str(err.value)


def test_patch_colours_grey_fragments_and_one_colour_per_patch():
    labels = np.array([0, 0, 0, 1, 2, 2, 2, 0, 1])
    rgb = patch_colours(labels, min_size=3)
    assert tuple(rgb[3]) == tuple(FRAGMENT_GREY) and tuple(rgb[8]) == tuple(FRAGMENT_GREY)
    assert (rgb[0] == rgb[7]).all() and not (rgb[0] == rgb[4]).all() and tuple(rgb[4]) != tuple(FRAGMENT_GREY)


@pytest.fixture(scope="module")
def meshed(tmp_path_factory):
    out = tmp_path_factory.mktemp("mesh")
    scene = Scene.from_dict({
        "lattice": {"n_bases": 1200, "n_start": 900, "join_rate": 30.0, "offsets": [21, 34]},
        "growth": {"name": "bulge", "base": {"name": "sqrt", "G": 0.05},
                   "bulges": [{"z": 0.25, "half_width": 0.15, "magnitude": 0.03, "decay": 0.02}]},
        "run": {"until_time": 8.0, "until_patches": None},
        "effects": {"want": ["mesh", "state-snapshot"]},
    })
    outcome = runner.run(scene, out)
    return outcome, out


def test_the_mesh_is_read_back_by_meshio_with_a_quad_per_base(meshed):
    outcome, out = meshed
    sim = outcome.sim
    n = sim.state.n_bases
    assert n == 900 + 8 * 30  # bases joined during the run are in the mesh
    labels = sim.patch_labels()
    for name in ("tree.vtu", "tree.ply"):
        mesh = meshio.read(out / name)
        assert mesh.points == pytest.approx(0.3 * leaf_quads(sim).reshape(-1, 3), rel=1e-12)  # metres
        assert [(c.type, c.data.shape) for c in mesh.cells] == [("quad", (n, 4))]
        colours = mesh.point_data["colour"] if name == "tree.vtu" else \
            np.column_stack([mesh.point_data[c] for c in ("red", "green", "blue")])
        assert colours.shape == (4 * n, 3) and colours.dtype == np.uint8
        assert (colours[::4] == simulation_colours(sim, 7)).all()
    assert (meshio.read(out / "tree.ply").point_data["patch"] == np.repeat(labels, 4)).all()  # each vertex its face's
    vtu = meshio.read(out / "tree.vtu")
    assert (vtu.cell_data["patch"][0] == labels).all()
    assert (vtu.cell_data["base"][0] == np.arange(n)).all()
    assert vtu.cell_data["born"][0] == pytest.approx(sim.state.born)
    assert not list(out.glob("*.tmp")) and not list(out.glob(".*"))


def test_mesh_corners_lie_on_the_trunk_and_surround_their_base(meshed):
    sim = meshed[0].sim
    quads = leaf_quads(sim)
    r = np.hypot(quads[..., 0], quads[..., 1])
    assert r == pytest.approx(np.broadcast_to(sim.growth.radius(sim.state.t, quads[..., 2].ravel()), r.size).reshape(r.shape),
                              rel=1e-12)
    assert quads.mean(axis=1) == pytest.approx(sim.state.x, abs=2e-3)  # corners come in opposite pairs
    from bark.model.tree import join_radii

    corners = leaf_corners(sim.lattice, join_radii(sim))  # the shape fixed at joining, carried: same diagonals
    for a, b in ((0, 2), (1, 3)):
        assert np.linalg.norm(quads[:, a] - quads[:, b], axis=1) == pytest.approx(
            np.linalg.norm(corners[:, a] - corners[:, b], axis=1), rel=2e-3)


@pytest.mark.parametrize("growth", [
    {"name": "bulge", "base": {"name": "sqrt", "G": 0.05}, "bulges": [{"z": 0.25, "half_width": 0.15, "magnitude": 0.03,
                                                                     "decay": 0.02, "G": 0.01}]},
    {"name": "sqrt", "G": 0.05}])
def test_join_radii_are_the_growth_laws_radius_at_each_bases_birth_to_the_bit(meshed, growth):
    """With the bulge law's weights (all sites at once) and without (a call per join group)."""
    from types import SimpleNamespace

    from bark.contract import registry
    from bark.model.tree import join_radii

    sim = SimpleNamespace(state=meshed[0].sim.state, growth=registry.create("growth", **growth))
    s = sim.state
    assert len(np.unique(s.born)) > 2 and (sim.growth.part_.weights is not None) == (growth["name"] == "bulge")
    expected = np.concatenate([np.broadcast_to(sim.growth.radius(float(t), s.anchor[i:i + 1, 2]), 1)
                               for i, t in enumerate(s.born)])
    assert np.array_equal(join_radii(sim), expected)
