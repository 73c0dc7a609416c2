"""Warm whole processes of ``bark simulate``, this checkout against another, interleaved.

    python benchmarks/whole_process.py --against DIR [--pairs 5] -- --scene whole-tree --backend numba \
        --set 'effects.want=["bulges","anchors","damping","patch-statistics"]'

Everything after ``--`` is given to ``bark simulate`` (with ``--out`` and ``--quiet``) on both sides.
Each side runs once first on caches of its own (its kernels compiled and cached, not timed), then the
pairs are timed in alternating order (this first, then that first), so that a change in the machine's
load falls on both.  Prints each run's wall and CPU seconds (user + sys, children included) and the
median of the pairs' ratios that / this: above 1, this checkout is faster.  ``DIR``: a checkout of
bark (``git worktree add /tmp/base <commit>``); its packages are put first on ``PYTHONPATH``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from first_run import ROOT, linked, timed  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", type=Path, required=True, help="another checkout of bark to compare with")
    parser.add_argument("--pairs", type=int, default=5)
    parser.add_argument("simulate", nargs=argparse.REMAINDER, help="-- and the options of bark simulate")
    args = parser.parse_args()
    options = args.simulate[1:] if args.simulate[:1] == ["--"] else args.simulate
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        links = linked(args.against, tmp / "links")
        sides = {}
        for side in ("this", "that"):
            caches = tmp / side
            env = {**os.environ, "NUMBA_CACHE_DIR": str(caches / "numba"), "BARK_CACHE_DIR": str(caches / "bark")}
            if side == "that":
                env["PYTHONPATH"] = str(links)
            argv = [sys.executable, "-m", "bark_cli", "simulate", *options, "--out", str(caches / "out"), "--quiet",
                    "--overwrite"]
            sides[side] = (argv, env)
            timed(argv, env, str(tmp))  # compiles and caches what it uses: not timed
        got = {"this": [], "that": []}
        for k in range(args.pairs):
            for side in (("this", "that") if k % 2 == 0 else ("that", "this")):
                got[side].append(timed(*sides[side], str(tmp)))
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
          f"bark simulate {' '.join(options)}; seconds: wall / CPU")
    for side, code in (("this", ROOT), ("that", args.against)):
        print(f"{side} ({code}): " + ", ".join(f"{w:.2f} / {c:.2f}" for w, c in got[side]))
    walls = [b[0] / a[0] for a, b in zip(got["this"], got["that"])]
    cpus = [b[1] / a[1] for a, b in zip(got["this"], got["that"])]
    print(f"that / this, median of {args.pairs} pairs: wall {statistics.median(walls):.3f} "
          f"({min(walls):.3f}-{max(walls):.3f}), CPU {statistics.median(cpus):.3f} ({min(cpus):.3f}-{max(cpus):.3f})")


if __name__ == "__main__":
    main()
