"""What accuracy costs on the whole tree: the shipped scene (bark/scenes/whole-tree.toml) at the
paper's fixed dt = 0.01, at adaptive steps of several overshoot tolerances and at coarser fixed
steps, three seeds each, statistics only (no pictures, nothing written)::

    python benchmarks/whole_tree_accuracy.py [--seeds 3] [--only adaptive-0.005,fixed-0.01]

Prints one markdown row per stepping: the steps (the work, the same on any machine), the broken
springs per seed, the patches, and the per-region statistics of summary.json (the straight trunk
of the start: its largest patch's share, mean orientation and SD; the bulges' mean).  A stepping
whose figures stay within the seeds' spread of dt = 0.01's costs no accuracy that matters.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

from bark.engine.scene import Scene, merge, read_toml
from bark.studies import runner

SCENE = Path(__file__).resolve().parent.parent / "bark" / "scenes" / "whole-tree.toml"
STEPPINGS = {
    "fixed-0.01": {"stepping": "fixed", "dt": 0.01},
    "adaptive-0.002": {"stepping": "adaptive", "overshoot_tol": 0.002},
    "adaptive-0.003": {"stepping": "adaptive", "overshoot_tol": 0.003},
    "adaptive-0.005": {"stepping": "adaptive", "overshoot_tol": 0.005},
    "adaptive-0.01": {"stepping": "adaptive", "overshoot_tol": 0.01},
    "fixed-0.05": {"stepping": "fixed", "dt": 0.05},
    "fixed-0.1": {"stepping": "fixed", "dt": 0.1},
}
STATISTICS = ["bulges", "anchors", "damping", "patch-statistics"]


def measure(name: str, seed: int) -> dict:
    scene = merge(read_toml(SCENE), {"run": {**STEPPINGS[name], "seed": seed}, "effects": {"want": STATISTICS}})
    s = runner.run(Scene.from_dict(scene), None).summary
    straight, bulge = s["regions"]["straight"], s["regions"]["bulge"]
    return {"steps": s["steps"], "broken": s["n_broken"], "patches": s["n_patches"], "share": straight["largest_patch_share"],
            "mean": straight["mean_orientation_deg"], "sd": straight["circular_sd_deg"],
            "bulge": bulge["mean_orientation_deg"]}


def row(name: str, runs: list[dict]) -> str:
    def spread(key, fmt):
        values = [r[key] for r in runs]
        return f"{fmt(min(values))}–{fmt(max(values))}"
    one = (lambda v: f"{v:.1f}°")
    return (f"| {name} | {statistics.mean(r['steps'] for r in runs):,.0f} | "
            f"{' / '.join(format(r['broken'], ',') for r in runs)} | "
            f"{statistics.mean(r['patches'] for r in runs):.0f} ± {statistics.pstdev(r['patches'] for r in runs):.0f} | "
            f"{spread('share', lambda v: f'{v:.4f}')} | {spread('mean', one)} | {spread('sd', one)} | {spread('bulge', one)} |")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--only", default=",".join(STEPPINGS), help="steppings, comma-separated: " + ", ".join(STEPPINGS))
    args = parser.parse_args(argv)
    names = args.only.split(",")
    unknown = [n for n in names if n not in STEPPINGS]
    if unknown:
        sys.exit(f"--only: unknown stepping {unknown[0]!r} (one of {', '.join(STEPPINGS)})")
    print("| stepping | steps | broken springs, seeds | patches | straight: largest patch | straight: mean | straight: SD "
          "| bulges: mean |\n|---|---|---|---|---|---|---|---|", flush=True)
    for name in names:
        print(row(name, [measure(name, seed) for seed in range(args.seeds)]), flush=True)


if __name__ == "__main__":
    main()
