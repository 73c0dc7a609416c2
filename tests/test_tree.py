"""The whole tree's geometry: the apical dome's profile and Ridley's placement of the organs on it."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st
from scipy.integrate import quad
from scipy.spatial import cKDTree

from bark.errors import BarkError
from bark.model.lattice import Lattice
from bark.model.tree import Apex, Dome, Packing

WHOLE_TREE = Lattice(n_bases=70000, n_start=45000, join_rate=101.0, rise=0.00012, offsets=(55, 89))
FIBONACCI = [1, 2, 3, 5, 8, 13, 21, 34, 55, 89, 144, 233, 377, 610, 987]


def ellipse_area(height: float, p: float, psi0: float = 0.0, psi1: float = 0.5 * math.pi) -> float:
    """Area (per radius²) of the superellipse dome between parameters psi0 and psi1, by quadrature of
    2πρ|c'(ψ)| on the curve's own parametrisation: independent of bark's tabulation."""
    e = 2.0 / p

    def integrand(psi):
        c, s = math.cos(psi), math.sin(psi)
        drho = -e * c ** (e - 1) * s if c > 0 else 0.0
        du = height * e * s ** (e - 1) * c if s > 0 else 0.0
        return 2.0 * math.pi * c**e * math.hypot(drho, du)

    return quad(integrand, psi0, psi1, limit=200, epsabs=1e-13, epsrel=1e-11)[0]


@pytest.mark.parametrize("height, p", [(1.0, 2.0), (0.5, 2.0), (2.0, 2.0), (0.8, 4.0), (1.3, 1.5)])
def test_the_dome_area_is_the_surface_of_revolution_of_its_profile(height, p):
    assert Dome(height=height, exponent=p).area(0.35) / 0.35**2 == pytest.approx(ellipse_area(height, p), rel=1e-6)


def test_a_hemisphere_has_area_two_pi_r_squared():
    assert Dome().area(2.0) == pytest.approx(8 * math.pi, rel=1e-7)


@pytest.mark.parametrize("t, radius", [(0.0, 0.35), (40.0, 0.6), (247.5, 0.98)])
def test_each_organ_takes_the_prescribed_area(t, radius):
    """Between two successive organs on the dome lies the organ area 2πRh of surface, and the
    youngest sits within 1½ organ areas of the tip (a new one is inserted once there is room)."""
    apex = Apex(dome=Dome(height=1.0), packing=Packing.of(WHOLE_TREE))
    ids, x = apex.organs(t, radius)
    u = (x[:, 2] - apex.top(t)) / radius  # height above the join, per radius: sin ψ on a hemisphere
    from_tip = np.array([ellipse_area(1.0, 2.0, math.asin(min(v, 1.0))) for v in u]) * radius**2
    a = apex.organ_area(t, radius)
    spacing = np.diff(from_tip[::-1])[:-1]  # tip first; the oldest may be waiting at the join
    assert len(ids) > 100
    assert a == pytest.approx(2 * math.pi * radius * 0.00012, rel=1e-15)  # one base's area on the trunk
    assert spacing == pytest.approx(np.full(len(ids) - 2, a), rel=1e-6)
    assert a / 2 - 1e-12 <= from_tip[-1] < 1.5 * a


def test_successive_organs_keep_the_divergence_angle():
    apex = Apex(packing=Packing.of(WHOLE_TREE))
    ids, x = apex.organs(12.3, 0.5)
    theta = np.arctan2(x[:, 1], x[:, 0])
    step = np.degrees(np.mod(np.diff(theta), 2 * math.pi))
    assert np.diff(ids).tolist() == [1] * (len(ids) - 1)
    assert step == pytest.approx(np.full(len(step), WHOLE_TREE.divergence_deg), abs=1e-9)


