"""What accuracy costs in time: the measurements behind ``bark bench accuracy``.

Two error measures, as the work-precision diagrams of the ODE world draw them (error against wall
time, one line per integrator and stepping mode, one point per dt or tolerance):

(a) **Position error, no breaking.**  A small lattice (bases displaced from their rest sites, no
    growth, nothing breaks) is integrated to ``T``; the error is the largest distance of any base
    from a Radau reference (``bark.analysis.reference``) of the same model at rtol 1e-10.  Each method is
    measured against its own equations (Euler–Cromer against the paper's massive model, the
    implicit overdamped method against the massless limit) and the convergence order is fitted;
    the distance of each from the paper's massive model is recorded as well.
(b) **Pattern error, with breaking.**  A scene (default: Table 2's vertical regime, 3000 bases) is
    run to a fixed time for several seeds; each run is compared with a fine-dt Euler–Cromer
    reference of the same seed: relative difference in broken springs, difference in patch count,
    and the Hellinger distance (paper, eq. 12) between the orientation distributions.  The same
    three measures between *different seeds* of the reference are the seed-to-seed spread: a
    difference below it is not an error.  The first two are also reported signed (run minus
    reference, :data:`SIGNED`), with the number of seeds on each side: a difference within the spread
    that has the same sign on every seed is a bias, which the unsigned measures hide.

Nothing here prints or plots; the command line does.
"""

from __future__ import annotations

import itertools
import time
from typing import Callable, Iterable

import attrs
import numpy as np

from bark.analysis.circular import orientation_hellinger
from bark.analysis.patches import patch_statistics
from bark.model.lattice import Lattice
from bark.contract import registry
from bark.engine.scene import DEFAULT_STRATEGIES, Scene, merge
from bark.engine.simulation import Simulation, Stop
from bark.engine.stepping import Numerics

__all__ = ["METRICS", "SIGNED", "Method", "position_study", "pattern_study", "spread", "pareto_front", "fit_order"]


@attrs.frozen
class Method:
    """An integrator and a stepping mode; ``param`` is what varies along its line (dt or tolerance)."""

    integrator: str
    stepping: str = "fixed"
    dt: float | None = None
    """For adaptive stepping: the largest step (the line varies the tolerance)."""

    @property
    def label(self) -> str:
        """How the method is named in tables and figures, e.g. ``euler-cromer adaptive (dt ≤ 0.5)``."""
        return f"{self.integrator} {self.stepping}" + (f" (dt ≤ {self.dt:g})" if self.stepping == "adaptive" else "")

    def run_settings(self, param: float) -> dict:
        """The numerics of a run at the method's accuracy setting ``param``: the overshoot tolerance for adaptive
        stepping, the step for fixed stepping."""
        if self.stepping == "adaptive":
            return {"dt": self.dt, "stepping": "adaptive", "overshoot_tol": param}
        return {"dt": param, "stepping": self.stepping}


def fit_order(params: Iterable[float], errors: Iterable[float]) -> float:
    """Slope of log(error) against log(param): the observed order of convergence."""
    return float(np.polyfit(np.log(list(params)), np.log(list(errors)), 1)[0])


# -- (a) position error -------------------------------------------------------------------------


def _displaced(integrator: str, dt: float, n_bases: int, seed: int, backend: str) -> Simulation:
    scene = Scene.from_dict({})  # the default scene's laws, the trunk held still and no spring breaking
    sim = Simulation(
        lattice=Lattice(n_bases=n_bases, jitter=0.05),
        growth=attrs.evolve(scene.strategies["growth"], G=0.0),
        integrator=registry.create("integrator", integrator),
        breakers=[scene.strategies["breaker"]],
        mechanics=attrs.evolve(scene.mechanics, f_max=1e9),
        numerics=Numerics(dt=dt, stepping="fixed", backend=backend),
        seed=seed,
    )
    rng = np.random.default_rng(seed + 1)
    s = sim.state
    r = float(np.hypot(s.x[0, 0], s.x[0, 1]))
    theta = np.arctan2(s.x[:, 1], s.x[:, 0]) + rng.normal(scale=0.1 * sim.lattice.spacing(r) / r, size=s.n_bases)
    z = s.x[:, 2] + rng.normal(scale=0.1 * sim.lattice.spacing(r), size=s.n_bases)
    with s.writing("x"):  # a declared write: the backends take it as the run's start
        s.x[:] = np.column_stack([r * np.cos(theta), r * np.sin(theta), z])
    return sim


def position_study(
    methods: dict[Method, list[float]], t_end: float = 4.0, n_bases: int = 400, seed: int = 3, backend: str = "auto",
    repeats: int = 3, progress: Callable[[str], None] | None = None,
) -> tuple[list[dict], dict[str, float]]:
    """Rows ``(method, param, steps, wall_s, error, error_vs_massive_model)`` and the fitted order
    of each method.  ``methods`` maps each (fixed-step) method to its list of dt; wall time is the
    best of ``repeats`` runs, after one untimed run that compiles what it needs."""
    from bark.analysis.reference import solve_reference

    refs = {}
    rows, orders = [], {}
    for method, dts in methods.items():
        overdamped = registry.load("integrator", method.integrator).overdamped
        for model in {overdamped, False}:
            if model not in refs:
                sim = _displaced(method.integrator, dts[0], n_bases, seed, backend)
                refs[model] = solve_reference(sim.state, sim.forces, sim.radius, t_end, overdamped=model)
        errors = []
        for dt in dts:
            _displaced(method.integrator, dt, n_bases, seed, backend).run(Stop(until_time=4 * dt))  # compile
            walls = []
            for _ in range(repeats):
                sim = _displaced(method.integrator, dt, n_bases, seed, backend)
                t0 = time.perf_counter()
                sim.run(Stop(until_time=t_end))
                walls.append(time.perf_counter() - t0)
            wall = min(walls)
            err = float(np.abs(sim.state.x - refs[overdamped]).max())
            errors.append(err)
            rows.append({
                "method": method.label, "param": dt, "steps": sim.step_count, "wall_s": wall, "error": err,
                "error_vs_massive_model": float(np.abs(sim.state.x - refs[False]).max()),
            })
            if progress:
                progress(f"(a) {method.label} dt={dt:g}: error {err:.3g}")
        orders[method.label] = fit_order(dts, errors)
    return rows, orders


