"""Bases that join during a run (primary growth at the top of the segment): the invariants hold
whenever and however many join, a checkpoint taken while the number of bases grows resumes bit for
bit, a pickled simulation goes on in another process, and compiled forms of third-party strategies
take the compiled path."""

from __future__ import annotations

import json
import pickle
import subprocess
import sys

import attrs
import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bark import Lattice, Stop
from bark.studies import runner
from bark.engine.scene import Scene
from bark.contract.parts import IntegratorPart
from bark.contract.strategies import Integrator
from bark.validators import in_range
from bark_plugins.integrators import EulerCromer

from conftest import REPO_ROOT, build_sim


def _invariants(sim, previous_intact: np.ndarray) -> None:
    s = sim.state
    edges = {tuple(sorted(e)) for e in sim.graph.edges}
    assert edges == {tuple(p) for p in s.pairs[s.intact].tolist()}, "graph and arrays disagree"
    assert sim.graph.number_of_nodes() == s.n_bases
    assert s.is_finite() and np.isfinite(s.anchor).all()
    r = np.broadcast_to(sim.growth.radius(s.t, s.x[:, 2]), (s.n_bases,))
    np.testing.assert_allclose(np.hypot(s.x[:, 0], s.x[:, 1]), r, rtol=1e-12)
    m = previous_intact.size
    assert not np.any(s.intact[:m] & ~previous_intact), "a broken spring came back"
    labels = sim.patch_labels()
    components = {frozenset(c) for c in nx.connected_components(sim.graph)}
    assert components == {frozenset(np.flatnonzero(labels == k).tolist()) for k in np.unique(labels)}


@settings(max_examples=15, deadline=None)
@given(
    joins=st.lists(st.tuples(st.floats(0.05, 3.0), st.integers(1, 80)), min_size=1, max_size=6),
    backend=st.sampled_from(["numpy", "numba"]),
    seed=st.integers(0, 1000),
)
def test_bases_joining_at_random_times_keep_every_invariant(joins, backend, seed):
    sim = build_sim(n_bases=2000, G=0.05, dt=0.05, seed=seed, backend=backend, fmax_spread=0.05)
    sim.lattice = attrs.evolve(sim.lattice, n_start=300, join_rate=1.0, join_every=1e6)  # joins by hand below
    t = 0.0
    for wait, count in joins:
        before = sim.state.intact.copy()
        t += wait
        sim.run(Stop(until_time=t))
        _invariants(sim, before)
        n, m = sim.state.n_bases, sim.state.n_springs
        ids = sim.join(*sim.lattice.sites(sim.radius, sim.rng, n, count))
        assert ids.tolist() == list(range(n, n + count))
        new = np.arange(m, sim.state.n_springs)
        assert new.size > 0 and np.all(sim.state.pairs[new] < n + count)
        assert np.all(sim.state.born[n:] == sim.state.t)
        np.testing.assert_allclose(sim.tension()[new], 0.0, atol=1e-15)  # a new spring is at rest
        assert sim.state.intact[new].all()
        _invariants(sim, np.concatenate([sim.state.intact[:m], np.ones(new.size, bool)]))
    assert sim.state.capacity[0] >= sim.state.n_bases  # grown by doubling, not a copy per base


def test_the_lattice_grows_at_its_rate_and_the_kernel_stops_where_bases_join():
    lattice = Lattice(n_bases=1200, n_start=600, join_rate=50.0, join_every=2.0)
    assert [lattice.bases_at(t) for t in (0.0, 1.9, 2.0, 5.0, 100.0)] == [600, 600, 700, 800, 1200]
    assert lattice.next_join(0.0, 600) == 2.0 and lattice.next_join(11.0, 1100) == 12.0
    assert lattice.next_join(12.0, 1200) is None
    sim = build_sim(n_bases=1200, G=0.05, dt=0.05, backend="numba")
    sim.lattice = lattice
    sizes = []
    sim.run(Stop(until_time=13.0), lambda s: sizes.append((s.state.t, s.state.n_bases)))
    assert sim.state.n_bases == 1200
    for t, n in sizes:  # each call ended where bases joined: never past a due time without them
        assert n == lattice.bases_at(t)
    assert np.unique(sim.state.born).tolist() == [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0]


def test_later_bases_have_longer_rest_lengths():
    """Springs made as bases join span the trunk as it is then, grown: longer rest lengths."""
    sim = build_sim(n_bases=1200, G=0.05, dt=0.05, backend="numba", jitter=0.0)
    sim.lattice = attrs.evolve(sim.lattice, n_start=400, join_rate=100.0, join_every=2.0, jitter=0.0)
    sim.mechanics = attrs.evolve(sim.mechanics, f_max=1e9)
    sim.run(Stop(until_time=12.0))
    s = sim.state
    born = s.born[s.pairs[:, 1]]
    for o in sim.lattice.offsets:
        block = (s.pairs[:, 1] - s.pairs[:, 0]) == o
        early, late = s.rest[block & (born == 0.0)], s.rest[block & (born == born.max())]
        assert late.mean() > early.mean() * 1.05


def _growing(**run):
    return Scene.from_dict({"lattice": {"n_bases": 1500, "n_start": 700, "join_rate": 40.0, "join_every": 1.0},
                            "growth": {"G": 0.05}, "run": {"until_time": 30.0, **run}})


