"""Whether a base pass that writes other vectors than it reads keeps its speed, per layout and alignment.

    python benchmarks/base_pass_layout.py [--n 3000] [--sweeps 5000] [--rounds 5] [--offset 0]

To take a refused step back inside a call, adaptive stepping at a uniform radius reads each step
from one of two buffers and writes it into the other, leaving a refused step untaken; at per-base
radii it copies the bases before every step (in calls of more than
``numba_backend.IN_PLACE_STEPS`` steps; shorter ones are replayed).  Two buffers pay
only if the base pass's loop stays as fast once the vectors it writes are not those it reads.  The
compiler cannot know they do not overlap, so it checks at run time and takes its vectorised loop
where they do not.

This script times the base pass's arithmetic (the forces of eq. 4, Euler–Cromer, the surface
constraint, the finiteness count), compiled with the kernel's options, on three layouts:

- in place on column vectors (the kernel's layout now);
- read from six column vectors, written into six others;
- read from one (n, 6) array, written into another.

It prints ns per base for each, the median of ``--rounds`` rounds taken in turn, and each layout's
time over the in-place one measured in the same rounds.  Every array begins on a 64-byte boundary,
except the vectors written apart with ``--offset``: a target misaligned against its source costs the
vectorised loop split loads and stores, which numpy's own placement of arrays does at random.  A
loop in place must be given the very same vectors to read and write (``in_place`` here, and the
kernel's in-place calls): given two views of the same memory, the run-time check finds them
overlapping and the loop runs one base at a time.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np
from numba import njit

from bark.engine.kernels.numba_backend import inline

KERNEL = njit(error_model="numpy")  # the kernel's own options (no fastmath: the bits as written)


@inline
def _update(x, v, f, a, c, b, hm, h):
    g = f - c * (x - a) - b * v
    w = v + hm * g
    return x + h * w, w


@inline
def _columns(x, v):
    return x[:, 0], x[:, 1], x[:, 2], v[:, 0], v[:, 1], v[:, 2]


@inline
def _sweep(source, target, f, d, az, c, b, hm, h):
    """One pass over the bases: read from the column vectors ``source`` (x, v), written into
    ``target`` — the very same vectors for a pass in place, so that the compiler sees it."""
    x0, x1, x2, v0, v1, v2 = source
    y0, y1, y2, u0, u1, u2 = target
    f0, f1, f2, dx, dy = f[:, 0], f[:, 1], f[:, 2], d[:, 0], d[:, 1]
    bad = 0
    for q in range(x0.shape[0]):
        p0, w0 = _update(x0[q], v0[q], f0[q], dx[q], c, b, hm, h)
        p1, w1 = _update(x1[q], v1[q], f1[q], dy[q], c, b, hm, h)
        p2, w2 = _update(x2[q], v2[q], f2[q], az[q], c, b, hm, h)
        s = 1.0 / np.sqrt(p0 * p0 + p1 * p1)
        p0 *= s
        p1 *= s
        y0[q], y1[q], y2[q] = p0, p1, p2
        bad += not abs(p0 + p1 + p2) < np.inf
        vr = w0 * p0 + w1 * p1
        u0[q], u1[q], u2[q] = w0 - vr * p0, w1 - vr * p1, w2
    return bad


@KERNEL
def in_place(x, v, f, d, az, sweeps, c, b, hm, h):
    bad = 0
    columns = _columns(x, v)
    for _ in range(sweeps):
        bad += _sweep(columns, columns, f, d, az, c, b, hm, h)
    return bad


@KERNEL
def apart_columns(x, v, y, u, f, d, az, sweeps, c, b, hm, h):
    bad = 0
    source, target = _columns(x, v), _columns(y, u)
    for _ in range(sweeps):
        bad += _sweep(source, target, f, d, az, c, b, hm, h)
    return bad


@KERNEL
def apart_arrays(s_in, t_out, f, d, az, sweeps, c, b, hm, h):
    bad = 0
    for _ in range(sweeps):
        for q in range(s_in.shape[0]):
            p0, w0 = _update(s_in[q, 0], s_in[q, 3], f[q, 0], d[q, 0], c, b, hm, h)
            p1, w1 = _update(s_in[q, 1], s_in[q, 4], f[q, 1], d[q, 1], c, b, hm, h)
            p2, w2 = _update(s_in[q, 2], s_in[q, 5], f[q, 2], az[q], c, b, hm, h)
            s = 1.0 / np.sqrt(p0 * p0 + p1 * p1)
            p0 *= s
            p1 *= s
            t_out[q, 0], t_out[q, 1], t_out[q, 2] = p0, p1, p2
            bad += not abs(p0 + p1 + p2) < np.inf
            vr = w0 * p0 + w1 * p1
            t_out[q, 3], t_out[q, 4], t_out[q, 5] = w0 - vr * p0, w1 - vr * p1, w2
    return bad


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=3000, help="bases (default 3000: the reticulate scene's)")
    parser.add_argument("--sweeps", type=int, default=5000, help="passes over the bases a timing")
    parser.add_argument("--rounds", type=int, default=5, help="timings of each layout, taken in turn")
    parser.add_argument("--offset", type=int, default=0, choices=range(0, 64, 8),
                        help="bytes past a 64-byte boundary the vectors written apart begin at (the others begin on one)")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    n, numbers = args.n, (0.1, 0.1, 0.01, 0.01)

    def columns(k, offset=0, shift=0.0):
        """An (n, k) array, columns contiguous, ``offset`` bytes past a 64-byte boundary, of random numbers."""
        raw = np.empty(n * k + 16)
        first = (-raw.ctypes.data % 64 + offset) // 8
        out = raw[first:first + n * k].reshape((n, k), order="F")
        out[:] = rng.random((n, k)) + shift
        return out

    x, v, f, d, az = columns(3, shift=1.0), columns(3), columns(3), columns(2), columns(1)[:, 0]
    y, u, s_in, t_out = columns(3, args.offset), columns(3, args.offset), columns(6, shift=1.0), columns(6, args.offset)
    layouts = {
        "in place, column vectors": lambda k: in_place(x, v, f, d, az, k, *numbers),
        "apart, column vectors": lambda k: apart_columns(x, v, y, u, f, d, az, k, *numbers),
        "apart, (n, 6) arrays": lambda k: apart_arrays(s_in, t_out, f, d, az, k, *numbers),
    }
    for run in layouts.values():  # compiled outside the timing
        run(1)
    times = {name: [] for name in layouts}
    for _ in range(args.rounds):
        for name, run in layouts.items():
            t0 = time.perf_counter()
            run(args.sweeps)
            times[name].append((time.perf_counter() - t0) / args.sweeps / n * 1e9)
    base = times["in place, column vectors"]
    print(f"{platform.processor() or platform.machine()}, {n} bases, {args.sweeps} sweeps, {args.rounds} rounds, "
          f"written apart {args.offset} bytes past a 64-byte boundary")
    for name, ns in times.items():
        ratio = statistics.median(a / b for a, b in zip(ns, base))
        print(f"{name:26s} {statistics.median(ns):6.2f} ns a base   {ratio:5.2f}x in place")


if __name__ == "__main__":
    main()
