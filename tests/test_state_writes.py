"""The state's fields are read-only outside the engine and the writes declared to it: a write nobody
declared fails at once, in one line that says how to declare it, and a declared write reaches every
backend (no copy of a field goes stale unseen: the numba frame keeps the rest lengths in its own order)."""

from __future__ import annotations

import attrs
import numpy as np
import pytest

from bark import Stop
from bark.engine.triggers import Periodic
from bark.errors import StateWriteError
from bark.model.state import BASE_FIELDS, FIXED, SPRING_FIELDS
from bark_plugins.breakers import ThresholdBreaker
from bark_plugins.integrators import EulerCromer
from conftest import build_sim

FIELDS = (*BASE_FIELDS, *SPRING_FIELDS)

WRITES = {  # every way a script writes into an array, as a statement on the field's rows `a`
    "item": "a[0] = a[0]",
    "slice": "a[:] = a",
    "fancy": "a[[0, 1]] = a[[0, 1]]",
    "mask": "a[np.zeros(len(a), bool)] = a[:0]",
    "column": "a.reshape(len(a), -1)[:, 0][0] = 0",
    "in place": "a += 0",
    "ufunc out": "np.multiply(a, 1, out=a)",
}


@pytest.fixture(scope="module")
def sim():
    s = build_sim(n_bases=120, seed=3)
    s.run(Stop(until_time=1.0))
    return s


@pytest.mark.parametrize("field", FIELDS)
@pytest.mark.parametrize("how", WRITES)
def test_every_undeclared_write_of_every_field_fails_in_one_line_and_changes_nothing(sim, field, how):
    before = np.array(getattr(sim.state, field))
    version = sim.state.version
    with pytest.raises(StateWriteError) as err:
        exec(WRITES[how], {"np": np, "a": getattr(sim.state, field)})
    message = str(err.value)
    assert "\n" not in message and f"state.{field}" in message
    assert ("writing(" in message) if field not in FIXED else FIXED[field] in message
    assert np.array_equal(getattr(sim.state, field), before) and sim.state.version == version


@pytest.mark.parametrize("field", FIELDS)
def test_assigning_the_attribute_fails_too(sim, field):
    with pytest.raises(StateWriteError, match=f"state.{field}"):
        setattr(sim.state, field, getattr(sim.state, field))


def test_the_error_is_a_value_error_and_an_attribute_error_as_numpy_and_properties_raise(sim):
    with pytest.raises(ValueError):
        sim.state.rest[0] = 1.0
    with pytest.raises(AttributeError):
        sim.state.rest = 1.0


@pytest.mark.parametrize("field", sorted(FIXED))
def test_pairs_and_intact_cannot_be_opened(sim, field):
    with pytest.raises(StateWriteError, match=f"state.{field} is read-only"):
        with sim.state.writing(field):
            pass


def test_an_unknown_field_is_named(sim):
    with pytest.raises(StateWriteError, match="no field 'rest_length'"):
        with sim.state.writing("rest_length"):
            pass


def test_a_declared_write_is_counted_per_field_and_closes_again():
    s = build_sim(n_bases=60).state
    assert s.edited("rest") == 0
    with s.writing("rest", "x"):
        s.rest[0] = s.rest[0] * 1.5
        s.x[1, 2] += 1e-9
    assert s.edited("rest") == s.edited("x") == s.version > 0 and s.edited("fmax") == 0
    with pytest.raises(StateWriteError):
        s.rest[0] = 1.0


def test_arithmetic_on_a_field_gives_plain_writable_arrays(sim):
    doubled = sim.state.rest * 2.0
    assert type(doubled) is np.ndarray and doubled.flags.writeable
    assert type(np.array(sim.state.x)) is np.ndarray and type(float(sim.state.rest.sum())) is float


@attrs.frozen(kw_only=True)
class _Scribbler(ThresholdBreaker):
    """A breaker whose Python ``select`` writes a field it did not declare."""

    def select(self, state, tension, rng):
        state.fmax[:] = 1e9  # what a breaker may not do
        return np.empty(0, np.int64)


@attrs.frozen(kw_only=True)
class _Pusher(EulerCromer):
    """An integrator whose Python ``step`` writes a field beyond its kind's (x and v)."""

    def step(self, state, dt, forces):
        super().step(state, dt, forces)
        state.rest[:] = state.rest * 1.0


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("strategy", ["breaker", "integrator"])
def test_a_strategy_writing_what_it_did_not_declare_fails_at_once(backend, strategy):
    kwargs = {"breakers": [_Scribbler()]} if strategy == "breaker" else {"integrator": _Pusher()}
    sim = build_sim(n_bases=120, backend=backend, **kwargs)
    with pytest.raises(StateWriteError, match="state.(fmax|rest) is read-only outside the engine"):
        sim.run(Stop(until_time=2.0))
    assert sim.state.edited("rest", "fmax") == 0  # it changed nothing


@attrs.frozen(kw_only=True)
class _PythonEuler(EulerCromer):
    """Euler–Cromer written as a Python step: writes x and v, as its kind declares."""

    def step(self, state, dt, forces):
        f = forces.total(state)
        state.v += f * (dt / forces.mechanics.m)
        state.x += state.v * dt


def test_an_integrator_writes_x_and_v_as_its_kind_declares():
    python, compiled = (build_sim(n_bases=120, integrator=i, backend="numpy") for i in (_PythonEuler(), EulerCromer()))
    for s in (python, compiled):
        s.run(Stop(until_time=2.0))
    assert python.step_count == compiled.step_count and np.allclose(python.state.x, compiled.state.x, rtol=0, atol=1e-12)


def _relaxing(tau: float):
    """A Maxwell resin written as a script would: after every step, each rest length relaxes toward
    its spring's length with time constant ``tau``, through a declared write."""

    def relax(sim) -> None:
        s = sim.state
        d = s.x[s.pairs[:, 1]] - s.x[s.pairs[:, 0]]
        length = np.sqrt((d * d).sum(axis=1))
        with s.writing("rest"):
            s.rest += (length - s.rest) * (s.h / tau)

    return relax


def test_a_declared_write_of_the_rest_lengths_gives_numba_the_bits_of_numpy():
    """Before the frame keyed its copy of the rest lengths on the state's edits, numba's forces used
    the old rest lengths while breaking saw the new: a different run, without a word."""
    runs = {}
    for backend in ("numpy", "numba"):
        sim = build_sim(n_bases=200, seed=2, G=0.05, fmax_spread=0.05, backend=backend)
        sim.add_action(Periodic(steps=1), _relaxing(tau=20.0))
        sim.run(Stop(until_time=12.0))
        runs[backend] = sim
    a, b = runs["numpy"], runs["numba"]
    assert a.n_broken > 5 and a.state.edited("rest") > 100
    assert a.step_count == b.step_count
    for name in ("x", "v", "rest", "intact"):
        assert np.array_equal(getattr(a.state, name), getattr(b.state, name)), name
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    assert all(np.array_equal(la[k], lb[k]) for k in la)
