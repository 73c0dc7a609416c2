"""A contract kit for strategy authors (after scikit-learn's ``check_estimator``).

``check_strategy(MyBreaker)`` runs, in your own test suite, what bark asks of every strategy; its
built-in strategies pass the same checks in bark's CI::

    from bark.testing import check_strategy

    def test_my_breaker_keeps_the_contract():
        check_strategy(MyBreaker, {"eps": 0.03})

What is checked (each failure an ``AssertionError`` naming the promise and the value that broke it):

* **construction** — an attrs class of one of bark's kinds; ``type(s)(**s.params())`` and a pickle
  round trip give an equal strategy (what sweeps, checkpoints and worker processes rely on);
* **validation** — a bad value for any field (NaN, ±inf, ±1e308, 1e-308, 0, negatives, text, None,
  drawn by hypothesis) is refused with a one-line :class:`~bark.errors.BarkError`, or accepted and
  then usable (a breaker's part, a growth law's radius are made without an error) — never another
  exception or a traceback;
* **the verb equals the part** — a breaker's ``select`` picks what its part's rule picks (when the
  part decides), a growth law's ``radius`` is its part's, an integrator's ``step`` its
  update's; a part's functions are elementwise (arrays give what each element gives);
* **numpy equals numba, to the bit** — the part compiled as the stepping kernel compiles it gives
  the bits of its functions on whole arrays, and a short simulation with the strategy ends in the
  same state and break log on both backends (skipped, and said so in the returned names, where numba
  is not installed).

Needs hypothesis (``pip install bark[test]``).
"""

from __future__ import annotations

import json
import math
import pickle
from typing import Any

import attrs
import numpy as np

from bark.errors import BarkError
from bark.contract.parts import spring_inputs
from bark.contract.strategies import KINDS, Breaker, Growth, Integrator, Made, Resin, Strategy, check_recordable
from bark.validators import construct, keywords

__all__ = ["check_strategy"]

BAD_VALUES = (math.nan, math.inf, -math.inf, 1e308, -1e308, 1e-308, 0.0, -1.0, -0, 2**63, "text", None, [1.0])


def check_strategy(cls: type, params: dict[str, Any] | None = None, *, examples: int = 40) -> list[str]:
    """Check that the strategy class ``cls``, constructed with ``params`` (default: its defaults),
    keeps bark's contract (see the module's docstring).  Returns the names of the checks that ran;
    raises ``AssertionError`` at the first promise broken."""
    from hypothesis import HealthCheck, settings

    assert isinstance(cls, type) and issubclass(cls, Strategy) and cls.kind in KINDS, \
        f"{cls!r} is not a bark strategy class (a subclass of Growth, Integrator, Breaker, Resin or Analyzer)"
    assert attrs.has(cls), f"{cls.__name__} is not an attrs class: decorate it with @attrs.frozen(kw_only=True)"
    params = dict(params or {})
    strategy = construct(cls, params, f"{cls.kind} {cls.__name__}")
    profile = settings(max_examples=examples, deadline=None, database=None, derandomize=True, report_multiple_bugs=False,
                       suppress_health_check=list(HealthCheck))
    ran = [_construction(strategy), _recording(strategy), _validation(cls, params, profile)]
    if isinstance(strategy, Breaker):
        ran += _breaker(strategy, profile)
    elif isinstance(strategy, Growth):
        ran += _growth(strategy, profile)
    elif isinstance(strategy, Integrator):
        ran += _integrator(strategy, profile)
    elif isinstance(strategy, Resin):
        ran += _resin(strategy, profile)
    if not isinstance(strategy, (Breaker, Growth, Integrator, Resin)):
        return ran
    ran.append(_life_cycle(strategy))
    ran.append(_backends(strategy) if _have_numba() else "numpy = numba: skipped (numba is not installed)")
    return ran


def _have_numba() -> bool:
    from bark.engine import kernels

    return kernels.available("numba")


def _construction(strategy) -> str:
    name = type(strategy).__name__
    again = type(strategy)(**strategy.params())
    assert again == strategy, f"{name}(**params()) gives {again!r}, not {strategy!r}: keep every parameter as given"
    try:
        copy = pickle.loads(pickle.dumps(strategy))
    except Exception as err:  # noqa: BLE001
        raise AssertionError(f"{name} cannot be pickled ({type(err).__name__}: {err}): sweeps and checkpoints "
                             "need it; define the class at a module's top level") from err
    assert copy == strategy, f"{name} does not survive pickling: {copy!r} != {strategy!r}"
    return "construction and pickling"


