"""The numba backend's frame: the springs in the kernel's order, kept across calls and extended in
place as bases join, is derived data — a run must not depend on whether it was extended or made
again, nor on which springs broke outside the kernel."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from bark import Stop
from bark.engine.kernels import numba_backend
from bark.model.lattice import Lattice
from bark_plugins.breakers import ProbabilisticBreaker
from bark_plugins.growth import Bulge, BulgeGrowth, SqrtGrowth
from conftest import build_sim


def _run(n_start: int, breakers=None, stepping="adaptive"):
    growth = BulgeGrowth(base=SqrtGrowth(G=0.05), bulges=[Bulge(z=0.1, half_width=0.05, magnitude=0.01, G=0.02)])
    lattice = Lattice(n_bases=700, n_start=n_start, join_rate=60.0, join_every=0.1, jitter=0.05)
    sim = build_sim(n_bases=700, G=0.05, dt=0.3 if stepping == "adaptive" else 0.05, seed=5, stepping=stepping,
                    backend="numba", fmax_spread=0.05, growth=growth, lattice=lattice, breakers=breakers)
    sim.run(Stop(until_time=6.0))
    return sim


def _same(a, b) -> None:
    assert a.state.n_bases == b.state.n_bases
    for name in ("x", "v", "anchor", "intact", "rest", "fmax"):
        assert np.array_equal(getattr(a.state, name), getattr(b.state, name)), name
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    for key in la:
        assert np.array_equal(la[key], lb[key]), key


@pytest.mark.parametrize("n_start", [400, 100])  # 100: runs too short for room, or outgrown: made again
@pytest.mark.parametrize("breakers", [None, "probabilistic"])
def test_a_frame_extended_at_joins_runs_as_one_made_again_every_call(monkeypatch, n_start, breakers):
    make = [0]
    original = numba_backend.NumbaBackend._make

    def counted(self, state):
        make[0] += 1
        return original(self, state)

    monkeypatch.setattr(numba_backend.NumbaBackend, "_make", counted)
    kinds = [ProbabilisticBreaker()] if breakers else None
    stepping = "fixed" if breakers else "adaptive"
    extended = _run(n_start, kinds, stepping)
    made = make[0]
    assert extended.n_broken > 20 and extended.state.n_bases > n_start
    monkeypatch.setattr(numba_backend.NumbaBackend, "_extend", lambda self, frame, state: False)
    again = _run(n_start, kinds, stepping)
    assert make[0] - made > 40  # every join made the frame again
    if n_start == 400:
        assert made <= 2  # the joins extended it in place (the stability check's lattice aside)
    _same(extended, again)


def test_springs_broken_outside_the_kernel_reach_it():
    """A spring broken by Simulation.break_springs between calls is broken in the kernel's copy too."""
    sim = build_sim(n_bases=300, G=0.05, dt=0.05, seed=1, backend="numba")
    sim.run(Stop(until_time=1.0))
    tension = sim.tension()
    strongest = np.argsort(np.where(sim.state.intact, -tension, np.inf))[:30]
    sim.break_springs(strongest)
    sim.run(Stop(until_time=1.5))
    other = build_sim(n_bases=300, G=0.05, dt=0.05, seed=1, backend="numpy")
    other.run(Stop(until_time=1.0))
    other.break_springs(strongest)
    other.run(Stop(until_time=1.5))
    assert np.array_equal(sim.state.x, other.state.x)
    assert np.array_equal(sim.state.intact, other.state.intact)


def test_positions_changed_between_calls_are_seen():
    """The kernel keeps the spring forces of the positions it ended with for its next call; a change
    to the positions in between (a user's, here one base moved by 1e-9) makes them again."""
    runs = []
    for backend in ("numba", "numpy"):
        sim = build_sim(n_bases=300, G=0.05, dt=0.05, seed=2, backend=backend)
        sim.run(Stop(until_time=1.0))
        with sim.state.writing("x"):
            sim.state.x[17, 2] += 1e-9
        sim.run(Stop(until_time=1.5))
        runs.append(sim)
    assert np.array_equal(runs[0].state.x, runs[1].state.x)
    assert np.array_equal(runs[0].state.intact, runs[1].state.intact)


