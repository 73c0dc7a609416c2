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
def _spring_pass(x0, x1, x2, pi, pj, rest, k, intact, inv_fmax, f0, f1, f2, fmax, log_id, log_step, log_t, n_log, step):
    """Add every intact spring's force (eq. 1) into ``f``; return the largest ``tension·inv_fmax``
    over them (skipped when ``inv_fmax`` is empty), whether all their tensions are finite, and the
    new length of the break log.

    With a break log (``log_id`` not empty) this pass also applies the threshold rule, as
    ``ThresholdBreaker.select`` does: an intact spring whose tension exceeds its ``fmax`` is marked
    broken in ``intact`` (the kernel's working copy), its force is left out of ``f`` (so ``f`` is
    what a fresh pass after the break would give, to the bit) and ``(spring, step, tension)`` is
    appended to the log at row ``n_log``.

    The one place a spring's force is written in this backend: the per-step and the quiet kernels
    both call it, so they give the same bits whatever the split of a run into calls.
    """
    loads = inv_fmax.shape[0] > 0
    breaking = log_id.shape[0] > 0
    top = -np.inf
    finite = True
    for s in range(pi.shape[0]):
        if not intact[s]:
            continue
        i = pi[s]
        j = pj[s]
        d0 = x0[j] - x0[i]
        d1 = x1[j] - x1[i]
        d2 = x2[j] - x2[i]
        length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        t = k * (length - rest[s])
        if not abs(t) < np.inf:
            finite = False
        if loads:
            load = t * inv_fmax[s]
            if load > top:
                top = load
        if breaking and t > fmax[s]:
            intact[s] = False
            log_id[n_log] = s
            log_step[n_log] = step
            log_t[n_log] = t
            n_log += 1
            continue
        if length > 0.0:
            g = t / length
            f0[i] += g * d0
            f1[i] += g * d1
            f2[i] += g * d2
            f0[j] -= g * d0
            f1[j] -= g * d1
            f2[j] -= g * d2
    return top, finite, n_log


@_jit
def _none():
    """Empty (float, int) arrays for the optional arguments of :func:`_spring_pass` (made here: a
    global array is read-only inside numba)."""
    return np.empty(0), np.empty(0, dtype=np.int64)


@_jit
def _spring_forces(x0, x1, x2, pi, pj, rest, k, intact, f0, f1, f2):
    """``f`` = the intact springs' forces alone: :func:`_spring_pass` with no loads and no breaking."""
    f0[:] = 0.0
    f1[:] = 0.0
    f2[:] = 0.0
    no_f, no_i = _none()
    _spring_pass(x0, x1, x2, pi, pj, rest, k, intact, no_f, f0, f1, f2, no_f, no_i, no_i, no_f, 0, 0)


@_jit
def _elastic(x, anchor, pi, pj, rest, k, c, intact, f):
    _spring_forces(x[:, 0], x[:, 1], x[:, 2], pi, pj, rest, k, intact, f[:, 0], f[:, 1], f[:, 2])
    if c != 0.0:
        for a in range(3):
            xa, aa, fa = x[:, a], anchor[:, a], f[:, a]
            for q in range(xa.shape[0]):
                fa[q] -= c * (xa[q] - aa[q])


@_jit
def _euler_cromer(x, v, anchor, pi, pj, rest, k, c, b, m, h, intact, f):
    _spring_forces(x[:, 0], x[:, 1], x[:, 2], pi, pj, rest, k, intact, f[:, 0], f[:, 1], f[:, 2])
    hm = h / m
    for a in range(3):
        xa, va, aa, fa = x[:, a], v[:, a], anchor[:, a], f[:, a]
        for q in range(xa.shape[0]):
            force = fa[q] - c * (xa[q] - aa[q]) - b * va[q]
            va[q] += force * hm
            xa[q] += va[q] * h


