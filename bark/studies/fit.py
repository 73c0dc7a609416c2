"""Calibration: which scene settings could have grown an observed bark, and how sure we can be.

    from bark.studies.fit import Fit, Observed, Prior, run_fit
    fit = Fit(observed=Observed.read("examples/paper/observed-reticulate.toml", mirror=True),
              base=read_toml("reticulate"),
              priors=(Prior("growth.G", 0.006, 0.016), Prior("mechanics.f_max", 0.002, 0.01)))
    result = run_fit(fit, "fit.db", workers=2)          # or client=distributed.Client(address)
    result.posterior()                                  # the last generation: settings and weights

**The method** is approximate Bayesian computation by sequential Monte Carlo (ABC-SMC; Toni et al.
2009, Beaumont et al. 2009), as pyabc implements it (Schälte et al. 2022): a population of settings
drawn from the priors is run, and each generation keeps the runs whose pattern statistics lie within
ε of the observed ones, ε shrinking from generation to generation (the median of the last
generation's distances), new settings proposed by a Gaussian kernel around the last generation's
(covariance from its weighted sample).  The distance is the L1 distance between the statistics
(:data:`STATISTICS`), each divided by its median absolute deviation over the last generation's runs
(Prangle 2017), so that degrees and anisotropies weigh alike.

**Deterministic**: the k-th run of generation t draws its settings and its simulation's seed from a
generator seeded by ``(seed, t, k)``, whichever process runs it; a generation takes the first
``population`` accepted runs in the order of k, all runs before them evaluated.  Local workers and a
Dask cluster therefore give the same posterior, to the bit, for the same seed.

**Resumable**: every generation is stored in pyabc's database (SQLite, ``fit.db``) when it ends, and
each generation starts from what the database holds (a fresh ``pyabc.ABCSMC`` loading it), so that a
fit killed in the middle of a generation and run again redoes only that generation, with the same
draws, and ends with the posterior an uninterrupted fit gives.  The fit's settings are kept in the
same file (table ``bark_fit``): a database of other settings is refused, not continued.

**What a run costs**: a fit's run builds its scene and runs it in memory, and measures only the
statistics the fit compares (the crack network only where a network statistic is fitted); it writes
nothing.  Workers are started once for the whole fit and stay warm, and run bark only: pyabc's code for
each run (its proposal, distance and acceptance) runs in this process, a thread per run in flight
taking turns (:class:`_Turns`), so a worker never imports pyabc.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import random
import sqlite3
import threading
from concurrent.futures import Future
from pathlib import Path
from typing import Any, Callable, Iterable

import attrs
import numpy as np

from bark.errors import BarkError
from bark.studies.pool import DaskPool, LocalPool, WorkerDied

__all__ = ["STATISTICS", "DEFAULT_PRIORS", "Prior", "Observed", "Fit", "FitResult", "Generation", "run_fit", "load_fit",
           "simulate_statistics", "predictive", "needs_pyabc"]

STATISTICS = {
    "orientation": "the patches' mean orientation (axial mean, degrees from horizontal; compared as the cosine and "
                   "sine of twice the angle, so that 1° and 179° are near)",
    "sd": "the circular standard deviation of the patches' orientations (degrees)",
    "anisotropy": "the patches' mean anisotropy (2A − 1)",
    "size_mean": "the mean patch size (bases)",
    "n_bar": "the mean number of junctions a patch touches",
    "v_bar": "the mean number of patches at a junction",
    "t_fraction": "the share of junctions of three patches that are T-junctions",
    "nematic_order": "the nematic order of the crack pieces",
}
"""The statistics a fit compares, by name (docs/patterns.md: Pattern statistics beyond the paper defines the
last five).  A fit compares those the observed pattern has, or those asked for."""
PATTERN_STATISTICS = ("orientation", "sd", "anisotropy")
NETWORK_STATISTICS = ("n_bar", "v_bar", "t_fraction", "nematic_order")
DEFAULT_POPULATION = 100
DEFAULT_GENERATIONS = 5
CREDIBLE = 0.90
"""The credible intervals reported: central, 5 % to 95 % of the posterior's weight."""


