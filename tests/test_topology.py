"""One owner of topology: the graph of record and the arrays agree after every public edit (break,
mend, join), and a backend's own copy of the intact flags never drifts from them."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bark import Stop
from conftest import build_sim


def _graph_matches_arrays(sim) -> bool:
    """Edges, their spring ids, nodes and components: the graph's (networkx's own algorithms) are the
    arrays' and the backend's patch labels."""
    import networkx as nx

    edges = {(min(i, j), max(i, j), k) for i, j, k in sim.graph.edges(data="spring")}
    ids = np.flatnonzero(sim.state.intact)
    intact = {(min(i, j), max(i, j), k) for (i, j), k in zip(sim.state.pairs[ids].tolist(), ids.tolist())}
    labels = sim.patch_labels()
    patches = {frozenset(np.flatnonzero(labels == lab).tolist()) for lab in np.unique(labels)}
    return (edges == intact and sim.graph.number_of_nodes() == sim.state.n_bases
            and sim.graph.number_of_edges() == len(ids) == sum(1 for _ in sim.graph.edges)
            and {frozenset(c) for c in nx.connected_components(sim.graph)} == patches)


def _same(a, b) -> None:
    for name in ("x", "v", "anchor", "intact"):
        assert np.array_equal(getattr(a.state, name), getattr(b.state, name)), name
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    assert all(np.array_equal(la[k], lb[k]) for k in la) and a.step_count == b.step_count


def test_a_mend_and_a_break_through_the_api_give_the_same_bits_on_both_backends():
    """Mend one spring and break another (the count of intact springs unchanged): the kernel's copy
    of the flags follows, and numba gives numpy's bits."""
    runs = []
    for backend in ("numpy", "numba"):
        sim = build_sim(n_bases=400, G=0.05, dt=0.05, seed=3, backend=backend, fmax_spread=0.05)
        sim.run(Stop(until_time=8.0))
        broken = np.flatnonzero(~sim.state.intact)
        assert sim.mend_springs(broken[:1]).tolist() == broken[:1].tolist()
        intact_one = np.flatnonzero(sim.state.intact)[10]
        assert sim.break_springs([intact_one]).tolist() == [intact_one]
        assert _graph_matches_arrays(sim)
        sim.run(Stop(until_time=12.0))
        assert _graph_matches_arrays(sim)
        runs.append(sim)
    _same(*runs)
    assert runs[0].n_broken > 20


@settings(max_examples=12, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["break", "mend", "run"]), st.integers(0, 10**6)), min_size=1, max_size=8))
def test_any_sequence_of_public_edits_keeps_graph_arrays_and_backends_together(edits):
    sims = [build_sim(n_bases=200, G=0.05, dt=0.05, seed=1, backend=b, fmax_spread=0.05) for b in ("numpy", "numba")]
    t = 4.0
    for sim in sims:
        sim.run(Stop(until_time=t))
    for what, pick in edits:
        for sim in sims:
            ids = np.flatnonzero(sim.state.intact if what == "break" else ~sim.state.intact)
            if what == "run":
                sim.run(Stop(until_time=t + 0.5))
            elif ids.size:
                chosen = ids[[pick % ids.size, (pick // 7) % ids.size]]
                (sim.break_springs if what == "break" else sim.mend_springs)(chosen)
            assert _graph_matches_arrays(sim)
        t += 0.5 if what == "run" else 0.0
        _same(*sims)


def test_joins_keep_graph_and_arrays_together():
    from bark.model.lattice import Lattice

    sim = build_sim(lattice=Lattice(n_bases=600, n_start=300, join_rate=60.0, jitter=0.05), G=0.05, backend="numba")
    sim.run(Stop(until_time=4.0))
    assert sim.state.n_bases > 300 and _graph_matches_arrays(sim)
    mended = sim.mend_springs(np.flatnonzero(~sim.state.intact))
    assert _graph_matches_arrays(sim) and sim.n_broken == 0 and (mended.size > 0 or sim.n_broken == 0)


def test_the_intact_flags_change_only_through_the_simulation():
    sim = build_sim(n_bases=200)
    with pytest.raises(ValueError, match="read-only"):
        sim.state.intact[3] = False
    with pytest.raises(AttributeError, match="break_springs"):
        sim.state.intact = np.zeros(sim.state.n_springs, bool)
    version = sim.state.intact_version
    sim.break_springs([3])
    sim.mend_springs([3, 4])  # 4 is intact: ignored
    assert sim.state.intact_version == version + 2 and sim.state.intact.all() and _graph_matches_arrays(sim)
    with pytest.raises(IndexError):
        sim.mend_springs([sim.state.n_springs])


def test_the_graph_is_a_read_only_view_of_the_state():
    """Changing the graph is refused in one line naming the way to do it; a copy is an ordinary graph;
    a state put in place (a checkpoint restored) is what the graph then shows."""
    import networkx as nx

    sim = build_sim(n_bases=200)
    for edit in (lambda g: g.add_edge(0, 1), lambda g: g.remove_edge(*next(iter(g.edges))), lambda g: g.clear(),
                 lambda g: g.add_nodes_from([10**6]), lambda g: g.remove_node(0)):
        with pytest.raises(nx.NetworkXError, match="break_springs") as err:
            edit(sim.graph)
        assert "\n" not in str(err.value)
    copy = sim.graph.copy()
    copy.remove_edge(*next(iter(copy.edges)))
    assert copy.number_of_edges() == sim.graph.number_of_edges() - 1 and _graph_matches_arrays(sim)
    other = build_sim(n_bases=300, seed=9)
    other.run(Stop(until_time=30.0))
    sim.state = other.state
    assert sim.graph.number_of_nodes() == 300 and _graph_matches_arrays(sim) and other.n_broken > 0
    with pytest.raises(TypeError, match="copy"):
        import pickle

        pickle.dumps(sim.graph)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_snapshot_and_restore_go_on_exactly(backend):
    """``Simulation.snapshot()`` / ``restore()``, the one way a run's state goes out and comes back:
    a run restored from a snapshot taken mid-run (bases still joining, springs broken, a spring mended)
    ends with the bits of the run it was taken of; a built simulation refuses a snapshot."""
    import pickle

    from bark.model.lattice import Lattice

    def make():
        return build_sim(lattice=Lattice(n_bases=500, n_start=300, join_rate=40.0, jitter=0.05), G=0.08, seed=4,
                         backend=backend, fmax_spread=0.05, stepping="adaptive")

    whole = make()
    whole.run(Stop(until_time=3.0))
    whole.mend_springs(np.flatnonzero(~whole.state.intact)[:1])
    kept = whole.snapshot()
    snap = pickle.loads(pickle.dumps(kept))  # plain data: it travels
    assert whole.n_broken > 0 and 300 < whole.state.n_bases < 500
    resumed = make().restore(snap)
    for sim in (whole, resumed):
        sim.run(Stop(until_time=7.0))
    _same(whole, resumed)
    assert all(np.array_equal(kept.arrays[k], snap.arrays[k]) for k in snap.arrays)  # the run left it as it was
    assert resumed.events == whole.events and resumed.rng.random() == whole.rng.random()
    assert _graph_matches_arrays(resumed)
    with pytest.raises(RuntimeError, match="not been built"):
        resumed.restore(snap)