def contact_offsets(lattice: Lattice, radius: float, window=(30000, 34000)) -> list[int]:
    """The index offsets to each base's four nearest neighbours on the unrolled cylinder (periodic
    around it: two parastichies, each up and down), most common first."""
    i = np.arange(*window)
    arc = np.mod(i * math.radians(lattice.divergence_deg), 2 * math.pi) * radius
    z = i * lattice.rise
    tree = cKDTree(np.column_stack([arc, z - z.min()]), boxsize=[2 * math.pi * radius, 1e9])
    _, nearest = tree.query(np.column_stack([arc, z - z.min()])[1000:-1000], k=5)
    offsets = np.abs(i[nearest[:, 1:]] - i[1000:-1000, None]).ravel()
    values, counts = np.unique(offsets, return_counts=True)
    return values[np.argsort(-counts)].tolist()


@settings(max_examples=20, deadline=None)
@given(radius=st.floats(0.2, 1.2), rise=st.floats(0.00005, 0.0005))
def test_parastichies_on_the_trunk_are_consecutive_fibonacci_numbers(radius, rise):
    lattice = Lattice(n_bases=40000, rise=rise, offsets=(55, 89))
    first, second = contact_offsets(lattice, radius)[:2]
    assert first in FIBONACCI and second in FIBONACCI
    assert abs(FIBONACCI.index(first) - FIBONACCI.index(second)) == 1


def test_the_whole_trees_parastichies_at_its_first_radius():
    """Table 1 (h = 0.00012) at 0.35 (10 cm): the closest neighbours are 89 and 144 apart."""
    assert sorted(contact_offsets(WHOLE_TREE, 0.35)[:2]) == [89, 144]


@pytest.mark.parametrize("dome", [Dome(), Dome(height=0.4), Dome(height=3.0, exponent=6.0),
                                  Dome(shape="points", points=[[1, 0], [0, 1]]),
                                  Dome(shape="points", points=[[1, 0], [0.9, 0.5], [0.4, 0.9], [0, 1.0]])])
def test_the_dome_meets_the_trunk_with_a_vertical_tangent(dome):
    assert dome.tangent_at_join() == pytest.approx([0.0, 1.0], abs=2e-3)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(0.05, 0.95), st.floats(0.05, 2.0)), min_size=0, max_size=4), st.floats(0.1, 2.0))
def test_a_curve_given_by_points_joins_smoothly_or_is_refused_in_one_line(inner, top):
    rho = sorted((p[0] for p in inner), reverse=True)
    u = sorted(p[1] for p in inner)
    assume(all(v < top for v in u) and len(set(rho)) == len(rho))
    points = [[1.0, 0.0], *([r, v] for r, v in zip(rho, u)), [0.0, top]]
    dome = Dome(shape="points", points=points)
    assert dome.tangent_at_join() == pytest.approx([0.0, 1.0], abs=1e-9)
    try:
        area = dome.area(1.0)
    except BarkError as err:  # the spline through these points bulges past the trunk or the axis
        assert "\n" not in str(err) and "points" in str(err)
        return
    assert area > 0 and np.isfinite(area)


@pytest.mark.parametrize("points, words", [
    ([], "at least two points"),
    ([[1, 0]], "from [1, 0]"),
    ([[0.9, 0], [0, 1]], "from [1, 0]"),
    ([[1, 0], [0.5, 1], [0.6, 1.2], [0, 2]], "no further from the axis"),
    ([[1, 0], [0.5, 0.5], [0.5, 0.5], [0, 1]], "differ"),
    ([[1, 0], [0, float("nan")]], "finite"),
    ([[1, 0], [0, 1e6]], "100 trunk radii"),
    ([[1, 0], [0, 1, 2]], "pairs"),
    ("round", "pairs"),
])
def test_bad_profiles_are_refused_in_one_line(points, words):
    with pytest.raises(BarkError) as err:
        Dome(shape="points", points=points)
    assert words in str(err.value) and "\n" not in str(err.value)


