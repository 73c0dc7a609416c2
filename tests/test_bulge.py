"""Bulge growth: the sin² profile, several bulges, decay, own G and f_max inside."""

from __future__ import annotations

import functools

import attrs
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from bark import Stop
from bark.errors import BarkError
from bark.engine.scene import Scene
from bark_plugins.breakers import ThresholdBreaker
from bark_plugins.growth import Bulge, BulgeGrowth, SqrtGrowth
from conftest import build_sim

bulges = st.builds(
    Bulge,
    z=st.floats(0.0, 1.5),
    half_width=st.floats(0.01, 1.0),
    magnitude=st.floats(0.0, 0.1),
    decay=st.floats(0.0, 1.0),
)


@given(bulges)
def test_profile_is_one_at_the_site_zero_outside_and_smooth_at_the_edges(b):
    assert b.profile(np.array([b.z]))[0] == pytest.approx(1.0)
    z = b.z + b.half_width * np.array([-3.0, -1.5, -1.01, 1.01, 1.5, 3.0])
    assert np.all(b.profile(z) == 0.0)
    edges = b.z + b.half_width * np.array([-1.0, 1.0])
    assert np.all(b.profile(edges) < 1e-20)  # 0, up to the rounding of where the edge falls
    inside = b.z + b.half_width * np.linspace(-0.999, 0.999, 201)
    p = b.profile(inside)
    assert np.all((p >= 0.0) & (p <= 1.0 + 1e-12))
    assert np.argmax(p) == 100  # the one maximum is at the site
    # smooth zero edges: value and slope vanish as the edge is approached (sin² ~ (π/2 · dist)²)
    eps = 1e-4
    edge = b.profile(np.array([b.z - b.half_width + eps * b.half_width]))[0]
    assert edge == pytest.approx((0.5 * np.pi * eps) ** 2, rel=1e-3)


@given(bulges, st.floats(0.0, 500.0))
def test_radius_is_the_base_law_outside_and_raised_at_the_peak(b, t):
    base = SqrtGrowth()
    g = BulgeGrowth(base=base, bulges=[b])
    far = np.array([b.z + 2 * b.half_width, b.z - 2 * b.half_width])
    np.testing.assert_allclose(g.radius(t, far), base.radius(t, far), rtol=0, atol=1e-15)
    peak = g.radius(t, np.array([b.z]))[0]
    assert peak == pytest.approx(base.radius(t, 0.0) + b.magnitude * np.exp(-b.decay * t), rel=1e-12)


def test_several_bulges_add_and_decay():
    a = Bulge(z=0.3, half_width=0.1, magnitude=0.02, decay=0.1)
    b = Bulge(z=1.1, half_width=0.2, magnitude=0.01)
    g = BulgeGrowth(bulges=[a, b])
    z = np.array([0.3, 1.1, 0.7])
    r0 = SqrtGrowth().radius(10.0, 0.0)
    np.testing.assert_allclose(g.radius(10.0, z), [r0 + 0.02 * np.exp(-1.0), r0 + 0.01, r0])


def test_own_growth_constant_inside_and_a_region_whose_threshold_the_breaker_sets():
    from bark.contract.strategies import Made

    b = Bulge(z=0.75, half_width=0.3, G=0.007)
    g = BulgeGrowth(base=SqrtGrowth(G=0.014), bulges=[b])
    assert g.radius(4.0, np.array([0.75]))[0] == pytest.approx(0.2 + 0.007 * 2.0)
    z = np.array([0.75, 0.0, 0.75 + 0.15])
    assert BulgeGrowth(bulges=[attrs.evolve(b, start=2.0)]).regions_at(1.0, z) == []  # before the bulge is there
    ((name, weight),) = g.regions_at(4.0, z)
    assert name == "bulge" and weight[0] == 1.0 and weight[1] == 0.0 and 0.0 < weight[2] < 1.0
    made = Made(per="spring", t=4.0, ids=np.arange(3), z=z, noise=np.zeros(3), regions=tuple(g.regions_at(4.0, z)))
    f = ThresholdBreaker(regions={"bulge": 0.005}).thresholds(made, np.full(3, 0.0028), np.random.default_rng(0))
    assert f[0] == pytest.approx(0.005) and f[1] == 0.0028 and 0.0028 < f[2] < 0.005
    assert ThresholdBreaker(regions={"knot": 0.005}).thresholds(made, np.full(3, 0.0028), None).tolist() == [0.0028] * 3


