"""The numpy backend's work arrays (``numpy_backend._Work``) evaluate the formulas of
``bark.model.physics`` to the bit: the same operations in the same order, written into arrays it
keeps instead of arrays allocated per step — for every float, NaN, ±inf, ±0 and extremes included."""

import numpy as np
from hypothesis import given, strategies as st
from hypothesis.extra.numpy import arrays

from bark.engine.kernels.numpy_backend import _Work
from bark.model import physics

ANY = st.floats(allow_nan=True, allow_infinity=True, width=64)


def bits(a) -> np.ndarray:
    """The 64 bits of every value: NaN equals NaN only with the same payload, and +0 is not -0."""
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def vectors(n: int, columns: int = 3):
    return arrays(np.float64, (n, columns), elements=ANY)


@st.composite
def bases(draw):
    n = draw(st.integers(1, 30))
    return n, draw(vectors(n)), draw(vectors(n)), draw(vectors(n)), draw(vectors(n))


@given(bases(), ANY, ANY)
def test_the_total_force_is_physics_base_force(case, c, b):
    n, fs, x, anchor, v = case
    work = _Work(n, 1)
    with np.errstate(all="ignore"):  # NaN and inf arise here by design: the bits are compared
        assert np.array_equal(bits(work.base_force(fs, x, anchor, v, c, b)), bits(physics.base_force(fs, x, anchor, v, c, b)))


@given(st.integers(1, 30).flatmap(lambda n: st.tuples(vectors(n), arrays(np.float64, n, elements=ANY))))
def test_lengths_and_force_scales_are_physics(case):
    d, t = case
    work = _Work(1, len(d))
    d = np.asfortranarray(d)
    with np.errstate(all="ignore"):  # NaN and inf arise here by design: the bits are compared
        length = work.length_of(d)
        assert np.array_equal(bits(length), bits(physics.length(d[:, 0], d[:, 1], d[:, 2])))
        want = physics.spring_force_scale(t, np.where(length > 0.0, length, np.inf))  # no force without a length
        assert np.array_equal(bits(work.scale(t, length)), bits(want))


@given(bases(), st.one_of(ANY, st.just(None)))
def test_the_surface_scale_and_radial_speed_are_physics(case, r):
    n, p, vel, radii, _ = case
    r = np.asarray(radii[:, 0] if r is None else r)  # one radius, or one a base
    work = _Work(n, 1)
    with np.errstate(all="ignore"):  # NaN and inf arise here by design: the bits are compared
        want = physics.surface_scale(p[:, 0], p[:, 1], r)
        assert np.array_equal(bits(work.surface_scale(p[:, 0], p[:, 1], r)), bits(want))
        inv = 1.0 / (r * r)
        want = physics.radial_speed(vel[:, 0], vel[:, 1], p[:, 0], p[:, 1], inv)
        assert np.array_equal(bits(work.radial_speed(vel[:, 0], vel[:, 1], p[:, 0], p[:, 1], inv)), bits(want))
