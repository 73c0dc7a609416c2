"""What a run records along the way: recorders on a trigger, carried through checkpoints, written at the end."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import attrs
import numpy as np

from bark.analysis.fracture import COLUMNS, FractureHistory, history
from bark.contract.strategies import pattern_of
from bark.io.files import write_csv
from bark.units import headed, unwrap

__all__ = ["Recorder", "StatisticsSeries", "Frames", "TreeFrames", "Dissipation", "SERIES_COLUMNS"]


SERIES_COLUMNS = ["t", "radius", "step", "n_broken", "n_patches", "mean_orientation_deg", "circular_sd_deg",
                  "mean_anisotropy", "fraction_within_45_deg"]


class Recorder:
    """What a run records along the way: an action for ``Simulation.add_action`` (on a trigger, e.g.
    ``Every(series_every)``) whose ``record(sim)`` keeps a sample; ``arrays``/``load`` carry the samples
    through a checkpoint (under ``name``), so a resumed run's record is whole.  At the run's end
    ``finish`` makes what is made of them, ``write`` puts them in the run's file ``file`` (if any),
    and ``summary`` is what they add to summary.json."""

    name = ""
    file: str | None = None
    from_start = False
    """Whether it also samples the state a run starts from (the runner asks it once, before the first
    step): its trigger's first due time, 0, would otherwise be seen only after that step."""

    def finish(self, sim, min_size: int) -> None:
        """At the end of the run, after its last sample (``min_size``: the smallest patch that counts)."""

    def record(self, sim) -> None:
        """Keep a sample of ``sim`` now (once per time: asked twice at one time, it keeps one)."""
        raise NotImplementedError

    def arrays(self) -> dict[str, np.ndarray]:
        """The samples kept so far as named arrays, for a checkpoint (under :attr:`name`)."""
        raise NotImplementedError

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        """Take back the samples of ``arrays`` (what :meth:`arrays` gave), resuming a run."""
        raise NotImplementedError

    def write(self, path: str | Path) -> Path:
        """Write what the samples make to ``path`` (the run's file :attr:`file`); returns the path."""
        raise NotImplementedError

    def summary(self) -> dict:
        """What this recorder adds to summary.json (by default nothing)."""
        return {}


class StatisticsSeries(Recorder):
    """The patch statistics along a run: the simulation's analyzers run, one row a call."""

    name = "series"
    file = "statistics.csv"

    def __init__(self) -> None:
        self.rows: list[dict[str, Any]] = []

    def record(self, sim) -> None:
        """Keep a row: time, radius, step, springs broken and the pattern statistics now (once per step)."""
        if self.rows and self.rows[-1]["step"] == sim.step_count:
            return
        measured = pattern_of(sim.analyze().values())
        stats = measured.summary if measured is not None else {}
        self.rows.append({"t": sim.state.t, "radius": sim.radius, "step": sim.step_count, "n_broken": sim.n_broken,
                          **{k: stats.get(k) for k in SERIES_COLUMNS[4:]}})

    def arrays(self) -> dict[str, np.ndarray]:
        """The rows as one array per column (NaN where a statistic had no value)."""
        return {c: np.array([np.nan if r[c] is None else r[c] for r in self.rows], dtype=float) for c in SERIES_COLUMNS}

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        """Take back the rows of a checkpoint's ``arrays``."""
        ints = ("step", "n_broken", "n_patches")
        cols = [[int(v) if c in ints and np.isfinite(v) else (None if not np.isfinite(v) else float(v))
                 for v in arrays[c].tolist()] for c in SERIES_COLUMNS]
        self.rows = [dict(zip(SERIES_COLUMNS, vals)) for vals in zip(*cols)]

    def write(self, path: str | Path) -> Path:
        """The rows as a CSV with units in its header (``statistics.csv``)."""
        return write_csv(path, self.rows, SERIES_COLUMNS, headed(SERIES_COLUMNS))

    def to_pandas(self):
        """The series as a ``pandas.DataFrame``, a row a sample, statistics.csv's columns (``t_tu``,
        ``radius_lu``, ...: ``bark.units.headed``)."""
        from bark.units import data_frame

        return data_frame(self.rows, SERIES_COLUMNS, headed(SERIES_COLUMNS))


class _Coloured(Recorder):
    """A recorder of frames whose last item is each base's patch label: it colours the patches of
    its frames once the run is finished, consistently through them (``colour_index``)."""

    frames: list[tuple]
    colours: list[np.ndarray]
    """Per frame, each base's colour (``bark.analysis.pattern.lineage_colours``), once finished."""

    def finish(self, sim, min_size: int) -> None:
        from bark.analysis.pattern import lineage_colours

        self.colours = lineage_colours([f[-1] for f in self.frames], min_size, sim.state.pairs,
                                       sim.state.intact) if self.frames else []

    def colour_index(self, k: int, min_size: int) -> np.ndarray:
        """Frame ``k``'s colours (indices into ``PALETTE`` followed by ``FRAGMENT_GREY``): as
        finished, else (frames never finished) each patch's label's."""
        from bark.analysis.pattern import label_colours

        return self.colours[k] if self.colours else label_colours(self.frames[k][-1], min_size)