def test_scene_builds_bulges_and_the_simulation_uses_their_thresholds():
    sc = Scene.from_dict({
        "lattice": {"n_bases": 600},
        "run": {"until_time": 10.0},
        "growth": {"name": "bulge", "base": {"name": "linear", "G": 0.001},
                   "bulges": [{"z": 0.15, "half_width": 0.05, "magnitude": 0.01}]},
        "breaker": {"name": "threshold", "regions": {"bulge": 0.01}},
    })
    assert isinstance(sc.strategies["growth"].base, type(Scene.from_dict({"growth": {"name": "linear"}}).strategies["growth"]))
    sim = sc.simulation()
    z = sim.state.x[:, 2]
    mid = 0.5 * (z[sim.state.pairs[:, 0]] + z[sim.state.pairs[:, 1]])
    assert sim.state.fmax[np.argmin(np.abs(mid - 0.15))] == pytest.approx(0.01, rel=0.01)
    assert np.all(sim.state.fmax[np.abs(mid - 0.15) > 0.06] == pytest.approx(0.0028))
    r = np.hypot(sim.state.x[:, 0], sim.state.x[:, 1])
    assert r[np.argmin(np.abs(z - 0.15))] > r[np.argmin(np.abs(z - 0.05))]  # the bulge is there at t = 0


@pytest.mark.parametrize("bulge, key", [({"z": 0.5, "half_width": 0.0}, "half_width"), ({"z": 0.5}, "half_width"),
                                        ({"z": 0.5, "half_width": 0.1, "magnitude": -1}, "magnitude")])
def test_bad_bulge_is_one_line(bulge, key):
    with pytest.raises(BarkError) as err:
        Scene.from_dict({"growth": {"name": "bulge", "bulges": [bulge]}})
    assert "\n" not in str(err.value) and key in str(err.value)


def test_pattern_statistics_per_region_near_bulges_and_away():
    """summary.json ``regions``: each patch counted in the region of its centroid (bulge or straight),
    the two counts adding up to all patches; a trunk without bulges has one region and no table."""
    from bark.studies import runner
    from bark.engine.scene import Scene

    data = {"lattice": {"n_bases": 1500}, "growth": {"name": "bulge", "base": {"name": "sqrt", "G": 0.05},
                                                     "bulges": [{"z": 0.2, "half_width": 0.15, "magnitude": 0.01}]},
            "run": {"until_time": 12.0}, "effects": {"want": ["bulges", "patch-statistics"]}}
    outcome = runner.run(Scene.from_dict(data))
    regions = outcome.summary["regions"]
    assert set(regions) == {"bulge", "straight"}
    assert regions["bulge"]["n_patches"] + regions["straight"]["n_patches"] == outcome.summary["n_patches"] > 5
    growth = outcome.sim.growth
    assert list(growth.region(np.array([0.04, 0.2, 0.34, 0.36]))) == ["straight", "bulge", "bulge", "straight"]
    plain = runner.run(Scene.from_dict({**data, "growth": {"name": "sqrt", "G": 0.05}, "effects": {"want": ["patch-statistics"]}}))
    assert plain.summary["regions"] is None


def test_regions_of_a_hand_made_trunk_count_patches_bases_and_the_largest_share():
    """Three bases away from a bulge and three in it on the trunk of the start, four that joined later:
    a patch goes to ``young`` when most of its bases joined later, else by its centroid's height; each
    region counts its own bases and the largest share of them one patch holds."""
    from types import SimpleNamespace

    from bark.io.output import region_summaries, trunk_regions

    growth = SimpleNamespace(region=lambda z: np.where(np.asarray(z) > 0.5, "bulge", "straight").astype(object))
    z = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
    state = SimpleNamespace(anchor=np.column_stack([np.ones(10), np.zeros(10), z]),
                            born=np.array([0.0] * 6 + [5.0] * 4))
    sim = SimpleNamespace(growth=growth, state=state)
    labels = np.array([0, 0, 0, 1, 1, 1, 1, 2, 2, 2])
    rows = [{"patch": 0, "z": 0.0, "orientation_deg": 80.0, "anisotropy": 0.5},
            {"patch": 1, "z": 1.2, "orientation_deg": 40.0, "anisotropy": 0.2},  # a quarter joined later
            {"patch": 2, "z": 2.0, "orientation_deg": 170.0, "anisotropy": 0.9}]
    every = trunk_regions(sim)
    assert list(every) == ["bulge", "straight", "young"]
    out = region_summaries(sim, rows, every, labels)
    assert {k: (v["n_patches"], v["mean_orientation_deg"]) for k, v in out.items()} == {
        "bulge": (1, pytest.approx(40.0)), "straight": (1, pytest.approx(80.0)), "young": (1, pytest.approx(170.0))}
    assert {k: (v["n_bases"], v["largest_patch_share"]) for k, v in out.items()} == {
        "bulge": (3, 1.0), "straight": (3, 1.0), "young": (4, 0.75)}
    windows = region_summaries(sim, rows, every, labels, shares=False)
    assert "n_bases" not in windows["young"] and windows["young"]["n_patches"] == 1