JOINING = Lattice(n_bases=2000, n_start=1500, join_rate=150.0, join_every=0.1, jitter=0.05)


def _threaded(threads: int, block: int, growth: str, lattice: Lattice = JOINING, until_time: float = 4.0,
              in_kernel: bool | None = None):
    """Bases joining (on ``JOINING``) and springs breaking — in the kernel (threshold, adaptive steps;
    by default at per-base radii, ``growth`` "bulge") or in Python (probabilistic, fixed steps; by
    default at a uniform radius, "sqrt") — with the kernel's loops in blocks of ``block``."""
    law = SqrtGrowth(G=0.08) if growth == "sqrt" else \
        BulgeGrowth(base=SqrtGrowth(G=0.08), bulges=[Bulge(z=0.4, half_width=0.2, magnitude=0.01, G=0.03)])
    if in_kernel is None:
        in_kernel = growth == "bulge"
    if in_kernel:
        breakers, stepping, dt = None, "adaptive", 0.3
    else:
        breakers, stepping, dt = [ProbabilisticBreaker()], "fixed", 0.05
    sim = build_sim(G=0.08, dt=dt, seed=2, stepping=stepping, backend="numba", fmax_spread=0.05, growth=law,
                    lattice=lattice, breakers=breakers, threads=threads)
    sim.build().backend.block = block
    sim.run(Stop(until_time=until_time))
    return sim


@pytest.mark.skipif(numba_backend.numba.config.NUMBA_NUM_THREADS < 2, reason="numba may use one thread here")
def test_threads_share_the_blocks_and_the_bits_stay_the_same(monkeypatch):
    """Blocks of 16 bases or springs, about a hundred a loop, shared between two threads — where a
    block that wrote another's bases, or a reduction taken out of order, would show — against the
    serial kernel with its usual blocks (every call threaded: none waits for a compile alongside).
    A uniform radius, breaks judged in Python; per-base radii and breaks in the kernel are checked
    so by ``tests/test_alongside.py``'s ``bark compile`` test, whose threaded kernel they are (each
    threaded kernel compiles for a minute or two)."""
    monkeypatch.setattr(numba_backend, "ALONGSIDE", False)
    serial, shared = _threaded(1, numba_backend.BLOCK, "sqrt"), _threaded(2, 16, "sqrt")
    assert (serial.backend.threads, shared.backend.threads) == (1, 2)
    assert shared.n_broken > 100 and shared.state.n_bases > serial.lattice.n_start  # breaks, and joins, happened
    _same(serial, shared)


@pytest.mark.slow
@pytest.mark.skipif(numba_backend.numba.config.NUMBA_NUM_THREADS < 2, reason="numba may use one thread here")
def test_threads_take_a_refused_step_back_to_the_serial_bits(monkeypatch, kernel_calls):
    """The threaded kernel's passes, in blocks of 16 shared between two threads, ready to take a step
    back at a uniform radius: the base pass writes each block into the second buffer, the spring
    pass reads the positions there, and a refused step is left untaken — the serial kernel's bits,
    breaks and steps, in long calls (no joins) and in short ones (bases joining every 0.1), which
    take a refused step back too.  At per-base radii (the base pass copies each block before it
    moves it) the same is checked by ``tests/test_alongside.py``'s ``bark compile`` test, on the
    threaded kernel it compiles.  Slow: a threaded kernel compiles for a minute or two."""
    monkeypatch.setattr(numba_backend, "ALONGSIDE", False)
    long_calls = Lattice(n_bases=2000, jitter=0.05)  # no joins: the kernel takes refused steps back itself
    serial = _threaded(1, numba_backend.BLOCK, "sqrt", long_calls, until_time=6.0, in_kernel=True)
    kernel_calls.clear()
    shared = _threaded(2, 16, "sqrt", long_calls, until_time=6.0, in_kernel=True)
    assert (serial.backend.threads, shared.backend.threads) == (1, 2)
    assert any(c.halved and not c.undone for c in kernel_calls) and shared.n_broken > 20  # refused steps taken back inside calls that went on
    _same(serial, shared)
    assert serial.step_count == shared.step_count
    kernel_calls.clear()  # and short calls (bases joining every 0.1), which take a refused step back too
    serial, shared = (_threaded(t, block, "sqrt", until_time=4.0, in_kernel=True) for t, block in ((1, numba_backend.BLOCK), (2, 16)))
    short = [c for c in kernel_calls if c.plan.n <= numba_backend.IN_PLACE_STEPS]
    assert short and not any(c.replayed for c in short) and any(c.halved for c in short)
    _same(serial, shared)
    assert serial.step_count == shared.step_count


