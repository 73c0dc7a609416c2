"""Springs broken inside the compiled quiet kernel (threshold rule, fixed or automatic steps) must
give, bit for bit, what the step-by-step loop gives: the same states, the same break log, the same
graph, the same events, the same stopping step — and Python must still see every break it asks to."""

from __future__ import annotations

import functools
import math

import attrs
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bark import Stop
from bark.errors import NonFiniteStateError
from bark.engine.triggers import At, Every, OnEvent, Periodic
from bark_plugins.breakers import ProbabilisticBreaker, ThresholdBreaker
from bark_plugins.growth import SqrtGrowth
from conftest import build_sim

LOG = ("spring", "i", "j", "step", "t", "tension")


def _stepped(sim, stop):
    while stop.reason(sim) is None and sim.stop_reason is None:
        sim.step()
    return sim


def _assert_same(a, b):
    for name in ("x", "v", "anchor", "intact"):
        assert np.array_equal(getattr(a.state, name), getattr(b.state, name)), name
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    for k in LOG:
        assert np.array_equal(la[k], lb[k]), k
    assert a.step_count == b.step_count and a.state.t == b.state.t
    assert [e["kind"] for e in a.events] == [e["kind"] for e in b.events]
    assert [(e["step"], e["t"]) for e in a.events] == [(e["step"], e["t"]) for e in b.events]


def _graph_matches_arrays(sim):
    edges = {tuple(sorted(e)) for e in sim.graph.edges}
    intact = {tuple(sorted(p)) for p in sim.state.pairs[sim.state.intact].tolist()}
    return edges == intact


@pytest.mark.parametrize("stepping", ["fixed", "auto"])
def test_breaking_inside_the_kernel_equals_the_step_loop(make_sim, stepping):
    kw = dict(n_bases=400, G=0.05, dt=0.05, seed=3, backend="numba", stepping=stepping, fmax_spread=0.05)
    fast, slow = make_sim(**kw), make_sim(**kw)
    stop = Stop(until_time=8.0)
    advances = []
    fast.run(stop, lambda s: advances.append(s.step_count))
    _stepped(slow, stop)
    _assert_same(fast, slow)
    steps_with_breaks = np.unique(fast.breaks.arrays()["step"]).size
    assert steps_with_breaks > 20
    assert len(advances) < steps_with_breaks  # calls went on through breaks: the kernel broke springs
    assert _graph_matches_arrays(fast)


def test_patch_stop_stops_at_the_same_step_as_the_step_by_step_loop(make_sim):
    kw = dict(n_bases=400, G=0.05, dt=0.05, seed=5, backend="numba")
    fast, slow = make_sim(**kw), make_sim(**kw)
    stop = Stop(until_patches=6, until_time=40.0)
    assert fast.run(stop) == "patches"
    _stepped(slow, stop)
    _assert_same(fast, slow)


@pytest.mark.parametrize("backend, stepping", [("numba", "adaptive"), ("numpy", "adaptive"), ("numba", "fixed")])
def test_a_patch_stop_runs_through_breaks_and_stops_where_watching_every_break_stops(make_sim, backend, stepping):
    """With a patch-count stop a call may break as many springs as patches may still be missing
    (each break adds at most one patch) before Python counts them: fewer calls than steps with
    breaks, and the same bits, stopping step and count as a run whose calls end at every break
    (a trigger that watches breaks makes them)."""
    kw = dict(n_bases=800, G=0.05, dt=0.05, seed=4, backend=backend, stepping=stepping)
    stop = Stop(until_patches=40, until_time=80.0)
    budget, every = make_sim(**kw), make_sim(**kw)
    passes, watched = [], []
    assert budget.run(stop, lambda s: passes.append(s.step_count)) == "patches"
    every.add_action(OnEvent("break"), lambda s: None)
    assert every.run(stop, lambda s: watched.append(s.step_count)) == "patches"
    _assert_same(budget, every)
    assert budget.patch_count(7) == every.patch_count(7) >= 40
    steps_with_breaks = np.unique(budget.breaks.arrays()["step"]).size
    assert len(passes) < steps_with_breaks <= len(watched) and steps_with_breaks > 20


