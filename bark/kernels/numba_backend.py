"""The numba backend: each kernel is one compiled pass over the springs and/or the bases.

Compiled on first use and cached on disk (``cache=True``).  Loops run serially: on the 2-core
machines bark targets, the spring scatter is memory-bound and threads buy little.
"""

from __future__ import annotations

import math

import numba
import numpy as np

NAME = "numba"

# error_model="numpy": no Python-style zero-division branches.  No fastmath: each expression is
# evaluated exactly as written, so the same expression in the per-step and the quiet kernels gives
# the same bits, and a run's result does not depend on where its compiled calls begin and end
# (what makes a resumed run end bit-identical to an uninterrupted one).
_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


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
def _project(points, radius, velocities):
    """Eq. 9 on the bases: radially onto the surface, radial velocity removed (as the quiet kernel)."""
    uniform = radius.shape[0] == 1
    for q in range(points.shape[0]):
        r = radius[0] if uniform else radius[q]
        px, py = points[q, 0], points[q, 1]
        scale = r / math.sqrt(px * px + py * py)
        px *= scale
        py *= scale
        points[q, 0] = px
        points[q, 1] = py
        vr = (velocities[q, 0] * px + velocities[q, 1] * py) * (1.0 / (r * r))
        velocities[q, 0] -= vr * px
        velocities[q, 1] -= vr * py


@_jit
def _place_anchors(anchor, anchor_dir, radius):
    uniform = radius.shape[0] == 1
    for q in range(anchor.shape[0]):
        r = radius[0] if uniform else radius[q]
        anchor[q, 0] = r * anchor_dir[q, 0]
        anchor[q, 1] = r * anchor_dir[q, 1]


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
def _constrain_measure(x, v, anchor, anchor_dir, r_x, r_anchor, pairs, rest, k, fmax, intact, out):
    _project(x, r_x, v)
    _place_anchors(anchor, anchor_dir, r_anchor)
    return _measure(x, pairs, rest, k, fmax, intact, out)


def _radii(r) -> np.ndarray:
    """A uniform radius travels as one value; a per-base one as its array."""
    r = np.asarray(r, dtype=float)
    if r.ndim == 0 or r.strides == (0,):  # a scalar, or np.broadcast_to of one
        return np.array([r.flat[0]])
    return np.ascontiguousarray(r)


def measure(state, out: np.ndarray) -> float:
    return float(_measure(state.x, state.pairs, state.rest, state.mechanics.k, state.fmax, state.intact, out))


def constrain_measure(state, r_x, r_anchor, out: np.ndarray) -> float:
    return float(_constrain_measure(state.x, state.v, state.anchor, state.anchor_dir, _radii(r_x), _radii(r_anchor),
                                    state.pairs, state.rest, state.mechanics.k, state.fmax, state.intact, out))


@_jit
def _euler_cromer_quiet(x, v, anchor, anchor_dir, pairs, rest, k, c, b, m, h, intact, inv_fmax, r_x, r_a, f):
    """Up to ``r_x.shape[0]`` whole steps (integrate, constrain, measure) in one call.

    Stops after the first step whose max load exceeds 1 (a spring to break) or whose tensions are
    not finite.  Returns ``(steps taken, max load of the last step)``, the load NaN if that step
    went non-finite.  The spring pass that finds the load also accumulates the next step's spring
    forces into ``f`` (first same as last), by the very expressions the per-step kernels use, so the
    result does not depend on where calls begin and end.  The loop is memory-bound, so it touches
    as little as it can: anchors (radius × fixed direction) are written back once at the end; the
    caller fills the tensions once, for the last step.  A step is non-finite if any coordinate of
    any base is (summed into ``total``) or any intact tension is.
    """
    n = x.shape[0]
    hm = h / m
    f[:] = 0.0
    _spring_forces(x, pairs, rest, k, intact, f)
    top = -np.inf
    total = 0.0
    ux = r_x.shape[1] == 1
    ua = r_a.shape[1] == 1
    done = 0
    for step in range(r_x.shape[0]):
        r = r_x[step, 0]
        total = 0.0
        for q in range(n):
            # the anchor before this step: as stored, then at the previous step's radius (the
            # very expression _place_anchors writes, so the bits do not depend on where calls end)
            if step == 0:
                ax = anchor[q, 0]
                ay = anchor[q, 1]
            else:
                ra = r_a[step - 1, 0] if ua else r_a[step - 1, q]
                ax = ra * anchor_dir[q, 0]
                ay = ra * anchor_dir[q, 1]
            f0 = f[q, 0] - c * (x[q, 0] - ax) - b * v[q, 0]
            f1 = f[q, 1] - c * (x[q, 1] - ay) - b * v[q, 1]
            f2 = f[q, 2] - c * (x[q, 2] - anchor[q, 2]) - b * v[q, 2]
            f[q, 0] = 0.0  # consumed: ready for the next spring pass
            f[q, 1] = 0.0
            f[q, 2] = 0.0
            v0 = v[q, 0] + f0 * hm
            v1 = v[q, 1] + f1 * hm
            v2 = v[q, 2] + f2 * hm
            px = x[q, 0] + v0 * h
            py = x[q, 1] + v1 * h
            x[q, 2] += v2 * h
            v[q, 2] = v2
            if not ux:
                r = r_x[step, q]
            sc = r / math.sqrt(px * px + py * py)
            px *= sc
            py *= sc
            x[q, 0] = px
            x[q, 1] = py
            total += px + py + x[q, 2]  # NaN or inf anywhere, even on a base with no intact spring, shows here
            vr = (v0 * px + v1 * py) * (1.0 / (r * r))
            v[q, 0] = v0 - vr * px
            v[q, 1] = v1 - vr * py
        top = -np.inf
        for s in range(pairs.shape[0]):
            if not intact[s]:
                continue
            i, j = pairs[s, 0], pairs[s, 1]
            d0 = x[j, 0] - x[i, 0]
            d1 = x[j, 1] - x[i, 1]
            d2 = x[j, 2] - x[i, 2]
            length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            t = k * (length - rest[s])
            total += t
            load = t * inv_fmax[s]
            if load > top:
                top = load
            # The spring's force, written exactly as in _spring_forces (same bits; enforced by the
            # tests that a split run and step() equal advance() bit for bit).  Kept inline on
            # purpose: a shared njit helper is not inlined across numba functions and made this
            # loop 2.5x slower (measured with bark bench speed).
            if length > 0.0:
                g = k * (length - rest[s]) / length
                f[i, 0] += g * d0
                f[i, 1] += g * d1
                f[i, 2] += g * d2
                f[j, 0] -= g * d0
                f[j, 1] -= g * d1
                f[j, 2] -= g * d2
        done = step + 1
        if not math.isfinite(total) or top > 1.0:
            break
    _place_anchors(anchor, anchor_dir, r_a[done - 1])  # the anchors at the last step's radius
    return done, (top if math.isfinite(total) else np.nan)