def test_the_bulge_law_per_base_and_on_arrays_gives_the_same_bits():
    """The kernel calls its part's ``radius(t, z, time(t, params, ...))`` for one height at a time (the
    sine only inside a bulge), the numpy backend for all heights at once: the same numbers, to the
    bit, and the same as the ``radius`` verb."""
    from bark_plugins.growth import Bulge, BulgeGrowth, bulge_radius, bulge_time

    growth = BulgeGrowth(base={"name": "sqrt", "r0": 0.35, "G": 0.04},
                         bulges=[Bulge(z=0.4, half_width=0.2, magnitude=0.1, decay=0.03, G=0.02),
                                 Bulge(z=0.5, half_width=0.05, magnitude=0.02),
                                 Bulge(z=0.7, half_width=0.1, magnitude=0.05, G=0.01, start=12.5)])
    part = growth.part_
    assert part.radius is bulge_radius and part.time is bulge_time and part.inner == growth.base.part_
    z = np.concatenate([np.linspace(0.0, 1.0, 1001), [0.2, 0.6, 0.45, 0.55]])  # edges of both bulges
    for t in (0.0, 0.37, 12.5, 247.5):
        q = part.at(t)
        one_by_one = np.array([bulge_radius(t, float(v), q) for v in z])
        assert np.array_equal(one_by_one, bulge_radius(t, z, q))
        assert np.array_equal(one_by_one, growth.radius(t, z))


@given(z=st.lists(st.floats(-1.0, 2.0, allow_nan=False), min_size=1, max_size=50),
       t=st.floats(0.0, 1e4, allow_nan=False))
def test_the_bulge_laws_weights_give_its_radius_to_the_bit(z, t):
    """The part's ``weights``: the anchors' radii as ``q[0] + s_1(z)·q[1] + s_2(z)·q[2]`` (the kernel
    sums them with each anchor's profiles taken once) are its radius exactly, inside, outside and at
    the edges of overlapping bulges."""
    from bark_plugins.growth import Bulge, BulgeGrowth, bulge_weights

    growth = BulgeGrowth(base={"name": "sqrt", "r0": 0.35, "G": 0.04},
                         bulges=[Bulge(z=0.4, half_width=0.2, magnitude=0.1, decay=0.03, G=0.02),
                                 Bulge(z=0.5, half_width=0.05, magnitude=0.02)])
    part = growth.part_
    assert part.weights is bulge_weights
    z = np.array(z + [0.2, 0.6, 0.45, 0.55])
    w, q = bulge_weights(z, part.params), part.at(t)
    assert w.shape == (2, len(z))
    assert np.array_equal((q[0] + w[0] * q[1]) + w[1] * q[2], growth.radius(t, z))


def test_weights_that_are_not_the_radius_are_refused_at_the_first_step():
    """A law whose part's ``weights`` break their promise would move its anchors wrongly without a
    trace: the backend checks each anchor's weights against the part's radius when it takes them."""
    from bark_plugins.growth import Bulge, BulgeGrowth, bulge_weights

    def off_by_one_ulp(z, p):
        return np.nextafter(bulge_weights(z, p), 2.0)

    @attrs.frozen(kw_only=True)
    class Careless(BulgeGrowth):
        def part(self):
            return attrs.evolve(super().part(), weights=off_by_one_ulp)

    growth = Careless(base={"name": "sqrt", "G": 0.05}, bulges=[Bulge(z=0.1, half_width=0.05, magnitude=0.01)])
    sim = build_sim(n_bases=300, growth=growth, backend="numba")
    with pytest.raises(BarkError, match="weights"):
        sim.run(Stop(until_time=0.5))


def test_weights_wrong_only_where_bases_join_later_are_refused_as_they_join():
    """Bases that join during the run have their weights checked too, in batches as they join: a
    law whose weights break their promise only above the first trunk's top is refused before the
    run ends."""
    from bark.engine.kernels.numba_backend import CHECK_BATCH
    from bark.model.lattice import Lattice
    from bark_plugins.growth import bulge_weights

    lattice = Lattice(n_bases=300 + 2 * CHECK_BATCH, n_start=300, join_rate=400.0, join_every=0.1, rise=0.0005)
    top = 300 * lattice.rise

    def off_above_the_first_top(z, p):
        w = bulge_weights(z, p)
        return np.where(np.asarray(z) > top, np.nextafter(w, 2.0), w)

    @attrs.frozen(kw_only=True)
    class CarelessAbove(BulgeGrowth):
        def part(self):
            return attrs.evolve(super().part(), weights=off_above_the_first_top)

    growth = CarelessAbove(base={"name": "sqrt", "G": 0.05},
                           bulges=[Bulge(z=top + 0.2, half_width=10.0, magnitude=0.01)])
    sim = build_sim(growth=growth, backend="numba", lattice=lattice)
    with pytest.raises(BarkError, match="weights"):
        sim.run(Stop(until_time=(lattice.n_bases - 300) / lattice.join_rate + 1.0))
    assert sim.state.n_bases <= 300 + CHECK_BATCH + 100  # refused with its first batch, not at the end


@functools.cache
def _compiled_weighted_radii():
    import numba

    from bark.engine.kernels.numba_backend import _weighted_radii

    @numba.njit(error_model="numpy")
    def weighted(out, q, weights, stride, spans, first):
        _weighted_radii(out, q, weights, stride, spans, first)

    return weighted