@pytest.mark.parametrize("stepping", ["adaptive", "fixed"])
def test_the_kernel_counts_the_patches_and_goes_on_through_its_budget(make_sim, stepping):
    """Where the breaks reach the patch-count stop's budget, the numba kernel counts the patches
    itself and goes on while there are fewer than asked: its calls end at the step budget or at the
    stop, not at each budget, yet it stops at the same step, with the same bits, as the numpy
    backend, whose calls end at every budget for Python to count."""
    from bark.engine.stepping import CHUNK

    kw = dict(n_bases=800, G=0.05, dt=0.05, seed=4, stepping=stepping)
    stop = Stop(until_patches=40, until_time=80.0)
    compiled, arrays = make_sim(backend="numba", **kw), make_sim(backend="numpy", **kw)
    passes = {"numba": [], "numpy": []}
    assert compiled.run(stop, lambda s: passes["numba"].append(s.step_count)) == "patches"
    assert arrays.run(stop, lambda s: passes["numpy"].append(s.step_count)) == "patches"
    _assert_same(compiled, arrays)
    assert compiled.patch_count(7) >= 40
    assert len(passes["numba"]) <= math.ceil(compiled.step_count / CHUNK) + 1 < len(passes["numpy"]), passes


@settings(max_examples=40, deadline=None)
@given(ops=st.lists(st.tuples(st.sampled_from(["break", "mend", "count"]), st.integers(0, 10**6)), max_size=40),
       min_size=st.integers(1, 8))
def test_the_patch_bound_holds_whatever_breaks_and_mends(ops, min_size):
    """``Simulation.patches_at_most`` is never below the count, whatever springs break or are
    mended (a mend can join two patches without the breaks since saying so: the bound is taken
    again) and whenever the count was last taken."""
    from bark.model.graph import components, count_patches

    sim = build_sim(n_bases=120, seed=0)
    s = sim.build().state
    for op, k in ops:
        if op == "count":
            sim.patch_count(min_size)
        else:
            (sim.break_springs if op == "break" else sim.mend_springs)([k % s.n_springs])
        exact = count_patches(components(s.n_bases, s.pairs, s.intact), min_size)
        assert sim.patches_at_most(min_size) >= exact


def test_the_patch_bound_is_taken_again_after_a_mend():
    """A break that cuts a base off adds a patch; mending a spring that joined nothing takes a
    break back from the count of broken springs without taking the patch back: the bound must not
    fall below the count for it."""
    sim = build_sim(n_bases=120, seed=0)
    s = sim.build().state
    base = 60
    own = np.flatnonzero((s.pairs == base).any(axis=1))
    elsewhere = int(np.flatnonzero(~(np.isin(s.pairs, [base]).any(axis=1)))[-1])
    sim.break_springs([*own[:-1], elsewhere])  # all but one of the base's springs, and one far from it
    before = sim.patch_count(1)
    sim.break_springs(own[-1:])  # the base alone now: one patch more
    sim.mend_springs([elsewhere])  # joins nothing: as many patches
    assert sim.patches_at_most(1) >= before + 1 == sim.patch_count(1)


@given(n=st.integers(4, 40), order=st.randoms(use_true_random=False), min_size=st.integers(1, 6))
def test_a_broken_spring_adds_at_most_one_patch_of_any_least_size(n, order, min_size):
    """What the patch-count stop's budget rests on (``Simulation.patches_at_most``): removing one
    edge splits at most one component in two, so the count of components of at least ``min_size``
    grows by at most one a break — on any graph, in any order of breaks."""
    from bark.model.graph import components, count_patches

    pairs = np.array([(i, j) for i in range(n) for j in (i + 1, i + 3, i + 7) if j < n], dtype=np.int64)
    intact = np.ones(len(pairs), bool)
    before = count_patches(components(n, pairs, intact), min_size)
    for spring in order.sample(range(len(pairs)), len(pairs)):
        intact[spring] = False
        now = count_patches(components(n, pairs, intact), min_size)
        assert now <= before + 1
        before = now


def test_an_on_break_trigger_fires_at_every_breaking_step(make_sim):
    sim = make_sim(n_bases=400, G=0.05, dt=0.05, seed=5, backend="numba")
    fired = []
    sim.add_action(OnEvent("break"), lambda s: fired.append(s.step_count))
    sim.run(Stop(until_time=6.0))
    assert fired == np.unique(sim.breaks.arrays()["step"]).tolist() and len(fired) > 10