@attrs.frozen
class Prior:
    """A fitted setting (``section.name``, as ``--set`` takes it) and its prior: uniform on
    ``[low, high]``, or uniform in the logarithm (``log``)."""

    key: str
    low: float = attrs.field(converter=float)
    high: float = attrs.field(converter=float)
    log: bool = False

    def __attrs_post_init__(self) -> None:
        section, dot, name = self.key.partition(".")
        if not dot or not section or not name:
            raise BarkError(f"prior {self.key!r}: expected SECTION.KEY, e.g. growth.G")
        if self.key == "run.seed":
            raise BarkError("prior run.seed: the seed is not a setting to fit; each run draws its own")
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise BarkError(f"prior {self.key}: needs finite LOW < HIGH, given {self.low:g}:{self.high:g}")
        if self.log and self.low <= 0:
            raise BarkError(f"prior {self.key}: a log-uniform prior needs LOW > 0, given {self.low:g}")

    def rv(self):
        """The prior as pyabc's random variable (scipy.stats ``uniform`` or ``loguniform``)."""
        pyabc = needs_pyabc()
        return pyabc.RV("loguniform", self.low, self.high) if self.log else pyabc.RV("uniform", self.low, self.high - self.low)

    def as_dict(self) -> dict:
        """The prior as plain data (key, bounds, whether uniform in the logarithm), for fit.json."""
        return {"key": self.key, "low": self.low, "high": self.high, "log": self.log}

    def scaled(self, values):
        """``values`` of the setting over the prior's range, 0 to 1, in the logarithm for a log-uniform
        prior: the scale a density estimate (KDE) of the posterior is made in."""
        v = np.asarray(values, dtype=float)
        if self.log:
            return (np.log(v) - math.log(self.low)) / (math.log(self.high) - math.log(self.low))
        return (v - self.low) / (self.high - self.low)


DEFAULT_PRIORS = (Prior("growth.G", 0.005, 0.016), Prior("mechanics.f_max", 0.002, 0.01))
"""The priors of a fit that names none: the growth rate and the breaking force, each uniform over a
range that holds Table 2's three regimes with a margin."""


def needs_pyabc(load: bool = True):
    """pyabc, or one line saying how to install it (``bark fit`` needs it; bark does not otherwise).
    ``load=False``: only whether it is installed, found without importing it (seconds: SQLAlchemy,
    pandas), so that a fit's settings are checked before that cost."""
    import importlib.util

    message = "bark fit needs pyabc: pip install 'bark-grasstree[fit]' (or pip install pyabc)"
    if not load:
        if importlib.util.find_spec("pyabc") is None:
            raise BarkError(message)
        return None
    try:
        import pyabc
    except ImportError:
        raise BarkError(message) from None
    return pyabc


def _finite(value) -> float | None:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) else None


def measured(stats, network: dict | None) -> dict[str, float | None]:
    """The fit's statistics (:data:`STATISTICS`) of a pattern: its ``PatternStatistics`` and its
    statistics beyond the paper's (``None`` where it has none); a statistic it lacks is ``None``."""
    a = stats.anisotropy
    out = {"orientation": _finite(stats.orientation.mean_deg), "sd": _finite(stats.orientation.sd_deg),
           "anisotropy": None if a is None else _finite(a.mean)}
    for name in ("size_mean", *NETWORK_STATISTICS):
        out[name] = _finite((network or {}).get(name))
    return out


def compared(values: dict[str, float | None], names: Iterable[str]) -> dict[str, float]:
    """What the distance compares of ``values``: each statistic of ``names`` as a number (NaN where
    missing), the orientation as the cosine and sine of twice its angle (axial: 0° and 180° alike)."""
    out = {}
    for name in names:
        v = values.get(name)
        v = math.nan if v is None else float(v)
        if name == "orientation":
            out["orientation_cos2"], out["orientation_sin2"] = math.cos(math.radians(2 * v)), math.sin(math.radians(2 * v))
        else:
            out[name] = v
    return out


