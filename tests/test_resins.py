"""Resin laws: the spring's force law and how the resin flows, a strategy kind compiled on both backends.

The paper's spring (Hookean) is the default and gives the bits it always gave; Maxwell, plastic and
non-linear laws and the example plugin's Zener solid (a declared field written every step) run
identically on numpy and numba, on a growing segment, and go on exactly after a snapshot."""

from __future__ import annotations

import pickle
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bark import Stop
from bark.contract import registry
from bark.contract.parts import HOOKEAN, ResinPart
from bark.errors import BarkError
from bark.model.lattice import Lattice
from bark_plugins.resins import Hookean, Maxwell, Nonlinear, Plastic, cubic, relaxed, yielded
from conftest import REPO_ROOT, build_sim

sys.path.insert(0, str(REPO_ROOT / "examples" / "plugin"))  # the example plugin, as its author tests it

from bark_example_plugin.zener import Zener  # noqa: E402

GROWING = Lattice(n_bases=300, n_start=240, join_rate=3.0, join_every=1.0, jitter=0.05)
RESINS = [Maxwell(tau=5.0), Plastic(yield_strain=0.15, hardening=1.0), Nonlinear(beta=20.0), Nonlinear(beta=-0.8),
          Zener(ratio=2.0, tau=3.0)]


def _run(backend: str, resin, until: float = 25.0, stepping: str = "fixed", seed: int = 4):
    sim = build_sim(n_bases=300, lattice=GROWING, seed=seed, backend=backend, resin=resin, stepping=stepping,
                    fmax_spread=0.05)
    sim.run(Stop(until_time=until))
    return sim


def _same(a, b) -> None:
    assert a.step_count == b.step_count
    for name, value in a.state.arrays().items():
        assert np.array_equal(value, b.state.arrays()[name]), name
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    assert all(np.array_equal(la[k], lb[k]) for k in la)


def _cases(*cases):
    """The quick subset keeps the first case of a class; the full suite (``slow``) runs the others."""
    return [pytest.param(*c, id="-".join(type(v).__name__ if not isinstance(v, str) else v for v in c),
                         marks=() if i == 0 else pytest.mark.slow) for i, c in enumerate(cases)]


@pytest.mark.parametrize("resin, stepping", _cases(*((r, s) for r in (RESINS[-1], *RESINS[:-1])
                                                     for s in ("adaptive", "fixed"))))
def test_every_resin_runs_identically_on_numpy_and_numba_on_a_growing_segment(resin, stepping):
    a, b = _run("numpy", resin, stepping=stepping), _run("numba", resin, stepping=stepping)
    assert a.n_broken > 10 and a.state.n_bases == 300
    _same(a, b)


@pytest.mark.parametrize("resin", _cases(*((r,) for r in (RESINS[-1], *RESINS[:-1]))))
def test_a_snapshot_of_a_flowing_resin_goes_on_exactly(resin):
    whole = _run("numba", resin)
    half = _run("numba", resin, until=12.0)
    fresh = build_sim(n_bases=300, lattice=GROWING, seed=4, backend="numba", resin=resin, fmax_spread=0.05)
    fresh.restore(pickle.loads(pickle.dumps(half.snapshot()))).run(Stop(until_time=25.0))
    _same(whole, fresh)


def test_the_paper_s_spring_is_the_default_and_the_hookean_law_to_the_bit():
    plain, hookean = _run("numba", None), _run("numba", Hookean())
    _same(plain, hookean)
    assert Hookean().part().key == HOOKEAN.key


def test_a_flowing_resin_changes_the_run():
    plain, maxwell = _run("numpy", None), _run("numpy", Maxwell(tau=5.0))
    assert not np.array_equal(plain.state.rest, maxwell.state.rest)
    assert maxwell.n_broken < plain.n_broken  # relaxed springs carry less tension: fewer break by the same time


@settings(max_examples=50, deadline=None)
@given(st.floats(1e-3, 1e3), st.floats(1e-4, 10.0), st.floats(0.01, 1.0), st.floats(0.5, 2.0))
def test_a_maxwell_spring_held_stretched_relaxes_toward_its_length_monotonically(tau, h, rest, stretch):
    length = rest * stretch
    (once,) = relaxed(length, rest, h, np.array([tau]))
    (twice,) = relaxed(length, once, h, np.array([tau]))
    lo, hi = min(rest, length), max(rest, length)
    assert lo <= once <= hi and lo <= twice <= hi  # backward Euler: never past the length, for any step
    assert abs(length - twice) <= abs(length - once) <= abs(length - rest)


