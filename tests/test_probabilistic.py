"""The probabilistic breaker: its law, its reproducibility, and breaking that only ever grows."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from bark import Stop
from bark_cli.main import cli
from bark_plugins.breakers import ProbabilisticBreaker
from conftest import build_sim


@given(
    load=st.floats(0.5, 1.5),
    h=st.floats(0.001, 0.5),
    nu=st.floats(0.1, 20.0),
    eta=st.floats(0.0, 30.0),
    seed=st.integers(0, 2**31 - 1),
)
@settings(max_examples=30)
def test_breaking_probability_matches_its_law(load, h, nu, eta, seed):
    """Over 200 000 springs at one load, the share broken in one check is 1 − exp(−h ν L^η),
    within 5 binomial standard deviations."""
    n = 200_000
    fmax = np.full(n, 0.004)
    state = SimpleNamespace(intact=np.ones(n, bool), fmax=fmax, h=h)
    ids = ProbabilisticBreaker(nu=nu, eta=eta).select(state, fmax * load, np.random.default_rng(seed))
    p = -math.expm1(-h * nu * load**eta)
    sd = math.sqrt(n * p * (1 - p))
    assert abs(ids.size - n * p) <= 5 * sd + 1


def test_compressed_and_broken_springs_never_break():
    state = SimpleNamespace(intact=np.array([True, True, False, True]), fmax=np.full(4, 1e-3), h=10.0)
    tension = np.array([-5.0, 0.0, 50.0, 50.0])  # compressed, slack, broken, stretched
    ids = ProbabilisticBreaker(nu=100.0, eta=1.0).select(state, tension, np.random.default_rng(0))
    assert ids.tolist() == [3]


def test_same_seed_same_breaks_different_seed_different(tmp_path):
    runs = {}
    for name, seed in [("a", 7), ("b", 7), ("c", 8)]:
        out = tmp_path / name
        result = CliRunner().invoke(cli, ["simulate", "--growth", "sqrt", "--breaker", "probabilistic", "--seed", str(seed),
                                          "--n-bases", "600", "--until-time", "40", "-G", "0.03", "--out", str(out), "--quiet"])
        assert result.exit_code == 0, result.output
        runs[name] = (out / "breaks.csv").read_bytes()
    assert runs["a"] == runs["b"]
    assert runs["a"] != runs["c"]
    assert runs["a"].count(b"\n") > 50  # it really broke springs


@pytest.mark.parametrize("stepping", ["fixed", "adaptive"])
def test_probabilistic_breaking_only_grows(stepping):
    sim = build_sim(n_bases=400, G=0.05, dt=0.05, seed=3, stepping=stepping, breakers=[ProbabilisticBreaker()])
    intact = sim.state.intact.copy()
    stop = Stop(until_time=6.0)
    while stop.reason(sim) is None:
        sim.advance(stop)
        assert not np.any(sim.state.intact & ~intact)  # nothing comes back
        intact = sim.state.intact.copy()
    assert sim.n_broken > 20
    log = sim.breaks.arrays()
    assert len(np.unique(log["spring"])) == len(log["spring"])  # each spring breaks once


@pytest.mark.parametrize("shape", [2.0, 8.0])
def test_weibull_thresholds_have_their_law(shape):
    """Mean f_max, and the Weibull shape recovered by scipy's fit of 100 000 drawn thresholds."""
    from scipy import stats

    from bark.contract.strategies import Made
    from bark_plugins.breakers import ThresholdBreaker

    n, rng = 100_000, np.random.default_rng(1)
    made = Made(per="spring", t=0.0, ids=np.arange(n), z=np.zeros(n), noise=rng.standard_normal(n))
    f = ThresholdBreaker(weibull_shape=shape).thresholds(made, np.full(n, 0.005), rng)
    assert f.mean() == pytest.approx(0.005, rel=0.01)
    k, _, _ = stats.weibull_min.fit(f, floc=0)
    assert k == pytest.approx(shape, rel=0.03)
    f = ThresholdBreaker(weibull_shape=shape, weibull_scale=0.004).thresholds(made, np.full(n, 0.005), rng)
    k, _, scale = stats.weibull_min.fit(f, floc=0)
    assert k == pytest.approx(shape, rel=0.03) and scale == pytest.approx(0.004, rel=0.01)  # by its scale


@pytest.mark.parametrize("breaker, message", [
    ({"spread": 0.05, "weibull_shape": 5.0}, "are two ways to spread the thresholds: give one"),
    ({"weibull_scale": 0.005}, "is the scale of a Weibull law: give its shape too"),
    ({"regions": {"bulge": -1.0}}, "regions.bulge = -1.0: must be > 0"),
    ({"regions": [0.006]}, "must be a table of names and values"),
])
def test_threshold_settings_that_cannot_hold_together_are_one_line(breaker, message):
    from bark.errors import BarkError
    from bark.engine.scene import Scene

    with pytest.raises(BarkError) as err:
        Scene.from_dict({"breaker": {"name": "threshold", **breaker}})
    assert message in str(err.value) and "\n" not in str(err.value)


def test_the_spread_options_set_the_breaker_s_and_say_so_where_it_has_none(tmp_path, monkeypatch):
    import json

    from click.testing import CliRunner

    from bark_cli.main import cli
    from conftest import REPO_ROOT

    monkeypatch.syspath_prepend(str(REPO_ROOT / "examples" / "plugin"))  # a breaker with no spread of thresholds

    args = ["simulate", "--n-bases", "300", "--until-time", "2", "--backend", "numpy", "--quiet"]
    out = tmp_path / "run"
    result = CliRunner().invoke(cli, [*args, "--fmax-spread", "0.05", "--breaker", "probabilistic", "--out", str(out)])
    assert result.exit_code == 0, result.output
    ran = json.loads((out / "summary.json").read_text())["settings"]["breaker"]
    assert (ran["name"], ran["spread"]) == ("probabilistic", 0.05)
    result = CliRunner().invoke(cli, [*args, "--fmax-weibull-shape", "4", "--breaker",
                                      "bark_example_plugin:StrainBreaker", "--out", str(tmp_path / "other")])
    assert result.exit_code == 2 and result.output.startswith("bark: error: --fmax-weibull-shape 4.0")
    assert result.output.count("\n") == 1 and not (tmp_path / "other").exists()
