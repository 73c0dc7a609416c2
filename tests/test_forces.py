"""The forces (eqs. 1–4), as both backends evaluate them from bark.model.physics, and the thresholds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from bark.engine import kernels
from bark.model import physics
from bark.model.forces import Mechanics, SpringOrder, incidence, spring_geometry
from bark.model.state import State

BACKENDS = ["numpy", "numba"]


def _state(x, pairs, rest, active=None) -> State:
    m = len(pairs)
    return State.from_arrays({
        "x": x, "v": np.zeros_like(x), "anchor": x, "anchor_dir": np.tile([1.0, 0.0], (len(x), 1)),
        "born": np.zeros(len(x)), "pairs": pairs, "rest": rest, "fmax": np.ones(m),
        "intact": np.ones(m, bool) if active is None else active,
    })


def spring_forces(x, pairs, rest, k, active=None, backend="numpy"):
    """The intact springs' forces on every base, as ``backend`` evaluates them."""
    state = _state(x, pairs, rest, active)
    return np.asarray(kernels.load(backend).spring_forces(state, Mechanics(k=k), state.x))


def tensions(x, pairs, rest, k, backend="numpy"):
    state = _state(x, pairs, rest)
    out = np.empty(len(pairs))
    kernels.load(backend).measure(state, Mechanics(k=k), out)
    return out

coord = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)


@st.composite
def spring_systems(draw, min_n: int = 2, max_n: int = 12):
    """Random positions, springs (pairs may repeat, ends may coincide), rest lengths, stiffness."""
    n = draw(st.integers(min_n, max_n))
    x = draw(hnp.arrays(np.float64, (n, 3), elements=coord))
    m = draw(st.integers(1, 3 * n))
    pairs = draw(hnp.arrays(np.int64, (m, 2), elements=st.integers(0, n - 1)))
    rest = draw(hnp.arrays(np.float64, (m,), elements=st.one_of(st.just(0.0), st.floats(1e-9, 5.0))))
    k = draw(st.floats(0.01, 100.0))
    active = draw(hnp.arrays(np.bool_, (m,)))
    return x, pairs, rest, k, active


def _rot_z(alpha: float) -> np.ndarray:
    c, s = math.cos(alpha), math.sin(alpha)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _scale(x, pairs, rest, k) -> float:
    """Size of the individual spring forces, for relative tolerances."""
    _, length = spring_geometry(x, pairs)
    return float(k * np.sum(np.abs(length - rest)) + 1e-300)


@pytest.mark.parametrize("backend", BACKENDS)
@given(system=spring_systems())
def test_internal_spring_forces_sum_to_zero(system, backend):
    x, pairs, rest, k, active = system
    f = spring_forces(x, pairs, rest, k, active, backend)
    assert f.shape == x.shape
    assert np.all(np.isfinite(f))
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12 * _scale(x, pairs, rest, k) + 1e-300)


@pytest.mark.parametrize("backend", BACKENDS)
@given(system=spring_systems())
def test_internal_spring_torques_about_origin_sum_to_zero(system, backend):
    """Central forces: equal and opposite along the line of centres, so no net torque either."""
    x, pairs, rest, k, _ = system
    f = spring_forces(x, pairs, rest, k, backend=backend)
    torque = np.cross(x, f).sum(axis=0)
    np.testing.assert_allclose(torque, 0.0, atol=1e-11 * _scale(x, pairs, rest, k) * (1 + np.abs(x).max()))


@pytest.mark.parametrize("backend", BACKENDS)
@given(system=spring_systems())
def test_springs_at_rest_length_exert_no_force(system, backend):
    x, pairs, _, k, _ = system
    _, length = spring_geometry(x, pairs)
    f = spring_forces(x, pairs, length.copy(), k, backend=backend)
    np.testing.assert_allclose(f, 0.0, atol=1e-12 * k * (1 + np.abs(x).max()))


