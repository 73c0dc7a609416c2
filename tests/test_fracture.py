"""Fracture history: cracks counted in lattice cells, patches over time, the power-law fit, the effect."""

from __future__ import annotations

import csv
import json

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bark.studies import runner
from bark.errors import BarkError
from bark.analysis.fracture import check_power_law, crack_counts, patch_count, power_law
from bark.engine.scene import Scene

A, B, N = 3, 5, 60
PAIRS = np.array([(i, i + o) for o in (A, B) for i in range(N - o)], dtype=np.int64)
FH = ["anchors", "damping", "fracture-history", "patch-statistics"]


def _cracks_by_cells(broken: list[int]) -> int:
    """Cracks the slow way: every cell of the lattice listed by its four sides, broken springs joined
    when they are sides of one cell, components counted by networkx."""
    index = {tuple(p): s for s, p in enumerate(PAIRS.tolist())}
    g = nx.Graph()
    g.add_nodes_from(broken)
    for c in range(N - A - B):
        sides = [index[(c, c + A)], index[(c, c + B)], index[(c + A, c + A + B)], index[(c + B, c + A + B)]]
        hit = [s for s in sides if s in g]
        g.add_edges_from(zip(hit, hit[1:]))
    return nx.number_connected_components(g)


def test_a_crack_across_a_cell_is_one_crack_and_far_apart_breaks_are_two():
    index = {tuple(p): s for s, p in enumerate(PAIRS.tolist())}
    two_sides = [index[(10, 10 + A)], index[(10, 10 + B)]]  # both sides at base 10 of the cell of 10
    far = index[(40, 40 + A)]
    assert crack_counts(np.array(two_sides + [far]), PAIRS, (A, B)).tolist() == [1, 1, 2]
    # (10+B, 10+A+B) is a side of the cell of 10 too: joins the first crack, not the far one
    assert crack_counts(np.array([two_sides[0], far, index[(10 + B, 10 + A + B)]]), PAIRS, (A, B)).tolist() == [1, 2, 2]


