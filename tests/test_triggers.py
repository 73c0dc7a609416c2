"""Triggers fire exactly when they should, on the step-by-step and the compiled quiet path alike."""

from __future__ import annotations

import numpy as np
import pytest

from bark import Stop
from bark.engine.triggers import At, Every, OnEvent, Periodic


def _fired(sim, trigger, until):
    seen = []
    sim.add_action(trigger, lambda s: seen.append((s.step_count, round(s.state.t, 9))))
    sim.run(Stop(until_time=until))
    return seen


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_periodic_in_steps(make_sim, backend):
    seen = _fired(make_sim(n_bases=300, G=0.0, dt=0.05, backend=backend), Periodic(7, phase=3), until=3.0)
    assert [s for s, _ in seen] == [n for n in range(1, 61) if n % 7 == 3]


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_every_simulated_time_and_at_given_times(make_sim, backend):
    seen = _fired(make_sim(n_bases=300, G=0.0, dt=0.05, backend=backend), Every(0.5), until=3.0)
    assert [t for _, t in seen] == [0.05, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]  # t = 0 is due at the first step
    seen = _fired(make_sim(n_bases=300, G=0.0, dt=0.05, backend=backend), At([0.72, 2.0, 9.0]), until=3.0)
    assert [t for _, t in seen] == [0.75, 2.0]  # the first step at or past each time


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_first_break_fires_once_at_the_first_break(make_sim, backend):
    sim = make_sim(n_bases=300, G=0.05, dt=0.05, backend=backend)
    seen = _fired(sim, OnEvent("first-break"), until=4.0)
    first = int(sim.breaks.arrays()["step"][0])
    assert [s for s, _ in seen] == [first]


def test_composition(make_sim):
    sim = make_sim(n_bases=300, G=0.05, dt=0.05, backend="numba")
    every_5 = Periodic(5)
    seen = _fired(sim, every_5 & OnEvent("break") | At([0.3]), until=4.0)
    steps = [s for s, _ in seen]
    broke = set(int(x) for x in sim.breaks.arrays()["step"])
    assert 6 in steps  # t = 0.3
    assert all(s == 6 or (s % 5 == 0 and s in broke) for s in steps)
    assert any(s % 5 == 0 for s in steps)
    negated = _fired(make_sim(n_bases=300, G=0.0, dt=0.05), ~Periodic(2), until=1.0)
    assert [s for s, _ in negated] == [1, 3, 5, 7, 9, 11, 13, 15, 17, 19]


def test_actions_do_not_change_the_run(make_sim):
    a, b = make_sim(n_bases=300, seed=2, backend="numba"), make_sim(n_bases=300, seed=2, backend="numba")
    b.add_action(Every(0.35), lambda s: None)
    a.run(Stop(until_time=4.0))
    b.run(Stop(until_time=4.0))
    assert np.array_equal(a.state.x, b.state.x) and a.n_broken == b.n_broken