def _recording(strategy) -> str:
    """What a scene file, summary.json and a checkpoint record of the strategy gives it back: its
    parameters are plain data (``check_recordable``), and through JSON they make an equal strategy."""
    from bark.engine.scene import plain

    name = type(strategy).__name__
    try:
        check_recordable(strategy)
    except BarkError as err:
        raise AssertionError(str(err)) from None
    recorded = json.loads(json.dumps(plain(strategy.params())))
    again = construct(type(strategy), recorded, f"{strategy.kind} {name}")
    assert again == strategy, f"{name}'s parameters through JSON give {again!r}, not {strategy!r}"
    return "parameters recorded (JSON round trip)"


def _validation(cls, params, profile) -> str:
    from hypothesis import given
    from hypothesis import strategies as st

    fields = keywords(cls)
    if not fields:
        return "validation (no parameters)"
    values = st.one_of(st.sampled_from(BAD_VALUES), st.floats(allow_nan=True, allow_infinity=True), st.integers(),
                       st.text(max_size=5))

    @profile
    @given(st.sampled_from(fields), values)
    def refused_in_one_line(field, value):
        try:
            accepted = construct(cls, {**params, field: value}, f"{cls.kind} {cls.__name__}")
        except BarkError as err:
            assert "\n" not in str(err), f"{cls.__name__}({field}={value!r}): a message of several lines: {err}"
            return
        except Exception as err:  # noqa: BLE001 (the point: nothing else may escape)
            raise AssertionError(f"{cls.__name__}({field}={value!r}) raised {type(err).__name__}: {err} — "
                                 "validate the field (bark.validators) so that it is a one-line BarkError") from err
        try:
            _use(accepted)
        except Exception as err:  # noqa: BLE001
            raise AssertionError(f"{cls.__name__}({field}={value!r}) was accepted, then failed with "
                                 f"{type(err).__name__}: {err} — validate the field (bark.validators) so that "
                                 "it is refused with a one-line BarkError") from err

    refused_in_one_line()
    return "validation"


def _use(strategy) -> None:
    """What the engine asks of a strategy before it runs: a breaker's part, a growth law's radius and
    compiled parameters."""
    if isinstance(strategy, (Breaker, Resin)):
        strategy.part()
    elif isinstance(strategy, Growth):
        strategy.part()
        strategy.radius(1.0, np.array([0.0, 0.5]))


# -- breakers --------------------------------------------------------------------------------------

def _spring_data(breaker):
    """Random springs as a :class:`~bark.model.state.State` (each on a pair of bases of its own, along x,
    so that its measured length is the drawn one exactly), with their tensions and lengths; the
    breaker's declared per-spring fields made by its own ``initial`` (at a drawn time, height and
    lattice offset)."""
    from hypothesis import strategies as st
    from hypothesis.extra import numpy as hnp

    from bark.model.state import State

    @st.composite
    def springs(draw):
        m = draw(st.integers(1, 40))
        rest = draw(hnp.arrays(float, m, elements=st.floats(1e-4, 10.0)))
        length = rest * draw(hnp.arrays(float, m, elements=st.floats(0.0, 3.0)))
        fmax = draw(hnp.arrays(float, m, elements=st.floats(1e-4, 1.0)))
        k = draw(st.floats(1e-3, 100.0))
        x = np.zeros((2 * m, 3))
        x[1::2, 0] = length
        declared = [d for d in breaker.declares if d.per == "spring"]
        state = State.empty(2 * m, m, declared)
        state.add_bases(x=x, v=np.zeros_like(x), anchor=x, anchor_dir=np.tile([1.0, 0.0], (2 * m, 1)),
                        born=np.zeros(2 * m))
        own = {}
        if declared:
            made = Made(per="spring", t=draw(st.floats(0.0, 1e3)), ids=np.arange(m),
                        z=draw(hnp.arrays(float, m, elements=st.floats(0.0, 10.0))),
                        offset=draw(hnp.arrays(np.int64, m, elements=st.sampled_from([1, 2, 3, 5, 8, 13, 21, 34, 55]))),
                        rest=rest)
            own = breaker.initial(made, np.random.default_rng(draw(st.integers(0, 2**32))))
        state.add_springs(pairs=np.arange(2 * m).reshape(m, 2), rest=rest, fmax=fmax,
                          intact=draw(hnp.arrays(bool, m)), **own)
        state.h = draw(st.floats(1e-4, 1.0))
        return state, k * (length - rest), length

    return springs()


