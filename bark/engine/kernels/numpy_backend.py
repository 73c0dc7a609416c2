"""The numpy backend: the physics of :mod:`bark.model.physics` and the strategies' parts on whole
arrays at once; no compiled code.  The reference, and the baseline every speed-up is quoted against
(``bark bench speed`` also measures it against a plain vectorised numpy step)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from bark.model.forces import SpringOrder, incidence, spring_geometry
from bark.engine.kernels import Backend, Call, Plan, Steps, doubles, ends_call, limits
from bark.contract.parts import Judge, resin_evolve, resin_tension

if TYPE_CHECKING:  # scipy.sparse only where the springs are no lattice's runs (``incidence``)
    import scipy.sparse as sp

NAME = "numpy"


class NumpyBackend(Backend):
    """The hot loop on whole arrays (numpy): the springs' forces summed per base in the compiled
    kernel's order (runs of springs as shifted slices; a sparse product where there are none), the
    strategies' parts called on arrays, a refused step taken back by replaying its call.  Always
    available."""

    name = NAME

    def __init__(self) -> None:
        self._inc_key = None
        self._inc = None
        self._runs_key = None
        self._runs = None
        self._order = SpringOrder()
        self._work = None

    def work(self, state) -> "_Work":
        """The work arrays for a state of this many bases and springs (made again when it grows)."""
        if self._work is None or self._work.size != (state.n_bases, state.n_springs):
            self._work = _Work(state.n_bases, state.n_springs)
        return self._work

    def incidence(self, state) -> sp.csr_matrix:
        """Spring-to-base incidence of the state's springs (derived; rebuilt when the topology grows).
        A sparse product sums spring forces onto bases faster than ``bincount`` (measured at 70 000
        bases)."""
        key = (state.n_bases, state.n_springs, id(state._store["pairs"]))
        if key != self._inc_key:  # each base's sum runs over its springs in the order the compiled pass adds them
            self._inc = incidence(state._rows("pairs"), state.n_bases, self._order.of(state._rows("pairs"), state))
            self._inc_key = key
        return self._inc

    def runs(self, state) -> list[tuple[int, int, int, int]] | None:
        """The springs as runs ``(first id, length, first i, offset o)`` of springs ``(i, i + o), (i + 1,
        i + 1 + o), ...`` when their ids are in summation order and they are few (a lattice: one run per
        offset); ``None`` otherwise (springs joined during the run, an irregular graph).  A run's springs
        are two shifted views of the positions, and its forces two shifted in-place sums: no gather
        and no sparse product (derived; made again when the topology grows)."""
        key = (state.n_bases, state.n_springs, id(state._store["pairs"]))
        if key != self._runs_key:
            self._runs = None
            if self._order.of(state._rows("pairs"), state) is None:
                starts, lengths, first, offsets = self._order.runs()
                if len(starts) <= max(16, state.n_springs // 256):
                    self._runs = list(zip(starts.tolist(), lengths.tolist(), first.tolist(), offsets.tolist()))
            self._runs_key = key
        return self._runs

    def geometry(self, state, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every spring's vector ``x_j − x_i`` and length (:func:`~bark.model.forces.spring_geometry`,
        the same numbers), run by run where the springs are runs."""
        runs = self.runs(state)
        if runs is None:
            return spring_geometry(x, state._rows("pairs"))
        w = self.work(state)
        d = w.d  # the positions' layout: each axis contiguous
        for at, n, i, o in runs:
            np.subtract(x[i + o:i + o + n], x[i:i + n], out=d[at:at + n])
        return d, w.length_of(d)

    def _spring_forces(self, state, mech, x, intact) -> np.ndarray:
        d, length = self.geometry(state, x)
        return self.forces_of(state, d, length, resin_tension(self.resin, state, length, mech.k), intact)

    def forces_of(self, state, d, length, t, intact) -> np.ndarray:
        """The springs' forces on the bases from their vectors ``d`` (used up: each becomes its spring's
        force vector, in place), lengths and tensions ``t``."""
        w = self.work(state)
        g = w.scale(t, length)
        g *= intact
        pull = np.multiply(d, g[:, None], out=d)
        runs = self.runs(state)
        if runs is None:
            return np.asarray(self.incidence(state) @ pull)
        f = w.f
        f.fill(0.0)
        for at, n, i, o in runs:  # a base's springs in summation order: as j of a run's spring, then as its i
            f[i + o:i + o + n] -= pull[at:at + n]
            f[i:i + n] += pull[at:at + n]
        return f

    def spring_forces(self, state, mech, x) -> np.ndarray:
        """On whole arrays, the intact springs' forces summed in the kernel's order."""
        return self._spring_forces(state, mech, x, state._rows("intact")).copy()  # not the work array

    def measure(self, state, mech, out: np.ndarray) -> bool:
        """On whole arrays, the resin law's tension of every spring."""
        _, length = self.geometry(state, state._rows("x"))
        out[:] = resin_tension(self.resin, state, length, mech.k)
        return bool(np.isfinite(out).all())

    def constrain(self, state, r_x, r_anchor) -> None:
        """On whole arrays: positions scaled to the radius, radial velocity removed, anchors placed."""
        x, v, w = state._rows("x"), state._rows("v"), self.work(state)
        r = np.asarray(r_x, dtype=float)
        x[:, :2] *= w.surface_scale(x[:, 0], x[:, 1], r)[:, None]
        vr = w.radial_speed(v[:, 0], v[:, 1], x[:, 0], x[:, 1], 1.0 / (r * r))
        for axis in (0, 1):
            v[:, axis] -= np.multiply(vr, x[:, axis], out=w.by_base_2)
        np.multiply(np.reshape(r_anchor, (-1, 1)), state._rows("anchor_dir"), out=state._rows("anchor")[:, :2])

    def call(self, state, mech, plan: Plan, tension: np.ndarray) -> "ArrayCall":
        """An :class:`ArrayCall`: the call's steps on whole arrays, one after another."""
        return ArrayCall(self, state, mech, plan, tension)

    def patch_labels(self, state) -> np.ndarray:
        """Connected components of the intact springs (``bark.model.components``)."""
        from bark.model.components import components

        return components(state.n_bases, state._rows("pairs"), state._rows("intact"))


