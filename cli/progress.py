"""Progress on stderr — the rich progress bar on a terminal, plain periodic lines in a log (simulated
time and years, bases, height, radius, broken springs, patches, elapsed time and the time left) —
and the closing table."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from bark.units import metres, years


def _fraction(sim, stop, r0: float) -> float:
    parts = []
    if stop.until_time is not None:
        parts.append(sim.state.t / stop.until_time)
    if stop.until_radius is not None and stop.until_radius > r0:
        parts.append((sim.radius - r0) / (stop.until_radius - r0))
    if stop.until_patches is not None:
        parts.append(sim.patch_count(stop.min_patch_size) / stop.until_patches)
    return min(1.0, max(parts, default=0.0))


def _fields(sim, stop) -> dict:
    """What the bar shows: simulated time (and years), bases on the trunk, its height (the highest
    site, in metres), mean radius (and cm), broken springs, patches."""
    s, r = sim.state, sim.radius
    return {"t": s.t, "years": years(s.t), "bases": s.n_bases, "height": metres(float(s.anchor[:, 2].max(initial=0.0))),
            "r": r, "r_cm": 100 * metres(r), "broken": sim.n_broken, "patches": sim.patch_count(stop.min_patch_size)}


WIDE = 165
"""Terminal columns from which ``bark simulate``'s bar shows every field; below, the fields that fit
80 columns with the bar and the time left."""


class ProgressBar:
    """An ``observe(sim, stop)`` callback for :func:`bark.studies.runner.run` that shows a progress bar,
    refreshed at most every ``every_s``; it starts at the first call and ends at :meth:`close`."""

    def __init__(self, every_s: float = 0.1) -> None:
        self.every_s = every_s
        self._progress = self._task = self._sim = self._stop = None
        self._last = 0.0
        self._r0 = 0.0

    def __call__(self, sim, stop, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last < self.every_s:
            return
        self._last, self._sim, self._stop = now, sim, stop
        try:
            self._show(sim, stop)
        except (OSError, ValueError):  # the terminal went away (EIO) or stderr closed: the run goes on unseen
            self.every_s, self._progress = float("inf"), None

    def _show(self, sim, stop) -> None:
        if self._progress is None:
            self._r0 = sim.radius
            console = Console(stderr=True)
            if console.width >= WIDE:
                columns = (
                    TextColumn("[bold]bark"),
                    BarColumn(),
                    TextColumn("t={task.fields[t]:>8.2f} ({task.fields[years]:.1f} y)  bases={task.fields[bases]}  "
                               "height={task.fields[height]:.2f} m  r={task.fields[r]:.4f} ({task.fields[r_cm]:.1f} cm)  "
                               "broken={task.fields[broken]:>6}  patches={task.fields[patches]:>4}"),
                    TimeElapsedColumn(),
                    TextColumn("left"),
                    TimeRemainingColumn(),
                )
            else:  # a narrower terminal (80 columns): the bar, time, breaks and patches, and the time left
                columns = (
                    TextColumn("[bold]bark"),
                    BarColumn(bar_width=12),
                    TextColumn("t={task.fields[t]:.1f} ({task.fields[years]:.1f} y)  {task.fields[broken]} broken  "
                               "{task.fields[patches]} patches"),
                    TextColumn("left"),
                    TimeRemainingColumn(),
                )
            progress = Progress(*columns, transient=False, console=console)
            progress.start()
            self._task = progress.add_task("run", total=1.0, **_fields(sim, stop))
            self._progress = progress  # whole: a signal in the middle of this leaves none to close
        self._progress.update(self._task, completed=_fraction(sim, stop, self._r0), **_fields(sim, stop))

    def close(self) -> None:
        """Show the bar's last state and take it off the terminal."""
        if self._progress is not None:
            self(self._sim, self._stop, force=True)
            try:
                if self._progress is not None:
                    self._progress.stop()
            except (OSError, ValueError):  # as in __call__
                pass
            self._progress = None


class ProgressLog:
    """An ``observe(sim, stop)`` callback that writes a plain line to stderr at the first call, then at
    most every ``every_s`` seconds of wall time, and at :meth:`close`: for a log (a batch job's stderr
    is a file), which a bar would leave empty until the end.  The time left is the elapsed time scaled
    by the part of the run still to go (its stop conditions'), once there is a part done to scale."""

    def __init__(self, every_s: float = 30.0) -> None:
        self.every_s = every_s
        self._start = self._last = None
        self._seen = None

    def __call__(self, sim, stop, force: bool = False) -> None:
        now = time.monotonic()
        if self._start is None:
            self._start, self._r0 = now, sim.radius
        elif not force and now - self._last < self.every_s:
            self._seen = (sim, stop)
            return
        self._last, self._seen = now, None
        f = _fields(sim, stop)
        done = _fraction(sim, stop, self._r0)
        elapsed = now - self._start
        left = f", {_duration(elapsed * (1 - done) / done)} left" if 0 < done < 1 else ""
        line = (f"bark: t = {f['t']:.6g} ({f['years']:.1f} years, {100 * done:.1f} %), {f['bases']:,} bases, "
                f"height {f['height']:.2f} m, r = {f['r']:.4g} ({f['r_cm']:.1f} cm), {f['broken']:,} broken, "
                f"{f['patches']:,} patch{'' if f['patches'] == 1 else 'es'}; {_duration(elapsed)} elapsed{left}")
        try:
            print(line, file=sys.stderr, flush=True)
        except (OSError, ValueError):  # a closed or full stderr: the run goes on without its log
            self.every_s = float("inf")

    def close(self) -> None:
        """Write the last line (where the run stopped)."""
        if self._seen is not None:
            self(*self._seen, force=True)


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}" if m else f"{s} s"


