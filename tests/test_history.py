"""The history effect: a ParaView time series (tree.pvd and a mesh a frame) and history.nc for xarray."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest
import xarray as xr

from bark.engine.scene import Scene
from bark.studies import runner

WANT = ["bulges", "anchors", "damping", "patch-statistics", "history", "checkpoints"]


@pytest.fixture(scope="module")
def history(tmp_path_factory):
    out = tmp_path_factory.mktemp("history") / "run"
    scene = Scene.from_toml("whole-tree-small", {"effects": {"want": WANT, "frame_every": 5.0}, "run": {"until_time": 12.0}})
    return runner.run(scene, out), out


def test_the_pvd_series_lists_a_mesh_a_frame_on_the_run_s_time_axis(history):
    outcome, out = history
    sets = ET.parse(out / "tree.pvd").getroot().find("Collection").findall("DataSet")
    times = [float(d.get("timestep")) for d in sets]
    assert times[0] == 0.0 and times[-1] == pytest.approx(12.0) and len(times) == 4  # the start, 5, 10, the end
    assert all(b > a for a, b in zip(times, times[1:]))
    sim = outcome.sim
    for d in sets:
        mesh = meshio.read(out / d.get("file"))
        n = len(mesh.cell_data["base"][0])
        assert mesh.cells[0].data.shape == (n, 4) and mesh.point_data["colour"].shape == (4 * n, 3)
        assert np.abs(mesh.points[:, 2]).max() < 1.0  # metres: the small tree is 25 cm tall
    assert n == sim.state.n_bases and (mesh.cell_data["patch"][0] == sim.patch_labels()).all()


def test_history_nc_opens_in_xarray_with_every_frame(history):
    outcome, out = history
    sim = outcome.sim
    with xr.open_dataset(out / "history.nc") as ds:
        assert ds.sizes["time"] == 4 and ds.sizes["base"] == sim.state.n_bases and ds.sizes["spring"] == sim.state.n_springs
        last = ds.isel(time=-1)
        assert np.allclose(last.x.values, 0.3 * sim.state.x, rtol=1e-6)  # metres, float32
        assert (last.patch.values == sim.patch_labels()).all()
        assert (last.intact.values == sim.state.intact).all() and int(last.n_broken) == sim.n_broken
        first = ds.isel(time=0)
        n0 = int(first.n_bases)
        assert n0 == sim.lattice.initial and np.isnan(first.x.values[n0:]).all() and (first.patch.values[n0:] == -1).all()
        assert (first.intact.values[int(first.n_springs):] == -1).all()  # springs not made yet
        intact = ds.intact.values
        assert not ((intact[:-1] == 0) & (intact[1:] == 1)).any()  # a broken spring never comes back
        assert ((intact[:-1] == 1) & (intact[1:] == 0)).any()  # and some break between frames
        assert ds.x.attrs["units"] == "m" and float(ds.t[-1]) == pytest.approx(12.0)
        since = ds.time.values - np.datetime64("2000-01-01")  # decoded: dates from the epoch that stands for the start
        assert ds.time.dtype.kind == "M" and since[-1] == np.timedelta64(int(12.0 * 88.5 * 86400), "s")
        assert "years" in ds.coords and float(ds.years[-1]) == pytest.approx(12.0 * 88.5 / 365.25)
        assert ds.attrs["Conventions"] == "CF-1.10" and "t" in ds.coords
        for name, v in ds.variables.items():  # every variable says its units and what it is
            if name != "time":  # decoded: its units went into its type (dates)
                assert v.attrs.get("units") and v.attrs.get("long_name"), name
        assert ds.intact.attrs["flag_meanings"] == "not_yet_made broken intact"
        units = {k: ds[k].attrs.get("units") for k in ("mean_orientation_deg", "circular_sd_deg", "mean_anisotropy",
                                                          "fraction_within_45_deg", "largest_patch_share")}
        assert units == {"mean_orientation_deg": "degrees", "circular_sd_deg": "degrees", "mean_anisotropy": "1",
                         "fraction_within_45_deg": "1", "largest_patch_share": "1"}  # a fraction is not in degrees


def test_history_nc_meets_the_cf_conventions(history, tmp_path):
    """The IOOS compliance checker's CF 1.10 suite finds no error (its high-priority findings)."""
    import json

    from compliance_checker.runner import CheckSuite, ComplianceChecker

    _, out = history
    CheckSuite.load_all_available_checkers()
    report = tmp_path / "cf.json"
    passed, failed = ComplianceChecker.run_checker(str(out / "history.nc"), ["cf:1.10"], 0, "lenient",
                                                   output_filename=str(report), output_format="json")
    found = json.loads(report.read_text())["cf:1.10"]
    errors = [m for check in found["high_priorities"] for m in check["msgs"]]
    assert passed and not failed and found["high_count"] == 0 and not errors, errors


def test_a_resumed_history_is_the_uninterrupted_one_to_the_byte(history, tmp_path):
    outcome, whole = history
    part = tmp_path / "part"
    seen = []
    runner.run(outcome.scene, part, checkpoint_every=1e-9, observe=lambda s, stop: seen.append(s.state.t),
               interrupted=lambda: "interrupted" if seen and seen[-1] >= 6.0 else None)
    runner.resume(part)
    for name in ("history.nc", "tree.pvd", *(f"history/tree-{k:04d}.vtu" for k in range(4))):
        assert (part / name).read_bytes() == (whole / name).read_bytes(), name


def test_a_fresh_run_removes_an_earlier_history_s_frames(history, tmp_path):
    outcome, _ = history
    out = tmp_path / "run"
    runner.run(outcome.scene, out)
    (out / "history" / "tree-0099.vtu").write_bytes(b"stale")  # as if an earlier, longer run wrote it
    (out / "history" / ".tree-0001.vtu.x1y2.tmp").write_bytes(b"half")  # a write a kill cut short
    runner.run(Scene.from_toml("whole-tree-small", {"effects": {"want": ["bulges", "anchors", "damping"]},
                                                   "run": {"until_time": 1.0}}), out)
    assert not list((out / "history").iterdir()) and not (out / "tree.pvd").exists()