@attrs.frozen
class Observed:
    """The pattern a fit is to reproduce: its name, where it comes from, and its statistics (those
    it has: a published summary has only the orientation's mean and SD)."""

    name: str
    values: dict = attrs.field(converter=dict)
    source: str = ""

    @classmethod
    def read(cls, path: str | Path, min_size: int | None = None, mirror: bool = False) -> "Observed":
        """The pattern at ``path``, anything ``bark compare`` accepts (``bark.analysis.pattern.read``);
        ``mirror``: seen in a mirror held along the trunk (orientation o → 180° − o)."""
        from bark.analysis.network import of_pattern
        from bark.analysis.pattern import read

        stats = read(path, min_size)
        network = None if stats.patches is None else of_pattern(path, stats.patches.size, min_size, law=False)
        if mirror:
            stats = stats.mirrored()
        return cls(name=stats.name or Path(path).name, values=measured(stats, network), source=stats.source or str(path))

    def available(self) -> tuple[str, ...]:
        """The statistics the observed pattern has a value for, in ``STATISTICS`` order."""
        return tuple(k for k in STATISTICS if self.values.get(k) is not None)


def _canonical(obj) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


@attrs.frozen
class Fit:
    """A calibration: the ``observed`` pattern, the scene every run starts from (``base``, a scene
    dict as ``read_toml`` gives it), the fitted settings' ``priors``, the ``statistics`` compared
    (default: every one the observed pattern has), the population of each generation, the number of
    generations, the smallest acceptance rate worth another generation, and the seed."""

    observed: Observed
    base: dict
    priors: tuple[Prior, ...] = attrs.field(converter=tuple)
    statistics: tuple[str, ...] = attrs.field(default=(), converter=tuple)
    population: int = DEFAULT_POPULATION
    generations: int = DEFAULT_GENERATIONS
    min_acceptance: float = 0.0
    seed: int = 0

    def __attrs_post_init__(self) -> None:
        keys = [p.key for p in self.priors]
        if not keys:
            raise BarkError("fit: give at least one prior (--prior SECTION.KEY=LOW:HIGH)")
        if len(set(keys)) != len(keys):
            raise BarkError(f"fit: a prior is given twice ({', '.join(keys)})")
        unknown = [s for s in self.statistics if s not in STATISTICS]
        if unknown:
            raise BarkError(f"fit: no statistic {unknown[0]!r}; the statistics are {', '.join(STATISTICS)}")
        missing = [s for s in self.compared if self.observed.values.get(s) is None]
        if missing:
            raise BarkError(f"fit: the observed pattern {self.observed.name!r} has no {', '.join(missing)} "
                            f"(it has {', '.join(self.observed.available()) or 'none of the statistics'})")
        if not self.compared:
            raise BarkError(f"fit: the observed pattern {self.observed.name!r} has none of the statistics a fit compares")
        if not (isinstance(self.population, int) and 2 <= self.population <= 100_000):
            raise BarkError(f"fit: the population must be a whole number in [2, 100000], given {self.population!r}")
        if not (isinstance(self.generations, int) and 1 <= self.generations <= 1000):
            raise BarkError(f"fit: the generations must be a whole number in [1, 1000], given {self.generations!r}")
        if not (isinstance(self.min_acceptance, (int, float)) and 0.0 <= self.min_acceptance < 1.0):
            raise BarkError(f"fit: the smallest acceptance rate must be in [0, 1), given {self.min_acceptance!r}")
        if not (isinstance(self.seed, int) and 0 <= self.seed < 2**63):
            raise BarkError(f"fit: the seed must be a whole number in [0, 2^63), given {self.seed!r}")

    @property
    def compared(self) -> tuple[str, ...]:
        """The statistics compared: those asked for, else every one the observed pattern has."""
        return self.statistics or self.observed.available()

    @property
    def keys(self) -> tuple[str, ...]:
        """The fitted scene keys, in the priors' order."""
        return tuple(p.key for p in self.priors)

    def scene(self, settings: dict, seed: int) -> dict:
        """The scene of one run: the base with ``settings`` (``section.name`` → value) and ``seed``."""
        from bark.engine.scene import merge

        layer: dict = {}
        for key, value in settings.items():
            section, _, name = key.partition(".")
            layer.setdefault(section, {})[name] = float(value)
        return merge(merge(self.base, layer), {"run": {"seed": int(seed)}})

    def check(self, workers: int | None = None) -> None:
        """Every corner of the priors makes a valid scene (one line for a bad key or range, before
        any run); with ``workers`` (local processes), that many runs at once fit in this machine's memory."""
        import itertools

        from bark.engine.scene import Scene

        for corner in itertools.product(*((p.low, p.high) for p in self.priors)):
            scene = Scene.from_dict(self.scene(dict(zip(self.keys, corner)), 0))
            if workers is not None:
                scene.check_memory(runs=workers)

    def settings(self) -> dict:
        """What identifies the fit (kept in its database): a database of other settings is not continued."""
        return {"observed": {"name": self.observed.name, "values": self.observed.values}, "base": self.base,
                "priors": [p.as_dict() for p in self.priors], "statistics": list(self.compared),
                "population": self.population, "seed": self.seed}

    def model(self) -> "RunModel":
        """The model pyabc samples: one run of the scene at a drawn setting, giving its statistics."""
        return RunModel(fit=self)


