"""The plugin contract: a third-party strategy gets what a built-in gets, the fast path included.

Every registered built-in and the example plugin's strategies pass the contract kit
(``bark.testing.check_strategy``); a breaker's part steers adaptive stepping by its own load, or not
at all; breakers with different parts are stepped in Python with the same bits on both backends.
"""

from __future__ import annotations

import sys

import attrs
import numpy as np
import pytest

from bark import Stop
from bark.contract import registry
from bark.engine import stepping
from bark.contract.parts import BreakerPart, how_it_runs
from bark.testing import check_strategy
from bark.model.lattice import Lattice
from bark_plugins.breakers import ProbabilisticBreaker, ThresholdBreaker
from bark_plugins.growth import SqrtGrowth
from bark_plugins.integrators import EulerCromer
from conftest import REPO_ROOT, build_sim

sys.path.insert(0, str(REPO_ROOT / "examples" / "plugin"))  # the example plugin, as its author tests it

from bark_example_plugin import MostOverloadedBreaker, PowerLawGrowth, StrainBreaker  # noqa: E402
from bark_example_plugin.disorder import ParastichyWeibull  # noqa: E402
from bark_example_plugin.zener import Zener  # noqa: E402

BUILT_IN = [(kind, name) for kind in ("growth", "integrator", "breaker", "resin", "analyzer") for name in registry.available(kind)
            if registry.available(kind)[name].value.startswith("bark_plugins.")]


@pytest.mark.parametrize("kind, name", BUILT_IN)
def test_every_built_in_keeps_the_contract(kind, name):
    ran = check_strategy(registry.load(kind, name))
    assert ran and all("skipped" not in r for r in ran), ran


@pytest.mark.slow
@pytest.mark.parametrize("cls, params", [(StrainBreaker, {"eps": 0.3}), (PowerLawGrowth, {"a": 0.6}),
                                         (MostOverloadedBreaker, {"max_per_step": 2}),
                                         (ParastichyWeibull, {"m": 4.0, "scale_steep": 0.002}),
                                         (Zener, {"ratio": 2.0, "tau": 3.0})])
def test_the_example_plugin_keeps_the_contract(cls, params):
    ran = check_strategy(cls, params)
    assert any(r.startswith("numpy = numba to the bit") for r in ran), ran


@attrs.frozen(kw_only=True)
class Liar(ThresholdBreaker):
    def part(self):
        return super().part()

    def select(self, state, tension, rng):  # breaks one spring too few
        return super().select(state, tension, rng)[1:]


@attrs.frozen(kw_only=True)
class Unchecked(ThresholdBreaker):
    scale: float = 1.0

    def part(self):
        return attrs.evolve(super().part(), params=[1.0 / self.scale])


def test_the_kit_finds_a_select_that_disagrees_with_its_part():
    with pytest.raises(AssertionError, match="select does not pick what its part's rule picks"):
        check_strategy(Liar, examples=30)


def test_the_kit_finds_a_field_without_a_validator():
    with pytest.raises(AssertionError, match="was accepted, then failed with"):
        check_strategy(Unchecked, examples=60)


def test_the_example_strategies_run_compiled():
    assert how_it_runs(StrainBreaker()) == "compiled" and how_it_runs(PowerLawGrowth()) == "compiled"
    assert "select in Python" in how_it_runs(MostOverloadedBreaker())
    sim = build_sim(n_bases=300, backend="numba", breakers=[StrainBreaker(eps=0.05)])  # the kit's growth law: no compile
    plan = stepping.plan(sim.build(), Stop(until_time=10.0))
    assert plan.compiled and plan.breaks == "kernel" and plan.n > 1
    calls = []
    sim.run(Stop(until_time=10.0), lambda s: calls.append(s.step_count))
    assert sim.n_broken > 20 and len(calls) < np.unique(sim.breaks.arrays()["step"]).size  # broken inside calls


def _strain_runs(stepping_mode, backend="numba"):
    sim = build_sim(n_bases=400, G=0.05, dt=0.3, stepping=stepping_mode, backend=backend, seed=2,
                    breakers=[StrainBreaker(eps=0.3)])
    sim.run(Stop(until_time=20.0))
    return sim


def _load_at_break(sim, eps):
    log = sim.breaks.arrays()
    return log["tension"] / sim.mechanics.k / sim.state.rest[log["spring"]] / eps, \
        log["tension"] / sim.state.fmax[log["spring"]]


