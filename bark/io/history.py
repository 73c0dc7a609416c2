"""A run's history for the tools users open (``history`` effect): a ParaView time series and a netCDF
file for xarray.

Every ``frame_every`` of simulated time (and at the start and the end) the :class:`History` recorder
keeps the bases' positions, their patches, which springs are intact and the pattern's statistics.
At the end it writes:

* ``history/tree-NNNN.vtu``, one mesh a frame — each leaf base its rhomboid, as ``tree.vtu`` draws it
  (``bark.io.mesh``), in metres, with cell data ``patch`` and ``base`` and the RGB point data
  ``colour`` — and ``tree.pvd``, the ParaView collection that puts them on the run's time axis
  (simulated time units; open ``tree.pvd`` in ParaView, or ``pyvista.read``);
* ``history.nc``, a netCDF (classic, 64-bit offset) file following the CF conventions (1.10) that
  ``xarray.open_dataset`` reads, with dimensions ``time`` (a frame each; its coordinate the simulated
  time in days since an epoch, 2000-01-01, that stands for the run's start: xarray decodes it as
  dates), ``base``, ``spring`` and
  ``xyz``: the coordinates ``t`` (model time units of 88.5 days) and ``years`` per frame, ``x``
  (metres; NaN for a base not yet on the trunk), ``patch`` (−1 for none), ``intact`` (1 intact, 0
  broken, −1 not yet made), ``spring_ends``, ``born``, and per frame ``n_bases``, ``n_springs``,
  ``n_broken``, ``n_patches``, ``largest_patch_share`` and the statistics of summary.json
  (``mean_orientation_deg`` ...).

Written with scipy's netCDF writer and meshio: xarray is needed only to read it.
"""

from __future__ import annotations

import io
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from bark.contract.strategies import pattern_of
from bark.io.files import atomic_write
from bark.io.recorders import Recorder
from bark.units import DAYS_PER_TIME_UNIT, DAYS_PER_YEAR, METRES_PER_LENGTH_UNIT, years
from bark.version import __version__

__all__ = ["History", "HISTORY_FILES", "FRAMES_FOLDER"]

EPOCH = "2000-01-01 00:00:00"
"""history.nc's time is in days since this date, which stands for the start of the run: a CF time
coordinate names an epoch, and xarray then decodes it; ``t`` and ``years`` give the model's own time."""

TIME_COORDINATES = ("t", "years")
"""history.nc's coordinates beside ``time`` (days): the model's own time units and years."""

FRAMES_FOLDER = "history"
"""The folder of the run's folder that holds the frames' meshes."""
HISTORY_FILES = ("history.nc", "tree.pvd")
STATISTICS = ("mean_orientation_deg", "circular_sd_deg", "mean_anisotropy", "fraction_within_45_deg")
"""The pattern statistics each frame keeps (summary.json's names)."""