def print_summary(summary: dict, out: Path) -> None:
    """Print a run's summary (summary.json's ``summary``) as a table on the terminal, with the folder ``out`` its
    files are in."""
    table = Table(title=f"stopped by {summary['stop_reason']}", caption=f"outputs in {out}", show_header=False)
    for key in ("t", "radius", "steps", "n_broken", "n_patches", "mean_orientation_deg", "circular_sd_deg",
                "mean_anisotropy", "fraction_within_45_deg", "wall_time_s"):
        value = summary.get(key)
        table.add_row(key, f"{value:.4g}" if isinstance(value, float) else str(value))
    for name, r in (summary.get("regions") or {}).items():  # a trunk with regions: each its own line
        table.add_row(f"region {name}", _region_line(r))
    for key, value in (summary.get("fracture") or {}).items():  # the fracture-history effect
        table.add_row(key, f"{value:.4g}" if isinstance(value, float) else str(value))
    Console().print(table)


def _region_line(r: dict) -> str:
    """A region's statistics in one line: its patches' orientation and anisotropy, its largest patch."""
    import math

    def num(key: str, fmt: str) -> str:
        value = r.get(key)
        return "—" if value is None or not math.isfinite(value) else format(value, fmt)

    n, share = r["n_patches"], r.get("largest_patch_share")
    text = "no patches" if not n else (f"{n} patch{'es' if n > 1 else ''} at {num('mean_orientation_deg', '.1f')}° "
                                       f"(SD {num('circular_sd_deg', '.1f')}°), anisotropy {num('mean_anisotropy', '.3f')}")
    return text + ("" if share is None else f"; largest {100 * share:.0f} % of {r['n_bases']:,} bases")


class Tally:
    """Progress of a long command counted in things done (a sweep's runs, a fit's accepted runs), on
    stderr, the same for every command: on a terminal a bar with the time left that fits 80 columns;
    in a log (stderr a file) a plain line at once, then every ``every_s`` seconds whether or not
    anything finished since, and a last one at :meth:`close`.  The time left scales the time since
    the first update by what is still to do, counting only what was done in this command (a run
    already in a sweep's table took none of its time).  ``quiet``: nothing."""

    def __init__(self, what: str, unit: str, every_s: float = 30.0, quiet: bool = False) -> None:
        import math
        import threading

        if not (math.isfinite(every_s) and every_s > 0):
            raise ValueError(f"progress every {every_s} s: expected a finite number of seconds above 0")
        self.what, self.unit, self.every_s = what, unit, every_s
        self.done = self.total = self.first = None
        self.detail = ""
        self.began = self.start = time.monotonic()  # the command's start; the count's (for the time left)
        self._lock, self._stop = threading.Lock(), threading.Event()
        self._bar = self._task = self._thread = None
        self.live = not quiet and sys.stderr.isatty()
        self.log = not quiet and not self.live
        if self.log:
            self._line()
            self._thread = threading.Thread(target=self._every, name=f"bark {what} progress", daemon=True)
            self._thread.start()

    def update(self, done: int, total: int, detail: str = "") -> None:
        """``done`` of ``total`` things are done now (``detail``: what to say beside the count); shown at once on
        a terminal, in a log at the next period."""
        with self._lock:
            if self.first is None:
                self.first, self.start = done, time.monotonic()
            self.done, self.total, self.detail = done, total, detail
        if self.live:
            self._show()

    def restart(self) -> None:
        """A new stretch of the count (a fit's next generation): the time left is taken from here."""
        with self._lock:
            self.first = None

    def say(self, line: str) -> None:
        """A line of the command's own on stderr, above the bar where there is one."""
        if self._bar is not None:
            try:
                self._bar.console.print(line, highlight=False, markup=False)
                return
            except (OSError, ValueError):
                self.live, self._bar = False, None
        try:
            print(line, file=sys.stderr, flush=True)
        except (OSError, ValueError):
            pass

    def _left(self) -> str:
        done, total, first = self.done, self.total, self.first
        if done is None or total is None or done <= first or done >= total:
            return ""
        return f", about {_duration((time.monotonic() - self.start) * (total - done) / (done - first))} left"

    def _line(self) -> None:
        with self._lock:
            done, total = self.done or 0, self.total
            count = f"{done:,} of {total:,} {self.unit}" if total is not None else "starting"
            detail = f"; {self.detail}" if self.detail else ""
            line = f"bark: {self.what}: {count}{detail}; {_duration(time.monotonic() - self.began)} elapsed{self._left()}"
        try:
            print(line, file=sys.stderr, flush=True)
        except (OSError, ValueError):  # a closed or full stderr: the command goes on without its log
            self._stop.set()

    def _every(self) -> None:
        while not self._stop.wait(self.every_s):
            self._line()

    def _show(self) -> None:
        try:
            if self._bar is None:
                from rich.progress import MofNCompleteColumn, Progress as Bar, TimeRemainingColumn

                self._bar = Bar(TextColumn(self.what), BarColumn(bar_width=24), MofNCompleteColumn(), TextColumn(self.unit),
                                TimeElapsedColumn(), TimeRemainingColumn(), console=Console(stderr=True), transient=True)
                self._bar.start()
                self._task = self._bar.add_task(self.what, total=self.total, completed=self.done)
            self._bar.update(self._task, total=self.total, completed=self.done)
        except (OSError, ValueError):  # the terminal went away: the command goes on unseen
            self.live, self._bar = False, None

    def close(self) -> None:
        """The last line (in a log) or the bar taken down (on a terminal); the ticking stopped."""
        if self._thread is not None and not self._stop.is_set():
            self._stop.set()
            self._thread.join()
            self._line()
        if self._bar is not None:
            try:
                self._bar.stop()
            except (OSError, ValueError):
                pass
            self._bar = None
