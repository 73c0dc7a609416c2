"""The trunk as a 3-D mesh: each leaf base a rhomboid, coloured by its patch (``mesh`` effect); with the
``leaves`` effect, the plant's leaves too.

Written with meshio (imported here only, when a scene asks for the mesh), in metres: ``tree.vtu`` for
ParaView and pyvista (cell data ``patch``, ``patch_size``, ``base``, ``born`` in time units; the point
data ``colour``, one RGB array, uint8) and ``tree.ply`` for Blender (vertex colours ``red``, ``green``,
``blue``, and each vertex's ``patch``).  The VTU file is binary and uncompressed: meshio's zlib
compression took many times as long as the writing itself (measured on the whole tree) for a file
about half as large.  Each leaf base is a quad of its own — four corners, not shared with its
neighbours — so bases that have moved apart show the crack between them.

A base's rhomboid is fixed when it joins the trunk (:func:`bark.model.tree.leaf_corners`, at the radius it
joined at) and carried with it: its corners keep their arc length and height offsets from the base's
centre, and lie on the trunk's surface at their own heights.  Patches of fewer than ``min_size``
bases (fragments) are grey; no two neighbouring patches share a colour (``bark.analysis.pattern.patch_colours``,
the colouring of every picture bark draws).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bark.io.files import atomic_write
from bark.units import metres
from bark.analysis.pattern import simulation_colours
from bark.model.tree import join_radii, leaf_corners

__all__ = ["leaf_quads", "write_mesh", "MESH_FILES"]

MESH_FILES = ("tree.vtu", "tree.ply")


def leaf_quads(sim, t: float | None = None, x: np.ndarray | None = None) -> np.ndarray:
    """The corners of every base's rhomboid now, shape ``(n, 4, 3)``, on the trunk's surface — or at
    an earlier time ``t`` of the run, its first ``len(x)`` bases at positions ``x`` then."""
    t, x = (sim.state.t, sim.state.x) if x is None else (t, np.asarray(x, dtype=float))
    n = len(x)
    corners = leaf_corners(sim.lattice, join_radii(sim)[:n], sim.packing.rise_of(np.arange(n)))
    theta = np.arctan2(x[:, 1], x[:, 0])
    r_now = np.hypot(x[:, 0], x[:, 1])
    angle = theta[:, None] + corners[:, :, 0] / r_now[:, None]  # arc length kept on today's trunk
    z = x[:, 2, None] + corners[:, :, 1]
    r = np.broadcast_to(sim.growth.radius(t, z.ravel()), z.size).reshape(z.shape)
    return np.stack([r * np.cos(angle), r * np.sin(angle), z], axis=-1)


def write_mesh(sim, out: str | Path, min_size: int = 7, leaves=None, dome=None) -> list[Path]:
    """Write ``tree.vtu`` and ``tree.ply`` into ``out``; returns their paths.  With ``leaves`` (the
    ``[leaves]`` settings) and the ``dome``, the plant's leaves too (``bark.model.leaves``): each a
    generalized cylinder of diamond cross-section, four quads a segment, coloured by its age, cell data
    ``leaf`` 1 (0 for the leaf bases), ``patch`` −1 and ``base`` the id of its leaf base."""
    import meshio

    quads = leaf_quads(sim)
    n = len(quads)
    labels = sim.patch_labels()
    colours = np.repeat(simulation_colours(sim, min_size), 4, axis=0)
    sizes = np.bincount(labels)[labels]
    cell_data = {"patch": [labels.astype(np.int32)], "patch_size": [sizes.astype(np.int32)],
                 "base": [np.arange(n, dtype=np.int32)], "born": [sim.state.born.astype(float)]}
    points = quads.reshape(-1, 3)
    faces = np.arange(4 * n, dtype=np.int64).reshape(n, 4)
    if leaves is not None:
        from bark.model.leaves import leaf_faces, leaf_rings, plant_leaves
        from bark.model.tree import Apex

        plant = plant_leaves(leaves, Apex(dome=dome, packing=sim.packing), sim.growth, sim.state.t, sim.state.x)
        rings = leaf_rings(plant, leaves.thickness)  # each leaf's rings share their corners among its quads
        per_leaf = 4 * leaves.segments
        faces = np.concatenate([faces, len(points) + leaf_faces(len(plant), leaves.segments)])
        points = np.concatenate([points, rings.reshape(-1, 3)])
        colours = np.concatenate([colours, np.repeat(np.round(255 * plant.colours).astype(np.uint8), rings[0].size // 3, axis=0)])
        m = len(plant) * per_leaf
        cell_data = {"patch": [np.concatenate([cell_data["patch"][0], np.full(m, -1, np.int32)])],
                     "patch_size": [np.concatenate([cell_data["patch_size"][0], np.zeros(m, np.int32)])],
                     "base": [np.concatenate([cell_data["base"][0], np.repeat(plant.ids, per_leaf).astype(np.int32)])],
                     "born": [np.concatenate([cell_data["born"][0], np.full(m, np.nan)])],
                     "leaf": [np.concatenate([np.zeros(n, np.int8), np.ones(m, np.int8)])]}
    cells = [("quad", faces.astype(np.int32))]
    points = metres(points)  # what ParaView, Blender and pyvista take lengths in
    vertex_patch = np.concatenate([np.repeat(labels.astype(np.int32), 4), np.full(len(points) - 4 * n, -1, np.int32)])
    out = Path(out)
    vtu = meshio.Mesh(points, cells, point_data={"colour": colours}, cell_data=cell_data)
    # PLY keeps no cell data: each vertex has its face's patch (every bark quad has its own corners)
    ply = meshio.Mesh(points, cells, point_data={**{name: colours[:, j] for j, name in enumerate(("red", "green", "blue"))},
                                                 "patch": vertex_patch})
    return [atomic_write(out / "tree.vtu", lambda tmp: meshio.write(tmp, vtu, file_format="vtu", compression=None),
                         by_name=True),
            atomic_write(out / "tree.ply", lambda fh: fh.write(_ply_bytes(meshio, ply)))]


def _ply_bytes(meshio, mesh) -> bytes:
    """The binary PLY meshio writes, less the time of writing it puts in its header comment: the same
    trunk gives the same file (two runs compare with ``cmp``, as the other outputs do)."""
    import io
    import re

    buf = io.BytesIO()
    meshio.write(buf, mesh, file_format="ply", binary=True)
    data = buf.getvalue()
    head, mark, body = data.partition(b"end_header\n")
    return re.sub(rb"(comment Created by meshio v[^,\n]*),[^\n]*", rb"\1", head, count=1) + mark + body
