"""The plain numpy baseline of a one-step run: what ``bark simulate`` of the default scene does in one
step, written as one script without bark, as well as numpy allows.

It builds the default scene's lattice (Table 2's vertical regime: 3000 leaf bases, divergence
137.5°, rise 0.0005, springs to the 21st and 34th neighbours, 5 % jitter), takes one Euler–Cromer
step of the model (Hookean springs k, anchors c, damping b, mass m; the trunk's radius r0 + G·√t;
the bases held on the trunk's surface), breaks the springs over f_max, finds the patches (connected
components of the intact springs), measures each patch's orientation and anisotropy (PCA in its
tangent plane) and their axial statistics, and draws the unwrapped pattern as a PNG.

Whole processes of this script are the baseline ``bark bench`` and the closing notes compare bark's
one-step process with (issue "per-run costs": the process around the kernel):

    python benchmarks/plain_numpy.py --out /tmp/plain          # writes pattern.png and statistics.json

It imports numpy, scipy.sparse (the components) and matplotlib (the picture) and nothing else.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

# The default scene's settings (bark.engine.scene's defaults; Table 2, vertical regime)
N, PHI, RISE, OFFSETS, JITTER = 3000, math.radians(137.50776405003785), 0.0005, (21, 34), 0.05
K, C, B, M, F_MAX = 0.4, 0.1, 5.0, 1.0, 0.0028
R0, G, DT, MIN_SIZE, SEED = 0.2, 0.014, 0.3, 7, 0


def lattice(rng: np.random.Generator):
    """Positions on the cylinder of radius R0, the springs (i, i + o) and their rest lengths."""
    i = np.arange(N, dtype=float)
    sigma = JITTER * math.sqrt(2.0 * math.pi * R0 * RISE)
    noise = rng.standard_normal((2, N))
    theta = i * PHI + noise[0] * (sigma / R0)
    z = i * RISE + noise[1] * sigma
    x = np.column_stack([R0 * np.cos(theta), R0 * np.sin(theta), z])
    pairs = np.concatenate([np.column_stack([np.arange(N - o), np.arange(o, N)]) for o in OFFSETS])
    rest = np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1)
    return x, theta, z, pairs, rest


def _lengths(x):
    """Each spring's vector and length, offset by offset (the springs are in the lattice's blocks):
    two shifted views of the positions, no gather."""
    d = np.concatenate([x[o:] - x[:-o] for o in OFFSETS])
    return d, np.sqrt(np.einsum("ij,ij->i", d, d))


def step(x, v, theta0, z0, pairs, rest, intact, t):
    """One Euler–Cromer step to t + DT; returns the springs' tensions of the new state."""
    d, length = _lengths(x)
    tension = np.where(intact, K * (length - rest), 0.0)
    f = d * (tension / length)[:, None]
    force = np.zeros_like(x)
    start = 0
    for o in OFFSETS:  # base i pulled toward i + o, i + o toward i: two shifted adds, no scatter
        block = f[start:start + N - o]
        force[:-o] += block
        force[o:] -= block
        start += N - o
    r = R0 + G * math.sqrt(t)
    anchor = np.column_stack([r * np.cos(theta0), r * np.sin(theta0), z0])
    force -= C * (x - anchor) + B * v
    v = v + (DT / M) * force
    x = x + DT * v
    r_new = R0 + G * math.sqrt(t + DT)
    x[:, :2] *= (r_new / np.hypot(x[:, 0], x[:, 1]))[:, None]  # held on the trunk's surface
    return x, v, K * (_lengths(x)[1] - rest), r_new


def patches(pairs, intact):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    kept = pairs[intact]
    graph = coo_matrix((np.ones(len(kept)), (kept[:, 0], kept[:, 1])), shape=(N, N))
    return connected_components(graph, directed=False)[1]


def statistics(x, labels) -> dict:
    """Per patch of at least MIN_SIZE bases: PCA of its tangent-plane coordinates (closed form of the
    2 × 2 eigenproblem, all patches at once); then the axial mean and SD of the orientations and the
    mean anisotropy."""
    ids, row, size = np.unique(labels, return_inverse=True, return_counts=True)
    kept = size >= MIN_SIZE
    at = kept[row]
    row = (np.cumsum(kept) - 1)[row][at]
    pts, size = x[at], size[kept]
    k = len(size)
    if k == 0:
        return {"n_patches": 0}

    def mean(values):
        return np.bincount(row, weights=values, minlength=k) / size

    angle = np.arctan2(pts[:, 1], pts[:, 0])
    centre = np.arctan2(mean(np.sin(angle)), mean(np.cos(angle)))
    rel = pts - np.column_stack([mean(pts[:, 0]), mean(pts[:, 1]), mean(pts[:, 2])])[row]
    u = rel[:, 0] * -np.sin(centre)[row] + rel[:, 1] * np.cos(centre)[row]
    w = rel[:, 2]
    u, w = u - mean(u)[row], w - mean(w)[row]
    a, b, c = (np.bincount(row, weights=p, minlength=k) / np.maximum(size - 1, 1) for p in (u * u, u * w, w * w))
    half = np.hypot(0.5 * (a - c), b)
    l1, l2 = 0.5 * (a + c) + half, 0.5 * (a + c) - half
    orientation = np.degrees(0.5 * np.arctan2(2.0 * b, a - c)) % 180.0
    anisotropy = np.divide(l1 - l2, l1 + l2, out=np.zeros(k), where=l1 + l2 > 0)
    doubled = np.radians(2.0 * orientation)
    resultant = np.hypot(np.mean(np.cos(doubled)), np.mean(np.sin(doubled)))
    return {"n_patches": int(k),
            "mean_orientation_deg": float(np.degrees(0.5 * np.arctan2(np.mean(np.sin(doubled)), np.mean(np.cos(doubled)))) % 180.0),
            "circular_sd_deg": float(np.degrees(0.5 * math.sqrt(max(0.0, -2.0 * math.log(resultant))))) if resultant > 0 else None,
            "mean_anisotropy": float(anisotropy.mean())}


def picture(x, labels, r, path: Path) -> None:
    import matplotlib

    matplotlib.use("agg")
    import matplotlib.pyplot as plt

    u = np.arctan2(x[:, 1], x[:, 0]) * r
    fig, ax = plt.subplots(figsize=(6, 6), dpi=150)
    ax.scatter(u, x[:, 2], c=labels % 6, s=4, cmap="tab10", linewidths=0)
    ax.set_aspect("equal")
    ax.set_xlabel("around the trunk (length units)")
    ax.set_ylabel("up the trunk (length units)")
    fig.savefig(path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("plain-out"))
    out = parser.parse_args().out
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(SEED)
    x, theta0, z0, pairs, rest = lattice(rng)
    intact = np.ones(len(pairs), bool)
    x, v, tension, r = step(x, np.zeros_like(x), theta0, z0, pairs, rest, intact, 0.0)
    intact &= tension <= F_MAX
    labels = patches(pairs, intact)
    stats = {"t": DT, "radius": r, "n_broken": int((~intact).sum()), **statistics(x, labels)}
    (out / "statistics.json").write_text(json.dumps(stats, indent=2))
    picture(x, labels, r, out / "pattern.png")


if __name__ == "__main__":
    main()
