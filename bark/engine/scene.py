"""Scenes: every setting of a run in one validated, TOML-shaped dictionary.

A scene file has these tables (all optional; anything left out takes its default, which is the
vertical regime of Table 2)::

    [scene]       name, description                      (free text, recorded in summary.json)
    [lattice]     bark.model.lattice.Lattice fields            (n_bases, divergence_deg, rise, offsets, jitter)
    [mechanics]   bark.model.forces.Mechanics fields           (k, c, b, m, f_max)
    [growth]      name = "sqrt" + that strategy's fields (r0, G)
    [integrator]  name = "euler-cromer" + its fields
    [breaker]     name = "threshold" + its fields
    [resin]       name = "hookean" + its fields          (the spring's law: maxwell tau, plastic yield_strain, ...)
    [analyzer]    name = "patches" + its fields          (min_size); or [[analyzer]] tables, one an analyzer:
                  the first measures the pattern, each writes its own summary and tables
    [run]         RunSettings fields                     (dt, seed, until_*, degenerate_*)
    [effects]     want = [...] (bark.model.effects), frame_every, series_every, tree_every, window  (what is simulated and written)
    [dome]        bark.model.tree.Dome fields                  (shape, height, exponent, points: the apical dome)
    [leaves]      bark.model.leaves.Leaves fields              (length, width, lifespan, ...: the leaves effect)

Unknown tables or keys, bad values and unknown strategy names raise :class:`~bark.errors.BarkError`
with one line naming the key and what is allowed.  Nothing here writes files or imports plotting.
"""

from __future__ import annotations

import copy
import os
import warnings
import tomllib
from pathlib import Path
from typing import Any

import attrs
import numpy as np

from bark.model import effects
from bark.contract import registry
from bark.validators import MISSING, construct, int_in, keywords, one_of, optional, positive
from bark.paths import NotARegularFile, open_regular
from bark.errors import BarkError, BarkWarning, Ref
from bark.model.forces import Mechanics
from bark.model.lattice import Lattice
from bark.model.leaves import Leaves
from bark.model.tree import Dome
from bark.engine.simulation import Simulation, Stop
from bark.engine.stepping import Numerics

__all__ = ["RunSettings", "Scene", "STRATEGY_SECTIONS", "DEFAULT_STRATEGIES"]


DEFAULT_STOP = {"until_time": 1000.0, "until_patches": 110}
"""A scene's stop conditions when it gives none (the paper's Fig. 7A stops at 110 patches)."""
RUN_FIELDS: dict[str, tuple[type, attrs.Attribute]] = {
    a.name: (cls, a)
    for cls, names in ((Numerics, None), (Stop, None), (Simulation, ("seed", "degenerate_fraction", "on_degenerate")))
    for a in attrs.fields(cls) if a.init and (names is None or a.name in names)
}
"""The keys of a scene's ``[run]`` table: each the field of the class that declares it (its
validator, default and docstring are that class's; only the stop conditions' defaults are the
scene's, ``DEFAULT_STOP``)."""


class RunSettings(attrs.make_class(
        "RunFields", {name: attrs.field(default=DEFAULT_STOP.get(name, a.default), validator=a.validator, kw_only=True)
                      for name, (_, a) in RUN_FIELDS.items()}, frozen=True)):
    """A scene's ``[run]`` table: how a run is stepped (:class:`~bark.engine.stepping.Numerics`), when it stops
    (:class:`~bark.engine.simulation.Stop`), its seed and degenerate-event handling (:class:`Simulation`)."""

    __slots__ = ()

    def _part(self, cls) -> dict[str, Any]:
        return {name: getattr(self, name) for name, (owner, _) in RUN_FIELDS.items() if owner is cls}

    def numerics(self) -> Numerics:
        """The run's numerics (:class:`~bark.engine.simulation.Numerics`) from these settings."""
        return Numerics(**self._part(Numerics))

    def stop(self) -> Stop:
        """The run's stop conditions (:class:`~bark.engine.simulation.Stop`) from these settings."""
        return Stop(**self._part(Stop))


STOP_KEYS = ("until_time", "until_radius", "until_patches")
STRATEGY_SECTIONS: dict[str, str] = {"growth": "growth", "integrator": "integrator", "breaker": "breaker", "resin": "resin",
                                     "analyzer": "analyzer"}
