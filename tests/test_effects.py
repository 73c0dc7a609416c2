"""Scenes simulate only the effects they ask for: checked by instrumentation, not by reading config."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from bark import Stop
from bark.model.effects import DEFAULT, EFFECTS, resolve
from bark.errors import BarkError
from bark.engine.scene import Scene
from bark.studies import runner
from bark_cli.main import cli
from conftest import REPO_ROOT

SCENES = REPO_ROOT / "bark" / "scenes"
SMALL = {"lattice": {"n_bases": 400}, "growth": {"G": 0.05}, "run": {"until_time": 6.0, "until_patches": None}}


def _scene(want, **extra):
    data = {**SMALL, **extra, "effects": {"want": list(want)}}
    return Scene.from_dict(data)


def test_resolution_adds_what_is_needed_and_says_why():
    got = resolve(["pattern-image"])
    assert got == {"secondary-growth": "needed by fracture", "fracture": "needed by pattern-image",
                   "pattern-image": "asked for"}
    assert set(resolve(DEFAULT)) == set(DEFAULT)
    with pytest.raises(BarkError) as err:
        resolve(["pattern-image", "sparkles"])
    assert "sparkles" in str(err.value) and "\n" not in str(err.value)


def test_image_and_mesh_not_asked_means_matplotlib_and_meshio_never_imported(tmp_path):
    code = (
        "import sys\n"
        "from bark_cli.main import cli\n"
        f"try:\n    cli.main(['simulate', '--scene', {str(SCENES / 'statistics-only.toml')!r}, '--n-bases', '400',"
        f" '--until-patches', '40', '--until-time', '1000', '-G', '0.05', '--out', {str(tmp_path / 'out')!r}, '--quiet'])\n"
        "except SystemExit as e:\n    assert e.code == 0, e.code\n"
        "print('matplotlib' in sys.modules, 'meshio' in sys.modules, sorted(p.name for p in __import__('pathlib').Path("
        f"{str(tmp_path / 'out')!r}).iterdir()))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "False False ['patches.csv', 'scene.toml', 'summary.json']"


def test_image_asked_imports_matplotlib_and_draws(tmp_path):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["simulate", "--scene", str(SCENES / "pattern-image.toml"), "--n-bases", "400",
                                      "-G", "0.05", "--until-time", "6", "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == ["pattern.png", "scene.toml", "summary.json"]


def test_the_library_draws_what_the_scene_asks_as_the_command_does(tmp_path):
    """``runner.run`` is the same run as ``bark simulate``: the same files, pictures included."""
    from bark.engine.scene import read_toml
    from bark.studies import runner

    path = tmp_path / "scene.toml"
    path.write_text("[lattice]\nn_bases = 400\n[growth]\nG = 0.05\n[run]\nuntil_time = 6.0\n[effects]\n"
                    "want = ['pattern-image', 'tree-image', 'animation', 'fracture-history', 'break-log']\n"
                    "frame_every = 2.0\nhistory_every = 2.0\n")
    outcome = runner.run(Scene.from_dict(read_toml(path)), tmp_path / "library")
    assert outcome.failed == []
    result = CliRunner().invoke(cli, ["simulate", "--scene", str(path), "--quiet", "--out", str(tmp_path / "command")])
    assert result.exit_code == 0, result.output
    names = sorted(p.name for p in (tmp_path / "library").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "command").iterdir())
    assert {"pattern.png", "tree.png", "development.gif", "fracture.png"} <= set(names)


def test_a_picture_nothing_can_draw_is_reported_not_drawn(tmp_path, monkeypatch):
    from bark.contract import registry
    from bark.studies import runner

    monkeypatch.setattr(registry, "picture_writers", lambda: None)  # the core alone: no bark_cli installed
    outcome = runner.run(_scene(["pattern-image", "tree-image", "break-log"]), tmp_path / "out")
    assert sorted(outcome.failed) == [f"{name}: not drawn (nothing installed draws {effect!r} (bark_cli's "
                                      "bark.pictures entry point))" for name, effect in
                                      (("pattern.png", "pattern-image"), ("tree.png", "tree-image"))]
    assert (tmp_path / "out" / "breaks.csv").exists()


def test_bulges_configured_but_not_asked_never_run(monkeypatch):
    from bark_plugins.growth import BulgeGrowth

    def boom(*a, **k):
        raise AssertionError("bulge code ran")

    monkeypatch.setattr(BulgeGrowth, "radius", boom)
    monkeypatch.setattr(BulgeGrowth, "regions_at", boom)
    bulge = {"name": "bulge", "bulges": [{"z": 0.1, "half_width": 0.05, "magnitude": 0.01}]}
    sim = _scene(["anchors", "damping", "fracture"], growth=bulge).simulation()
    sim.run(Stop(until_time=2.0))
    assert type(sim.growth).__name__ == "SqrtGrowth"
    with pytest.raises(AssertionError, match="bulge code ran"):  # and asked for, it does run
        _scene(["bulges", "fracture"], growth=bulge).simulation().build()


def test_no_fracture_asked_means_no_breaker_is_called(monkeypatch):
    from bark_plugins.breakers import ThresholdBreaker

    monkeypatch.setattr(ThresholdBreaker, "select", lambda *a: (_ for _ in ()).throw(AssertionError("breaker ran")))
    sim = _scene(["anchors", "damping", "state-snapshot"]).simulation()
    sim.run(Stop(until_time=6.0))
    assert sim.breakers == () and sim.analyzers == () and sim.n_broken == 0
    assert np.max(sim.tension() / sim.state.fmax) > 1  # springs were over threshold: nothing broke them


def test_statistics_only_records_nothing_along_the_way():
    sim = _scene(["anchors", "damping", "patch-statistics"]).simulation()
    sim.run(Stop(until_time=6.0))
    assert sim.n_broken > 20  # it cracked ...
    assert len(sim.breaks) == 0 and sim.actions == []  # ... and kept no log, no frames, no triggers
    full = _scene(DEFAULT).simulation()
    full.run(Stop(until_time=6.0))
    assert len(full.breaks) == full.n_broken == sim.n_broken  # the same physics, with the log


def test_anchors_and_damping_off_when_not_asked():
    sim = _scene(["fracture"]).simulation()
    assert sim.mechanics.c == 0.0 and sim.mechanics.b == 0.0
    assert _scene(["fracture", "anchors", "damping"]).simulation().mechanics.b == 5.0


@pytest.mark.parametrize("data, key", [
    ({"effects": {"want": ["bulges", "fracture"]}}, "bulge"),
    ({"effects": {"want": ["anchors"]}, "run": {"until_patches": 10}}, "until_patches"),
    ({"effects": {"want": "fracture"}}, "want"),
    ({"effects": {"wanted": ["fracture"]}}, "wanted"),
    ({"effects": {"want": ["fracture"], "frame_every": 0}}, "frame_every"),
    ({"effects": {"want": ["fracture"], "window": -1.0}}, "window"),
])
def test_bad_effects_are_one_line(data, key):
    with pytest.raises(BarkError) as err:
        Scene.from_dict(data)
    assert "\n" not in str(err.value) and key in str(err.value)


def test_plan_shows_different_effect_sets_for_the_three_scenes():
    runner = CliRunner()
    shown = {}
    for name in ("statistics-only", "pattern-image", "everything"):
        result = runner.invoke(cli, ["plan", str(SCENES / f"{name}.toml")])
        assert result.exit_code == 0, result.output
        shown[name] = {line.split("│")[1].strip() for line in result.output.splitlines()
                       if line.count("│") >= 4 and "│ yes" in line}
    assert shown["statistics-only"] == {"secondary-growth", "anchors", "damping", "fracture", "patch-statistics"}
    assert shown["pattern-image"] == {"secondary-growth", "anchors", "damping", "fracture", "pattern-image"}
    assert shown["everything"] == set(EFFECTS) | {"bulges"}  # the model's effects and the bulge law's own


def _simulate_small(tmp_path, effects_table: str):
    """Run a 400-base scene with this [effects] table to t = 8 through the CLI; its output folder."""
    out, scene = tmp_path / "out", tmp_path / "scene.toml"
    scene.write_text(f"[effects]\n{effects_table}\n[lattice]\nn_bases = 400\n[growth]\nG = 0.05\n[run]\nuntil_time = 8.0\n")
    result = CliRunner().invoke(cli, ["simulate", "--scene", str(scene), "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    return out


def test_statistics_series_runs_the_analyzers_on_their_trigger(tmp_path):
    out = _simulate_small(tmp_path, 'want = ["anchors", "damping", "statistics-series"]\nseries_every = 2.0')
    import csv

    rows = list(csv.DictReader((out / "statistics.csv").read_text().splitlines()))
    # each row at the first step at or past its due time (0, 2, 4, 6, 8; steps are at most 0.3 long)
    t = np.array([float(r["t_tu"]) for r in rows])
    due = np.array([0.0, 2.0, 4.0, 6.0, 8.0])
    assert len(t) == len(due) and np.all((t >= due - 1e-9) & (t - due < 0.3))
    assert [int(r["n_broken"]) for r in rows] == sorted(int(r["n_broken"]) for r in rows)
    assert int(rows[-1]["n_broken"]) > 0 and rows[-1]["n_patches"] != ""


@pytest.mark.parametrize("n", [500, 60_000])  # drawn as dots, and as a raster (over SPRINGS_UP_TO)
def test_each_animation_frame_shows_its_own_pattern_only(tmp_path, n):
    """Each frame is drawn over the axes drawn once: nothing of the frame before shows through (a frame
    is the same image whether another came before it or not)."""
    from PIL import Image

    from bark.io.recorders import Frames
    from bark.analysis.pattern import PALETTE
    from bark_cli.animation import write_gif
    from bark_cli.plot import SPRINGS_UP_TO

    rng = np.random.default_rng(3)

    def frame(t, patches):
        uv = np.column_stack([rng.uniform(0, 2 * np.pi * 0.3, n), rng.uniform(0, 1, n)])
        uv[:2] = [[0.0, 0.0], [2 * np.pi * 0.3, 1.0]]  # the same extent in every frame: the same axes
        return (t, 0.3, uv.astype(np.float32), rng.integers(0, patches, n).astype(np.int32))

    first, second = frame(1.0, 3), frame(2.0, 40)
    both, alone = Frames(), Frames()
    both.frames, alone.frames = [first, second], [second]
    write_gif(both, tmp_path / "both.gif")
    write_gif(alone, tmp_path / "alone.gif")
    with Image.open(tmp_path / "both.gif") as a, Image.open(tmp_path / "alone.gif") as b:
        a.seek(1)
        later, own = np.asarray(a.convert("RGB")), np.asarray(b.convert("RGB"))
        a.seek(0)
        earlier = np.asarray(a.convert("RGB"))
    np.testing.assert_array_equal(later, own)
    assert np.count_nonzero((earlier != later).any(axis=-1)) > 1000  # and the two frames do differ
    if n > SPRINGS_UP_TO:  # composed in the patches' own palette: each patch's colour exactly
        colours = {tuple(c) for c in own.reshape(-1, 3)}
        assert {tuple(c) for c in PALETTE} <= colours
    dark = own.max(axis=-1) < 100
    spine = int(np.flatnonzero(dark.mean(axis=1) > 0.5)[0])  # the axes' top edge: a dark line across
    assert np.count_nonzero(dark[:spine]) > 50  # above it, the title, in dark ink


def test_graphml_is_the_graph_of_record(tmp_path):
    import networkx as nx

    from bark.io.output import write_graphml

    sim = _scene(DEFAULT).simulation()
    sim.run(Stop(until_time=6.0))
    write_graphml(tmp_path / "g.graphml", sim)
    g = nx.read_graphml(tmp_path / "g.graphml", node_type=int)
    assert sim.n_broken > 20
    assert g.number_of_nodes() == sim.state.n_bases and g.number_of_edges() == sim.state.n_springs  # every spring
    labels = sim.patch_labels()
    for node in (0, 137, 399):
        assert g.nodes[node]["patch"] == labels[node] and g.nodes[node]["z"] == pytest.approx(sim.state.x[node, 2])
        theta = np.degrees(np.arctan2(sim.state.anchor_dir[node, 1], sim.state.anchor_dir[node, 0]))
        assert g.nodes[node]["theta0_deg"] == pytest.approx(theta)  # degrees, as patches.csv
    intact = {frozenset((i, j)) for i, j, ok in g.edges(data="intact") if ok}
    assert intact == set(map(frozenset, sim.graph.edges))  # the intact edges: the graph of record
    log = sim.breaks.arrays()
    for k in log["spring"][:5]:
        i, j = sim.state.pairs[k]
        data = g.edges[int(i), int(j)]
        assert not data["intact"] and data["spring"] == k
        assert data["broke_t"] == log["t"][log["spring"] == k][0] and data["broke_tension"] == log["tension"][log["spring"] == k][0]
    i, j, data = next((i, j, d) for i, j, d in g.edges(data=True) if d["intact"])
    assert np.isnan(data["broke_t"]) and data["rest"] == pytest.approx(sim.state.rest[data["spring"]])


def test_animation_writes_one_frame_per_trigger(tmp_path):
    from PIL import Image

    out = _simulate_small(tmp_path, 'want = ["anchors", "damping", "animation"]\nframe_every = 2.0')
    assert sorted(p.name for p in out.iterdir()) == ["development.gif", "scene.toml", "summary.json"]
    with Image.open(out / "development.gif") as gif:
        assert gif.n_frames == 5  # due at t = 0, 2, 4, 6, 8


def test_the_animation_ends_in_the_colours_of_the_pattern(tmp_path):
    """The development animation's frames are coloured through the run (``lineage_colours``): the
    last, the run's end, as pattern.png colours it."""
    from bark.analysis.pattern import rgb, simulation_colours

    scene = Scene.from_dict({"lattice": {"n_bases": 1200}, "growth": {"G": 0.03},
                             "effects": {"want": ["anchors", "damping", "fracture", "animation"], "frame_every": 4.0},
                             "run": {"until_time": 16.0, "until_patches": None}})
    seen = {}

    def keep(sim, scene, recorded, path):  # the picture writer sees what the GIF is drawn from
        seen["frames"] = recorded["frames"]

    done = runner.run(scene, tmp_path / "run", pictures={"animation": ("development.gif", keep)})
    frames = seen["frames"]
    assert len(frames.colours) == len(frames.frames) == 5 and done.sim.patch_count(7) > 3
    np.testing.assert_array_equal(rgb(frames.colour_index(4, 7)), simulation_colours(done.sim, 7))


