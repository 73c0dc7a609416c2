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

Options: ``--out DIR`` (default ``runs/paper``), ``--workers N`` (sweeps).  Runs already there are
reused: ``bark sweep`` skips finished points, and a regime's run folder with its summary is kept.
"""

from __future__ import annotations

import argparse
import json
import sqlite3
import subprocess
import sys
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
    # bark's phyllotactic spiral turns the other way from the photographed tree's (README): the same
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
    rates = {  # two readings of "the rate of energy dissipation" (README: Fracture history)
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


def fig11(out: Path, workers: int) -> None:
    """Fig. 11's comparison on whole patches: the shipped whole tree over anchor stiffness c, damping
    b and the lattice's jitter, three seeds a point; per point the straight trunk of the start (its
    largest patch's share, the mean orientation and SD of its patches, their anisotropy) and the
    bulges' difference from it, each seed's figure, and whether the point meets the three tests:
    no patch over 10 % of the straight trunk's bases, its mean within 15° of vertical with an SD
    under 25°, and the bulges' mean over 20° from it or their anisotropy over 0.1 lower."""
    import csv

    from bark.analysis.circular import axial_difference

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
    lines = []
    for settings, seeds in points.items():
        s = [r["straight"] for r in seeds]
        b = [r["bulge"] for r in seeds]
        dmean = [abs(float(axial_difference(y["mean_orientation_deg"], x["mean_orientation_deg"]))) for x, y in zip(s, b)]
        daniso = [x["mean_anisotropy"] - y["mean_anisotropy"] for x, y in zip(s, b)]
        passes = sum(x["largest_patch_share"] <= 0.1 and abs(x["mean_orientation_deg"] - 90) <= 15
                     and x["circular_sd_deg"] < 25 and (dm > 20 or da > 0.1) for x, dm, da in zip(s, dmean, daniso))
        lines.append([*(f"{v:g}" for v in settings),
                      " / ".join(f"{x['largest_patch_share']:.3f}" for x in s),
                      " / ".join(f"{x['mean_orientation_deg']:.1f}" for x in s),
                      " / ".join(f"{x['circular_sd_deg']:.1f}" for x in s),
                      " / ".join(f"{x['mean_anisotropy']:.2f}" for x in s),
                      " / ".join(f"{d:.1f}" for d in dmean), " / ".join(f"{d:.2f}" for d in daniso),
                      f"{passes} of {len(seeds)}"])
    with open(folder / "fig11-study.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([columns, *lines])
    print("| " + " | ".join(columns) + " |\n|" + "---|" * len(columns))
    for line in lines:
        print("| " + " | ".join(line) + " |")
    print(f"table: {folder / 'fig11-study.csv'} (each cell: seeds 0 / 1 / 2; orientations in degrees)")


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
generation for three generations (about 240 runs and 50 s a fit on 2 workers of an Intel Xeon)."""


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
    print(f"{n} draws fitted, {summary['skipped']} without a pattern; {folder / 'sbc.png'}")


FIGURES = {"fig7": fig7, "fig8": fig8, "fig9": fig9, "fractures": fractures, "fig11": fig11, "packing": packing,
           "recovery": recovery, "fit": fit, "resins": resins, "sbc": sbc}


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