@_jit
def _project(points, radius, velocities):
    """Eq. 9 on the bases: radially onto the surface, radial velocity removed (as the quiet kernel)."""
    uniform = radius.shape[0] == 1
    px_, py_, vx_, vy_ = points[:, 0], points[:, 1], velocities[:, 0], velocities[:, 1]
    for q in range(px_.shape[0]):
        r = radius[0] if uniform else radius[q]
        px, py = px_[q], py_[q]
        scale = r / math.sqrt(px * px + py * py)
        px *= scale
        py *= scale
        px_[q] = px
        py_[q] = py
        vr = (vx_[q] * px + vy_[q] * py) * (1.0 / (r * r))
        vx_[q] -= vr * px
        vy_[q] -= vr * py


@_jit
def _place_anchors(anchor, anchor_dir, radius):
    uniform = radius.shape[0] == 1
    ax, ay, dx, dy = anchor[:, 0], anchor[:, 1], anchor_dir[:, 0], anchor_dir[:, 1]
    for q in range(ax.shape[0]):
        r = radius[0] if uniform else radius[q]
        ax[q] = r * dx[q]
        ay[q] = r * dy[q]


@_jit
def _measure(x, pi, pj, rest, k, fmax, intact, out):
    x0, x1, x2 = x[:, 0], x[:, 1], x[:, 2]
    top = -np.inf
    finite = True
    for s in range(pi.shape[0]):
        i = pi[s]
        j = pj[s]
        d0 = x0[j] - x0[i]
        d1 = x1[j] - x1[i]
        d2 = x2[j] - x2[i]
        t = k * (math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) - rest[s])
        out[s] = t
        if not math.isfinite(t):
            finite = False
        elif intact[s]:
            load = t / fmax[s]
            if load > top:
                top = load
    return top if finite else np.nan


def _ends(state) -> tuple[np.ndarray, np.ndarray]:
    """Spring ends as two unsigned 32-bit vectors (cached while ``state.pairs`` is the same array):
    unsigned indices spare numba's negative-index wrap-around, and half-width ones memory traffic."""
    sc = state.scratch
    if sc.get("ends_of") is not state.pairs:
        p = state.pairs.astype(np.uint32)
        sc["ends_of"], sc["ends"] = state.pairs, (np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]))
    return sc["ends"]


def _scratch(state, name: str, like: np.ndarray, dtype=None) -> np.ndarray:
    """A work buffer shaped and laid out like ``like`` (of ``dtype``, default ``like``'s), kept in
    ``state.scratch`` between calls."""
    dtype = like.dtype if dtype is None else np.dtype(dtype)
    buf = state.scratch.get(name)
    if (buf is None or buf.shape != like.shape or buf.dtype != dtype
            or buf.flags.f_contiguous != like.flags.f_contiguous):
        buf = state.scratch[name] = np.empty_like(like, dtype=dtype)
    return buf


def elastic_forces(state, x: np.ndarray) -> np.ndarray:
    mech = state.mechanics
    f = np.empty_like(x, order="F")
    _elastic(x, state.anchor, *_ends(state), state.rest, mech.k, mech.c, state.intact, f)
    return f


def euler_cromer_step(state, h: float) -> None:
    mech = state.mechanics
    _euler_cromer(state.x, state.v, state.anchor, *_ends(state), state.rest, mech.k, mech.c, mech.b, mech.m, h,
                  state.intact, _scratch(state, "f", state.x))


@_jit
def _constrain_measure(x, v, anchor, anchor_dir, r_x, r_anchor, pi, pj, rest, k, fmax, intact, out):
    _project(x, r_x, v)
    _place_anchors(anchor, anchor_dir, r_anchor)
    return _measure(x, pi, pj, rest, k, fmax, intact, out)


def _radii(r) -> np.ndarray:
    """A uniform radius travels as one value; a per-base one as its array."""
    r = np.asarray(r, dtype=float)
    if r.ndim == 0 or r.strides == (0,):  # a scalar, or np.broadcast_to of one
        return np.array([r.flat[0]])
    return np.ascontiguousarray(r)


def measure(state, out: np.ndarray) -> float:
    return float(_measure(state.x, *_ends(state), state.rest, state.mechanics.k, state.fmax, state.intact, out))


