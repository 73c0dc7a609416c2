"""The rich progress bar (simulated time, radius, broken springs, patches) and the closing table."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table


def _fraction(sim, stop, r0: float) -> float:
    parts = []
    if stop.until_time is not None:
        parts.append(sim.state.t / stop.until_time)
    if stop.until_radius is not None and stop.until_radius > r0:
        parts.append((sim.radius - r0) / (stop.until_radius - r0))
    if stop.until_patches is not None:
        parts.append(sim.patch_count(stop.min_patch_size) / stop.until_patches)
    return min(1.0, max(parts, default=0.0))


@contextlib.contextmanager
def progress_observer(sim, stop, enabled: bool, every_s: float = 0.1):
    """Yield an ``observe(sim)`` callback that refreshes a progress bar at most every ``every_s``."""
    if not enabled:
        yield None
        return
    r0 = sim.radius
    columns = (
        TextColumn("[bold]bark"),
        BarColumn(),
        TextColumn("t={task.fields[t]:>9.2f}  r={task.fields[r]:.4f}  broken={task.fields[broken]:>6}  patches={task.fields[patches]:>4}"),
        TimeElapsedColumn(),
    )
    with Progress(*columns, transient=False) as progress:
        task = progress.add_task("run", total=1.0, t=0.0, r=r0, broken=0, patches=0)
        last = [0.0]

        def observe(s):
            now = time.monotonic()
            if now - last[0] < every_s:
                return
            last[0] = now
            progress.update(
                task, completed=_fraction(s, stop, r0), t=s.state.t, r=s.radius, broken=s.n_broken,
                patches=s.patch_count(stop.min_patch_size),
            )

        yield observe
        last[0] = 0.0
        observe(sim)


def print_summary(summary: dict, out: Path) -> None:
    table = Table(title=f"stopped by {summary['stop_reason']}", caption=f"outputs in {out}", show_header=False)
    for key in ("t", "radius", "steps", "n_broken", "n_patches", "mean_orientation_deg", "circular_sd_deg",
                "mean_anisotropy", "fraction_within_45_deg", "wall_time_s"):
        value = summary.get(key)
        table.add_row(key, f"{value:.4g}" if isinstance(value, float) else str(value))
    Console().print(table)
