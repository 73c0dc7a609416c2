"""Runs per minute of a whole ``bark fit`` process, against another checkout, interleaved.

    python benchmarks/fit_rate.py --against DIR [--scene reticulate] [--population 30] [--workers 2]
                                  [--rounds 3]

``bark bench fit`` measures a fit against plain ``bark simulate`` processes of this checkout; this
script measures the same fit of two checkouts in one run — what an issue's "runs per minute against
today's code" asks. One observed pattern is made (this checkout, ``--seed 999``); then, round by
round, the fit of each checkout (``--generations 1 --predictive 0``: a calibration of
``--population`` runs from the prior and one generation; the same ``--seed`` on both sides, so
that the same settings are drawn and, where the two compute the same statistics, the same runs
are made) runs as a whole process, the two alternating so that a change in the machine's load falls
on both. Each fit's runs are counted from its ``fit.json`` (the calibration's ``--population``, then
its generation's runs); the script prints runs per minute of wall time and CPU seconds of the
process tree per run for each side, the median of the pairwise ratios this / that, and whether the
two fits made the same runs and the same posterior.

With ``DIR`` a checkout of bark (``git worktree add /tmp/base <commit>``), its packages are put on
``PYTHONPATH`` under the names the installed ones have; the interpreter, and so the libraries, are
this one's. Absolute figures are this machine's; the ratios are the figure.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from first_run import linked, timed  # noqa: E402


def _bark(args: list[str], env: dict) -> tuple[float, float]:
    """``bark ARGS`` as a process of its own: its wall and CPU seconds (its workers' included)."""
    return timed([[sys.executable, "-m", "bark_cli", *args]], env, tempfile.gettempdir())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", type=Path, required=True, help="another checkout of bark to compare with")
    parser.add_argument("--scene", default="reticulate")
    parser.add_argument("--population", type=int, default=30)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        links = linked(args.against, tmp / "links")
        envs = {"this": dict(os.environ), "that": {**os.environ, "PYTHONPATH": str(links)}}
        _bark(["simulate", "--scene", args.scene, "--seed", "999", "--out", str(tmp / "observed"), "--quiet"], envs["this"])
        records: dict[str, list[dict]] = {side: [] for side in envs}
        for r in range(args.rounds):
            for side, env in envs.items():
                out = tmp / f"{side}-{r}"
                wall, cpu = _bark(["fit", str(tmp / "observed"), "--scene", args.scene, "--population", str(args.population),
                       "--generations", "1", "--predictive", "0", "--seed", str(r), "--workers", str(args.workers),
                       "--out", str(out), "--quiet"], env)
                fit = json.loads((out / "fit.json").read_text())
                runs = args.population + fit["runs"]
                records[side].append({"wall": wall, "cpu": cpu, "runs": runs, "rate": 60.0 * runs / wall,
                                      "posterior": fit["posterior"]})
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; bark fit of scene {args.scene}, "
          f"population {args.population}, one generation, {args.workers} workers; {args.rounds} rounds")
    for side in envs:
        rec = records[side]
        each = ", ".join(f"{x['rate']:.0f}" for x in rec)
        print(f"{side} ({'this checkout' if side == 'this' else args.against}): runs per minute "
              f"{statistics.median(x['rate'] for x in rec):.0f} (median; {each}), "
              f"CPU per run {statistics.median(x['cpu'] / x['runs'] for x in rec):.3f} s, runs {[x['runs'] for x in rec]}")
    rate = [a["rate"] / b["rate"] for a, b in zip(records["this"], records["that"])]
    cpu = [(a["cpu"] / a["runs"]) / (b["cpu"] / b["runs"]) for a, b in zip(records["this"], records["that"])]
    print(f"this / that: runs per minute {statistics.median(rate):.2f} (median of {len(rate)} pairs; range "
          f"{min(rate):.2f}-{max(rate):.2f}); CPU per run {statistics.median(cpu):.3f}")
    same_runs = all(a["runs"] == b["runs"] for a, b in zip(records["this"], records["that"]))
    same_posterior = all(a["posterior"] == b["posterior"] for a, b in zip(records["this"], records["that"]))
    print(f"the same runs in every round: {same_runs}; the same posterior: {same_posterior}")


if __name__ == "__main__":
    main()