def test_a_strain_breaker_steers_the_step_by_its_own_load():
    """Its springs break past the force threshold by more than the tolerance: judged by tension /
    f_max every breaking step would overshoot, and adaptive stepping would sit at its smallest step.
    Judged by its own load (strain / eps), each break lands within the tolerance, in a few times the
    steps of plain automatic stepping (whose breaks overshoot), for the same cracks."""
    adaptive, auto = _strain_runs("adaptive"), _strain_runs("auto")
    own, by_force = _load_at_break(adaptive, 0.3)
    assert np.median(by_force) > 1.0 + 10 * adaptive.numerics.overshoot_tol
    overshoots = {e["step"] for e in adaptive.events if e["kind"] == "overshoot"}  # at the smallest step
    over = adaptive.breaks.arrays()["step"][own > 1.0 + adaptive.numerics.overshoot_tol]
    assert own.size > 50 and set(over.tolist()) <= overshoots and len(overshoots) < 0.05 * own.size
    assert np.max(_load_at_break(auto, 0.3)[0]) > 1.01  # what the tolerance saves
    assert abs(adaptive.n_broken - auto.n_broken) <= 0.02 * auto.n_broken
    smallest_steps = 20.0 / adaptive.clock.h_min
    assert auto.step_count < adaptive.step_count < 8 * auto.step_count < smallest_steps / 100


def test_a_breaker_without_a_load_does_not_steer():
    """The probabilistic breaker's part has no load: adaptive stepping takes the steps of automatic
    stepping, and the same breaks."""
    runs = {}
    for mode in ("adaptive", "auto"):
        sim = build_sim(n_bases=300, G=0.05, dt=0.3, stepping=mode, breakers=[ProbabilisticBreaker()], seed=4)
        sim.run(Stop(until_time=15.0))
        runs[mode] = sim
    a, b = runs["adaptive"], runs["auto"]
    assert a.n_broken > 20 and a.step_count == b.step_count
    assert np.array_equal(a.breaks.arrays()["spring"], b.breaks.arrays()["spring"])
    assert not [e for e in a.events if e["kind"] == "overshoot"]


def test_breakers_with_different_parts_step_in_python_with_both_loads():
    """Two breakers with different parts: each is asked in Python after every step, the step held
    to the larger of their loads, the same bits on both backends."""
    runs = []
    for backend in ("numpy", "numba"):
        sim = build_sim(n_bases=300, G=0.05, dt=0.3, stepping="adaptive", backend=backend, seed=3,
                        breakers=[StrainBreaker(eps=0.2), ThresholdBreaker()])
        plan = stepping.plan(sim.build(), Stop(until_time=12.0))
        assert plan.breaks == "python" and not plan.compiled
        sim.run(Stop(until_time=12.0))
        runs.append(sim)
    a, b = runs
    assert a.n_broken > 20 and a.step_count == b.step_count
    assert np.array_equal(a.state.x, b.state.x)
    assert np.array_equal(a.breaks.arrays()["spring"], b.breaks.arrays()["spring"])
    live = a.state.intact
    assert np.max(a.tension()[live] / a.state.fmax[live]) <= 1.0 + a.numerics.overshoot_tol


def test_a_part_is_one_value_compared_by_its_work():
    a = BreakerPart(rule=np.greater, reads=("tension", "fmax"), params=[1.0])
    assert a == BreakerPart(rule=np.greater, reads=["tension", "fmax"], params=np.array([1.0]))
    assert a != attrs.evolve(a, params=[2.0]) and len({a, attrs.evolve(a)}) == 1
    for reads in (("tension", "tension"), ("tension", "two words"), ("tension", "_private"), ("tension", 3)):
        with pytest.raises(ValueError, match="each field once"):
            BreakerPart(rule=np.greater, reads=reads)
    assert BreakerPart(rule=np.greater, reads=("tension", "stress")).reads == ("tension", "stress")  # a declared
    # field's name: a simulation whose strategies declare no 'stress' refuses it (tests/test_declared_fields.py)
    assert not a.params.flags.writeable


def nan_load(tension, params):
    return tension + params[0]  # params[0] is NaN: a defective load


@attrs.frozen(kw_only=True)
class NaNLoad(ThresholdBreaker):
    def part(self):
        return attrs.evolve(super().part(), load=nan_load, load_reads=("tension",), params=[np.nan])


@pytest.mark.parametrize("backend, integrator", [("numba", "euler-cromer"), ("numpy", "euler-cromer"),
                                                 ("numba", "implicit-overdamped")])
def test_a_load_that_goes_nan_stops_the_run_never_silently(backend, integrator):
    from bark.errors import NonFiniteStateError

    sim = build_sim(n_bases=200, stepping="adaptive", backend=backend, breakers=[NaNLoad()],
                    integrator=registry.create("integrator", integrator))
    with pytest.raises(NonFiniteStateError):
        sim.run(Stop(until_time=2.0))
    assert sim.step_count == 0 and np.isfinite(sim.state.x).all()