@settings(max_examples=60, deadline=None)
@given(t1=st.floats(0.0, 240.0), dt=st.floats(0.0, 20.0), r1=st.floats(0.3, 1.0), dr=st.floats(0.0, 0.2))
def test_organs_are_never_lost_or_duplicated_and_only_move_down(t1, dt, r1, dr):
    """From t1 to t2 = t1 + dt, with the trunk not narrowing: ids on the dome are one run, every organ
    on it at t1 is still on it or has passed to the trunk at t2, the tip only gains organs, and each
    organ is further from the tip (in area) than before."""
    apex = Apex(packing=Packing.of(WHOLE_TREE))
    t2, r2 = t1 + dt, r1 + dr
    ids1, x1 = apex.organs(t1, r1)
    ids2, x2 = apex.organs(t2, r2, first=int(ids1[0]))
    assert np.all(np.diff(ids1) == 1) and np.all(np.diff(ids2) == 1)
    assert ids2[0] == ids1[0] and ids2[-1] >= ids1[-1]
    joined = ids1 <= apex.top_index(t2)  # passed onto the trunk by t2: they sit at the join
    u1 = (x1[:, 2] - apex.top(t1)) / r1
    u2 = (x2[: len(ids1), 2] - apex.top(t2)) / r2
    assert np.all(u2[joined] == 0.0)
    # further down the profile (in units of the radius) means further from the tip in area per radius²
    assert np.all(u2[~joined] <= u1[~joined] + 1e-12)


def test_an_organ_reaches_the_trunk_at_its_lattice_site():
    """When j(t) = i the organ is at the join, at height i·h and angle i·φ: the site where it joins the
    mechanics (before jitter)."""
    apex = Apex(packing=Packing.of(WHOLE_TREE))
    i = 50000
    t = (i - (WHOLE_TREE.initial - 1)) / WHOLE_TREE.join_rate
    ids, x = apex.organs(t, 0.6, first=i)
    theta = i * math.radians(WHOLE_TREE.divergence_deg)
    assert ids[0] == i
    assert x[0] == pytest.approx([0.6 * math.cos(theta), 0.6 * math.sin(theta), i * WHOLE_TREE.rise], abs=1e-9)


@pytest.mark.parametrize("radius", [0.35, 0.6, 0.97])
def test_the_phyllotaxis_checks_on_the_exact_lattice(radius):
    """On Table 1's exact lattice: the parastichy angle is that between the lattice vectors of 55 and 89;
    a horizontal line crosses 144 rhomboids around the trunk (each spans 144 rises), 72 on the half a
    viewer sees; a row of rhomboids side by side on that half holds π / |34·φ mod 2π| of them."""
    from bark.analysis.phyllotaxis import phyllotaxis

    lattice = Lattice(n_bases=20000, rise=0.00012, offsets=(55, 89), jitter=0.0)
    theta, z = lattice.sites(radius, np.random.default_rng(0), 0, lattice.n_bases)
    sites = np.column_stack([radius * np.cos(theta), radius * np.sin(theta), z])
    got = phyllotaxis(lattice, sites, np.full(lattice.n_bases, radius))
    phi = math.radians(lattice.divergence_deg)
    v55, v89 = ([radius * math.remainder(o * phi, 2 * math.pi), o * lattice.rise] for o in (55, 89))
    cos = abs(np.dot(v55, v89)) / (np.linalg.norm(v55) * np.linalg.norm(v89))
    assert got["parastichy_angle_deg"] == pytest.approx(math.degrees(math.acos(cos)), abs=1e-6)
    assert got["bases_crossed_front"] == pytest.approx(72, abs=1.0)
    assert got["bases_side_by_side_front"] == pytest.approx(math.pi / abs(math.remainder(34 * phi, 2 * math.pi)))