def simulate_statistics(scene: dict, names: Iterable[str]) -> dict[str, float | None]:
    """Run ``scene`` in memory and measure the statistics of ``names`` (:data:`STATISTICS`), nothing
    more: the crack network only where a network statistic is asked for, and no patch-size law.  A run whose state went
    non-finite, or that made no patch, has no statistics (``None``): the fit rejects it."""
    from bark.analysis.network import measure
    from bark.analysis.pattern import Pattern
    from bark.engine.scene import Scene
    from bark.errors import NonFiniteStateError

    names = tuple(names)
    sc = Scene.from_dict(scene)
    sim, stop = sc.simulation(), sc.stop()
    sim.prepare(stop)
    try:
        sim.run(stop)
    except NonFiniteStateError:
        return dict.fromkeys(names)
    s, min_size = sim.state, sc.run.min_patch_size
    labels = sim.patch_labels()
    stats = Pattern(points=s.x, patches=labels).statistics(min_size)
    network = None
    if stats.patches is not None and any(n in names for n in ("size_mean", *NETWORK_STATISTICS)):
        springs = (s.pairs, s.intact, tuple(sim.lattice.offsets)) if any(n in names for n in NETWORK_STATISTICS) else ()
        network = measure(s.x, labels, min_size, *springs, law=False)  # a fit compares no size law
    values = measured(stats, network)
    return {n: values[n] for n in names}


@attrs.frozen
class RunModel:
    """pyabc's model: one run of the fit's scene at the proposed settings, its seed drawn from the
    generator the sampler seeded for this run; returns what the distance compares.  In a sampler's
    thread the run itself goes to the fit's workers (:class:`_Turns`); else it runs here."""

    fit: Fit

    def __call__(self, parameters) -> dict:
        seed = int(np.random.randint(0, 2**31 - 1))
        settings = {k: float(parameters[k]) for k in self.fit.keys}
        scene, names = self.fit.scene(settings, seed), self.fit.compared
        away = getattr(_AWAY, "turns", None)
        return compared(away.run(scene, names) if away is not None else simulate_statistics(scene, names), names)


def warm_worker(base: dict) -> None:
    """A fit's worker made ready while the fit starts: the ``base`` scene built for its stop — the
    backend a run takes chosen as for a run — and one step of it taken in memory and its patches
    labelled, which loads (or compiles) the compiled code its runs take: a prior's settings change a
    scene's numbers, not its parts.  A worker runs bark's runs only (pyabc stays in the fit's
    process), so it imports no pyabc."""
    from bark.analysis.pattern import Pattern  # noqa: F401  (what measures each run)
    from bark.engine.scene import Scene

    scene = Scene.from_dict(base)
    sim, stop = scene.simulation(), scene.stop()
    sim.prepare(stop)
    sim.advance(stop, most=1)
    sim.patch_labels()


def run_away(scene: dict, names: tuple[str, ...]) -> dict[str, float | None]:
    """In a worker (local or Dask): one run of a fit, :func:`simulate_statistics`, its kernels'
    compile shared with the worker's other runs."""
    from bark.engine import kernels

    kernels.expect_many()  # a worker's runs (local or Dask) share its kernels' compile
    return simulate_statistics(scene, names)


_AWAY = threading.local()
"""In a sampler's thread: ``turns``, the :class:`_Turns` its run goes through (else none: runs here)."""


class _Abandoned(Exception):
    """A run of a generation that has ended: its thread leaves pyabc's code without going on."""


