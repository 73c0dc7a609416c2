"""Regenerate the paper's Figs. 7, 8 and 9, and the fracture power law of its Discussion, from the
shipped scenes — one command each, through the same ``bark`` commands a user types (printed as they
run)::

    python examples/paper/figures.py fig7       # the three regimes: pattern, radial plot, histogram
    python examples/paper/figures.py fig8       # quartet analysis against the photographs
    python examples/paper/figures.py fig9       # the G × f_max montage
    python examples/paper/figures.py fractures  # initial fractures against the dissipation rate

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
SCENES = HERE.parent / "scenes"
REGIMES = {  # Fig. 7's rows: Table 2's first regime, the reticulate fit (43 %), the third regime
    "vertical": SCENES / "vertical.toml",
    "intermediate-43": HERE / "intermediate-43.toml",
    "diamond": SCENES / "diamond.toml",
}
FRACTURE_GRID = ["--grid", "mechanics.b=1,2,5,10,20", "--grid", "growth.G=0.007,0.01,0.014"]


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
    import matplotlib.image as mpimg
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    runs = regime_runs(out)
    cells = []
    for name, run in runs.items():
        bark("analyze", str(run), "--out", str(out / "analysis" / name))
        cells.append((name, [run / "pattern.png", out / "analysis" / name / "radial.png",
                             out / "analysis" / name / "histogram.png"]))
    fig = Figure(figsize=(15, 4.6 * len(cells)), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(cells), 3)
    for row, (name, paths) in zip(axes, cells):
        for ax, path in zip(row, paths):
            ax.imshow(mpimg.imread(path))
            ax.set_axis_off()
        row[0].set_title(name, loc="left", fontsize=14)
    fig.tight_layout()
    fig.savefig(out / "fig7.png")
    print(f"Fig. 7: {out / 'fig7.png'} (rows: {', '.join(runs)}; columns: pattern, radial plot, histogram)")


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
    import numpy as np

    from bark.analysis.fracture import power_law
    from bark_cli.figures import plot_power_law

    folder = out / "fractures"
    bark("sweep", "--scene", str(HERE / "fractures.toml"), *FRACTURE_GRID, "--seeds", "2", "--workers", str(workers),
         "--out", str(folder), "--quiet")
    con = sqlite3.connect(folder / "sweep.sqlite")
    rows = con.execute('SELECT "mechanics.b", "growth.G", seed, dissipation_rate, growth_dissipation, initial_fractures '
                       'FROM runs ORDER BY "growth.G", "mechanics.b", seed').fetchall()
    con.close()
    b, G, _, measured, growth, count = (np.array(c, dtype=float) for c in zip(*rows))
    rates = {  # two readings of "the rate of energy dissipation" (README: Fracture history)
        "dissipation_rate": (measured, "dissipation rate (damping power per base, first break to most cracks)"),
        "growth_dissipation": (growth, "growth dissipation b·(dr/dt)² at the first break"),
    }
    report = {}
    print(f"{'against':>19} {'runs':>10} {'exponent':>9} {'95 % CI':>19} {'R²':>6}")
    for name, (x, label) in rates.items():
        fits = {"all": power_law(x, count)}
        for g in sorted(set(G.tolist())):
            fits[f"G = {g:g}"] = power_law(x[G == g], count[G == g])
        plot_power_law(x, count, G, fits["all"], folder / f"power-law-{name}.png", "G", label)
        for group, f in fits.items():
            print(f"{name:>19} {group:>10} {f.exponent:9.3f} [{f.ci[0]:8.3f}, {f.ci[1]:8.3f}] {f.r2:6.3f}   (n = {f.n})")
        report[name] = {k: {"exponent": f.exponent, "ci": f.ci, "level": f.level, "prefactor": f.prefactor, "r2": f.r2,
                            "n": f.n} for k, f in fits.items()}
    print(f"{'b':>5} {'G':>6} {'dissipation rate':>17} {'growth dissipation':>19} {'initial fractures':>18}")
    for row in rows:
        print(f"{row[0]:5g} {row[1]:6g} {row[3]:17.4g} {row[4]:19.4g} {row[5]:18d}")
    (folder / "power-law.json").write_text(json.dumps(report, indent=2))
    print(f"power laws: {folder}/power-law-*.png, {folder / 'power-law.json'}")


FIGURES = {"fig7": fig7, "fig8": fig8, "fig9": fig9, "fractures": fractures}


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