def euler_cromer_quiet(
    state, h: float, r_x: np.ndarray, r_a: np.ndarray, tension: np.ndarray, accept_load: float = math.inf
) -> tuple[int, float]:
    """Euler–Cromer steps with radii ``r_x``/``r_a`` (one row per step, 1 or n columns); see
    :func:`_euler_cromer_quiet`.  Returns ``(accepted steps, max load of the last step tried)``.

    If the last step tried went non-finite, or its load exceeds ``accept_load``, it is undone: the
    state is put back to the one before it by replaying the call's steps up to there from its start
    (nothing breaks inside a call, so the replay is exact), and it is not counted.  ``tension`` is
    filled only when the returned step overloads a spring (load > 1): only then is it read."""
    mech = state.mechanics
    sc = state.scratch
    if sc.get("pairs_of") is not state.pairs:  # int32 spring ends: less memory traffic per step
        sc["pairs_of"], sc["pairs32"] = state.pairs, state.pairs.astype(np.int32)
    start = (state.x.copy(), state.v.copy(), state.anchor.copy())
    inv_fmax = 1.0 / state.fmax

    def call(rows_x, rows_a):
        return _euler_cromer_quiet(
            state.x, state.v, state.anchor, state.anchor_dir, sc["pairs32"], state.rest, mech.k, mech.c, mech.b,
            mech.m, h, state.intact, inv_fmax, rows_x, rows_a, _scratch(state),
        )

    done, load = call(r_x, r_a)
    if math.isnan(load) or load > accept_load:
        for keep, now in zip(start, (state.x, state.v, state.anchor)):
            np.copyto(now, keep)
        if done > 1:
            call(r_x[: done - 1], r_a[: done - 1])
        return done - 1, float(load)
    if load > 1.0:  # springs to break: the breakers need every tension of this state
        _measure(state.x, sc["pairs32"], state.rest, mech.k, state.fmax, state.intact, tension)
    return int(done), float(load)


@_jit
def _components(n, pairs, intact, labels):
    """Connected components of the intact springs by union-find; labels numbered in order of each
    component's smallest base, as scipy.sparse.csgraph.connected_components numbers them."""
    parent = np.arange(n)
    for s in range(pairs.shape[0]):
        if not intact[s]:
            continue
        a, b = pairs[s, 0], pairs[s, 1]
        while parent[a] != a:  # find, halving the path as we go
            parent[a] = parent[parent[a]]
            a = parent[a]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a != b:
            if a < b:
                parent[b] = a
            else:
                parent[a] = b
    count = 0
    for q in range(n):  # roots are each component's smallest base, met in increasing order
        r = q
        while parent[r] != r:
            r = parent[r]
        if r == q:
            labels[q] = count
            count += 1
        else:
            labels[q] = labels[r]
    return count


def patch_labels(state) -> np.ndarray:
    labels = np.empty(state.n_bases, dtype=np.int32)
    _components(state.n_bases, state.pairs, state.intact, labels)
    return labels
