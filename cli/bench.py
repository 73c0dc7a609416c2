"""``bark bench`` — measurements, never tests.  Every figure is also given as a ratio against a
baseline measured in the same run, because the machines are shared and noisy."""

from __future__ import annotations

import time
import tracemalloc

import click
import numpy as np


@click.group()
def bench():
    """Benchmarks: speed of the step loop."""


def _time_per_call(fn, min_time: float = 0.5, min_calls: int = 5) -> float:
    """Median over rounds of the mean seconds per call."""
    fn()
    rounds = []
    for _ in range(3):
        n, t0 = 0, time.perf_counter()
        while n < min_calls or time.perf_counter() - t0 < min_time / 3:
            fn()
            n += 1
        rounds.append((time.perf_counter() - t0) / n)
    return float(np.median(rounds))


@bench.command()
@click.option("--n-bases", "sizes", type=int, multiple=True, default=(3000, 70000), show_default=True)
@click.option("--seconds", type=float, default=2.0, show_default=True, help="Time spent timing each size.")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None, help="Also write the table as CSV.")
def speed(sizes, seconds, csv_path):
    """Steps per second of the full step (forces, integrate, constrain, tensions, breaking) on the
    default scene at each size, against the force evaluation alone as baseline."""
    from rich.console import Console
    from rich.table import Table

    from bark.scene import Scene

    rows = []
    for n in sizes:
        sim = Scene.from_dict({"lattice": {"n_bases": n}}).simulation()
        tracemalloc.start()
        step = _time_per_call(sim.step, seconds / 2)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        force = _time_per_call(sim.state.forces, seconds / 2)
        rows.append({
            "n_bases": n, "n_springs": sim.state.n_springs, "steps_per_s": 1 / step, "us_per_step": step * 1e6,
            "force_eval_us": force * 1e6, "step_over_force_eval": step / force, "peak_step_mem_MiB": peak / 2**20,
        })
    table = Table(*rows[0].keys(), title="bark bench speed (numpy)")
    for r in rows:
        table.add_row(*(f"{v:.4g}" if isinstance(v, float) else str(v) for v in r.values()))
    Console().print(table)
    if csv_path:
        from bark.output import write_csv

        write_csv(csv_path, rows, list(rows[0]))
