"""What a warm run costs, as a fit's or a sweep's worker runs it: CPU per run, against another checkout.

    python benchmarks/warm_run.py [--scene reticulate] [--seeds 3] [--rounds 3] [--against DIR]

A worker process runs the scene in memory to its stop and measures its statistics, as ``bark fit``'s
workers do (``bark.studies.fit.simulate_statistics``), once to warm up (imports, compiled kernels
loaded — or compiled: the worker says it runs many, as a fit's does, so that ``auto`` takes numba
even where its kernel is not compiled yet) and then once per seed, timing each run's CPU
(``time.process_time``), the share of it inside its calls' ``take`` (the compiled kernel and the
building of its arguments: what is not Python per pass of the loop), and counting its passes of the
loop (``Simulation.advance``: one call of the kernel each).  What a pass costs outside the kernel's
calls is split among the parts of the loop that this checkout has: the bases joining
(``Simulation.join``), ``break_springs``, ``stepping.plan`` and the call around the kernel
(``Backend.steps`` less the kernel's ``take``: the frame, the live springs, the result); what a
run spends outside its passes (building the scene, its first bases joined, its statistics) is
said apart. With ``--against DIR`` (a
checkout of bark, e.g. ``git worktree add /tmp/base <commit>``) the same worker runs that code too,
the two interleaved round by round so that a change in the machine's load falls on both, and the
script prints both, the median of the pairwise ratios this / that, and whether the final states and
break logs are the same to the bit.
"""

from __future__ import annotations

import argparse
import hashlib
import json
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
from bark.engine.scene import read_toml
from bark.engine.simulation import Simulation
from bark.studies.fit import simulate_statistics
from bark.engine import kernels, stepping
if hasattr(kernels, "expect_many"):  # as a fit's worker says: its warm-up compiles a kernel not yet compiled
    kernels.expect_many()

scene, seeds = sys.argv[1], [int(s) for s in sys.argv[2].split(",")]
counted = {"advances": 0, "sim": None, "kernel": 0.0, "passes": 0.0, "in_pass": False}
advance, run = Simulation.advance, Simulation.run

def counting(self, *a, **k):
    counted["advances"] += 1
    t0, counted["in_pass"] = time.process_time(), True
    try:
        return advance(self, *a, **k)
    finally:
        counted["passes"] += time.process_time() - t0
        counted["in_pass"] = False

def keeping(self, *a, **k):
    counted["sim"] = self
    return run(self, *a, **k)

Simulation.advance, Simulation.run = counting, keeping
PARTS = {"join": (Simulation, "join"), "break_springs": (Simulation, "break_springs"), "plan": (stepping, "plan"),
         "steps": (getattr(kernels, "Backend", None), "steps")}


def part_timed(key, f):
    def timed(*a, **k):
        if not counted["in_pass"]:  # e.g. the first bases joined when the scene is built: not a pass's
            return f(*a, **k)
        t0, k0 = time.process_time(), counted["kernel"]
        try:
            return f(*a, **k)
        finally:  # less the kernel's calls made inside (Backend.steps: the call around the kernel)
            counted[key] += time.process_time() - t0 - (counted["kernel"] - k0)
    return timed


for key, (owner, name) in PARTS.items():  # where a pass's Python goes (each part that this checkout has)
    if getattr(owner, name, None) is not None:
        counted[key] = 0.0
        setattr(owner, name, part_timed(key, getattr(owner, name)))
if hasattr(kernels, "take_steps"):  # the CPU inside each call's take (the kernel, and building its arguments)
    steps_of = kernels.take_steps

    def timed_steps(call, *rest):
        take = call.take

        def timed(*a):
            t0 = time.process_time()
            try:
                return take(*a)
            finally:
                counted["kernel"] += time.process_time() - t0
        call.take = timed
        return steps_of(call, *rest)
    kernels.take_steps = timed_steps
    if getattr(stepping, "take_steps", None) is steps_of:  # the Python path's steps take the algorithm by name
        stepping.take_steps = timed_steps
