"""Regenerate the paper's Figs. 7, 8 and 9, and the fracture power law of its Discussion, from the
shipped scenes — one command each, through the same ``bark`` commands a user types (printed as they
run)::

    python examples/paper/figures.py fig7       # the three regimes: pattern, radial plot, histogram
    python examples/paper/figures.py fig8       # quartet analysis against the photographs
    python examples/paper/figures.py fig9       # the G × f_max montage
    python examples/paper/figures.py fractures  # initial fractures against the dissipation rate
    python examples/paper/figures.py fig11      # the whole tree's regions over c × b × jitter
    python examples/paper/figures.py packing    # Ridley's packing: what each leaf-size law keeps
    python examples/paper/figures.py recovery   # bark fit finds known (G, f_max) again: 5 points
    python examples/paper/figures.py fit        # posteriors for the two photographs' summaries
    python examples/paper/figures.py resins     # viscoelastic, plastic, disordered resin: the three regimes
    python examples/paper/figures.py sbc        # simulation-based calibration of bark fit: 60 prior draws
    python examples/paper/figures.py boundary   # the elongated/reticulate boundary near a bulge, as a law

Options: ``--out DIR`` (default ``runs/paper``), ``--workers N`` (sweeps).  Runs already there are
reused: ``bark sweep`` skips finished points, and a regime's run folder with its summary is kept.
"""

from __future__ import annotations

import argparse
import json
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
SCENES = HERE.parent.parent / "bark" / "scenes"
REGIMES = {  # Fig. 7's rows: Table 2's first regime, the reticulate fit (43 %), the third regime
    "vertical": SCENES / "vertical.toml",
    "intermediate-43": HERE / "intermediate-43.toml",
    "diamond": SCENES / "diamond.toml",
}
FRACTURE_B = "mechanics.b=0.5,1,2,5,10,20,50"
FRACTURE_GRID = ["--grid", FRACTURE_B, "--grid", "growth.G=0.005,0.007,0.01,0.014,0.02,0.03,0.04"]
FRACTURE_SLOW = ["--grid", FRACTURE_B, "--grid", "growth.G=0.003", "--set", "run.until_time=900"]
"""The slowest growth, its first breaks near t = 280: a sweep of its own, run longer."""
FRACTURE_SEEDS = 10
FIG11_GRID = ["--grid", "mechanics.c=0.03,0.06,0.1,0.15,0.2", "--grid", "mechanics.b=2,5",
              "--grid", "lattice.jitter=0.03,0.05"]
FIG11_EFFECTS = '["bulges", "anchors", "damping", "patch-statistics"]'  # the statistics only: no pictures
FIG11_AXES = ("mechanics.c", "mechanics.b", "lattice.jitter")


def bark(*args: str) -> None:
    """Run one ``bark`` command, shown as typed; stop on its failure (it has said why)."""
    print("$ bark " + " ".join(args), flush=True)
    done = subprocess.run([sys.executable, "-m", "bark_cli", *args])
    if done.returncode:
        sys.exit(done.returncode)


def regime_runs(out: Path) -> dict[str, Path]:
    runs = {}
    for name, scene in REGIMES.items():
        run = out / "runs" / name
        if not (run / "summary.json").is_file():
            bark("simulate", "--scene", str(scene), "--out", str(run), "--quiet")
        runs[name] = run
    return runs


def fig7(out: Path, workers: int) -> None:
    """Fig. 7: a row per regime — its pattern, radial plot and orientation histogram — drawn as
    vectors into one figure (fig7.pdf; fig7.png beside it)."""
    from bark.analysis.pattern import read
    from bark_cli.figures import draw_histogram, draw_radial
    from bark_cli.pictures import PatternData
    from bark_cli.plot import draw_pattern, new_figure, save_figure

    runs = regime_runs(out)
    fig = new_figure(figsize=(15, 4.8 * len(runs)), layout="constrained")
    for k, (name, run) in enumerate(runs.items()):
        stats = read(run)
        draw_pattern(fig.add_subplot(len(runs), 3, 3 * k + 1), PatternData.of_state(run, 7), 7, title=name)
        draw_radial(fig.add_subplot(len(runs), 3, 3 * k + 2, projection="polar"), stats)
        draw_histogram(fig.add_subplot(len(runs), 3, 3 * k + 3, projection="polar"), stats)
    for name in ("fig7.pdf", "fig7.png"):
        save_figure(fig, out / name)
    print(f"Fig. 7: {out / 'fig7.pdf'} and .png (rows: {', '.join(runs)}; columns: pattern, radial plot, histogram)")


def fig8(out: Path, workers: int) -> None:
    runs = regime_runs(out)
    observed = [str(HERE / "observed-elongated.toml"), str(HERE / "observed-reticulate.toml")]
    simulated = [str(runs["vertical"]), str(runs["intermediate-43"])]
    bark("compare", *simulated, *observed, "--out", str(out / "fig8"))
    # bark's phyllotactic spiral turns the other way from the photographed tree's (examples/paper/README.md): the same
    # comparison with the simulated reticulate bark seen in a mirror
    bark("compare", *simulated, *observed, "--mirror", "2", "--out", str(out / "fig8-mirrored"))
    print(f"Fig. 8: {out / 'fig8' / 'quartets.png'} and {out / 'fig8-mirrored' / 'quartets.png'}")


def fig9(out: Path, workers: int) -> None:
    bark("sweep", "--workers", str(workers), "--out", str(out / "fig9"), "--quiet")
    print(f"Fig. 9: {out / 'fig9' / 'montage.png'}")