def _breaker(breaker, profile) -> list[str]:
    from hypothesis import given

    part = breaker.part_
    name = type(breaker).__name__
    if part is None:
        return ["part: none (select runs in Python after every step)"]
    columns = tuple(d.name for d in breaker.declares if d.per == "spring")
    evaluate = _compiled(part, "part_on_springs", columns)

    @profile
    @given(_spring_data(breaker))
    def part_is_elementwise_and_select_follows(data):
        state, tension, length = data
        rule_in = spring_inputs(state, tension, part.reads, length)
        picked = np.broadcast_to(part.rule(*rule_in, part.params), tension.shape)
        one_by_one = [bool(part.rule(*(a[i] for a in rule_in), part.params)) for i in range(tension.size)]
        assert picked.tolist() == one_by_one, f"{name}'s rule on arrays is not its rule on each spring"
        if part.load is not None:
            load_in = spring_inputs(state, tension, part.load_reads, length)
            loads = np.broadcast_to(part.load(*load_in, part.params), tension.shape)
            each = [float(part.load(*(a[i] for a in load_in), part.params)) for i in range(tension.size)]
            assert np.array_equal(loads, each, equal_nan=True), f"{name}'s load on arrays is not its load on each spring"
        if part.decides:
            chosen = np.sort(np.asarray(breaker.select(state, tension, np.random.default_rng(0))))
            assert chosen.tolist() == np.flatnonzero(state.intact & picked).tolist(), \
                f"{name}.select does not pick what its part's rule picks"
        if evaluate is not None:
            own = np.column_stack([state[c] for c in columns]) if columns else None
            got_picked, got_loads = evaluate(tension, length, state.rest, state.fmax, 1.0 / state.fmax, own)
            assert got_picked.tolist() == picked.tolist(), f"{name}'s rule compiled (numba) differs from numpy"
            if part.load is not None:
                assert np.array_equal(got_loads, loads, equal_nan=True), \
                    f"{name}'s load compiled (numba) differs from numpy: {got_loads} != {loads}"

    part_is_elementwise_and_select_follows()
    return ["breaker part: elementwise, select follows" + (", compiled = numpy" if evaluate else "")]


def _compiled(part, how: str, *args):
    """The part compiled as the stepping kernel compiles it, by ``bark.engine.kernels.numba_backend``'s
    function ``how`` (``None`` where numba is not installed)."""
    if not _have_numba():
        return None
    from bark.engine.kernels import numba_backend

    return getattr(numba_backend, how)(part, *args)


# -- resin laws ------------------------------------------------------------------------------------