_weight = st.one_of(st.just(0.0), st.just(0.0), st.just(-0.0), st.floats(0.0, 1.0), st.sampled_from([np.nan, 1e-308]))
_coefficient = st.one_of(st.floats(-1.0, 1.0), st.sampled_from([0.0, -0.0, np.inf, -np.inf, np.nan, 1e308, -1e308]))


@given(data=st.data(), k=st.integers(1, 4), n=st.integers(0, 24), room=st.integers(0, 5),
       q0=st.sampled_from([0.35, 1.0, -1.0, 0.0, -0.0, 1e-308, np.inf, np.nan]))
def test_anchors_summed_over_each_terms_span_are_the_whole_sum_to_the_bit(data, k, n, room, q0):
    """The kernel sums each weight term only over the bases from its first weight that is not 0 to
    its last (their spans, widened as bases join); the anchors' radii are those of every term over
    every base, to the bit — for any block of the bases, weights of ±0, NaN or tiny, a radius
    ``q[0]`` of ±0 (a sum that could end −0), and coefficients ±0, huge, infinite or NaN (0·inf is
    NaN: such a term is summed over every base)."""
    from bark.engine.kernels.numba_backend import _widened

    table = np.zeros((k, n + room))  # capacity for bases still to join, as the backend keeps it
    table[:, :n] = np.array(data.draw(st.lists(_weight, min_size=k * n, max_size=k * n)), dtype=float).reshape(k, n)
    joined = data.draw(st.integers(0, n))  # the weights taken in two joins: the spans widened twice
    spans = _widened(_widened(None, table[:, :joined], 0), table[:, joined:n], joined)
    q = np.array([q0, *data.draw(st.lists(_coefficient, min_size=k, max_size=k))], dtype=float)
    first = data.draw(st.integers(0, n))
    out = np.full(data.draw(st.integers(0, n - first)), -7.0)
    _compiled_weighted_radii()(out, q, table.ravel(), table.shape[1], spans.ravel(), first)
    whole = np.full(out.size, q0)
    with np.errstate(invalid="ignore", over="ignore"):
        for term in range(k):
            whole = whole + table[term, first:first + out.size] * q[1 + term]
    number = ~np.isnan(whole)  # a NaN's sign and payload follow the compiler's order of an addition's operands
    np.testing.assert_array_equal(np.isnan(out), ~number)
    np.testing.assert_array_equal(out[number].view(np.int64), whole[number].view(np.int64))


@pytest.mark.parametrize("q", [[-0.0, 1.0], [0.0, -1.0], [1.0, np.inf], [1.0, np.nan], [0.35, 2.0]])
def test_anchors_summed_over_spans_keep_the_sign_of_zero_and_the_nan_of_zero_times_inf(q):
    """The cases the spans' fallbacks are for, every time (the property test above draws them only
    now and then): a radius ``q[0]`` of −0, which ``+ 0·q`` turns into +0 at a base outside the span,
    and a coefficient that is infinite or NaN, which makes ``0·q`` NaN there."""
    from bark.engine.kernels.numba_backend import _widened

    table = np.array([[0.0, 0.5, 0.0]])  # base 1 in the span, bases 0 and 2 outside it
    q = np.array(q)
    out = np.full(3, -7.0)
    _compiled_weighted_radii()(out, q, table.ravel(), 3, _widened(None, table, 0).ravel(), 0)
    with np.errstate(invalid="ignore"):
        whole = q[0] + table[0] * q[1]
    assert np.array_equal(np.isnan(out), np.isnan(whole))
    assert np.array_equal(np.signbit(out), np.signbit(whole)) or np.isnan(whole).any()
    assert np.array_equal(out, whole, equal_nan=True)


def test_a_growth_law_that_writes_radius_again_loses_the_inherited_part():
    import attrs

    from bark_plugins.growth import BulgeGrowth, SqrtGrowth

    @attrs.frozen(kw_only=True)
    class Wider(BulgeGrowth):
        def radius(self, t, z):
            return 2 * super().radius(t, z)

    @attrs.frozen(kw_only=True)
    class Thicker(SqrtGrowth):
        def radius(self, t, z):
            return 2 * super().radius(t, z)  # super() still means the parent's part

    assert Wider(bulges=[Bulge(z=0.1, half_width=0.05)]).part_ is None and Thicker().part_ is None
    assert Thicker().radius(4.0, 0.0) == 2 * SqrtGrowth().radius(4.0, 0.0)


@functools.cache
def _compiled_radii():
    """``bulge_radii`` compiled as the kernel compiles it (its helpers inlined)."""
    import numba

    from bark.engine.kernels.numba_backend import _helpers, _make_jitable
    from bark_plugins.growth import bulge_radii

    _make_jitable(_helpers(bulge_radii)[1:])
    return numba.njit(error_model="numpy")(bulge_radii)