def test_degenerate_events_match_with_the_exact_lattice(make_sim):
    """The exact lattice breaks a whole offset class in one step (docs/model.md, Symmetry breaking): the kernel must hand
    that step back so the event is recorded (and, with on_degenerate = stop, the run ends there)."""
    for on in ("warn", "stop"):
        kw = dict(n_bases=400, G=0.05, dt=0.05, seed=1, backend="numba", jitter=0.0, on_degenerate=on)
        fast, slow = make_sim(**kw), make_sim(**kw)
        stop = Stop(until_time=10.0)
        fast.run(stop)
        _stepped(slow, stop)
        assert any(e["kind"] == "degenerate" for e in fast.events)
        _assert_same(fast, slow)
        if on == "stop":
            assert fast.stop_reason == "degenerate"


def test_a_subclass_that_changes_select_is_asked(make_sim):
    """A breaker that inherits a part but writes ``select`` again loses the part unless it declares
    one again: its ``select`` is always the one asked, and ``super().select`` still means the
    parent's rule."""
    calls = []

    class EveryOther(ThresholdBreaker):
        def select(self, state, tension, rng):
            calls.append(1)
            return super().select(state, tension, rng)[::2]

    class Lower(ThresholdBreaker):  # the trap: breaks below the threshold, inherits the part
        def select(self, state, tension, rng):
            return np.flatnonzero(state.intact & (tension > 0.5 * state.fmax))

    class Promised(EveryOther):
        def part(self):
            return attrs.evolve(ThresholdBreaker().part(), decides=False)

    assert ThresholdBreaker().part_ is not None and ThresholdBreaker().part_.decides
    assert EveryOther().part_ is None and Lower().part_ is None
    assert Promised().part_ is not None and not Promised().part_.decides
    assert not ProbabilisticBreaker().part_.decides and ProbabilisticBreaker().part_.load is None
    sim = make_sim(n_bases=300, backend="numba", breakers=[EveryOther()])
    sim.run(Stop(until_time=4.0))
    assert calls and sim.n_broken > 0
    first = {}
    for breaker in (Lower(), ThresholdBreaker()):
        sim = make_sim(n_bases=300, backend="numba", breakers=[breaker])
        sim.run(Stop(until_time=10.0), lambda s: s.n_broken and s.__setattr__("stop_reason", "broke"))
        first[type(breaker).__name__] = sim.breaks.arrays()["t"][0]
    assert first["Lower"] < first["ThresholdBreaker"]  # it never waits for a spring to reach 100 %


@pytest.mark.parametrize("trigger", [Periodic(7), Every(0.4), At([1.0, 2.5])])
def test_time_and_step_triggers_let_the_kernel_break(trigger):
    assert not trigger.watches_breaks()
    assert OnEvent("break").watches_breaks() and (trigger | OnEvent("break")).watches_breaks()
    assert not (trigger & Periodic(3)).watches_breaks() and not (~trigger).watches_breaks()


@attrs.frozen(kw_only=True)
class _SqrtThenNaN(SqrtGrowth):
    t_bad: float = 1.0

    def radius(self, t, z):
        return math.nan if t > self.t_bad else super().radius(t, z)


def test_nan_in_a_call_that_broke_springs_keeps_them_broken():
    """A call that breaks springs and then meets a NaN radius: the state goes back to the last
    finite step, and exactly the springs broken up to it are broken, in graph, arrays and log."""
    dt, bad_step = 0.05, 97  # inside a call, past the first breaks

    ref = build_sim(n_bases=400, seed=2, dt=dt, backend="numba")  # G = 0.05
    sim = attrs.evolve(ref, growth=_SqrtThenNaN(G=0.05, t_bad=(bad_step - 0.5) * dt))
    with pytest.raises(NonFiniteStateError):
        sim.run(Stop(until_time=100.0))
    for _ in range(bad_step - 1):
        ref.step()
    _assert_same(sim, ref)
    assert _graph_matches_arrays(sim) and len(sim.breaks) == sim.n_broken
    assert sim.breaks.arrays()["step"].max() > bad_step - 30  # springs broke in the call that met the NaN


def test_break_springs_logs_a_batch_in_step_order():
    sim = build_sim(n_bases=300, backend="numba")
    tension = np.arange(sim.state.n_springs, dtype=float)
    got = sim.break_springs([9, 4, 6, 4], tension, step=[3, 5, 3, 2], t=[0.3, 0.5, 0.3, 0.2])
    assert got.tolist() == [4, 6, 9]
    log = sim.breaks.arrays()
    assert log["spring"].tolist() == [4, 6, 9] and log["step"].tolist() == [2, 3, 3]
    assert log["t"].tolist() == [0.2, 0.3, 0.3] and log["tension"].tolist() == [4.0, 6.0, 9.0]
    assert _graph_matches_arrays(sim)