class History(Recorder):
    """The recorder of the ``history`` effect (an action on ``Every(frame_every)``, carried through
    checkpoints like the others): per call the time, positions (float32), patch labels, the intact
    flags (packed bits) and the pattern statistics; ``write`` makes the files (module docstring)."""

    name = "history"
    file = "history.nc"
    from_start = True

    def __init__(self) -> None:
        self.frames: list[dict[str, Any]] = []
        self._sim = None
        self._min_size = 7

    def record(self, sim) -> None:
        """Keep the time, positions, patch labels, intact flags and pattern statistics now (once per time)."""
        t = sim.state.t
        if self.frames and self.frames[-1]["t"] == t:
            return
        s = sim.state
        labels = sim.patch_labels().astype(np.int32)
        measured = pattern_of(sim.analyze().values())
        stats = measured.summary if measured is not None else {}
        self.frames.append({"t": t, "x": s.x.astype(np.float32), "labels": labels, "intact": np.packbits(s.intact),
                            "n_springs": s.n_springs, "n_broken": sim.n_broken,
                            "stats": np.array([np.nan if stats.get(k) is None else stats[k] for k in STATISTICS], float)})

    def arrays(self) -> dict[str, np.ndarray]:
        """The frames packed as arrays (positions and labels concatenated, intact flags as bits), for a
        checkpoint."""
        f = self.frames
        if not f:
            return {"t": np.empty(0), "count": np.empty(0, np.int64), "springs": np.empty(0, np.int64),
                    "broken": np.empty(0, np.int64), "x": np.empty((0, 3), np.float32), "labels": np.empty(0, np.int32),
                    "intact": np.empty(0, np.uint8), "stats": np.empty((0, len(STATISTICS)))}
        return {"t": np.array([r["t"] for r in f]), "count": np.array([len(r["x"]) for r in f], np.int64),
                "springs": np.array([r["n_springs"] for r in f], np.int64),
                "broken": np.array([r["n_broken"] for r in f], np.int64),
                "x": np.concatenate([r["x"] for r in f]), "labels": np.concatenate([r["labels"] for r in f]),
                "intact": np.concatenate([r["intact"] for r in f]), "stats": np.stack([r["stats"] for r in f])}

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        """Unpack the frames of a checkpoint's ``arrays``."""
        ends = np.cumsum(arrays["count"])
        packed = -(-arrays["springs"] // 8)
        bit_ends = np.cumsum(packed)
        self.frames = [{"t": float(t), "x": arrays["x"][e - n:e], "labels": arrays["labels"][e - n:e],
                        "intact": arrays["intact"][b - p:b], "n_springs": int(m), "n_broken": int(k), "stats": st}
                       for t, n, e, m, k, p, b, st in zip(arrays["t"], arrays["count"], ends, arrays["springs"],
                                                          arrays["broken"], packed, bit_ends, arrays["stats"])]

    def finish(self, sim, min_size: int) -> None:
        """Keep the simulation and the least patch size for :meth:`write`."""
        self._sim, self._min_size = sim, min_size

    def write(self, path: str | Path) -> Path:
        """``history.nc`` at ``path``, then the frames' meshes and ``tree.pvd`` beside it."""
        folder = Path(path).parent
        self._write_netcdf(Path(path))
        self._write_series(folder)
        return Path(path)

    # -- the files ------------------------------------------------------------------------------

    def _write_series(self, folder: Path) -> None:
        import meshio

        from bark.analysis.pattern import patch_colours
        from bark.io.mesh import leaf_quads

        frames_dir = folder / FRAMES_FOLDER
        frames_dir.mkdir(exist_ok=True)
        collection = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
        sets = ET.SubElement(collection, "Collection")
        keep = set()
        for k, frame in enumerate(self.frames):
            x = frame["x"].astype(float)
            n = len(x)
            quads = leaf_quads(self._sim, frame["t"], x) * METRES_PER_LENGTH_UNIT
            colours = np.repeat(patch_colours(frame["labels"], self._min_size), 4, axis=0)
            mesh = meshio.Mesh(quads.reshape(-1, 3), [("quad", np.arange(4 * n, dtype=np.int32).reshape(n, 4))],
                               point_data={"colour": colours},
                               cell_data={"patch": [frame["labels"]], "base": [np.arange(n, dtype=np.int32)]})
            name = f"tree-{k:04d}.vtu"
            atomic_write(frames_dir / name, lambda tmp, m=mesh: meshio.write(tmp, m, file_format="vtu", compression=None),
                         by_name=True)
            keep.add(name)
            ET.SubElement(sets, "DataSet", timestep=repr(float(frame["t"])), group="", part="0",
                          file=f"{FRAMES_FOLDER}/{name}")
        for stale in frames_dir.glob("tree-*.vtu"):  # an earlier, longer history's frames
            if stale.name not in keep:
                stale.unlink()
        text = ET.tostring(collection, encoding="unicode")
        atomic_write(folder / "tree.pvd", lambda fh: fh.write(b'<?xml version="1.0"?>\n' + text.encode() + b"\n"))

    def _write_netcdf(self, path: Path) -> None:
        from scipy.io import netcdf_file

        frames = self.frames
        sim = self._sim
        n_frames, n_bases, n_springs = len(frames), sim.state.n_bases, sim.state.n_springs
        x = np.full((n_frames, n_bases, 3), np.nan, np.float32)
        patch = np.full((n_frames, n_bases), -1, np.int32)
        intact = np.full((n_frames, n_springs), -1, np.int8)
        for k, f in enumerate(frames):
            n, m = len(f["x"]), f["n_springs"]
            x[k, :n] = f["x"] * np.float32(METRES_PER_LENGTH_UNIT)
            patch[k, :n] = f["labels"]
            intact[k, :m] = np.unpackbits(f["intact"], count=m).astype(np.int8)
        t = np.array([f["t"] for f in frames], float)

        buffer = io.BytesIO()  # scipy's writer closes what it writes to: a buffer, then the file atomically
        nc = netcdf_file(buffer, "w", version=2)
        nc.Conventions = "CF-1.10"
        nc.title = "bark: a run's history (frames of its state)"
        nc.source = f"bark {__version__}"
        nc.history = f"frames recorded by bark {__version__}'s history effect along the run"
        nc.comment = ("orientation: degrees from horizontal in [0, 180), 90 = along the trunk axis; "
                      "anisotropy = 2A - 1; positions in metres; t in model time units of 88.5 days, time in days")
        for dim, size in (("time", n_frames), ("base", n_bases), ("spring", n_springs), ("xyz", 3), ("end", 2)):
            nc.createDimension(dim, size)

        def var(name, data, dims, units, long_name, **attrs):
            v = nc.createVariable(name, data.dtype, dims)
            v[...] = data
            v.units, v.long_name = units, long_name  # UDUNITS units, "1" for a count or a pure number
            for key, value in attrs.items():
                setattr(v, key, value)
            if dims[0] == "time" and name not in ("time", *TIME_COORDINATES):
                v.coordinates = " ".join(TIME_COORDINATES)  # each frame's time in model units and years: coordinates

        # time in days since an epoch that stands for the run's start (a CF time coordinate needs one; the
        # model has no calendar date); t, the model's own time (a unit of 88.5 days), and years beside it
        var("time", t * DAYS_PER_TIME_UNIT, ("time",), f"days since {EPOCH}",
            f"simulated time; its epoch, {EPOCH[:10]}, stands for the start of the run", standard_name="time", axis="T",
            calendar="proleptic_gregorian")
        var("t", t, ("time",), f"{DAYS_PER_TIME_UNIT:g} days", "simulated time in model time units")
        var("years", np.asarray(years(t), float), ("time",), f"{DAYS_PER_YEAR:g} days", "simulated time in years")
        var("x", x, ("time", "base", "xyz"), "m", "position of each leaf base (NaN: not yet on the trunk)")
        var("patch", patch, ("time", "base"), "1", "patch of each base, numbered by its smallest base (-1: none)")
        var("intact", intact, ("time", "spring"), "1", "state of each spring", flag_values=np.array([-1, 0, 1], np.int8),
            flag_meanings="not_yet_made broken intact")
        var("spring_ends", sim.state.pairs.astype(np.int32), ("spring", "end"), "1", "the bases each spring joins")
        var("born", sim.state.born.astype(float), ("base",), f"{DAYS_PER_TIME_UNIT:g} days",
            "when each base joined, in model time units")
        var("n_bases", np.array([len(f["x"]) for f in frames], np.int32), ("time",), "1", "bases on the trunk")
        var("n_springs", np.array([f["n_springs"] for f in frames], np.int32), ("time",), "1", "springs made")
        var("n_broken", np.array([f["n_broken"] for f in frames], np.int32), ("time",), "1", "springs broken")
        counts = [np.bincount(f["labels"]) for f in frames]
        var("n_patches", np.array([int((c >= self._min_size).sum()) for c in counts], np.int32), ("time",), "1",
            f"patches of at least {self._min_size} bases")
        var("largest_patch_share", np.array([c.max() / c.sum() for c in counts], float), ("time",), "1",
            "share of the bases the largest patch holds")
        stats = np.stack([f["stats"] for f in frames]) if frames else np.empty((0, len(STATISTICS)))
        for j, key in enumerate(STATISTICS):  # angles in degrees; anisotropy and the fraction are pure numbers
            var(key, stats[:, j], ("time",), "degrees" if key in ("mean_orientation_deg", "circular_sd_deg") else "1",
                f"{key} of the patches, as in summary.json")
        nc.flush()
        data = buffer.getvalue()

        atomic_write(path, lambda fh: fh.write(data))
