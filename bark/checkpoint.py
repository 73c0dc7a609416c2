"""Checkpoints: a run written down so that it can go on later, bit for bit as if never stopped.

A checkpoint is one ``checkpoint.npz`` (numpy arrays; ``np.load(..., allow_pickle=False)`` reads it)
holding:

* the state: positions ``x``, velocities ``v``, ``anchor``, the ``intact`` mask, thresholds ``fmax``
  and the spring ends ``pairs`` (a check that the scene rebuilds the same lattice);
* the break log so far (``breaks_*`` columns);
* ``meta``, a JSON text: checkpoint format, bark's version, the whole scene (every setting, as in
  summary.json), the stop conditions, the clock (t, step count, tick count), adaptive stepping's
  current level, the random generator's state, the events so far, and why it was written
  (``periodic``, ``interrupted`` or ``end``).

The leaf-base graph is not stored: it is rebuilt from the scene (same seed, same lattice) and the
intact mask.  Writing is atomic (temporary file, then ``os.replace``), so a crash while writing leaves
the previous checkpoint whole.  A resumed run rewrites the run's outputs (patches.csv, breaks.csv,
summary.json, state.npz, pattern.png) at its end; the break log in them is the whole run's.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import attrs
import numpy as np

from bark.errors import BarkError
from bark.output import write_npz

__all__ = ["FORMAT", "save", "load", "CHECKPOINT_NAME"]

FORMAT = 1
CHECKPOINT_NAME = "checkpoint.npz"


def save(path: str | Path, sim, scene, stop, reason: str, extra: dict[str, Any] | None = None) -> Path:
    """Write ``sim``'s checkpoint to ``path`` atomically."""
    from bark import __version__

    arrays, meta = sim.snapshot()
    meta = {
        "format": FORMAT, "bark_version": __version__, "reason": reason, "scene": scene.to_dict(),
        "stop": attrs.asdict(stop), **meta, **(extra or {}),
    }
    return write_npz(path, meta=np.array(json.dumps(meta)), **arrays)


def load(path: str | Path):
    """``(scene, simulation, stop, meta)`` restored from a checkpoint; one-line BarkError if unreadable."""
    from bark.scene import Scene
    from bark.simulation import Stop

    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise BarkError(f"no checkpoint at {str(path)!r}") from None
    except (OSError, ValueError) as err:
        raise BarkError(f"checkpoint {str(path)!r} cannot be read: {err}") from None
    try:
        meta = json.loads(str(arrays.pop("meta")))
    except (KeyError, ValueError):
        raise BarkError(f"checkpoint {str(path)!r} has no readable meta record") from None
    if meta.get("format") != FORMAT:
        raise BarkError(f"checkpoint {str(path)!r} has format {meta.get('format')!r}; this bark reads format {FORMAT}")
    scene = Scene.from_dict(meta["scene"])
    sim = scene.simulation()
    sim.restore(arrays, meta)
    return scene, sim, Stop(**meta["stop"]), meta