class _Work:
    """Work arrays of one size of state, written by every step in place of the arrays a formula
    would allocate: at 70,000 bases an array allocated and freed each step costs more than the
    arithmetic on it (its memory is mapped in again).  Each method evaluates a formula of
    :mod:`bark.model.physics` operation by operation, in its order (the same bits; the backends'
    tests hold it to the kernel's), into these arrays: a result is good until the next call."""

    def __init__(self, n_bases: int, n_springs: int) -> None:
        self.size = (n_bases, n_springs)
        self.f = np.empty((n_bases, 3), order="F")  # the springs' forces on the bases
        self.force, self.damping = np.empty((n_bases, 3), order="F"), np.empty((n_bases, 3), order="F")
        self.by_base, self.by_base_2 = np.empty(n_bases), np.empty(n_bases)
        self.d = np.empty((n_springs, 3), order="F")
        self.length, self.by_spring = np.empty(n_springs), np.empty(n_springs)
        self.mask = np.empty(n_springs, bool)

    def length_of(self, d: np.ndarray) -> np.ndarray:
        """``physics.length`` of the springs' vectors ``d``."""
        out, tmp = self.length, self.by_spring
        np.multiply(d[:, 0], d[:, 0], out=out)
        out += np.multiply(d[:, 1], d[:, 1], out=tmp)
        out += np.multiply(d[:, 2], d[:, 2], out=tmp)
        return np.sqrt(out, out=out)

    def scale(self, t: np.ndarray, length: np.ndarray) -> np.ndarray:
        """``physics.spring_force_scale`` of tensions ``t`` and ``length`` where it is positive; a
        spring of no length (or NaN) divided by infinity: no force."""
        safe, short = self.by_spring, self.mask
        np.copyto(safe, length)
        np.greater(length, 0.0, out=short)
        np.logical_not(short, out=short)
        safe[short] = np.inf
        return np.divide(t, safe, out=safe)

    def base_force(self, spring_force, x, anchor, v, c, b) -> np.ndarray:
        """``physics.base_force`` of every coordinate of every base."""
        out = np.subtract(x, anchor, out=self.force)
        np.multiply(c, out, out=out)
        np.subtract(spring_force, out, out=out)
        return np.subtract(out, np.multiply(b, v, out=self.damping), out=out)

    def surface_scale(self, px, py, r) -> np.ndarray:
        """``physics.surface_scale`` of every base."""
        out = np.multiply(px, px, out=self.by_base)
        out += np.multiply(py, py, out=self.by_base_2)
        return np.divide(r, np.sqrt(out, out=out), out=out)

    def radial_speed(self, vx, vy, px, py, inv_r2) -> np.ndarray:
        """``physics.radial_speed`` of every base."""
        out = np.multiply(vx, px, out=self.by_base)
        out += np.multiply(vy, py, out=self.by_base_2)
        return np.multiply(out, inv_r2, out=out)


