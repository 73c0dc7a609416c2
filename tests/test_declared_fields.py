"""Fields a strategy declares: the state carries them (grown, snapshot, checkpointed, restored), the
strategy makes each new spring's value, a breaker's part reads them inside the kernel on both backends,
and every way of getting them wrong is one line before anything runs."""

from __future__ import annotations

import pickle
import sys

import attrs
import numpy as np
import pytest

from bark import Stop
from bark.contract.parts import BreakerPart
from bark.contract.strategies import Breaker, Declared
from bark.errors import BarkError
from bark.io import checkpoint
from bark.model.lattice import Lattice
from bark_plugins.breakers import ThresholdBreaker
from conftest import REPO_ROOT, build_sim

sys.path.insert(0, str(REPO_ROOT / "examples" / "plugin"))  # the example plugin, as its author tests it

from bark_example_plugin.disorder import ParastichyWeibull  # noqa: E402

GROWING = Lattice(n_bases=300, n_start=240, join_rate=3.0, join_every=1.0, jitter=0.05)


def _run(backend: str, breaker=None, until: float = 25.0, seed: int = 4):
    sim = build_sim(n_bases=300, lattice=GROWING, seed=seed, backend=backend,
                    breakers=[breaker or ParastichyWeibull(m=4.0, scale_steep=0.002)])
    sim.run(Stop(until_time=until))
    return sim


def test_each_new_spring_gets_its_own_threshold_from_its_direction():
    sim = build_sim(n_bases=2000, seed=1, breakers=[ParastichyWeibull(m=8.0, scale_steep=0.004, scale_shallow=0.001)])
    s = sim.state
    offset = s.pairs[:, 1].astype(np.int64) - s.pairs[:, 0]
    own = s["threshold"]
    steep, shallow = own[offset == 34], own[offset == 21]
    assert steep.size > 1000 and shallow.size > 1000 and np.all(own > 0)
    # Weibull(8): mean = scale·Γ(1 + 1/8) ≈ 0.942·scale; the two parastichies take their own scales
    assert np.mean(steep) == pytest.approx(0.004 * 0.9417, rel=0.02)
    assert np.mean(shallow) == pytest.approx(0.001 * 0.9417, rel=0.02)
    assert s.declared == ParastichyWeibull.declares


def test_bases_that_join_bring_springs_with_their_own_thresholds():
    sim = _run("numpy")
    s = sim.state
    assert s.n_bases == 300 and s.n_springs > 480 and np.all(s["threshold"] > 0)
    joined = s.pairs[:, 1] >= 240
    assert joined.sum() >= 100 and len(np.unique(s["threshold"][joined])) == joined.sum()


def test_the_thresholds_break_springs_identically_on_numpy_and_numba():
    a, b = _run("numpy"), _run("numba")
    assert a.n_broken > 20
    assert a.step_count == b.step_count
    for name, value in a.state.arrays().items():
        assert np.array_equal(value, b.state.arrays()[name]), name
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    assert all(np.array_equal(la[k], lb[k]) for k in la)
    # every logged break was over its spring's own threshold, and the field decided it, not fmax
    assert np.all(la["tension"] > a.state["threshold"][la["spring"]])


def test_a_snapshot_carries_the_field_and_going_on_is_exact():
    whole = _run("numpy")
    half = _run("numpy", until=12.0)
    snap = pickle.loads(pickle.dumps(half.snapshot()))
    assert "field_threshold" in snap.arrays and snap.meta["declared"] == {"threshold": "spring"}
    fresh = build_sim(n_bases=300, lattice=GROWING, seed=4, backend="numpy",
                      breakers=[ParastichyWeibull(m=4.0, scale_steep=0.002)])
    fresh.restore(snap).run(Stop(until_time=25.0))
    assert fresh.step_count == whole.step_count
    for name, value in whole.state.arrays().items():
        assert np.array_equal(value, fresh.state.arrays()[name]), name


def test_a_snapshot_of_another_model_is_refused_in_one_line():
    snap = _run("numpy", until=2.0).snapshot()
    plain = build_sim(n_bases=300, lattice=GROWING, seed=4, backend="numpy")
    with pytest.raises(BarkError, match=r"holds the declared fields \['threshold'\].*declare none"):
        plain.restore(snap)


