"""The numba backend: the physics of :mod:`bark.model.physics` and the strategies' parts, compiled.

**One stepping kernel.**  ``_steps_kernel`` is written once, with the integrator's update, the
breaking rule and the growth law's radius as parameters.  Each combination gets a file of its own
(``specialized``): the kernel's source, those parameters bound by name to the parts' functions as
the file's globals, so that numba inlines them into the loop (as fast as writing them out,
measured) and compiles and caches the kernel on disk like any other function: a plugin's part
costs a compilation once, not per run.  The per-step and
the many-step paths are calls of this one kernel, so their bits agree by construction.

Each piece of physics is :mod:`bark.model.physics`'s function, inlined (``inline="always"``).  No
fastmath: every expression is evaluated as written, so a run does not depend on where its compiled
calls begin and end (what makes a resumed run end bit-identical).  A maximum is exact in any order:
the largest load (``_largest_load``) is taken in SIMD lanes, in every step's pass over the loads the
pass makes anyway, whether or not adaptive stepping judges the step by it.

**Blocks, and threads.**  The loops over bases and over a run's springs go a block of ``BLOCK`` at a
time, and a spring's force reaches its bases by a *gather* over blocks of bases (each base takes its
springs' forces in the order of the serial sum), so no two blocks write the same entry.  Every
kernel is compiled twice from the same source: with the blocks shared among threads (``prange``,
``Numerics.threads``: ``_step_split``, the base pass over every block, then the spring pass), and
serial, in one sweep over the blocks of bases (``_step_fused``: each block of bases moved, the
springs that reach it made, its forces gathered, while they are in cache).  Per base and per
spring the arithmetic, and its order, are the same, so the two give the same bits (tested).
Threads pay on large lattices only (a parallel loop costs a few microseconds to start:
``PARALLEL_BASES``).
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import importlib
import importlib.util
import inspect
import json
import logging
import math
import os
import pickle
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Callable

import attrs
import llvmlite.ir

from bark.engine.kernels import numba_alongside, numba_env

numba_env.settle()  # before numba reads the environment

import numba  # noqa: E402
import numba.core.caching  # noqa: E402
import numba.extending  # noqa: E402
import numpy as np
from numba import prange

from bark.model import physics
from bark.model.forces import SpringOrder, order_keys
from bark.engine.kernels import Backend, Call, Plan, Steps, doubles, ends_call, limits, runs_many
from bark.errors import BarkError, BarkWarning
from bark.model.state import grown
from bark.model.physics import weighted_radius
from bark.contract.parts import HOOKEAN, GrowthPart, resin_tension

NAME = "numba"
LOG = logging.getLogger("bark")
"""Where the backend says what takes long (a first compilation): a notice, not a warning."""

jit = numba.njit(cache=True, nogil=True, error_model="numpy")
inline = numba.njit(inline="always", error_model="numpy")

_length = inline(physics.length)
_tension = inline(physics.tension)
_force_scale = inline(physics.spring_force_scale)
_base_force = inline(physics.base_force)
_surface_scale = inline(physics.surface_scale)
_radial_speed = inline(physics.radial_speed)
_ends_call = inline(ends_call)
_doubles = inline(doubles)
_limits = inline(limits)


@inline
def _never(tension, length, rest, fmax, inv_fmax, own, q, params):
    """The kernel's rule where none is asked (a pass for forces alone)."""
    return False


@inline
def _no_load(tension, length, rest, fmax, inv_fmax, own, q, params):
    """The kernel's load where none is asked."""
    return -np.inf


@inline
def _hooke(length, rest, own, q, k, params):
    """The kernel's resin law where the paper's spring is asked (eq. 1), as the adapters call a law."""
    return _tension(length, rest[q], k)


@inline
def _no_flow(length, rest, own, q, h, params):
    """The flow of a resin that does not flow."""
    return None


IN_PLACE_STEPS = 8
"""Steps a call at per-base radii must be allowed to take before a step adaptive stepping refuses is
taken back in the call rather than by replaying the call to it.  A replay costs the steps before
the refused one, at most ``Plan.n − 1``, the forces made again, and a call of its own for the
halved step; it is paid only when a step is refused.  Taken back in the call, a radius that
depends on height has each step's bases copied first (a pass over them every step), so calls of a
few steps (the whole tree's, ended by every join) replay and long ones (up to 128 steps) take back
in the call.  A uniform radius takes back in the call whatever its length: each step is written
into the other of two buffers (the state before it left in the one it is read from), which costs
a copy into the state's vectors at the end of a call that ends in the other one.  The bits are the
same either way."""

BLOCK = 2048
"""Bases or springs a block (``NumbaBackend.block``): the loops over them go a block at a time (each
block's loops in SIMD lanes); in a parallel kernel the blocks are shared among threads.  Every base's
arithmetic is the same whatever the blocks and threads, so the bits are too.  Chosen as the fastest
of the powers of two tried on the whole tree with two threads."""


@inline
def _run_forces(a0, a1, a2, b0, b1, b2, rest, live, fmax, inv, own, k, w0, w1, w2, wt, wl, wp, loads, rule, load, bp,
                law, flow, resin):
    """Tension and force vector of each spring of a run, ends ``a`` and ``b``, into ``wt`` and ``w``;
    with ``loads``, also the breaker part's load into ``wl`` (``-inf`` where the spring is not live) and
    whether its ``rule`` picks each live spring into ``wp`` (``rule`` and ``load`` take ``(tension,
    length, rest, fmax, 1/fmax, own, q, bp)``, ``own[q]`` the spring's declared fields: the generated
    adapters pass on what the part reads), and return whether every live tension is finite and every
    live load a number (not NaN) and whether the rule picked a live spring.  The tension is the resin
    law's (``law(length, rest, own, q, k, rp)``); with ``resin = (rp, h, evolve)``'s ``evolve``, each
    live spring then flows for a step ``h`` (``flow`` writes its new rest length or own fields in place)
    and its force is of the tension after the flow — the next step's (``tests/test_resins.py``: the bits
    of numpy's)."""
    rp, h, evolve = resin
    finite = True
    hit = False
    for q in range(rest.shape[0]):
        d0 = b0[q] - a0[q]
        d1 = b1[q] - a1[q]
        d2 = b2[q] - a2[q]
        length = _length(d0, d1, d2)
        t = law(length, rest, own, q, k, rp)
        on = live[q]
        tf = t
        if evolve and on:
            flow(length, rest, own, q, h, rp)
            tf = law(length, rest, own, q, k, rp)
        g = _force_scale(tf, length)
        g = g if (length > 0.0) & on else 0.0  # a spring of zero length has no direction
        wt[q] = t
        w0[q] = g * d0
        w1[q] = g * d1
        w2[q] = g * d2
        if loads:
            lq = load(t, length, rest[q], fmax[q], inv[q], own, q, bp)
            pq = on & rule(t, length, rest[q], fmax[q], inv[q], own, q, bp)
            wl[q] = lq if on else -np.inf  # as ``_largest_load`` takes them
            wp[q] = pq
            finite = finite & (((abs(t) < np.inf) & (lq == lq)) | (not on))
            hit = hit | pq
    return finite, hit


@inline
def _blocks(n, block):
    """How many blocks of ``block`` items ``n`` items make (a parallel loop's iterations)."""
    return (n + block - 1) // block


@inline
def _gather_forces(u, w, i0, o, n, lo, hi):
    """A run's forces along one axis added into the bases ``lo .. hi`` (a block of the bases the run
    reaches: its first ends ``i0 .. i0 + n`` and second ends ``i0 + o .. i0 + o + n``): subtracted at
    those that are its springs' second ends, then added at those that are their first ends — per
    base, the order in which a pass over the run's springs adds them (all second ends, then all first
    ends), so the same bits whatever the blocks."""
    s_lo, s_hi = max(lo, i0 + o), min(hi, i0 + o + n)
    if s_hi > s_lo:
        second, ws = u[s_lo:s_hi], w[s_lo - i0 - o:s_hi - i0 - o]
        for q in range(second.shape[0]):
            second[q] -= ws[q]
    f_lo, f_hi = max(lo, i0), min(hi, i0 + n)
    if f_hi > f_lo:
        first, wf = u[f_lo:f_hi], w[f_lo - i0:f_hi - i0]
        for q in range(first.shape[0]):
            first[q] += wf[q]


@numba.extending.intrinsic
def _bits(typingctx, x):
    """A double's 64 bits as an integer (no conversion: the same register)."""
    return numba.types.int64(numba.types.float64), lambda context, builder, sig, args: builder.bitcast(
        args[0], llvmlite.ir.IntType(64))


@numba.extending.intrinsic
def _number(typingctx, x):
    """The double whose 64 bits are the integer ``x`` (``_bits`` undone)."""
    return numba.types.float64(numba.types.int64), lambda context, builder, sig, args: builder.bitcast(
        args[0], llvmlite.ir.DoubleType())


_MAGNITUDE = np.int64(0x7FFF_FFFF_FFFF_FFFF)
"""A double's bits but its sign: flipped where it is negative, its bits as an integer order as the
numbers do (``_largest_load``)."""


@jit
def _largest_load(wl):
    """The largest of the loads ``wl`` (``_run_forces`` writes ``-inf`` for a spring that is not
    live; ``-inf`` if there are none).  A maximum is exact in any order, so it is taken on integers
    that order as the doubles do — each one's bits, its magnitude bits flipped where it is negative
    — in SIMD lanes: numba takes a maximum of doubles one at a time (a chain of compares, several
    times slower).  The order differs from the doubles' only for NaN (the finiteness check
    reports that step instead) and between −0 and +0 (equal as loads)."""
    top = _bits(-np.inf) ^ _MAGNITUDE
    for q in range(wl.shape[0]):
        key = _bits(wl[q])
        key = key ^ ((key >> 63) & _MAGNITUDE)
        top = key if key > top else top
    return _number(top ^ ((top >> 63) & _MAGNITUDE))


@inline
def _picked(lv, s0, lo, hi, wp, wt, w0, w1, w2, breaking, log_id, log_step, log_t, n_log, step):
    """The springs ``lo .. hi`` of a run (from spring ``s0``, ``lv`` its working ``live``) that the
    breaker's rule picked (``wp``; ``wp``, ``wt`` and the force vectors ``w`` a block's work buffers,
    from spring ``lo``): with ``breaking``, each marked broken, logged (id, ``step``, tension) and its
    force left out (zeroed); without, only noted.  Returns ``(log length, whether one was noted)``."""
    picked = False
    for q in range(hi - lo):
        if wp[q]:
            if breaking:
                lv[lo + q] = False
                log_id[n_log] = s0 + lo + q
                log_step[n_log] = step
                log_t[n_log] = wt[q]
                n_log += 1
                w0[q] = 0.0
                w1[q] = 0.0
                w2[q] = 0.0
            else:
                picked = True
    return n_log, picked