DEFAULT_STRATEGIES: dict[str, str] = {"growth": "sqrt", "integrator": "euler-cromer", "breaker": "threshold",
                                      "resin": "hookean", "analyzer": "patches"}
PARAM_SECTIONS: dict[str, type] = {"lattice": Lattice, "mechanics": Mechanics, "run": RunSettings, "dome": Dome,
                                   "leaves": Leaves}
SECTIONS = ("scene", *PARAM_SECTIONS, *STRATEGY_SECTIONS, "effects")


def _place(section: str, build):
    """``build()``, with the refs of any BarkError it raises placed in ``section``."""
    try:
        return build()
    except BarkError as err:
        raise err.within(section) from None


def _build(section: str, cls, params: dict[str, Any]):
    return _place(section, lambda: construct(cls, params, f"[{section}]"))


@attrs.frozen(kw_only=True)
class SceneInfo:
    """The ``[scene]`` table: free text, recorded in summary.json."""

    name: str = attrs.field(default="", converter=str)
    description: str = attrs.field(default="", converter=str)


def _want(value):
    if value is None:
        return None
    if isinstance(value, str) or not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        raise BarkError("{0}: must be a list of effect names, e.g. ['fracture', 'pattern-image']", Ref(None, "want", value))
    return tuple(value)  # the names are checked against the scene's strategies (Scene.from_dict)


@attrs.frozen(kw_only=True)
class EffectSettings:
    """The ``[effects]`` table."""

    want: tuple[str, ...] | None = attrs.field(default=None, converter=_want)
    """The effects asked for (``bark.model.effects``); ``None``: the usual outputs of the configured model."""
    frame_every: float = attrs.field(default=10.0, validator=positive)
    """With the ``animation`` effect: simulated time between frames."""
    series_every: float = attrs.field(default=10.0, validator=positive)
    """With the ``statistics-series`` effect: simulated time between two rows of statistics."""
    history_every: float = attrs.field(default=0.5, validator=positive)
    """With the ``fracture-history`` effect: simulated time between two samples of fracture.csv (the
    dissipation rate is a mean over these samples: keep them several to the initial fracture phase)."""
    window: float = attrs.field(default=0.5, validator=positive)
    """On a trunk with regions (bulges): side of the windows of summary.json's ``windows``, length
    units (0.5 = 15 cm, a photograph's field of view)."""
    tree_every: float | None = attrs.field(default=None, validator=optional(positive))
    """With the ``tree-series`` effect: simulated time between two of its pictures of the tree; none:
    a quarter of the run's ``until_time`` (five ages, from its start to its end)."""
    picture_format: str = attrs.field(default="png", validator=one_of(*effects.PICTURE_FORMATS))
    """The format of the run's still pictures: png, pdf or svg (pattern.pdf, ...; the animation stays a GIF)."""
    picture_dpi: int = attrs.field(default=150, validator=int_in(30, 1200))
    """Resolution of the pictures, dots per inch (for png; pdf and svg keep their vectors, rasters at it)."""


MEMORY = {"fixed": 300 * 2**20, "per_base": 800, "per_spring": 400, "per_base_image": 4000}
"""Coefficients of ``Scene.memory_estimate`` (bytes), measured as peak resident memory of whole
``bark simulate`` processes at 10 000 to 160 000 bases (interpreter, numpy, scipy and numba's
runtime; state, graph and work arrays; the image's points and spring segments)."""


HISTORY = {"file_per_base": 212, "record_per_base": 17}
"""Bytes per base and frame of the ``history`` effect (``Scene.history_estimate``): its files
(``history.nc`` and a VTU mesh a frame), measured on runs of 1 000 and 4 000 bases (20 and 192 bytes),
and its record in memory until the end, from the record's layout (positions as float32, labels as
int32, the intact springs as bits)."""