@pytest.mark.parametrize("backend", BACKENDS)
@given(system=spring_systems(), alpha=st.floats(-2 * math.pi, 2 * math.pi), shift_z=st.floats(-5.0, 5.0))
def test_forces_equivariant_under_rotation_about_trunk_axis(system, alpha, shift_z, backend):
    """Rotating the positions about z (and shifting along z) rotates the forces the same way.

    Springs whose ends (nearly) coincide have no direction, and a shift can round their length to
    exactly zero: that case has its own test (zero-length springs exert no force)."""
    x, pairs, rest, k, active = system
    _, length = spring_geometry(x, pairs)
    assume(np.all((length == 0.0) | (length > 1e-6 * (1.0 + np.abs(x).max()))))
    R = _rot_z(alpha)
    x2 = x @ R.T + np.array([0.0, 0.0, shift_z])
    f = spring_forces(x, pairs, rest, k, active, backend)
    f2 = spring_forces(x2, pairs, rest, k, active, backend)
    tol = 1e-9 * (_scale(x, pairs, rest, k) + k * (1 + np.abs(x).max()))
    np.testing.assert_allclose(f2, f @ R.T, atol=tol)


def test_rotation_equivariance_is_not_vacuous():
    """The forces in the rotation test are generally non-zero: rotating changes them."""
    x = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.5]])
    pairs = np.array([[0, 1]])
    f = spring_forces(x, pairs, np.array([0.5]), 1.0)
    R = _rot_z(0.7)
    assert not np.allclose(f, f @ R.T)
    np.testing.assert_allclose(spring_forces(x @ R.T, pairs, np.array([0.5]), 1.0), f @ R.T, atol=1e-14)


@pytest.mark.parametrize("backend", BACKENDS)
@given(point=hnp.arrays(np.float64, (3,), elements=coord), rest=st.floats(0.0, 5.0), k=st.floats(0.01, 100.0))
def test_zero_length_spring_gives_finite_zero_force(point, rest, k, backend):
    x = np.array([point, point, point + 1.0])
    pairs = np.array([[0, 1], [1, 0], [0, 0]])
    f = spring_forces(x, pairs, np.full(3, rest), k, backend=backend)
    assert np.all(np.isfinite(f))
    np.testing.assert_array_equal(f, 0.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_single_spring_matches_equation_1(backend):
    """Force on i from the spring to j is k(|d| − l) d/|d| with d = x_j − x_i."""
    x = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]])
    f = spring_forces(x, np.array([[0, 1]]), np.array([4.0]), 2.0, backend=backend)
    # |d| = 5, stretch 1, k = 2 → |f| = 2 along d/|d| = (0.6, 0.8, 0) on base 0, opposite on base 1
    np.testing.assert_allclose(f, [[1.2, 1.6, 0.0], [-1.2, -1.6, 0.0]], rtol=1e-14)


@given(st.floats(0.1, 10.0), st.floats(0.0, 10.0), st.floats(0.01, 10.0))
def test_stretched_spring_pulls_compressed_spring_pushes(length, rest, k):
    assume(abs(length - rest) > 1e-6)
    x = np.array([[0.0, 0.0, 0.0], [length, 0.0, 0.0]])
    f = spring_forces(x, np.array([[0, 1]]), np.array([rest]), k)
    if length > rest:  # stretched: base 0 pulled towards +x (towards base 1)
        assert f[0, 0] > 0 > f[1, 0]
    else:  # compressed: pushed apart
        assert f[0, 0] < 0 < f[1, 0]
    assert f[0, 0] == pytest.approx(k * (length - rest))


@pytest.mark.parametrize("backend", BACKENDS)
@given(system=spring_systems())
def test_inactive_springs_are_skipped(system, backend):
    x, pairs, rest, k, active = system
    f_masked = spring_forces(x, pairs, rest, k, active, backend)
    f_subset = spring_forces(x, pairs[active], rest[active], k, backend=backend)
    np.testing.assert_allclose(f_masked, f_subset, atol=1e-12 * _scale(x, pairs, rest, k) + 1e-300)