@inline
def _spring_pass(x, runs, rest, k, live, fmax, inv_fmax, own, f, work, loads, breaking, rule, load, bp,
                 log_id, log_step, log_t, n_log, step, block, law, flow, resin, first):
    """Add every live spring's force (eq. 1) into ``f`` at the bases from ``first`` on (0: all; only the
    springs that reach them are made, a block at a time from the block of the first).  With ``loads``:
    also check the tensions are finite and apply the breaker part's rule: with ``breaking``, a spring it
    picks is marked broken in ``live`` (the call's working copy), left out of ``f`` (what a fresh pass
    after the break gives, to the bit) and logged; without, it is only noted; and find the largest of
    the part's loads (else ``-inf``).  Returns ``(largest load, all tensions finite, log length, whether
    the rule picked a spring)``.

    Springs come in runs ``(i, i + o)``, ``i`` consecutive (a lattice is a few such runs; see
    ``SpringOrder.runs``), each done on contiguous slices so the loops run in SIMD lanes, a block of
    springs at a time, the blocks shared among threads: the springs' tensions, force vectors,
    finiteness and the rule in one loop, into the run's work buffers; their largest load in a
    second; a spring by itself only where the rule picks one (after all blocks, ``_picked``); then
    the forces, gathered a block of bases at a time, each base taking its force as a second end
    before its force as a first end (``_gather_forces``), so that every base receives its springs'
    forces in the order of the runs (:class:`bark.model.forces.SpringOrder`, in which the springs
    come here) — the order, and the bits, of a pass one spring at a time, and of the numpy
    backend's sum."""
    x0, x1, x2 = x
    f0, f1, f2 = f
    w0, w1, w2, wt, wl, wp = work
    r_start, r_len, r_i, r_o = runs
    top = -np.inf
    finite = True
    picked = False
    for r in range(r_start.shape[0]):
        s0, n, i0, o = r_start[r], r_len[r], r_i[r], r_o[r]
        rr, lv = rest[s0:s0 + n], live[s0:s0 + n]
        fm, inv, ow = fmax[s0:s0 + n], inv_fmax[s0:s0 + n], own[s0:s0 + n]
        nb = _blocks(n, block)
        block_finite, block_hit, block_top = np.ones(nb, np.bool_), np.zeros(nb, np.bool_), np.full(nb, -np.inf)
        for blk in prange(max(0, first - i0 - max(o, 0)) // block, nb):  # the springs' forces, a block at a time
            lo, hi = blk * block, min(n, (blk + 1) * block)
            a, e = i0 + lo, i0 + hi
            block_finite[blk], block_hit[blk] = _run_forces(
                x0[a:e], x1[a:e], x2[a:e], x0[a + o:e + o], x1[a + o:e + o], x2[a + o:e + o], rr[lo:hi], lv[lo:hi],
                fm[lo:hi], inv[lo:hi], ow[lo:hi], k, w0[lo:hi], w1[lo:hi], w2[lo:hi], wt[lo:hi], wl[lo:hi], wp[lo:hi],
                loads, rule, load, bp, law, flow, resin)
            if loads:
                block_top[blk] = _largest_load(wl[lo:hi])
        hit = False
        for blk in range(nb):
            finite = finite & block_finite[blk]
            hit = hit | block_hit[blk]
            top = max(top, block_top[blk])
        if loads and hit:
            for blk in range(nb):  # only the blocks the rule picked springs in, in order
                if block_hit[blk]:
                    lo, hi = blk * block, min(n, (blk + 1) * block)
                    n_log, noted = _picked(lv, s0, lo, hi, wp[lo:hi], wt[lo:hi], w0[lo:hi], w1[lo:hi], w2[lo:hi],
                                           breaking, log_id, log_step, log_t, n_log, step)
                    picked = picked | noted
        low = i0 + min(o, 0)  # the bases they reach: low .. low + span (an offset may be negative)
        span = n + abs(o)
        for blk in prange(max(0, first - low) // block, _blocks(span, block)):  # then added to the bases they
            lo, hi = max(first, low + blk * block), low + min(span, (blk + 1) * block)  # reach, a block at a time
            _gather_forces(f0, w0, i0, o, n, lo, hi)
            _gather_forces(f1, w1, i0, o, n, lo, hi)
            _gather_forces(f2, w2, i0, o, n, lo, hi)
    return top, finite, n_log, picked


@inline
def _step_split(bases, to, runs, rest, k, live, fmax, inv_fmax, own, work, move, first, motion, update, radii, heights,
                block, prev, save, breaking, rule, load, bp, log, n_log, step, law, flow, resin, base_block):
    """One step (``move``; without, only the forces of the bases from ``first`` on as they are, added
    into ``f``: the step's spring pass without its base pass, its loads or its breaks): the base pass over
    every base (``_base_pass``, its numbers ``motion``, a block at a time by ``base_block``), from
    ``bases`` into ``to`` (the kernel's other buffer, or vectors of ``bases``' own: ``_base_pass``), then
    the spring pass over every spring, on the positions in ``to``, each a block at a time, the blocks
    shared among threads (the parallel kernel's).  Returns ``(bases finite, largest load, tensions
    finite, log length, whether
    the rule picked a spring)``."""
    c, b, hm, h, t, ip, q, r_now, r_before, from_radius = motion
    log_id, log_step, log_t = log
    finite = True
    if move:
        finite = _base_pass(bases, to, c, b, hm, h, t, update, ip, radii, q, r_now, r_before, from_radius, heights,
                            block, prev, save, base_block)
    x, f = (to[0], to[1], to[2]), (bases[6], bases[7], bases[8])
    top, springs_finite, n_log, picked = _spring_pass(x, runs, rest, k, live, fmax, inv_fmax, own, f, work, move,
                                                      breaking and move, rule, load, bp, log_id, log_step, log_t, n_log,
                                                      step, block, law, flow, resin, first)
    return finite, top, springs_finite, n_log, picked


@inline
def _step_fused(bases, to, runs, rest, k, live, fmax, inv_fmax, own, work, move, first, motion, update, radii, heights,
                block, prev, save, breaking, rule, load, bp, log, n_log, step, law, flow, resin, base_block):
    """``_step_split`` on one thread, the same bits, in one sweep over blocks of bases: a block's
    forces are gathered as soon as the springs that reach it are made, and those springs are made as
    soon as the base pass has moved both their ends, so that the bases' positions and forces, and
    the springs' work buffers, are used while they are in cache — on a large lattice their round
    trips through main memory cost as much as the arithmetic.  The base pass runs ahead of the
    gather by the runs' largest offset; each run keeps its springs made but not yet gathered at both
    ends in a window of its own (``2 · block + |o|`` springs, slid down when full).  Per base the
    forces arrive in the order of the runs, second end before first end (``_gather_forces`` over the
    block of bases, on the run's window), per spring the arithmetic is the same: the same bits.  The
    springs the rule picks are broken and logged as their block is made (the log's order is not
    the split pass's; the backend sorts it by step and spring id)."""
    c, b, hm, h, t, ip, q, r_now, r_before, from_radius = motion
    log_id, log_step, log_t = log
    x0, x1, x2, f0, f1, f2 = to[0], to[1], to[2], bases[6], bases[7], bases[8]  # the springs' ends: where the
    # base pass leaves the positions
    r_start, r_len, r_i, r_o = runs
    n, runs_n = x0.shape[0], r_start.shape[0]
    reach = 0
    room = np.empty(runs_n + 1, np.int64)  # run r's window: room[r] .. room[r + 1] of the window buffers
    room[0] = 0
    for r in range(runs_n):
        reach = max(reach, abs(r_o[r]))
        room[r + 1] = room[r] + min(r_len[r], 2 * block + abs(r_o[r]))
    win = (np.empty(room[runs_n]), np.empty(room[runs_n]), np.empty(room[runs_n]), np.empty(room[runs_n]),
           np.empty(room[runs_n]), np.zeros(room[runs_n], np.bool_))
    low = np.empty(runs_n, np.int64)  # the first spring in run r's window
    made = np.empty(runs_n, np.int64)  # springs of run r made so far: from the first that reaches base ``first``
    for r in range(runs_n):
        low[r] = made[r] = min(r_len[r], max(0, first - r_i[r] - max(r_o[r], 0)))
    bad = 0
    top = -np.inf
    finite = True
    picked = False
    moved = 0 if move else n  # bases moved so far
    for blk in range(first // block, _blocks(n, block)):
        lo, hi = max(first, blk * block), min(n, (blk + 1) * block)
        while moved < min(n, hi + reach):  # the base pass, ahead of the springs that reach this block
            bad += base_block(bases, to, moved, min(n, moved + block), c, b, hm, h, t, update, ip, radii, q, r_now,
                              r_before, from_radius, heights, prev, save)
            moved = min(n, moved + block)
        for r in range(runs_n):
            s0, nr, i0, o = r_start[r], r_len[r], r_i[r], r_o[r]
            need_lo = max(0, lo - i0 - max(o, 0))  # the springs whose ends this block holds
            need_hi = min(nr, hi - i0 + max(-o, 0))
            if need_hi <= need_lo:
                continue
            w = _window(win, room[r], room[r + 1])
            if need_hi > made[r]:
                if need_hi - low[r] > room[r + 1] - room[r]:  # slid down: what is still to be gathered to the front
                    keep = min(need_lo, made[r])
                    _slide(w, keep - low[r], made[r] - keep)
                    low[r] = keep
                run_finite, run_top, n_log, run_picked = _make_springs(
                    x0, x1, x2, rest[s0:s0 + nr], live[s0:s0 + nr], fmax[s0:s0 + nr], inv_fmax[s0:s0 + nr],
                    own[s0:s0 + nr], k, w, low[r], made[r], need_hi, s0, i0, o, move, breaking, rule, load,
                    bp, log, n_log, step, law, flow, resin)
                finite = finite & run_finite
                top = max(top, run_top)
                picked = picked | run_picked
                made[r] = need_hi
            i_low, m = i0 + low[r], made[r] - low[r]  # the window as a run of its own
            _gather_forces(f0, w[0], i_low, o, m, lo, hi)
            _gather_forces(f1, w[1], i_low, o, m, lo, hi)
            _gather_forces(f2, w[2], i_low, o, m, lo, hi)
    return bad == 0, top, finite, n_log, picked


@inline
def _window(win, a, e):
    """Entries ``a .. e`` of each of the window buffers."""
    w0, w1, w2, wt, wl, wp = win
    return w0[a:e], w1[a:e], w2[a:e], wt[a:e], wl[a:e], wp[a:e]


@inline
def _slide(w, first, count):
    """Entries ``first .. first + count`` of each of a window's buffers moved to its front."""
    w0, w1, w2, wt, wl, wp = w
    for q in range(count):
        w0[q] = w0[first + q]
        w1[q] = w1[first + q]
        w2[q] = w2[first + q]
        wt[q] = wt[first + q]
        wl[q] = wl[first + q]
        wp[q] = wp[first + q]


@inline
def _make_springs(x0, x1, x2, rest, live, fmax, inv_fmax, own, k, w, low, lo, hi, s0, i0, o, loads, breaking,
                  rule, load, bp, log, n_log, step, law, flow, resin):
    """The springs ``lo .. hi`` of a run (``rest`` … ``own`` its fields) made into its window ``w``
    (which begins at spring ``low``), with the rule applied (``_run_forces``, ``_picked``).  Returns
    ``(tensions finite, largest load or -inf, log length, whether the rule picked a spring)``."""
    w0, w1, w2, wt, wl, wp = w
    log_id, log_step, log_t = log
    a, e, p, z = i0 + lo, i0 + hi, lo - low, hi - low
    finite, hit = _run_forces(x0[a:e], x1[a:e], x2[a:e], x0[a + o:e + o], x1[a + o:e + o], x2[a + o:e + o],
                              rest[lo:hi], live[lo:hi], fmax[lo:hi], inv_fmax[lo:hi], own[lo:hi], k, w0[p:z], w1[p:z],
                              w2[p:z], wt[p:z], wl[p:z], wp[p:z], loads, rule, load, bp, law, flow, resin)
    top = _largest_load(wl[p:z]) if loads else -np.inf
    picked = False
    if loads and hit:
        n_log, picked = _picked(live, s0, lo, hi, wp[p:z], wt[p:z], w0[p:z], w1[p:z], w2[p:z], breaking, log_id,
                                log_step, log_t, n_log, step)
    return finite, top, n_log, picked


@inline
def _moved(bases, q, anchor_x, anchor_y, c, b, hm, h, update, ip):
    """Base ``q`` moved by its total force (eq. 4: its springs' forces in f, used up and zeroed, its
    anchor at ``(anchor_x, anchor_y)`` and its own height, damping) through the integrator's update:
    its new position and velocity, not yet on the surface."""
    x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy = bases
    g0 = _base_force(f0[q], x0[q], anchor_x, v0[q], c, b)
    g1 = _base_force(f1[q], x1[q], anchor_y, v1[q], c, b)
    g2 = _base_force(f2[q], x2[q], az[q], v2[q], c, b)
    f0[q] = 0.0
    f1[q] = 0.0
    f2[q] = 0.0
    px, u0 = update(x0[q], v0[q], g0, hm, h, ip)
    py, u1 = update(x1[q], v1[q], g1, hm, h, ip)
    pz, u2 = update(x2[q], v2[q], g2, hm, h, ip)
    return px, py, pz, u0, u1, u2


@inline
def _base_pass(bases, to, c, b, hm, h, t, update, ip, radii, params, r_now, r_before, from_radius, heights, block,
               prev, save, base_block):
    """One step of every base on the spring forces in ``f`` (zeroed as consumed): the total force
    (eq. 4), the integrator's update, the surface constraint (eq. 9: radially onto the trunk, radial
    velocity removed), the anchors moved with the surface.  With a uniform radius, after a call's first
    step the anchors are ``r_before · direction`` (the last step's radius; written back once, at the end
    of the call — the very products, so the bits do not depend on where calls end); else each is placed
    at its own radius, every step (``_per_base_radius``, with the anchors' ``heights``).  Returns
    whether every coordinate stayed finite.

    A block of bases at a time (``base_block``: ``_uniform_block`` or ``_height_block``, the one the
    growth part's radius calls for, bound in the kernel's module so that only it is compiled), shared
    among threads in a parallel kernel, each block on slices of the vectors, one coordinate per
    vector, so its loops run in SIMD lanes.  With ``save`` the step can be taken back: with a uniform
    radius the bases are read from ``bases`` and their new positions and velocities written into
    ``to`` (the kernel's other buffer), which leaves ``bases`` as they were; with a radius that depends
    on height each block's positions, velocities and anchors are first copied into ``prev``, while
    the block is in cache, and moved in place (``to`` unused).  Without, the bases move in place."""
    n = bases[0].shape[0]
    block_bad = np.zeros(_blocks(n, block), np.int64)
    for blk in prange(_blocks(n, block)):
        block_bad[blk] = base_block(bases, to, blk * block, min(n, (blk + 1) * block), c, b, hm, h, t, update, ip,
                                    radii, params, r_now, r_before, from_radius, heights, prev, save)
    return block_bad.sum() == 0


@inline
def _uniform_block(bases, to, lo, hi, c, b, hm, h, t, update, ip, radii, params, r_now, r_before, from_radius,
                   heights, prev, save):
    """``_base_pass`` on the bases ``lo .. hi``, for a radius that does not depend on height (which
    leaves the anchors as they are until the call ends), into ``to`` with ``save``, else in place;
    returns how many went non-finite."""
    here = _slices(bases, lo, hi)
    if save:
        return _uniform_radius(here, _slices(to, lo, hi), c, b, hm, h, update, ip, r_now, r_before, from_radius)
    # in place, one set of slices: two views of the same vectors fail the compiler's run-time overlap check,
    # and the loop runs one base at a time
    return _uniform_radius(here, here, c, b, hm, h, update, ip, r_now, r_before, from_radius)


@inline
def _height_block(bases, to, lo, hi, c, b, hm, h, t, update, ip, radii, params, r_now, r_before, from_radius,
                  heights, prev, save):
    """``_base_pass`` on the bases ``lo .. hi``, for a radius that depends on height, in place (``to``
    unused: written into other vectors, its loops ran slower); returns how many went non-finite."""
    weights, stride, spans = heights
    x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy = bases
    if save:
        _copy_block((x0, x1, x2, v0, v1, v2, ax, ay, az), prev, lo, hi)
    return _per_base_radius(_slices(bases, lo, hi), c, b, hm, h, t, update, ip, radii, params, weights, stride, spans,
                            lo)


@inline
def _slices(bases, lo, hi):
    """The bases ``lo .. hi`` of the 14 base vectors."""
    x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy = bases
    return (x0[lo:hi], x1[lo:hi], x2[lo:hi], v0[lo:hi], v1[lo:hi], v2[lo:hi], f0[lo:hi], f1[lo:hi], f2[lo:hi],
            ax[lo:hi], ay[lo:hi], az[lo:hi], dx[lo:hi], dy[lo:hi])


@inline
def _uniform_radius(bases, to, c, b, hm, h, update, ip, r_now, r_before, from_radius):
    """``_base_pass`` on a block, for a radius that does not depend on height, from ``bases`` into
    ``to`` (the same slices, or another buffer's); returns how many bases went non-finite."""
    x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy = bases
    y0, y1, y2, w0, w1, w2 = to[0], to[1], to[2], to[3], to[4], to[5]
    # the anchors: r_before times the directions, or as they are (times 1.0: the same bits), chosen once, so
    # that the loop reads one vector an axis (a choice per base reads both, and a loop that writes vectors
    # other than those it reads then has too many to check for overlap to run in SIMD lanes)
    s, wx, wy = (r_before, dx, dy) if from_radius else (1.0, ax, ay)
    bad = 0
    for q in range(x0.shape[0]):
        px, py, pz, u0, u1, u2 = _moved(bases, q, s * wx[q], s * wy[q], c, b, hm, h, update, ip)
        r = r_now
        scale = _surface_scale(px, py, r)
        px *= scale
        py *= scale
        y0[q] = px
        y1[q] = py
        y2[q] = pz
        bad += not abs(px + py + pz) < np.inf  # NaN or inf in any coordinate shows here
        vr = _radial_speed(u0, u1, px, py, 1.0 / (r * r))
        w0[q] = u0 - vr * px
        w1[q] = u1 - vr * py
        w2[q] = u2
    return bad


@inline
def _per_base_radius(bases, c, b, hm, h, t, update, ip, radii, params, weights, stride, spans, first):
    """``_base_pass`` on a block (bases ``first ..``), for a radius that depends on height, in loops:
    the forces and the update (no calls: SIMD lanes), the radius at each base's height (the growth
    law's block form, its part's ``radii``, or its ``radius`` called per height), the
    surface at those radii (SIMD lanes again), then the anchors at their sites' radii.  The anchors'
    heights never change, so a part that gives ``weights`` has each anchor's radius as
    ``q[0] + w_0 q[1] + w_1 q[2] + ...`` with its weights ``w`` taken once (``_weighted_radii``:
    sums in SIMD lanes, the same bits as the call); with no weights
    (stride 0), the block form at the anchors' heights, from the same call as the bases' (its
    inlined copy, compiled once: the anchors' heights and radii are read only after the moves).
    Per base the same operations in the same order as one loop: the same bits.  Returns how many
    bases went non-finite."""
    x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy = bases
    n = x0.shape[0]
    for q in range(n):
        x0[q], x1[q], x2[q], v0[q], v1[q], v2[q] = _moved(bases, q, ax[q], ay[q], c, b, hm, h, update, ip)
    by_weights = stride > 0
    r_at = np.empty(n)  # each base's radius at its height; then, without weights, each anchor's (into ax)
    for side in range(1 if by_weights else 2):  # one call of the block form, so that it is compiled once
        z, out = (x2, r_at) if side == 0 else (az, ax)
        radii(t, z, params, out)
    bad = 0
    for q in range(n):
        px, py, pz = x0[q], x1[q], x2[q]
        r = r_at[q]
        scale = _surface_scale(px, py, r)
        px *= scale
        py *= scale
        x0[q] = px
        x1[q] = py
        bad += not abs(px + py + pz) < np.inf  # NaN or inf in any coordinate shows here
        vr = _radial_speed(v0[q], v1[q], px, py, 1.0 / (r * r))
        v0[q] = v0[q] - vr * px
        v1[q] = v1[q] - vr * py
    if by_weights:  # ax holds each anchor's radius while it is summed
        _weighted_radii(ax, params, weights, stride, spans, first)
    for q in range(n):
        ra = ax[q]
        ax[q] = ra * dx[q]
        ay[q] = ra * dy[q]
    return bad


@inline
def _weighted_radii(out, q, weights, stride, spans, first):
    """The radii ``q[0] + w_0 q[1] + w_1 q[2] + ...`` of the bases ``first .. first + len(out)`` into
    ``out``, their weights taken once (``weights``: weight k of base i at ``k·stride + i``), added
    term by term in SIMD lanes — each term only over the bases from its first weight that is not 0 to
    its last (``spans[2k] .. spans[2k + 1]``, ``_Weights.spans``: a bulge reaches a band of heights).
    Elsewhere its weight is 0, and ``r + 0·q`` is ``r`` to the bit for a finite ``q`` and an ``r``
    that is not −0 (no sum that begins at a ``q[0]`` other than 0 is −0): where ``q[0]`` is 0 or
    a term's ``q`` is not finite, every base takes that term, as a sum over all does."""
    n = out.shape[0]
    for i in range(n):
        out[i] = q[0]
    spanned = q[0] != 0.0
    for term in range(weights.shape[0] // stride):
        coefficient = q[1 + term]
        lo, hi = 0, n
        if spanned and abs(coefficient) < np.inf:  # only where the term's weights are not 0
            lo = min(n, max(0, spans[2 * term] - first))
            hi = max(lo, min(n, spans[2 * term + 1] - first))
        w = weights[term * stride + first + lo:term * stride + first + hi]
        for i in range(hi - lo):
            out[lo + i] = out[lo + i] + w[i] * coefficient


@inline
def _step_of(size, h_min, m, over, halvings, levels):
    """The step of ``size`` ticks of ``h_min``: ``(h, h / m``, the largest load it accepts and the
    largest it reports at: ``limits``)."""
    h = size * h_min
    accept_load, report_load = _limits(over, halvings, levels)
    return h, h / m, accept_load, report_load


@inline
def _steps_kernel(bases, runs, work, rest, fmax, inv_fmax, own, live, constants, ends, clock, params, bp, ip, rp, flags,
                  log, heights, start, update, rule, load, radius, prepare, radii, law, flow, step_pass, base_block,
                  uniform):
    """Up to ``len(ends)`` whole steps in one call (see ``Plan``), on the clock ``clock`` (``Plan.clock``:
    it doubles a halved step where ``kernels.doubles`` says, and leaves in ``clock`` the ticks and
    halvings it ends with; ``ends`` receives each kept step's end in ticks).  Returns ``(steps taken, largest
    load of the last step, length of the break log, whether the rule named a candidate in the last
    step, whether that step was refused and taken back here, whether it was refused)``, the load
    NaN if that step went non-finite.  ``rule`` and ``load`` are the breaker
    part's (its numbers ``bp``), ``update`` the integrator part's (its numbers ``ip``), ``radius``,
    ``prepare`` and ``radii`` the growth part's (its numbers ``params``), ``law`` and ``flow`` the
    resin's (its numbers ``rp``); ``step_pass`` how a step's passes go (``_step_fused`` on one thread,
    ``_step_split``); ``uniform`` whether the growth part's radius is the same at every height, and
    ``base_block`` the base pass that follows from it (``_uniform_block``, ``_height_block``): both
    constants of the kernel's module, so that numba compiles only the branches they take.

    The spring pass that finds a step's loads also accumulates the next step's spring forces into
    ``f`` (first same as last), through the same function as the fresh pass at the start of the
    call, so the result does not depend on where calls begin and end.  That pass makes the forces of
    the bases from ``fresh`` on (0: all); the others' are taken from ``f`` as the last call left them
    — when ``kept >= 0`` and the positions of the first ``kept`` bases are still those the last call
    ended with (kept in ``start``: compared here, to the bit), which the backend knows to be all that
    can have changed (``_NumbaCall``: ``kept`` and ``fresh``); else all are made again.

    ``start`` also keeps the positions, velocities and anchors this call begins from (an undone
    step is replayed from them), and, when the last step is accepted, receives the positions it ends
    with (for the next call's comparison).  Where adaptive stepping may refuse a step, the resin does
    not flow and the radius is uniform or the call may take more than ``IN_PLACE_STEPS`` steps, a
    refused step is taken back here (its breaks undone) instead of by a replay of the call.
    ``start``'s vectors from the tenth on then serve: with a uniform radius, its first six are the
    second of two buffers of positions and velocities (``_joined``), each step read from one and
    written into the other and taken when it is kept, a refused one taken back by not taking it,
    and a call that ends in the second buffer copies it into the state's vectors; with a radius
    that depends on height, they receive each step's bases (and anchors) before it moves them in
    place, and a refused step is copied back from them (``_take_back``).  Where the step may still
    be halved it is halved and the call goes on, the forces of the bases made again by the pass
    that begins a call; else the call ends, its steps those before it (the forces in ``f`` are then
    the refused step's, and the next call makes them again).

    ``constants`` ends with the patch-count stop's goal and least patch (``Plan.patch_goal``, 0:
    none): after a kept step at which the call's breaks reach ``break_budget``, the patches the live
    springs make are counted here (``_patch_count``) and, while fewer than the goal, the budget
    grows by as many breaks as are missing (each adds at most one patch), so the call goes on where
    Python would only count and call again; it ends at the step where the goal is reached."""
    x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy = bases
    f = (f0, f1, f2)
    k, c, b, m, h_min, over, t_limit, max_batch, break_budget, patch_goal, min_size = constants
    breaking, fresh, block, kept, evolve = flags
    ticks, halvings, levels, may_double = clock[0], clock[1], clock[2], clock[3] != 0
    size = 1 << (levels - halvings)
    h, hm, accept_load, report_load = _step_of(size, h_min, m, over, halvings, levels)
    log_id, log_step, log_t = log
    # a step adaptive stepping may refuse is taken back here (a resin that flows changes its springs too: that
    # call is replayed from its start by the caller instead): with a uniform radius by not taking it (each step
    # written into the other of two buffers), else, in calls long enough to pay for it, from a copy of the
    # bases before it
    in_place = over < np.inf and levels > 0 and not evolve and (uniform or ends.shape[0] > IN_PLACE_STEPS)
    apart = in_place and uniform  # two buffers
    prev = (start[9], start[10], start[11], start[12], start[13], start[14], start[15], start[16], start[17])
    here = (x0, x1, x2, v0, v1, v2)  # the state's positions and velocities
    cur = here  # the buffer holding them now
    nxt = prev[:6] if apart else here  # the one a step writes into
    flipped = False  # whether the state is in the other buffer
    if not _kept_and_started(bases, start, kept, block):
        fresh = 0
    remake = fresh < x0.shape[0]  # the forces of the bases from ``fresh`` on made again, in the loop (one place)
    top = -np.inf  # every step's largest load, found by its pass: the last one's is the call's
    finite = True
    done = 0
    n_log = 0
    before = 0
    r_before = 0.0
    r_kept = 0.0
    picked = False
    undone = False
    kept_step = False
    tried = 0
    t = 0.0
    while done < ends.shape[0]:
        step = not remake
        if remake:  # the forces of the bases as they are (at the call's start, or after a step taken back): the
            f0[fresh:] = 0.0  # step's spring pass without its base pass, its loads or its breaks
            f1[fresh:] = 0.0
            f2[fresh:] = 0.0
        t = (ticks + size) * h_min  # the clock's time (``Clock.times``)
        q = prepare(t, params)  # the growth law's time-only part, once a step
        r_now = radius(t, 0.0, q) if uniform else 0.0
        before = n_log
        from_radius = uniform and done > 0  # (outside the call: numba takes no branch among its arguments)
        resin = (rp, h, evolve and step)
        motion = (c, b, hm, h, t, ip, q, r_now, r_before, from_radius)
        now = _joined(cur, bases)
        finite, top, springs_finite, n_log, picked = step_pass(  # one place for it, so that it is compiled once
            now, _joined(nxt, bases) if step else now, runs, rest, k, live, fmax, inv_fmax, own, work, step,
            0 if step else fresh, motion, update, radii, heights, block, prev, in_place, breaking, rule, load, bp, log,
            n_log, done + 1, law, flow, resin, base_block)
        if remake:
            remake = False
            continue
        r_kept = r_before
        r_before = r_now
        finite = finite and springs_finite
        tried = 1
        kept_step = finite and top <= accept_load
        double = kept_step and _doubles(halvings, top, ticks + size, size)
        if kept_step:
            ticks += size
            ends[done] = ticks
            done += 1
            tried = 0
            if apart:  # the step taken: the buffer it was written into holds the state
                cur, nxt = nxt, cur
                flipped = not flipped
        elif in_place:  # refused: the step taken back (its breaks undone)
            if apart:  # by not taking the buffer it was written into
                for spring in log_id[before:n_log]:
                    live[spring] = True
            else:  # from the copy of the bases before it
                _take_back(prev, (x0, x1, x2, v0, v1, v2, ax, ay, az), live, log_id[before:n_log])
            n_log = before
            r_before = r_kept
            undone, tried = True, 0
            if halvings < levels:  # halved and taken again in this call (``Clock.halve``): its forces made again
                halvings += 1
                size //= 2
                h, hm, accept_load, report_load = _step_of(size, h_min, m, over, halvings, levels)
                remake, undone, fresh = True, False, 0
                continue
        if kept_step and patch_goal > 0 and n_log >= break_budget and n_log > before:
            have = _patch_count(runs, live, x0.shape[0], min_size)  # the patch-count stop may hold: counted
            if have < patch_goal:  # here, and while it does not, the call goes on to the breaks that may reach it
                break_budget = n_log + patch_goal - have
        stop = _ends_call(finite, top, accept_load, report_load, picked, n_log - before, n_log, break_budget,
                          max_batch, t >= t_limit or double and not may_double)
        if double:  # the clock doubles the step, for this call or the next
            halvings -= 1
            size *= 2
            h, hm, accept_load, report_load = _step_of(size, h_min, m, over, halvings, levels)
        if stop:
            break
    done += tried  # a refused last step the state still holds counts (the caller replays the call to it)
    clock[0], clock[1] = ticks, halvings
    if flipped:  # the state in the other buffer: into the state's vectors
        _copy_blocks(cur, here, 0, block)
    if uniform and done > 0:  # the anchors at the last step's radius (the same products as above)
        for q in range(ax.shape[0]):
            ax[q] = r_before * dx[q]
            ay[q] = r_before * dy[q]
    if kept_step:  # accepted: the positions the next call compares
        _copy_blocks((x0, x1, x2), start[:3], 0, block)
    return done, (top if finite else np.nan), n_log, picked and finite and not undone, undone, not kept_step


@inline
def _kept_and_started(bases, start, kept, block):
    """Whether the first ``kept`` bases' positions are those in ``start`` (``kept < 0``: not known),
    to the bit; and ``start`` made the state this call begins from: its velocities and anchors copied
    in the same pass over blocks of bases as the comparison, then the positions not already there."""
    x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy = bases
    n = x0.shape[0]
    block_same = np.ones(_blocks(n, block), np.bool_)
    for blk in prange(_blocks(n, block)):
        lo, hi = blk * block, min(n, (blk + 1) * block)
        same = True
        top = min(hi, max(kept, lo))
        s0, s1, s2 = start[0][lo:top], start[1][lo:top], start[2][lo:top]
        p0, p1, p2 = x0[lo:top], x1[lo:top], x2[lo:top]
        for q in range(top - lo):
            same = same & (s0[q] == p0[q]) & (s1[q] == p1[q]) & (s2[q] == p2[q])
        block_same[blk] = same
        _copy_block((v0, v1, v2, ax, ay, az), start[3:], lo, hi)
    same = kept >= 0
    for blk in range(block_same.shape[0]):
        same = same & block_same[blk]
    _copy_blocks((x0, x1, x2), start[:3], kept if same else 0, block)
    return same


@inline
def _joined(xv, bases):
    """The 14 base vectors ``bases`` with the positions and velocities of the buffer ``xv``."""
    x0, x1, x2, v0, v1, v2, f0, f1, f2, ax, ay, az, dx, dy = bases
    return (xv[0], xv[1], xv[2], xv[3], xv[4], xv[5], f0, f1, f2, ax, ay, az, dx, dy)


@jit
def _take_back(prev, bases, live, broke):
    """A refused step taken back: the bases from ``prev`` (as the base pass saved them) and the
    springs it broke (``broke``) intact again.  Compiled once for every kernel (not inlined)."""
    _copy_block(prev, bases, 0, bases[0].shape[0])
    for s in broke:
        live[s] = True


@jit
def _copy_block(source, target, lo, hi):
    """Entries ``lo .. hi`` of the vectors ``source`` into ``target``.  Compiled once for every kernel
    (not inlined into each: their compile time)."""
    for v in range(len(source)):  # a loop, not a slice assignment: numba's generic setitem compiles slowly
        s, t = source[v][lo:hi], target[v][lo:hi]
        for q in range(s.shape[0]):  # from 0: no negative index to wrap, so a vector copy
            t[q] = s[q]


@inline
def _copy_blocks(source, target, first, block):
    """The vectors ``source`` into ``target`` from entry ``first`` on, a block at a time."""
    n = source[0].shape[0]
    for blk in prange(_blocks(n, block)):
        _copy_block(source, target, max(first, blk * block), min(n, (blk + 1) * block))


# -- one wrapper per combination of parts, generated and cached -----------------------------------

_WRAPPER = '''"""Generated by bark: its stepping kernel specialised for {names}.  Safe to delete."""
import numba
from bark.engine.kernels.numba_backend import _no_flow, _no_load, each_height, inline
{imports}
_update = inline({update})
_rule_part = inline({rule})
_load_part = {load}
_radius = inline({radius})
{prepare}
_radii = {radii}
_law_part = inline({law})
_flow_part = {flow}
{adapters}
{resin}

# the kernel's source, its parts' functions bound by name (compiled as written, not inlined into a wrapper)
import numpy as np
from bark.engine.kernels.numba_backend import {kernel_names}
update, rule, load, radius, prepare, radii, law, flow = _update, _rule, _load, _radius, _prepare, _radii, _law, _flow
from bark.engine.kernels.numba_backend import {step_pass} as step_pass  # how a step's passes go
from bark.engine.kernels.numba_backend import {base_block} as base_block  # the base pass the radius calls for
uniform = {uniform}  # the growth part's radius is the same at every height


@numba.njit(cache=True, nogil=True, error_model="numpy", parallel={parallel})
KERNEL
'''

_ADAPTERS = '''

@inline
def _rule(tension, length, rest, fmax, inv_fmax, own, q, params):
    return _rule_part({rule_args})
{load}'''
_LOAD_ADAPTER = '''

@inline
def _load(tension, length, rest, fmax, inv_fmax, own, q, params):
    return _load_part({load_args})
'''


_RESIN = '''

@inline
def _law(length, rest, own, q, k, params):
    return _law_part(length, rest[q], k, {law_args})
{flow}'''
_FLOW = '''

@inline
def _flow(length, rest, own, q, h, params):
    new = _flow_part(length, rest[q], h, {law_args})
{stores}
'''


_COMPOSED = '''_inner_time = inline({inner_time})
_inner_radius = inline({inner_radius})
_time_part = inline({time})


@inline
def _prepare(t, params):
    return _time_part(t, params, _inner_time, _inner_radius)
'''


def _time_of(growth):
    """The growth part's per-step function as the kernel calls it, ``prepare(t, params) -> q``,
    compiled in this process: its ``time``, given its inner part's functions when it has one."""
    if growth.inner is None:
        return inline(growth.time)
    time_part, inner_time, inner_radius = (inline(fn) for fn in (growth.time, growth.inner.time, growth.inner.radius))

    @inline
    def prepare(t, params):
        return time_part(t, params, inner_time, inner_radius)

    return prepare


def _adapters(part, columns: tuple[str, ...]) -> str:
    """The source of ``_rule`` and ``_load``: the kernel's per-spring signature ``(tension, length,
    rest, fmax, inv_fmax, own, q, params)`` passed on as the breaker part reads it (``_rule_part``
    and ``_load_part`` its functions), a declared field as its column of ``own`` (``columns``: the
    declared per-spring fields in the frame's order); ``_load = _no_load`` for a part without one."""
    def args(reads) -> str:
        return ", ".join((*(f"own[q, {columns.index(r)}]" if r in columns else r for r in reads), "params"))

    load = "\n_load = _no_load\n" if part.load is None else _LOAD_ADAPTER.format(load_args=args(part.load_reads))
    return _ADAPTERS.format(rule_args=args(part.reads), load=load)


def _resin_adapters(part, columns: tuple[str, ...]) -> str:
    """The source of ``_law`` and ``_flow``: the kernel's per-spring resin calls ``(length, rest,
    own, q, k or h, params)`` passed on as the resin part reads its fields (``_law_part``,
    ``_flow_part`` its functions), its flow's values stored into ``rest`` and its ``own`` columns;
    ``_flow = _no_flow`` for a law that does not flow."""
    def at(name: str) -> str:
        return "rest[q]" if name == "rest" else f"own[q, {columns.index(name)}]"

    law_args = ", ".join((*(at(r) for r in part.reads), "params"))
    if part.evolve is None:
        return _RESIN.format(law_args=law_args, flow="\n_flow = _no_flow\n")
    stores = "\n".join(f"    {at(name)} = new[{i}]" for i, name in enumerate(part.writes))
    return _RESIN.format(law_args=law_args, flow=_FLOW.format(law_args=law_args, stores=stores))


def resin_adapted(part, columns: tuple[str, ...] = ()):
    """The resin part's law and flow as the kernel calls them (inlined where called), compiled here."""
    _make_jitable([h for fn in (part.tension, part.evolve) if fn is not None for h in _helpers(fn)[1:]])
    scope = {"inline": inline, "_no_flow": _no_flow, "_law_part": inline(part.tension),
             "_flow_part": None if part.evolve is None else inline(part.evolve)}
    exec(_resin_adapters(part, columns), scope)
    return scope["_law"], scope["_flow"]


def resin_on_springs(part, columns: tuple[str, ...] = ()):
    """``evaluate(length, rest, k, h, own) -> (tension, flowed rest, flowed own)``: the resin part's
    law and flow at each spring, compiled as the stepping kernel compiles them (for the contract kit)."""
    law, flow = resin_adapted(part, columns)
    params = part.params

    @numba.njit(error_model="numpy")
    def each(length, rest, k, h, own, params, out):
        for q in range(length.shape[0]):
            out[q] = law(length[q], rest, own, q, k, params)
            flow(length[q], rest, own, q, h, params)

    def evaluate(length, rest, k, h, own=None):
        rest = np.array(rest, dtype=float)
        own = np.zeros((len(rest), 0)) if own is None else np.array(own, dtype=float)
        out = np.empty(len(rest))
        each(np.ascontiguousarray(length, dtype=float), rest, float(k), float(h), own, params, out)
        return out, rest, own

    return evaluate


_SPECIALIZED: dict[tuple, object] = {}


def _importable(fn) -> tuple[str, str] | None:
    """``(module, qualname)`` by which ``fn`` can be imported, or ``None`` (a lambda, a local function)."""
    module, qualname = getattr(fn, "__module__", None), getattr(fn, "__qualname__", "")
    if not module or "<" in qualname or module == "__main__":
        return None
    return module, qualname


def _source(fn) -> str:
    try:
        return inspect.getsource(fn)
    except (OSError, TypeError):
        return repr(fn)


def cache_dir() -> Path:
    """Where generated kernels live: ``kernels`` in bark's cache folder (``numba_env.cache_dir``;
    numba caches their compiled code beside them)."""
    return numba_env.cache_dir() / "kernels"


_JITABLE: set = set()


def _helpers(fn, seen=None) -> list:
    """``fn`` and the plain Python functions it calls through its module's globals, transitively:
    what numba must be able to compile inside it."""
    seen = [] if seen is None else seen
    if fn in seen:
        return seen
    seen.append(fn)
    code, scope = getattr(fn, "__code__", None), getattr(fn, "__globals__", {})
    for name in code.co_names if code is not None else ():
        obj = scope.get(name)
        if inspect.isfunction(obj) and not isinstance(obj, numba.core.dispatcher.Dispatcher):
            _helpers(obj, seen)
    return seen


def _make_jitable(functions) -> None:
    """Let compiled code call these plain functions (``register_jitable``): a plugin's part
    may call its own helpers without importing numba.  They are inlined where called, as the compiled
    forms themselves are: a call per base and step otherwise costs more than the helper (measured
    on a bulge's profile)."""
    for fn in functions:
        if fn not in _JITABLE:
            numba.extending.register_jitable(inline="always")(fn)
            _JITABLE.add(fn)


def each_height(radius):
    """The block form (a growth part's ``radii``) of a part that gives none: its
    ``radius`` called for each height."""
    def radii(t, z, q, out):
        for i in range(z.shape[0]):
            out[i] = radius(t, z[i], q)
    return inline(radii)


def adapted(part, columns: tuple[str, ...] = ()):
    """The breaker part's rule and load as the kernel calls them, ``(tension, length, rest, fmax,
    inv_fmax, own, q, params)`` (inlined where called), compiled in this process."""
    _make_jitable([h for fn in (part.rule, part.load) if fn is not None for h in _helpers(fn)[1:]])
    scope = {"inline": inline, "_no_load": _no_load, "_rule_part": inline(part.rule),
             "_load_part": None if part.load is None else inline(part.load)}
    exec(_adapters(part, columns), scope)
    return scope["_rule"], scope["_load"]


def part_on_springs(part, columns: tuple[str, ...] = ()):
    """``evaluate(tension, length, rest, fmax, inv_fmax, own) -> (picked, load)``: the part's rule
    and load at each spring of the arrays (``own``: the declared fields ``columns``, a column each),
    compiled as the stepping kernel compiles them (the contract kit holds them against the part's
    functions on whole arrays, ``bark.testing``)."""
    rule, load = adapted(part, columns)
    params = part.params

    @numba.njit(error_model="numpy")
    def each(tension, length, rest, fmax, inv_fmax, own, params, picked, loads):
        for q in range(tension.shape[0]):
            picked[q] = rule(tension[q], length[q], rest[q], fmax[q], inv_fmax[q], own, q, params)
            loads[q] = load(tension[q], length[q], rest[q], fmax[q], inv_fmax[q], own, q, params)

    def evaluate(tension, length, rest, fmax, inv_fmax, own=None):
        own = np.zeros((len(tension), 0)) if own is None else np.ascontiguousarray(own, dtype=float)
        picked, loads = np.zeros(len(tension), np.bool_), np.empty(len(tension))
        each(*(np.ascontiguousarray(a, dtype=float) for a in (tension, length, rest, fmax, inv_fmax)), own, params,
             picked, loads)
        return picked, loads

    return evaluate


def radius_at_heights(growth):
    """``evaluate(t, z) -> r``: a growth part's radius at each height of ``z``, its per-step part
    taken once, compiled as the stepping kernel compiles them (for the contract kit)."""
    _make_jitable([h for fn in growth.functions for h in _helpers(fn)[1:]])
    g, p = inline(growth.radius), _time_of(growth)
    uniform = growth.uniform

    @numba.njit(error_model="numpy")
    def each(t, z, params, out):
        q = p(t, params)
        for i in range(z.shape[0]):
            out[i] = g(t, 0.0 if uniform else z[i], q)

    def evaluate(t, z):
        z = np.ascontiguousarray(z, dtype=float)
        out = np.empty(z.shape[0])
        each(float(t), z, growth.params, out)
        return out

    return evaluate


def update_on_axis(part):
    """``evaluate(x, v, f, hm, h) -> (x, v)``: an integrator part's update at each entry, compiled as
    the stepping kernel compiles it (for the contract kit)."""
    u = inline(part.update)
    _make_jitable(_helpers(part.update)[1:])

    @numba.njit(error_model="numpy")
    def each(x, v, f, hm, h, ip, x_out, v_out):
        for i in range(x.shape[0]):
            x_out[i], v_out[i] = u(x[i], v[i], f[i], hm, h, ip)

    def evaluate(x, v, f, hm, h):
        x, v, f = (np.ascontiguousarray(a, dtype=float) for a in (x, v, f))
        x_out, v_out = np.empty_like(x), np.empty_like(v)
        each(x, v, f, float(hm), float(h), part.params, x_out, v_out)
        return x_out, v_out

    return evaluate


_BY_PARTS: dict[tuple, tuple] = {}
"""The kernel of the last combinations of part objects seen (at most ``BY_PARTS_KEPT``), by their
identities (a strategy makes its part once): a call finds its kernel without building the
combination's key again (:func:`_combination` walks every part's helpers).  Bounded: a fit's worker
makes new parts for every run, and each entry keeps its parts alive."""
BY_PARTS_KEPT = 16


def specialized(integrator, breaker, growth, parallel=False, columns: tuple[str, ...] = (), resin=None):
    """:func:`_specialized`, found by the parts' identities after the first time."""
    ids = _ids(integrator, breaker, growth, resin, parallel, columns)
    seen = _BY_PARTS.get(ids)
    if _same_parts(seen, (integrator, breaker, growth, resin)):
        return seen[4]
    kernel = _specialized(integrator, breaker, growth, parallel, columns, resin)
    while len(_BY_PARTS) >= BY_PARTS_KEPT:  # the oldest goes
        del _BY_PARTS[next(iter(_BY_PARTS))]
    _BY_PARTS[ids] = (integrator, breaker, growth, resin, kernel)  # the parts kept: their ids stay theirs
    return kernel


def _ids(integrator, breaker, growth, resin, parallel, columns) -> tuple:
    """What ``_BY_PARTS`` and ``_WAITING`` key on: the parts' identities, the threads, the columns."""
    return id(integrator), id(breaker), id(growth), id(resin), bool(parallel), tuple(columns)


def _same_parts(entry: tuple | None, parts: tuple) -> bool:
    """Whether ``entry`` (of ``_BY_PARTS`` or ``_WAITING``, found by the parts' ids) holds these very
    parts: an id is another object's once its own is gone."""
    return entry is not None and all(a is b for a, b in zip(entry[:len(parts)], parts))


def _specialized(integrator, breaker, growth, parallel=False, columns: tuple[str, ...] = (), resin=None):
    """The stepping kernel with the integrator part's ``update`` (``integrator``, an
    :class:`~bark.contract.parts.IntegratorPart`), the breaker part's rule and load (``breaker``, a
    :class:`~bark.contract.parts.BreakerPart`) and the growth part's functions (``growth``, a
    :class:`~bark.contract.parts.GrowthPart`: its radius, its per-step ``time`` — given its inner
    part's functions when it has one — and its block form, or its radius per height) inlined
    (compiled once per combination and kept on disk; see the module's docstring), its block loops
    shared among threads if ``parallel``, the breaker and the resin law (``resin``, a
    :class:`~bark.contract.parts.ResinPart`; the paper's spring by default) reading the declared
    per-spring fields by their ``columns`` of the frame's ``own``.  Functions that cannot be imported
    by name (lambdas, local functions) get a wrapper compiled in this process only."""
    combination = _combination(integrator, breaker, growth, parallel, columns, resin)
    key = combination.key
    if key in _SPECIALIZED:
        return _SPECIALIZED[key]
    resin, columns = combination.resin, key[4]
    if not combination.importable:
        u, g = inline(integrator.update), inline(growth.radius)
        p = _time_of(growth)
        block = each_height(g) if growth.radii is None else inline(growth.radii)
        rule, load = adapted(breaker, columns)
        law, flow = resin_adapted(resin, columns)
        step_pass = _step_split if parallel else _step_fused
        uniform = bool(growth.uniform)
        base_block = _uniform_block if uniform else _height_block

        @numba.njit(nogil=True, error_model="numpy", parallel=bool(parallel))
        def steps(bases, runs, work, rest, fmax, inv_fmax, own, live, constants, ends, clock, params, bp, ip, rp, flags,
                  log, heights, start):
            return _steps_kernel(bases, runs, work, rest, fmax, inv_fmax, own, live, constants, ends, clock, params, bp,
                                 ip, rp, flags, log, heights, start, u, rule, load, g, p, block, law, flow, step_pass,
                                 base_block, uniform)

        _SPECIALIZED[key] = steps
        return steps
    path = _write_once(*combination.file())
    first = not _compiled_before(path)
    kind = "threaded" if parallel else "serial"
    if first:
        LOG.info(f"compiling the {'threaded ' if parallel else ''}stepping kernel for {integrator.update.__name__}, "
                 f"{breaker.rule.__name__} and {growth.radius.__name__} (once, {_how_long(kind)}: later runs load it "
                 f"from {str(path.parent)!r})")
    _SPECIALIZED[key] = steps = _load_generated(path).steps
    if first:
        _FIRST_CALL[steps] = (path, kind)
    return steps


def compile_record() -> Path:
    """The file that keeps how long the last first compile of each kind of kernel (``serial``,
    ``threaded``) took on this machine, in seconds (in the kernels' cache folder): what the notice
    of the next one says it will take."""
    return cache_dir() / "compile-seconds.json"


_FIRST_CALL: dict = {}
"""Kernels loaded but not compiled yet (numba compiles them at their first call), with their kind
and generated module: their first call goes through :func:`_compile_alone`."""


def _compile_alone(path: Path, kind: str, make: Callable):
    """``make()`` — the compile of the generated module ``path``'s kernel (a ``kind`` one), or its
    first call, which compiles it — alone: where another process compiles the same kernel (a sweep's
    workers starting together), after it, then loaded from numba's cache (``numba_alongside.alone``);
    and timed, for the next notice (:func:`record_compile`), unless it was loaded.  Its result."""
    with numba_alongside.alone(path):
        meanwhile = _compiled_before(path)
        t0 = time.perf_counter()
        result = make()
        if not meanwhile:
            record_compile(kind, time.perf_counter() - t0)
    return result


def compile_seconds() -> dict[str, float]:
    """The seconds the last first compile of each kind of kernel took here (:func:`compile_record`);
    none where the file is missing, damaged or cannot be read (an estimate, never an error)."""
    try:
        held = json.loads(compile_record().read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(held, dict):
        return {}
    return {kind: float(held[kind]) for kind in ("serial", "threaded")
            if isinstance(held.get(kind), (int, float)) and not isinstance(held[kind], bool)
            and math.isfinite(held[kind]) and held[kind] > 0}


def record_compile(kind: str, seconds: float, at_least: bool = False) -> None:
    """Keep ``seconds`` as the last first compile of a ``kind`` kernel here (``at_least``: only if
    the record is shorter — a compile ended unfinished took longer); a cache folder that cannot be
    written keeps nothing (an estimate is not worth a warning)."""
    if not (math.isfinite(seconds) and seconds > 0) or at_least and compile_seconds().get(kind, 0.0) >= seconds:
        return
    with contextlib.suppress(OSError, ValueError):
        compile_record().parent.mkdir(parents=True, exist_ok=True)
        _write_atomically(compile_record(), json.dumps({**compile_seconds(), kind: max(0.1, round(seconds, 1))}))


def _how_long(kind: str) -> str:
    """What the notice of a compile says of its length: the last one of its kind here, or a range."""
    last = compile_seconds().get(kind)
    if last is None:
        return "tens of seconds" if kind == "serial" else "minutes"
    return f"about {max(1, round(last))} s here the last time"


def _load_generated(path: Path):
    """The generated module ``path``, imported by its file (and named in ``sys.modules``)."""
    name = path.stem
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@attrs.frozen
class _Combination:
    """A combination of parts as its kernel is found: its ``key`` (what ``_SPECIALIZED`` keys on), the
    functions it inlines by role (``named``), their ``helpers`` (made jitable), the name each is
    imported by (``names``; ``None``: it cannot be), and the parts (``resin``: the paper's spring where
    none is given)."""

    key: tuple
    named: dict
    helpers: list
    names: dict
    breaker: object
    growth: object
    resin: object
    parallel: bool

    @property
    def importable(self) -> bool:
        """Whether its functions can all be imported by name (else compiled in each process, no file)."""
        return None not in self.names.values()

    def file(self) -> tuple[str, str]:
        """Its generated module's name and text (:func:`_wrapper`); only where it is importable."""
        return _wrapper(self)


def _combination(integrator, breaker, growth, parallel, columns, resin) -> _Combination:
    """These parts' :class:`_Combination`."""
    inner = growth.inner
    resin = HOOKEAN if resin is None else resin
    named = {"update": integrator.update, "rule": breaker.rule, "radius": growth.radius, "time": growth.time,
             "load": breaker.load, "radii": growth.radii, "law": resin.tension, "flow": resin.evolve,
             "inner_time": inner.time if inner is not None else None,
             "inner_radius": inner.radius if inner is not None else None}
    named = {k: fn for k, fn in named.items() if fn is not None}
    columns = tuple(columns)
    if not set(columns) & {*breaker.reads, *breaker.load_reads, *resin.reads, *resin.writes}:
        columns = ()  # it reads no declared field: one kernel, whatever fields the state carries
    key = (breaker.reads, breaker.load_reads, resin.reads, resin.writes, columns, *named.items(), bool(parallel),
           bool(growth.uniform))
    helpers = [h for fn in named.values() for h in _helpers(fn)[1:]]
    _make_jitable(helpers)
    return _Combination(key, named, helpers, {k: _importable(fn) for k, fn in named.items()}, breaker, growth, resin,
                        bool(parallel))


def _wrapper(combination: _Combination) -> tuple[str, str]:
    """The generated module's name and text for a combination of parts: named by a digest of
    everything its compiled code depends on (numba's version, the sources), so that a change
    compiles it again."""
    named, helpers, names, parallel = combination.named, combination.helpers, combination.names, combination.parallel
    resin, columns, inner = combination.resin, combination.key[4], combination.growth.inner
    uniform = bool(combination.growth.uniform)
    adapters = _adapters(combination.breaker, columns)
    resin_text = _resin_adapters(resin, columns)
    digest = hashlib.sha256()
    for piece in (numba.__version__, _source(sys.modules[__name__]), _source(physics), _source(ends_call),
                  *(_source(fn) for fn in named.values()), *(_source(fn) for fn in helpers),
                  *(f"{k}={m}:{q}" for k, (m, q) in names.items()), adapters, resin_text, f"parallel={bool(parallel)}",
                  f"uniform={uniform}"):
        digest.update(piece.encode())
    imports, refs = [], {}
    for i, (k, (module, qualname)) in enumerate(names.items()):
        head, _, rest = qualname.partition(".")
        imports.append(f"from {module} import {head} as _f{i}")
        refs[k] = f"_f{i}" + (f".{rest}" if rest else "")
    prepare = f"_prepare = inline({refs['time']})" if inner is None else \
        _COMPOSED.format(inner_time=refs["inner_time"], inner_radius=refs["inner_radius"], time=refs["time"])
    text = _WRAPPER.format(names=", ".join(f"{m}.{q}" for m, q in names.values()), imports="\n".join(imports),
                           update=refs["update"], rule=refs["rule"], radius=refs["radius"], prepare=prepare,
                           load=f"inline({refs['load']})" if "load" in refs else "None",
                           radii="each_height(_radius)" if "radii" not in refs else f"inline({refs['radii']})",
                           adapters=adapters, parallel=bool(parallel), law=refs["law"],
                           flow=f"inline({refs['flow']})" if "flow" in refs else "None", resin=resin_text,
                           kernel_names=_kernel_names(),
                           step_pass="_step_split" if parallel else "_step_fused", uniform=uniform,
                           base_block="_uniform_block" if uniform else "_height_block")
    name = f"bark_steps_{digest.hexdigest()[:20]}"
    return name, text.replace("KERNEL", _kernel_source())


_PARTS = ("update", "rule", "load", "radius", "prepare", "radii", "law", "flow", "step_pass", "base_block", "uniform")
"""The kernel's last parameters, which a generated module binds by name: the parts' functions, how a
step's passes go (``_step_fused`` on one thread, ``_step_split``) and whether the radius is uniform,
with the base pass that calls for (``_uniform_block``, ``_height_block``): only those writings are
compiled into the kernel."""


def _kernel_source() -> str:
    """``_steps_kernel``'s source as the generated module's ``steps``: its parameters before the parts'
    functions (:data:`_PARTS`), which that module binds as globals.  numba then compiles the kernel
    itself, not a copy of its whole body inlined into a wrapper that passes the functions in (the
    copy, and every pass run again over it, cost a good part of the compile)."""
    code = _steps_kernel.py_func.__code__
    args = code.co_varnames[:code.co_argcount]
    assert args[-len(_PARTS):] == _PARTS
    source = inspect.getsource(_steps_kernel.py_func)
    body = source[source.index("):\n", source.index("def _steps_kernel(")) + 3:]
    return f"def steps({', '.join(args[:-len(_PARTS)])}):\n" + body


def _kernel_names() -> str:
    """The module's names the kernel's source uses (the generated module imports them)."""
    names = _steps_kernel.py_func.__code__.co_names
    return ", ".join(n for n in names if n in globals() and n != "np" and not n.startswith("__"))


def compiled(integrator, breaker, growth, parallel=False, columns: tuple[str, ...] = (), resin=None) -> bool:
    """Whether the kernel :func:`specialized` gives for these parts is compiled already, in this
    process or in the cache on disk (numba's index of it there, undamaged), so that a run can start
    without compiling it.  Compiles nothing."""
    combination = _combination(integrator, breaker, growth, parallel, columns, resin)
    if combination.key in _SPECIALIZED:
        return True
    if not combination.importable:
        return False  # compiled in each process that uses it
    name, text = combination.file()
    path = cache_dir() / f"{name}.py"
    return _holds(path, text) and _compiled_before(path)


ALONGSIDE = True
"""Whether a threaded kernel not yet compiled is compiled alongside the run, in a process of its own,
the run's calls taking one thread meanwhile (:func:`threaded_ready`); ``False``: in the run's process,
before its first threaded call (what a measurement of the threaded kernel itself needs)."""

SERIAL_BASE_STEP_S = 2e-8
"""Seconds a base-step of the serial kernel takes, about (``bark bench speed`` measures it: a
base-step costs more on large lattices, whose bases do not stay in cache): what a run's expected
work (``Backend.expected_work``) is turned into seconds by, to be weighed against a threaded
kernel's compile (:meth:`NumbaBackend.threads_worth_compiling`)."""

THREADED_COMPILE_S = 60.0
"""Seconds a threaded kernel's compile is taken to last where none has been timed here yet
(``compile-seconds.json``; one to two minutes measured on 2-core machines): the low end, so that
no run that would gain from threads is kept from them."""

_WAITING: dict[tuple, tuple] = {}
"""Threaded kernels compiling alongside, by their parts' identities (as ``_BY_PARTS``): the parts
(kept, so that the ids stay theirs) and the compile's job."""


def threaded_ready(integrator, breaker, growth, columns, resin, arguments, worth=lambda: True) -> bool:
    """Whether a call may take the threaded kernel of these parts now: compiled in this process or
    in the cache, or to be compiled here (parts or their helpers that cannot be imported by name,
    ``ALONGSIDE`` off, a compile alongside that failed or could not start: said in one line).  Else
    it is compiled alongside (:mod:`~bark.engine.kernels.numba_alongside`: started the first time,
    for the types of a call's ``arguments()``, where ``worth()``), and not ready until that process
    has put it in the cache."""
    ids = _ids(integrator, breaker, growth, resin, True, columns)
    parts = (integrator, breaker, growth, resin)
    if not ALONGSIDE or _same_parts(_BY_PARTS.get(ids), parts):
        return True
    if not _same_parts(_WAITING.get(ids), parts):
        combination = _combination(integrator, breaker, growth, True, columns, resin)
        helper_names = [_importable(fn) for fn in combination.helpers]
        if combination.key in _SPECIALIZED or not combination.importable or None in helper_names:
            return True
        path = _write_once(*combination.file())
        job = numba_alongside.job(path)
        if job is None:
            if _compiled_before(path):
                return True
            if not worth():
                return False
            try:
                job = numba_alongside.start(path, tuple(numba.typeof(a) for a in arguments()), helper_names)
            except Exception as err:  # noqa: BLE001 — no process, or an order it cannot be given: compiled here
                why = err.strerror if isinstance(err, OSError) and err.strerror else f"{type(err).__name__}: {err}"
                LOG.info(f"the threaded stepping kernel cannot be compiled alongside ({why}): compiling it in this "
                         "process")
                return True
            LOG.info(f"compiling the threaded stepping kernel alongside, in a process of its own (once, "
                     f"{_how_long('threaded')}): the run goes on with one thread until it is ready, with the same "
                     "results")
        _WAITING[ids] = (integrator, breaker, growth, resin, job)
    job = _WAITING[ids][4]
    done = job.done()
    if done is None:
        return False
    _WAITING.pop(ids, None)
    if not done:
        LOG.info(f"the threaded stepping kernel could not be compiled alongside ({job.why()}): compiling it in this "
                 "process")
    return True


@atexit.register
def _unfinished_compiles() -> None:
    """A threaded compile alongside still running as the run's process leaves (``numba_alongside``
    ends it next: its exit hook was registered first, so runs after this one) took longer than it
    has run: that is recorded as the least its compile takes (:func:`record_compile`), so that a
    record that is too short — a compile that was really a load from the cache — cannot start, run
    after run, a compile that none of them outlasts (:meth:`NumbaBackend.threads_worth_compiling`)."""
    for *_, job in list(_WAITING.values()):
        if job.done() is None:
            record_compile("threaded", job.running_for(), at_least=True)


def compile_alongside() -> None:
    """The process of a compile alongside (``numba_alongside.CODE``): given its order
    (``numba_alongside.read_order``), the helpers made jitable and the generated module imported as a
    run's process does (:func:`_combination`, :func:`_specialized`), its kernel compiled for the
    types given (numba caches it) — alone: where another process compiles it already, once that one
    has ended (``numba_alongside.alone``), loaded from the cache instead."""
    path, types, helpers = numba_alongside.read_order()
    functions = []
    for module, qualname in helpers:
        obj = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
        functions.append(obj)
    _make_jitable(functions)
    _compile_alone(Path(path), "threaded", lambda: _load_generated(Path(path)).steps.compile(tuple(types)))


def _cache_folders(source: Path) -> list[Path]:
    """The folders numba may cache the compiled functions of ``source`` in (its locators': under
    ``NUMBA_CACHE_DIR``, beside the source, in the user's cache)."""
    sub = numba.core.caching._CacheLocator.get_suitable_cache_subpath(str(source))
    given = [Path(os.environ["NUMBA_CACHE_DIR"]) / sub] if os.environ.get("NUMBA_CACHE_DIR") else []
    return [*given, source.parent / "__pycache__", numba_env.user_cache() / "numba" / sub]


def _holds(path: Path, text: str) -> bool:
    """Whether the file ``path`` holds ``text`` (not missing, damaged or another's)."""
    try:
        return path.read_text(encoding="utf-8") == text
    except (OSError, UnicodeDecodeError):
        return False


def _compiled_before(source: Path) -> bool:
    """Whether numba has compiled code cached for the functions of ``source`` (an index file of
    theirs, undamaged: a damaged entry is removed, and compiled again)."""
    _drop_damaged(source)
    return any(next(folder.glob(f"{source.stem}.*.nbi"), None) is not None for folder in _cache_folders(source))


def _drop_damaged(source: Path) -> None:
    """Remove numba's cache entries of ``source``'s functions that cannot be read (a garbled or
    truncated file): numba would stop with a traceback on them, and compiles the function again
    without them.  Each file is read through to its end as a pickle, nothing in it built or imported
    (``_Readable``)."""
    for folder in _cache_folders(source):
        for index in folder.glob(f"{source.stem}.*.nbi") if folder.is_dir() else ():
            entries = [index, *index.parent.glob(f"{index.name[:-len('.nbi')]}.*.nbc")]
            try:
                with open(index, "rb") as fh:
                    _Readable(fh).load()  # the version, then the stamp and the names of the data files
                    _Readable(fh).load()
                for data in entries[1:]:
                    with open(data, "rb") as fh:
                        _Readable(fh).load()
            except Exception:  # noqa: BLE001 — any failure to read is a damaged entry
                for entry in entries:
                    with contextlib.suppress(OSError):
                        entry.unlink()
                warnings.warn(f"numba's cache entry {str(index)!r} was damaged: removed, compiled again", BarkWarning,
                              stacklevel=2)


class _Anything:
    """What :class:`_Readable` makes of every class a pickle names: it takes any arguments and state."""

    def __init__(self, *args, **kwargs) -> None:
        pass

    def __setstate__(self, state) -> None:
        pass


class _Readable(pickle.Unpickler):
    """Reads a pickle through without importing or building what it names: a check of its form."""

    def find_class(self, module, name):
        return _Anything


def _write_atomically(path: Path, text: str) -> None:
    """``text`` into ``path`` through a temporary file beside it, renamed onto it: a reader (another
    process starting a run) sees the old file or the whole new one.  Raises ``OSError``."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _write_once(name: str, text: str) -> Path:
    """The generated file ``name``.py holding ``text``: written (atomically) unless it is there with
    that text already (a damaged one is written again); in the temporary folder, said in one line,
    when bark's cache folder cannot be written (numba then caches its compiled code there too)."""
    first = cache_dir()
    for folder in (first, Path(tempfile.gettempdir()) / f"bark-kernels-{os.getuid() if hasattr(os, 'getuid') else 0}"):
        path = folder / f"{name}.py"
        if not _holds(path, text):
            try:
                folder.mkdir(parents=True, exist_ok=True)
                _write_atomically(path, text)
            except OSError:
                continue
        if folder is not first:
            warnings.warn(f"bark's cache folder {str(first)!r} cannot be written: generated kernels go to "
                          f"{str(folder)!r} (BARK_CACHE_DIR chooses another)", BarkWarning, stacklevel=2)
        return path
    raise OSError("no folder to write bark's generated kernels to: set BARK_CACHE_DIR")


# -- per-step operations (integrators and growth laws without a part) ---------------------------


@jit
def _spring_forces(x, runs, work, rest, k, intact, f):
    for axis in range(3):
        f[:, axis] = 0.0  # a column at a time: a vector fill (the whole 2-D array is filled elementwise)
    no = np.empty(0)
    no_i = np.empty(0, dtype=np.int64)
    own = np.empty((rest.shape[0], 0))  # the paper's spring reads no declared field
    _spring_pass((x[:, 0], x[:, 1], x[:, 2]), runs, rest, k, intact, rest, rest, own, (f[:, 0], f[:, 1], f[:, 2]),
                 work, False, False, _never, _no_load, no, no_i, no_i, no, 0, 0, BLOCK, _hooke, _no_flow,
                 (no, 0.0, False), 0)


@jit
def _measure(x, pi, pj, rest, k, out):
    x0, x1, x2 = x[:, 0], x[:, 1], x[:, 2]
    finite = True
    for s in range(pi.shape[0]):
        d0 = x0[pj[s]] - x0[pi[s]]
        d1 = x1[pj[s]] - x1[pi[s]]
        d2 = x2[pj[s]] - x2[pi[s]]
        t = _tension(_length(d0, d1, d2), rest[s], k)
        out[s] = t
        finite = finite & (abs(t) < np.inf)
    return finite


@jit
def _constrain(x, v, anchor, anchor_dir, r_x, r_anchor):
    uniform_x, uniform_a = r_x.shape[0] == 1, r_anchor.shape[0] == 1
    for q in range(x.shape[0]):
        r = r_x[0] if uniform_x else r_x[q]
        px, py = x[q, 0], x[q, 1]
        scale = _surface_scale(px, py, r)
        px *= scale
        py *= scale
        x[q, 0] = px
        x[q, 1] = py
        vr = _radial_speed(v[q, 0], v[q, 1], px, py, 1.0 / (r * r))
        v[q, 0] -= vr * px
        v[q, 1] -= vr * py
        ra = r_anchor[0] if uniform_a else r_anchor[q]
        anchor[q, 0] = ra * anchor_dir[q, 0]
        anchor[q, 1] = ra * anchor_dir[q, 1]


@inline
def _root(parent, a):
    """The root of base ``a``'s tree in the union–find forest ``parent``, the path halved on the way."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@inline
def _join(parent, a, b):
    """Union–find's union of bases ``a`` and ``b`` in the forest ``parent``: the larger root under
    the smaller, so every root is its tree's smallest base."""
    a, b = _root(parent, a), _root(parent, b)
    if a < b:
        parent[b] = a
    elif b < a:
        parent[a] = b


@jit
def _components(n, pi, pj, intact, labels):
    """Connected components of the intact springs by union-find; labels numbered in order of each
    component's smallest base, as scipy.sparse.csgraph.connected_components numbers them."""
    parent = np.arange(n)
    for s in range(pi.shape[0]):
        if intact[s]:
            _join(parent, np.int64(pi[s]), np.int64(pj[s]))
    count = 0
    for q in range(n):  # roots are each component's smallest base, met in increasing order
        r = _root(parent, q)
        if r == q:
            labels[q] = count
            count += 1
        else:
            labels[q] = labels[r]
    return count


@jit
def _patch_count(runs, live, n, min_size):
    """How many patches of at least ``min_size`` bases the ``live`` springs make among ``n`` bases
    (``runs`` and ``live`` as the kernel takes them: springs by position), by union–find — what
    ``Simulation.patch_count`` gives, without the labels.  Compiled once for every kernel (not
    inlined into each: their compile time)."""
    r_start, r_len, r_i, r_o = runs
    parent = np.arange(n)
    for r in range(r_start.shape[0]):
        s0, i0, o = r_start[r], r_i[r], r_o[r]
        for q in range(r_len[r]):
            if live[s0 + q]:
                _join(parent, i0 + q, i0 + q + o)
    size = np.zeros(n, np.int64)
    for q in range(n):
        size[_root(parent, q)] += 1
    count = 0
    for q in range(n):
        count += size[q] >= min_size
    return count


def _radii(r) -> np.ndarray:
    """A uniform radius travels as one value; a per-base one as its array."""
    r = np.asarray(r, dtype=float)
    if r.ndim == 0 or r.strides == (0,):  # a scalar, or np.broadcast_to of one
        return np.array([r.flat[0]])
    return np.ascontiguousarray(r)


PARALLEL_BASES = 16_000
"""Automatic threads (``Numerics.threads = 0``) share a kernel call's blocks among all the cores for
a lattice of at least this many bases (``bark bench speed --threads 1 --threads 2`` measures where
that begins to pay); below, one thread, and the serial kernel."""

SLACK_RUN = 64
"""A run of at least this many springs gets as many free positions again after it, where springs
that extend it later (the next base of the same offset, as bases join) go without moving any other."""


@attrs.define(eq=False)
class _Frame:
    """What a kernel call is given besides the state: the state's columns as vectors, its springs in
    the kernel's order, and work space kept between calls (derived data of one state, extended as its
    bases and springs are appended: a join costs its new springs, not a copy of all).

    The springs are laid out by run (``SpringOrder.runs``), each run at its own *position* in the
    per-spring arrays and followed by free positions (``SLACK_RUN``), so that a joining base's springs,
    which continue the runs of their offsets, are written in place; springs that continue no run
    with room make the frame again.  Positions are the kernel's spring indices (it logs them);
    ``ids`` maps them back to spring ids."""

    state: object
    """The state it was made for (compared by identity)."""
    sizes: tuple
    """``(n_bases, n_springs)`` it covers, and the stored arrays whose columns ``bases`` are."""
    bases: tuple
    """The 14 base vectors the kernel takes: x, v, f, anchor (3 each), anchor direction (2)."""
    runs: tuple
    """``(position, length, first i, offset o)`` of each run, in summation order (lengths grow in place)."""
    room: np.ndarray
    """Positions each run may fill (its length plus its free positions)."""
    first_keys: np.ndarray
    """Each run's first spring's sort key (``bark.model.forces.order_keys``), to place appended springs."""
    springs: tuple
    """Rest lengths, thresholds, ``1 / fmax`` and the declared per-spring fields (``own``, a column
    each: ``columns``) by position: copies, taken again whenever a declared write has edited the
    state's (``material``; see ``bark.model.state``)."""
    ids: np.ndarray
    """Spring id at each position (``-1``: a free one)."""
    live: np.ndarray
    """The intact mask by position (free positions ``False``): the kernel's working copy, kept in step
    with the state's ``intact`` (see ``NumbaBackend._live``)."""
    n_live: int
    """How many are ``True``."""
    pending: np.ndarray
    """Springs the last call broke (ids): the state has them broken once the simulation has taken them."""
    version: int
    """The state's ``intact_version`` when ``live`` was last in step with it."""
    work: tuple
    start: tuple
    """Copies of x, v and anchor at the start of a call, made by the kernel: an undone step is replayed
    from them; after an accepted call, x is the positions it ended with.  Then, for a call that takes
    a refused step back itself, the kernel's second buffer of x and v (a uniform radius), or the
    bases and anchors before the last step (per-base radii, in calls of more than
    ``IN_PLACE_STEPS`` steps)."""
    log: tuple
    start_columns: tuple = ()
    """``start`` as the kernel takes it: one vector per coordinate (made with the views)."""
    forces: float | None = None
    """The stiffness ``k`` of the spring forces the last call left in f, of the positions it ended
    with (kept in ``start[0]``, ``kept`` bases of them); ``None`` when they are of nothing now."""
    kept: int = 0
    refresh_from: int = 0
    """Bases from this id on have springs (or are bases) that came after those forces: theirs are
    made again at the next call, the others' kept (``_NumbaCall``: ``fresh``)."""
    weights: "_Weights | None" = None
    """The anchors' growth-law weights (``NumbaBackend._heights``)."""
    material: int = 0
    """``State.edited`` of the springs' material when ``springs`` was last taken from the state."""


@attrs.define(eq=False)
class _Weights:
    """The anchors' weights (a growth part's ``weights``) for one growth law."""

    key: tuple
    table: np.ndarray = attrs.field(factory=lambda: np.zeros((0, 0)))
    """Weight k of base i at ``[k, i]``; capacity for more bases in its columns."""
    spans: np.ndarray = attrs.field(factory=lambda: np.zeros((0, 2), np.int64))
    """Row k's first base with a weight that is not 0 and one past its last (``first > last``:
    none): the bases the kernel sums its term over (``_weighted_radii``)."""
    count: int = 0
    """Bases done."""
    checked: int = 0
    """Bases whose weights have been checked against the law's radius (``_check_weights``)."""


_NO_WEIGHTS = (np.empty(0), 0, np.empty(0, np.int64))
_NO_IDS = np.empty(0, np.int64)
CHECK_BATCH = 1024
"""The anchors' weights are checked against the growth law's radius when first taken, then in
batches of this many bases as bases join (a check per join was a noticeable share of the whole
tree's run)."""


def _widened(spans: np.ndarray | None, weights: np.ndarray, first: int) -> np.ndarray:
    """``spans`` (``_Weights.spans``; ``None``: none yet, each row's first past any column and its
    last 0) widened to the columns of ``weights`` (the table's from column ``first``) that are not 0."""
    if spans is None:
        spans = np.zeros((len(weights), 2), np.int64)
        spans[:, 0] = np.iinfo(np.int64).max
    nonzero = weights != 0.0  # (NaN too)
    has = nonzero.any(axis=1)
    if has.any():
        spans[has, 0] = np.minimum(spans[has, 0], first + nonzero[has].argmax(axis=1))
        spans[has, 1] = np.maximum(spans[has, 1], first + weights.shape[1] - nonzero[has, ::-1].argmax(axis=1))
    return spans


def _check_weights(growth: GrowthPart, t: float, z: np.ndarray, weights: np.ndarray) -> None:
    """The promise of a growth part's ``weights``: at heights ``z``, ``q[0] + w_0 q[1] + w_1 q[2] + ...``
    is its radius, to the bit (the kernel sums them in place of calling it)."""
    q = np.asarray(growth.at(t), dtype=float)
    summed = weighted_radius(q, weights)
    radius = np.broadcast_to(growth.radius(t, z, q), z.shape)
    if weights.shape[1:] != z.shape or not np.array_equal(summed, radius):
        raise BarkError(f"the growth part's weights ({getattr(growth.weights, '__qualname__', growth.weights)}) "
                        f"do not reproduce its radius ({getattr(growth.radius, '__qualname__', growth.radius)}) "
                        "at its anchors' heights: they must give q[0] + w[0]·q[1] + w[1]·q[2] + ... exactly")


MATERIAL = ("rest", "fmax")
"""The state's own per-spring fields the frame keeps copies of, by position (and the declared ones:
``columns``)."""


def columns(state) -> tuple[str, ...]:
    """The declared per-spring fields of ``state``, in its order: the columns of a frame's ``own``."""
    return tuple(d.name for d in state.declared if d.per == "spring")


def _place(springs: tuple, live: np.ndarray, at: np.ndarray, ids: np.ndarray, state) -> None:
    """The state's springs ``ids`` at positions ``at`` of a frame: rest lengths, thresholds, their
    inverses, the declared fields and intact flags."""
    rest, fmax, inv_fmax, own = springs
    rest[at], fmax[at] = state._rows("rest")[ids], state._rows("fmax")[ids]
    inv_fmax[at] = 1.0 / state._rows("fmax")[ids]
    for c, name in enumerate(columns(state)):
        own[at, c] = state._rows(name)[ids]
    live[at] = state._rows("intact")[ids]


def _store_of(state) -> tuple:
    return tuple(state._store.values())


def _same(a: tuple, b: tuple) -> bool:
    return len(a) == len(b) and all(p is q for p, q in zip(a, b))


class NumbaBackend(Backend):
    """The hot loop compiled (numba): one kernel per composition of parts, generated, compiled once
    and cached on disk, running many steps a call over blocks of bases and springs (threaded on
    large lattices); the same bits as :class:`~bark.engine.kernels.numpy_backend.NumpyBackend`."""

    name = NAME

    def __init__(self) -> None:
        self._frame: _Frame | None = None
        self._order = SpringOrder()
        self._buffers: dict[str, np.ndarray] = {}
        self.threads = 1
        """Threads the last kernel call shared its blocks among."""
        self.block = BLOCK
        """Bases or springs a block of the kernel's loops (the results do not depend on it)."""
        self.one_thread = False
        """Whether this run keeps to one thread, its threaded kernel not compiled and the run expected
        to end before it would be (:meth:`threads_worth_compiling`)."""

    @staticmethod
    def _threads(requested: int, n_bases: int) -> int:
        """Threads for a call: ``requested`` (``Numerics.threads``), at most numba's pool
        (``NUMBA_NUM_THREADS``: the cores this process may use, unless set); automatic (0) takes them
        all for a lattice of ``PARALLEL_BASES`` or more, else one."""
        most = numba.config.NUMBA_NUM_THREADS
        if requested == 0:
            return most if n_bases >= PARALLEL_BASES else 1
        return min(requested, most)

    def frame(self, state) -> _Frame:
        """The call frame for ``state``: reused while the state keeps its arrays and sizes, extended
        when it has grown (bases and springs appended), else made again."""
        fr = self._frame
        sizes = (state.n_bases, state.n_springs, *_store_of(state))
        if fr is not None and fr.state is state and _same(fr.sizes, sizes):
            return self._material(fr, state)
        if fr is None or fr.state is not state or not (fr.sizes[0] <= state.n_bases and fr.sizes[1] <= state.n_springs) \
                or not self._extend(fr, state):
            fr = self._frame = self._make(state)
        fr.sizes = sizes
        self._views(fr, state)
        return self._material(fr, state)

    @staticmethod
    def _material(fr: _Frame, state) -> _Frame:
        """The frame's copies of the springs' material (rest lengths, thresholds) taken again when a
        declared write has edited them since (``State.edited``): never a stale copy."""
        edited = state.edited(*MATERIAL, *columns(state))
        if edited != fr.material:
            valid = np.flatnonzero(fr.ids >= 0)
            _place(fr.springs, fr.live, valid, fr.ids[valid], state)
            fr.material, fr.forces = edited, None  # the forces it kept are of the old material
        return fr

    def _make(self, state) -> _Frame:
        """A frame made from scratch: the springs in summation order, laid out run by run with room."""
        ids = self._order.of(state._rows("pairs"), state)
        ids = np.arange(state.n_springs) if ids is None else ids
        starts, lengths, first_i, offsets = self._order.runs()
        room = lengths + np.where(lengths >= SLACK_RUN, lengths, 0)
        position = np.cumsum(room) - room
        where = np.arange(len(ids)) + np.repeat(position - starts, lengths)  # sorted place -> position
        size = int(room.sum())
        by_position = np.full(size, -1, np.int64)
        by_position[where] = ids
        springs = (*(np.zeros(size) for _ in range(3)), np.zeros((size, len(columns(state)))))
        live = np.zeros(size, bool)
        _place(springs, live, where, ids, state)
        return _Frame(state=state, sizes=(), bases=(), runs=(position, lengths.copy(), first_i, offsets), room=room,
                      first_keys=self._order.keys[starts] if len(starts) else np.empty(0, np.uint64),
                      springs=springs, ids=by_position, live=live, n_live=int(np.count_nonzero(live)),
                      pending=_NO_IDS, version=state.intact_version, work=(),
                      start=(), log=(), material=state.edited(*MATERIAL, *columns(state)))

    def _extend(self, fr: _Frame, state) -> bool:
        """Place the springs appended since ``fr`` was made at the ends of the runs they continue;
        ``False`` (nothing changed) when one continues no run with room."""
        seen = fr.sizes[1]
        fr.refresh_from = min(fr.refresh_from, fr.sizes[0])  # new bases
        if seen == state.n_springs:
            return True
        new = np.arange(seen, state.n_springs)
        keys = order_keys(state._rows("pairs")[seen:])
        by_key = np.argsort(keys, kind="stable")
        keys, new = keys[by_key], new[by_key]
        run = np.searchsorted(fr.first_keys, keys, side="right") - 1
        if run.size and run.min() < 0:
            return False
        position, lengths, _, offsets = fr.runs
        start = np.searchsorted(run, run, side="left")  # each new spring's rank among those of its run
        rank = np.arange(len(run)) - start
        fits = (keys == fr.first_keys[run] + (lengths[run] + rank).astype(np.uint64)) & (offsets[run] > 0) \
            & (lengths[run] + rank < fr.room[run])
        if not fits.all():
            return False
        at = position[run] + lengths[run] + rank
        fr.ids[at] = new
        _place(fr.springs, fr.live, at, new, state)
        fr.n_live += int(np.count_nonzero(state._rows("intact")[new]))
        np.add.at(lengths, run, 1)
        fr.refresh_from = min(fr.refresh_from, int(state._rows("pairs")[seen:].min()))  # and the bases they join
        return True

    def _views(self, fr: _Frame, state) -> None:
        """The frame's base vectors and work space for the state's present sizes."""
        x, v, a, d = state._rows("x"), state._rows("v"), state._rows("anchor"), state._rows("anchor_dir")
        n, m = state.n_bases, state.n_springs
        f = self._space("f", (n, 3))
        fr.bases = (*(x[:, i] for i in range(3)), *(v[:, i] for i in range(3)), *(f[:, i] for i in range(3)),
                    *(a[:, i] for i in range(3)), d[:, 0], d[:, 1])
        longest = int(fr.runs[1].max(initial=1))
        fr.work = (*(self._space(f"work{i}", (longest,)) for i in range(5)), self._space("picks", (longest,), np.bool_))
        fr.start = tuple(self._space(f"start{i}", (n, 3)) for i in range(6))  # the call's start; then the second
        # buffer or the last step's copy (``_Frame.start``)
        fr.start_columns = tuple(a[:, i] for a in fr.start for i in range(3))
        fr.log = (self._space("log_id", (m,), np.int64), self._space("log_step", (m,), np.int64), self._space("log_t", (m,)))

    def _space(self, name: str, shape: tuple, dtype=float) -> np.ndarray:
        """Work space ``name`` of ``shape`` (columns contiguous): the leading rows of a buffer kept
        between frames and doubled when outgrown (its rows carried over), so a join does not allocate
        (and fault in) it anew, and what a call left in it stays."""
        buf = self._buffers.get(name)
        if buf is None or buf.shape[0] < shape[0]:
            rows = grown(0 if buf is None else buf.shape[0], shape[0])
            bigger = np.empty((rows, *shape[1:]), dtype=dtype, order="F")
            if buf is not None:
                bigger[:buf.shape[0]] = buf
            buf = self._buffers[name] = bigger
        return buf[:shape[0]]

    def _live(self, state, fr: _Frame | None = None) -> np.ndarray:
        """The kernel's intact mask, in step with the state's: copied again unless the flags are as
        the kernel knows them — not edited since it last looked (``State.intact_version``), or edited
        once, by the breaking of exactly the springs of its last call (what ``Simulation.advance``
        does next: those are broken, and as many are intact as the kernel counts).  ``fr``: the
        state's frame, when the caller has it."""
        fr = fr or self.frame(state)
        edits = state.intact_version - fr.version
        took_breaks = edits == 1 and fr.pending.size > 0 and fr.n_live == np.count_nonzero(state._rows("intact")) \
            and not state._rows("intact")[fr.pending].any()
        if not (edits == 0 and fr.pending.size == 0 or took_breaks):
            fr.forces = None  # of other springs
            valid = fr.ids >= 0
            fr.live[valid] = state._rows("intact")[fr.ids[valid]]
            fr.n_live = int(np.count_nonzero(fr.live))
        fr.version, fr.pending = state.intact_version, _NO_IDS
        return fr.live

    def _heights(self, state, plan: Plan, fr: _Frame | None = None) -> tuple:
        """``(weights, stride, spans)`` of the anchors' heights for the kernel (``_height_block``):
        the growth part's ``weights`` of each anchor's height, taken when its base is first seen (an
        anchor's height never changes) and checked against the part's own radius then, or with the
        next ``CHECK_BATCH`` bases that join, and the bases each row's weights are not 0 at (from the
        first to the last: ``_Weights.spans``); ``(empty, 0, empty)`` for a law without them, or uniform."""
        growth = plan.growth
        if growth.weights is None or growth.uniform:  # only for a radius that depends on height
            return _NO_WEIGHTS
        key = (growth.weights, growth.params.tobytes())
        fr = fr or self.frame(state)
        w = fr.weights
        if w is None or w.key != key:
            w = fr.weights = _Weights(key=key)
        n = state.n_bases
        if w.count < n:
            z = np.ascontiguousarray(state._rows("anchor")[w.count:n, 2])
            new = np.atleast_2d(np.asarray(growth.weights(z, growth.params), dtype=float))
            if new.shape[1:] != z.shape:
                _check_weights(growth, state.t, z, new)  # refuses them
            if w.table.shape[1] < n or w.table.shape[0] != len(new):
                table = np.zeros((len(new), grown(w.table.shape[1], n)))
                table[:len(w.table), :w.count] = w.table[:, :w.count]
                w.table = table
            if len(w.spans) != len(new):
                w.spans = _widened(None, w.table[:, :w.count], 0)
            w.table[:, w.count:n] = new
            w.spans = _widened(w.spans, new, w.count)
            w.count = n
            if w.checked == 0 or n - w.checked >= CHECK_BATCH:
                _check_weights(growth, state.t, np.ascontiguousarray(state._rows("anchor")[w.checked:n, 2]), w.table[:, w.checked:n])
                w.checked = n
        return w.table.ravel(), w.table.shape[1], w.spans.ravel()

    def spring_forces(self, state, mech, x) -> np.ndarray:
        """Compiled for the paper's spring; another resin law's forces on whole arrays (the kernel's bits)."""
        if self.resin.key != HOOKEAN.key:  # outside the kernel, another law's forces on whole arrays (the same bits)
            from bark.engine.kernels.numpy_backend import NumpyBackend

            other = NumpyBackend()
            other.resin = self.resin
            return other.spring_forces(state, mech, x)
        fr = self.frame(state)
        f = np.empty_like(x, order="F")
        _spring_forces(x, fr.runs, fr.work, fr.springs[0], mech.k, self._live(state, fr), f)
        return f

    def measure(self, state, mech, out: np.ndarray) -> bool:
        """Compiled for the paper's spring; another resin law's tensions on whole arrays (the kernel's bits)."""
        if self.resin.key != HOOKEAN.key:  # another law's tensions on whole arrays: the kernel's bits
            from bark.model.forces import spring_geometry

            _, length = spring_geometry(state._rows("x"), state._rows("pairs"))
            out[:] = resin_tension(self.resin, state, length, mech.k)
            return bool(np.isfinite(out).all())
        return bool(_measure(state._rows("x"), state._rows("pairs")[:, 0], state._rows("pairs")[:, 1], state._rows("rest"), mech.k, out))

    def constrain(self, state, r_x, r_anchor) -> None:
        """Compiled, base by base."""
        _constrain(state._rows("x"), state._rows("v"), state._rows("anchor"), state._rows("anchor_dir"), _radii(r_x), _radii(r_anchor))

    def call(self, state, mech, plan: Plan, tension: np.ndarray) -> "_NumbaCall":
        """One kernel call's steps.  The spring forces the last call left in f are kept where they
        are of the positions, springs and stiffness now (``k`` the same, no break outside the kernel,
        and the positions those the call ended with, compared in full by the kernel as it copies the
        state it starts from): only the bases that joined since, and those their springs reach, get
        theirs made again (from ``refresh_from``; the same bits as a fresh pass over all).  A call
        that would share its blocks among threads takes one while the threaded kernel compiles
        alongside (:func:`threaded_ready`), or throughout a run expected to end before it would
        (:meth:`threads_worth_compiling`)."""
        made = _NumbaCall(self, state, mech, plan, tension)
        threads = self._threads(plan.threads, state.n_bases)
        if threads > 1 and (self.one_thread or not threaded_ready(*made.parts, lambda: made.arguments(1),
                                                                   self.threads_worth_compiling)):
            threads = 1  # the serial kernel meanwhile, or throughout: the same bits
        self.threads = threads
        if threads > 1 and numba.get_num_threads() != threads:  # setting it costs more than asking
            numba.set_num_threads(threads)
        made.kernel = specialized(made.parts[0], made.parts[1], made.parts[2], threads > 1, made.parts[3], made.parts[4])
        return made

    def threads_worth_compiling(self) -> bool:
        """Whether this run's threaded kernel, not compiled yet, is worth compiling alongside: the run
        is expected to last on one thread (``expected_work`` base-steps at ``SERIAL_BASE_STEP_S``) as
        long as the compile takes (the last one timed here, else ``THREADED_COMPILE_S``), or its
        length is not known, or the process runs many (a sweep's or a fit's worker, ``bark
        compile``: ``kernels.expect_many``).  Else the run keeps to one thread — the same bits — and
        says so once: a compile it would end unused as it leaves (and the next short run start
        again) is not begun."""
        work = self.expected_work
        compile_s = compile_seconds().get("threaded", THREADED_COMPILE_S)
        if work is None or runs_many() or work * SERIAL_BASE_STEP_S >= compile_s:
            return True
        self.one_thread = True
        LOG.info(f"running on one thread, with the same results: this run is expected to end before its threaded "
                 f"kernel would compile ({_how_long('threaded')}); `bark compile` compiles it for later runs")
        return False

    def ready(self, kernel) -> bool:
        """Whether a run of ``kernel``'s parts can start without compiling first: its kernel
        compiled already (:func:`compiled`) — for a threaded run, either kernel, the serial one
        stepping while the threaded one compiles alongside (:func:`threaded_ready`); a run whose
        strategies have no compiled parts steps in Python and compiles no kernel."""
        if kernel.integrator is None or kernel.breaker is None or kernel.growth is None:
            return True
        parts, threaded = (kernel.integrator, kernel.breaker, kernel.growth), self._threads(kernel.threads, kernel.n_bases) > 1
        # a threaded run starts on the serial kernel while the threaded one compiles alongside
        return (ALONGSIDE or not threaded) and compiled(*parts, False, kernel.columns, kernel.resin) or (
            threaded and compiled(*parts, True, kernel.columns, kernel.resin))

    def patch_labels(self, state) -> np.ndarray:
        """Compiled union–find over the intact springs, labels in order of each patch's smallest base."""
        labels = np.empty(state.n_bases, dtype=np.int32)
        _components(state.n_bases, state._rows("pairs")[:, 0], state._rows("pairs")[:, 1], state._rows("intact"), labels)
        return labels


class _NumbaCall(Call):
    """One call of the kernel specialised for the plan's parts, on the backend's frame of the state."""

    def __init__(self, backend: NumbaBackend, state, mech, plan: Plan, tension: np.ndarray) -> None:
        self.backend, self.state, self.mech, self.plan, self.tension = backend, state, mech, plan, tension
        self.parts = (plan.integrator, plan.breaker, plan.growth, columns(state), backend.resin)
        self.kernel = None  # the serial or the threaded one (``NumbaBackend.call``)
        fr = self.frame = backend.frame(state)
        self.live = backend._live(state, fr)
        self.k = float(mech.k)
        self.kept = fr.kept if fr.forces == self.k and fr.kept <= state.n_bases else -1  # the kernel compares them
        self.fresh = min(fr.refresh_from, state.n_bases)  # forces made again from this base on (all, if those moved)
        self.start = fr.start_columns
        fr.forces = None
        self.constants = (self.k, float(mech.c), float(mech.b), float(mech.m), float(plan.h_min),
                          float(plan.over), float(plan.t_limit), float(plan.max_batch), float(plan.break_budget),
                          float(plan.patch_goal), float(plan.min_patch_size))
        self.heights = backend._heights(state, plan, fr)
        self.resin = backend.resin
        # a resin that flows changes the frame's rest lengths or own fields: kept to replay from, written back after
        self.flowed = (fr.springs[0].copy(), fr.springs[3].copy()) if self.resin.evolves else None
        self.n_log, self.valid = 0, True  # valid: the forces in f are of the positions the last call ended with

    def arguments(self, n: int) -> tuple:
        """The kernel's arguments for a call of at most ``n`` steps."""
        plan, fr = self.plan, self.frame
        rest, fmax, inv_fmax, own = fr.springs
        flags = (plan.breaks == "kernel", int(self.fresh),
                 self.backend.block, int(self.kept), self.resin.evolves)
        return (fr.bases, fr.runs, fr.work, rest, fmax, inv_fmax, own, self.live, self.constants, np.empty(n, np.int64),
                plan.clock(), plan.growth.params, plan.breaker.params, plan.integrator.params, self.resin.params, flags,
                fr.log, self.heights, self.start)

    def take(self, n: int) -> tuple[int, float, bool]:
        arguments = self.arguments(n)
        self.ends, self.clock = arguments[9], arguments[10]
        first = _FIRST_CALL.pop(self.kernel, None) if _FIRST_CALL else None
        kernel = self.kernel
        result = kernel(*arguments) if first is None else _compile_alone(*first, lambda: kernel(*arguments))
        done, load, self.n_log, picked, self.undone, self.refused = result
        return done + self.undone, load, picked

    def undo(self) -> None:
        fr = self.frame
        for keep, arr in zip(fr.start, (self.state._rows("x"), self.state._rows("v"), self.state._rows("anchor"))):
            np.copyto(arr, keep)
        self.live[fr.log[0][:self.n_log]] = True  # what the call broke is intact again at its start
        if self.flowed is not None:  # and the resin as it was
            np.copyto(fr.springs[0], self.flowed[0])
            np.copyto(fr.springs[3], self.flowed[1])
        self.n_log, self.fresh, self.kept = 0, 0, -1  # a replay makes every force again
        self.valid = False

    def result(self, done: int, load: float, picked: bool, refused: bool) -> Steps:
        state, fr, n_log = self.state, self.frame, self.n_log
        if (self.valid or done > 0) and not self.undone:  # for the next call (the kernel has put the positions
            # it ended with in start; a step it took back leaves forces of the positions it refused)
            fr.forces, fr.kept, fr.refresh_from = self.k, state.n_bases, state.n_bases
        if self.flowed is not None:  # the resin's flow, into the state (the frame's copies are its source)
            valid = np.flatnonzero(fr.ids >= 0)
            ids, names = fr.ids[valid], columns(state)
            for name in self.resin.writes:
                rows = state._rows(name)
                rows[ids] = fr.springs[0][valid] if name == "rest" else fr.springs[3][valid, names.index(name)]
        if self.plan.breaks != "kernel":  # the breakers judge in Python: they see every tension of the state left
            self.backend.measure(state, self.mech, self.tension)
        positions, step, t = (a[:n_log] for a in fr.log)
        ids = fr.ids[positions]
        if n_log:  # positions -> spring ids, by step then id
            by = np.lexsort((ids, step))
            ids, step, t = ids[by], step[by], t[by]
        fr.n_live -= n_log  # the simulation breaks these in the state next (Simulation.break_springs)
        fr.pending = ids
        return Steps(done=int(done), load=float(load), broken=ids.copy(), step=step.copy(), tension=t.copy(),
                     picked=bool(picked), ends=self.ends[:done].copy(), halvings=int(self.clock[1]), refused=refused)


BACKEND_CLASS = NumbaBackend

_drop_damaged(Path(__file__))  # this module's own compiled functions load lazily, at their first call: after this
