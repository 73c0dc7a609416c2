"""Scenes: defaults, validation messages, merge rules, shipped scene files."""

from __future__ import annotations

import re
import warnings

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bark.errors import BarkError, BarkWarning
from bark.model.lattice import GOLDEN_ANGLE_DEG
from bark.engine.scene import Scene, merge, read_toml

from conftest import REPO_ROOT

SCENE_DIR = REPO_ROOT / "bark" / "scenes"


def _assert_one_line_naming(err: BaseException, *names: str) -> None:
    msg = str(err)
    assert msg and "\n" not in msg, msg
    for name in names:
        assert re.search(rf"(?<![A-Za-z0-9_]){re.escape(name)}(?![A-Za-z0-9_])", msg), f"{name!r} not in {msg!r}"


# -- defaults ----------------------------------------------------------------------------------


def test_empty_scene_is_table_2_vertical_regime():
    s = Scene.from_dict({})
    assert s.lattice.n_bases == 3000
    assert s.lattice.rise == 0.0005
    assert s.lattice.offsets == (21, 34)
    assert s.lattice.divergence_deg == pytest.approx(137.5078, abs=1e-4) == GOLDEN_ANGLE_DEG
    assert s.lattice.jitter > 0  # symmetry breaking on by default
    m = s.mechanics
    assert (m.k, m.c, m.b, m.m, m.f_max) == (0.4, 0.1, 5.0, 1.0, 0.0028)
    assert s.names == {"growth": "sqrt", "integrator": "euler-cromer", "breaker": "threshold", "resin": "hookean",
                       "analyzer": "patches"}
    assert s.strategies["growth"].r0 == 0.2 and s.strategies["growth"].G == 0.014
    # numerics: adaptive steps of at most 0.3, overshoot at a break at most 0.2 % (on the measured
    # work-precision front; the paper's fixed dt = 0.01 is one option away)
    assert (s.run.dt, s.run.stepping, s.run.overshoot_tol) == (0.3, "adaptive", 0.002)
    assert s.strategies["analyzer"].min_size == 7 and s.run.min_patch_size == 7


def test_shipped_vertical_scene_is_the_default_scene():
    """bark/scenes/vertical.toml says it is what `bark simulate` runs without --scene."""
    shipped = Scene.from_toml(REPO_ROOT / "bark" / "scenes" / "vertical.toml").to_dict()
    default = Scene.from_dict({}).to_dict()
    shipped.pop("scene"), default.pop("scene")
    assert shipped == default


def test_scene_builds_the_simulation_it_describes():
    s = Scene.from_dict({"lattice": {"n_bases": 300}, "run": {"dt": 0.02, "seed": 9, "until_time": 5.0}, "growth": {"G": 0.03}})
    sim = s.simulation()
    assert sim.lattice is s.lattice and sim.mechanics is s.mechanics
    assert sim.growth is s.strategies["growth"]
    assert sim.numerics.dt == 0.02 and sim.seed == 9
    assert sim.state.n_bases == 300
    assert list(sim.breakers) == [s.strategies["breaker"]]