def _largest(loads: list[float]) -> float:
    """The largest of the breakers' loads; NaN if one is NaN."""
    return math.nan if any(map(math.isnan, loads)) else max(loads, default=-math.inf)


class ArrayCall(Call):
    """One call's steps on whole arrays: the parts' functions over every base and spring at once.

    What a step does is written here once for arrays (the numba backend's kernel is the other
    writing, checked against this one to the bit): the integrator moves the bases, the surface
    constraint puts them on the trunk at the growth law's radius, the springs' lengths and tensions
    follow (the resin law's), the breakers' load and rule judge them, and — the step kept — the
    resin flows and the springs the rule picked break.  The Python path of a strategy without a
    part (``bark.engine.stepping.python_step``) is this same call given ``verbs``: the integrator's
    ``step`` and the growth law's ``radius`` in place of their parts, each breaker's load judged
    after the step, one step a call."""

    def __init__(self, backend, state, mech, plan: Plan, tension: np.ndarray, verbs=None) -> None:
        self.backend, self.state, self.mech, self.plan, self.tension = backend, state, mech, plan, tension
        self.verbs = verbs
        self.start = (state._rows("x").copy(order="F"), state._rows("v").copy(order="F"), state._rows("anchor").copy(order="F"))
        self.flowed = {name: state._rows(name).copy() for name in backend.resin.writes}  # what the resin changes
        self.log: list[tuple[np.ndarray, int, np.ndarray]] = []

    def take(self, n: int) -> tuple[int, float, bool]:
        """:meth:`Call.take` on whole arrays, one step after another (with strategies' Python verbs,
        one step a call)."""
        state, mech, plan, verbs = self.state, self.mech, self.plan, self.verbs
        breaking, resin = plan.breaks == "kernel", self.backend.resin
        rule = Judge(plan.breaker, state)
        judges = [Judge(p, state) for p in verbs.parts] if verbs is not None and plan.breaks == "python" else [rule]
        ticks, halvings, levels, h_min = plan.ticks, plan.halvings, plan.levels, plan.h_min
        size = 1 << (levels - halvings)
        h, (accept, report) = size * h_min, limits(plan.over, halvings, levels)
        # every step's load is needed (to refuse, report or double on it, or a resin that flows changes
        # it after the step); else only the last step's, judged once after the loop, as the kernel does
        tops = verbs is not None or plan.over < math.inf or halvings > 0 or resin.evolves
        live = state._rows("intact").copy()
        self.log = log = []
        self.ends = ends = np.empty(n if verbs is None else 1, np.int64)
        fs = None if verbs is not None else self.backend._spring_forces(state, mech, state._rows("x"), live)
        update, ip, growth = (None, None, None) if verbs is not None else (plan.integrator.update, plan.integrator.params,
                                                                          plan.growth)
        x, v, a = state._rows("x"), state._rows("v"), state._rows("anchor")  # rows changed in place only
        z0, work = a[:, 2], (self.backend.work(state) if verbs is None else None)  # verbs: any backend's
        done, load, candidate, broken, picked, t_all, broke = 0, -math.inf, False, 0, None, None, 0
        refused = False
        for step in range(1, len(ends) + 1):
            t = (ticks + size) * h_min  # the clock's time (``Clock.times``)
            if verbs is not None:
                verbs.move(state, h)
                r_x, r_a = verbs.radii(t, state)
                x = state._rows("x")  # as the Python step left it
            else:  # every coordinate at once: the part's update is element-wise (one coordinate of one base)
                g = work.base_force(fs, x, a, v, mech.c, mech.b)
                x[...], v[...] = update(x, v, g, h / mech.m, h, ip)
                q = growth.at(t)
                r_x = growth.radius(t, 0.0, q) if growth.uniform else growth.radius(t, x[:, 2], q)
                r_a = r_x if growth.uniform else growth.radius(t, z0, q)
            self.backend.constrain(state, r_x, r_a)
            d, length = self.backend.geometry(state, x)
            t_all = resin_tension(resin, state, length, mech.k)
            load = _largest([j.largest_load(t_all, live, length) for j in judges]) if tops else -math.inf
            finite = bool(np.isfinite(x).all() and (np.isfinite(t_all).all() or np.isfinite(t_all[live]).all())) and not math.isnan(load)
            load, done = (load if finite else math.nan), step
            picked = rule.picks(t_all, live, length) if finite else np.empty(0, np.int64)
            candidate, broke = bool(picked.size) and not breaking, picked.size if breaking else 0
            refused = math.isnan(load) or load > accept
            double = not refused and doubles(halvings, load, ticks + size, size)
            if not refused:
                self.tension[:] = t_all
                if resin.evolves:  # the springs intact this step flow; the next forces, and the tensions
                    resin_evolve(resin, state, length, h, live)  # Python's breakers see, follow them
                    self.tension[:] = resin_tension(resin, state, length, mech.k)
                if broke:
                    live[picked] = False
                    broken += broke
                    log.append((picked, step, t_all[picked]))
                if verbs is None:  # the next step's forces: the springs as they are now, tensions as just taken
                    fs = self.backend.forces_of(state, d, length, self.tension, live)
                ticks += size
                ends[step - 1] = ticks
            stop = ends_call(finite, load, accept, report, candidate, broke, broken, plan.break_budget,
                             plan.max_batch, t >= plan.t_limit or double and not plan.may_double)
            if double:  # the clock doubles the step (``kernels.doubles``), for this call or the next
                halvings, size = halvings - 1, size * 2
                h, (accept, report) = size * h_min, limits(plan.over, halvings, levels)
            if stop:
                break
        if not tops and done and not math.isnan(load):  # the last step's load, over the springs live before it
            if broke:
                live[picked] = True
            load = _largest([j.largest_load(t_all, live, length) for j in judges])
            refused = math.isnan(load)  # as where it is judged every step
        self.halvings, self.refused = halvings, refused
        return done, load, candidate

    def undo(self) -> None:
        """Back to the copies kept at the call's start: positions, velocities, anchors and the fields
        the resin changes; the break log emptied."""
        for keep, arr in zip(self.start, (self.state._rows("x"), self.state._rows("v"), self.state._rows("anchor"))):
            arr[...] = keep
        for name, keep in self.flowed.items():
            self.state._rows(name)[...] = keep
        self.log = []

    def result(self, done: int, load: float, picked: bool, refused: bool) -> Steps:
        """:meth:`Call.result`: the springs broken at each step kept, with their tensions."""
        log = self.log
        return Steps(done=done, load=load, picked=picked, ends=self.ends[:done].copy(), halvings=self.halvings,
                     refused=refused,
                     broken=np.concatenate([b for b, _, _ in log]) if log else np.empty(0, np.int64),
                     step=np.concatenate([np.full(b.size, s, np.int64) for b, s, _ in log]) if log else np.empty(0, np.int64),
                     tension=np.concatenate([t for _, _, t in log]) if log else np.empty(0))


BACKEND_CLASS = NumpyBackend