def constrain_measure(state, r_x, r_anchor, out: np.ndarray) -> float:
    return float(_constrain_measure(state.x, state.v, state.anchor, state.anchor_dir, _radii(r_x), _radii(r_anchor),
                                    *_ends(state), state.rest, state.mechanics.k, state.fmax, state.intact, out))


@_jit
def _ec_bases(x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy, ra, from_dir, r, c, b, hm, h):
    """One Euler–Cromer step of every base (eqs. 4, 7, 8) on the spring forces in ``f``, then the
    surface constraint at uniform radius ``r`` (eq. 9, as :func:`_project`); ``f`` is zeroed as it is
    consumed.  The anchors are ``(ra·d, az)`` if ``from_dir``, else as stored (the very expression
    :func:`_place_anchors` writes, so the bits do not depend on where calls end).  Returns whether
    every coordinate stayed finite.  One coordinate per vector: this loop runs in SIMD lanes."""
    bad = 0
    inv_r2 = 1.0 / (r * r)
    for q in range(x0.shape[0]):
        if from_dir:
            anchor_x = ra * dx[q]
            anchor_y = ra * dy[q]
        else:
            anchor_x = ax[q]
            anchor_y = ay[q]
        g0 = f0[q] - c * (x0[q] - anchor_x) - b * v0[q]
        g1 = f1[q] - c * (x1[q] - anchor_y) - b * v1[q]
        g2 = f2[q] - c * (x2[q] - az[q]) - b * v2[q]
        f0[q] = 0.0
        f1[q] = 0.0
        f2[q] = 0.0
        u0 = v0[q] + g0 * hm
        u1 = v1[q] + g1 * hm
        u2 = v2[q] + g2 * hm
        px = x0[q] + u0 * h
        py = x1[q] + u1 * h
        pz = x2[q] + u2 * h
        scale = r / math.sqrt(px * px + py * py)
        px *= scale
        py *= scale
        x0[q] = px
        x1[q] = py
        x2[q] = pz
        bad += not abs(px + py + pz) < np.inf  # NaN or inf in any coordinate shows here
        vr = (u0 * px + u1 * py) * inv_r2
        v0[q] = u0 - vr * px
        v1[q] = u1 - vr * py
        v2[q] = u2
    return bad == 0


@_jit
def _euler_cromer_quiet(x, v, anchor, anchor_dir, pi, pj, rest, k, c, b, m, h, intact, inv_fmax, fmax, radii, f,
                        accept_load, log_id, log_step, log_t, return_on_break, max_batch):
    """Up to ``len(radii)`` whole steps (integrate, constrain, measure) at uniform radii ``radii``, in
    one call.  Returns ``(steps taken, max load of the last step, length of the break log)``, the load
    NaN if that step went non-finite (any coordinate of any base, or any intact tension).

    Without a break log it stops after the first step whose max load exceeds 1 (a spring for the
    breakers to judge).  With one, springs over their threshold break inside the call (see
    :func:`_spring_pass`; ``intact`` is then the caller's working copy) and it goes on, unless
    ``return_on_break`` or a step breaks more than ``max_batch`` springs (a degenerate event).  It
    also stops after a step whose load exceeds ``accept_load`` (the caller undoes that step).

    The spring pass that finds the load also accumulates the next step's spring forces into ``f``
    (first same as last), through :func:`_spring_pass` as the per-step kernels do, so the result
    does not depend on where calls begin and end.  Anchors (radius × fixed direction) are written
    back once, at the end; the caller fills the tensions, if it needs them, for the last step.
    """
    hm = h / m
    x0, x1, x2 = x[:, 0], x[:, 1], x[:, 2]
    v0, v1, v2 = v[:, 0], v[:, 1], v[:, 2]
    f0, f1, f2 = f[:, 0], f[:, 1], f[:, 2]
    ax, ay, az = anchor[:, 0], anchor[:, 1], anchor[:, 2]
    dx, dy = anchor_dir[:, 0], anchor_dir[:, 1]
    breaking = log_id.shape[0] > 0
    _spring_forces(x0, x1, x2, pi, pj, rest, k, intact, f0, f1, f2)
    top = -np.inf
    finite = True
    done = 0
    n_log = 0
    for step in range(radii.shape[0]):
        ra = radii[step - 1] if step > 0 else 0.0
        finite = _ec_bases(x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy, ra, step > 0, radii[step], c, b, hm, h)
        before = n_log
        top, springs_finite, n_log = _spring_pass(x0, x1, x2, pi, pj, rest, k, intact, inv_fmax, f0, f1, f2,
                                                  fmax, log_id, log_step, log_t, n_log, step)
        finite = finite and springs_finite
        done = step + 1
        if not finite or top > accept_load:
            break
        if not breaking:
            if top > 1.0:
                break
        elif n_log > before and (return_on_break or n_log - before > max_batch):
            break
    _place_anchors(anchor, anchor_dir, radii[done - 1 : done])  # the anchors at the last step's radius
    return done, (top if finite else np.nan), n_log