def _resin(resin, profile) -> list[str]:
    """A resin law's part: its tension and flow elementwise (arrays give what each spring gives), the
    flow giving one value per field it writes, and compiled (numba) the same bits."""
    from hypothesis import given
    from hypothesis import strategies as st
    from hypothesis.extra import numpy as hnp

    name, part = type(resin).__name__, resin.part_
    assert part is not None, f"{name} gives no part: a resin law runs inside the kernel (ResinPart)"
    columns = tuple(d.name for d in resin.declares if d.per == "spring")
    evaluate = _compiled(part, "resin_on_springs", columns)

    @profile
    @given(st.integers(1, 30).flatmap(lambda m: st.tuples(
        hnp.arrays(float, m, elements=st.floats(1e-3, 1.0)), hnp.arrays(float, m, elements=st.floats(0.5, 2.0)),
        st.floats(1e-3, 10.0), st.floats(1e-4, 1.0), st.integers(0, 2**32))))
    def law_is_elementwise_and_compiled_the_same(data):
        rest, stretch, k, h, seed = data
        length, m = rest * stretch, len(rest)
        own = {}
        if columns:
            made = Made(per="spring", t=0.0, ids=np.arange(m), z=np.zeros(m), offset=np.full(m, 21), rest=rest)
            own = {c: np.asarray(v, dtype=float) for c, v in resin.initial(made, np.random.default_rng(seed)).items()}
        reads = [own[r] for r in part.reads]
        t = np.broadcast_to(part.tension(length, rest, k, *reads, part.params), (m,))
        each = [float(part.tension(length[i], rest[i], k, *(r[i] for r in reads), part.params)) for i in range(m)]
        assert np.array_equal(t, each, equal_nan=True), f"{name}'s tension on arrays is not its tension on each spring"
        flowed = {"rest": rest, **own}
        if part.evolve is not None:
            new = part.evolve(length, rest, h, *reads, part.params)
            assert isinstance(new, tuple) and len(new) == len(part.writes), \
                f"{name}'s evolve gives {type(new).__name__}, not a tuple of its {len(part.writes)} written field(s)"
            flowed.update({w: np.broadcast_to(v, (m,)) for w, v in zip(part.writes, new)})
        if evaluate is not None:
            got_t, got_rest, got_own = evaluate(length, rest, k, h, np.column_stack([own[c] for c in columns])
                                                if columns else None)
            assert np.array_equal(got_t, t, equal_nan=True), f"{name}'s tension compiled (numba) differs from numpy"
            assert np.array_equal(got_rest, flowed["rest"], equal_nan=True), \
                f"{name}'s flow of the rest length compiled (numba) differs from numpy"
            for c, column in enumerate(columns):
                assert np.array_equal(got_own[:, c], flowed[column], equal_nan=True), \
                    f"{name}'s flow of {column!r} compiled (numba) differs from numpy"

    law_is_elementwise_and_compiled_the_same()
    return ["resin part: elementwise" + (", compiled = numpy" if evaluate else "")]


# -- growth laws and integrators -------------------------------------------------------------------

def _growth(growth, profile) -> list[str]:
    from hypothesis import given
    from hypothesis import strategies as st
    from hypothesis.extra import numpy as hnp

    name = type(growth).__name__
    part = growth.part_
    if part is None:
        return ["growth: no part (radius runs in Python)"]
    evaluate = _compiled(part, "radius_at_heights")

    @profile
    @given(st.floats(0.0, 1e4), hnp.arrays(float, st.integers(1, 30), elements=st.floats(-10.0, 10.0)))
    def radius_is_the_part(t, z):
        r = np.broadcast_to(growth.radius(t, z), z.shape)
        each = [float(np.broadcast_to(growth.radius(t, zi), ())) for zi in z.tolist()]
        assert np.array_equal(r, each, equal_nan=True), f"{name}.radius on an array is not its radius at each height"
        assert np.array_equal(r, np.broadcast_to(part.radius_at(t, z), z.shape), equal_nan=True), \
            f"{name}.radius is not its part's radius at t = {t}"
        if evaluate is not None:
            got = evaluate(t, z)
            assert np.array_equal(got, r, equal_nan=True), f"{name}'s part compiled (numba) differs from numpy at t = {t}"

    radius_is_the_part()
    return ["growth: radius is the part's" + (", compiled = numpy" if evaluate else "")]


def _integrator(integrator, profile) -> list[str]:
    from hypothesis import given
    from hypothesis import strategies as st
    from hypothesis.extra import numpy as hnp

    name = type(integrator).__name__
    part = integrator.part_
    if part is None:
        return ["integrator: no part (step runs in Python)"]
    evaluate = _compiled(part, "update_on_axis")
    finite = st.floats(-1e3, 1e3)

    @profile
    @given(st.integers(1, 30).flatmap(lambda n: st.tuples(*(hnp.arrays(float, n, elements=finite) for _ in range(3)))),
           st.floats(1e-6, 1.0), st.floats(1e-3, 10.0))
    def update_is_elementwise_and_compiled_the_same(xvf, h, m):
        x, v, f = xvf
        want = part.update(x, v, f, h / m, h, part.params)
        each = [part.update(float(a), float(b), float(c), h / m, h, part.params) for a, b, c in zip(x, v, f)]
        assert all(np.array_equal(w, [e[i] for e in each]) for i, w in enumerate(want)), \
            f"{name}'s update on arrays is not its update of each element"
        if evaluate is not None:
            got = evaluate(x, v, f, h / m, h)
            assert all(np.array_equal(a, b) for a, b in zip(got, want)), f"{name}'s compiled update (numba) differs from numpy"

    update_is_elementwise_and_compiled_the_same()
    return ["integrator: update elementwise" + (", compiled = numpy" if evaluate else " (compiled check skipped: numba is not installed)")]


