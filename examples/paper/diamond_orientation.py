"""The diamond regime's orientation over time: does it turn horizontal, as the paper reports (1.2°)?

    python examples/paper/diamond_orientation.py [--out runs/diamond-orientation] [--until-time 8000]
    python examples/paper/diamond_orientation.py --held-ends [--seeds 3]

Runs Table 2's diamond scene (bark/scenes/diamond.toml, `--scene diamond`) past its stop at 80 patches, with the
patch statistics every 40 time units, and draws the mean orientation of the patches against time
and against their number, beside the orientations of the lattice's two parastichies (the springs
at offsets 21 and 34, from the bases' sites at the radius of the moment).  Prints when the mean
comes within 20° of horizontal, if it does.  Writes diamond-orientation.png and the run's files
into --out.  Nothing is tuned: this is the shipped scene.

``--held-ends`` tries one more reading instead: the segment's ends held in place (the bases of its
first and last turn of the spiral, within one spring of either end, stay at their sites on the
widening trunk), run to the scene's stop at 80 patches for each seed, and prints the mean orientation
and SD of each.  The holding is an integrator of this script's own (a subclass of the Euler-Cromer
integrator that writes its ``step`` again: it runs in Python, one step a call, as any strategy
without a compiled part does).
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import numpy as np

import attrs

from bark.studies import runner
from bark_plugins.integrators import EulerCromer
from bark.analysis.circular import axial_difference
from bark.model.effects import DEFAULT
from bark.engine.scene import Scene, merge, read_toml

HERE = Path(__file__).resolve().parent


def parastichy_orientations(sim, radius: float) -> dict[int, float]:
    """Orientation (degrees from horizontal, [0, 180)) of the line from a base to the base ``k``
    above it, for each spring offset ``k``, on the trunk unrolled at ``radius``."""
    lat = sim.lattice
    out = {}
    for k in lat.offsets:
        turn = math.remainder(k * math.radians(lat.divergence_deg), 2 * math.pi)  # signed, (-π, π]
        out[k] = math.degrees(math.atan2(k * lat.rise, radius * turn)) % 180.0
    return out


@attrs.frozen(kw_only=True)
class HeldEnds(EulerCromer):
    """Euler-Cromer, with the bases within ``reach`` of either end of the segment held at their sites."""

    reach: int = 34
    """Bases held at each end (the largest spring offset: one turn of the spiral)."""

    def step(self, state, dt: float, forces) -> None:
        super().step(state, dt, forces)
        ends = np.r_[0:self.reach, state.n_bases - self.reach:state.n_bases]
        state.x[ends] = state.anchor[ends]  # the surface constraint then puts them on the trunk of the moment
        state.v[ends] = 0.0


def held_ends(seeds: int) -> None:
    """The shipped diamond scene with its ends held, each seed to its stop at 80 patches."""
    base = Scene.from_toml("diamond")
    reach = max(base.lattice.offsets)
    print(f"| reading | means, seeds {' / '.join(map(str, range(seeds)))} | SDs |\n|---|---|---|")
    means, sds = [], []
    for seed in range(seeds):
        scene = attrs.evolve(base, run=attrs.evolve(base.run, seed=seed),
                             strategies={**base.strategies, "integrator": HeldEnds(reach=reach)})
        s = runner.run(scene, None).summary
        means.append(s["mean_orientation_deg"])
        sds.append(s["circular_sd_deg"])
    print(f"| the segment's ends held ({reach} bases at each) | {' / '.join(f'{m:.1f}°' for m in means)} "
          f"| {min(sds):.1f}–{max(sds):.1f}° |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="runs/diamond-orientation")
    ap.add_argument("--until-time", type=float, default=4000.0)
    ap.add_argument("--held-ends", action="store_true", help="the segment's ends held in place, each seed to 80 patches")
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    if args.held_ends:
        held_ends(args.seeds)
        return
    data = merge(read_toml("diamond"),  # its physics as shipped, plus the series
                 {"run": {"until_time": args.until_time},
                  "effects": {"want": [*DEFAULT, "statistics-series"], "series_every": 20.0}})
    outcome = runner.run(Scene.from_dict(data), args.out, overwrite=True)
    sim = outcome.sim
    with open(Path(args.out) / "statistics.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["mean_orientation_deg"] not in ("", "nan")]
    t = np.array([float(r["t_tu"]) for r in rows])
    n = np.array([float(r["n_patches"]) for r in rows])
    mean = np.array([float(r["mean_orientation_deg"]) for r in rows])
    radius = np.array([float(r["radius_lu"]) for r in rows])
    para = {k: np.array([parastichy_orientations(sim, r)[k] for r in radius]) for k in sim.lattice.offsets}

    many = n >= 10  # a mean over fewer patches says little
    near = np.flatnonzero(many & (np.abs(axial_difference(mean, 0.0)) <= 20.0))
    at80 = int(np.argmax(n >= 80)) if (n >= 80).any() else None
    print(f"{len(rows)} rows, t = {t[0]:.0f} … {t[-1]:.0f}, patches {int(n[0])} … {int(n[-1])}, radius {radius[0]:.3f} … {radius[-1]:.3f}")
    print(f"mean orientation: {mean[0]:.1f}° at the first row, {mean[-1]:.1f}° at the last; "
          + ("never within 20° of horizontal" if near.size == 0 else
             f"first within 20° of horizontal (≥ 10 patches) at t = "
             f"{t[near[0]]:.0f} ({int(n[near[0]])} patches, SD {float(rows[near[0]]['circular_sd_deg']):.0f}°)"))
    if at80 is not None:
        print(f"at 80 patches (the paper's stop): t = {t[at80]:.0f}, mean {mean[at80]:.1f}°, SD {float(rows[at80]['circular_sd_deg']):.1f}°")
    peak = int(np.argmax(n))
    after = np.flatnonzero(~many & (t > t[peak]))  # split into fragments of fewer than 7 bases
    print(f"most patches: {int(n[peak])} at t = {t[peak]:.0f}; fewer than 10 again from "
          + (f"t = {t[after[0]]:.0f}" if after.size else "never"))
    for k, a in para.items():
        print(f"parastichy of offset {k}: {a[0]:.1f}° at r = {radius[0]:.3f} → {a[-1]:.1f}° at r = {radius[-1]:.3f}")

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)
    left, right = fig.subplots(1, 2)
    left.plot(t, mean, "o-", ms=3, label="mean orientation of the patches")
    for k, a in para.items():
        left.plot(t, a, "--", label=f"parastichy of offset {k}")
    left.axhline(1.2, color="crimson", lw=0.8, label="the paper: 1.2°")
    left.set_xlabel("time (time units; 1 = 88.5 days)")
    left.set_ylabel("orientation (° from horizontal; 90 = up the trunk)")
    left.set_ylim(0, 180)
    left.legend(fontsize=7)
    right.plot(n, mean, "o-", ms=3)
    right.set_xlabel("patches (≥ 7 bases)")
    right.set_ylabel("mean orientation (°)")
    right.set_ylim(0, 180)
    fig.suptitle("Table 2 diamond regime (3000 bases), its shipped scene run on", fontsize=9)
    path = Path(args.out) / "diamond-orientation.png"
    fig.savefig(path)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
