"""The compiled quiet path (Simulation.advance) must notice what step() notices."""

from __future__ import annotations

import numpy as np
import pytest

from bark import Stop
from bark.errors import NonFiniteStateError


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_non_finite_base_without_springs_is_caught(make_sim, backend):
    """A base whose springs are all broken is seen by no tension; a NaN on it must still stop the run."""
    sim = make_sim(n_bases=300, G=0.0, backend=backend)
    sim.run(Stop(until_time=0.5))
    touching = np.flatnonzero((sim.state.pairs == 7).any(axis=1))
    sim.break_springs(touching)
    with sim.state.writing("anchor"):
        sim.state.anchor[7, 0] = np.nan  # its anchor pulls it to NaN on the next step
    steps, t = sim.step_count, sim.state.t
    with pytest.raises(NonFiniteStateError):
        sim.run(Stop(until_time=2.0))
    assert sim.step_count == steps and sim.state.t == pytest.approx(t)
    assert np.isfinite(sim.state.x).all()


def test_quiet_path_gives_breakers_the_tensions_of_the_state_it_left(make_sim):
    """Whenever a compiled call returns with springs to break, the tensions the breaker sees are
    those of the state the call left."""
    from bark_plugins.breakers import ThresholdBreaker

    seen = []

    class Checking(ThresholdBreaker):
        def part(self):  # the threshold names candidates: the kernel returns when a spring is over it
            import attrs

            return attrs.evolve(super().part(), decides=False)

        def select(self, state, tension, rng):
            seen.append(float(np.abs((tension - sim.tension())[state.intact]).max()))
            return super().select(state, tension, rng)

    sim = make_sim(n_bases=300, backend="numba", breakers=[Checking()])  # noqa: F841 (seen by Checking)
    advances = []
    sim.run(Stop(until_time=3.0), lambda s: advances.append(s.step_count))
    assert sim.n_broken > 0 and len(seen) > 5
    assert len(advances) < sim.step_count  # calls of several steps, returning when a spring is over
    assert max(seen) <= 1e-15


def test_patch_labels_agree_between_backends(make_sim):
    """numba's union-find numbers components exactly as scipy's connected_components does."""
    from bark.engine import kernels

    sim = make_sim(n_bases=400, seed=2, fmax_spread=0.05)
    sim.run(Stop(until_time=4.0))
    a, b = kernels.load("numpy").patch_labels(sim.state), kernels.load("numba").patch_labels(sim.state)
    assert a.max() > 5  # a real pattern with several components
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("stepping, split", [("fixed", 2.37), ("adaptive", 1.8), ("adaptive", 3.3)])
def test_where_a_run_is_split_does_not_change_a_bit(make_sim, stepping, split):
    """Stopping and going on (as a resumed run does) gives bit for bit the uninterrupted run: the
    compiled calls' boundaries do not enter the arithmetic."""
    kw = dict(n_bases=400, G=0.05, dt=0.05 if stepping == "fixed" else 0.3, seed=4, stepping=stepping, backend="numba")
    whole, split_run = make_sim(**kw), make_sim(**kw)
    whole.run(Stop(until_time=6.0))
    split_run.run(Stop(until_time=split))
    split_run.run(Stop(until_time=6.0))
    assert whole.n_broken > 20
    for a, b in [(whole.state.x, split_run.state.x), (whole.state.v, split_run.state.v),
                 (whole.state.anchor, split_run.state.anchor), (whole.state.intact, split_run.state.intact)]:
        assert np.array_equal(a, b)
    assert all(np.array_equal(whole.breaks.arrays()[k], split_run.breaks.arrays()[k]) for k in ("spring", "step", "tension"))


def test_step_and_advance_are_bit_identical(make_sim):
    kw = dict(n_bases=400, G=0.05, dt=0.05, seed=6, backend="numba")
    stepped, chunked = make_sim(**kw), make_sim(**kw)
    stop = Stop(until_time=5.0)
    chunked.run(stop)
    while stop.reason(stepped) is None:
        stepped.step()
    assert chunked.n_broken > 20
    assert np.array_equal(stepped.state.x, chunked.state.x) and np.array_equal(stepped.state.anchor, chunked.state.anchor)
