"""What a one-step run costs as a whole process, against the plain numpy baseline of the same work.

    python benchmarks/one_step_process.py [--pairs 5] [--backend numpy|numba]

Runs, in turn, ``bark simulate --until-time 0.3`` of the default scene (one step: its outputs, the
checkpoint, pattern.png) and ``benchmarks/plain_numpy.py`` (the same lattice, step, statistics and
PNG, in one script without bark), after one warm-up of each, and prints each one's CPU (user + sys,
the operating system's accounting of the finished process) and wall time, their medians, and the
median of the pairwise ratios bark / plain. Ratios, not seconds, are what compares across machines.

Both run with their bytecode cached, as an installed package has it (pip compiles a wheel's modules
when it installs them): where the environment sets ``PYTHONDONTWRITEBYTECODE`` the benchmark lifts
it for its processes, so that the warm-up writes the ``.pyc`` files an editable checkout lacks.
Otherwise every process would compile bark's modules from source again, a cost no user's run pays
(the plain script, run as ``__main__``, is compiled every time either way).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
"""The processes' environment: bytecode cached (the module's docstring)."""


def timed(argv: list[str]) -> tuple[float, float]:
    """(CPU seconds, wall seconds) of one whole process running ``argv``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=ENV)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({proc.returncode}): {err.strip()}")
    return usage.ru_utime + usage.ru_stime, wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=5)
    parser.add_argument("--backend", choices=("auto", "numpy", "numba"), default="auto")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bark = [sys.executable, "-m", "bark_cli", "simulate", "--until-time", "0.3", "--backend", args.backend,
                "--out", f"{tmp}/bark", "--overwrite", "--quiet"]
        plain = [sys.executable, str(HERE / "plain_numpy.py"), "--out", f"{tmp}/plain"]
        timed(bark), timed(plain)  # warm-up: caches, the file system
        runs = [(timed(bark), timed(plain)) for _ in range(args.pairs)]
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; {args.pairs} pairs after a warm-up"
          f"{' (PYTHONDONTWRITEBYTECODE lifted: bytecode cached)' if 'PYTHONDONTWRITEBYTECODE' in os.environ else ''}")
    for name, k in (("bark simulate (one step)", 0), ("plain numpy script", 1)):
        cpu, wall = zip(*(r[k] for r in runs))
        print(f"{name:26s} CPU {statistics.median(cpu):6.2f} s   wall {statistics.median(wall):6.2f} s")
    ratio = statistics.median(b[0] / p[0] for b, p in runs)
    print(f"bark / plain, CPU: {ratio:.2f} (median of the pairs)")


if __name__ == "__main__":
    main()