@pytest.mark.parametrize("growth", ["bulge", "sqrt"])
def test_one_thread_sweeps_in_small_blocks_to_the_same_bits(growth):
    """The serial kernel's one sweep over blocks of bases (``_step_fused``) in blocks of 16: its base
    pass runs blocks ahead of the gather, and each run's window of springs slides down every block or
    two — against the same kernel in its usual blocks, where no window slides at this size."""
    usual, small = _threaded(1, numba_backend.BLOCK, growth), _threaded(1, 16, growth)
    assert small.n_broken > 100 and small.state.n_bases > small.lattice.n_start  # breaks, and joins, happened
    _same(usual, small)


@settings(max_examples=200, deadline=None)
@given(i0=st.integers(0, 50), o=st.integers(-40, 40).filter(bool), n=st.integers(1, 200), block=st.integers(1, 64),
       seed=st.integers(0, 2**32 - 1))
def test_the_gather_blocks_write_apart_so_any_order_of_blocks_gives_the_serial_bits(i0, o, n, block, seed):
    """A run's forces reach its bases by blocks of bases (``_gather_forces``): each block writes only
    its own bases, each base its second-end force before its first-end one — so the blocks done in
    any order (as threads may do them) give the bits of the serial sum."""
    assume(i0 + o >= 0)  # a run's second ends are bases too
    rng = np.random.default_rng(seed)
    low, span = i0 + min(o, 0), n + abs(o)
    size = i0 + n + abs(o) + 5
    start, w = rng.normal(size=size), rng.normal(size=n)
    serial = start.copy()
    serial[i0 + o:i0 + o + n] -= w
    serial[i0:i0 + n] += w
    gathered = start.copy()
    for blk in rng.permutation((span + block - 1) // block):
        numba_backend._gather_forces(gathered, w, i0, o, n, low + blk * block, low + min(span, (blk + 1) * block))
    assert np.array_equal(gathered, serial)


SPECIAL = st.sampled_from([0.0, -0.0, np.inf, -np.inf, 5e-324, -5e-324, 2.2250738585072014e-308, -1.0, 1.0,
                           1.7976931348623157e308, -1.7976931348623157e308])


@settings(max_examples=300, deadline=None)
@given(loads=st.lists(st.one_of(SPECIAL, st.floats(allow_nan=False)), max_size=300))
def test_the_largest_load_taken_on_integers_is_the_largest_double(loads):
    """``_largest_load`` takes its maximum on the loads' bits as integers that order as the doubles do
    (in SIMD lanes): the same as numpy's maximum for any doubles but NaN — signs of zero, infinities,
    subnormals, the extremes — and ``-inf`` for none (every spring broken: ``_run_forces`` writes
    ``-inf`` for a spring that is not live)."""
    wl = np.array(loads, dtype=float)
    got = numba_backend._largest_load(wl)
    assert got == (wl.max() if wl.size else -np.inf)