class _Turns:
    """The runs of one generation, each in a thread of the fit's process, taking turns.

    pyabc's code for a run (its proposal, its distance, its acceptance) draws from numpy's legacy
    global generator, seeded by ``(seed, t, k)`` for run k (and Python's ``random`` with it, for
    whatever else a run's code draws); so at most one thread runs it at a time (``lock``), and a
    thread gives its turn up only while its run is away on a worker, its generators' states kept
    and put back when it takes its turn again: each run draws what it would draw alone, in whatever
    order the runs end.  Once the generation has ended (``close``, which then takes the turn itself,
    so that no thread is in pyabc's code after it) a thread whose run comes back leaves without
    going on, and the generators are as the fit's own code left them before the generation (which
    draws from them as it would with the runs in other processes)."""

    def __init__(self, pool, seed: int, t: int) -> None:
        self.pool, self.seed, self.t = pool, seed, t
        self.lock = threading.Lock()
        self.ended = False
        self.away: set = set()  # the runs' futures on the pool, while they are away
        self.callers = np.random.get_state(), random.getstate()  # the fit's own, put back by ``close``

    def one(self, simulate_one: Callable, k: int):
        """Run k of the generation: pyabc's ``simulate_one`` with the generators seeded by ``(seed, t, k)``."""
        with self.lock:
            if self.ended:
                raise _Abandoned
            state = np.random.SeedSequence([self.seed, self.t + 1, k]).generate_state(4)
            np.random.seed(state)
            random.seed(int(state[0]))
            _AWAY.turns = self
            try:
                return simulate_one()
            finally:
                _AWAY.turns = None

    def run(self, scene: dict, names: tuple[str, ...]) -> dict[str, float | None]:
        """The run of the calling thread's turn, on the pool, its turn given up while it is away."""
        kept = np.random.get_state(), random.getstate()
        future = self.pool.submit(run_away, scene, names)
        self.away.add(future)
        self.lock.release()
        try:
            return future.result()
        finally:
            self.lock.acquire()
            self.away.discard(future)
            if self.ended:
                raise _Abandoned  # noqa: B012 (the generation has ended: whatever came back is not wanted)
            np.random.set_state(kept[0])
            random.setstate(kept[1])

    def close(self) -> None:
        """The generation has ended: no thread goes on in pyabc's code (one in it now ends its
        part first), the generators are the caller's again, and the runs still waiting or away
        are cancelled where they can be (a run a worker has begun ends there, unread)."""
        self.ended = True  # first: a thread that comes back while this waits for its turn leaves
        with self.lock:
            np.random.set_state(self.callers[0])
            random.setstate(self.callers[1])
            away = list(self.away)
        for future in away:
            future.cancel()


def _in_thread(fn: Callable, *args) -> Future:
    """``fn(*args)`` in a daemon thread of its own; a future of its result.  Not an executor's
    thread: one left waiting on a run that never comes back (a cluster gone) must not hold the
    interpreter at its exit, where an executor joins its threads."""
    future: Future = Future()

    def body() -> None:
        future.set_running_or_notify_cancel()
        try:
            future.set_result(fn(*args))
        except BaseException as err:  # noqa: BLE001 (the future's to report)
            future.set_exception(err)

    threading.Thread(target=body, name="bark-fit-run", daemon=True).start()
    return future


@functools.cache
def _sampler_class():
    """The sampler (a subclass of pyabc's ``Sampler``, made when pyabc is first needed)."""
    class SeededSampler(needs_pyabc().sampler.Sampler):
        """Runs of a generation numbered k = 0, 1, ..., each seeded by ``(seed, t, k)``, pyabc's code
        for each run in a thread of this process (:class:`_Turns`), its simulation on ``pool``; the
        generation is the first ``n`` accepted runs in the order of k, with every run before the
        n-th accepted one (those rejected too: the distance's scales use them)."""

        def __init__(self, pool, seed: int, observe: Callable | None = None) -> None:
            super().__init__()
            self.pool, self.seed, self.observe = pool, seed, observe

        def sample_until_n_accepted(self, n, simulate_one, t, *, max_eval=np.inf, all_accepted=False, ana_vars=None):
            from concurrent.futures import FIRST_COMPLETED, wait

            turns = _Turns(self.pool, self.seed, t)
            results: dict[int, Any] = {}
            running: dict = {}  # future → its run's k
            next_id, accepted_ids = 0, []
            try:
                while True:
                    nth = accepted_ids[n - 1] if len(accepted_ids) >= n else None
                    if nth is not None and all(k in results for k in range(nth)):
                        break
                    while nth is None and len(running) < 2 * self.pool.slots:
                        running[_in_thread(turns.one, simulate_one, next_id)] = next_id
                        next_id += 1
                    if nth is not None:  # runs after the n-th accepted one are not needed (``close`` drops them)
                        for f in [f for f, k in running.items() if k > nth]:
                            del running[f]
                    for f in wait(running, return_when=FIRST_COMPLETED).done:
                        k = running.pop(f)
                        results[k] = particle = f.result()
                        if particle.accepted:
                            accepted_ids.append(k)
                        accepted_ids.sort()
                    if self.observe is not None:
                        self.observe(t, min(len(accepted_ids), n), n, len(results))
            except Exception as err:
                if self.pool.died(err):
                    raise WorkerDied("a fit worker died (killed, or out of memory): the generations finished before "
                                     "are in the database; the same fit run again goes on from there") from None
                raise
            finally:
                turns.close()
            sample = self._create_empty_sample()
            last = accepted_ids[n - 1]
            for k in range(last + 1):
                sample.append(results[k])
            self.nr_evaluations_ = last + 1
            return sample

    return SeededSampler