@pytest.mark.parametrize("divergence_deg, partition", [(90.0, (4, 8)), (1e-308, (13, 55))])
def test_rhomboids_of_no_width_have_no_count_side_by_side(divergence_deg, partition):
    """A divergence angle that stacks the bases in columns (or as near as a float gets) leaves no
    finite count: ``None``, quietly (no overflow warning, no infinity in summary.json)."""
    from bark.analysis.phyllotaxis import phyllotaxis

    lattice = Lattice(n_bases=2000, offsets=(21, 34), divergence_deg=divergence_deg, partition=partition)
    theta, z = lattice.sites(0.2, np.random.default_rng(0), 0, lattice.n_bases)
    sites = np.column_stack([0.2 * np.cos(theta), 0.2 * np.sin(theta), z])
    assert phyllotaxis(lattice, sites, np.full(lattice.n_bases, 0.2))["bases_side_by_side_front"] is None


# -- Ridley's packing makes the trunk's sites ---------------------------------------------------

def _growing(organ_area=None, area_exponent=1.0, jitter=0.0, growth=None, n_bases=6000):
    """A simulation whose trunk of 3,000 bases gains up to 3,000 more from the dome, widening fast."""
    from bark.engine.scene import Scene

    scene = {"lattice": {"n_bases": n_bases, "n_start": 3000, "rise": 0.00012, "offsets": [55, 89], "join_rate": 100.0,
                         "join_every": 0.1, "jitter": jitter, "organ_area": organ_area, "area_exponent": area_exponent},
             "growth": growth or {"name": "sqrt", "r0": 0.35, "G": 0.04}, "run": {"until_time": 20.0}}
    scene["lattice"] = {k: v for k, v in scene["lattice"].items() if v is not None}
    return Scene.from_dict(scene).simulation()