data = read_toml(scene)
names = ("orientation", "sd", "anisotropy")  # what a fit compares by default
simulate_statistics({**data, "run": {**data.get("run", {}), "seed": 10_000}}, names)  # warm: imports, kernels
for seed in seeds:
    counted.update({key: 0.0 for key in PARTS if key in counted}, advances=0, kernel=0.0, passes=0.0)
    t0 = time.process_time()
    stats = simulate_statistics({**data, "run": {**data.get("run", {}), "seed": seed}}, names)
    cpu = time.process_time() - t0
    sim = counted["sim"]
    digest = hashlib.sha256()
    for a in (sim.state.x, sim.state.intact, *(sim.breaks.arrays()[k] for k in sorted(sim.breaks.arrays()))):
        digest.update(np.ascontiguousarray(a).tobytes())
    print(json.dumps({"seed": seed, "cpu": cpu, "kernel": counted["kernel"], "advances": counted["advances"],
                      "passes": counted["passes"], "steps": sim.step_count,
                      "parts": {key: counted[key] for key in PARTS if key in counted},
                      "t": sim.state.t, "stats": stats, "bits": digest.hexdigest()}), flush=True)
"""


def worker(code: Path | None, scene: str, seeds: list[int], links: Path) -> list[dict]:
    """One worker process on ``code`` (``None``: this checkout as installed): its runs' records."""
    return worker_records(code, links, WORKER, scene, ",".join(map(str, seeds)))


def _pass(rounds: list[list[dict]]) -> str:
    """Where a pass's CPU outside the kernel's calls goes, in µs, and what a run spends outside its
    passes (medians over the runs)."""
    runs = [r for rnd in rounds for r in rnd if r.get("parts")]
    if not runs:
        return "where a pass's Python goes: not measured"
    per = lambda r, v: 1e6 * v / max(r["advances"], 1)  # noqa: E731
    outside = statistics.median(per(r, r["passes"] - r["kernel"]) for r in runs)
    parts = {k: statistics.median(per(r, r["parts"][k]) for r in runs) for k in runs[0]["parts"]}
    named = {"steps": "the call around the kernel"}
    rest = statistics.median(1e3 * (r["cpu"] - r["passes"]) for r in runs)
    return (f"a pass outside the kernel's calls: {outside:.0f} µs; of it " +
            ", ".join(f"{named.get(k, k)} {v:.0f}" for k, v in parts.items()) +
            f"; outside the passes (the scene built, its statistics): {rest:.1f} ms a run")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="reticulate")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--against", type=Path, default=None, help="another checkout of bark to compare with")
    args = parser.parse_args()
    seeds = list(range(args.seeds))
    with tempfile.TemporaryDirectory() as tmp:
        links = linked(args.against, Path(tmp)) if args.against is not None else Path(tmp)
        sides = {"this": None, **({"that": args.against} if args.against is not None else {})}
        runs: dict[str, list[list[dict]]] = {side: [] for side in sides}
        for _ in range(args.rounds):
            for side, code in sides.items():
                runs[side].append(worker(code, args.scene, seeds, links))
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; scene {args.scene}, seeds "
          f"{seeds}, {args.rounds} rounds after a warm-up run in each worker")
    for side, code in sides.items():
        last = runs[side][-1]
        cpu = [r["cpu"] for rnd in runs[side] for r in rnd]
        share = statistics.median(r["kernel"] / r["cpu"] for rnd in runs[side] for r in rnd) if "kernel" in last[0] else None
        print(f"{side} ({code or ROOT}): CPU per run {statistics.median(cpu):.3f} s (median), "
              + (f"{100 * share:.0f} % of it in the kernel's calls, " if share is not None else "") + "passes of the loop "
              f"{[r['advances'] for r in last]}, steps {[r['steps'] for r in last]}, t {[round(r['t'], 3) for r in last]}")
        print(f"  {_pass(runs[side])}")
    if "that" in sides:
        ratios = [a["cpu"] / b["cpu"] for ra, rb in zip(runs["this"], runs["that"]) for a, b in zip(ra, rb)]
        same = all(a["bits"] == b["bits"] for a, b in zip(runs["this"][-1], runs["that"][-1]))
        stats = all(a["stats"] == b["stats"] for a, b in zip(runs["this"][-1], runs["that"][-1]))
        print(f"this / that, CPU per run: {statistics.median(ratios):.3f} (median of {len(ratios)} pairs; "
              f"range {min(ratios):.3f}-{max(ratios):.3f})")
        print(f"final states and break logs the same to the bit: {same}; statistics equal: {stats}")
    digest = hashlib.sha256(json.dumps([r["bits"] for r in runs["this"][-1]]).encode()).hexdigest()[:12]
    print(f"this checkout's runs: {digest}")


if __name__ == "__main__":
    main()