def fractures(out: Path, workers: int) -> None:
    """The paper's brittleness claim, measured: initial fractures against the dissipation rate over
    :data:`FRACTURE_GRID` and :data:`FRACTURE_SLOW` (b over two decades, G over a factor 13,
    :data:`FRACTURE_SEEDS` seeds a point), fitted as a power law in log–log with the exponent's 95 % interval, and checked: whether
    log–log is straight (adding (log rate)²) and whether the rate alone sets the count (adding log b
    and log G); F tests, p printed.  Against the measured rate first, the growth-driven one second."""
    import numpy as np

    from bark.analysis.fracture import check_power_law, power_law
    from bark_cli.figures import plot_power_law

    folder = out / "fractures"
    rows = []
    for grid, where in ((FRACTURE_SLOW, folder / "slow"), (FRACTURE_GRID, folder)):
        bark("sweep", "--scene", str(HERE / "fractures.toml"), *grid, "--seeds", str(FRACTURE_SEEDS),
             "--workers", str(workers), "--out", str(where), "--quiet")
        con = sqlite3.connect(where / "sweep.sqlite")
        rows += con.execute('SELECT "mechanics.b", "growth.G", seed, dissipation_rate, growth_dissipation, '
                            'initial_fractures FROM runs ORDER BY "growth.G", "mechanics.b", seed').fetchall()
        con.close()
    b, G, _, measured, growth, count = (np.array([np.nan if v is None else v for v in c], dtype=float)
                                        for c in zip(*rows))
    rates = {  # two readings of "the rate of energy dissipation" (docs/patterns.md: Fracture history)
        "dissipation_rate": (measured, "measured dissipation rate (damping power per base, first break to most cracks)"),
        "growth_dissipation": (growth, "growth-driven rate b·(dr/dt)² at the first break (set by b and G)"),
    }
    report = {}
    print(f"{'against':>19} {'runs':>10} {'exponent':>9} {'95 % CI':>19} {'R²':>6}")
    for name, (x, label) in rates.items():
        fits = {"all": power_law(x, count)}
        for g in sorted(set(G.tolist())):
            fits[f"G = {g:g}"] = power_law(x[G == g], count[G == g])
        check = check_power_law(x, count, {"b": b, "G": G})
        plot_power_law(x, count, G, fits["all"], folder / f"power-law-{name}.png", "G", label, check)
        for group, f in fits.items():
            print(f"{name:>19} {group:>10} {f.exponent:9.3f} [{f.ci[0]:8.3f}, {f.ci[1]:8.3f}] {f.r2:6.3f}   (n = {f.n})")
        print(f"{name:>19} over {check.decades:.2f} decades: straight in log-log? p = {check.curvature_p:.3g}; "
              f"the rate alone sets the count? p = {check.alone_p:.3g}")
        report[name] = {k: {"exponent": f.exponent, "ci": f.ci, "level": f.level, "prefactor": f.prefactor, "r2": f.r2,
                            "n": f.n} for k, f in fits.items()}
        report[name]["check"] = {"decades": check.decades, "curvature_p": check.curvature_p,
                                 "alone_p": check.alone_p, "n": check.n}
    print(f"{'b':>5} {'G':>6} {'dissipation rate':>27} {'initial fractures':>24}   (mean, lowest–highest of the seeds)")
    for g in sorted(set(G.tolist())):
        for bb in sorted(set(b.tolist())):
            on = (G == g) & (b == bb)
            r, c = measured[on], count[on]
            print(f"{bb:5g} {g:6g} {np.nanmean(r):11.3g} ({np.nanmin(r):.3g}–{np.nanmax(r):.3g}) "
                  f"{np.nanmean(c):9.1f} ({np.nanmin(c):.0f}–{np.nanmax(c):.0f})")
    (folder / "power-law.json").write_text(json.dumps(report, indent=2))
    print(f"power laws: {folder}/power-law-*.png, {folder / 'power-law.json'}")


def _fig11_seed(straight: dict, bulge: dict) -> tuple[bool, float, float]:
    """Whether one run meets Fig. 11's three tests (README: Fig. 11 on whole patches), and the
    bulges' axial distance from the straight trunk's mean and their anisotropy's shortfall."""
    from bark.analysis.circular import axial_difference

    dmean = abs(float(axial_difference(bulge["mean_orientation_deg"], straight["mean_orientation_deg"])))
    daniso = straight["mean_anisotropy"] - bulge["mean_anisotropy"]
    ok = (straight["largest_patch_share"] <= 0.1 and abs(straight["mean_orientation_deg"] - 90) <= 15
          and straight["circular_sd_deg"] < 25 and (dmean > 20 or daniso > 0.1))
    return ok, dmean, daniso


