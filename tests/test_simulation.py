"""The Simulation loop: surface constraint, breaking, determinism, degenerate events, stopping."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from bark import Lattice, Mechanics, Simulation, State, Stop
from bark.engine.stepping import Numerics
from bark.errors import NonFiniteStateError
from bark_plugins.breakers import ThresholdBreaker
from bark_plugins.growth import LinearGrowth, SqrtGrowth
from bark_plugins.integrators import EulerCromer

from conftest import build_sim


def _surface_error(sim: Simulation) -> float:
    """Largest relative deviation of any base or anchor from the growth radius at sim's time."""
    s = sim.state
    r_x = np.broadcast_to(sim.growth.radius(s.t, s.x[:, 2]), s.x[:, 2].shape)
    r_a = np.broadcast_to(sim.growth.radius(s.t, s.anchor[:, 2]), s.anchor[:, 2].shape)
    ex = np.abs(np.hypot(s.x[:, 0], s.x[:, 1]) / r_x - 1.0)
    ea = np.abs(np.hypot(s.anchor[:, 0], s.anchor[:, 1]) / r_a - 1.0)
    return float(max(ex.max(), ea.max()))


# -- surface constraint ------------------------------------------------------------------------


@given(
    jitter=st.floats(0.0, 0.2),
    G=st.floats(0.005, 0.2),
    seed=st.integers(0, 2**31 - 1),
    dt=st.floats(0.001, 0.1),
    linear=st.booleans(),
    backend=st.sampled_from(["numpy", "numba"]),
    chunked=st.booleans(),
    stepping=st.sampled_from(["fixed", "adaptive"]),
)
def test_surface_constraint_holds_after_every_step(jitter, G, seed, dt, linear, backend, chunked, stepping):
    """After every step (``step``), and after every run of compiled quiet steps (``advance``)."""
    growth = LinearGrowth(G=G) if linear else SqrtGrowth(G=G)
    sim = Simulation(
        lattice=Lattice(n_bases=200, jitter=jitter),
        mechanics=Mechanics(f_max=0.002),
        growth=growth,
        integrator=EulerCromer(),
        breakers=[ThresholdBreaker()],
        numerics=Numerics(dt=dt, backend=backend, stepping=stepping),
        seed=seed,
    )
    assert _surface_error(sim) < 1e-12  # at t = 0 too
    r0 = sim.radius
    errors = []
    stop = Stop(until_time=40 * dt)
    while stop.reason(sim) is None:
        sim.advance(stop) if chunked else sim.step()
        errors.append(_surface_error(sim))
    assert sim.step_count == 40 or stepping == "adaptive"  # adaptive steps may be halved
    assert len(errors) == sim.step_count or chunked
    assert max(errors) < 1e-12
    if G > 0:
        assert sim.radius > r0  # the surface really moved: the check is not vacuous


def test_surface_constraint_removes_radial_velocity(small_sim):
    small_sim.run(Stop(until_time=1.0))
    s = small_sim.state
    e_r = s.x[:, :2] / np.hypot(s.x[:, 0], s.x[:, 1])[:, None]
    v_r = np.einsum("ij,ij->i", s.v[:, :2], e_r)
    assert np.abs(s.v).max() > 0
    np.testing.assert_allclose(v_r, 0.0, atol=1e-12 * np.abs(s.v).max())


def test_initial_springs_are_unstressed(make_sim):
    """Rest lengths are taken from the (jittered) initial positions: nothing starts stressed."""
    sim = make_sim(jitter=0.1)
    np.testing.assert_allclose(sim.tension(), 0.0, atol=1e-15)
    np.testing.assert_allclose(sim.forces.total(sim.state), 0.0, atol=1e-15)


# -- breaking ----------------------------------------------------------------------------------


def test_broken_set_only_grows_and_nothing_goes_non_finite(make_sim):
    sim = make_sim(n_bases=400, fmax_spread=0.05, seed=3)
    previous = sim.state.intact.copy()
    counts = []

    def observe(s):
        nonlocal previous
        intact = s.state.intact
        assert not np.any(intact & ~previous), "a broken spring came back"
        assert s.state.is_finite()
        assert np.all(np.isfinite(s.state.anchor))
        previous = intact.copy()
        counts.append(s.n_broken)

    sim.run(Stop(until_time=6.0), observe)
    assert counts[-1] > 0.2 * sim.state.n_springs  # plenty of breaking happened
    assert all(a <= b for a, b in zip(counts, counts[1:]))
    assert counts[-1] == len(sim.breaks)