@pytest.mark.parametrize("run", [{}, {"dt": 0.05, "stepping": "fixed"}, {"backend": "numpy"}])
def test_a_checkpoint_taken_while_bases_join_resumes_bit_for_bit(tmp_path, run):
    whole, part = tmp_path / "whole", tmp_path / "part"
    runner.run(_growing(**run), whole)
    seen = []
    out = runner.run(_growing(**run), part, checkpoint_every=1e-9, observe=lambda s, stop: seen.append(s.state.t),
                     interrupted=lambda: "interrupted" if seen and seen[-1] >= 11.0 else None)
    assert out.stop_reason == "interrupted" and 700 < out.sim.state.n_bases < 1500
    resumed = runner.resume(part)
    assert resumed.sim.state.n_bases == 1500
    for name in ("breaks.csv", "state.npz", "patches.csv"):
        assert (part / name).read_bytes() == (whole / name).read_bytes(), name


def test_a_pickled_simulation_goes_on_in_another_process(tmp_path):
    """State is data: a simulation pickled mid-run (bases still joining) and finished in a fresh
    interpreter ends exactly where the one that never left ends."""
    scene = _growing()
    sim, stop = scene.simulation(), scene.stop()
    sim.run(Stop(until_time=9.0))
    (tmp_path / "sim.pkl").write_bytes(pickle.dumps(sim))
    sim.run(stop)
    code = ("import pickle, sys, numpy as np\n"
            "from bark import Stop\n"
            f"sim = pickle.loads(open({str(tmp_path / 'sim.pkl')!r}, 'rb').read())\n"
            "sim.run(Stop(until_time=30.0))\n"
            f"np.savez({str(tmp_path / 'far.npz')!r}, x=sim.state.x, intact=sim.state.intact, "
            "spring=sim.breaks.arrays()['spring'], n=sim.state.n_bases)\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    with np.load(tmp_path / "far.npz") as far:
        assert int(far["n"]) == sim.state.n_bases == 1500
        assert np.array_equal(far["x"], sim.state.x) and np.array_equal(far["intact"], sim.state.intact)
        assert np.array_equal(far["spring"], sim.breaks.arrays()["spring"])


def leapfrog_update(x, v, f, hm, h, p):
    """A third party's update: semi-implicit Euler written the other way round (position with the old
    velocity, then the velocity), the velocity then kept less a share ``p[0]`` (its own number) — a
    different method, so its results differ."""
    x = x + v * h
    return x, (v + f * hm) * (1.0 - p[0])


@attrs.frozen(kw_only=True)
class ThirdPartyIntegrator(Integrator):
    drag: float = attrs.field(default=0.0, validator=in_range(0.0, 1.0, hi_open=True))

    def part(self) -> IntegratorPart:
        return IntegratorPart(update=leapfrog_update, params=(self.drag,))

    def stability_limit(self, state, forces) -> float:
        return EulerCromer().stability_limit(state, forces)


def test_a_third_party_integrators_numbers_reach_the_kernel_to_the_bit():
    runs = {}
    for backend in ("numpy", "numba"):
        for drag in (0.0, 0.05):
            sim = build_sim(n_bases=400, G=0.05, dt=0.05, backend=backend, integrator=ThirdPartyIntegrator(drag=drag))
            sim.run(Stop(until_time=5.0))
            runs[backend, drag] = sim
    for drag in (0.0, 0.05):
        assert np.array_equal(runs["numpy", drag].state.x, runs["numba", drag].state.x)
    assert not np.array_equal(runs["numba", 0.0].state.x, runs["numba", 0.05].state.x)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_third_party_integrator_with_a_compiled_form_takes_the_compiled_path(backend):
    sim = build_sim(n_bases=400, G=0.05, dt=0.05, backend=backend, integrator=ThirdPartyIntegrator())
    calls = []
    sim.run(Stop(until_time=5.0), lambda s: calls.append(s.step_count))
    assert len(calls) < sim.step_count / 5  # many steps per call: the kernel ran the plugin's update
    assert sim.n_broken > 0 and sim.state.is_finite()
    reference = build_sim(n_bases=400, G=0.05, dt=0.05, backend=backend)
    reference.run(Stop(until_time=5.0))
    assert not np.array_equal(reference.state.x, sim.state.x)  # its own method, not Euler–Cromer's
    if backend == "numba":
        from bark.engine.kernels import numba_backend

        assert any(("update", leapfrog_update) in key for key in numba_backend._SPECIALIZED)
        # and the generated wrapper is a file, cached on disk: it names the plugin's function
        names = [p.read_text() for p in numba_backend.cache_dir().glob("bark_steps_*.py")]
        assert any("leapfrog_update" in text for text in names)


def test_growing_scene_runs_through_the_command_line(tmp_path):
    from click.testing import CliRunner

    from bark_cli.main import cli

    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["simulate", "--scene", str(REPO_ROOT / "bark" / "scenes" / "growing.toml"),
                                      "--until-time", "20", "--n-bases", "1500", "--n-start", "800", "--quiet",
                                      "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert 800 < summary["n_bases"] <= 1500