def test_all_springs_inactive_gives_zero():
    x = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    pairs = np.array([[0, 1]])
    assert np.any(spring_forces(x, pairs, np.array([1.0]), 1.0) != 0)
    np.testing.assert_array_equal(spring_forces(x, pairs, np.array([1.0]), 1.0, np.array([False])), 0.0)


@pytest.mark.parametrize("backend", BACKENDS)
@given(system=spring_systems())
def test_tension_sign(system, backend):
    """Tension k(|d| − l): > 0 exactly when stretched, < 0 when compressed."""
    x, pairs, rest, k, _ = system
    _, length = spring_geometry(x, pairs)
    t = tensions(x, pairs, rest, k, backend)
    np.testing.assert_allclose(t, k * (length - rest), rtol=1e-12, atol=1e-300)
    assert np.all((t > 0) == (length > rest))
    assert np.all((t < 0) == (length < rest))


def test_tension_of_stretched_and_compressed_springs():
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 2.0, 0.0]])
    pairs = np.array([[0, 1], [1, 2]])
    t = tensions(x, pairs, np.array([0.5, 3.0]), 0.4)
    np.testing.assert_allclose(t, [0.2, -0.4])


@given(
    hnp.arrays(np.float64, (5, 3), elements=coord),
    hnp.arrays(np.float64, (5, 3), elements=coord),
    st.floats(0.0, 10.0),
)
def test_anchor_force_is_zero_rest_length_hooke(x, anchor, c):
    f = physics.base_force(0.0, x, anchor, 0.0, c, 0.0)
    np.testing.assert_allclose(f, -c * (x - anchor), rtol=1e-15, atol=1e-300)
    # restoring: never pushes a base further from its anchor
    assert np.all(np.einsum("ij,ij->i", f, x - anchor) <= 0)
    np.testing.assert_array_equal(physics.base_force(0.0, anchor, anchor, 0.0, c, 0.0), 0.0)


def test_anchor_force_example():
    f = physics.base_force(0.0, np.array([[1.0, 2.0, 3.0]]), np.array([[1.0, 0.0, 1.0]]), 0.0, 0.1, 0.0)
    np.testing.assert_allclose(f, [[0.0, -0.2, -0.2]])


@given(hnp.arrays(np.float64, (6, 3), elements=coord), st.floats(0.0, 10.0))
def test_damping_opposes_velocity(v, b):
    f = physics.base_force(0.0, 0.0, 0.0, v, 0.0, b)
    np.testing.assert_allclose(f, -b * v, rtol=1e-15, atol=1e-300)
    assert np.all(np.einsum("ij,ij->i", f, v) <= 0)


def test_incidence_puts_plus_on_first_end_minus_on_second():
    pairs = np.array([[0, 2], [2, 1]])
    f = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    out = incidence(pairs, 4) @ f
    np.testing.assert_array_equal(out, [[1, 0, 0], [0, -1, 0], [-1, 1, 0], [0, 0, 0]])


spring_pair = st.tuples(st.integers(0, 40), st.integers(0, 40))


@given(st.lists(st.lists(spring_pair, max_size=12), min_size=1, max_size=6), st.booleans())
def test_the_spring_order_extended_join_by_join_is_the_order_made_at_once(batches, with_state):
    """Springs appended batch by batch (bases joining) are placed exactly where sorting all of them
    at once puts them: by offset j − i, then by i, ties in id order — whether the springs come alone
    (compared with those seen before) or with the state that owns them (trusted: it only appends)."""
    order, pairs = SpringOrder(), np.empty((0, 2), np.int64)
    owner = object() if with_state else None
    for batch in batches:
        pairs = np.concatenate([pairs, np.array(batch, np.int64).reshape(-1, 2)])
        got = order.of(pairs, owner)
        o, i = pairs[:, 1] - pairs[:, 0], pairs[:, 0]
        expected = np.lexsort((np.arange(len(pairs)), i, o))
        np.testing.assert_array_equal(np.arange(len(pairs)) if got is None else got, expected)
        assert (got is None) == bool(np.all(expected == np.arange(len(pairs))))