# -- the fit ---------------------------------------------------------------------------------------

@attrs.frozen
class Generation:
    """One generation of a fit: its index, its ε, the runs it took and accepted, its effective
    sample size."""

    t: int
    epsilon: float
    runs: int
    accepted: int
    ess: float

    @property
    def acceptance(self) -> float:
        """The share of runs accepted in this generation (NaN before any run)."""
        return self.accepted / self.runs if self.runs else math.nan


@attrs.define
class FitResult:
    """A fit's database, read: its generations and its posterior."""

    fit: Fit
    database: Path
    generations: list[Generation]
    ran: int = 0
    """Generations run by this call (the others were in the database)."""
    stop_reason: str = ""
    _read: dict = attrs.field(factory=dict, init=False, repr=False, eq=False)
    """Populations read from the database, by generation (the last generation: by its count)."""

    def posterior(self, t: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The population of generation ``t`` (default: the last): settings (one column per prior,
        in the priors' order) and normalised weights; read from the database once."""
        at = len(self.generations) - 1 if t is None else t
        if at not in self._read:
            frame, w = _history(self.database).get_distribution(m=0, t=at)
            self._read[at] = (frame[list(self.fit.keys)].to_numpy(dtype=float), np.asarray(w, dtype=float) / np.sum(w))
        return self._read[at]

    def estimates(self) -> dict[str, dict]:
        """Per fitted setting: the posterior mean, SD, median and the central 90 % credible interval."""
        x, w = self.posterior()
        out = {}
        for j, key in enumerate(self.fit.keys):
            lo, med, hi = weighted_quantiles(x[:, j], w, ((1 - CREDIBLE) / 2, 0.5, (1 + CREDIBLE) / 2))
            mean = float(np.sum(w * x[:, j]))
            out[key] = {"mean": mean, "sd": float(np.sqrt(np.sum(w * (x[:, j] - mean) ** 2))), "median": med,
                        "ci90": [lo, hi]}
        return out

    def hpd_level(self, point: dict) -> float:
        """The posterior weight of the settings more probable than ``point`` (a weighted Gaussian
        KDE of the last generation, ``scipy.stats.gaussian_kde``): a point inside the 50 %
        highest-density region has a level below 0.5; 1 far outside the posterior."""
        from scipy.stats import gaussian_kde

        x, w = self.posterior()
        scaled, at = self._scaled(x), self._scaled(np.array([[point[k] for k in self.fit.keys]], dtype=float))
        kde = gaussian_kde(scaled.T, weights=w)
        density = kde(scaled.T)
        return float(np.sum(w[density > kde(at.T)[0]]))

    def _scaled(self, x: np.ndarray) -> np.ndarray:
        return np.column_stack([p.scaled(x[:, j]) for j, p in enumerate(self.fit.priors)])


def weighted_quantiles(x: np.ndarray, w: np.ndarray, qs) -> list[float]:
    """Quantiles of a weighted sample (the weights' cumulative sum, interpolated at each weight's centre)."""
    order = np.argsort(x)
    x, w = x[order], w[order] / np.sum(w)
    centre = np.cumsum(w) - w / 2
    return [float(np.interp(q, centre, x)) for q in qs]


def _url(database: Path) -> str:
    return "sqlite:///" + str(Path(database).resolve())


def _history(database: Path):
    return needs_pyabc().History(_url(database), _id=1, create=False)


SETTINGS_TABLE = "bark_fit"


def _stored_settings(database: Path) -> dict | None:
    """The settings of the fit in ``database``: ``None`` where there is none yet, ``{}`` for a fit
    stopped before its settings were stored (in its first generation); one line for a file that
    is not a fit's database."""
    if not database.exists():
        return None
    from bark.io.files import sqlite_reader

    try:
        with sqlite_reader(database) as con:  # another program's database is left as it was
            tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
            row = con.execute(f"SELECT settings FROM {SETTINGS_TABLE}").fetchone() if SETTINGS_TABLE in tables else None
    except sqlite3.DatabaseError as err:
        raise BarkError(f"{database}: not a fit's database, or a damaged one ({err})") from None
    if SETTINGS_TABLE not in tables:
        if tables and "abc_smc" not in tables:
            raise BarkError(f"{database}: not a fit's database (it has tables, none of them a fit's)")
        return {} if tables else None
    return {} if row is None else json.loads(row[0])


def _store_settings(database: Path, settings: dict) -> None:
    with contextlib.closing(sqlite3.connect(database, timeout=60.0)) as con, con:
        con.execute(f"CREATE TABLE IF NOT EXISTS {SETTINGS_TABLE} (settings TEXT NOT NULL, bark_version TEXT)")
        from bark.version import __version__

        con.execute(f"INSERT INTO {SETTINGS_TABLE} VALUES (?, ?)", (_canonical(settings), __version__))


def _generations(database: Path) -> list[Generation]:
    if not database.exists():
        return []
    try:
        history = _history(database)
    except BarkError:
        raise
    except Exception:  # noqa: BLE001 — pyabc has no run there yet
        return []
    if history.n_populations == 0:
        return []
    out = []
    for row in history.get_all_populations().itertuples():
        if row.t < 0:  # pyabc's record of the observed statistics
            continue
        _, w = history.get_distribution(m=0, t=int(row.t))
        w = np.asarray(w, dtype=float)
        out.append(Generation(t=int(row.t), epsilon=float(row.epsilon), runs=int(row.samples), accepted=int(row.particles),
                              ess=float(np.sum(w) ** 2 / np.sum(w**2))))
    return out


def _quiet_pyabc() -> None:
    """pyabc's log lines (one per generation and more) are bark's to say, in its own words."""
    import logging

    for name in ("ABC", "ABC.History", "ABC.Distance", "ABC.Epsilon", "ABC.Sampler", "ABC.Transition", "ABC.Population",
                 "ABC.Predictor", "ABC.Adaptation", "ABC.Acceptor"):
        logging.getLogger(name).setLevel(logging.WARNING)


MISSING = 5.0
"""What a statistic a run lacks (a run without junctions has no n̄) adds to its distance: as much as
five median absolute deviations, so that such a run is far, not undefined."""


@functools.cache
def _distance_class():
    """The distance (pyabc's adaptive L1 distance, a statistic a run lacks counted as :data:`MISSING`)."""
    pyabc = needs_pyabc()

    class Distance(pyabc.AdaptivePNormDistance):
        def __call__(self, x, x_0, t=None, par=None) -> float:
            s, s0 = self.sumstat(x).flatten(), self.sumstat(x_0).flatten()
            weights = np.broadcast_to(self.get_weights(t=t), s.shape)
            parts = np.abs(weights * (s - s0))
            parts[np.isnan(parts) & (weights > 0)] = MISSING
            return float(np.nansum(parts))

    return Distance


def _abcsmc(fit: Fit, sampler):
    pyabc = needs_pyabc()
    _quiet_pyabc()
    prior = pyabc.Distribution({p.key: p.rv() for p in fit.priors})
    distance = _distance_class()(p=1, scale_function=pyabc.distance.mad, max_scale_weight_ratio=1e3)
    return pyabc.ABCSMC(fit.model(), prior, distance, population_size=fit.population, sampler=sampler,
                        eps=pyabc.QuantileEpsilon(alpha=0.5))


def run_fit(fit: Fit, database: str | Path, *, workers: int = 1, client=None, pool=None,
            progress: Callable[[int, int, int, int], None] | None = None,
            generation_done: Callable[[Generation], None] | None = None) -> FitResult:
    """Run ``fit`` into ``database`` (pyabc's SQLite file), going on from the generations already
    there: every generation starts from the database alone, so a fit stopped at any moment and run
    again gives the posterior an uninterrupted one gives.  ``client``: a ``distributed.Client`` to
    run on; else ``pool`` (a started ``LocalPool`` or ``DaskPool``, left open: several fits share its warm
    workers); else ``workers`` local processes.  ``progress(t, accepted, population, runs)`` after
    each run or runs that come back, ``generation_done(generation)`` after each generation stored."""
    database = Path(database)
    if workers < 1:
        raise BarkError(f"fit: workers must be at least 1, given {workers}")
    fit.check(None if client is not None or pool is not None else workers)
    stored = _stored_settings(database)
    settings = fit.settings()
    if stored and stored != json.loads(_canonical(settings)):
        raise BarkError(f"{database}: holds a fit of other settings (its observed pattern, scene, priors, statistics, "
                        "population or seed differ); give the fit a folder of its own")
    done = _generations(database)
    if not done and stored is not None:  # stopped in its first generation: nothing of it was kept
        for part in ("", "-wal", "-shm", "-journal"):
            Path(f"{database}{part}").unlink(missing_ok=True)
        stored = None
    result = FitResult(fit=fit, database=database, generations=done)
    if done and done[-1].acceptance < fit.min_acceptance:
        result.stop_reason = "acceptance"
        return result
    if len(done) >= fit.generations:
        result.stop_reason = "generations"
        return result
    own = pool is None
    if own:
        pool = DaskPool(client) if client is not None else LocalPool(workers, "fit", (warm_worker, (fit.base,)))
    sampler_class = _sampler_class()
    try:
        while len(result.generations) < fit.generations:
            t = len(result.generations)
            np.random.seed(np.random.SeedSequence([fit.seed, 2**32, t]).generate_state(4))  # pyabc's draws here, if any
            abc = _abcsmc(fit, sampler_class(pool, fit.seed, progress))
            if t == 0:
                abc.new(_url(database), compared(fit.observed.values, fit.compared))
                _store_settings(database, settings)
            else:
                abc.load(_url(database), 1)
            abc.run(max_nr_populations=1)
            result.generations = _generations(database)
            result.ran += 1
            if generation_done is not None:
                generation_done(result.generations[-1])
            if result.generations[-1].acceptance < fit.min_acceptance:
                result.stop_reason = "acceptance"
                break
        else:
            result.stop_reason = "generations"
    finally:
        if own:
            pool.close()
    return result


def load_fit(fit: Fit, database: str | Path) -> FitResult:
    """The fit in ``database``, read (nothing run)."""
    return FitResult(fit=fit, database=Path(database), generations=_generations(Path(database)))


def predictive(result: FitResult, n: int, *, workers: int = 1, client=None, seed: int | None = None) -> list[dict]:
    """``n`` runs at settings drawn from the posterior (by weight, seeded by the fit's seed): their
    settings, seeds and statistics, for the posterior-predictive check."""
    fit = result.fit
    x, w = result.posterior()
    rng = np.random.default_rng(np.random.SeedSequence([fit.seed if seed is None else seed, 2**33]))
    picks = rng.choice(len(w), size=n, p=w)
    seeds = rng.integers(0, 2**31 - 1, size=n)
    points = [{k: float(x[i, j]) for j, k in enumerate(fit.keys)} for i in picks]
    scenes = [fit.scene(p, int(s)) for p, s in zip(points, seeds)]
    names = fit.compared
    if client is None and (workers == 1 or n == 1):
        values = [simulate_statistics(sc, names) for sc in scenes]
    else:
        # its runs are handed out at once and need no pyabc: a warm-up would only delay them
        pool = DaskPool(client) if client is not None else LocalPool(min(workers, n), "fit")
        try:
            values = [f.result() for f in [pool.submit(simulate_statistics, sc, names) for sc in scenes]]
        finally:
            pool.close()
    return [{"settings": p, "seed": int(s), "statistics": v} for p, s, v in zip(points, seeds, values)]