def fig11(out: Path, workers: int) -> None:
    """Fig. 11's comparison on whole patches: the shipped whole tree over anchor stiffness c, damping
    b and the lattice's jitter, three seeds a point; per point the straight trunk of the start (its
    largest patch's share, the mean orientation and SD of its patches, their anisotropy) and the
    bulges' difference from it, each seed's figure, and whether the point meets the three tests:
    no patch over 10 % of the straight trunk's bases, its mean within 15° of vertical with an SD
    under 25°, and the bulges' mean over 20° from it or their anisotropy over 0.1 lower.  Then the
    two bulges of the trunk of the start over their own G and f_max (:data:`FIG11_BULGES`) at the
    scene's c, b and jitter; fig11-map.png maps the seeds that pass over both.  Last, the whole tree
    with Table 1's own values (:data:`FIG11_TABLE1`) beside the shipped scene, 3 seeds each."""
    import csv

    folder = out / "fig11"
    bark("sweep", "--scene", str(SCENES / "whole-tree.toml"), *FIG11_GRID, "--seeds", "3", "--workers", str(workers),
         "--set", f"effects.want={FIG11_EFFECTS}", "--out", str(folder), "--quiet")
    con = sqlite3.connect(folder / "sweep.sqlite")
    axes = ", ".join(f'"{a}"' for a in FIG11_AXES)
    got = con.execute(f"SELECT {axes}, seed, regions FROM runs ORDER BY {axes}, seed").fetchall()
    con.close()
    points: dict[tuple, list[dict]] = {}
    for *settings, _seed, regions in got:
        points.setdefault(tuple(settings), []).append(json.loads(regions))
    columns = [*FIG11_AXES, "straight share", "straight mean", "straight SD", "straight anisotropy",
               "bulge − straight mean", "straight − bulge anisotropy", "passes"]
    lines, passing = [], {}
    for settings, seeds in points.items():
        s = [r["straight"] for r in seeds]
        tests = [_fig11_seed(r["straight"], r["bulge"]) for r in seeds]
        passing[settings] = sum(t[0] for t in tests)
        lines.append([*(f"{v:g}" for v in settings),
                      " / ".join(f"{x['largest_patch_share']:.3f}" for x in s),
                      " / ".join(f"{x['mean_orientation_deg']:.1f}" for x in s),
                      " / ".join(f"{x['circular_sd_deg']:.1f}" for x in s),
                      " / ".join(f"{x['mean_anisotropy']:.2f}" for x in s),
                      " / ".join(f"{t[1]:.1f}" for t in tests), " / ".join(f"{t[2]:.2f}" for t in tests),
                      f"{passing[settings]} of {len(seeds)}"])
    with open(folder / "fig11-study.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([columns, *lines])
    print("| " + " | ".join(columns) + " |\n|" + "---|" * len(columns))
    for line in lines:
        print("| " + " | ".join(line) + " |")
    print(f"table: {folder / 'fig11-study.csv'} (each cell: seeds 0 / 1 / 2; orientations in degrees)")

    scene_bulges = _toml(SCENES / "whole-tree.toml")["growth"]["bulges"]
    points = folder / "bulges-points.csv"  # the two bulges of the trunk of the start take each (G, f_max)
    rows = [[g] * len(scene_bulges) + [f] for g in FIG11_BULGES["G"] for f in FIG11_BULGES["f_max"]]
    points.write_text("\n".join(",".join(map(str, r)) for r in
                                [[*(f"growth.bulges.{i}.G" for i in range(len(scene_bulges))), "breaker.regions.bulge"], *rows]) + "\n")
    bark("sweep", "--scene", str(SCENES / "whole-tree.toml"), "--points", str(points), "--seeds", "3",
         "--workers", str(workers), "--set", f"effects.want={FIG11_EFFECTS}", "--out", str(folder / "bulges"), "--quiet")
    con = sqlite3.connect(folder / "bulges" / "sweep.sqlite")
    got = con.execute('SELECT "growth.bulges.0.G", "breaker.regions.bulge", seed, regions FROM runs '
                      'ORDER BY "growth.bulges.0.G", "breaker.regions.bulge", seed').fetchall()
    con.close()
    tested: dict[tuple, list] = {}
    for g, f, _seed, regions in got:
        r = json.loads(regions)
        tested.setdefault((g, f), []).append(_fig11_seed(r["straight"], r["bulge"]))
    bulges = {}  # (G, f_max) → seeds passing
    for (g, f), passed in tested.items():
        bulges[(g, f)] = sum(p[0] for p in passed)
        print(f"bulges G {g:g}, f_max {f:g}: bulge − straight mean "
              + " / ".join(f"{p[1]:.1f}" for p in passed) + f"; {bulges[(g, f)]} of {len(passed)} pass")
    _fig11_table1(folder, workers)
    _fig11_map(passing, bulges, folder / "fig11-map.png")
    own = (scene_bulges[0]["G"], _toml(SCENES / "whole-tree.toml")["breaker"]["regions"]["bulge"])
    mapped = [*passing.values(), *(v for k, v in bulges.items() if k != own)]  # the shipped scene's point once
    runs, every = sum(mapped), sum(v == 3 for v in mapped)
    print(f"Fig. 11 holds on {runs} of {3 * len(mapped)} runs ({100 * runs / (3 * len(mapped)):.0f} %); on every seed at "
          f"{every} of {len(mapped)} points (the shipped scene's counted once); map: {folder / 'fig11-map.png'}")


FIG11_BULGES = {"G": (0.01, 0.02, 0.03), "f_max": (0.005, 0.006, 0.007)}
"""The bulges' own growth constant and breaking force mapped (the scene: 0.02 and Table 1's 0.006)."""


FIG11_TABLE1 = ["--set", "mechanics.c=0.03", "--set", "mechanics.b=2", "--set", "lattice.jitter=0.05",
                "--grid", "growth.series.0.G=0.02"]
"""The whole tree with Table 1's own values where the shipped scene departs from them: c, b, the
series' bulges' G at the peak (0.02) and bark's default jitter (Table 1 has none)."""


def _fig11_table1(folder: Path, workers: int) -> None:
    """The whole tree with Table 1's values (:data:`FIG11_TABLE1`), 3 seeds to 60 years, its regions'
    statistics printed beside the shipped scene's (the sweep's c 0.1, b 5, jitter 3 % point)."""
    bark("sweep", "--scene", str(SCENES / "whole-tree.toml"), *FIG11_TABLE1, "--seeds", "3", "--workers", str(workers),
         "--set", f"effects.want={FIG11_EFFECTS}", "--out", str(folder / "table1"), "--quiet")
    shown = {}
    for name, db, where in (("Table 1's values", folder / "table1" / "sweep.sqlite", ""),
                            ("the shipped scene", folder / "sweep.sqlite",
                             ' WHERE "mechanics.c" = 0.1 AND "mechanics.b" = 5 AND "lattice.jitter" = 0.03')):
        con = sqlite3.connect(db)
        shown[name] = [json.loads(r) for (r,) in con.execute(f"SELECT regions FROM runs{where} ORDER BY seed")]
        con.close()
    print("| whole tree, 60 years | straight: largest patch | straight: patches | straight: mean | straight: SD | "
          "straight: anisotropy | bulges: mean | bulges: SD | bulges: anisotropy | Fig. 11's tests |\n|" + "---|" * 10)
    for name, seeds in shown.items():
        s, b = [r["straight"] for r in seeds], [r["bulge"] for r in seeds]
        cells = [" / ".join(f"{x[k]:{fmt}}" for x in xs) for xs, k, fmt in (
            (s, "largest_patch_share", ".3f"), (s, "n_patches", "d"), (s, "mean_orientation_deg", ".1f"),
            (s, "circular_sd_deg", ".1f"), (s, "mean_anisotropy", ".2f"), (b, "mean_orientation_deg", ".1f"),
            (b, "circular_sd_deg", ".1f"), (b, "mean_anisotropy", ".2f"))]
        passed = sum(_fig11_seed(r["straight"], r["bulge"])[0] for r in seeds)
        print(f"| {name} | " + " | ".join(cells) + f" | {passed} of {len(seeds)} pass |")


def _toml(path: Path) -> dict:
    import tomllib

    return tomllib.loads(path.read_text())


def _fig11_map(passing: dict, bulges: dict, path: Path) -> None:
    """Seeds of three that meet Fig. 11's tests: a c × b panel per jitter, and the bulges' G × f_max."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    jitters = sorted({k[2] for k in passing})
    cs, bs = sorted({k[0] for k in passing}), sorted({k[1] for k in passing})
    gs, fs = FIG11_BULGES["G"], FIG11_BULGES["f_max"]
    fig, axes = plt.subplots(1, len(jitters) + 1, figsize=(3.8 * (len(jitters) + 1), 3.6),
                             gridspec_kw={"width_ratios": [len(cs)] * len(jitters) + [len(gs)]})
    cmap = plt.get_cmap("Greys", 4)

    def panel(ax, grid, xs, ys, xlabel, ylabel, title, shipped):
        ax.imshow(grid, origin="lower", cmap=cmap, vmin=-0.5, vmax=3.5, aspect="auto")
        for (i, j), v in np.ndenumerate(grid):
            ax.text(j, i, f"{v:.0f}", ha="center", va="center", color="white" if v >= 2 else "black", fontsize=9)
        ax.set_xticks(range(len(xs)), [f"{x:g}" for x in xs])
        ax.set_yticks(range(len(ys)), [f"{y:g}" for y in ys])
        ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
        if shipped is not None:
            ax.add_patch(plt.Rectangle((shipped[0] - 0.5, shipped[1] - 0.5), 1, 1, fill=False, lw=2.5, color="C3"))

    for ax, jit in zip(axes, jitters):
        grid = np.array([[passing.get((c, b, jit), np.nan) for c in cs] for b in bs])
        shipped = (cs.index(0.1), bs.index(5.0)) if jit == 0.03 and 0.1 in cs and 5.0 in bs else None
        panel(ax, grid, cs, bs, "anchor stiffness c (Table 1: 0.03)", "damping b (Table 1: 2)",
              f"jitter {100 * jit:g} % of the spacing", shipped)
    grid = np.array([[bulges.get((g, f), np.nan) for g in gs] for f in fs])
    panel(axes[-1], grid, gs, fs, "bulges' G (length / time½)", "bulges' f_max (force)",
          "bulges (c 0.1, b 5, 3 %)", (gs.index(0.02), fs.index(0.006)))
    fig.suptitle("Fig. 11 on whole patches: seeds of 3 that pass (red: the shipped scene)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


BOUNDARY_RANGES = ["--range", "growth.bulges.0.magnitude=0:0.1", "--range", "growth.bulges.0.G=0.007:0.028:log",
                   "--range", "growth.bulges.0.decay=0:0.01", "--range", "breaker.regions.bulge=0.0014:0.0084:log"]
"""The bulge's magnitude (up to half the trunk's starting radius), growth constant (half to twice the
trunk's), fading and threshold (half to three times the trunk's): a Latin hypercube over them."""
BOUNDARY_POINTS, BOUNDARY_FIT_SEEDS = 240, (0, 1)
"""Points of the design, three seeds each; the law is fitted on these seeds and tested on the third."""


def _table2(out: Path) -> dict[str, list[dict]]:
    """The summaries of Table 2's vertical and reticulate scenes, seeds 0–2."""
    runs = {}
    for name in ("vertical", "reticulate"):
        runs[name] = []
        for seed in range(3):
            run = out / "runs" / f"{name}-seed{seed}"
            if not (run / "summary.json").is_file():
                bark("simulate", "--scene", name, "--seed", str(seed), "--out", str(run), "--quiet")
            runs[name].append(json.loads((run / "summary.json").read_text()))
    return runs