# -- short runs: the life cycle, and both backends ----------------------------------------------------

RUN_UNTIL = 25.0
"""A short run's end: past the first breaks of Table 2's vertical regime on the kit's small, growing
segment."""


def _short_run(strategy, backend: str, seed: int = 1):
    """A simulation of a small segment that grows (bases join during the run) and cracks, with
    ``strategy`` in place of the default of its kind, and its stop."""
    from bark.contract import registry
    from bark.model.forces import Mechanics
    from bark.model.lattice import Lattice
    from bark.engine.scene import DEFAULT_STRATEGIES
    from bark.engine.simulation import Simulation, Stop
    from bark.engine.stepping import Numerics

    parts = {kind: registry.create(kind, DEFAULT_STRATEGIES[kind]) for kind in ("growth", "integrator", "breaker", "resin")}
    parts[strategy.kind] = strategy
    parts["breakers"] = [parts.pop("breaker")]
    if strategy.kind != "breaker" and "spread" in attrs.fields_dict(type(parts["breakers"][0])):
        parts["breakers"] = [attrs.evolve(parts["breakers"][0], spread=0.05)]  # no two springs alike
    lattice = Lattice(n_bases=300, n_start=240, join_rate=3.0, join_every=1.0, jitter=0.05)  # joins to t = 20
    sim = Simulation(lattice=lattice, mechanics=Mechanics(), numerics=Numerics(dt=0.05, backend=backend),
                     seed=seed, **parts)  # Table 2's k, c, b, m
    return sim, Stop(until_time=RUN_UNTIL)


def _same_run(a, b, what: str) -> None:
    """Two simulations that must have run alike: the same steps, every field of the state and the
    break log, to the bit."""
    assert a.step_count == b.step_count, f"{what}: {a.step_count} steps against {b.step_count}"
    for field, value in a.state.arrays().items():
        assert np.array_equal(value, b.state.arrays()[field]), f"{what}: state.{field} differs"
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    assert all(np.array_equal(la[k], lb[k]) for k in la), f"{what}: the break logs differ"


def _life_cycle(strategy) -> str:
    """Run, stop halfway, snapshot, restore into a fresh simulation made from the strategy's recorded
    parameters (what a resumed run has: ``type(s)(**params())``, nothing the strategy kept), go on
    under the same stop: the bits of the uninterrupted run.  The run itself holds the strategy to the
    fields it declares (any other write fails at once)."""
    name = type(strategy).__name__
    whole, stop = _short_run(strategy, "numpy")
    whole.run(stop)
    again = type(strategy)(**strategy.params())
    first, _ = _short_run(again, "numpy")
    for sim in first.irun(stop):
        if sim.state.t >= 0.5 * RUN_UNTIL:
            break
    assert first.step_count < whole.step_count, f"{name}: the run ended before its half"
    snap = pickle.loads(pickle.dumps(first.snapshot()))
    fresh, _ = _short_run(type(strategy)(**strategy.params()), "numpy")
    fresh.restore(snap).run(stop)
    _same_run(whole, fresh, f"a run with {name} stopped at t = {first.state.t:.6g}, restored and gone on")
    return f"snapshot, restore, go on = uninterrupted, to the bit (stopped at step {first.step_count} of {whole.step_count})"


def _backends(strategy) -> str:
    """A short growing, cracking run with ``strategy`` in place of the default of its kind, on the
    numpy and the numba backend: the same state, steps and break log, to the bit."""
    runs = []
    for backend in ("numpy", "numba"):
        sim, stop = _short_run(strategy, backend)
        sim.run(stop)
        runs.append(sim)
    a, b = runs
    _same_run(a, b, f"a run with {type(strategy).__name__} on the numpy and numba backends")
    return f"numpy = numba to the bit (a run of {a.step_count} steps, {len(a.breaks)} breaks)"