_odd_heights = st.one_of(st.floats(-1.0, 6.0), st.sampled_from([np.nan, np.inf, -np.inf, 1e308, -1e308, 1e-308, 0.0]),
                         st.sampled_from([1.55, 2.45, 3.55, 4.45, 2.0, 4.0]).map(lambda z: float(np.nextafter(z, z + np.array([-1.0, 0.0, 1.0]))[0])))


@given(t=st.floats(0.0, 1e4), heights=st.lists(_odd_heights, min_size=0, max_size=40),
       extra=st.sampled_from([None, 0.0, -0.0, 1e308, np.inf, -np.inf, np.nan]))
def test_the_bulge_laws_block_form_is_its_radius_per_height_to_the_bit(t, heights, extra):
    """The part's ``radii`` (what the kernel calls on a block of bases: no branch per height, and a
    bulge the block is out of reach of skipped) gives, to the bit, what ``radius`` gives height by
    height — blocks inside, outside and across either bulge's edge, NaN and infinite heights, an
    extra radius that is huge, infinite or NaN (never skipped then: 0·inf is NaN per height too)."""
    from bark_plugins.growth import bulge_radii, bulge_radius

    g = BulgeGrowth(base={"name": "sqrt", "G": 0.04},
                    bulges=[Bulge(z=2.0, half_width=0.45, magnitude=0.3, G=0.02),
                            Bulge(z=4.0, half_width=0.45, magnitude=0.3, decay=0.1, G=0.03, start=100.0)])
    assert g.part_.radii is bulge_radii
    q = g.part_.at(t)
    if extra is not None:
        q[2] = extra
    z = np.array(heights, dtype=float)
    out = np.full(len(z), -1.0)
    _compiled_radii()(t, z, q, out)
    with np.errstate(invalid="ignore"):  # 0·inf, per height
        one_by_one = np.array([bulge_radius(t, float(v), q) for v in z])
    np.testing.assert_array_equal(out.view(np.int64), one_by_one.view(np.int64))


@functools.cache
def _compiled_extent():
    """``_extent`` compiled once for the test's examples (as the kernel compiles it)."""
    import numba

    from bark_plugins.growth import _extent

    return numba.njit(error_model="numpy")(_extent)


@given(heights=st.lists(_odd_heights, min_size=0, max_size=40))
def test_a_blocks_extent_bounds_its_heights(heights):
    """The lowest and highest height of a block (what decides which bulges it is out of reach of),
    compiled as the kernel compiles it: exactly the least and the greatest where no height is NaN;
    with a NaN, at least one end NaN (so that no bulge is skipped) or both still bounds."""
    z = np.array(heights, dtype=float)
    lowest, highest = _compiled_extent()(z)
    if z.size and not np.isnan(z).any():
        assert (lowest, highest) == (z.min(), z.max())
    elif z.size and not (np.isnan(lowest) or np.isnan(highest)):
        assert lowest <= np.nanmin(z) and highest >= np.nanmax(z)
    else:
        assert np.isnan(lowest) or np.isnan(highest)


def test_a_law_without_a_block_form_steps_to_the_same_bits():
    """The kernel calls a part's ``radius`` per height when the part gives no ``radii``: the same
    state, to the bit, as with the bulge law's block form."""
    from bark.engine import stepping
    from bark.model.lattice import Lattice

    @attrs.frozen(kw_only=True)
    class PerHeight(BulgeGrowth):
        def part(self):
            return attrs.evolve(super().part(), radii=None)

    runs = {}
    for law in (BulgeGrowth, PerHeight):
        growth = law(base={"name": "sqrt", "G": 0.05}, bulges=[Bulge(z=0.05, half_width=0.03, magnitude=0.01, G=0.02)])
        sim = build_sim(growth=growth, backend="numba", lattice=Lattice(n_bases=600, n_start=400, join_rate=100.0))
        sim.run(Stop(until_time=1.5))
        runs[law] = sim
    a, b = runs.values()
    assert stepping.plan(a, None).growth.radii is not None and stepping.plan(b, None).growth.radii is None
    assert a.state.n_bases == b.state.n_bases > 400 and a.n_broken == b.n_broken
    for name in ("x", "v", "anchor"):
        np.testing.assert_array_equal(getattr(a.state, name), getattr(b.state, name))


@given(bulges, st.lists(st.floats(-1.0, 1.0, allow_nan=False), max_size=20))
def test_one_height_and_an_array_of_heights_give_the_same_bits(b, offsets):
    """The compiled kernel evaluates the profile one base at a time (skipping the division outside
    the bulge), the numpy backend on arrays: the same values to the bit, at the edges too."""
    from bark_plugins.growth import bump

    edge = np.nextafter(b.half_width, [0.0, np.inf])  # a hair inside and outside the reach
    z = np.concatenate([b.z + np.array(offsets) * 2 * b.half_width, b.z + edge, b.z - edge, [b.z, np.nan]])
    one = np.array([bump(float(v), b.z, b.half_width) for v in z])
    np.testing.assert_array_equal(one, bump(z, b.z, b.half_width))
    np.testing.assert_array_equal(one, b.profile(z))  # the Python path, which skips heights outside


