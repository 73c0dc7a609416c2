"""Shared fixtures and hypothesis profiles for bark's test suite.

Profiles: ``ci`` (30 examples, no deadline) is loaded when the environment variable ``CI`` is set;
otherwise ``HYPOTHESIS_PROFILE`` names the profile, defaulting to ``dev`` (100 examples).

Every simulation here is small (a few hundred bases) and uses a large growth constant or a coarse
(stable) time step, so that springs break within a few dozen to a few hundred steps.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from pathlib import Path

import numpy as np
import attrs
import pytest
from hypothesis import HealthCheck, settings

from bark import Lattice, Mechanics, Simulation
from bark.engine.stepping import Numerics
from bark_plugins.breakers import ThresholdBreaker
from bark_plugins.growth import SqrtGrowth
from bark_plugins.integrators import EulerCromer

settings.register_profile("ci", max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", max_examples=100, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else os.environ.get("HYPOTHESIS_PROFILE", "dev"))

REPO_ROOT = Path(__file__).resolve().parent.parent


NUMERICS = ("dt", "stepping", "overshoot_tol", "max_halvings", "backend", "threads")


def slow_cases(*values) -> list:
    """Parameters left to the full suite (``slow``): the quick subset keeps one case of a class."""
    return [pytest.param(v, marks=pytest.mark.slow) for v in values]


@attrs.frozen
class KernelCall:
    """One call of a backend's steps (``bark.engine.kernels.take_steps``), as :func:`recorded_calls`
    keeps it: what it was asked (``plan``), what it did (``result``) and whether it took its refused
    last step back itself (``undone``: the numba kernel's second buffer or copy)."""

    plan: object
    result: object
    undone: bool

    @property
    def replayed(self) -> bool:
        """Whether its refused last step was taken back by replaying the call up to it."""
        return self.result.refused and not self.undone

    @property
    def sizes(self) -> np.ndarray:
        """The sizes of the steps it kept, in ticks of the clock."""
        return np.diff(np.r_[self.plan.ticks, self.result.ends])

    @property
    def halved(self) -> bool:
        """Whether it halved a step and went on: a step it kept is smaller than the one kept
        before it, or than the step it began with."""
        began = 1 << (self.plan.levels - self.plan.halvings)  # in ticks, as the sizes
        return bool((np.diff(np.r_[began, self.sizes]) < 0).any())

    @property
    def doubled(self) -> bool:
        """Whether it doubled a step and went on: the sizes of the steps it kept grow somewhere."""
        return bool((np.diff(self.sizes) > 0).any())


@contextlib.contextmanager
def recorded_calls():
    """Every call of the backends' step algorithm (``Backend.steps``: the compiled path; the
    Python path's steps are not recorded) made inside the block, in order, in the list it yields
    (a test may clear it between runs).  A plain context manager, so that a script a test runs in
    a process of its own can record its calls too; in-process tests take the ``kernel_calls``
    fixture."""
    from bark.engine import kernels

    calls: list[KernelCall] = []
    take_steps = kernels.take_steps

    def recording(call, plan):
        result = take_steps(call, plan)
        calls.append(KernelCall(plan, result, call.undone))
        return result

    kernels.take_steps = recording
    try:
        yield calls
    finally:
        kernels.take_steps = take_steps


@pytest.fixture
def kernel_calls():
    """The test's kernel calls (:func:`recorded_calls`), recorded from here to the test's end."""
    with recorded_calls() as calls:
        yield calls


def build_sim(
    *,
    n_bases: int = 300,
    jitter: float = 0.05,
    G: float = 0.05,
    f_max: float = 0.0028,
    fmax_spread: float = 0.0,
    dt: float = 0.05,
    seed: int = 0,
    **kwargs,
) -> Simulation:
    """A small simulation: sqrt growth, Euler–Cromer, threshold breaker (Table 2 k, c, b, m); the
    numerics (``dt``, ``stepping`` — fixed unless given —, ``overshoot_tol``, ``max_halvings``,
    ``backend``) may be given as keywords.  ``fmax_spread`` is the first breaker's ``spread`` (it
    must be a :class:`~bark_plugins.breakers.Thresholds`)."""
    numerics = {"dt": dt, "stepping": "fixed", **{k: kwargs.pop(k) for k in NUMERICS if k in kwargs}}
    breakers = list(kwargs.pop("breakers", None) or [ThresholdBreaker()])
    if fmax_spread:
        breakers[0] = attrs.evolve(breakers[0], spread=fmax_spread)
    return Simulation(
        lattice=kwargs.pop("lattice", None) or Lattice(n_bases=n_bases, jitter=jitter),
        mechanics=Mechanics(f_max=f_max),
        growth=kwargs.pop("growth", None) or SqrtGrowth(G=G),
        integrator=kwargs.pop("integrator", None) or EulerCromer(),
        breakers=breakers,
        numerics=Numerics(**numerics),
        seed=seed,
        **kwargs,
    )


@pytest.fixture(autouse=True)
def _own_compile_record(monkeypatch, tmp_path_factory):
    """Compile timings a test records stay the test's: the user's record (``compile_record``, what
    decides whether a run compiles its threaded kernel alongside) is never written by the suite —
    tests that pretend a kernel is not cached would record its load as a compile of 0.1 s, and every
    later large run on that machine would start a compile alongside that it ends unfinished."""
    record = tmp_path_factory.mktemp("compile-record") / "compile-seconds.json"
    monkeypatch.setattr("bark.engine.kernels.numba_backend.compile_record", lambda: record)


@pytest.fixture
def make_sim():
    """Factory fixture: ``make_sim(n_bases=..., G=..., ...)`` → a fresh small :class:`Simulation`."""
    return build_sim


@pytest.fixture
def small_sim() -> Simulation:
    """400 bases, G = 0.05 (first breaks within ~20 steps at dt = 0.05), jittered, seed 1."""
    return build_sim(n_bases=400, seed=1)


@pytest.fixture
def broken_sim() -> Simulation:
    """A small simulation already run to t = 4, with many springs broken."""
    sim = build_sim(n_bases=400, seed=2, fmax_spread=0.05)
    from bark import Stop

    sim.run(Stop(until_time=4.0))
    assert sim.n_broken > 0
    return sim


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


# -- fault injection: bounded CLI runs and the contract every outcome must keep -----------------


@contextlib.contextmanager
def signal_after(seconds: float, sig: int = signal.SIGTERM):
    """Send ``sig`` to this process after ``seconds`` (a run that would go on too long is stopped the
    way a scheduler stops it).  A signal that comes after the command returned is ignored."""
    previous = signal.signal(sig, lambda *args: None)
    timer = threading.Timer(seconds, os.kill, (os.getpid(), sig))
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        timer.join()
        signal.signal(sig, previous)


def assert_clean_outcome(result, out: Path | None = None) -> None:
    """The CLI's promise for any input: exit 0 (warnings at most), 2 (one line naming what is wrong,
    nothing written), 1 (a non-finite state or an output that could not be written, said in lines of
    its own) or 128 + signal (stopped from outside, with the command that goes on); never a traceback."""
    code, err = result.exit_code, result.stderr
    assert "Traceback" not in result.output and "Traceback" not in err, err
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    lines = err.splitlines()
    assert all(line.startswith("bark: ") for line in lines), err
    if code == 2:
        assert len(lines) == 1 and lines[0].startswith("bark: error: "), err
        if out is not None:
            assert not out.exists() or not any(out.iterdir()), sorted(p.name for p in out.iterdir())
    elif code == 0:
        assert not any(line.startswith("bark: error") for line in lines), err
    elif code == 1:
        assert any("NaN or infinite" in line or "that state is written to" in line or "could not be drawn" in line
                   or "could not be written" in line for line in lines), err
    elif code in (128 + signal.SIGTERM, 128 + signal.SIGINT):
        assert "go on with: bark simulate --resume" in err or "not drawn" in err or "before the run began" in err, err
    else:
        raise AssertionError(f"exit status {code}: {err}")


def as_a_user_who_cannot_write() -> tuple:
    """A command prefix that runs a command as a user for whom read-only folders, bark's source and
    a missing home cannot be written: none needed for an ordinary user; as root (who writes
    anywhere) ``nobody``, by ``setpriv``.  Skips where no such user is to be had."""
    import shutil
    import subprocess
    import sys

    if os.geteuid() != 0:
        return ()
    if shutil.which("setpriv") is None:
        pytest.skip("running as root without setpriv: no user to run as who cannot write")
    prefix = ("setpriv", "--reuid=65534", "--regid=65534", "--clear-groups")
    probe = subprocess.run([*prefix, sys.executable, "-c", "import bark_cli.main"], cwd=REPO_ROOT, capture_output=True,
                           timeout=120)
    if probe.returncode != 0:
        pytest.skip("the checkout cannot be read by the user nobody")
    return prefix