def available_memory() -> int | None:
    """Memory this machine can give a new process now (Linux's MemAvailable), or ``None`` if unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


FAR_FUTURE = 1e12
"""Time at which a radius stop with no time bound must have been reached, or it never will."""


def _check_feasible(lattice: Lattice, run: RunSettings, growth, resolved: dict) -> None:
    """Refuse a run that has nothing to simulate or whose stop conditions can never hold."""
    if min(lattice.offsets) >= lattice.n_bases:
        raise BarkError("{0} with {1}: no spring fits (each offset must be below the number of bases); nothing to simulate",
                        Ref("lattice", "n_bases", lattice.n_bases), Ref("lattice", "offsets", list(lattice.offsets)))
    if run.until_patches is not None and run.until_patches * run.min_patch_size > lattice.n_bases:
        raise BarkError("{0} patches of {1} or more bases need more bases than {2}: this stop can never hold "
                        "(ask for fewer patches, or smaller ones)",
                        Ref("run", "until_patches", run.until_patches), Ref("run", "min_patch_size", run.min_patch_size),
                        Ref("lattice", "n_bases", lattice.n_bases))
    growth = growth.on(lattice)
    _check_effects_act(lattice, growth, resolved)
    if run.until_radius is not None:
        z = np.linspace(0.0, (lattice.n_bases - 1) * lattice.rise, min(lattice.n_bases, 1000))
        mean_radius = lambda t: growth.mean_radius(t, z)  # noqa: E731
        start = mean_radius(0.0)
        if run.until_radius <= start:
            raise BarkError(f"{{0}} is not above the trunk's initial mean radius {start:.6g}: the run would stop before it starts",
                            Ref("run", "until_radius", run.until_radius))
        if run.until_time is None and not mean_radius(FAR_FUTURE) >= run.until_radius:
            raise BarkError(f"{{0}} is never reached (at t = {FAR_FUTURE:g} the mean radius is {mean_radius(FAR_FUTURE):.6g}) "
                            "and no time bound is given: this stop can never hold", Ref("run", "until_radius", run.until_radius))


def _check_effects_act(lattice: Lattice, growth, resolved: dict) -> None:
    """Say, in one line, that an effect of the growth law changes nothing on this trunk (a bulge
    placed far above it, or a trunk shortened below its bulges): the law and the law without it
    (``without``) give the same radius and thresholds at every height of the trunk, now and later.
    The run goes on (it is the run without the effect)."""
    z = np.linspace(0.0, (lattice.n_bases - 1) * lattice.rise, min(lattice.n_bases, 1000))
    for effect in growth.provides:
        if effect.name not in resolved:
            continue
        plain = growth.without(effect.name)
        same = all(_same_regions(growth.regions_at(t, z), plain.regions_at(t, z)) and
                   np.array_equal(np.broadcast_to(growth.radius(t, z), z.shape), np.broadcast_to(plain.radius(t, z), z.shape))
                   for t in (0.0, 1.0, 100.0, 10_000.0))
        if same:
            warnings.warn(f"the effect {effect.name!r} of the growth law {registry.name_of(growth)!r} changes nothing on "
                          f"this trunk (its heights run from 0 to {z[-1]:.6g}): the run is the run without it",
                          BarkWarning, stacklevel=4)


def _same_regions(a: list, b: list) -> bool:
    """Whether two growth laws' regions (``regions_at``) set the same thresholds: the same names, each
    weighing the same everywhere it weighs anything."""
    a, b = ([(n, w) for n, w in r if np.any(np.asarray(w) != 0.0)] for r in (a, b))
    return len(a) == len(b) and all(n == m and np.array_equal(v, w) for (n, v), (m, w) in zip(a, b))


def _moved(data: dict) -> None:
    """Refuse, in one line naming the new key, a setting of an earlier version that a strategy took
    over from one of the scene's own tables (``Strategy.moved_in``: the installed strategies are
    asked only when a table holds a key it does not know); a value that meant "not used", as an
    earlier run's scene.toml records it, is dropped in silence."""
    strange = [(section, key) for section, cls in PARAM_SECTIONS.items() if isinstance(data.get(section), dict)
               for key in data[section] if key not in keywords(cls)]
    if not strange:
        return
    claims: dict[tuple, list] = {}
    for kind, name in registry.find(lambda cls: bool(cls.moved_in)):
        try:
            cls = registry.load(kind, name)
        except BarkError:  # registered under another kind: said when a scene names it
            continue
        for old, (new, unused) in cls.moved_in.items():
            claims.setdefault(old, []).append((kind, name, new, unused))
    for section, key in strange:
        if (section, key) not in claims:
            continue  # not a setting of the table's: said as such when it is built
        value = data[section][key]
        if any(not _same_value(value, unused) for *_, unused in claims[(section, key)]):
            where: dict[tuple, list] = {}  # each new place, with the strategies that took it there
            for kind, name, new, _ in claims[(section, key)]:
                where.setdefault((kind, new), []).append(name)
            refs = [Ref(kind, new, value) for kind, new in where]
            said = " or ".join(f"{{{i + 1}}} ({', '.join(sorted(names))})" for i, names in enumerate(where.values()))
            raise BarkError("{0}: that setting has moved: give " + said, Ref(section, key, value), *refs)
        data[section] = {k: v for k, v in data[section].items() if k != key}