@given(
    n=st.integers(35, 5000),
    G=st.floats(0.0, 1.0),
    dt=st.floats(1e-4, 1.0),
    seed=st.integers(0, 2**32),
    name=st.sampled_from(["sqrt", "linear"]),
)
def test_to_dict_round_trips(n, G, dt, seed, name):
    s = Scene.from_dict({"lattice": {"n_bases": n}, "growth": {"name": name, "G": G},
                         "run": {"dt": dt, "seed": seed, "until_patches": max(1, n // 7)}})
    again = Scene.from_dict(s.to_dict())
    assert again == s
    assert again.to_dict() == s.to_dict()


# -- validation --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "data, names",
    [
        ({"nope": {}}, ["nope"]),
        ({"lattice": {"foo": 1}}, ["foo", "lattice"]),
        ({"mechanics": {"stiffness": 1}}, ["stiffness"]),
        ({"run": {"until": 3}}, ["until"]),
        ({"scene": {"title": "x"}}, ["title"]),
        ({"growth": {"name": "nope"}}, ["nope", "growth"]),
        ({"integrator": {"name": "rk4"}}, ["rk4"]),
        ({"breaker": {"name": "nope"}}, ["nope", "breaker"]),
        ({"analyzer": {"name": "nope"}}, ["nope"]),
        ({"growth": {"name": 3}}, ["name"]),
        ({"growth": {"H": 1.0}}, ["H"]),
        ({"growth": {"name": "linear", "r0": 0}}, ["r0"]),
        ({"growth": {"G": -1}}, ["G"]),
        ({"mechanics": {"k": -1}}, ["k"]),
        ({"mechanics": {"k": "stiff"}}, ["k"]),
        ({"mechanics": {"m": 0}}, ["m"]),
        ({"mechanics": {"f_max": 0.0}}, ["f_max"]),
        ({"run": {"dt": 0}}, ["dt"]),
        ({"run": {"dt": -0.01}}, ["dt"]),
        ({"run": {"seed": -1}}, ["seed"]),
        ({"run": {"seed": 1.5}}, ["seed"]),
        ({"run": {"on_degenerate": "explode"}}, ["on_degenerate"]),
        ({"run": {"degenerate_fraction": 0}}, ["degenerate_fraction"]),
        ({"run": {"until_time": None, "until_patches": None}}, ["until_time"]),
        ({"run": {"until_patches": 0}}, ["until_patches"]),
        ({"lattice": {"n_bases": 0}}, ["n_bases"]),
        ({"lattice": {"n_bases": 2.5}}, ["n_bases"]),
        ({"lattice": {"n_bases": True}}, ["n_bases"]),
        ({"lattice": {"jitter": -0.1}}, ["jitter"]),
        ({"lattice": {"offsets": [21, 21]}}, ["offsets"]),
        ({"lattice": {"offsets": [0, 34]}}, ["offsets"]),
        ({"lattice": {"divergence_deg": 360}}, ["divergence_deg"]),
        ({"lattice": {"rise": float("inf")}}, ["rise"]),
    ],
)
def test_bad_scene_raises_one_line_naming_the_key(data, names):
    with pytest.raises(BarkError) as info:
        Scene.from_dict(data)
    _assert_one_line_naming(info.value, *names)


@pytest.mark.parametrize("data, key", [({"growth": "sqrt"}, "growth"), ({"lattice": 5}, "lattice"), ({"scene": "x"}, "scene")])
def test_value_instead_of_table_is_a_bark_error(data, key):
    with pytest.raises(BarkError) as info:
        Scene.from_dict(data)
    _assert_one_line_naming(info.value, key)


def test_offsets_as_string_names_the_key():
    with pytest.raises(BarkError) as info:
        Scene.from_dict({"lattice": {"offsets": "21,34"}})
    _assert_one_line_naming(info.value, "offsets")


def test_bark_error_is_a_value_error():
    assert issubclass(BarkError, ValueError)


def test_malformed_toml_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[lattice\nn_bases = \n")
    with pytest.raises(BarkError) as info:
        Scene.from_toml(path)
    _assert_one_line_naming(info.value)
    assert "bad.toml" in str(info.value)


def test_missing_toml_file(tmp_path):
    with pytest.raises(BarkError) as info:
        read_toml(tmp_path / "nowhere.toml")
    _assert_one_line_naming(info.value)
    assert "nowhere.toml" in str(info.value)


def test_directory_as_toml_file(tmp_path):
    with pytest.raises(BarkError) as info:
        read_toml(tmp_path)
    _assert_one_line_naming(info.value)


def test_unknown_key_in_toml_file(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("[lattice]\nfoo = 1\n")
    with pytest.raises(BarkError) as info:
        Scene.from_toml(path)
    _assert_one_line_naming(info.value, "foo")


def test_toml_overrides_apply(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[lattice]\nn_bases = 500\njitter = 0.1\n[growth]\nname = "linear"\nG = 0.02\n')
    s = Scene.from_toml(path, {"lattice": {"n_bases": 800}})
    assert s.lattice.n_bases == 800 and s.lattice.jitter == 0.1
    assert s.names["growth"] == "linear" and s.strategies["growth"].G == 0.02


# -- merge rules -------------------------------------------------------------------------------


def test_merge_changing_strategy_name_drops_old_params():
    base = {"growth": {"name": "sqrt", "G": 0.05, "r0": 0.3}}
    out = merge(base, {"growth": {"name": "linear"}})
    assert out["growth"] == {"name": "linear"}
    out = merge(base, {"growth": {"name": "linear", "r0": 0.4}})
    assert out["growth"] == {"name": "linear", "r0": 0.4}
    assert base == {"growth": {"name": "sqrt", "G": 0.05, "r0": 0.3}}  # inputs unchanged


def test_merge_same_strategy_name_keeps_params():
    out = merge({"growth": {"name": "sqrt", "G": 0.05}}, {"growth": {"name": "sqrt", "r0": 0.3}})
    assert out["growth"] == {"name": "sqrt", "G": 0.05, "r0": 0.3}
    out = merge({"growth": {"name": "sqrt", "G": 0.05}}, {"growth": {"r0": 0.3}})
    assert out["growth"] == {"name": "sqrt", "G": 0.05, "r0": 0.3}


def test_merge_restating_the_default_strategy_name_keeps_params():
    """A table without ``name`` is the default strategy: naming it again is no change (regression)."""
    out = merge({"growth": {"G": 0.05}}, {"growth": {"name": "sqrt"}})
    assert Scene.from_dict(out).strategies["growth"].G == 0.05


def test_merge_any_until_replaces_all_stop_conditions():
    base = {"run": {"until_time": 50.0, "until_patches": 20, "dt": 0.02}}
    out = merge(base, {"run": {"until_radius": 0.3}})
    assert out["run"]["until_radius"] == 0.3
    assert out["run"]["until_time"] is None and out["run"]["until_patches"] is None
    assert out["run"]["dt"] == 0.02
    s = Scene.from_dict(out)
    assert (s.run.until_time, s.run.until_radius, s.run.until_patches) == (None, 0.3, None)
    # also against the defaults (until_time 1000, until_patches 110)
    s = Scene.from_dict(merge({}, {"run": {"until_time": 5.0}}))
    assert (s.run.until_time, s.run.until_radius, s.run.until_patches) == (5.0, None, None)
    # a [run] override without until_* keeps the stop conditions
    out = merge(base, {"run": {"dt": 0.05}})
    assert out["run"]["until_time"] == 50.0 and out["run"]["until_patches"] == 20


@pytest.mark.parametrize("base, overrides", [({}, {"growth": "sqrt"}), ({"lattice": 5}, {}), ({"run": 1}, {"run": {"dt": 0.1}})])
def test_merge_value_instead_of_table_is_a_bark_error(base, overrides):
    with pytest.raises(BarkError) as info:
        merge(base, overrides)
    _assert_one_line_naming(info.value, next(iter({**base, **overrides})))


# -- shipped scenes ----------------------------------------------------------------------------

SHIPPED = sorted(SCENE_DIR.glob("*.toml"))


def test_at_least_three_shipped_scenes():
    names = {p.stem for p in SHIPPED}
    assert len(SHIPPED) >= 3
    assert {"vertical", "reticulate", "diamond"} <= names


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_shipped_scene_loads(path):
    s = Scene.from_toml(path)
    assert s.name
    assert Scene.from_dict(s.to_dict()) == s
    n = max(50, 2 * max(s.lattice.offsets))  # a few bases, enough for its springs
    with warnings.catch_warnings(record=True) as said:  # a trunk that short may end below its bulges
        warnings.simplefilter("always")
        small = Scene.from_toml(path, {"lattice": {"n_bases": n, "n_start": None}, "run": {"until_time": 1.0}})
    assert all(issubclass(w.category, BarkWarning) and "changes nothing on this trunk" in str(w.message) for w in said)
    assert small.simulation().state.n_bases == n


@pytest.mark.parametrize(
    "name, f_max, G", [("vertical", 0.0028, 0.014), ("reticulate", 0.005, 0.011), ("diamond", 0.008, 0.007)]
)
def test_shipped_regimes_match_table_2(name, f_max, G):
    s = Scene.from_toml(SCENE_DIR / f"{name}.toml")
    assert s.mechanics.f_max == f_max
    assert s.strategies["growth"].G == G
    assert s.lattice.n_bases == 3000 and s.lattice.offsets == (21, 34)
    assert s.lattice.jitter > 0 or s.strategies["breaker"].spread > 0  # symmetry breaking


def test_vertical_scene_equals_defaults():
    """The default scene is the vertical regime: same settings apart from the [scene] text."""
    shipped = Scene.from_toml(SCENE_DIR / "vertical.toml").to_dict()
    default = Scene.from_dict({}).to_dict()
    shipped.pop("scene"), default.pop("scene")
    assert shipped == default


def test_a_shipped_scene_runs_by_its_name_and_a_path_names_a_file(tmp_path, monkeypatch):
    from bark.engine.scene import SHIPPED, find_scene, shipped_scenes

    names = shipped_scenes()
    assert {"vertical", "reticulate", "diamond", "whole-tree", "whole-tree-small"} <= set(names)
    assert all(p.parent == SHIPPED and p.suffix == ".toml" for p in names.values())
    assert find_scene("whole-tree") == find_scene("whole-tree.toml") == SHIPPED / "whole-tree.toml"
    assert Scene.from_toml("reticulate").to_dict() == Scene.from_toml(SHIPPED / "reticulate.toml").to_dict()
    monkeypatch.chdir(tmp_path)
    small = '[lattice]\nn_bases = 400\n[run]\nuntil_time = 1.0\n'
    (tmp_path / "reticulate").write_text(small)
    with pytest.warns(BarkWarning, match=r"scene 'reticulate' is the scene bark ships; the file 'reticulate' here is "
                                         r"not read \('\./reticulate' names it\)"):
        assert Scene.from_toml("reticulate").lattice.n_bases == 3000  # a bare name is the shipped scene
    assert Scene.from_toml("./reticulate").lattice.n_bases == 400     # a path is a file
    (tmp_path / "reticulate").unlink()
    (tmp_path / "reticulate").mkdir()  # an earlier --out reticulate
    with pytest.warns(BarkWarning, match="the folder 'reticulate' here is not read"):
        assert Scene.from_toml("reticulate").lattice.n_bases == 3000
    (tmp_path / "diamond.toml").write_text(small)
    with pytest.warns(BarkWarning, match=r"the file 'diamond.toml' here is read, not the scene bark ships"):
        assert Scene.from_toml("diamond.toml").lattice.n_bases == 400
    (tmp_path / "mine").write_text(small)
    assert Scene.from_toml("mine").lattice.n_bases == 400  # no scene bark ships is called so: the file
    with pytest.raises(BarkError) as err:
        Scene.from_toml("no-such-scene")
    assert "'no-such-scene' does not exist" in str(err.value) and "whole-tree" in str(err.value)
    with pytest.raises(BarkError) as err:
        Scene.from_toml("sub/whole-tree")  # a path with a folder is a path: no shipped scene is guessed
    assert "shipped" not in str(err.value) and "\n" not in str(err.value)


def test_bark_scenes_lists_each_shipped_scene_with_what_it_is():
    from click.testing import CliRunner

    from bark.engine.scene import shipped_scenes
    from bark_cli.main import cli

    result = CliRunner().invoke(cli, ["scenes"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    for name in shipped_scenes():
        assert any(line.split("│")[1].strip() == name for line in result.output.splitlines() if line.count("│") >= 3), name
    assert "Table 1 whole grasstree" in result.output


def test_scene_toml_gives_the_scene_back_setting_for_setting():
    """Every shipped scene, resolved and written as scene.toml, reads back as the same scene."""
    import tomllib

    from bark.engine.scene import shipped_scenes

    for name, path in shipped_scenes().items():
        scene = Scene.from_toml(path)
        text = scene.to_toml()
        assert Scene.from_dict(tomllib.loads(text)).to_dict() == scene.to_dict(), name


@pytest.mark.parametrize("command", [["plan"], ["simulate", "--until-time", "0.5", "--n-bases", "300", "--out", "o",
                                                 "--quiet", "--scene"], ["sweep", "--grid", "growth.G=0.02", "--set",
                                                                         "run.until_time=0.5", "--set",
                                                                         "lattice.n_bases=300", "--out", "s",
                                                                         "--quiet", "--scene"]])
def test_a_folder_named_as_a_shipped_scene_does_not_shadow_it(command, tmp_path, monkeypatch):
    """An earlier ``--out vertical`` made ``--scene vertical`` fail ("is a directory"): a bare name
    is the shipped scene, and the command says that the folder here is not read."""
    from click.testing import CliRunner

    from bark_cli.main import cli

    monkeypatch.chdir(tmp_path)
    (tmp_path / "vertical").mkdir()
    result = CliRunner().invoke(cli, [*command, "vertical"])
    assert result.exit_code == 0, result.output
    assert "the folder 'vertical' here is not read ('./vertical' names it)" in result.stderr
    assert "Traceback" not in result.output