def test_pictures_come_in_the_format_and_resolution_asked_for(tmp_path):
    """--format pdf|svg writes every still picture so (the animation stays a GIF), --dpi sets a PNG's
    size, and a run in one format leaves none of an earlier run's pictures in another."""
    from PIL import Image

    from bark_cli.main import cli

    out = tmp_path / "out"
    base = ["simulate", "--n-bases", "400", "--until-time", "20", "--quiet", "--out", str(out)]
    sizes = {}
    for dpi in (60, 120):
        assert CliRunner().invoke(cli, [*base, "--dpi", str(dpi)]).exit_code == 0
        with Image.open(out / "pattern.png") as image:
            sizes[dpi] = image.size
    assert sizes[120][0] == pytest.approx(2 * sizes[60][0], rel=0.05)
    result = CliRunner().invoke(cli, [*base, "--format", "pdf"])
    assert result.exit_code == 0, result.output
    pdf = (out / "pattern.pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and not (out / "pattern.png").exists()
    assert b"/FontFile2" in pdf and b"/Type3" not in pdf  # TrueType text a journal's tools can edit
    result = CliRunner().invoke(cli, [*base, "--format", "svg"])
    assert result.exit_code == 0, result.output
    svg = (out / "pattern.svg").read_text()
    assert "<svg" in svg[:500] and not (out / "pattern.pdf").exists()
    assert "<text" in svg  # text as text, not glyphs drawn as paths
    result = CliRunner().invoke(cli, [*base, "--format", "bmp"])
    assert result.exit_code == 2 and "--format" in result.stderr