def test_the_profile_is_sin_squared_by_its_series():
    """``sin2_profile`` is sin²(π(u + 1)/2) by a polynomial: its coefficients are the series' (summed
    here independently, in exact arithmetic with π to 40 digits), it is within 4e-16 of sin² measured
    in extended precision, exactly 1 at the centre and 0 at the edges, even, and falls monotonically
    from the centre."""
    import inspect
    import re
    from fractions import Fraction

    from bark_plugins.growth import sin2_profile

    pi = Fraction("3.141592653589793238462643383279502884197")
    term, total, series = Fraction(1), Fraction(0), []
    for k in range(11):
        if k:
            term = term * -(pi * pi / 4) / ((2 * k - 1) * (2 * k))
        total += term
        series.append(float(total))
    written = [float(v) for v in re.findall(r"[-+]?\d\.\d+(?:e[-+]\d+)?", inspect.getsource(sin2_profile).split('"""')[-1])]
    assert sorted(written[:11], key=abs) == sorted(series, key=abs)

    u = np.linspace(-1.0, 1.0, 400_001)
    pi_ld = np.longdouble(4) * np.arctan(np.longdouble(1))
    exact = np.sin(pi_ld * (u.astype(np.longdouble) + 1) / 2) ** 2
    assert float(np.max(np.abs(sin2_profile(u) - exact))) < 4e-16
    assert sin2_profile(0.0) == 1.0 and sin2_profile(1.0) == 0.0 and sin2_profile(-1.0) == 0.0
    np.testing.assert_array_equal(sin2_profile(u), sin2_profile(-u))
    right = sin2_profile(u[u >= 0])
    assert np.all(np.diff(right) <= 0)


@given(st.floats(0.0, 300.0), st.lists(st.floats(-1.0, 10.0, allow_nan=False), min_size=1, max_size=30))
def test_a_bulge_laws_radius_of_heights_is_its_compiled_form_to_the_bit(t, heights):
    """In Python the law sums its anchors' weights (its part's ``weights``: the profile only where a
    height is inside a bulge); the kernel calls its part's radius per base: the same bits."""
    from bark_plugins.growth import bulge_radius

    g = BulgeGrowth(base={"name": "sqrt", "G": 0.04},
                    bulges=[Bulge(z=2.0, half_width=0.45, magnitude=0.3, G=0.02),
                            Bulge(z=4.0, half_width=0.45, magnitude=0.3, decay=0.1, G=0.03, start=100.0)])
    z = np.array(heights)
    compiled = bulge_radius(t, z, g.part_.at(t))
    np.testing.assert_array_equal(g.radius(t, z), compiled)
    np.testing.assert_array_equal([float(g.radius(t, v)) for v in z], compiled)


# -- bulges made during the run, below the apical dome -------------------------------------------

def _series_law(**series):
    from bark_plugins.growth import BulgeSeries

    return BulgeGrowth(base={"name": "sqrt", "G": 0.05},
                       series=[BulgeSeries(**{"every": 2.0, "count": 3, "half_width": 0.05, "magnitude": 0.01,
                                              "G": 0.02, **series})])


def test_a_series_places_its_bulges_above_the_top_of_the_trunk_as_it_grows():
    from bark.model.lattice import Lattice

    lattice = Lattice(n_bases=1200, n_start=400, join_rate=100.0)
    placed = _series_law(first=1.0).on(lattice)
    assert placed.series == () and placed.on(lattice) is placed
    assert [b.start for b in placed.bulges] == [1.0, 3.0, 5.0]
    for b in placed.bulges:  # its peak one half width above the top then: the lower edge at the top
        assert b.z == pytest.approx(lattice.top(b.start) + 0.05, abs=1e-15)
        assert (b.G, b.magnitude, b.half_width) == (0.02, 0.01, 0.05)
    below = _series_law(offset=-0.02).on(lattice).bulges[0]
    assert below.z == pytest.approx(lattice.top(0.0) - 0.02)


@given(t=st.floats(0.0, 30.0), dz=st.floats(-0.2, 0.2))
def test_a_bulge_is_not_there_before_its_start_and_moves_no_base_already_there_when_it_comes(t, dz):
    from bark.model.lattice import Lattice

    lattice = Lattice(n_bases=1200, n_start=400, join_rate=100.0)
    law = _series_law().on(lattice)
    plain = SqrtGrowth(G=0.05)
    first = law.bulges[1]  # appears at t = 2
    z = np.array([first.z + dz])
    expected = plain.radius(t, z) + sum(float(b.profile(z)[0]) * (0.01 + (0.02 - 0.05) * (np.sqrt(t) - np.sqrt(b.start)))
                                        for b in law.bulges if t >= b.start)  # only the bulges already there
    assert law.radius(t, z)[0] == pytest.approx(expected, abs=1e-12)
    at = first.start
    below_top = np.linspace(0.0, float(lattice.top(at)), 50)
    before = law.radius(np.nextafter(at, 0.0), below_top)
    np.testing.assert_allclose(law.radius(at, below_top), before, rtol=0, atol=1e-9)
    peak = law.radius(at, np.array([first.z]))[0]
    assert peak == pytest.approx(plain.radius(at, 0.0) + 0.01, abs=1e-12)  # its magnitude, its own G from now on
    later = law.radius(at + 4.0, np.array([first.z]))[0]
    assert later == pytest.approx(plain.radius(at + 4.0, 0.0) + 0.01 + (0.02 - 0.05) * (np.sqrt(at + 4) - np.sqrt(at)), abs=1e-12)