class Frames(_Coloured):
    """Frames of the unwrapped pattern along a run, for the development animation: per call, the time,
    the mean radius, each base's unwrapped position (float32) and patch label (int32).  Drawing them
    is the CLI's (``bark_cli.animation``)."""

    name = "frames"

    def __init__(self) -> None:
        self.frames: list[tuple[float, float, np.ndarray, np.ndarray]] = []
        self.colours: list[np.ndarray] = []

    def record(self, sim) -> None:
        """Keep the time, the mean radius, the unwrapped positions and the patch labels now (once per time)."""
        if self.frames and self.frames[-1][0] == sim.state.t:
            return
        r = sim.radius
        self.frames.append((sim.state.t, r, unwrap(sim.state.x, r).astype(np.float32), sim.patch_labels().astype(np.int32)))

    def arrays(self) -> dict[str, np.ndarray]:
        """The frames as arrays, positions and labels concatenated with a count per frame."""
        f = self.frames
        return {
            "t": np.array([x[0] for x in f], dtype=float), "r": np.array([x[1] for x in f], dtype=float),
            "count": np.array([x[2].shape[0] for x in f], dtype=np.int64),
            "uv": np.concatenate([x[2] for x in f]) if f else np.empty((0, 2), np.float32),
            "labels": np.concatenate([x[3] for x in f]) if f else np.empty(0, np.int32),
        }

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        """Take back the frames of a checkpoint's ``arrays``."""
        ends = np.cumsum(arrays["count"])
        starts = ends - arrays["count"]
        self.frames = [(float(t), float(r), arrays["uv"][a:b], arrays["labels"][a:b])
                       for t, r, a, b in zip(arrays["t"], arrays["r"], starts, ends)]


class TreeFrames(_Coloured):
    """The tree at several ages, for the tree-series picture (Fig. 10): per call, the time, each base's
    position (float32) and patch label (int32).  Drawing them is the CLI's (``bark_cli.pictures``)."""

    name = "trees"
    from_start = True  # the tree as the run found it: the first picture of the series

    def __init__(self) -> None:
        self.frames: list[tuple[float, np.ndarray, np.ndarray]] = []
        self.colours: list[np.ndarray] = []

    def record(self, sim) -> None:
        """Keep the time, the positions and the patch labels now (once per time)."""
        if self.frames and self.frames[-1][0] == sim.state.t:
            return
        self.frames.append((sim.state.t, sim.state.x.astype(np.float32), sim.patch_labels().astype(np.int32)))

    def arrays(self) -> dict[str, np.ndarray]:
        """The frames as arrays, positions and labels concatenated with a count per frame."""
        f = self.frames
        return {
            "t": np.array([x[0] for x in f], dtype=float), "count": np.array([x[1].shape[0] for x in f], dtype=np.int64),
            "x": np.concatenate([x[1] for x in f]) if f else np.empty((0, 3), np.float32),
            "labels": np.concatenate([x[2] for x in f]) if f else np.empty(0, np.int32),
        }

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        """Take back the frames of a checkpoint's ``arrays``."""
        ends = np.cumsum(arrays["count"])
        starts = ends - arrays["count"]
        self.frames = [(float(t), arrays["x"][a:b], arrays["labels"][a:b]) for t, a, b in zip(arrays["t"], starts, ends)]


class Dissipation(Recorder):
    """The dissipation along a run (on ``Every(history_every)``): the time and the damping's power per
    base, ``b·Σ|v|² / n``; at the end, the run's fracture history made from them (``finish``)."""

    name = "dissipation"
    file = "fracture.csv"

    def __init__(self) -> None:
        self.t: list[float] = []
        self.power: list[float] = []
        self.result: FractureHistory | None = None
        """The history, once ``analyse`` has made it (at the end of the run)."""

    def record(self, sim) -> None:
        """Keep the time and the damping's power per base now, ``b·Σ|v|² / n`` (once per time)."""
        t = sim.state.t
        if self.t and self.t[-1] == t:
            return
        v = sim.state.v
        self.t.append(t)
        self.power.append(float(sim.mechanics.b * np.einsum("ij,ij->", v, v) / max(sim.state.n_bases, 1)))

    def arrays(self) -> dict[str, np.ndarray]:
        """The times and powers, for a checkpoint."""
        return {"t": np.array(self.t, dtype=float), "power": np.array(self.power, dtype=float)}

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        """Take back the times and powers of a checkpoint's ``arrays``."""
        self.t, self.power = arrays["t"].tolist(), arrays["power"].tolist()

    def finish(self, sim, min_size: int) -> None:
        """Make the run's fracture history (:meth:`analyse`)."""
        self.analyse(sim, min_size)

    def summary(self) -> dict:
        """The fracture history's figures under ``fracture`` (nothing before :meth:`finish`)."""
        return {"fracture": self.result.summary()} if self.result is not None else {}

    def analyse(self, sim, min_size: int) -> FractureHistory:
        """The run's fracture history at the samples recorded (kept as ``result``)."""
        found = history(sim.breaks.arrays(), sim.state.pairs, sim.lattice.offsets, sim.packing.bases_at,
                        np.array(self.t), np.array(self.power), min_size)
        if found.first_break_t is not None:
            found = attrs.evolve(found, growth_dissipation=growth_dissipation(sim, found.first_break_t))
        self.result = found
        return found

    def write(self, path):
        """The history ``analyse`` made, as ``fracture.csv`` at ``path``."""
        return write_csv(path, self.result.rows(), COLUMNS, headed(COLUMNS))


def growth_dissipation(sim, t: float) -> float:
    """``b·(dr/dt)²`` at time ``t``: dr/dt the mean over the bases' sites, by a central difference of
    the growth law (one-sided at t = 0)."""
    z = sim.state.anchor[:, 2]
    h = 1e-4 * max(t, 1.0)
    lo = max(t - h, 0.0)
    rate = (sim.growth.mean_radius(t + h, z) - sim.growth.mean_radius(lo, z)) / (t + h - lo)
    return float(sim.mechanics.b * rate * rate)


