"""``bark bench`` — measurements, never tests.  Every figure is also given as a ratio against a
baseline measured in the same run (the numpy backend), because the machines are shared and noisy."""

from __future__ import annotations

import time
import tracemalloc

import click
import numpy as np

from bark.simulation import Stop


@click.group()
def bench():
    """Benchmarks: speed of the step loop, per backend."""


def _phase_sim(n: int, backend: str, start_t: float):
    """The default scene at ``n`` bases on ``backend``, compiled and run up to ``start_t``."""
    from bark.scene import Scene

    sim = Scene.from_dict({"lattice": {"n_bases": n}, "run": {"backend": backend}}).simulation()
    sim.run(Stop(until_time=max(start_t, 2 * sim.h)))  # also compiles the kernels, outside the timing
    return sim


def _steps_per_second(n: int, backend: str, start_t: float, steps: int, repeats: int) -> float:
    """Median steps/s over ``repeats`` stretches of ``steps`` steps from ``start_t``."""
    sim = _phase_sim(n, backend, start_t)
    rates = []
    for _ in range(repeats):
        s0, t0 = sim.step_count, time.perf_counter()
        sim.run(Stop(until_time=sim.state.t + steps * sim.h))
        rates.append((sim.step_count - s0) / (time.perf_counter() - t0))
    return float(np.median(rates))


def _peak_memory(n: int, backend: str, start_t: float, steps: int) -> float:
    """Peak memory (MiB, numpy and Python allocations as traced by tracemalloc) of building the
    simulation and running it through the phase; measured apart from the timing, which tracing slows."""
    tracemalloc.start()
    sim = _phase_sim(n, backend, start_t)
    sim.run(Stop(until_time=sim.state.t + steps * sim.h))
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


PHASES = {
    # name: (start time, end time, description) — default scene, vertical regime: first breaks at t ≈ 13
    "quiet": (0.0, 12.0, "t in [0, 12]: no spring over its threshold yet"),
    "cracking": (13.0, 40.0, "t in [13, 40]: springs breaking every few steps"),
}


@bench.command()
@click.option("--n-bases", "sizes", type=int, multiple=True, default=(3000, 70000), show_default=True)
@click.option("--backend", "backends", type=click.Choice(["numpy", "numba"]), multiple=True,
              default=("numpy", "numba"), show_default=True, help="numpy is always measured: it is the baseline.")
@click.option("--phase", "phases", type=click.Choice(list(PHASES)), multiple=True, default=("quiet", "cracking"),
              show_default=True, help="cracking is measured only up to 10000 bases (reaching it takes long).")
@click.option("--steps", type=int, default=None, help="Steps per timed stretch (default: about 0.3 s of numpy work).")
@click.option("--repeats", type=int, default=3, show_default=True)
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None, help="Also write the table as CSV.")
def speed(sizes, backends, phases, steps, repeats, csv_path):
    """Steps per second of the full step (integrate, constrain, tensions, breaking, stop checks) on
    the default scene, per backend and phase, with ratios against numpy measured in this run."""
    from rich.console import Console
    from rich.table import Table

    backends = ("numpy", *[b for b in backends if b != "numpy"])
    rows = []
    for n in sizes:
        for phase in phases:
            start_t, end_t, _ = PHASES[phase]
            if phase == "cracking" and n > 10000:
                continue
            k = steps or max(10, int(0.3 / (1.3e-7 * n)))  # numpy takes ~0.13 µs per base per step
            k = min(k, int((end_t - start_t) / 0.01 / repeats))  # stay inside the phase
            base = None
            for backend in backends:
                rate = _steps_per_second(n, backend, start_t, k, repeats)
                peak = _peak_memory(n, backend, start_t, k)
                base = base or (rate, peak)
                rows.append({
                    "n_bases": n, "phase": phase, "backend": backend, "steps": k * repeats,
                    "steps_per_s": rate, "speed_vs_numpy": rate / base[0],
                    "peak_MiB": peak, "memory_vs_numpy": peak / base[1],
                })
    table = Table(*rows[0].keys(), title="bark bench speed — default scene (Table 2 vertical regime)")
    for r in rows:
        table.add_row(*(f"{v:.4g}" if isinstance(v, float) else str(v) for v in r.values()))
    Console(width=140).print(table)
    if csv_path:
        from bark.output import write_csv

        write_csv(csv_path, rows, list(rows[0]))