@settings(max_examples=60, deadline=None)
@given(st.permutations(list(range(len(PAIRS)))), st.integers(1, len(PAIRS)))
def test_crack_counts_match_cells_listed_side_by_side(order, k):
    broken = order[:k]
    got = crack_counts(np.array(broken), PAIRS, (A, B))
    assert got.shape == (k,)
    for j in sorted({0, k // 2, k - 1}):
        assert got[j] == _cracks_by_cells(broken[: j + 1])


def test_crack_counts_need_two_offsets():
    with pytest.raises(ValueError):
        crack_counts(np.array([0]), PAIRS, (A, B, 8))
    scene = {"lattice": {"n_bases": 400, "offsets": [13, 21, 34]}, "effects": {"want": FH}}
    with pytest.raises(BarkError) as err:
        Scene.from_dict(scene)
    assert "offsets = [13, 21, 34]" in str(err.value) and "fracture-history" in str(err.value) and "\n" not in str(err.value)


def test_patch_count_counts_components_of_at_least_min_size():
    pairs = np.array([(0, 1), (1, 2), (3, 4), (5, 6), (6, 7), (7, 8)])
    intact = np.array([True, True, True, True, True, False])
    assert patch_count(10, pairs, intact, 3) == 2  # {0,1,2}, {5,6,7}; {3,4}, {8}, {9} too small
    assert patch_count(10, pairs, intact, 1) == 5


def test_power_law_recovers_an_exponent_and_covers_it_with_its_interval():
    x = np.geomspace(1e-7, 1e-4, 12)
    exact = power_law(x, 3.0 * x**0.45)
    assert exact.exponent == pytest.approx(0.45, abs=1e-12) and exact.r2 == pytest.approx(1.0)
    assert exact.ci[0] == pytest.approx(0.45, abs=1e-9) and exact.prefactor == pytest.approx(3.0)
    rng = np.random.default_rng(7)
    covered = 0
    for _ in range(200):
        y = 3.0 * x**0.45 * np.exp(rng.normal(0.0, 0.2, x.size))
        fit = power_law(x, y, level=0.9)
        covered += fit.ci[0] <= 0.45 <= fit.ci[1]
    assert 0.84 <= covered / 200 <= 0.96  # a 90 % interval holds the true exponent about 90 % of the time
    for bad in ([1.0, 2.0], [1.0, 0.0, -1.0, np.nan, np.inf]):
        with pytest.raises(ValueError):
            power_law(bad, np.ones(len(bad)))


def test_the_power_law_check_passes_a_power_law_and_rejects_a_curve_or_a_second_cause():
    """p of each F test: uniform-ish for a true power law of x alone (rejected at 1 % about 1 % of the
    time), tiny for a bent law in log-log, and tiny for y that depends on a setting beyond x."""
    rng = np.random.default_rng(11)
    b = np.repeat(np.geomspace(0.5, 50.0, 7), 10)
    g = np.tile(np.repeat([0.005, 0.01], 5), 7)
    x = b * g**2 * np.exp(rng.normal(0.0, 0.1, b.size))
    rejected = {"curvature": 0, "alone": 0}
    for _ in range(200):
        y = 2.0 * x**0.3 * np.exp(rng.normal(0.0, 0.15, x.size))
        c = check_power_law(x, y, {"b": b, "G": g})
        rejected["curvature"] += c.curvature_p < 0.01
        rejected["alone"] += c.alone_p < 0.01
    assert rejected["curvature"] <= 8 and rejected["alone"] <= 8  # about 2 of 200 expected
    bent = np.exp(0.3 * np.log(x) + 0.2 * np.log(x) ** 2 + rng.normal(0.0, 0.1, x.size))
    assert check_power_law(x, bent).curvature_p < 1e-6
    second = 2.0 * x**0.3 * b**0.5 * np.exp(rng.normal(0.0, 0.1, x.size))  # b acts beyond the rate
    checked = check_power_law(x, second, {"b": b, "G": g})
    assert checked.alone_p < 1e-6 and checked.n == x.size
    assert checked.decades == pytest.approx(np.log10(x.max() / x.min()))
    exact = check_power_law(x, 2.0 * x**0.3, {"b": b})
    assert exact.alone_p == 1.0 and exact.curvature_p == 1.0  # a perfect fit: nothing to add
    assert check_power_law(x, 2.0 * x**0.3).alone_p is None
    with pytest.raises(ValueError, match="at least five"):
        check_power_law([1.0, 2.0, 3.0, 0.0, -1.0, np.nan], np.ones(6))


def _read(path):
    return list(csv.DictReader(path.read_text().splitlines()))


def test_the_effect_writes_the_history_that_matches_the_run(tmp_path):
    scene = Scene.from_dict({"lattice": {"n_bases": 1200}, "growth": {"G": 0.03},
                             "effects": {"want": FH + ["break-log"], "history_every": 0.5},
                             "run": {"until_time": 14.0, "until_patches": None}})
    out = runner.run(scene, tmp_path / "run")
    rows = _read(tmp_path / "run" / "fracture.csv")
    breaks = np.array([float(r["t_tu"]) for r in _read(tmp_path / "run" / "breaks.csv")])
    t = np.array([float(r["t_tu"]) for r in rows])
    assert np.all(np.diff(t) > 0) and t[-1] == out.sim.state.t
    for r in rows:  # broken springs by each sample, from the break log
        assert int(r["n_broken"]) == np.count_nonzero(breaks <= float(r["t_tu"]))
    assert int(rows[-1]["n_patches"]) == out.sim.patch_count(scene.run.min_patch_size)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())["fracture"]
    assert summary["first_break_t"] == breaks[0]
    assert summary["initial_fractures"] >= max(int(r["n_cracks"]) for r in rows) > 0
    assert breaks[0] <= summary["initial_fractures_t"] <= t[-1]
    assert summary["dissipation_rate"] > 0 and summary["growth_dissipation"] > 0
    power = [float(r["dissipation_fu_lu_per_tu"]) for r in rows]
    assert all(np.isfinite(p) and p >= 0 for p in power)


def test_the_history_of_a_growing_trunk_counts_bases_from_their_join():
    """A chain of 10 bases of which 5 are there before t = 1; spring (4, 5) breaks at t = 1.5."""
    from bark.analysis.fracture import history

    pairs = np.array([(i, i + 1) for i in range(9)])
    log = {"spring": np.array([4]), "t": np.array([1.5])}
    times = np.array([0.5, 1.2, 2.0])

    def patches(min_size):
        h = history(log, pairs, (1, 2), lambda t: 5 if t < 1.0 else 10, times, np.zeros(3), min_size)
        return h.samples["n_patches"].tolist()

    assert patches(6) == [0, 1, 0]  # 5 bases; the whole chain of 10; two halves of 5
    assert patches(5) == [1, 1, 2]


def test_a_resumed_run_ends_with_the_same_history(tmp_path):
    data = {"lattice": {"n_bases": 800}, "growth": {"G": 0.03},
            "effects": {"want": FH + ["checkpoints"], "history_every": 0.5}, "run": {"until_time": 16.0}}
    whole = runner.run(Scene.from_dict(data), tmp_path / "whole")
    assert whole.stop_reason == "time"
    state = {"n": 0}

    def stop_midway():
        state["n"] += 1
        return "interrupted" if state["n"] == 40 else None

    part = runner.run(Scene.from_dict(data), tmp_path / "part", interrupted=stop_midway)
    assert part.stop_reason == "interrupted"
    runner.resume(tmp_path / "part")
    assert (tmp_path / "whole" / "fracture.csv").read_bytes() == (tmp_path / "part" / "fracture.csv").read_bytes()
    a, b = (json.loads((tmp_path / p / "summary.json").read_text())["fracture"] for p in ("whole", "part"))
    assert a == b
