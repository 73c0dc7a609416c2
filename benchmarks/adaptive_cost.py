"""What adaptive stepping costs over fixed steps: ns per base-step, compiled, one thread, quiet.

    python benchmarks/adaptive_cost.py [--n-bases 3000] [--case default] [--steps 1000] [--rounds 3]
                                       [--against DIR]

A worker process builds the scene (``default``: a uniform radius; ``bulge``: per-base radii, as
``bark bench speed --case``), once with fixed steps of 0.01 and once adaptive with the same largest
step, on the numba backend with one thread; runs both to t = 0.02 (compiles, or loads, the kernels),
then times ``--steps`` steps of each, alternating, three times (``time.process_time``).  In that
quiet phase no spring is near breaking, so adaptive stepping takes every step at its largest and
refuses none (the worker checks: the same step count): the difference is what being ready to take a
step back costs.  Each worker prints ns per base-step of both and their ratio; ``--rounds`` workers
run per checkout.  With ``--against DIR`` (another checkout of bark) its workers alternate with this
checkout's, and the script prints the ratios this / that of each stepping, and whether the two
checkouts' final states are the same to the bit.
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
from first_run import linked, worker_records  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent

WORKER = r"""
import hashlib, json, sys, time
import numpy as np
from bark import Stop
from bark.engine.scene import Scene, merge
from bark_cli.bench import _case

n, case, steps = int(sys.argv[1]), sys.argv[2], int(sys.argv[3])
sims = {}
for stepping in ("fixed", "adaptive"):
    run = {"backend": "numba", "threads": 1, "dt": 0.01, "stepping": stepping, "until_time": 1e6}
    sims[stepping] = sim = Scene.from_dict(merge(_case(n, case), {"run": run})).simulation()
    sim.run(Stop(until_time=0.02))
ns = {"fixed": [], "adaptive": []}
for _ in range(3):
    for stepping, sim in sims.items():
        first, t0 = sim.step_count, time.process_time()
        sim.run(Stop(until_time=sim.state.t + steps * 0.01 - 0.005))
        ns[stepping].append(1e9 * (time.process_time() - t0) / ((sim.step_count - first) * n))
counts = {s: sim.step_count for s, sim in sims.items()}
if counts["fixed"] != counts["adaptive"]:
    raise SystemExit(f"adaptive stepping took {counts['adaptive']} steps against {counts['fixed']}: not quiet")
digest = hashlib.sha256()
for sim in sims.values():
    for a in (sim.state.x, sim.state.v, sim.state.intact):
        digest.update(np.ascontiguousarray(a).tobytes())
print(json.dumps({"fixed": min(ns["fixed"]), "adaptive": min(ns["adaptive"]), "steps": counts["fixed"],
                  "bits": digest.hexdigest()}), flush=True)
"""


def worker(code: Path | None, args: argparse.Namespace, links: Path) -> dict:
    """One worker process on ``code`` (``None``: this checkout as installed): its record."""
    return worker_records(code, links, WORKER, str(args.n_bases), args.case, str(args.steps))[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-bases", type=int, default=3000)
    parser.add_argument("--case", choices=("default", "bulge"), default="default")
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--against", type=Path, default=None, help="another checkout of bark to compare with")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        links = linked(args.against, Path(tmp)) if args.against is not None else Path(tmp)
        sides = {"this": None, **({"that": args.against} if args.against is not None else {})}
        runs: dict[str, list[dict]] = {side: [] for side in sides}
        for _ in range(args.rounds):
            for side, code in sides.items():
                runs[side].append(worker(code, args, links))
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; {args.case} scene, "
          f"{args.n_bases} bases, {args.steps} steps a stretch, best of 3 stretches, {args.rounds} workers each")
    for side, code in sides.items():
        rs = runs[side]
        listed = {k: ", ".join(f"{r[k]:.2f}" for r in rs) for k in ("fixed", "adaptive")}
        ratios = ", ".join(f"{r['adaptive'] / r['fixed']:.3f}" for r in rs)
        print(f"{side} ({code or ROOT}): ns per base-step fixed {listed['fixed']}; adaptive {listed['adaptive']}; "
              f"adaptive / fixed {ratios}")
    if "that" in sides:
        for stepping in ("fixed", "adaptive"):
            ratios = [a[stepping] / b[stepping] for a, b in zip(runs["this"], runs["that"])]
            print(f"this / that, {stepping}: {statistics.median(ratios):.3f} (median of {len(ratios)} pairs; "
                  f"range {min(ratios):.3f}-{max(ratios):.3f})")
        print(f"final states the same to the bit: {runs['this'][-1]['bits'] == runs['that'][-1]['bits']}")


if __name__ == "__main__":
    main()