def _same_value(a, b) -> bool:
    """Whether a scene's value ``a`` is ``b`` (of any type: a list or a table is never a number)."""
    return type(a) is type(b) and a == b or isinstance(a, (int, float)) and isinstance(b, (int, float)) \
        and not isinstance(a, bool) and a == b


def _analyzer_tables(section: str, value) -> bool:
    """Whether ``value`` is ``[[analyzer]]``: the analyzer section as a list of one or more tables."""
    return section == "analyzer" and isinstance(value, list) and bool(value) and all(isinstance(t, dict) for t in value)


def merge(base: dict, overrides: dict) -> dict:
    """``base`` updated table by table with ``overrides`` (a new dict; neither input changes).

    Changing a strategy's ``name`` drops the old strategy's parameters that the override does not
    restate, since they belong to the old strategy.  Giving any ``until_*`` key in ``[run]`` replaces
    all stop conditions of ``base``.
    """
    out = copy.deepcopy(base)
    for section, table in [*base.items(), *overrides.items()]:
        if not isinstance(table, dict) and not _analyzer_tables(section, table):
            raise BarkError("{0}: must be a table like [" + str(section) + "], not a value", Ref(None, str(section), table))
    for section, table in overrides.items():
        if isinstance(table, list):  # [[analyzer]] given: they replace the base's
            out[section] = copy.deepcopy(table)
            continue
        target = out.setdefault(section, {})
        if isinstance(target, list):  # an override of [[analyzer]]'s first (the one options name)
            target = target[0]
        current = target.get("name", DEFAULT_STRATEGIES.get(section))
        if section in STRATEGY_SECTIONS and "name" in table and table["name"] != current:
            target.clear()
        if section == "run" and any(k in table for k in STOP_KEYS):
            for k in STOP_KEYS:
                target[k] = None
        target.update(table)
    return out