def test_the_spring_order_starts_again_for_another_state_or_changed_springs():
    order = SpringOrder()
    first, second = object(), object()
    np.testing.assert_array_equal(order.of(np.array([[0, 3], [0, 1]]), first), [1, 0])
    assert order.of(np.array([[0, 1], [0, 3]]), second) is None  # another state: made again
    assert order.of(np.array([[0, 3], [0, 1]])) is not None  # springs alone, unlike those seen: made again
    assert order.of(np.array([[0, 1]])) is None  # fewer springs than seen: made again


def test_the_incidence_sums_each_base_in_the_order_given():
    """Rows hold their springs in summation order, whatever the ids: the sum is taken in that order
    (seen in the bits: 1 + 1e-16 − 1 is not −1 + 1 + 1e-16)."""
    pairs = np.array([[0, 1], [0, 2], [0, 3]])
    w = np.array([[1.0, 0, 0], [1e-16, 0, 0], [-1.0, 0, 0]])
    assert (incidence(pairs, 4) @ w)[0, 0] == 0.0  # (1 + 1e-16) − 1
    by_order = incidence(pairs, 4, np.array([2, 0, 1])) @ w  # −1 + 1 + 1e-16
    assert by_order[0, 0] == 1e-16
    np.testing.assert_array_equal(by_order[1:], -w)


@given(hnp.arrays(np.float64, (20, 3), elements=coord), st.floats(0.01, 10.0))
def test_backends_give_the_same_forces_to_round_off(x, k):
    pairs = np.array([[i, (i + o) % 20] for o in (3, 7) for i in range(20)])
    rest = np.full(len(pairs), 0.5)
    a, b = spring_forces(x, pairs, rest, k, backend="numpy"), spring_forces(x, pairs, rest, k, backend="numba")
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * k * (1 + np.abs(x).max()))


def _thresholds(n: int, f_max: float, seed: int, **breaker) -> np.ndarray:
    """The thresholds a threshold breaker with ``breaker``'s keywords gives ``n`` springs made."""
    from bark.contract.strategies import Made
    from bark_plugins.breakers import ThresholdBreaker

    rng = np.random.default_rng(seed)
    made = Made(per="spring", t=0.0, ids=np.arange(n), z=np.zeros(n), noise=rng.standard_normal(n))
    return ThresholdBreaker(**breaker).thresholds(made, np.full(n, f_max), rng)


@given(st.integers(1, 500), st.floats(0.001, 0.01), st.floats(0.0, 0.3), st.integers(0, 2**32 - 1))
def test_thresholds_per_spring(n, f_max, spread, seed):
    th = _thresholds(n, f_max, seed, spread=spread)
    assert th.shape == (n,)
    assert np.all(th > 0)
    if spread == 0:
        np.testing.assert_array_equal(th, f_max)


def test_threshold_spread_gives_distinct_thresholds_with_mean_fmax():
    th = _thresholds(20000, 0.005, 0, spread=0.05)
    assert len(np.unique(th)) == th.size
    assert th.mean() == pytest.approx(0.005, rel=0.01)
    assert th.std() / th.mean() == pytest.approx(0.05, rel=0.1)


@pytest.mark.parametrize(
    "kwargs",
    [{"k": 0}, {"k": -1.0}, {"m": 0}, {"c": -0.1}, {"b": -1}, {"f_max": 0}, {"k": float("nan")}],
)
def test_mechanics_rejects_bad_values_naming_the_field(kwargs):
    (name,) = kwargs
    with pytest.raises(ValueError, match=rf"^{name} = "):
        Mechanics(**kwargs)