def test_a_law_with_an_unplaced_series_refuses_in_one_line():
    with pytest.raises(BarkError, match=r"series.*placed on a trunk"):
        _series_law().radius(1.0, np.zeros(3))


@pytest.mark.parametrize("series, key", [({"half_width": 0.05}, "series[0].every"),
                                         ({"every": 2.0}, "series[0].half_width"),
                                         ({"every": -1.0, "half_width": 0.05}, "series[0].every"),
                                         ({"every": 2.0, "half_width": 0.05, "count": 0}, "series[0].count"),
                                         ({"every": 2.0, "half_width": 0.05, "offset": float("nan")}, "series[0].offset"),
                                         ({"every": 2.0, "half_width": 0.05, "height": 1.0}, "height")])
def test_a_bad_series_is_one_line_naming_its_key(series, key):
    data = {"lattice": {"n_bases": 600, "n_start": 400, "join_rate": 100.0}, "run": {"until_time": 1.0},
            "growth": {"name": "bulge", "series": [series]}}
    with pytest.raises(BarkError) as err:
        Scene.from_dict(data)
    assert key in str(err.value) and "\n" not in str(err.value)


def test_a_run_with_a_series_numpy_and_numba_to_the_bit_and_the_bulges_own_thresholds():
    """Bulges made as bases join: the same state on both backends; springs made inside a bulge once it
    is there take its threshold, those made before it (the trunk already there, below the top) the
    scene's; and the bases that joined in it have the longer springs of its larger radius."""
    from bark.engine.kernels import available
    from bark.model.lattice import Lattice

    lattice = Lattice(n_bases=1600, n_start=400, join_rate=100.0)
    growth = _series_law(every=3.0, count=3, first=1.0, offset=-0.01, magnitude=0.02)
    runs = {}
    for backend in ["numpy"] + (["numba"] if available("numba") else []):
        sim = build_sim(growth=growth, backend=backend, lattice=lattice, stepping="adaptive",
                        breakers=[ThresholdBreaker(regions={"bulge": 0.006})])
        sim.run(Stop(until_time=9.0))
        runs[backend] = sim
    sims = list(runs.values())
    for other in sims[1:]:
        for name in ("x", "v", "anchor", "rest", "fmax"):
            np.testing.assert_array_equal(getattr(sims[0].state, name), getattr(other.state, name))
        assert np.array_equal(sims[0].state.intact, other.state.intact)
    s = sims[0].state
    placed = sims[0].growth
    assert [b.start for b in placed.bulges] == [1.0, 4.0, 7.0]
    mid = 0.5 * (s.anchor[s.pairs[:, 0], 2] + s.anchor[s.pairs[:, 1], 2])
    born = np.maximum(s.born[s.pairs[:, 0]], s.born[s.pairs[:, 1]])
    for b in placed.bulges:
        inside = np.abs(mid - b.z) < 0.3 * b.half_width
        assert (inside & (born >= b.start)).any() and (s.fmax[inside & (born >= b.start)] > 0.0028).all()
        assert (s.fmax[inside & (born < b.start)] == 0.0028).all()
    first = placed.bulges[0]  # against the same trunk without bulges: the same springs before it, longer in it
    plain = build_sim(growth=SqrtGrowth(G=0.05), backend="numpy", lattice=lattice, stepping="adaptive")
    plain.run(Stop(until_time=9.0))
    before = born < first.start
    assert np.array_equal(plain.state.pairs[: before.sum()], s.pairs[before]) and before[: before.sum()].all()
    np.testing.assert_allclose(plain.state.rest[: before.sum()], s.rest[before], rtol=1e-12)
    inside = (born >= first.start) & (born < placed.bulges[1].start) & (np.abs(mid - first.z) < 0.2 * first.half_width)
    plain_rest = dict(zip(map(tuple, plain.state.pairs.tolist()), plain.state.rest))
    ratio = [r / plain_rest[p] for p, r in zip(map(tuple, s.pairs[inside].tolist()), s.rest[inside]) if p in plain_rest]
    assert len(ratio) > 20 and np.mean(ratio) > 1.02


@pytest.mark.parametrize("item, named", [("growth.bulges=[{z=0.5}]", "bulges[0].half_width in --set"),
                                         ("growth.series=[{every=2.0}]", "series[0].half_width in --set")])
