"""The numba backend: each kernel is one compiled pass over the springs and/or the bases.

Compiled on first use and cached on disk (``cache=True``).  Loops run serially: on the 2-core
machines bark targets, the spring scatter is memory-bound and threads buy little.
"""

from __future__ import annotations

import math

import numba
import numpy as np

NAME = "numba"

_jit = numba.njit(cache=True, fastmath=False, nogil=True)


@_jit
def _spring_forces(x, pairs, rest, k, intact, f):
    for s in range(pairs.shape[0]):
        if not intact[s]:
            continue
        i, j = pairs[s, 0], pairs[s, 1]
        d0 = x[j, 0] - x[i, 0]
        d1 = x[j, 1] - x[i, 1]
        d2 = x[j, 2] - x[i, 2]
        length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if length <= 0.0:
            continue
        sc = k * (length - rest[s]) / length
        f[i, 0] += sc * d0
        f[i, 1] += sc * d1
        f[i, 2] += sc * d2
        f[j, 0] -= sc * d0
        f[j, 1] -= sc * d1
        f[j, 2] -= sc * d2


@_jit
def _elastic(x, anchor, pairs, rest, k, c, intact, f):
    f[:] = 0.0
    _spring_forces(x, pairs, rest, k, intact, f)
    if c != 0.0:
        for q in range(x.shape[0]):
            for a in range(3):
                f[q, a] -= c * (x[q, a] - anchor[q, a])


@_jit
def _euler_cromer(x, v, anchor, pairs, rest, k, c, b, m, h, intact, f):
    f[:] = 0.0
    _spring_forces(x, pairs, rest, k, intact, f)
    hm = h / m
    for q in range(x.shape[0]):
        for a in range(3):
            force = f[q, a] - c * (x[q, a] - anchor[q, a]) - b * v[q, a]
            v[q, a] += force * hm
            x[q, a] += v[q, a] * h


@_jit
def _project(points, radius, velocities, with_velocity):
    uniform = radius.shape[0] == 1
    for q in range(points.shape[0]):
        r = radius[0] if uniform else radius[q]
        px, py = points[q, 0], points[q, 1]
        scale = r / math.sqrt(px * px + py * py)
        px *= scale
        py *= scale
        points[q, 0] = px
        points[q, 1] = py
        if with_velocity:
            vr = (velocities[q, 0] * px + velocities[q, 1] * py) / (r * r)
            velocities[q, 0] -= vr * px
            velocities[q, 1] -= vr * py


@_jit
def _measure(x, pairs, rest, k, fmax, intact, out):
    top = -np.inf
    finite = True
    for s in range(pairs.shape[0]):
        i, j = pairs[s, 0], pairs[s, 1]
        d0 = x[j, 0] - x[i, 0]
        d1 = x[j, 1] - x[i, 1]
        d2 = x[j, 2] - x[i, 2]
        t = k * (math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) - rest[s])
        out[s] = t
        if not math.isfinite(t):
            finite = False
        elif intact[s]:
            load = t / fmax[s]
            if load > top:
                top = load
    return top if finite else np.nan


def _scratch(state) -> np.ndarray:
    buf = state.scratch.get("numba_f")
    if buf is None or buf.shape != state.x.shape:
        buf = state.scratch["numba_f"] = np.empty_like(state.x)
    return buf


def elastic_forces(state, x: np.ndarray) -> np.ndarray:
    mech = state.mechanics
    f = np.empty_like(x)
    _elastic(x, state.anchor, state.pairs, state.rest, mech.k, mech.c, state.intact, f)
    return f


def euler_cromer_step(state, h: float) -> None:
    mech = state.mechanics
    _euler_cromer(state.x, state.v, state.anchor, state.pairs, state.rest, mech.k, mech.c, mech.b, mech.m, h,
                  state.intact, _scratch(state))


@_jit
def _constrain_measure(x, v, anchor, r_x, r_anchor, pairs, rest, k, fmax, intact, out):
    _project(x, r_x, v, True)
    _project(anchor, r_anchor, v, False)
    return _measure(x, pairs, rest, k, fmax, intact, out)


def _radii(r) -> np.ndarray:
    """A uniform radius travels as one value; a per-base one as its array."""
    r = np.asarray(r, dtype=float)
    if r.ndim == 0 or r.strides == (0,):  # a scalar, or np.broadcast_to of one
        return np.array([r.flat[0]])
    return np.ascontiguousarray(r)


def constrain(state, r_x, r_anchor) -> None:
    _project(state.x, _radii(r_x), state.v, True)
    _project(state.anchor, _radii(r_anchor), state.v, False)


def measure(state, out: np.ndarray) -> float:
    return float(_measure(state.x, state.pairs, state.rest, state.mechanics.k, state.fmax, state.intact, out))


def constrain_measure(state, r_x, r_anchor, out: np.ndarray) -> float:
    return float(_constrain_measure(state.x, state.v, state.anchor, _radii(r_x), _radii(r_anchor), state.pairs,
                                    state.rest, state.mechanics.k, state.fmax, state.intact, out))