@settings(max_examples=50, deadline=None)
@given(st.floats(0.01, 0.5), st.floats(0.01, 1.0), st.floats(0.0, 3.0))
def test_a_perfectly_plastic_spring_stays_at_its_yield_strain(yield_strain, rest, strain):
    length = rest * (1.0 + strain)
    (after,) = yielded(length, rest, 0.1, np.array([yield_strain, 0.0]))
    if strain <= yield_strain:
        assert after == rest  # elastic: no flow
    else:
        assert length / after - 1.0 == pytest.approx(yield_strain, rel=1e-12)


@settings(max_examples=50, deadline=None)
@given(st.floats(-1.0, 100.0), st.floats(0.01, 1.0), st.floats(-0.99, 0.99))
def test_a_nonlinear_spring_is_hookean_at_small_strain_and_pulls_when_stretched(beta, rest, strain):
    length = rest * (1.0 + strain)
    t = cubic(length, rest, 0.4, np.array([beta]))
    assert np.sign(t) == np.sign(length - rest)
    small = cubic(rest * (1 + 1e-6), rest, 0.4, np.array([beta]))
    assert small == pytest.approx(0.4 * rest * 1e-6, rel=1e-9)


def test_the_zener_arm_is_born_at_rest_and_relaxes():
    sim = _run("numpy", Zener(ratio=2.0, tau=3.0), until=8.0)
    s = sim.state
    assert s.declared == Zener.declares
    young = s.pairs[:, 1] >= sim.lattice.bases_at(8.0) - 3  # springs made at the last join
    assert np.array_equal(s["arm"][young], s.rest[young]) or not young.any()
    old = ~young & s.intact
    assert np.any(s["arm"][old] != s.rest[old])  # the arm has flowed toward the stretched length


@pytest.mark.parametrize("name", ["hookean", "maxwell", "plastic", "nonlinear"])
def test_the_resins_are_registered_as_a_plugin_would_register_them(name):
    cls = registry.load("resin", name)
    assert registry.available("resin")[name].value.startswith("bark_plugins.resins:")
    assert cls().part_ is not None


def test_a_resin_law_with_a_python_integrator_is_refused_in_one_line():
    sim = build_sim(n_bases=120, resin=Maxwell(), integrator=registry.create("integrator", "implicit-overdamped"))
    with pytest.raises(BarkError, match="needs an integrator with a compiled step") as err:
        sim.build()
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("part, message", [
    (lambda: ResinPart(tension=cubic, reads=("nosuch",)), "names 'nosuch'"),
    (lambda: ResinPart(tension=cubic, evolve=relaxed, writes=("arm",)), "names 'arm'"),
])
def test_a_resin_naming_fields_nobody_declared_is_refused(part, message):
    import attrs

    from bark.contract.strategies import Resin

    @attrs.frozen(kw_only=True)
    class Odd(Resin):
        def part(self):
            return part()

    with pytest.raises(BarkError, match=message):
        build_sim(n_bases=120, resin=Odd()).build()


@pytest.mark.parametrize("kwargs, message", [
    ({"tension": cubic, "evolve": relaxed}, "gives both evolve and the fields"),
    ({"tension": cubic, "writes": ("rest",)}, "gives both evolve and the fields"),
    ({"tension": cubic, "stiffness": 0.5}, "stiffness must be a finite number of at least 1"),
    ({"tension": cubic, "stiffness": float("inf")}, "stiffness must be a finite number of at least 1"),
    ({"tension": cubic, "reads": ("a", "a")}, "each once"),
])
def test_a_malformed_resin_part_is_one_line(kwargs, message):
    with pytest.raises(BarkError, match=message):
        ResinPart(**kwargs)


def test_a_stiffer_resin_lowers_the_stability_bound():
    soft, stiff = build_sim(n_bases=200).build(), build_sim(n_bases=200, resin=Nonlinear(beta=10.0)).build()
    assert stiff.stability_limit < soft.stability_limit