def euler_cromer_quiet(state, h: float, radii: np.ndarray, tension: np.ndarray, accept_load: float = math.inf,
                       break_rule: str | None = None, return_on_break: bool = True, max_batch: float = math.inf):
    """Euler–Cromer steps at the uniform trunk radii ``radii`` (one per step); see
    :func:`_euler_cromer_quiet`.  Returns ``(accepted steps, max load of the last step tried,
    breaks)``, ``breaks`` being ``(spring ids, step within the call counted from 1, tensions)`` of
    the springs broken inside the call (empty unless ``break_rule`` is ``"over-threshold"``).  The
    state's ``intact`` is not touched: the caller applies ``breaks`` (``Simulation.break_springs``).

    If the last step tried went non-finite, or its load exceeds ``accept_load``, it is undone: the
    state is put back to the one before it by replaying the call's steps up to there from its start
    (breaks included: the replay is exact), and it is not counted.  Without a break rule,
    ``tension`` is filled when the returned step overloads a spring (load > 1): only then is it read."""
    if break_rule not in (None, "over-threshold"):
        raise ValueError(f"break_rule = {break_rule!r}: this backend knows only 'over-threshold'")
    mech = state.mechanics
    pi, pj = _ends(state)
    now = (state.x, state.v, state.anchor)
    start = [_scratch(state, f"start{i}", a) for i, a in enumerate(now)]
    for keep, a in zip(start, now):
        np.copyto(keep, a)
    inv_fmax = np.divide(1.0, state.fmax, out=_scratch(state, "inv_fmax", state.fmax))
    radii = np.ascontiguousarray(radii, dtype=float)
    if break_rule is None:
        no_f, no_i = _none()
        live, log = state.intact, (no_i, no_i, no_f)
    else:
        live = _scratch(state, "live", state.intact)
        log = (_scratch(state, "log_id", state.intact, np.int64), _scratch(state, "log_step", state.intact, np.int64),
               _scratch(state, "log_t", state.intact, float))

    def call(r):
        if live is not state.intact:
            np.copyto(live, state.intact)
        return _euler_cromer_quiet(state.x, state.v, state.anchor, state.anchor_dir, pi, pj, state.rest, mech.k,
                                   mech.c, mech.b, mech.m, h, live, inv_fmax, state.fmax, r,
                                   _scratch(state, "f", state.x), accept_load, *log, return_on_break, max_batch)

    done, load, n_log = call(radii)
    if math.isnan(load) or load > accept_load:
        for keep, a in zip(start, now):
            np.copyto(a, keep)
        n_log = call(radii[: done - 1])[2] if done > 1 else 0
        done -= 1
    elif load > 1.0 and break_rule is None:  # springs to break: the breakers need every tension of this state
        _measure(state.x, pi, pj, state.rest, mech.k, state.fmax, state.intact, tension)
    breaks = (log[0][:n_log].copy(), log[1][:n_log] + 1, log[2][:n_log].copy())
    return int(done), float(load), breaks


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