def test_break_log_matches_intact_mask_and_logs_each_spring_once(broken_sim):
    log = broken_sim.breaks.arrays()
    s = broken_sim.state
    assert set(log) == {"spring", "i", "j", "step", "t", "tension"}
    assert len(np.unique(log["spring"])) == log["spring"].size
    np.testing.assert_array_equal(np.sort(log["spring"]), np.flatnonzero(~s.intact))
    np.testing.assert_array_equal(log["i"], s.pairs[log["spring"], 0])
    np.testing.assert_array_equal(log["j"], s.pairs[log["spring"], 1])
    assert np.all(np.diff(log["step"]) >= 0) and np.all(np.diff(log["t"]) >= 0)
    # the threshold breaker only breaks springs in tension above their own threshold
    assert np.all(log["tension"] > s.fmax[log["spring"]])


def test_graph_of_record_agrees_with_arrays_after_breaks(broken_sim):
    s = broken_sim.state
    g = broken_sim.graph
    assert g.number_of_nodes() == s.n_bases
    edges = {frozenset(e) for e in g.edges()}
    intact_pairs = {frozenset(map(int, p)) for p in s.pairs[s.intact]}
    assert edges == intact_pairs
    assert g.number_of_edges() == np.count_nonzero(s.intact)
    assert not any(data for _, data in g.nodes(data=True))
    assert all(tuple(sorted(s.pairs[k])) == tuple(sorted((i, j))) for i, j, k in g.edges(data="spring"))


def test_graph_of_record_agrees_with_arrays_as_bases_join_and_springs_break():
    """Bases joining during the run (primary growth) and springs breaking: the graph's nodes are the
    bases and its edges the intact springs after every advance, with no attribute mapping of its own."""
    sim = build_sim(n_bases=500, seed=3, lattice=Lattice(n_bases=500, n_start=300, join_rate=40.0, join_every=0.3,
                                                         jitter=0.05), fmax_spread=0.05, G=0.08)
    joined = broke = False
    for _ in sim.irun(Stop(until_time=6.0)):
        s, g = sim.state, sim.graph
        assert g.number_of_nodes() == s.n_bases and sorted(g.nodes) == list(range(s.n_bases))
        assert {frozenset(e) for e in g.edges()} == {frozenset(map(int, p)) for p in s.pairs[s.intact]}
        joined, broke = joined or s.n_bases > 300, broke or sim.n_broken > 0
    assert joined and broke and sim.state.n_bases == 500
    assert all(set(d) == {"spring"} for *_, d in sim.graph.edges(data=True))


@given(offsets=st.lists(st.integers(1, 40), min_size=1, max_size=3, unique=True), count=st.integers(1, 150),
       data=st.data())
def test_new_pairs_of_a_run_of_new_bases_are_those_of_any_container(offsets, count, data):
    """The springs a run of joining bases makes (found from ranges) are those the general path finds
    asking a plain container which bases are present."""
    from bark.model.graph import LeafBaseGraph

    a = data.draw(st.integers(0, count - 1))
    b = data.draw(st.integers(a + 1, count))
    lattice = Lattice(n_bases=200, offsets=tuple(offsets))
    graph = LeafBaseGraph(lambda: SimpleNamespace(n_bases=count))  # what a joining base asks: which bases exist
    general = lattice.new_pairs(np.arange(a, b), set(range(count)))
    for present in (graph, range(count)):
        got = lattice.new_pairs(np.arange(a, b), present)
        assert got.dtype == general.dtype and np.array_equal(got, general)
    ids = data.draw(st.lists(st.integers(0, count - 1), min_size=1, max_size=8))  # any ids, repeated or not
    assert np.array_equal(lattice.new_pairs(np.array(ids), graph), lattice.new_pairs(np.array(ids), set(range(count))))


def test_break_springs_ignores_already_broken_ids_and_logs_once(small_sim):
    sim = small_sim
    m = sim.state.n_springs
    got = sim.break_springs([5, 7, 7, 5])
    np.testing.assert_array_equal(got, [5, 7])
    assert sim.n_broken == 2 and len(sim.breaks) == 2
    assert not sim.graph.has_edge(*map(int, sim.state.pairs[5]))
    got = sim.break_springs(np.array([7, 5, 9]))
    np.testing.assert_array_equal(got, [9])
    assert sim.break_springs([5, 7, 9]).size == 0
    log = sim.breaks.arrays()
    np.testing.assert_array_equal(np.sort(log["spring"]), [5, 7, 9])
    assert sim.n_broken == 3 and np.count_nonzero(sim.state.intact) == m - 3
    assert sim.graph.number_of_edges() == m - 3


