"""``bark bench`` — measurements, never tests.  Every figure is also given as a ratio against a
baseline measured in the same run, because the machines are shared and noisy: for speed, a plain
vectorised numpy step of the same model written here (``PlainNumpy``), not a slow path of bark's own."""

from __future__ import annotations

import contextlib
import time
import tracemalloc

import click
import numpy as np

from bark.engine.simulation import Stop
from bark_cli.options import SCENE_RULE, json_option


@click.group()
def bench():
    """Benchmarks: speed of the step loop, per backend."""


PLAIN = ("plain numpy", 1)
"""The baseline ``bench speed`` measures beside the backends: a plain vectorised numpy step."""

CASES = {
    "default": "the default scene (Table 2 vertical regime)",
    "bulge": "the default scene with two bulges (a radius that depends on height: per-base radii)",
    "joining": "the default scene growing: half the bases at t = 0, the rest joining at the top",
}


def _case(n: int, case: str) -> dict:
    if case == "bulge":
        bulges = [{"z": 0.25 * n * 0.0005, "half_width": 0.1 * n * 0.0005, "magnitude": 0.01, "G": 0.02},
                  {"z": 0.7 * n * 0.0005, "half_width": 0.1 * n * 0.0005, "magnitude": 0.005}]
        return {"lattice": {"n_bases": n}, "growth": {"name": "bulge", "bulges": bulges},
                "breaker": {"name": "threshold", "regions": {"bulge": 0.004}}}
    if case == "joining":
        return {"lattice": {"n_bases": n, "n_start": n // 2, "join_rate": n / 80.0, "join_every": 1.0}}
    return {"lattice": {"n_bases": n}}


def _phase_sim(n: int, backend: str, start_t: float, case: str = "default", threads: int = 0):
    """``case`` at ``n`` bases on ``backend`` (with ``threads``), stepped as the paper did (fixed
    dt = 0.01, so that a step is the same work whatever the backend), compiled and run up to ``start_t``."""
    from bark.engine.scene import Scene, merge

    run = {"backend": backend, "threads": threads, "dt": 0.01, "stepping": "fixed", "until_time": 1e6}  # the bench stops it
    sim = Scene.from_dict(merge(_case(n, case), {"run": run})).simulation()
    with _kernel_first(backend):  # also compiles the kernels, outside the timing
        sim.run(Stop(until_time=max(start_t, 2 * sim.clock.h)))
    return sim


@contextlib.contextmanager
def _kernel_first(backend: str):
    """The kernel measured is the one asked for: a threaded one compiles in this process before the
    timing, not alongside it (``numba_backend.ALONGSIDE``, as it was after)."""
    if backend != "numba":
        yield
        return
    from bark.engine.kernels import numba_backend as module

    was, module.ALONGSIDE = module.ALONGSIDE, False
    try:
        yield
    finally:
        module.ALONGSIDE = was


class PlainNumpy:
    """The model of the default scene (sqrt growth, Euler–Cromer, threshold breaking, fixed steps) as
    someone would write it in plain vectorised numpy, with no bark code in the step: the baseline
    every speed-up is quoted against.  Written as well as numpy allows: the lattice's springs of one
    offset o join every base i to i + o, so each offset's springs are two shifted views of the
    positions and their forces two shifted in-place adds — no gather, no scatter (``bincount`` or
    a sparse product sum the same forces several times more slowly at 70 000 bases).  Starts from a copy of a
    simulation's state; ``tests`` hold it to bark's results."""

    def __init__(self, sim) -> None:
        s, mech, growth = sim.state, sim.mechanics, sim.growth
        self.x, self.v = np.array(s.x), np.array(s.v)
        self.direction, self.anchor = np.array(s.anchor_dir), np.array(s.anchor)
        self.k, self.c, self.b, self.m = mech.k, mech.c, mech.b, mech.m
        self.r0, self.G, self.t, self.h = growth.r0, growth.G, s.t, sim.clock.h
        self.steps, self.n = 0, len(self.x)
        i, j = s.pairs[:, 0].astype(np.intp), s.pairs[:, 1].astype(np.intp)
        order, self.blocks, start = [], [], 0  # the springs regrouped by offset, each block by its lower base
        for o in np.unique(j - i):
            ids = np.flatnonzero(j - i == o)
            ids = ids[np.argsort(i[ids])]
            if not np.array_equal(i[ids], np.arange(self.n - o)):
                raise ValueError("the plain baseline knows a whole lattice only: a spring (i, i + o) for every base i")
            order.append(ids)
            self.blocks.append((int(o), slice(start, start + ids.size)))
            start += ids.size
        self.order = np.concatenate(order)  # plain's spring k is bark's spring order[k]
        self.rest, self.fmax, self.intact = (np.array(a)[self.order] for a in (s.rest, s.fmax, s.intact))

    def step(self) -> None:
        """One Euler–Cromer step of the whole lattice: spring forces by shifted views, anchors and damping, the
        update, the surface constraint at the grown radius, and the threshold rule on the intact springs."""
        x, v = self.x, self.v
        f = np.zeros_like(x)
        for o, block in self.blocks:
            d = x[o:] - x[:-o]
            length = np.sqrt(np.einsum("ij,ij->i", d, d))
            tension = self.k * (length - self.rest[block])
            g = np.where(self.intact[block] & (length > 0), tension / np.where(length > 0, length, 1.0), 0.0)
            pull = g[:, None] * d
            f[:-o] += pull
            f[o:] -= pull
        f += -self.c * (x - self.anchor) - self.b * v
        v += f * (self.h / self.m)
        x += v * self.h
        self.t += self.h
        r = self.r0 + self.G * np.sqrt(self.t)
        x[:, :2] *= (r / np.hypot(x[:, 0], x[:, 1]))[:, None]
        v[:, :2] -= ((v[:, :2] * x[:, :2]).sum(axis=1) / (r * r))[:, None] * x[:, :2]
        self.anchor[:, :2] = r * self.direction
        for o, block in self.blocks:
            d = x[o:] - x[:-o]
            tension = self.k * (np.sqrt(np.einsum("ij,ij->i", d, d)) - self.rest[block])
            self.intact[block] &= ~(tension > self.fmax[block])
        self.steps += 1

    @property
    def intact_in_bark_order(self) -> np.ndarray:
        """The intact flags in bark's order of springs (this baseline keeps them grouped by offset), to compare
        with a bark run's."""
        out = np.empty_like(self.intact)
        out[self.order] = self.intact
        return out


def _steps_per_second(n: int, backends, start_t: float, steps: int, repeats: int, case: str = "default"
                      ) -> dict[tuple, float]:
    """Median steps/s of the plain numpy baseline (the default case only: it knows no bulges and no
    joining) and each ``(backend, threads)`` over ``repeats`` stretches of ``steps`` steps from ``start_t``.

    The stretches are interleaved (plain, numpy, numba, plain, numpy, numba, ...), so that a change in
    the machine's load falls on all of them alike and the ratios stay honest."""
    sims = {b: _phase_sim(n, b[0], start_t, case, b[1]) for b in backends}
    plain = PlainNumpy(sims[backends[0]]) if case == "default" else None
    rates = {b: [] for b in ((PLAIN,) if plain else ()) + tuple(backends)}
    for _ in range(repeats):
        if plain is not None:
            t0 = time.perf_counter()
            for _ in range(steps):
                plain.step()
            rates[PLAIN].append(steps / (time.perf_counter() - t0))
        for b, sim in sims.items():
            s0, t0 = sim.step_count, time.perf_counter()
            sim.run(Stop(until_time=sim.state.t + steps * sim.clock.h))
            rates[b].append((sim.step_count - s0) / (time.perf_counter() - t0))
    return {b: float(np.median(r)) for b, r in rates.items()}


def _peak_memory(n: int, backend: tuple, start_t: float, steps: int, case: str = "default") -> float:
    """Peak memory (MiB, numpy and Python allocations as traced by tracemalloc) of building the
    simulation with ``(backend, threads)`` and running it through the phase; measured apart from the
    timing, which tracing slows."""
    tracemalloc.start()
    sim = _phase_sim(n, backend[0], start_t, case, backend[1])
    sim.run(Stop(until_time=sim.state.t + steps * sim.clock.h))
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


PHASES = {
    # name: (start time, end time, description) — default scene, vertical regime: first breaks at t ≈ 13
    "quiet": (0.0, 12.0, "t in [0, 12]: no spring over its threshold yet"),
    "cracking": (13.0, 40.0, "t in [13, 40]: springs breaking every few steps"),
}


def _machine() -> dict:
    """The machine a benchmark ran on (absolute times say it; ratios hold across machines)."""
    import os
    import platform

    return {"processor": platform.processor() or platform.machine(), "cores": os.cpu_count(),
            "python": platform.python_version()}


def _emit(table, document: dict, as_json: bool, width: int = 140) -> None:
    """The benchmark's table, or with --json its rows as JSON on stdout, the machine's facts beside them."""
    from rich.console import Console

    if as_json:
        from bark.io.files import json_text

        click.echo(json_text({"machine": _machine(), **document}, indent=2))
    else:
        Console(width=width).print(table)


@bench.command()
@click.option("--n-bases", "sizes", type=click.IntRange(100, 10_000_000), multiple=True, default=(3000, 70000),
              show_default=True, help="Sizes of the default scene to measure (repeatable).")
@click.option("--backend", "backends", type=click.Choice(["numpy", "numba"]), multiple=True,
              default=("numpy", "numba"), show_default=True, help="numpy is always measured: it is the baseline.")
@click.option("--phase", "phases", type=click.Choice(list(PHASES)), multiple=True, default=("quiet", "cracking"),
              show_default=True, help="cracking is measured only up to 10000 bases (reaching it takes long).")
@click.option("--steps", type=click.IntRange(1, 10_000_000), default=None,
              help="Steps per timed stretch (default: about 0.3 s of numpy work, and at least one kernel call's "
                   "steps).")
@click.option("--repeats", type=click.IntRange(1, 1000), default=5, show_default=True,
              help="Timed stretches per backend, interleaved.")
@click.option("--case", "cases", type=click.Choice(list(CASES)), multiple=True, default=("default",), show_default=True,
              help="default: the vertical regime; bulge: with two bulges (per-base radii); joining: bases joining "
                   "at the top during the run.  The plain numpy baseline is measured for the default case.")
@click.option("--threads", "thread_counts", type=click.IntRange(0, 65536), multiple=True, default=(0,), show_default=True,
              help="The numba backend's threads (repeatable: each count is measured; 0: automatic).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), default=None, help="Also write the table as CSV.")
@json_option
def speed(sizes, backends, phases, steps, repeats, cases, thread_counts, csv_path, as_json):
    """Steps per second of the full step (integrate, constrain, tensions, breaking, stop checks) on
    the default scene, per backend (and the numba backend's threads) and phase, with ratios against a
    plain vectorised numpy step of the same model measured in this run, interleaved."""
    from rich.table import Table

    backends = (("numpy", 1), *[(b, t) for b in dict.fromkeys(backends) if b != "numpy" for t in dict.fromkeys(thread_counts)])
    from bark.engine.scene import Scene
    from bark.engine.stepping import call_steps

    for n in sizes:  # every size is a valid scene that fits in memory, before any work
        Scene.from_dict({"lattice": {"n_bases": n}, "run": {"until_time": 1e6}}).memory_estimate()
    rows = []
    for case in cases:
        for n in sizes:
            for phase in phases:
                start_t, end_t, _ = PHASES[phase]
                if phase == "cracking" and n > 10000:
                    continue
                # about 0.3 s of numpy work (~0.13 µs a base-step), and at least one kernel call, so that a call's
                # start and end weigh as in a run (the default lattice has two springs a base)
                k = steps or max(10, int(0.3 / (1.3e-7 * n)), call_steps(n, 2 * n))
                k = min(k, int((end_t - start_t) / 0.01 / repeats))  # stay inside the phase
                rates = _steps_per_second(n, backends, start_t, k, repeats, case)
                peaks = {b: _peak_memory(n, b, start_t, k, case) for b in backends}
                for backend, rate in rates.items():
                    rows.append({
                        "case": case, "n_bases": n, "phase": phase, "backend": backend[0], "threads": backend[1] or "auto",
                        "steps": k * repeats, "steps_per_s": rate,
                        "speed_vs_plain_numpy": rate / rates.get(PLAIN, float("nan")),
                        "speed_vs_numpy_backend": rate / rates[("numpy", 1)],
                        "peak_MiB": peaks.get(backend, float("nan")),
                        "memory_vs_numpy_backend": peaks.get(backend, float("nan")) / peaks[("numpy", 1)],
                    })
    table = Table(*rows[0].keys(), title="bark bench speed — steps per second, interleaved")
    for r in rows:
        table.add_row(*(f"{v:.4g}" if isinstance(v, float) else str(v) for v in r.values()))
    _emit(table, {"rows": rows}, as_json)
    if csv_path:
        from bark.io.files import write_csv

        write_csv(csv_path, rows, list(rows[0]))


def _accuracy_methods(quick: bool, integrators=()):
    """Position and pattern methods to study, of the given integrators (none given: all)."""
    from bark.studies.accuracy import Method

    ec, io = "euler-cromer", "implicit-overdamped"
    position = {Method(ec): [0.16, 0.08, 0.04, 0.02, 0.01], Method(io): [0.16, 0.08, 0.04, 0.02, 0.01]}
    pattern = {
        Method(ec): [0.01, 0.03, 0.1, 0.3],
        Method(ec, "adaptive", 0.3): [0.05, 0.02, 0.01, 0.005, 0.002],
        Method(io): [0.3, 1.0, 3.0],
        Method(io, "adaptive", 3.0): [0.05, 0.01],
    }
    if quick:
        position = {m: v[::2] for m, v in position.items()}
        pattern = {Method(ec): [0.01, 0.1], Method(ec, "adaptive", 0.3): [0.05, 0.01, 0.002],
                   Method(io, "adaptive", 3.0): [0.01]}
    keep = set(integrators) or {ec, io}
    return ({m: v for m, v in position.items() if m.integrator in keep},
            {m: v for m, v in pattern.items() if m.integrator in keep})


@bench.command()
@click.option("--scene", "scene_file", default=None, metavar="SCENE",
              help=f"Scene for the pattern error: the name of one {SCENE_RULE} (default: the default scene, "
                   "vertical regime).")
@click.option("--seeds", type=click.IntRange(2, 100), default=3, show_default=True,
              help="Seeds per setting (0, 1, ...); at least 2, for the seed-to-seed spread.")
@click.option("--until-time", type=click.FloatRange(0, 1e6, min_open=True), default=300.0, show_default=True,
              help="Time each pattern run stops at (time units; 1 = 88.5 days).")
@click.option("--reference-dt", type=click.FloatRange(0, 1, min_open=True), default=0.005, show_default=True,
              help="dt of the fine Euler–Cromer reference (fixed steps; must be below the stability limit).")
@click.option("--quick", is_flag=True, help="A few settings only (the default among them): a look, not a measurement.")
@click.option("--integrator", "integrators", type=click.Choice(["euler-cromer", "implicit-overdamped"]), multiple=True,
              help="Study only these integrators (repeatable; default: both).  The implicit one is slow on large scenes.")
@click.option("--out", type=click.Path(file_okay=False), default="bark-bench-accuracy", show_default=True)
@json_option
def accuracy(scene_file, seeds, until_time, reference_dt, quick, integrators, out, as_json):
    """Work-precision: error against wall time per integrator and stepping mode.

    (a) position error on a small system without breaking, against a Radau reference, with each
    method's fitted convergence order; (b) pattern error with breaking (broken springs, patch count,
    Hellinger distance of orientations) against a fine-dt reference, averaged over seeds, with the
    seed-to-seed spread as the band below which a difference is not an error.  Writes
    accuracy.png, accuracy_position.csv and accuracy_pattern.csv to --out."""
    from rich.console import Console
    from rich.table import Table

    from bark.studies.accuracy import METRICS, SIGNED, pareto_front, pattern_study, position_study
    from bark.io.files import write_csv, write_json
    from bark.engine.scene import RunSettings, read_toml
    from bark_cli.plot import plot_work_precision

    console = Console(width=150, quiet=as_json)  # --json: the results alone on stdout
    scene = read_toml(scene_file) if scene_file else {}
    scene.pop("run", None)  # the study sets dt, stepping, seed and stop itself
    from bark.io.folder import writable_folder
    from bark.engine.scene import Scene, merge
    from bark_cli.options import NAMER, Provenance

    NAMER.set(Provenance(aliases={("run", "dt"): "--reference-dt", ("run", "until_time"): "--until-time",
                                  (None, "out"): "--out"}).name)

    # before any work: the scene, the reference's step (below the stability limit) and the folder
    reference = merge(scene, {"integrator": {"name": "euler-cromer"},
                              "run": {"dt": reference_dt, "stepping": "fixed", "until_time": until_time}})
    Scene.from_dict(reference).simulation().build()
    out = writable_folder(out)
    position_methods, pattern_methods = _accuracy_methods(quick, integrators)
    log = (lambda m: console.print(f"[dim]{m}[/dim]"))

    pos_rows, orders = position_study(position_methods, progress=log)
    pat_rows, spread = pattern_study(pattern_methods, scene=scene, seeds=range(seeds), until_time=until_time,
                                     reference_dt=reference_dt, progress=log)

    defaults = RunSettings()
    default_label = next((r["method"] for r in pat_rows if r["method"].startswith("euler-cromer " + defaults.stepping)), None)
    default_param = defaults.overshoot_tol if defaults.stepping == "adaptive" else defaults.dt
    fronts = {m: pareto_front(pat_rows, m) for m in METRICS}
    # a measure that is NaN (fewer than two patches) for the run and the spread alike cannot tell them apart
    within = [all(r[m] <= spread[m] or (np.isnan(r[m]) and np.isnan(spread[m])) for m in METRICS) for r in pat_rows]

    table = Table("method", "dt / tol", "wall s", "steps", *METRICS, "within spread", "on front",
                  "broken bias (seeds +/−)", "patch bias (seeds +/−)",
                  title=f"(b) pattern error at t = {until_time:g}, mean of {seeds} seeds vs Euler–Cromer dt = {reference_dt:g}")
    for i, r in enumerate(pat_rows):
        on = ",".join(m.split("_")[0] for m in METRICS if i in fronts[m]) or "-"
        table.add_row(r["method"], f"{r['param']:g}", f"{r['wall_s']:.3g}", f"{r['steps']:.0f}",
                      *(f"{r[m]:.3g}" for m in METRICS), "yes" if within[i] else "no", on,
                      *(f"{r[m]:+.3g} ({r[m + '_above']}/{r[m + '_below']})" for m in SIGNED))
    table.add_row("seed-to-seed spread", "", "", "", *(f"{spread[m]:.3g}" for m in METRICS), "", "", "", "")
    console.print(table)
    ptable = Table("method", "dt", "wall s", "steps", "error", "error vs massive model", title="(a) position error, no breaking")
    for r in pos_rows:
        ptable.add_row(r["method"], f"{r['param']:g}", f"{r['wall_s']:.3g}", str(r["steps"]), f"{r['error']:.3g}",
                       f"{r['error_vs_massive_model']:.3g}")
    console.print(ptable)
    console.print("fitted convergence order: " + ", ".join(f"{k}: {v:.3f}" for k, v in orders.items()))

    paper = next((r for r in pat_rows if r["method"] == "euler-cromer fixed" and r["param"] == 0.01), None)
    verdict = {"spread": spread, "orders": orders}
    idx = next((i for i, r in enumerate(pat_rows) if r["method"] == default_label and r["param"] == default_param), None)
    if idx is not None and paper is not None:
        r = pat_rows[idx]
        verdict.update(default=f"{r['method']} {r['param']:g}", default_within_spread=within[idx],
                       default_on_front={m: idx in fronts[m] for m in METRICS},
                       default_speedup_over_paper_dt_0_01=paper["wall_s"] / r["wall_s"])
        console.print(
            f"default ({r['method']}, {'tol' if defaults.stepping == 'adaptive' else 'dt'} {r['param']:g}): "
            f"{'within seed spread on every measure' if within[idx] else 'OUTSIDE seed spread on ' + str([m for m in METRICS if not r[m] <= spread[m]])}, on the front for "
            f"{[m for m in METRICS if idx in fronts[m]] or 'none'}; {paper['wall_s'] / r['wall_s']:.1f}× faster than "
            f"the paper's fixed dt = 0.01 ({paper['wall_s']:.3g} s → {r['wall_s']:.3g} s)"
        )
    write_csv(out / "accuracy_position.csv", pos_rows, list(pos_rows[0]))
    write_csv(out / "accuracy_pattern.csv", [{k: v for k, v in r.items() if not k.endswith("_per_seed")} for r in pat_rows],
              [k for k in pat_rows[0] if not k.endswith("_per_seed")])
    write_json(out / "accuracy_summary.json", verdict)
    plot_work_precision(pos_rows, orders, pat_rows, spread, out / "accuracy.png",
                        highlight=(default_label, default_param), title=f"t = {until_time:g}, {seeds} seeds")
    console.print(f"wrote {out}/accuracy.png, accuracy_position.csv, accuracy_pattern.csv, accuracy_summary.json")
    if as_json:  # the summary and both tables' rows (per seed too), as the CSV files and the JSON hold them
        _emit(None, {"summary": verdict, "position": pos_rows, "pattern": pat_rows}, True)


def _run_words(text: str) -> list[str]:
    """``bark simulate`` arguments for one ``bench scenes`` argument: a scene file, optionally followed
    by options (``"whole-tree.toml --backend numpy --dt 0.01"``), checked as ``simulate`` checks them."""
    import shlex

    from bark_cli.main import scene_of, simulate

    try:
        words = shlex.split(text)
    except ValueError as err:
        raise click.BadParameter(f"{text!r}: {err}", param_hint="SCENES") from None
    if not words or words[0].startswith("-"):
        raise click.BadParameter(f"{text!r}: must start with a scene file", param_hint="SCENES")
    args = ["--scene", words[0], *words[1:]]
    if any(w in ("--out", "--resume", "--overwrite") or w.startswith(("--out=", "--resume=")) for w in words[1:]):
        raise click.BadParameter(f"{text!r}: the benchmark chooses the output folder", param_hint="SCENES")
    scene_of(simulate.make_context("simulate", list(args)).params)  # every run is valid before any runs
    return args


@bench.command()
@click.argument("scenes", nargs=-1, required=True)
@click.option("--repeats", type=click.IntRange(1, 1000), default=3, show_default=True, help="Runs per scene, interleaved; medians.")
@json_option
def scenes(scenes, repeats, as_json):
    """Wall time and peak memory of `bark simulate --scene S` for each scene, as the command runs it
    (a fresh process each time, outputs to a temporary folder), with ratios against the first.  A
    scene may come with options for `bark simulate`, in one argument: compare the whole tree with its
    paper-numerics numpy baseline by `bark bench scenes whole-tree "whole-tree --backend numpy --dt 0.01
    --stepping fixed"`."""
    import subprocess
    import sys
    import tempfile

    from rich.table import Table

    runs = {scene: _run_words(scene) for scene in scenes}
    # the command as `bark` runs it (its entry point: how it starts and leaves included), each run
    # reporting its own peak resident memory as it leaves (RUSAGE_CHILDREN would give the largest so far)
    child = ("import atexit, resource, sys\n"
             "atexit.register(lambda: print('PEAK_KIB', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr))\n"
             "sys.argv = ['bark', *sys.argv[1:]]\n"
             "from bark_cli.__main__ import main\nmain()\n")
    times = {s: [] for s in scenes}
    peaks = {s: [] for s in scenes}
    for _ in range(repeats):
        for scene in scenes:  # interleaved, so that a change in the machine's load falls on all alike
            with tempfile.TemporaryDirectory() as out:
                t0 = time.perf_counter()
                done = subprocess.run([sys.executable, "-c", child, "simulate", *runs[scene], "--out", out, "--quiet"],
                                      capture_output=True, text=True)
                times[scene].append(time.perf_counter() - t0)
                if done.returncode != 0:
                    raise click.ClickException(f"{scene}: {done.stderr.strip().splitlines()[-1]}")
                peaks[scene].append(int(done.stderr.split("PEAK_KIB")[-1].split()[0]))
    base = scenes[0]
    t_base = float(np.median(times[base]))
    p_base = max(peaks[base])
    table = Table("scene", "wall s (median)", "time vs first", "peak RSS MiB", "memory vs first", title="bark bench scenes")
    rows = []
    for scene in scenes:
        t = float(np.median(times[scene]))
        rows.append({"scene": scene, "wall_s": t, "time_vs_first": t / t_base, "peak_MiB": max(peaks[scene]) / 1024,
                     "memory_vs_first": max(peaks[scene]) / p_base, "wall_s_each": times[scene]})
        table.add_row(scene, f"{t:.3g}", f"{t / t_base:.3g}", f"{max(peaks[scene]) / 1024:.0f}",
                      f"{max(peaks[scene]) / p_base:.3g}")
    _emit(table, {"rows": rows}, as_json)


@bench.command("fit")
@click.option("--scene", "scene_name", default="reticulate", show_default=True,
              help="Scene of every run (a shipped scene's name or a TOML file); the observed pattern is one of its runs.")
@click.option("--population", type=click.IntRange(2, 10_000), default=30, show_default=True,
              help="The fit's population: it runs a calibration and one generation, all drawn from the prior.")
@click.option("--workers", type=click.IntRange(1, 256), default=2, show_default=True,
              help="The fit's workers, and the plain processes run at a time.")
@click.option("--repeats", type=click.IntRange(1, 100), default=1, show_default=True,
              help="Measurements of each, interleaved; medians.")
@json_option
def fit_speed(scene_name, population, workers, repeats, as_json):
    """Runs per minute of a fit against plain `bark simulate` processes: a whole `bark fit` process
    (its start-up, its warm workers, runs that write nothing but their statistics), then as many
    `bark simulate` processes of settings drawn from the same prior, each writing what the scene
    asks for: one at a time (a shell loop) and --workers at a time (xargs -P)."""
    import json
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    from rich.table import Table

    from bark.engine.scene import Scene, read_toml
    from bark.studies.fit import DEFAULT_PRIORS as priors  # the settings bark fit draws when told none

    Scene.from_dict(read_toml(scene_name))  # a scene that is not one: one line, before any work
    bark = [sys.executable, "-m", "bark_cli"]

    def command(*args: str) -> None:
        done = subprocess.run([*bark, *args], capture_output=True, text=True)
        if done.returncode != 0:
            raise click.ClickException(f"bark {args[0]}: {(done.stderr.strip().splitlines() or ['failed'])[-1]}")
    lanes = sorted({1, workers})
    rates: dict = {"fit": [], **{lanes_: [] for lanes_ in lanes}}

    def plain(todo: list, at_a_time: int, folder: Path) -> float:
        t0 = time.perf_counter()
        running: list = []
        for k, settings in enumerate(todo):
            while len(running) >= at_a_time:
                running.pop(0).wait()
            running.append(subprocess.Popen([*bark, "simulate", "--scene", scene_name, *settings, "--out",
                                             str(folder / str(k)), "--quiet"], stdout=subprocess.DEVNULL,
                                            stderr=subprocess.DEVNULL))
        for p in running:
            p.wait()
        return 60.0 * len(todo) / (time.perf_counter() - t0)

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        command("simulate", "--scene", scene_name, "--seed", "999", "--out", str(tmp / "observed"), "--quiet")
        runs = 0
        for r in range(repeats):  # interleaved, so that a change in the machine's load falls on all alike
            out = tmp / f"fit-{r}"
            t0 = time.perf_counter()
            command("fit", str(tmp / "observed"), "--scene", scene_name, "--population", str(population), "--generations",
                    "1", "--predictive", "0", "--seed", str(r), "--workers", str(workers), "--out", str(out), "--quiet")
            wall = time.perf_counter() - t0
            runs = population + json.loads((out / "fit.json").read_text())["runs"]  # the calibration, then the generation
            rates["fit"].append(60.0 * runs / wall)
            rng = np.random.default_rng(r)
            todo = [[f"--set=growth.G={rng.uniform(priors[0].low, priors[0].high):.6g}",
                     f"--set=mechanics.f_max={rng.uniform(priors[1].low, priors[1].high):.6g}", f"--seed={k}"]
                    for k in range(runs)]
            for at_a_time in lanes:
                rates[at_a_time].append(plain(todo, at_a_time, tmp / f"plain-{r}-{at_a_time}"))
    fit = float(np.median(rates["fit"]))
    table = Table("", "runs per minute (median)", "fit vs this",
                  title=f"bark bench fit: {scene_name}, {runs} runs, {repeats} measurement{'s' if repeats > 1 else ''}")
    rows = []
    for at_a_time in lanes:
        p = float(np.median(rates[at_a_time]))
        rows.append({"what": f"plain bark simulate, {at_a_time} at a time", "runs_per_min": p, "fit_vs_this": fit / p,
                     "runs_per_min_each": rates[at_a_time]})
        table.add_row(f"plain `bark simulate` processes, {at_a_time} at a time", f"{p:.0f}", f"{fit / p:.2f}")
    rows.append({"what": f"bark fit, {workers} workers", "runs_per_min": fit, "fit_vs_this": 1.0,
                 "runs_per_min_each": rates["fit"]})
    table.add_row(f"`bark fit`, {workers} worker{'s' if workers > 1 else ''} (whole process)", f"{fit:.0f}", "1")
    _emit(table, {"scene": scene_name, "runs": runs, "rows": rows}, as_json, width=120)
