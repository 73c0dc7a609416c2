"""Adaptive stepping: the overshoot tolerance holds, time stays on its grid, and the compiled
quiet path makes exactly the decisions the step-by-step path makes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bark import Stop
from bark.engine.kernels import Call
from bark.errors import BarkError
from conftest import build_sim


def _radius(bulged: bool) -> dict:
    """``make_sim``'s keywords for a radius that depends on height (a bulge on the sqrt law:
    ``bulged``), else none (the uniform sqrt law)."""
    from bark_plugins.growth import Bulge, BulgeGrowth, SqrtGrowth

    return {"growth": BulgeGrowth(base=SqrtGrowth(G=0.05), bulges=(Bulge(z=0.5, half_width=0.3, magnitude=0.02),))} \
        if bulged else {}


def _joining():
    """A lattice of 300 bases to which 100 join, two every 0.1 time units: calls of a few steps."""
    from bark.model.lattice import Lattice

    return Lattice(n_bases=400, n_start=300, join_rate=20.0, join_every=0.1, jitter=0.05)


def _overshoots(sim) -> np.ndarray:
    log = sim.breaks.arrays()
    return log["tension"] / sim.state.fmax[log["spring"]] - 1.0


@given(
    tol=st.sampled_from([0.002, 0.01, 0.05]),
    dt=st.sampled_from([0.1, 0.2, 0.3]),
    seed=st.integers(0, 1000),
    backend=st.sampled_from(["numpy", "numba"]),
)
@settings(max_examples=12)
def test_no_spring_breaks_beyond_the_overshoot_tolerance(tol, dt, seed, backend):
    sim = build_sim(n_bases=300, G=0.05, dt=dt, seed=seed, stepping="adaptive", overshoot_tol=tol, backend=backend)
    sim.run(Stop(until_time=6.0))
    over = _overshoots(sim)
    assert over.size > 20  # the run really cracked
    floor_hits = [e for e in sim.events if e["kind"] == "overshoot"]
    assert not floor_hits
    assert over.max() <= tol + 1e-12


def test_fixed_steps_do_overshoot_where_adaptive_ones_do_not(make_sim):
    """The tolerance is not vacuous: with the same largest step, fixed stepping overshoots more."""
    fixed = make_sim(n_bases=300, G=0.05, dt=0.3, seed=4)
    fixed.run(Stop(until_time=6.0))
    adaptive = make_sim(n_bases=300, G=0.05, dt=0.3, seed=4, stepping="adaptive", overshoot_tol=0.002)
    adaptive.run(Stop(until_time=6.0))
    assert _overshoots(fixed).max() > 0.002
    assert adaptive.step_count > fixed.step_count  # it took smaller steps somewhere


def test_adaptive_time_stays_on_the_grid_and_stops_exactly(make_sim):
    sim = make_sim(n_bases=300, G=0.05, dt=0.3, seed=2, stepping="adaptive", overshoot_tol=0.001, max_halvings=6)
    sim.run(Stop(until_time=6.0))
    assert sim.state.t == pytest.approx(6.0, abs=1e-12)
    h_min = 0.3 / 2**6
    assert abs(sim.state.t / h_min - round(sim.state.t / h_min)) < 1e-9


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_smallest_step_overshoot_is_recorded_not_silent(make_sim, backend):
    """With no room to halve, an overshoot is accepted and recorded as an event — every one: calls of
    many steps record the same events, step for step, as the step-by-step loop (they recorded only
    a call's last step: 3 of 6 here)."""
    kw = dict(n_bases=300, G=0.2, dt=0.3, seed=1, stepping="adaptive", overshoot_tol=1e-9, max_halvings=1,
              backend=backend)
    sim, stepped = make_sim(**kw), make_sim(**kw)
    stop = Stop(until_time=3.0)
    sim.run(stop)
    while stop.reason(stepped) is None:
        stepped.step()
    events = [e for e in sim.events if e["kind"] == "overshoot"]
    assert len(events) > 3 and all(e["load"] > 1.0 for e in events)
    assert events == [e for e in stepped.events if e["kind"] == "overshoot"]
    assert np.array_equal(sim.state.x, stepped.state.x) and sim.step_count == stepped.step_count


@pytest.mark.parametrize("seed", [0, 5])
def test_quiet_kernel_and_step_by_step_agree_under_adaptive_stepping(make_sim, seed):
    """advance() (compiled chunks — halved steps too, each chunk ending where the clock may double
    the step; a rejected step taken back in the call, halved, and the call going on) and step()
    decide alike, to the bit."""
    kw = dict(n_bases=300, G=0.05, dt=0.3, seed=seed, stepping="adaptive", overshoot_tol=0.005, backend="numba")
    chunked, stepped = make_sim(**kw), make_sim(**kw)
    stop = Stop(until_time=8.1)  # 27 full steps: run() keeps h, as step() by hand does
    chunked.prepare(stop)
    halved_chunks = 0
    while stop.reason(chunked) is None:
        halved = chunked.clock.halvings > 0
        done = chunked.advance(stop)
        halved_chunks += halved and done > 1
    while stop.reason(stepped) is None:
        stepped.step()
    a, b = chunked.breaks.arrays(), stepped.breaks.arrays()
    assert np.array_equal(a["spring"], b["spring"]) and np.array_equal(a["step"], b["step"])
    assert chunked.step_count == stepped.step_count
    assert np.array_equal(chunked.state.x, stepped.state.x)
    assert halved_chunks > 0  # several halved steps in one call happened


def test_adaptive_numpy_and_numba_agree(make_sim):
    kw = dict(n_bases=300, G=0.05, dt=0.3, seed=3, stepping="adaptive", overshoot_tol=0.005)
    runs = {}
    for backend in ("numpy", "numba"):
        runs[backend] = make_sim(backend=backend, **kw)
        runs[backend].run(Stop(until_time=8.0))
    a, b = runs["numpy"].breaks.arrays(), runs["numba"].breaks.arrays()
    assert np.array_equal(a["spring"], b["spring"]) and np.array_equal(a["step"], b["step"])
    np.testing.assert_allclose(runs["numpy"].state.x, runs["numba"].state.x, rtol=0, atol=1e-12)


@pytest.mark.parametrize("bulged", [False, True])
def test_short_calls_take_a_refused_step_back_as_their_radius_asks_with_the_same_bits(make_sim, kernel_calls, bulged):
    """A call allowed only a few steps (bases joining every 0.1 time units end many) takes a refused
    step back itself at a uniform radius (two buffers: nothing is copied per step), and is replayed
    up to it where the radius depends on height (taken back in the call, the bases would be copied
    every step: ``IN_PLACE_STEPS``) — either way to the numpy backend's bits, which replays."""
    from bark.engine.kernels.numba_backend import IN_PLACE_STEPS

    runs, calls = {}, {}
    for backend in ("numpy", "numba"):
        kernel_calls.clear()
        runs[backend] = make_sim(backend=backend, lattice=_joining(), G=0.05, dt=0.3, seed=3, stepping="adaptive",
                                 **_radius(bulged))
        runs[backend].run(Stop(until_time=5.0))
        calls[backend] = [c for c in kernel_calls if c.plan.n <= IN_PLACE_STEPS]  # the short ones
    assert any(c.replayed for c in calls["numpy"])  # refused steps of short calls there were
    if bulged:
        assert not any(c.undone for c in calls["numba"]) and any(c.replayed for c in calls["numba"])
    else:  # none replayed, and fewer calls: a halved step goes on in the call that refused it
        assert not any(c.replayed for c in calls["numba"]) and len(calls["numba"]) < len(calls["numpy"])
    a, b = runs["numpy"], runs["numba"]
    assert a.n_broken > 20 and a.step_count == b.step_count
    for name in ("x", "v", "anchor", "intact"):
        assert np.array_equal(getattr(a.state, name), getattr(b.state, name)), name


@pytest.mark.parametrize("bulged", [False, True])
def test_a_refused_step_taken_back_in_place_gives_the_replays_bits(make_sim, kernel_calls, bulged):
    """Under adaptive stepping the numba kernel takes a refused step back — at a uniform radius by not
    taking the buffer it wrote the step into, where the radius depends on height from its copy of
    the bases and anchors before it — halves it and goes on: the
    same bits, steps and breaks as the numpy backend, which ends the call there and replays it up
    to that step."""
    kw = dict(n_bases=300, G=0.05, dt=0.3, seed=3, stepping="adaptive", **_radius(bulged))
    runs = {}
    for backend in ("numpy", "numba"):
        runs[backend] = make_sim(backend=backend, **kw)
        runs[backend].run(Stop(until_time=8.0))
    assert any(c.undone or c.halved for c in kernel_calls)  # ended there, or halved and went on
    a, b = runs["numpy"], runs["numba"]
    for name in ("x", "v", "anchor", "intact"):
        assert np.array_equal(getattr(a.state, name), getattr(b.state, name)), name
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    assert all(np.array_equal(la[k], lb[k]) for k in la) and a.step_count == b.step_count and la["spring"].size > 20


@pytest.mark.parametrize("bulged", [False, True])
def test_a_call_leaves_the_next_one_the_positions_its_forces_are_of(make_sim, kernel_calls, bulged):
    """The numba kernel leaves the forces of the positions a call ended with for the next call,
    which takes them where those positions are still the state's (compared to the bit, else every
    force is made again: the same bits, only slower).  So after every call whose forces it kept,
    ``start``'s first vectors hold the state's positions — also where an adaptive call at a uniform
    radius ended in its second buffer (an odd count of steps kept) and copied it back into the
    state, and where per-base radii took a refused step back from a copy or replayed.  Bases join
    every 0.1 time units: many calls, the positions of the bases there before each join compared."""
    sim = make_sim(backend="numba", lattice=_joining(), G=0.05, dt=0.3, seed=3, stepping="adaptive", **_radius(bulged))
    odd = []

    def compare(sim):
        fr = sim.backend._frame
        if fr.forces is not None:  # kept for the next call
            odd.append(kernel_calls[-1].result.done % 2 == 1)
            assert np.array_equal(fr.start[0][:fr.kept], sim.state.x[:fr.kept]), (len(odd), kernel_calls[-1])

    sim.run(Stop(until_time=5.0), compare)
    assert sum(odd) > 3 and len(odd) - sum(odd) > 3, odd  # calls that ended in either buffer
    assert any(c.undone or c.halved for c in kernel_calls) and sim.n_broken > 20


def test_adaptive_stepping_also_keeps_explicit_steps_stable(make_sim):
    """A largest step above the stability limit is split, as with stepping = auto."""
    sim = make_sim(n_bases=200, dt=2.0, stepping="adaptive")
    assert sim.clock.h <= 0.9 * sim.stability_limit
    assert math.isclose(2.0 / sim.clock.h, round(2.0 / sim.clock.h))
    with pytest.raises(BarkError):
        make_sim(n_bases=200, dt=2.0, stepping="fixed").build()


def test_adaptive_implicit_respects_the_tolerance(make_sim):
    from bark_plugins.integrators import ImplicitOverdamped

    sim = make_sim(n_bases=200, G=0.05, dt=2.0, seed=1, stepping="adaptive", overshoot_tol=0.01,
                   integrator=ImplicitOverdamped())
    sim.run(Stop(until_time=6.0))
    assert _overshoots(sim).size > 10
    assert _overshoots(sim).max() <= 0.01 + 1e-12


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_with_no_breakers_adaptive_steps_are_not_halved_for_tension(make_sim, backend):
    """A scene without the fracture effect has no breakers: tension over a threshold breaks nothing,
    so it is no overshoot — the step stays whole (halving it to the floor only slowed the run) and no
    overshoot event is recorded."""
    import attrs

    with_breakers = make_sim(n_bases=300, G=0.2, dt=0.3, seed=1, stepping="adaptive", backend=backend)
    sim = attrs.evolve(with_breakers, breakers=())
    sim.run(Stop(until_time=6.0))
    assert float(np.max(sim.forces.tension(sim.state) / sim.state.fmax)) > 1.0 + sim.numerics.overshoot_tol
    assert sim.step_count == round(6.0 / sim.clock.h) and sim.clock.halvings == 0
    assert not [e for e in sim.events if e["kind"] == "overshoot"]


class _Recorded(Call):
    """A Call that ends after ``ends_at`` steps with ``load``, and records what it is asked; with
    ``in_place`` it takes a refused last step back itself."""

    def __init__(self, ends_at: int, load: float, in_place: bool = False) -> None:
        self.ends_at, self.load, self.asked, self.in_place = ends_at, load, [], in_place

    def take(self, n):
        self.asked.append(("take", n))
        done = min(self.ends_at, n)
        load = self.load if done == self.ends_at else 0.5
        self.refused = not load <= 1.002
        self.undone = self.in_place and self.refused
        return done, load, done == 2 and not self.undone

    def undo(self):
        self.asked.append(("undo",))

    def result(self, done, load, picked, refused):
        from bark.engine.kernels import Steps

        empty = np.empty(0, np.int64)
        return Steps(done=done, load=load, picked=picked, broken=empty, step=empty, tension=np.empty(0),
                     refused=refused)


@pytest.mark.parametrize("load, ends_at, in_place, asked, done", [
    (math.nan, 3, False, [("take", 5), ("undo",), ("take", 2)], 2),  # non-finite: undone, replayed up to it
    (1.5, 1, False, [("take", 5), ("undo",)], 0),                    # over at the first step: nothing to replay
    (1.001, 3, False, [("take", 5)], 3),                             # within the tolerance: kept
    (math.nan, 3, True, [("take", 5)], 2),                           # taken back by the call itself
    (1.5, 3, True, [("take", 5)], 2),
])
def test_every_backend_undoes_a_step_by_one_algorithm(load, ends_at, in_place, asked, done):
    """``take_steps`` — what every backend's ``steps`` and the Python path are — undoes a last step
    that went non-finite or over ``accept_load``, and only then: by replaying the call up to it, or
    by the call itself where it kept a copy of the state before that step (``Call.undone``)."""
    from bark.engine.kernels import Plan, take_steps

    plan = Plan(h_min=0.05, ticks=0, n=5, integrator=None, growth=None, levels=1, over=1.002)
    assert plan.accept_load == 1.002 and plan.h == 0.1
    call = _Recorded(ends_at, load, in_place)
    result = take_steps(call, plan)
    assert call.asked == asked and result.done == done and result.refused == (not load <= 1.002)
    assert math.isnan(result.load) if math.isnan(load) else result.load == load
    assert result.picked == (done == 2 and not in_place)  # a step taken back named no candidate


INF = math.inf


@pytest.mark.parametrize("finite, load, candidate, broke, broken, budget, max_batch, stop_here, ends", [
    (True, 0.9, False, 0, 0, INF, 10, False, False),
    (False, 0.9, False, 0, 0, INF, 10, False, True),     # non-finite
    (True, 1.01, False, 0, 0, INF, 10, False, True),     # over accept_load (1.002)
    (True, 0.9, True, 0, 0, INF, 10, False, True),       # a candidate for Python
    (True, 1.001, False, 3, 3, INF, 10, False, False),   # broke, nobody must see
    (True, 1.001, False, 3, 3, 1, 10, False, True),      # broke, Python must see every break
    (True, 1.001, False, 2, 4, 5, 10, False, False),     # broke, the call's breaks short of the budget
    (True, 1.001, False, 2, 6, 5, 10, False, True),      # broke, the call's breaks past the budget
    (True, 1.001, False, 0, 6, 5, 10, False, False),     # past the budget, but broke nothing this step
    (True, 1.001, False, 11, 11, INF, 10, False, True),  # a degenerate batch
    (True, 1.0, False, 0, 0, INF, 10, True, True),       # at the time limit, or doubled where it may not go on
])
def test_one_rule_ends_a_call(finite, load, candidate, broke, broken, budget, max_batch, stop_here, ends):
    from bark.engine.kernels import ends_call

    assert ends_call(finite, load, 1.002, INF, candidate, broke, broken, budget, max_batch, stop_here) == ends
    assert ends_call(finite, load, INF, 1.002, candidate, broke, broken, budget, max_batch, stop_here) == (
        ends or finite and load > 1.002)  # at the smallest step: kept, and the call ends to record it


@pytest.mark.parametrize("halvings, load, end_tick, size, doubled", [
    (1, 1.0, 8, 4, True),      # quiet, on the grid of the step twice as long
    (1, 1.0, 4, 4, False),     # quiet, between two of its steps
    (1, 1.001, 8, 4, False),   # not quiet
    (0, 0.5, 8, 4, False),     # the full step already
    (3, -INF, 16, 1, True),    # a breaker without a load is always quiet
])
def test_one_rule_doubles_the_step(halvings, load, end_tick, size, doubled):
    from bark.engine.kernels import doubles, limits

    assert doubles(halvings, load, end_tick, size) == doubled
    assert limits(1.002, 0, 2) == (1.002, INF) and limits(1.002, 2, 2) == (INF, 1.002) and limits(INF, 0, 2) == (INF, INF)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_calls_that_double_the_step_inside_give_the_bits_of_one_step_calls(make_sim, kernel_calls, backend):
    """The clock doubles a halved step inside a call and the call goes on (no call ends for it), and
    where the call takes a refused step back itself (numba's long calls) it halves it and goes on:
    the steps, their times and sizes, and so every bit, are those of a run whose calls take one step
    each (where the simulation's clock does everything)."""
    kw = dict(n_bases=400, G=0.05, dt=0.3, seed=3, stepping="adaptive", overshoot_tol=0.002, backend=backend)
    whole, single = make_sim(**kw).build(), make_sim(**kw)
    whole.run(Stop(until_time=6.0))
    calls = list(kernel_calls)  # the whole run's
    while single.state.t < whole.state.t - 1e-12:
        single.step()
    assert whole.step_count == single.step_count and whole.clock.ticks == single.clock.ticks
    assert whole.n_broken > 20 and whole.events == single.events
    for a, b in [(whole.state.x, single.state.x), (whole.state.v, single.state.v), (whole.state.intact, single.state.intact)]:
        assert np.array_equal(a, b)
    for key, a in whole.breaks.arrays().items():
        assert np.array_equal(a, single.breaks.arrays()[key]), key
    assert sum(c.doubled for c in calls) > 3  # calls that doubled the step and went on
    halved = sum(c.halved for c in calls)  # and that halved it and went on
    assert halved > 3 if backend == "numba" else halved == 0