@attrs.frozen(kw_only=True)
class Scene:
    """A validated scene: the parts a :class:`~bark.engine.simulation.Simulation` is composed of."""

    name: str
    description: str
    lattice: Lattice
    mechanics: Mechanics
    run: RunSettings
    strategies: dict[str, Any]
    """The strategy instances, by section: growth, integrator, breaker, resin, analyzer (the first)."""
    more_analyzers: tuple = ()
    """Analyzers after the first (``[[analyzer]]`` tables), in order."""
    wanted: tuple[str, ...] = effects.DEFAULT
    """The effects the scene asked for (``[effects] want``)."""
    frame_every: float = 10.0
    """With the ``animation`` effect: simulated time between frames."""
    series_every: float = 10.0
    """With the ``statistics-series`` effect: simulated time between two rows of statistics."""
    history_every: float = 0.5
    """With the ``fracture-history`` effect: simulated time between two samples of fracture.csv."""
    window: float = 0.5
    """Side of the windows of summary.json's ``windows`` (length units; ``EffectSettings.window``)."""
    tree_every: float | None = None
    """With the ``tree-series`` effect: simulated time between two pictures (``EffectSettings.tree_every``)."""
    picture_format: str = "png"
    """The still pictures' format (``EffectSettings.picture_format``)."""
    picture_dpi: int = 150
    """The pictures' resolution, dots per inch (``EffectSettings.picture_dpi``)."""
    dome: Dome = attrs.field(factory=Dome)
    """The apical dome's profile (``bark.model.tree.Dome``): drawn in tree.png."""
    leaves: Leaves = attrs.field(factory=Leaves)
    """How the ``leaves`` effect draws the plant's leaves (``bark.model.leaves.Leaves``)."""

    @property
    def names(self) -> dict[str, str]:
        """How each strategy is recorded, by section: its entry-point name, or the import path
        ``module:Class`` of one not registered (``bark.contract.registry.name_of``) — of the instances the scene
        holds, so a scene whose strategies were replaced (``attrs.evolve``) records what it runs."""
        return {section: registry.name_of(strategy) for section, strategy in self.strategies.items()}

    @property
    def known_effects(self) -> dict[str, effects.Effect]:
        """The effects this scene can ask for: the model's own and those its strategies provide."""
        return _known(self.strategies)

    @property
    def effects(self) -> dict[str, str]:
        """Every effect the run has, with why (``bark.model.effects.resolve``)."""
        return effects.resolve(self.wanted, self.known_effects)

    def has(self, effect: str) -> bool:
        """Whether the scene simulates the effect ``effect`` (a name in ``bark.model.effects.EFFECTS``)."""
        return effect in self.effects

    @property
    def tree_interval(self) -> float:
        """Time between two pictures of the ``tree-series`` effect: ``tree_every``, or a quarter of the
        run's ``until_time``."""
        return self.tree_every if self.tree_every is not None else self.run.until_time / 4.0

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "Scene":
        """Validate a scene dictionary (as read from TOML); missing tables take their defaults.

        Beyond each value's own domain, settings that meet are checked together, so that a run that
        could never do what it is asked is refused before it starts: a lattice with no springs, a
        patch count more patches than the bases can make, a radius the trunk starts above or never
        reaches."""
        for section, table in data.items():
            if _analyzer_tables(section, table):
                continue  # [[analyzer]]: several
            if not isinstance(table, dict):
                raise BarkError("{0}: must be a table like [" + str(section) + "], not a value", Ref(None, str(section), table))
        data = dict(data)
        _moved(data)
        unknown = sorted(set(data) - set(SECTIONS), key=str)
        if unknown:
            allowed = ", ".join(f"[{s}]" for s in SECTIONS)
            table = data[unknown[0]]
            if table:  # named as the user gave it: the --set or --grid item, or the key in the scene file
                key = next(iter(table))
                raise BarkError(f"{{0}}: there is no table [{unknown[0]}] in a scene; allowed are {allowed}",
                                Ref(str(unknown[0]), str(key), table[key]))
            raise BarkError(f"unknown table [{unknown[0]}] in scene: allowed are {allowed}")
        meta = construct(SceneInfo, dict(data.get("scene", {})), "[scene]")
        tables = {s: dict(data.get(s, {})) for s in PARAM_SECTIONS}
        if any(k in tables["run"] for k in STOP_KEYS):  # stop conditions given replace the default ones
            for k in STOP_KEYS:
                tables["run"].setdefault(k, None)
        parts = {s: _build(s, c, tables[s]) for s, c in PARAM_SECTIONS.items()}
        run = parts["run"]
        _place("run", run.stop)  # at least one stop condition (Stop says so)
        eff = _build("effects", EffectSettings, dict(data.get("effects", {})))
        strategies = {}
        analyzers = data.get("analyzer", {})
        analyzers = analyzers if isinstance(analyzers, list) else [analyzers]
        for section, kind in STRATEGY_SECTIONS.items():
            params = dict(analyzers[0] if section == "analyzer" else data.get(section, {}))
            name = params.pop("name", DEFAULT_STRATEGIES[section])
            if not isinstance(name, str):
                raise BarkError("{0}: must be a string naming a " + kind + " strategy", Ref(section, "name", name))
            strategies[section] = _place(section, lambda: registry.create(kind, name, **params))
        strategies["analyzer"], run = _one_patch_size(strategies["analyzer"], run, "min_patch_size" in tables["run"],
                                                      "min_size" in analyzers[0])
        more = tuple(_more_analyzer(i, dict(t), run) for i, t in enumerate(analyzers[1:], start=1))
        names = [registry.name_of(a) for a in (strategies["analyzer"], *more)]
        if len(set(names)) != len(names):
            twice = next(n for n in names if names.count(n) > 1)
            raise BarkError(f"two analyzers {twice!r} in [[analyzer]]: each writes its results under its name; give it once")
        parts["run"] = run
        known = _known(strategies)
        wanted = eff.want
        if wanted is None:  # no list: the default outputs, and the model the scene configures
            wanted = effects.DEFAULT + tuple(e for e in known if e not in effects.EFFECTS)
        _check_wanted(wanted, known)
        resolved = effects.resolve(wanted, known)
        if run.until_patches is not None and "fracture" not in resolved:
            raise BarkError("{0} needs the effect 'fracture' (no fracture, no patches)", Ref("run", "until_patches", run.until_patches))
        if "fracture-history" in resolved and len(parts["lattice"].offsets) != 2:
            raise BarkError("{0}: the effect 'fracture-history' counts cracks in the lattice's cells, which takes two "
                            "spring offsets",
                            Ref("lattice", "offsets", list(parts["lattice"].offsets)))
        if "tree-series" in resolved and eff.tree_every is None and run.until_time is None:
            raise BarkError("{0}: the effect 'tree-series' takes a picture every tree_every, which needs a value "
                            "when the run has no {1}", Ref("effects", "tree_every", MISSING), Ref("run", "until_time", None))
        _check_feasible(parts["lattice"], run, strategies["growth"], resolved)
        _place("dome", lambda: parts["dome"].table)  # a curve through points that leaves the trunk's width
        return cls(
            name=meta.name,
            description=meta.description,
            strategies=strategies,
            more_analyzers=more,
            wanted=tuple(wanted),
            frame_every=eff.frame_every,
            series_every=eff.series_every,
            history_every=eff.history_every,
            window=eff.window,
            tree_every=eff.tree_every,
            picture_format=eff.picture_format,
            picture_dpi=eff.picture_dpi,
            **parts,
        )

    @classmethod
    def from_toml(cls, path: str | Path, overrides: dict | None = None) -> "Scene":
        """Read a TOML scene file, apply ``overrides`` (same shape), validate."""
        return cls.from_dict(merge(read_toml(path), overrides or {}))

    def components(self) -> dict[str, Any]:
        """The parts a simulation of this scene is composed of — exactly the scene's effects: what is
        not asked for is not built (no strategy's own effect, ``Strategy.without``; no breaker, no analyzer, no anchor or damping
        terms, no break log).  Cheap: nothing is allocated (``bark plan`` shows these)."""
        has = self.effects
        chosen = {section: _without(strategy, has) for section, strategy in self.strategies.items()}
        mechanics = self.mechanics
        if "anchors" not in has or "damping" not in has:
            mechanics = attrs.evolve(mechanics, c=mechanics.c if "anchors" in has else 0.0,
                                     b=mechanics.b if "damping" in has else 0.0)
        return dict(
            lattice=self.lattice,
            mechanics=mechanics,
            growth=chosen["growth"].on(self.lattice),
            integrator=chosen["integrator"],
            breakers=[chosen["breaker"]] if "fracture" in has else [],
            resin=chosen["resin"],
            analyzers=[chosen["analyzer"], *self.more_analyzers] if "patch-statistics" in has else [],
            record_breaks="break-log" in has,
            numerics=self.run.numerics(),
            **self.run._part(Simulation),
        )

    def memory_estimate(self) -> int:
        """Peak memory of a run of this scene, in bytes, from measured coefficients (``MEMORY``):
        the interpreter and libraries, then per base and per spring, more with an image."""
        n = self.lattice.n_bases
        m = sum(max(n - o, 0) for o in self.lattice.offsets)
        per_base, per_spring = MEMORY["per_base"], MEMORY["per_spring"]
        if self.has("pattern-image") or self.has("animation"):
            per_base += MEMORY["per_base_image"]
        return int(MEMORY["fixed"] + per_base * n + per_spring * m)

    def history_estimate(self, stop: Stop) -> tuple[int, int, int] | None:
        """``(frames, bytes of its files, bytes of its record in memory)`` of the ``history``
        effect of a run to ``stop`` (at most: every base there from the start), from ``HISTORY``;
        ``None`` for a run without it or without a time bound."""
        if not self.has("history") or stop.until_time is None:
            return None
        frames = int(stop.until_time // self.frame_every) + 2  # the start, each frame_every, the end
        n = self.lattice.n_bases
        return frames, frames * n * HISTORY["file_per_base"], frames * n * HISTORY["record_per_base"]

    def simulation(self) -> Simulation:
        """A fresh simulation composed of exactly this scene's effects (:meth:`components`).  A run
        whose estimated peak memory exceeds what this machine has available is refused first."""
        self.check_memory()
        return Simulation(**self.components())

    def check_memory(self, have: int | None = -1, runs: int = 1) -> None:
        """Refuse, in one line, ``runs`` runs of this scene at once (a sweep's workers) whose
        estimated peak memory exceeds ``have`` bytes (default: what this machine has available now;
        ``None``: not known, nothing refused)."""
        have = available_memory() if have == -1 else have
        need = self.memory_estimate() * runs
        if have is not None and need > have:
            n = self.lattice.n_bases
            if runs > 1:  # the runs side by side are what is too many (a sweep's or a fit's workers)
                raise BarkError(f"{{0}}: {runs} runs of {n:,} bases at once need about {need / 2**30:.3g} GiB of memory, "
                                f"and this machine has {have / 2**30:.3g} GiB available; fewer workers fit",
                                Ref(None, "workers", MISSING))
            raise BarkError(f"{{0}}: a run this size needs about {need / 2**30:.3g} GiB of memory, and this machine "
                            f"has {have / 2**30:.3g} GiB available", Ref("lattice", "n_bases", n))

    def stop(self) -> Stop:
        """The scene's stop conditions (``[run]``)."""
        return self.run.stop()

    def to_toml(self) -> str:
        """Every setting, resolved, as a scene file (``to_dict`` less the settings that are none, which
        a scene file leaves out): reading it back gives this scene again, setting for setting."""
        import tomli_w

        def kept(value):
            if isinstance(value, dict):
                return {k: kept(v) for k, v in value.items() if v is not None}
            if isinstance(value, (list, tuple)):
                return [kept(v) for v in value]
            return value

        head = f"# The scene of a bark run, every setting resolved: `bark simulate --scene scene.toml` runs it again.\n"
        return head + tomli_w.dumps(kept(self.to_dict()))

    def to_dict(self) -> dict[str, Any]:
        """Every setting, resolved (defaults filled in): the same shape as a scene file."""
        out: dict[str, Any] = {"scene": {"name": self.name, "description": self.description}}
        for section in PARAM_SECTIONS:
            out[section] = {k: v for k, v in attrs.asdict(getattr(self, section)).items()}
        for section, strategy in self.strategies.items():
            out[section] = {"name": self.names[section], **plain(strategy.params())}
        if self.more_analyzers:  # [[analyzer]]
            out["analyzer"] = [out["analyzer"], *({"name": registry.name_of(a), **plain(a.params())}
                                                  for a in self.more_analyzers)]
        out["effects"] = {"want": list(self.wanted), "frame_every": self.frame_every, "series_every": self.series_every,
                          "history_every": self.history_every, "window": self.window, "tree_every": self.tree_every,
                          "picture_format": self.picture_format, "picture_dpi": self.picture_dpi}
        return out


def _more_analyzer(index: int, params: dict, run: RunSettings):
    """An analyzer after the first of ``[[analyzer]]`` (its ``index``), counting the run's patch size
    when it drops small patches (``min_size``), as the first does."""
    name = params.pop("name", None)
    if not isinstance(name, str):
        raise BarkError("{0}: each [[analyzer]] table names its analyzer", Ref("analyzer", f"[{index}].name", name))
    analyzer = _place("analyzer", lambda: registry.create("analyzer", name, **params))
    if "min_size" in attrs.fields_dict(type(analyzer)) and analyzer.min_size != run.min_patch_size:
        if "min_size" in params:
            raise BarkError("{0} and {1} disagree: a run counts one size of patch",
                            Ref("run", "min_patch_size", run.min_patch_size),
                            Ref("analyzer", f"[{index}].min_size", analyzer.min_size))
        analyzer = attrs.evolve(analyzer, min_size=run.min_patch_size)
    return analyzer


def _one_patch_size(analyzer, run: RunSettings, run_given: bool, analyzer_given: bool):
    """``(analyzer, run)`` agreeing on the smallest patch that counts, so that a run has one patch
    size: the stop (``until_patches``), the pictures and the analyzer's statistics count the same
    patches.  An analyzer that drops small patches declares it by a ``min_size`` field (the
    contract's name for it); the one of ``[run] min_patch_size`` and ``[analyzer] min_size`` a scene
    gives sets the other, and two that disagree are refused."""
    if "min_size" not in attrs.fields_dict(type(analyzer)):
        return analyzer, run
    if run_given and analyzer_given and run.min_patch_size != analyzer.min_size:
        raise BarkError("{0} and {1} disagree: a run counts one size of patch (give one of them)",
                        Ref("run", "min_patch_size", run.min_patch_size), Ref("analyzer", "min_size", analyzer.min_size))
    if analyzer_given and not run_given:
        return analyzer, attrs.evolve(run, min_patch_size=analyzer.min_size)
    if analyzer.min_size != run.min_patch_size:
        return attrs.evolve(analyzer, min_size=run.min_patch_size), run
    return analyzer, run


def _known(strategies: dict[str, Any]) -> dict[str, effects.Effect]:
    """The model's effects, then those the strategies provide (``Strategy.provides``)."""
    return {**effects.EFFECTS, **{e.name: e for s in strategies.values() for e in type(s).provides}}


def _check_wanted(wanted, known: dict[str, effects.Effect]) -> None:
    """Each effect of ``wanted`` is one the scene can have; one that another strategy would provide
    names it (in the user's terms), any other lists what is allowed."""
    for name in wanted:
        if name not in known:
            offer = registry.providers(name)
            if offer:
                kind, strategy = offer[0]
                section = next(s for s, k in STRATEGY_SECTIONS.items() if k == kind)
                raise BarkError(f"the effect {name!r} needs {{0}}", Ref(section, "name", strategy))
            raise BarkError("{0}: " + f"unknown effect {name!r}; allowed are {', '.join(known)}", Ref("effects", "want", list(wanted)))


def _without(strategy, has: dict[str, str]):
    """``strategy`` less each of its own effects that the run does not have (``Strategy.without``)."""
    for effect in type(strategy).provides:
        if effect.name not in has:
            strategy = strategy.without(effect.name)
    return strategy


def plain(value):
    """Strategy parameters as TOML/JSON-shaped data (nested attrs objects become tables)."""
    if attrs.has(type(value)):
        params = {a.name: plain(getattr(value, a.name)) for a in attrs.fields(type(value)) if a.init}
        from bark.contract.strategies import Strategy

        if isinstance(value, Strategy):  # a nested strategy (a bulge law's base) is named as in a scene
            params = {"name": registry.name_of(value), **params}
        return params
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


SHIPPED = Path(__file__).resolve().parent.parent / "scenes"
"""The scenes bark ships (package data ``bark/scenes/*.toml``), each selected by its name."""


def shipped_scenes() -> dict[str, Path]:
    """The shipped scenes by name (the file's name without ``.toml``), sorted."""
    return {p.stem: p for p in sorted(SHIPPED.glob("*.toml"))}


def find_scene(given: str | Path) -> Path:
    """The scene file ``given`` names, by one rule: a path with a folder in it (``./vertical``,
    ``runs/a/scene.toml``) is that file; a bare name ending in ``.toml`` is the file of that name
    here, or else the shipped scene of that name; any other bare name (``vertical``) is the scene bark
    ships under it, never a file that happens to be called so in the current folder — a warning
    says when one is (``./vertical`` names it).  A bare name that is no shipped scene is the file of
    that name (``read_toml`` says when there is none, and which scenes there are)."""
    path = Path(given)
    if "/" in str(given) or os.sep in str(given) or len(path.parts) != 1:  # (Path drops a leading ./)
        return path
    shipped = SHIPPED / (path.name if path.suffix == ".toml" else f"{path.name}.toml")
    here = os.path.lexists(path)
    if path.suffix == ".toml" and here:
        if shipped.is_file():
            warnings.warn(f"scene {str(given)!r}: the file {str(given)!r} here is read, not the scene bark ships of "
                          f"that name ({path.stem!r} names that one)", BarkWarning, stacklevel=3)
        return path
    if shipped.is_file():
        if here:
            warnings.warn(f"scene {str(given)!r} is the scene bark ships; the {'folder' if path.is_dir() else 'file'} "
                          f"{str(given)!r} here is not read ({'./' + str(given)!r} names it)", BarkWarning, stacklevel=3)
        return shipped
    return path


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a scene file, or a shipped scene by name (``find_scene``); a missing or malformed file
    gives one line naming it."""
    path = find_scene(path)
    try:
        with open_regular(path) as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        hint = f"; a scene bark ships is named by one of {', '.join(shipped_scenes())}" if len(path.parts) == 1 else ""
        raise BarkError(f"scene file {str(path)!r} does not exist{hint}") from None
    except NotARegularFile as err:
        raise BarkError(f"scene file {str(path)!r}: {err}") from None
    except OSError as err:
        raise BarkError(f"scene file {str(path)!r} cannot be read ({err.strerror or err})") from None
    except tomllib.TOMLDecodeError as err:
        raise BarkError(f"scene file {str(path)!r} is not valid TOML: {err}") from None
    except UnicodeDecodeError:
        raise BarkError(f"scene file {str(path)!r} is not UTF-8 text") from None