def test_the_trunk_s_sites_come_from_the_dome_s_placement():
    """A fixed leaf area of 30 mm² (not the lattice's 2πRh): each base that joins sits where its organ,
    placed on the dome by Ridley's packing, meets the dome's base — at its crossing time, on the
    dome's rim, at its divergence angle — and its vertical spacing is a/(2πR), not the lattice's h."""
    from bark.engine.simulation import Stop

    area = 30e-6 / 0.09  # 30 mm² in length units²
    sim = _growing(organ_area=area, area_exponent=0.0)
    sim.run(Stop(until_time=15.0))
    lat, packing = sim.lattice, sim.packing
    ids = np.arange(lat.initial, sim.state.n_bases)
    assert len(ids) > 1000 and not packing.uniform
    apex = Apex(dome=Dome(height=0.8), packing=packing)
    for i in ids[:: len(ids) // 20]:
        t = float(packing.crossing(i))
        radius = float(sim.growth.radius(t, 0.0))
        got, where = apex.organs(t, radius, first=int(i))
        assert got[0] == i
        theta = i * lat.turn
        assert where[0] == pytest.approx([radius * math.cos(theta), radius * math.sin(theta), sim.state.anchor[i, 2]], abs=1e-9)
    z = sim.state.anchor[ids, 2]
    when = packing.crossing(ids)
    r_between = np.array([float(sim.growth.radius(t, 0.0)) for t in 0.5 * (when[1:] + when[:-1])])
    band = 2 * math.pi * r_between * np.diff(z)  # the trunk's area between two successive leaves
    assert band == pytest.approx(np.full(band.size, area), rel=2e-3)
    # not the lattice's h: 30 mm² takes 1.2 h of the trunk at first, less as the trunk widens
    assert np.diff(z)[0] > 1.2 * lat.rise and np.diff(z)[-1] < 0.9 * lat.rise


def test_with_the_default_leaf_size_the_packing_continues_the_lattice():
    """One base's area on the trunk of the start, growing with the trunk (p = 1), on a trunk of one
    radius: the joining bases are the lattice's own sites, to the bit (no table is made)."""
    sim = _growing(jitter=0.05)
    sim.build()
    assert sim.packing.uniform
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    got = sim.packing.sites(0.5, rng_a, 3000, 200)
    want = sim.lattice.sites(0.5, rng_b, 3000, 200)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def test_the_leaves_crossed_are_the_trunk_s_new_area_over_the_leaf_area():
    """A fixed leaf area a on r = r0 + G√t: N(t) = (2πv/a)(r0·t + ⅔G·t^{3/2}), v the dome's rise a time unit."""
    area = 3e-4
    sim = _growing(organ_area=area, area_exponent=0.0, n_bases=60000)
    sim.build()
    v = 100.0 * 0.00012
    for t in (1.0, 7.3, 20.0, 60.0):
        exact = 2 * math.pi * v / area * (0.35 * t + 2.0 / 3.0 * 0.04 * t**1.5)
        assert float(sim.packing.crossed(t)) == pytest.approx(exact, rel=1e-6)


def test_an_area_growing_with_the_square_of_the_radius_keeps_the_parastichy_angle():
    """p = 2: the leaves' lattice only scales as the trunk widens, so the angle between the parastichies of
    the springs stays that of the trunk of the start; p = 1 (a fixed rise) flattens them."""
    from bark.analysis.phyllotaxis import phyllotaxis
    from bark.engine.simulation import Stop
    from bark.model.tree import join_radii

    angles = {}
    for p in (1.0, 2.0):
        sim = _growing(area_exponent=p, growth={"name": "sqrt", "r0": 0.35, "G": 0.1}, n_bases=9000)
        sim.run(Stop(until_time=60.0))
        s = sim.state
        late = slice(s.n_bases - 2000, s.n_bases)
        rise, radii = sim.packing.rise_of(np.arange(s.n_bases)), join_radii(sim)
        sites = np.column_stack([radii[:, None] * s.anchor_dir, s.anchor[:, 2]])  # as each joined
        start = phyllotaxis(sim.lattice, sites[:3000], radii[:3000])["parastichy_angle_deg"]
        angles[p] = (start, phyllotaxis(sim.lattice, sites[late], radii[late], rise[late])["parastichy_angle_deg"])
    assert angles[2.0][1] == pytest.approx(angles[2.0][0], abs=0.5)
    assert angles[1.0][1] < angles[1.0][0] - 10.0


def test_a_bulge_at_the_dome_s_base_packs_its_leaves_closer_in_height():
    """The leaf size follows the trunk, not the bulge: where the dome's base is wider, the leaves crossing
    there are closer in height by the ratio of the radii (each keeps its area)."""
    bulge = {"name": "bulge", "base": {"name": "sqrt", "r0": 0.35, "G": 0.04},
             "series": [{"every": 100.0, "half_width": 0.05, "first": 2.0, "magnitude": 0.1}]}
    sim = _growing(growth=bulge)
    sim.build()
    b = sim.growth.bulges[0]
    t = float((b.z - float(sim.lattice.top(0.0))) / (100.0 * 0.00012))  # the dome's base at the bulge's peak
    r, r_trunk = float(sim.growth.radius(t, np.array([b.z]))[0]), float(sim.growth.base.radius(t, 0.0))
    assert float(sim.packing.rise_at(t)) == pytest.approx(0.00012 * r_trunk / r, rel=1e-3)
    assert float(sim.packing.rise_at(1.0)) == pytest.approx(0.00012, rel=1e-12)


@settings(max_examples=40, deadline=None)
@given(t=st.floats(0.0, 40.0), p=st.sampled_from([0.0, 0.5, 2.0]))
def test_bases_join_when_the_packing_says_and_never_before(t, p):
    sim = _growing(area_exponent=p, organ_area=3e-4)
    sim.build()
    packing, every = sim.packing, sim.lattice.join_every
    present = packing.bases_at(t)
    later = packing.next_join(t, present)
    if present >= sim.lattice.n_bases:
        assert later is None
        return
    assert later > t and packing.bases_at(later) > present
    assert later - every <= t or packing.bases_at(later - every) == present


@pytest.mark.parametrize("key, value", [("organ_area", 3e-4), ("area_exponent", 2.0)])
def test_a_leaf_size_for_a_trunk_that_grows_no_leaves_is_refused_in_one_line(key, value):
    with pytest.raises(BarkError) as err:
        Lattice(n_bases=3000, **{key: value})
    assert key in str(err.value) and "n_start" in str(err.value) and "\n" not in str(err.value)
