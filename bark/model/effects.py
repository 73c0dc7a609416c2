"""Effects: what a scene asks to be simulated and written — and so, what is built and run at all.

A scene's ``[effects]`` table names the effects it wants (``want = [...]``); the simulation is
composed from exactly those plus what they need, and nothing else is built or run: no image asked,
matplotlib is never imported; only statistics at the end asked, nothing is recorded along the way.
``bark plan SCENE`` prints the resolved set and why each effect is in it.  A scene without a
``want`` list gets ``DEFAULT`` plus the effects its strategies provide: the usual outputs of the
model it configures.

``EFFECTS`` are the model's own.  A strategy may provide more (``Strategy.provides``: a bulge law's
``bulges``); a scene that leaves one out runs the strategy's ``without(name)`` instead, so its code
is never built.
"""

from __future__ import annotations

from typing import Mapping

import attrs

from bark.errors import BarkError

__all__ = ["Effect", "EFFECTS", "DEFAULT", "resolve", "PICTURE_FORMATS", "in_format"]

PICTURE_FORMATS = ("png", "pdf", "svg")
"""The formats a run's still pictures may be written in (``[effects] picture_format``)."""


def in_format(name: str, picture_format: str) -> str:
    """A still picture's file ``name`` (``pattern.png``) in ``picture_format`` (``pattern.pdf``); an
    animation (``.gif``) stays as it is."""
    stem, dot, suffix = name.rpartition(".")
    return f"{stem}.{picture_format}" if dot and suffix == "png" else name


@attrs.frozen
class Effect:
    """One effect a scene may simulate (its ``[effects] want``): what it does, what it needs, and the
    files of a run it writes."""

    name: str
    """How a scene names it (``fracture``, ``pattern-image``)."""
    does: str
    """What it does, in a line (``bark plan`` prints it)."""
    needs: tuple[str, ...] = ()
    """The effects it cannot be simulated without."""
    files: tuple[str, ...] = ()
    """The files of a run's folder it writes (a fresh run removes every effect's, and only those)."""
    drawn: tuple[str, ...] = ()
    """Those of its files that are pictures, drawn by what is installed to draw (``bark.pictures``),
    not by the core."""


EFFECTS: dict[str, Effect] = {
    e.name: e
    for e in [
        Effect("secondary-growth", "the trunk grows in girth ([growth] law; eq. 9)"),
        Effect("anchors", "anchor springs tie each base to its site (eq. 2; without: c = 0)"),
        Effect("damping", "damping of the bases' motion (eq. 3; without: b = 0)"),
        Effect("fracture", "springs over their threshold break ([breaker])", ("secondary-growth",)),
        Effect("patch-statistics", "patches, PCA orientation, anisotropy at the end: patches.csv, summary.json",
               ("fracture",), ("patches.csv",)),
        Effect("statistics-series", "the patch statistics along the way, every series_every: statistics.csv",
               ("patch-statistics",), ("statistics.csv",)),
        Effect("pattern-image", "the unwrapped pattern at the end: pattern.png", ("fracture",), ("pattern.png",),
               ("pattern.png",)),
        Effect("break-log", "every break recorded as it happens: breaks.csv", ("fracture",), ("breaks.csv",)),
        Effect("fracture-history", "broken springs, cracks, patches and the damping's power against time, every "
               "history_every: fracture.csv, fracture.png, summary.json's initial fractures", ("break-log",),
               ("fracture.csv", "fracture.png"), ("fracture.png",)),
        Effect("state-snapshot", "the mechanical state at the end: state.npz", (), ("state.npz",)),
        Effect("checkpoints", "checkpoint.npz: periodic, on Ctrl-C and at the end (for --resume)", (),
               ("checkpoint.npz", "checkpoint.prev.npz")),
        Effect("graphml", "the leaf-base graph of intact springs at the end: graph.graphml", (), ("graph.graphml",)),
        Effect("animation", "frames of the pattern along the way: development.gif", ("fracture",),
               ("development.gif",), ("development.gif",)),
        Effect("tree-image", "the trunk seen from the side at the end, leaf bases coloured by patch: tree.png",
               ("fracture",), ("tree.png",), ("tree.png",)),
        Effect("mesh", "the trunk's leaf bases as a 3-D mesh coloured by patch at the end: tree.vtu (ParaView), "
               "tree.ply (Blender)", ("fracture",), ("tree.vtu", "tree.ply")),
        Effect("history", "the run's history every frame_every: tree.pvd with history/tree-NNNN.vtu (a ParaView "
               "time series) and history.nc (netCDF for xarray: positions, patches, intact springs, statistics)",
               ("fracture",), ("history.nc", "tree.pvd", "history/tree-*.vtu")),
        Effect("region-image", "per region of the trunk (straight, bulge, young), its patches' orientation and "
               "anisotropy (Fig. 6B) and statistics: regions.png", ("patch-statistics",), ("regions.png",),
               ("regions.png",)),
        Effect("leaves", "the plant's leaves, ageing, drooping and burnt ([leaves]; Fig. 10), in tree.png, the "
               "tree series and the mesh", ("tree-image",)),
        Effect("tree-series", "the tree seen from the side at several ages (Fig. 10), every tree_every: "
               "tree-series.png", ("fracture",), ("tree-series.png",), ("tree-series.png",)),
    ]
}

DEFAULT: tuple[str, ...] = (
    "secondary-growth", "anchors", "damping", "fracture", "patch-statistics", "pattern-image", "break-log",
    "state-snapshot", "checkpoints",
)


def resolve(wanted, known: Mapping[str, Effect] = EFFECTS) -> dict[str, str]:
    """Every effect needed for ``wanted``, each with why it is there ("asked for" or "needed by X"),
    in the order of ``known`` (``EFFECTS`` and those a scene's strategies provide).  An unknown name
    is a one-line BarkError."""
    wanted = list(wanted)
    for name in wanted:
        if not isinstance(name, str) or name not in known:
            raise BarkError(f"unknown effect {name!r}; allowed are {', '.join(known)}")
    why: dict[str, str] = {name: "asked for" for name in wanted}
    todo = list(wanted)
    while todo:
        name = todo.pop()
        for need in known[name].needs:
            if need not in why:
                why[need] = f"needed by {name}"
                todo.append(need)
    return {name: why[name] for name in known if name in why}