def test_bulges_on_a_third_party_growth_law_run_compiled_with_the_same_bits():
    """The bulge law is built on the part of the law it sits on, whichever that is: on the example
    plugin's power law it runs compiled (many steps a kernel call, not one), to the bit on both
    backends, and its radius is that law's plus the bulges' (each with its own G, a variant of it)."""
    from bark.model.lattice import Lattice
    from bark_plugins.growth import Bulge, BulgeGrowth

    def bulged(**base):
        return BulgeGrowth(base=PowerLawGrowth(**base), bulges=[Bulge(z=0.06, half_width=0.04, magnitude=0.01, G=0.03),
                                                                 Bulge(z=0.12, half_width=0.03, magnitude=0.02, decay=0.1)])

    growth = bulged(G=0.05, a=0.6)
    assert how_it_runs(growth) == "compiled" and growth.part_.inner == PowerLawGrowth(G=0.05, a=0.6).part_
    z = np.array([0.0, 0.03, 0.06, 0.12, 0.5])
    r = growth.radius(9.0, z)
    assert r[0] == r[-1] == PowerLawGrowth(G=0.05, a=0.6).radius(9.0, 0.0)  # away from the bulges: the law's
    assert r[2] == pytest.approx(PowerLawGrowth(G=0.03, a=0.6).radius(9.0, 0.0) + 0.01, abs=1e-15)  # at a peak: its own G
    runs = {}
    for backend in ("numpy", "numba"):
        sim = build_sim(growth=growth, backend=backend, fmax_spread=0.05,
                        lattice=Lattice(n_bases=600, n_start=400, join_rate=60.0, jitter=0.05))
        calls = []
        sim.run(Stop(until_time=12.0), lambda s: calls.append(s.step_count))
        runs[backend] = sim
        assert len(calls) < sim.step_count / 3, (len(calls), sim.step_count)  # many steps a call
    a, b = runs.values()
    assert a.n_broken == b.n_broken > 0 and a.state.n_bases == b.state.n_bases > 400
    for name in ("x", "v", "anchor", "intact"):
        assert np.array_equal(getattr(a.state, name), getattr(b.state, name)), name


@attrs.frozen(kw_only=True)
class _SqrtByVerb(SqrtGrowth):
    """The square-root law with its verb written again: no part of its own, so it runs on the Python path."""

    def radius(self, t, z):
        return super().radius(t, z)


@attrs.frozen(kw_only=True)
class _EulerByVerb(EulerCromer):
    """Euler–Cromer with its verb written again: the Python path."""

    def step(self, state, dt, forces):
        super().step(state, dt, forces)


@pytest.mark.parametrize("mode", ["fixed", "adaptive"])
@pytest.mark.parametrize("resin", [None, "maxwell"])
def test_the_python_path_is_the_array_step_with_the_verbs_to_the_bit(mode, resin):
    """A strategy without a part steps by the numpy backend's array step with its verb in the part's
    place: the same law given as a verb gives the run of the law given as a part, bit for bit — bases
    joining, springs breaking, the resin flowing."""
    extra = {} if resin is None else {"resin": registry.create("resin", resin, tau=5.0)}
    lattice = Lattice(n_bases=300, n_start=240, join_rate=3.0, join_every=1.0, jitter=0.05)
    runs = []
    for growth, integrator in ((SqrtGrowth(G=0.05), EulerCromer()), (_SqrtByVerb(G=0.05), EulerCromer()),
                               *(() if resin else ((_SqrtByVerb(G=0.05), _EulerByVerb()),))):
        sim = build_sim(lattice=lattice, growth=growth, integrator=integrator, backend="numpy", stepping=mode,
                        fmax_spread=0.05, seed=3, **extra)
        sim.run(Stop(until_time=12.0))
        runs.append(sim)
    assert [stepping.plan(sim, None).compiled for sim in runs] == [True] + [False] * (len(runs) - 1)
    for other in runs[1:]:
        assert other.step_count == runs[0].step_count and other.n_broken == runs[0].n_broken > 0
        for name in ("x", "v", "anchor", "rest", "fmax", "intact"):
            np.testing.assert_array_equal(getattr(other.state, name), getattr(runs[0].state, name), err_msg=name)
        for key, column in runs[0].breaks.arrays().items():
            np.testing.assert_array_equal(other.breaks.arrays()[key], column, err_msg=key)