def test_a_checkpoint_verifies_the_declared_fields(tmp_path):
    from bark.engine.scene import Scene

    scene = Scene.from_dict({"lattice": {"n_bases": 300}, "run": {"until_time": 3.0},
                             "breaker": {"name": "bark_example_plugin.disorder:ParastichyWeibull", "m": 4.0}})
    sim, stop = scene.simulation(), scene.stop()
    sim.run(stop)
    path = checkpoint.save(tmp_path, sim, scene, stop, "end")
    arrays, meta = checkpoint.read(path)
    assert np.array_equal(arrays["field_threshold"], sim.state["threshold"])
    _, again, *_ = checkpoint.load(tmp_path)
    assert np.array_equal(again.state["threshold"], sim.state["threshold"])
    for broken, message in (({**arrays, "field_threshold": arrays["field_threshold"][:-1]}, "one value per spring"),
                            ({**arrays, "field_threshold": np.full_like(arrays["field_threshold"], np.nan)}, "NaN"),
                            ({k: v for k, v in arrays.items() if k != "field_threshold"}, "is missing")):
        with pytest.raises(checkpoint.Damaged, match=message):
            checkpoint._check_parts(broken, meta, lambda problem: checkpoint.Damaged(problem))


def _reads(name):
    @attrs.frozen(kw_only=True)
    class Reader(ThresholdBreaker):
        def part(self):
            return BreakerPart(rule=lambda tension, own, params: tension > own, reads=("tension", name))

    return Reader()


@attrs.frozen(kw_only=True)
class _Twice(Breaker):
    declares = (Declared(name="threshold", per="spring"),)

    def initial(self, made, rng):
        return {"threshold": np.ones(len(made))}

    def select(self, state, tension, rng):
        return np.empty(0, np.int64)


def _giving(values):
    @attrs.frozen(kw_only=True)
    class Giver(_Twice):
        def initial(self, made, rng):
            return values(len(made))

    return Giver()


@pytest.mark.parametrize("breakers, message", [
    ([_reads("nosuch")], "reads 'nosuch', which is neither one of tension"),
    ([ParastichyWeibull(), _Twice()], "both declare the field 'threshold'"),
    ([_giving(lambda n: {"other": np.ones(n)})], r"gave \['other'\] for new springs: give exactly"),
    ([_giving(lambda n: {"threshold": np.full(n, np.nan)})], "'threshold' holds NaN or infinite values"),
    ([_giving(lambda n: {"threshold": np.ones(n + 1)})], "'threshold' is not one number per spring"),
    ([_giving(lambda n: {"threshold": "strong"})], "'threshold' is not one number per spring"),
    ([_giving(lambda n: None)], "gave NoneType for new springs"),
])
def test_a_declaration_gone_wrong_is_one_line_before_anything_runs(breakers, message):
    sim = build_sim(n_bases=120, breakers=breakers)
    with pytest.raises(BarkError, match=message) as err:
        sim.build()
    assert "\n" not in str(err.value) and not sim._built


@pytest.mark.parametrize("name", ["rest", "tension", "x", "inv_fmax", "_private", "two words", ""])
def test_a_field_may_not_take_an_engine_name_or_a_non_identifier(name):
    with pytest.raises(BarkError, match="declared field"):
        Declared(name=name, per="spring")


@attrs.frozen(kw_only=True)
class _Hidden(ThresholdBreaker):
    table: object = attrs.field(init=False, factory=lambda: np.ones(3))


@attrs.frozen(kw_only=True)
class _Arrayed(ThresholdBreaker):
    table: object = attrs.field(factory=lambda: np.ones(3))


@attrs.frozen(kw_only=True)
class _Nested(ThresholdBreaker):
    table: object = attrs.field(factory=lambda: {"a": [1.0, {"b": np.ones(2)}]})


@pytest.mark.parametrize("breaker, message", [
    (_Hidden(), "its field 'table' is not a constructor keyword"),
    (_Arrayed(), "its parameter table holds a ndarray"),
    (_Nested(), r"its parameter table.a\[1\].b holds a ndarray"),
])
def test_a_strategy_whose_parameters_cannot_be_recorded_is_refused_before_the_run(breaker, message):
    sim = build_sim(n_bases=120, breakers=[breaker])
    with pytest.raises(BarkError, match=message):
        sim.run(Stop(until_time=1.0))
    assert not sim._built