def boundary(out: Path, workers: int) -> None:
    """The elongated/reticulate boundary as a law (``bark.analysis.boundary``): the trunk segment of
    ``boundary.toml`` with one bulge, over :data:`BOUNDARY_RANGES` (240 points, 3 seeds), each run
    stopped when the plain segment (Table 2's vertical scene, seed 0) has its 110 patches.  The bulge's
    pattern is elongated when its mean orientation lies nearer vertical than the midpoint between
    Table 2's vertical and reticulate scenes (3 seeds each).  The law, a logistic regression on the
    bulge's strain ratio ε_a/ε_h and ln(f_max/G) (each the bulge's profile-weighted mean), is fitted on
    seeds 0–1 and its misclassification measured on seed 2; ``boundary.png`` and ``boundary.json``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from bark.analysis.boundary import fit_boundary, nested_p, stretch_strains
    from bark.engine.scene import Scene
    from bark.io.files import write_json

    folder = out / "boundary"
    table2 = _table2(folder)
    t_stop = table2["vertical"][0]["t"]
    off = {k: [abs(r["mean_orientation_deg"] - 90) for r in v] for k, v in table2.items()}
    cut = (np.mean(off["vertical"]) + np.mean(off["reticulate"])) / 2
    print(f"stop at t = {t_stop!r} (vertical, seed 0: {table2['vertical'][0]['n_patches']} patches); elongated within "
          f"{cut:.1f}° of vertical: midway between the vertical scene's {np.mean(off['vertical']):.1f}° and the "
          f"reticulate scene's {np.mean(off['reticulate']):.1f}° (3 seeds each)")
    bark("sweep", "--scene", str(HERE / "boundary.toml"), "--design", "lhs", "--samples", str(BOUNDARY_POINTS),
         *BOUNDARY_RANGES, "--seeds", "3", "--workers", str(workers), "--set", f"run.until_time={t_stop!r}",
         "--out", str(folder), "--quiet")
    con = sqlite3.connect(folder / "sweep.sqlite")
    got = con.execute("SELECT scene, seed, regions, t FROM runs").fetchall()
    con.close()
    rows = []
    for scene, seed, regions, t in got:
        sc, bulge = json.loads(scene), json.loads(regions).get("bulge")
        if sc["run"]["until_time"] != t_stop:
            continue  # an older study's stop
        b = sc["growth"]["bulges"][0]
        law = Scene.from_dict(sc).strategies["growth"]
        hoop, axial = stretch_strains(law.radius, t, b["z"] - b["half_width"], b["z"] + b["half_width"])
        # the bulge's threshold and growth constant as the runs weight them: by its profile, here its mean
        w = float(np.mean(law.bulges[0].profile(np.linspace(b["z"] - b["half_width"], b["z"] + b["half_width"], 2001))))
        f = sc["mechanics"]["f_max"] + w * (sc["breaker"]["regions"]["bulge"] - sc["mechanics"]["f_max"])
        g = sc["growth"]["base"]["G"] + w * (b["G"] - sc["growth"]["base"]["G"])
        rows.append({"seed": seed, "ratio": axial / hoop, "log_f_over_G": float(np.log(f / g)), "log_f": float(np.log(f)),
                     "log_G": float(np.log(g)), "hoop": hoop, "axial": axial,
                     "patches": bulge["n_patches"] if bulge else 0,
                     "off": abs(bulge["mean_orientation_deg"] - 90) if bulge and bulge["n_patches"] else None,
                     "anisotropy": bulge["mean_anisotropy"] if bulge and bulge["n_patches"] else None})
    cracked = [r for r in rows if r["off"] is not None and r["patches"] >= CRACKED]
    print(f"{len(rows)} runs; {len(rows) - len(cracked)} with fewer than {CRACKED} patches in the bulge left out")
    fit_rows = [r for r in cracked if r["seed"] in BOUNDARY_FIT_SEEDS]
    test_rows = [r for r in cracked if r["seed"] not in BOUNDARY_FIT_SEEDS]

    def columns(rs, names):
        return np.array([[r[n] for n in names] for r in rs]), np.array([r["off"] < cut for r in rs])

    names = ("ratio", "log_f_over_G")
    law = fit_boundary(*columns(fit_rows, names), names)
    x_test, y_test = columns(test_rows, names)
    miss = law.misclassified(x_test, y_test)
    guess = min(y_test.mean(), 1 - y_test.mean())
    alone = {n: fit_boundary(*columns(fit_rows, (n,)), (n,)) for n in names}
    apart = fit_boundary(*columns(fit_rows, ("ratio", "log_f", "log_G")), ("ratio", "log_f", "log_G"))
    ratio_p = nested_p(law, apart)
    # the same law with anisotropy as the kind: elongated above the midpoint of the two scenes'
    a_cut = (np.mean([r["mean_anisotropy"] for r in table2["vertical"]])
             + np.mean([r["mean_anisotropy"] for r in table2["reticulate"]])) / 2
    by_a = [np.array([[r[n] for n in names] for r in rs]) for rs in (fit_rows, test_rows)]
    ya = [np.array([r["anisotropy"] >= a_cut for r in rs]) for rs in (fit_rows, test_rows)]
    law_a = fit_boundary(by_a[0], ya[0], names)
    miss_a = law_a.misclassified(by_a[1], ya[1])
    labels = {"ratio": "ε_a/ε_h", "log_f_over_G": "ln(f_max/G)"}
    print(f"law: logit P(elongated) = β0 + β1·ε_a/ε_h + β2·ln(f_max/G), fitted on seeds 0–1 ({law.n} runs):")
    for name, c, lo, hi in zip(("β0", *(f"β{i + 1} ({labels[n]})" for i, n in enumerate(names))), law.coef, law.low, law.high):
        print(f"  {name:22s} {c:8.3g}  (95 % interval {lo:.3g} to {hi:.3g})")
    print(f"  likelihood-ratio p against no feature {law.llr_p:.2g}, McFadden R² {law.pseudo_r2:.2f}")
    print(f"misclassified on seed 2: {miss:.3f} of {len(test_rows)} runs (always guessing the commoner kind: {guess:.3f}); "
          + "; ".join(f"{labels[n]} alone {alone[n].misclassified(*columns(test_rows, (n,))):.3f}" for n in names))
    ratio_adds_p = nested_p(alone["log_f_over_G"], law)
    print(f"the strain ratio added to ln(f_max/G) alone: likelihood-ratio p {ratio_adds_p:.2g}")
    print(f"ln f_max and ln G apart: {apart.coef[2]:.3g} and {apart.coef[3]:.3g} (the ratio's law: equal and opposite; "
          f"likelihood-ratio p of setting them apart {ratio_p:.2g})")
    print(f"with anisotropy as the kind (elongated from {a_cut:.3f}): misclassified {miss_a:.3f} on seed 2 "
          f"(commoner kind {min(ya[1].mean(), 1 - ya[1].mean()):.3f}), McFadden R² {law_a.pseudo_r2:.2f}")

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.8))
    seeds_at: dict[tuple, list[bool]] = {}  # a point's seeds share its features: its share of elongated seeds
    for r in cracked:
        seeds_at.setdefault((r["ratio"], r["log_f_over_G"]), []).append(r["off"] < cut)
    at = np.array(list(seeds_at))
    share = ax.scatter(at[:, 0], at[:, 1], s=16, c=[np.mean(v) for v in seeds_at.values()], cmap="coolwarm_r",
                       vmin=0, vmax=1, edgecolors="k", linewidths=0.3)
    fig.colorbar(share, ax=ax, label="share of its 3 seeds elongated")
    xs = np.linspace(*ax.get_xlim(), 50)
    ax.plot(xs, -(law.coef[0] + law.coef[1] * xs) / law.coef[2], "k-", label="law (seeds 0–1): P(elongated) = ½")
    ax.set(xlabel="strain ratio ε_a/ε_h over the bulge", ylabel="ln(f_max/G) over the bulge",
           title=f"{len(seeds_at)} points: {100 * miss:.1f} % of seed 2's runs misclassified")
    ax.legend(fontsize=8, loc="lower right")
    v = np.array([r["log_f_over_G"] for r in cracked])
    fig.colorbar(bx.scatter(v, [r["off"] for r in cracked], s=10, c=[r["ratio"] for r in cracked], cmap="viridis"),
                 ax=bx, label="ε_a/ε_h")
    bx.axhline(cut, color="k", ls="--", label=f"cut: {cut:.1f}°, midway between Table 2's scenes")
    bx.set(xlabel="ln(f_max/G) over the bulge", ylabel="bulge's mean orientation from vertical (°)",
           title="the kind: elongated below the cut (colour: ε_a/ε_h)")
    bx.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / "boundary.png", dpi=120)
    write_json(folder / "boundary.json", {
        "formula": law.formula(), "names": list(names), "coef": law.coef, "low": law.low, "high": law.high,
        "level": law.level, "llr_p": law.llr_p, "pseudo_r2": law.pseudo_r2, "fitted_runs": law.n,
        "held_out_runs": len(test_rows), "misclassified": miss, "commoner_kind": guess, "cut_deg": cut,
        "stop_time": t_stop, "ratio_restriction_p": ratio_p, "strain_ratio_adds_p": ratio_adds_p, "left_out": len(rows) - len(cracked),
        "anisotropy_kind": {"cut": a_cut, "misclassified": miss_a, "pseudo_r2": law_a.pseudo_r2}})
    print(f"{folder / 'boundary.png'}, {folder / 'boundary.json'}")


PACKINGS = [  # (organ area in mm², or None: one base's area on the trunk of the start; area exponent p)
    (None, 1.0), (None, 0.0), (None, 2.0), (30.0, 0.0), (30.0, 1.0), (30.0, 2.0)]


def packing(out: Path, workers: int) -> None:
    """What each law of the leaves' size keeps of the paper's numbers, on the shipped whole tree
    (geometry only: Ridley's packing, no mechanics): the leaves at 60 years, and the leaf-base area
    and parastichy angle of the bases crossing from the dome at the start and at the end."""
    import math

    import attrs

    from bark.analysis.phyllotaxis import lattice_angle
    from bark.engine.scene import Scene
    from bark.model.tree import Packing
    from bark.units import METRES_PER_LENGTH_UNIT, metres

    scene = Scene.from_toml(SCENES / "whole-tree.toml")
    end = scene.run.until_time
    mm2 = (1000.0 * METRES_PER_LENGTH_UNIT) ** 2
    growth = scene.simulation().growth.without("bulges")  # the leaves' own law, on a trunk without bulges
    rows = ["| leaf area at the start | p | leaves at 60 years | bases at the end | height at the end "
            "| leaf-base area, start → end | parastichy angle, start → end |", "|---|---|---|---|---|---|---|"]
    for area, p in PACKINGS:
        lattice = attrs.evolve(scene.lattice, n_bases=400_000, organ_area=None if area is None else area / mm2,
                               area_exponent=p)
        packed = Packing.of(lattice, growth)
        radius = [float(growth.radius(t, 0.0)) for t in (0.0, end)]
        rise = [float(packed.rise_at(t)) for t in (0.0, end)]
        areas = [2.0 * math.pi * r * h * mm2 for r, h in zip(radius, rise)]
        angles = [float(lattice_angle(lattice, r, h)) for r, h in zip(radius, rise)]
        joined = packed.bases_at(end) - lattice.initial
        rows.append(f"| {'one base of the start' if area is None else f'{area:g} mm²'} | {p:g} | {joined:,} "
                    f"| {lattice.initial + joined:,} | {metres(float(lattice.top(end))):.2f} m "
                    f"| {areas[0]:.1f} → {areas[1]:.1f} mm² | {angles[0]:.1f}° → {angles[1]:.1f}° |")
    print("\n".join(rows))
    print(f"(the paper: 25,000 leaves, 45,000 → 70,000 bases, 1.62 → 2.52 m, ≈ 30 mm², ≈ 57°; radius "
          f"{100 * metres(radius[0]):.1f} → {100 * metres(radius[1]):.1f} cm)")


RECOVERY = ((0.014, 0.0028), (0.011, 0.005), (0.007, 0.008), (0.009, 0.004), (0.0125, 0.0065))
"""True (G, f_max) of the recovery study: Table 2's three regimes and two points between them."""
FIT = ("--population", "100", "--generations", "4")
"""The fits' size: 100 accepted runs a generation, four generations."""
TABLE2 = {"vertical": (0.014, 0.0028), "reticulate": (0.011, 0.005), "diamond": (0.007, 0.008),
          "43 %": (0.01099, 0.005036)}
"""Table 2's regimes and the paper's reticulate fit, 43 % of the way from the first to the third."""


def _marks(points: dict) -> list[str]:
    return [a for label, (g, f) in points.items() for a in ("--mark", f"{label}:growth.G={g},mechanics.f_max={f}")]


def recovery(out: Path, workers: int) -> None:
    """Calibration checked: a pattern grown at each known (G, f_max) of :data:`RECOVERY` (3000 bases,
    the reticulate scene, a seed of its own), fitted by ``bark fit`` over the default priors; prints
    whether each true value lies in its 90 % credible interval, and the intervals' widths."""
    rows, covered = [], 0
    for i, (g, f) in enumerate(RECOVERY):
        observed, fitted = out / "recovery" / f"observed-{i}", out / "recovery" / f"fit-{i}"
        if not (observed / "summary.json").is_file():
            bark("simulate", "--scene", "reticulate", "--set", f"growth.G={g}", "--set", f"mechanics.f_max={f}",
                 "--seed", str(1000 + i), "--out", str(observed), "--quiet")
        if not (fitted / "fit.json").is_file():
            bark("fit", str(observed), "--scene", "reticulate", *FIT, "--seed", str(i), "--workers", str(workers),
                 *_marks({"truth": (g, f)}), "--out", str(fitted), "--quiet")
        post = json.loads((fitted / "fit.json").read_text())["posterior"]
        for key, true in (("growth.G", g), ("mechanics.f_max", f)):
            lo, hi = post[key]["ci90"]
            covered += lo <= true <= hi
            rows.append(f"{i}  {key:16s} true {true:<8g} 90 % CI {lo:.5f} – {hi:.5f}  width {hi - lo:.5f}  "
                        f"{'covered' if lo <= true <= hi else 'MISSED'}")
    print("\n".join(rows))
    print(f"{covered} of {2 * len(RECOVERY)} intervals cover the true value")


def fit(out: Path, workers: int) -> None:
    """The posteriors over (G, f_max) of the two photographs' published summaries (the reticulate one
    in a mirror: its spiral turns the other way from the scene's), Table 2's regimes and the 43 %
    point marked on corner.png and placed in fit.json."""
    for name in ("reticulate", "elongated"):
        fitted = out / "fit" / name
        if not (fitted / "fit.json").is_file():
            bark("fit", str(HERE / f"observed-{name}.toml"), "--scene", "reticulate", *FIT, "--workers", str(workers),
                 *(("--mirror",) if name == "reticulate" else ()), *_marks(TABLE2), "--out", str(fitted), "--quiet")
        report = json.loads((fitted / "fit.json").read_text())
        print(f"{name}: " + ", ".join(f"{k} {v['mean']:.4g} [{v['ci90'][0]:.4g}, {v['ci90'][1]:.4g}]"
                                      for k, v in report["posterior"].items()))
        for label, entry in report["marks"].items():
            print(f"    {label}: {100 * entry['hpd_level']:.0f} % of the posterior is more probable")


TABLE2 = {name: SCENES / f"{name}.toml" for name in ("vertical", "reticulate", "diamond")}
RESIN_FAMILIES = {  # family: (settings of every point, the swept setting, its values, their label)
    "maxwell": (["resin.name=maxwell"], "resin.tau", (300.0, 1000.0, 3000.0, 10000.0), "relaxation time τ (time units)"),
    "plastic": (["resin.name=plastic", "resin.hardening=1.0"], "resin.yield_strain", (0.2, 0.3, 0.5, 1.0),
                "yield strain (hardening 1)"),
    "weibull": ([], "breaker.weibull_shape", (2.0, 4.0, 8.0), "Weibull modulus m of the thresholds"),
}
RESIN_STATISTICS = (("mean_orientation_deg", "mean orientation (°)"), ("circular_sd_deg", "circular SD (°)"),
                    ("mean_anisotropy", "anisotropy 2A − 1"), ("n_patches", "patches"),
                    ("n_bar", "junctions per patch n̄"), ("t", "time at the stop"))
PATTERN_ONLY = ("mean_orientation_deg", "circular_sd_deg", "mean_anisotropy", "n_bar")
"""Statistics of a pattern: taken only over runs that cracked into at least ``CRACKED`` patches (a
layer still whole, or in a few pieces, at its time cap has no distribution of orientations)."""
CRACKED = 10


def resins(out: Path, workers: int) -> None:
    """The paper's open question — what the resin's own mechanics does to the pattern — on the three
    Table 2 regimes (3000 bases, each to its own patch count): a Maxwell (viscoelastic) resin over
    its relaxation time, a plastic one over its yield strain, and quenched Weibull disorder of the
    thresholds over its modulus, against the paper's Hookean spring; three seeds a point.  One
    figure (a column per family, a row per statistic, a line per regime, bars: the seeds' range;
    a pattern's statistics over the runs that cracked into at least ``CRACKED`` patches) and a table
    of means."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.ticker import NullFormatter

    folder = out / "resins"
    stats = [k for k, _ in RESIN_STATISTICS]
    found: dict[tuple, list[dict]] = {}
    for regime, scene in TABLE2.items():
        base = folder / regime / "hookean"  # the paper's spring: every family's reference
        bark("sweep", "--scene", str(scene), "--grid", "resin.name=hookean", "--seeds", "3", "--workers", str(workers),
             "--out", str(base), "--quiet")
        found[(regime, "hookean", None)] = _rows(base, stats)
        for family, (sets, axis, values, _) in RESIN_FAMILIES.items():
            where = folder / regime / family
            bark("sweep", "--scene", str(scene), "--grid", f"{axis}={','.join(f'{v:g}' for v in values)}",
                 *(a for s in sets for a in ("--set", s)), "--seeds", "3", "--workers", str(workers),
                 "--out", str(where), "--quiet")
            for value in values:
                found[(regime, family, value)] = _rows(where, stats, axis, value)
    fig, axes = plt.subplots(len(stats), len(RESIN_FAMILIES), figsize=(4.2 * len(RESIN_FAMILIES), 2.3 * len(stats)),
                             sharex="col", squeeze=False, constrained_layout=True)
    colours = {"vertical": "#0072B2", "reticulate": "#E69F00", "diamond": "#009E73"}
    for col, (family, (_, axis, values, label)) in enumerate(RESIN_FAMILIES.items()):
        for row, (key, name) in enumerate(RESIN_STATISTICS):
            ax = axes[row][col]
            for regime in TABLE2:
                ref = _values(found[(regime, "hookean", None)], key)
                if ref:
                    ax.axhline(_spread(key, ref)[0], color=colours[regime], lw=0.8, ls=":")
                got = [_values(found[(regime, family, v)], key) for v in values]
                x = [v for v, g in zip(values, got) if g]
                spread = np.array([_spread(key, g) for g in got if g]).reshape(-1, 3)
                ax.errorbar(x, spread[:, 0], yerr=[spread[:, 0] - spread[:, 1], spread[:, 2] - spread[:, 0]],
                            color=colours[regime], marker="o", ms=3, lw=1, capsize=2, label=regime if row == 0 else None)
            ax.set_xscale("log")
            ax.set_xticks(values, [f"{v:g}" for v in values])  # the values swept, as they are set
            ax.xaxis.set_minor_formatter(NullFormatter())
            if col == 0:
                ax.set_ylabel(name, fontsize=9)
            if row == 0:
                ax.set_title(family, fontsize=10)
            if row == len(stats) - 1:
                ax.set_xlabel(label, fontsize=9)
    axes[0][0].legend(fontsize=8, title="regime (dotted: Hookean)", title_fontsize=8)
    fig.savefig(folder / "resins.png", dpi=150)
    print(f"figure: {folder / 'resins.png'}")
    print("| regime | resin | " + " | ".join(n for _, n in RESIN_STATISTICS) + " |\n|---|---|" + "---|" * len(stats))
    for (regime, family, value), rows in found.items():
        cells = []
        for key in stats:
            got = _values(rows, key)
            cells.append("{:.3g} ({:.3g}–{:.3g})".format(*_spread(key, got)) if got else "no pattern")
        what = family if value is None else f"{family} {RESIN_FAMILIES[family][1].split('.')[1]} = {value:g}"
        print(f"| {regime} | {what} | " + " | ".join(cells) + " |")


def _spread(key: str, values: list[float]) -> tuple[float, float, float]:
    """``(centre, lowest, highest)`` of the seeds' ``values``: for an orientation (axial, degrees in
    [0, 180)) the axial mean, each seed's taken within ±90° of it; else the mean."""
    import numpy as np
    from scipy.stats import circmean

    v = np.asarray(values, dtype=float)
    if key != "mean_orientation_deg":
        return float(v.mean()), float(v.min()), float(v.max())
    centre = float(circmean(v, high=180.0, low=0.0))
    near = centre + (v - centre + 90.0) % 180.0 - 90.0
    return centre, float(near.min()), float(near.max())


