"""The plain numba baseline of bark's compiled step: the model of the default scene stepped by a short
kernel written as one would write it without bark, against bark's numba backend, interleaved.

    python benchmarks/plain_numba.py [--n-bases 3000 --n-bases 1000000] [--repeats 5] [--steps K]

``bark bench speed`` quotes bark's steps against a plain vectorised numpy step (``PlainNumpy``); this
script asks how far bark's kernel is from a plain *compiled* one of the same work — what its
bookkeeping costs (blocks and windows, the breaker part's load and its largest, the break log, the
finiteness checks, the stop checks, a kernel call per stretch) and what its layout saves. The plain
kernel (``plain_steps``) takes fixed Euler–Cromer steps of the default scene (sqrt growth, threshold
breaking, one thread), each as one pass over the bases (the move, the surface constraint, the
anchors) and one pass over the springs, offset by offset (tension, the threshold rule, the force
into a work vector, then added at second ends and at first ends): written plainly, as loops that
numba runs in SIMD lanes, in the order of bark's spring runs, so that each base receives its forces
in bark's order and the results are bark's to the bit (checked after the timing, and by
``tests/test_integrators.py``). Both start from the same state of the quiet phase
(t = 0: no spring near its threshold, as ``bark bench speed --phase quiet``) and take the same
steps; the script prints ns per base-step of each, their ratio, and whether the positions and the
intact flags are equal.

Absolute times are this machine's; the ratio is the figure.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numba
import numpy as np


@numba.njit(nogil=True, error_model="numpy")
def _spring_pass(x0, x1, x2, f0, f1, f2, w0, w1, w2, rest, fmax, intact, offsets, starts, k, breaking):
    """Every intact spring's force added into ``f`` (zeroed first), offset by offset: the springs of
    offset ``o`` join base ``i`` to ``i + o`` and are ``starts[b] + i``; with ``breaking``, a spring
    over its threshold breaks first (and exerts no force).  Each offset's forces go to the work
    vectors ``w`` in one loop, then into ``f`` in two, at second ends before first ends (bark's order
    of summation): loops without a dependence from one spring to the next, which numba runs in SIMD
    lanes (adding at both ends in the first loop, as one would first write it, does not vectorise)."""
    n = x0.shape[0]
    for q in range(n):
        f0[q] = 0.0
        f1[q] = 0.0
        f2[q] = 0.0
    for b in range(offsets.shape[0]):
        o, s0 = offsets[b], starts[b]
        for i in range(n - o):
            s = s0 + i
            d0 = x0[i + o] - x0[i]
            d1 = x1[i + o] - x1[i]
            d2 = x2[i + o] - x2[i]
            length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            tension = k * (length - rest[s])
            on = intact[s]
            if breaking:
                on = on and not tension > fmax[s]
                intact[s] = on
            g = tension / length if on and length > 0.0 else 0.0
            w0[i] = g * d0
            w1[i] = g * d1
            w2[i] = g * d2
        for i in range(n - o):
            f0[i + o] -= w0[i]
            f1[i + o] -= w1[i]
            f2[i + o] -= w2[i]
        for i in range(n - o):
            f0[i] += w0[i]
            f1[i] += w1[i]
            f2[i] += w2[i]


@numba.njit(nogil=True, error_model="numpy")
def plain_steps(x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy, w0, w1, w2, rest, fmax, intact, offsets,
                starts, k, c, b, m, h, r0, g_rate, ticks, n_steps):
    """``n_steps`` fixed steps from tick ``ticks`` (time ``ticks · h``), the forces of the present
    positions in ``f`` on entry and on return."""
    n = x0.shape[0]
    hm = h / m
    for s in range(n_steps):
        t = (ticks + s + 1) * h
        r = r0 + g_rate * np.sqrt(t)
        inv_r2 = 1.0 / (r * r)
        for q in range(n):  # the move (eq. 4, 7, 8), onto the surface (eq. 9), the anchors with it
            u0 = v0[q] + (f0[q] - c * (x0[q] - ax[q]) - b * v0[q]) * hm
            u1 = v1[q] + (f1[q] - c * (x1[q] - ay[q]) - b * v1[q]) * hm
            u2 = v2[q] + (f2[q] - c * (x2[q] - az[q]) - b * v2[q]) * hm
            px = x0[q] + u0 * h
            py = x1[q] + u1 * h
            pz = x2[q] + u2 * h
            scale = r / np.sqrt(px * px + py * py)
            px *= scale
            py *= scale
            vr = (u0 * px + u1 * py) * inv_r2
            x0[q], x1[q], x2[q] = px, py, pz
            v0[q], v1[q], v2[q] = u0 - vr * px, u1 - vr * py, u2
            ax[q] = r * dx[q]
            ay[q] = r * dy[q]
        _spring_pass(x0, x1, x2, f0, f1, f2, w0, w1, w2, rest, fmax, intact, offsets, starts, k, True)


class PlainNumba:
    """The plain kernel's arrays, copied from a simulation's state (a whole lattice: a spring (i, i + o)
    for every base i and each offset o, as ``PlainNumpy`` requires), one vector per coordinate."""

    def __init__(self, sim) -> None:
        from bark_cli.bench import PlainNumpy

        p = PlainNumpy(sim)  # the springs regrouped by offset, in order of offset: bark's runs
        self.vectors = [np.ascontiguousarray(a[:, i]) for a in (p.x, p.v, np.zeros_like(p.x), p.anchor) for i in range(3)]
        self.vectors += [np.ascontiguousarray(p.direction[:, i]) for i in range(2)]
        self.vectors += [np.zeros(len(p.x)) for _ in range(3)]  # the work vectors
        self.rest, self.fmax, self.intact, self.order = p.rest, p.fmax, p.intact, p.order
        self.offsets = np.array([o for o, _ in p.blocks], np.int64)
        self.starts = np.array([blk.start for _, blk in p.blocks], np.int64)
        mech, growth = sim.mechanics, sim.growth
        self.numbers = (float(mech.k), float(mech.c), float(mech.b), float(mech.m), float(sim.clock.h),
                        float(growth.r0), float(growth.G))
        self.ticks = int(round(sim.state.t / sim.clock.h))
        x0, x1, x2, _, _, _, f0, f1, f2 = self.vectors[:9]
        _spring_pass(x0, x1, x2, f0, f1, f2, *self.vectors[14:], self.rest, self.fmax, self.intact, self.offsets,
                     self.starts, self.numbers[0], False)

    def steps(self, n: int) -> None:
        plain_steps(*self.vectors, self.rest, self.fmax, self.intact, self.offsets, self.starts, *self.numbers,
                    self.ticks, n)
        self.ticks += n

    @property
    def x(self) -> np.ndarray:
        return np.column_stack(self.vectors[:3])

    @property
    def intact_in_bark_order(self) -> np.ndarray:
        out = np.empty_like(self.intact)
        out[self.order] = self.intact
        return out


def main() -> None:
    from bark.engine.simulation import Stop
    from bark_cli.bench import _phase_sim

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-bases", type=int, action="append", default=None)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--steps", type=int, default=None, help="steps per timed stretch (default: about 0.2 s)")
    args = parser.parse_args()
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, numba {numba.__version__}; "
          f"one thread, fixed steps (dt = 0.01) from t = 0, {args.repeats} stretches each, interleaved")
    for n in args.n_bases or [3000, 1_000_000]:
        sim = _phase_sim(n, "numba", 0.0, threads=1)  # compiled, and run to its first step
        plain = PlainNumba(sim)
        plain.steps(0)  # compiled outside the timing (not cached on disk: a few seconds)
        steps = args.steps or max(5, int(0.2 / (2e-8 * n)))
        ns = {"plain numba": [], "bark numba": []}
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            plain.steps(steps)
            ns["plain numba"].append((time.perf_counter() - t0) / (steps * n) * 1e9)
            s0, t0 = sim.step_count, time.perf_counter()
            sim.run(Stop(until_time=sim.state.t + steps * sim.clock.h))
            ns["bark numba"].append((time.perf_counter() - t0) / ((sim.step_count - s0) * n) * 1e9)
        same_x = np.array_equal(plain.x, sim.state.x)
        close = np.allclose(plain.x, sim.state.x, rtol=0, atol=1e-10)
        same_intact = np.array_equal(plain.intact_in_bark_order, sim.state.intact)
        a, b = (statistics.median(v) for v in ns.values())
        ratios = [y / x for x, y in zip(ns["plain numba"], ns["bark numba"])]
        print(f"{n:>9} bases, {steps} steps a stretch: plain numba {a:.2f} ns per base-step, bark's numba backend "
              f"{b:.2f}; bark / plain {statistics.median(ratios):.3f} (stretches {min(ratios):.3f}-{max(ratios):.3f}); "
              f"positions the same to the bit: {same_x} (within 1e-10: {close}), intact flags the same: {same_intact}")


if __name__ == "__main__":
    main()