def test_params_are_the_constructors_keywords_only():
    assert _Hidden().params() == ThresholdBreaker().params() == {"spread": 0.0, "weibull_shape": None,
                                                                  "weibull_scale": None, "regions": {}}
    assert ParastichyWeibull().params() == {"m": 6.0, "scale_steep": 0.0028, "scale_shallow": 0.0028, "steep": 34}


@attrs.frozen(kw_only=True)
class _TwoFields(Breaker):
    """A breaker owning a per-spring and a per-base field (its Python select reads them)."""

    declares = (Declared(name="toughness", per="spring"), Declared(name="age", per="base", unit="time"))

    def initial(self, made, rng):
        return {"toughness": np.full(len(made), 1e9)} if made.per == "spring" else {"age": np.full(len(made), made.t)}

    def select(self, state, tension, rng):
        return np.flatnonzero(state.intact & (tension > state["toughness"]))


def test_a_strategy_may_own_several_fields_of_both_kinds():
    sim = build_sim(n_bases=300, lattice=GROWING, seed=1, breakers=[_TwoFields()])
    sim.run(Stop(until_time=25.0))
    s = sim.state
    assert [d.name for d in s.declared] == ["toughness", "age"]
    assert s["age"].shape == (300,) and np.array_equal(s["age"], s.born)  # made when each base joined
    assert s["toughness"].shape == (s.n_springs,) and sim.n_broken == 0


@attrs.frozen(kw_only=True)
class _Started(Breaker):
    """A breaker whose fields are all made by their ``start`` (no ``initial`` of its own)."""

    declares = (Declared(name="toughness", per="spring", start=1e9), Declared(name="made_at", per="spring", start="t"),
                Declared(name="length0", per="spring", start="rest"), Declared(name="direction", per="spring", start="offset"),
                Declared(name="age", per="base", start="t"), Declared(name="height0", per="base", start="z"))

    def select(self, state, tension, rng):
        return np.flatnonzero(state.intact & (tension > state["toughness"]))


def test_a_field_with_a_start_is_made_from_it_without_an_initial():
    sim = build_sim(n_bases=300, lattice=GROWING, seed=1, breakers=[_Started()])
    sim.run(Stop(until_time=25.0))
    s = sim.state
    assert np.all(s["toughness"] == 1e9) and sim.n_broken == 0
    assert np.array_equal(s["length0"], s.rest)  # the rest length each spring was made with (Hookean: kept)
    assert np.array_equal(s["direction"], s.pairs[:, 1].astype(np.int64) - s.pairs[:, 0])
    assert np.array_equal(s["age"], s.born) and set(np.unique(s["made_at"])) <= set(np.unique(s.born))
    assert np.unique(s["made_at"]).size > 1  # springs of joining bases: made later, at their own time
    assert s["height0"][:240] == pytest.approx(s.x[:240, 2], abs=0.05)  # the sites' heights (bases move little)


@pytest.mark.parametrize("per, start, message", [
    ("spring", "noise", "start='noise' is not known of a new spring"),
    ("base", "rest", "start='rest' is not known of a new base"),
    ("base", "offset", "start='offset' is not known of a new base"),
    ("spring", float("nan"), "neither a finite number nor a name"),
    ("spring", float("inf"), "neither a finite number nor a name"),
    ("spring", -float("inf"), "neither a finite number nor a name"),
    ("spring", True, "neither a finite number nor a name"),
    ("spring", [1.0], "neither a finite number nor a name"),
    ("spring", "", "start='' is not known"),
])
def test_a_start_that_is_not_a_number_or_a_known_name_is_refused_in_one_line(per, start, message):
    with pytest.raises(BarkError, match=message) as err:
        Declared(name="own", per=per, start=start)
    assert "\n" not in str(err.value)


def test_a_field_without_a_start_or_an_initial_says_how_to_give_one():
    @attrs.frozen(kw_only=True)
    class Startless(_Twice):
        initial = Breaker.initial

    sim = build_sim(n_bases=120, breakers=[Startless()])
    with pytest.raises(NotImplementedError, match=r"declares 'threshold' without a start: give it one \(Declared"):
        sim.build()