def _values(rows: list[dict], key: str) -> list[float]:
    """``key`` of each run of ``rows`` that has it (a pattern's statistics: of the runs that cracked)."""
    return [r[key] for r in rows if r[key] is not None and (key not in PATTERN_ONLY or (r["n_patches"] or 0) >= CRACKED)]


def _rows(folder: Path, stats: list[str], axis: str | None = None, value: float | None = None) -> list[dict]:
    """The runs of a sweep's table (at ``axis = value``), their ``stats`` each."""
    con = sqlite3.connect(folder / "sweep.sqlite")
    where = f' WHERE abs("{axis}" - {value!r}) < 1e-12' if axis is not None else ""
    got = con.execute(f"SELECT {', '.join(stats)} FROM runs{where} ORDER BY seed").fetchall()
    con.close()
    return [dict(zip(stats, r)) for r in got]


SBC = {"draws": 60, "population": 30, "generations": 3}
"""The calibration study's size: 60 settings from the default priors, each fitted with 30 accepted runs a
generation for three generations (the study prints the runs each fit took and the whole study's time)."""


def sbc(out: Path, workers: int) -> None:
    """Simulation-based calibration of ``bark fit`` (``bark.studies.sbc``): :data:`SBC`'s draws from the
    default priors over (G, f_max), each grown in the reticulate scene (3000 bases, to 115 patches,
    a seed of its own) and fitted on the eight statistics over the same priors.  ``sbc.png``: the
    ranks' histograms (G, f_max, and the joint highest-density level) against the uniform band, and
    the coverage of the 50/80/95 % intervals against their nominal level; ``sbc.json``: the figures."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from scipy.stats import binom

    from bark.engine.scene import read_toml
    from bark.io.files import write_json
    from bark.studies.sbc import LEVELS, Calibration, run_calibration, summarise

    cal = Calibration(base=read_toml("reticulate"), **SBC)
    folder = out / "sbc"
    began = time.monotonic()
    rows = run_calibration(cal, folder, workers=workers, draw_done=lambda r: print(
        f"draw {r['draw']}: " + (r.get("skipped") or ", ".join(f"{k} rank {v:.2f}" for k, v in r["rank"].items())
                                 + f", joint {r['hpd_level']:.2f}, {r['runs']} runs"), flush=True))
    summary = summarise(rows, cal.keys)
    write_json(folder / "sbc.json", summary)
    panels = (*cal.keys, "joint")
    titles = {"growth.G": "G: posterior weight below the truth", "mechanics.f_max": "f_max: weight below the truth",
              "joint": "joint: weight more probable than the truth"}
    n, bins = summary["draws"], summary["bins"]
    fig, axes = plt.subplots(1, len(panels) + 1, figsize=(4.2 * (len(panels) + 1), 3.6))
    lo, hi = binom.ppf(0.005, n, 1 / bins), binom.ppf(0.995, n, 1 / bins)
    for ax, key in zip(axes, panels):
        ax.axhspan(lo, hi, color="0.85", label="99 % band, uniform")
        ax.bar((np.arange(bins) + 0.5) / bins, summary[key]["counts"], width=1 / bins, edgecolor="k", color="C0")
        ax.set(xlim=(0, 1), xlabel="rank (0 to 1)", ylabel="draws",
               title=f"{titles[key]}\nχ² p = {summary[key]['chi2_p']:.2g}")
    axes[0].legend(loc="lower center", fontsize=8)
    ax = axes[-1]
    q = np.array(LEVELS)
    band = np.array([summary["joint"]["coverage"][f"{v:g}"]["expected"] for v in LEVELS])
    ax.fill_between(q, band[:, 0], band[:, 1], color="0.85", label="95 % range if calibrated")
    ax.plot([0.4, 1], [0.4, 1], "k:", lw=1)
    for i, key in enumerate(panels):
        ax.plot(q, [summary[key]["coverage"][f"{v:g}"]["covered"] for v in LEVELS], "o-", color=f"C{i}", label=key)
    ax.set(xlabel="interval level", ylabel="draws covered", title=f"coverage over {n} draws", xlim=(0.4, 1),
           ylim=(0, 1.02))
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / "sbc.png", dpi=120)
    for key in panels:
        cover = ", ".join(f"{v:g}: {summary[key]['coverage'][f'{v:g}']['covered']:.2f}" for v in LEVELS)
        print(f"{key:16s} ranks {summary[key]['counts']}  chi2 p {summary[key]['chi2_p']:.3g}  coverage {cover}")
    print(f"{n} draws fitted, {summary['skipped']} without a pattern, in {(time.monotonic() - began) / 60:.0f} min "
          f"on {workers} workers (draws already there reused); {folder / 'sbc.png'}")


FIGURES = {"fig7": fig7, "fig8": fig8, "fig9": fig9, "fractures": fractures, "fig11": fig11, "packing": packing,
           "recovery": recovery, "fit": fit, "resins": resins, "sbc": sbc, "boundary": boundary}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("figure", choices=sorted(FIGURES))
    parser.add_argument("--out", type=Path, default=Path("runs/paper"))
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    FIGURES[args.figure](args.out, args.workers)


if __name__ == "__main__":
    main()