def test_a_missing_key_in_a_set_table_is_named_without_a_value(item, named):
    from click.testing import CliRunner

    from bark_cli.main import cli

    result = CliRunner().invoke(cli, ["simulate", "--set", "growth.name=bulge", "--set", item, "--quiet"])
    assert result.exit_code == 2 and named in result.stderr and "is missing" in result.stderr
    assert "NOTHING" not in result.stderr and len(result.stderr.splitlines()) == 1


@pytest.mark.parametrize("old, new", [
    ({"growth": {"name": "bulge", "bulges": [{"z": 0.15, "half_width": 0.05, "f_max": 0.006}]}},
     "[growth] bulges[0].f_max = 0.006: a bulge's threshold is the breaker's setting now: give [breaker] regions = { bulge = 0.006 }"),
    ({"growth": {"name": "bulge", "series": [{"every": 2.0, "half_width": 0.05, "f_max": 0.007}]}},
     "[growth] series[0].f_max = 0.007: a bulge's threshold is the breaker's setting now: give [breaker] regions = { bulge = 0.007 }"),
    ({"mechanics": {"fmax_spread": 0.05}}, "[mechanics] fmax_spread = 0.05: that setting has moved: give [breaker] "
                                           "spread = 0.05 ("),
    ({"mechanics": {"fmax_weibull_shape": 4.0}}, "give [breaker] weibull_shape = 4.0"),
])
def test_a_threshold_setting_of_an_earlier_version_is_refused_naming_its_new_key(old, new):
    with pytest.raises(BarkError) as err:
        Scene.from_dict(old)
    assert new in str(err.value) and "\n" not in str(err.value)


class _TookOverTheJitter(ThresholdBreaker):
    """A third party's breaker that says a lattice setting of an earlier version is its own now."""

    moved_in = {("lattice", "old_jitter"): ("jitter_now", 0.0)}


class _TookItToo(SqrtGrowth):
    """Another, of another kind, that took the same setting elsewhere, where 1.0 meant unused."""

    moved_in = {("lattice", "old_jitter"): ("wobble", 1.0)}


def test_a_third_party_strategy_names_the_settings_it_took_over_and_ordinary_scenes_do_not_ask(monkeypatch):
    """``Strategy.moved_in`` is the contract's, not the built-ins' alone: a plugin's strategy that
    took over a setting gets it named as the new key; the installed strategies are asked only when
    a table holds a key it does not know (an ordinary scene never loads them for this)."""
    from bark.contract import registry

    asked = []
    monkeypatch.setattr(registry, "find", lambda test: asked.append(test) or [("breaker", f"{__name__}:_TookOverTheJitter")])
    Scene.from_dict({"lattice": {"n_bases": 4000}, "mechanics": {"f_max": 0.005}, "run": {"until_time": 10.0}})
    assert asked == []
    with pytest.raises(BarkError) as err:
        Scene.from_dict({"lattice": {"old_jitter": 0.1}})
    assert str(err.value).startswith("[lattice] old_jitter = 0.1: ") and "give [breaker] jitter_now = 0.1 (" in str(err.value)
    assert Scene.from_dict({"lattice": {"old_jitter": 0.0}}).to_dict() == Scene.from_dict({}).to_dict()
    for value in ([0.0], "0", True, float("nan")):  # never "unused" but the value itself: one line, no traceback
        with pytest.raises(BarkError, match="old_jitter"):
            Scene.from_dict({"lattice": {"old_jitter": value}})
    # two strategies that took it, each elsewhere: both places named, and unused only where both say so
    monkeypatch.setattr(registry, "find", lambda test: [("breaker", f"{__name__}:_TookOverTheJitter"),
                                                        ("growth", f"{__name__}:_TookItToo")])
    for value in (0.0, 1.0):
        with pytest.raises(BarkError) as err:
            Scene.from_dict({"lattice": {"old_jitter": value}})
        assert f"give [breaker] jitter_now = {value} (" in str(err.value) and f"or [growth] wobble = {value} (" in str(err.value)


def test_a_moved_setting_declared_wrongly_is_refused_when_its_class_is_made():
    """``moved_in`` maps (table, key) to (its key, the unused value): anything else is the plugin
    author's mistake, said when the class is defined rather than as a traceback in every user's scene."""
    for wrong in ({("lattice", "old"): "jitter"}, {"lattice.old": ("jitter", 0.0)}, [("lattice", "old")]):
        with pytest.raises(TypeError, match="moved_in"):
            type("Wrong", (ThresholdBreaker,), {"moved_in": wrong})


def test_an_earlier_run_s_scene_file_with_its_unused_threshold_keys_still_reads():
    """Earlier versions wrote every [mechanics] key, the unused spread included: such a scene.toml
    (a run's, a checkpoint's) is read as it meant."""
    now = Scene.from_dict({"mechanics": {"f_max": 0.005}})
    assert Scene.from_dict({"mechanics": {"f_max": 0.005, "fmax_spread": 0.0}}).to_dict() == now.to_dict()