@pytest.mark.parametrize("bad", [-1, "m"])
def test_break_springs_rejects_out_of_range_ids(small_sim, bad):
    m = small_sim.state.n_springs
    with pytest.raises(IndexError):
        small_sim.break_springs([0, m if bad == "m" else bad])
    assert small_sim.n_broken == 0 and len(small_sim.breaks) == 0
    assert small_sim.graph.number_of_edges() == m


def test_break_springs_changes_patches(small_sim):
    sim = small_sim
    assert sim.patch_count(1) == 1
    # isolate base 0 entirely: break every spring touching it
    touching = np.flatnonzero((sim.state.pairs == 0).any(axis=1))
    sim.break_springs(touching)
    labels = sim.patch_labels()
    assert np.count_nonzero(labels == labels[0]) == 1
    assert sim.patch_count(1) == 2


def test_threshold_breaker_selects_per_spring():
    """Equal tensions, different thresholds: exactly the springs over their own threshold."""
    n = 6
    pairs = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5]])
    state = State.from_arrays(dict(
        x=np.zeros((n, 3)), v=np.zeros((n, 3)), anchor=np.zeros((n, 3)), anchor_dir=np.zeros((n, 2)), born=np.zeros(n),
        pairs=pairs, rest=np.ones(5), fmax=np.array([1.0, 0.1, 1.0, 0.1, 1.0]),
        intact=np.array([True, True, True, False, True]),
    ))
    tension = np.full(5, 0.5)
    ids = ThresholdBreaker().select(state, tension, np.random.default_rng(0))
    np.testing.assert_array_equal(ids, [1])  # 3 is over its threshold but already broken
    ids = ThresholdBreaker().select(state, np.full(5, -5.0), np.random.default_rng(0))
    assert ids.size == 0  # compression never breaks


def test_per_spring_thresholds_stay_per_spring(make_sim):
    """A weakened spring breaks first; springs sharing its bases, under the same tension, do not."""
    sim = make_sim(n_bases=400, jitter=0.0, G=0.05)
    s = sim.state
    target = int(np.flatnonzero((s.pairs[:, 0] == 180) & (s.pairs[:, 1] == 201))[0])
    with s.writing("fmax"):
        s.fmax[target] = 0.5 * sim.mechanics.f_max
    while sim.n_broken == 0:
        sim.step()
        assert sim.state.t < 5.0
    log = sim.breaks.arrays()
    np.testing.assert_array_equal(log["spring"], [target])
    tension = sim.tension()
    shares_a_base = np.flatnonzero(np.isin(s.pairs, s.pairs[target]).any(axis=1))
    same_tension = [k for k in shares_a_base if k != target and tension[k] >= s.fmax[target]]
    assert same_tension, "test set-up: some neighbour should carry the weakened spring's tension"
    assert np.all(s.intact[same_tension])


# -- determinism -------------------------------------------------------------------------------


def test_same_seed_gives_identical_run(make_sim):
    runs = []
    for _ in range(2):
        sim = make_sim(n_bases=300, seed=42, fmax_spread=0.05)
        sim.run(Stop(until_time=3.0))
        runs.append(sim)
    a, b = runs
    assert a.n_broken > 0
    np.testing.assert_array_equal(a.state.x, b.state.x)
    np.testing.assert_array_equal(a.state.v, b.state.v)
    np.testing.assert_array_equal(a.state.fmax, b.state.fmax)
    np.testing.assert_array_equal(a.state.intact, b.state.intact)
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    for key in la:
        np.testing.assert_array_equal(la[key], lb[key])


def test_different_seeds_give_different_jitter(make_sim):
    a, b = make_sim(seed=1), make_sim(seed=2)
    assert not np.array_equal(a.state.x, b.state.x)
    assert not np.allclose(a.state.anchor_dir, b.state.anchor_dir)  # the sites themselves
    c, d = make_sim(seed=1, fmax_spread=0.05), make_sim(seed=2, fmax_spread=0.05)
    assert not np.array_equal(c.state.fmax, d.state.fmax)


def test_zero_jitter_gives_the_exact_lattice(make_sim):
    sim = make_sim(jitter=0.0, seed=7)
    other = make_sim(jitter=0.0, seed=8)
    np.testing.assert_array_equal(sim.state.x, other.state.x)
    i = np.arange(sim.state.n_bases)
    theta = np.arctan2(sim.state.x[:, 1], sim.state.x[:, 0])
    expected = np.angle(np.exp(1j * i * math.radians(sim.lattice.divergence_deg)))
    np.testing.assert_allclose(np.angle(np.exp(1j * (theta - expected))), 0.0, atol=1e-9)
    np.testing.assert_allclose(sim.state.x[:, 2], i * sim.lattice.rise, atol=1e-12)