@given(st.lists(st.tuples(st.integers(0, 40), st.integers(1, 4)), max_size=30), st.booleans())
def test_break_springs_logs_any_batch_by_step_then_id_each_once(batch, presorted):
    """Whatever the order and repeats of a batch (sorted already, as the kernel gives it, or not),
    the log is each intact id once, at its earliest step, ordered by step then id."""
    sim = _small_sim()
    batch = sorted(set(batch), key=lambda p: (p[1], p[0])) if presorted else batch
    ids, steps = [p[0] for p in batch], [p[1] for p in batch]
    sim.break_springs([3], step=0)  # one broken before: ignored when given again
    first = {}
    for i, k in zip(ids, steps):
        first[i] = min(first.get(i, k), k)
    want = sorted(((k, i) for i, k in first.items() if i != 3))
    got = sim.break_springs(ids, np.arange(sim.state.n_springs, dtype=float), step=steps, t=[0.1 * k for k in steps])
    assert got.tolist() == [i for _, i in want]
    log = sim.breaks.arrays()
    assert log["spring"].tolist() == [3] + [i for _, i in want] and log["step"].tolist() == [0] + [k for k, _ in want]
    assert _graph_matches_arrays(sim)


@functools.cache
def _small_sim_state():
    return build_sim(n_bases=120, backend="numpy")


def _small_sim():
    import copy

    return copy.deepcopy(_small_sim_state())


@pytest.mark.parametrize("budget", [math.inf, 1.0, 3.0])
def test_a_calls_load_is_its_last_steps_largest_load(budget):
    """With no load bound the kernel takes the largest load once, after its last step, over the
    springs live before that step (those it broke included); with one, every step.  Both, and the
    numpy backend, report the same load to the bit, and the same steps and breaks."""
    import copy

    from bark.engine import kernels, stepping

    sim = build_sim(n_bases=400, G=0.05, dt=0.05, seed=3, backend="numba", stepping="fixed", fmax_spread=0.05)
    stop = Stop(until_time=8.0)
    sim.prepare(stop)
    backends = {"numba": sim.backend, "numpy": kernels.load("numpy")}
    with_breaks = ended_on_a_break = 0
    while stop.reason(sim) is None:
        plan = attrs.evolve(stepping.plan(sim, stop, most=5), break_budget=budget)
        results = []
        for name, bound in (("numba", math.inf), ("numba", 1e300), ("numpy", math.inf)):
            state = copy.deepcopy(sim.state)
            tension = np.empty(state.n_springs)
            r = backends[name].steps(state, sim.mechanics, attrs.evolve(plan, over=bound), tension)
            results.append((r, state))
        (first, s0), *rest = results
        for r, s in rest:
            assert r.done == first.done and np.array_equal(r.broken, first.broken)
            assert np.array_equal(r.step, first.step) and np.array_equal(r.tension, first.tension)
            assert r.load == first.load and np.array_equal(s.x, s0.x), (first.load, r.load)
        with_breaks += bool(first.step.size)
        ended_on_a_break += bool(first.step.size and first.step[-1] == first.done)
        sim.advance(stop, most=5)
    assert sim.n_broken > 20 and with_breaks > 5
    assert ended_on_a_break > 5 or budget == math.inf


@settings(max_examples=200, deadline=None)
@given(loads=st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.just(math.nan)),
                      min_size=1, max_size=30),
       alive=st.lists(st.booleans(), min_size=30, max_size=30))
def test_the_largest_load_is_the_live_springs_largest_nan_and_all(loads, alive):
    """``largest_load`` takes every spring's load and leaves the dead ones out: the same number as the
    largest of the live springs' loads alone — NaN when a live one is NaN, a dead one's never counts,
    ``-inf`` when none is live."""
    from bark.contract.parts import BreakerPart, largest_load

    values = np.array(loads)
    live = np.array(alive[:len(values)])
    part = BreakerPart(rule=lambda tension, params: tension > 1.0, reads=("tension",),
                       load=lambda tension, params: tension * 1.0)
    got = largest_load(part, None, values, live)
    if not live.any():
        assert got == -math.inf
    elif np.isnan(values[live]).any():
        assert math.isnan(got)
    else:
        assert got == float(np.max(values[live]))