# -- (b) pattern error ------------------------------------------------------------------------


def _pattern_run(scene: dict, settings: dict, integrator: str, seed: int, until_time: float) -> dict:
    """One run of ``scene`` with these numerics, through the library runner, in memory."""
    from bark.studies import runner

    data = merge(scene, {"integrator": {"name": integrator}, "run": {**settings, "seed": seed, "until_time": until_time}})
    sc = Scene.from_dict(data)
    outcome = runner.run(sc)
    sim = outcome.sim
    rows = patch_statistics(sim.state.x, sim.patch_labels(), sc.run.min_patch_size)
    return {
        "wall_s": outcome.summary["wall_time_s"], "steps": sim.step_count, "t": sim.state.t, "n_broken": sim.n_broken,
        "n_patches": len(rows), "orientations": np.array([r["orientation_deg"] for r in rows]),
    }


def _distance(a: dict, b: dict) -> dict:
    both = len(a["orientations"]) >= 2 and len(b["orientations"]) >= 2
    broken, patches = (a["n_broken"] - b["n_broken"]) / max(b["n_broken"], 1), a["n_patches"] - b["n_patches"]
    return {
        "broken_rel_diff": abs(broken), "patch_count_diff": abs(patches),
        "hellinger": orientation_hellinger(a["orientations"], b["orientations"]) if both else float("nan"),
        "broken_rel_bias": broken, "patch_count_bias": patches,
    }


METRICS = ("broken_rel_diff", "patch_count_diff", "hellinger")
"""The unsigned errors: what the seed-to-seed spread bounds and the Pareto fronts are drawn on."""
SIGNED = ("broken_rel_bias", "patch_count_bias")
"""The signed errors (run minus reference; broken springs relative to the reference's)."""


def spread(reference: dict[int, dict]) -> dict[str, float]:
    """Mean of each metric over all pairs of different seeds of the reference."""
    pairs = [_distance(reference[a], reference[b]) for a, b in itertools.combinations(sorted(reference), 2)]
    return {m: _mean_of_defined([p[m] for p in pairs]) for m in METRICS}


def _mean_of_defined(values) -> float:
    """Mean of the values that are defined (a Hellinger distance needs two patches on each side), NaN
    when none is — without numpy's warning about an empty slice."""
    values = np.asarray(values, dtype=float)
    values = values[~np.isnan(values)]
    return float(values.mean()) if values.size else float("nan")


def pattern_study(
    methods: dict[Method, list[float]], scene: dict | None = None, seeds: Iterable[int] = (0, 1, 2),
    until_time: float = 300.0, reference_dt: float = 0.005, progress: Callable[[str], None] | None = None,
) -> tuple[list[dict], dict[str, float]]:
    """Rows per (method, param): mean wall time and mean of each error over seeds (plus per-seed
    values), and the seed-to-seed spread of the reference.  ``scene`` defaults to the default scene."""
    scene = scene or {}
    seeds = list(seeds)
    reference = {}
    for seed in seeds:
        reference[seed] = _pattern_run(scene, {"dt": reference_dt, "stepping": "fixed"}, DEFAULT_STRATEGIES["integrator"], seed,
                                       until_time)
        if progress:
            progress(f"(b) reference seed {seed}: {reference[seed]['n_patches']} patches, {reference[seed]['wall_s']:.1f} s")
    rows = []
    for method, params in methods.items():
        for param in params:
            runs = [_pattern_run(scene, method.run_settings(param), method.integrator, seed, until_time) for seed in seeds]
            dist = [_distance(r, reference[seed]) for r, seed in zip(runs, seeds)]
            row = {"method": method.label, "param": param, "wall_s": float(np.mean([r["wall_s"] for r in runs])),
                   "steps": float(np.mean([r["steps"] for r in runs]))}
            for m in METRICS + SIGNED:
                row[m] = _mean_of_defined([d[m] for d in dist])
                row[m + "_per_seed"] = [d[m] for d in dist]
            for m in SIGNED:  # how many seeds lie above and below the reference: all on one side is a bias
                row[m + "_above"] = sum(d[m] > 0 for d in dist)
                row[m + "_below"] = sum(d[m] < 0 for d in dist)
            rows.append(row)
            if progress:
                progress(f"(b) {method.label} {param:g}: " + ", ".join(f"{m} {row[m]:.3g}" for m in METRICS))
    return rows, spread(reference)


def pareto_front(rows: list[dict], error: str) -> set[int]:
    """Indices of rows not dominated in (wall_s, ``error``): nothing is both faster and more accurate."""
    front = set()
    for i, r in enumerate(rows):
        if not any(
            o["wall_s"] <= r["wall_s"] and o[error] <= r[error] and (o["wall_s"] < r["wall_s"] or o[error] < r[error])
            for o in rows
        ):
            front.add(i)
    return front