# -- degenerate events -------------------------------------------------------------------------


def test_exact_lattice_triggers_degenerate_event(make_sim):
    sim = make_sim(n_bases=600, jitter=0.0, G=0.014, f_max=0.0028, dt=0.05)
    reason = sim.run(Stop(until_time=20.0))
    assert reason == "time"
    events = [e for e in sim.events if e["kind"] == "degenerate"]
    assert events, "the exact lattice should fail in one degenerate step"
    e = events[0]
    assert e["n_springs"] > sim.degenerate_fraction * sim.state.n_springs
    assert 13.0 <= e["t"] <= 17.0
    assert {"kind", "t", "step"} <= set(e)


def test_on_degenerate_stop_stops_the_run(make_sim):
    sim = make_sim(n_bases=600, jitter=0.0, G=0.014, f_max=0.0028, dt=0.05, on_degenerate="stop")
    reason = sim.run(Stop(until_time=40.0))
    assert reason == "degenerate" and sim.stop_reason == "degenerate"
    assert sim.state.t < 20.0
    assert sim.events and sim.events[-1]["kind"] == "degenerate"
    assert sim.events[-1]["step"] == sim.step_count


def test_jittered_lattice_with_threshold_spread_has_no_degenerate_event(make_sim):
    sim = make_sim(n_bases=600, jitter=0.05, G=0.014, f_max=0.0028, dt=0.05, fmax_spread=0.05)
    sim.run(Stop(until_time=20.0))
    assert sim.n_broken > 0
    assert not [e for e in sim.events if e["kind"] == "degenerate"]


# -- stopping ----------------------------------------------------------------------------------


def test_until_time_stops_and_reports(make_sim):
    sim = make_sim(dt=0.05)
    assert sim.run(Stop(until_time=1.0)) == "time"
    assert sim.stop_reason == "time"
    assert sim.step_count == 20
    assert sim.state.t == pytest.approx(1.0, abs=1e-12)


def test_until_radius_stops_and_reports(make_sim):
    sim = make_sim(G=0.05, dt=0.05)
    target = 0.2 + 0.05 * math.sqrt(2.0)  # reached at t = 2
    assert sim.run(Stop(until_radius=target, until_time=100.0)) == "radius"
    assert sim.radius >= target
    assert sim.state.t == pytest.approx(2.0, abs=0.051)


def test_until_patches_stops_and_reports(make_sim):
    sim = make_sim(n_bases=400, G=0.05, fmax_spread=0.05, seed=5)
    stop = Stop(until_patches=3, min_patch_size=7, until_time=50.0)
    assert sim.run(stop) == "patches"
    assert sim.patch_count(7) >= 3
    assert sim.state.t < 50.0


def test_stop_needs_a_condition():
    with pytest.raises(ValueError):
        Stop()


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_observe_called_after_every_advance(make_sim, backend):
    """Steps run in calls of the backend's kernel, several at a time (numpy too: the same loop);
    observe sees each call's end, and the run ends exactly at the stop time."""
    sim = make_sim(backend=backend)
    seen = []
    sim.run(Stop(until_time=2.0), lambda s: seen.append(s.step_count))
    assert seen == sorted(set(seen)) and seen[-1] == 40 and len(seen) < 40
    assert sim.state.t == pytest.approx(2.0)


def test_observe_sees_every_step_when_a_breaker_must(make_sim):
    """A breaker whose part names every stretched spring a candidate is asked after every step."""
    from bark_plugins.breakers import ProbabilisticBreaker

    sim = make_sim(breakers=[ProbabilisticBreaker()])
    seen = []
    sim.run(Stop(until_time=0.5), lambda s: seen.append(s.step_count))
    assert seen == list(range(1, 11))


def test_dt_above_stability_limit_never_runs_silently():
    """dt far above the Euler–Cromer stability bound (h_max ≈ 0.37): refused up front, or the run
    stops with NonFiniteStateError — never a silent NaN state."""
    try:
        sim = build_sim(n_bases=200, dt=0.9, G=0.0, f_max=10.0).build()
    except ValueError:  # BarkError: refused before running
        return
    with sim.state.writing("v"):
        sim.state.v[:, 2] = 1e-3  # a kick, so that something can grow
    with pytest.raises(NonFiniteStateError):
        sim.run(Stop(until_time=5000.0))


def test_non_finite_state_raises(make_sim):
    sim = make_sim()
    sim.run(Stop(until_time=0.5))
    with sim.state.writing("x"):
        sim.state.x[3, 0] = np.nan
    with pytest.raises(NonFiniteStateError):
        sim.run(Stop(until_time=1.0))
