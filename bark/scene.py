"""Scenes: every setting of a run in one validated, TOML-shaped dictionary.

A scene file has these tables (all optional; anything left out takes its default, which is the
vertical regime of Table 2)::

    [scene]       name, description                      (free text, recorded in summary.json)
    [lattice]     bark.lattice.Lattice fields            (n_bases, divergence_deg, rise, offsets, jitter)
    [mechanics]   bark.forces.Mechanics fields           (k, c, b, m, f_max, fmax_spread)
    [growth]      name = "sqrt" + that strategy's fields (r0, G)
    [integrator]  name = "euler-cromer" + its fields
    [breaker]     name = "threshold" + its fields
    [analyzer]    name = "patches" + its fields          (min_size)
    [run]         RunSettings fields                     (dt, seed, until_*, degenerate_*)
    [effects]     want = [...] (bark.effects), frame_every  (what is simulated and written)

Unknown tables or keys, bad values and unknown strategy names raise :class:`~bark.errors.BarkError`
with one line naming the key and what is allowed.  Nothing here writes files or imports plotting.
"""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

import attrs

from bark import effects, registry
from bark._validate import in_range, one_of, optional, positive, positive_int
from bark.errors import BarkError
from bark.forces import Mechanics
from bark.kernels import BACKENDS
from bark.lattice import Lattice
from bark.simulation import DEFAULT_DT, DEFAULT_OVERSHOOT_TOL, DEFAULT_STEPPING, Simulation, Stop

__all__ = ["RunSettings", "Scene", "STRATEGY_SECTIONS", "DEFAULT_STRATEGIES"]


def _seed(instance, attribute, value) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"{attribute.name} = {value!r}: must be an integer >= 0")


@attrs.frozen(kw_only=True)
class RunSettings:
    """How a run is stepped and when it stops."""

    dt: float = attrs.field(default=DEFAULT_DT, validator=positive)
    """Time step, time units (1 = 88.5 days); with adaptive stepping the largest one.  The paper
    used a fixed 0.01 (21 h): dt = 0.01 with stepping = "fixed" reproduces it."""
    seed: int = attrs.field(default=0, validator=_seed)
    """Seed of the one random generator: same seed → identical run."""
    until_time: float | None = attrs.field(default=1000.0, validator=optional(positive))
    """Stop at this simulated time (time units; 1 = 88.5 days)."""
    until_radius: float | None = attrs.field(default=None, validator=optional(positive))
    """Stop when the mean trunk radius reaches this (length units; 1 = 0.3 m)."""
    until_patches: int | None = attrs.field(default=110, validator=optional(positive_int))
    """Stop when this many patches of ≥ min_patch_size bases exist (paper, Fig. 7A: 110)."""
    min_patch_size: int = attrs.field(default=7, validator=positive_int)
    """Smallest patch that counts, for the stop condition."""
    degenerate_fraction: float = attrs.field(default=0.1, validator=in_range(0.0, 1.0, lo_open=True))
    """A step breaking more than this share of all springs is reported as degenerate."""
    on_degenerate: str = attrs.field(default="warn", validator=one_of("warn", "stop"))
    """``warn``: record the event and go on; ``stop``: end the run there."""
    stepping: str = attrs.field(default=DEFAULT_STEPPING, validator=one_of("fixed", "auto", "adaptive"))
    """``fixed``: refuse a dt above the integrator's stability limit; ``auto``: split it into
    sub-steps; ``adaptive``: also halve steps around breaks to keep overshoot below overshoot_tol."""
    overshoot_tol: float = attrs.field(default=DEFAULT_OVERSHOOT_TOL, validator=positive)
    """Adaptive stepping: largest relative overshoot tension/fmax − 1 allowed at a break."""
    max_halvings: int = attrs.field(default=10, validator=positive_int)
    """Adaptive stepping: the smallest step is the full step / 2**max_halvings."""
    backend: str = attrs.field(default="auto", validator=one_of(*BACKENDS))
    """Compute backend: ``numpy``, ``numba``, or ``auto`` (numba if installed, else numpy)."""

    def stop(self) -> Stop:
        return Stop(
            until_time=self.until_time,
            until_radius=self.until_radius,
            until_patches=self.until_patches,
            min_patch_size=self.min_patch_size,
        )


STOP_KEYS = ("until_time", "until_radius", "until_patches")
STRATEGY_SECTIONS: dict[str, str] = {"growth": "growth", "integrator": "integrator", "breaker": "breaker", "analyzer": "analyzer"}
DEFAULT_STRATEGIES: dict[str, str] = {"growth": "sqrt", "integrator": "euler-cromer", "breaker": "threshold", "analyzer": "patches"}
PARAM_SECTIONS: dict[str, type] = {"lattice": Lattice, "mechanics": Mechanics, "run": RunSettings}
SECTIONS = ("scene", *PARAM_SECTIONS, *STRATEGY_SECTIONS, "effects")


def _fields(cls) -> list[str]:
    return [a.name for a in attrs.fields(cls) if a.init]


def _build(section: str, cls, params: dict[str, Any]):
    unknown = sorted(set(params) - set(_fields(cls)))
    if unknown:
        raise BarkError(f"unknown key {unknown[0]!r} in [{section}]: allowed are {', '.join(_fields(cls))}")
    try:
        return cls(**params)
    except (TypeError, ValueError) as err:
        raise BarkError(f"[{section}] {err}") from None


def merge(base: dict, overrides: dict) -> dict:
    """``base`` updated table by table with ``overrides`` (a new dict; neither input changes).

    Changing a strategy's ``name`` drops the old strategy's parameters that the override does not
    restate, since they belong to the old strategy.  Giving any ``until_*`` key in ``[run]`` replaces
    all stop conditions of ``base``.
    """
    out = copy.deepcopy(base)
    for section, table in [*base.items(), *overrides.items()]:
        if not isinstance(table, dict):
            raise BarkError(f"scene key {section!r} must be a table like [{section}], not a value")
    for section, table in overrides.items():
        target = out.setdefault(section, {})
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
    """A validated scene: the parts a :class:`~bark.simulation.Simulation` is composed of."""

    name: str
    description: str
    lattice: Lattice
    mechanics: Mechanics
    run: RunSettings
    strategies: dict[str, Any]
    """The strategy instances, by section: growth, integrator, breaker, analyzer."""
    names: dict[str, str]
    """The registered name of each strategy, by section."""
    wanted: tuple[str, ...] = effects.DEFAULT
    """The effects the scene asked for (``[effects] want``)."""
    frame_every: float = 10.0
    """With the ``animation`` effect: simulated time between frames."""
    series_every: float = 10.0
    """With the ``statistics-series`` effect: simulated time between two rows of statistics."""

    @property
    def effects(self) -> dict[str, str]:
        """Every effect the run has, with why (``bark.effects.resolve``)."""
        return effects.resolve(self.wanted)

    def has(self, effect: str) -> bool:
        return effect in self.effects

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "Scene":
        """Validate a scene dictionary (as read from TOML); missing tables take their defaults."""
        for section, table in data.items():
            if not isinstance(table, dict):
                raise BarkError(f"scene key {section!r} must be a table like [{section}], not a value")
        unknown = sorted(set(data) - set(SECTIONS))
        if unknown:
            raise BarkError(f"unknown table [{unknown[0]}] in scene: allowed are {', '.join(f'[{s}]' for s in SECTIONS)}")
        meta = dict(data.get("scene", {}))
        bad = sorted(set(meta) - {"name", "description"})
        if bad:
            raise BarkError(f"unknown key {bad[0]!r} in [scene]: allowed are name, description")
        tables = {s: dict(data.get(s, {})) for s in PARAM_SECTIONS}
        if any(k in tables["run"] for k in STOP_KEYS):  # stop conditions given replace the default ones
            for k in STOP_KEYS:
                tables["run"].setdefault(k, None)
        parts = {s: _build(s, c, tables[s]) for s, c in PARAM_SECTIONS.items()}
        if parts["run"].until_time is None and parts["run"].until_radius is None and parts["run"].until_patches is None:
            raise BarkError("[run] no stop condition: give until_time, until_radius or until_patches")
        eff = dict(data.get("effects", {}))
        bad = sorted(set(eff) - {"want", "frame_every", "series_every"})
        if bad:
            raise BarkError(f"unknown key {bad[0]!r} in [effects]: allowed are want, frame_every, series_every")
        wanted = eff.get("want")
        if wanted is None:  # no list: the default outputs, and the model the scene configures
            growth_name = dict(data.get("growth", {})).get("name", DEFAULT_STRATEGIES["growth"])
            wanted = effects.DEFAULT + (("bulges",) if growth_name == "bulge" else ())
        if isinstance(wanted, str) or not isinstance(wanted, (list, tuple)):
            raise BarkError(f"[effects] want = {wanted!r}: must be a list of effect names, e.g. ['fracture', 'pattern-image']")
        resolved = effects.resolve(wanted)
        every = {key: eff.get(key, 10.0) for key in ("frame_every", "series_every")}
        for key, value in every.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                raise BarkError(f"[effects] {key} = {value!r}: must be a number > 0")
        if parts["run"].until_patches is not None and "fracture" not in resolved:
            raise BarkError("[run] until_patches needs the effect 'fracture' (no fracture, no patches)")
        strategies, names = {}, {}
        for section, kind in STRATEGY_SECTIONS.items():
            params = dict(data.get(section, {}))
            name = params.pop("name", DEFAULT_STRATEGIES[section])
            if not isinstance(name, str):
                raise BarkError(f"[{section}] name = {name!r}: must be a string naming a {kind} strategy")
            strategies[section] = registry.create(kind, name, **params)
            names[section] = name
        if "bulges" in resolved and names["growth"] != "bulge":
            raise BarkError("the effect 'bulges' needs [growth] name = 'bulge' with its bulges")
        return cls(
            name=str(meta.get("name", "")),
            description=str(meta.get("description", "")),
            strategies=strategies,
            names=names,
            wanted=tuple(wanted),
            frame_every=float(every["frame_every"]),
            series_every=float(every["series_every"]),
            **parts,
        )

    @classmethod
    def from_toml(cls, path: str | Path, overrides: dict | None = None) -> "Scene":
        """Read a TOML scene file, apply ``overrides`` (same shape), validate."""
        return cls.from_dict(merge(read_toml(path), overrides or {}))

    def simulation(self) -> Simulation:
        """A fresh simulation composed of exactly this scene's effects: what is not asked for is not
        built (no bulge wrapper, no breaker, no analyzer, no anchor or damping terms, no break log)."""
        has = self.effects
        growth = self.strategies["growth"]
        if self.names["growth"] == "bulge" and "bulges" not in has:
            growth = growth.base  # bulges configured but not asked for: the bulge code is never built
        mechanics = self.mechanics
        if "anchors" not in has or "damping" not in has:
            mechanics = attrs.evolve(mechanics, c=mechanics.c if "anchors" in has else 0.0,
                                     b=mechanics.b if "damping" in has else 0.0)
        return Simulation(
            lattice=self.lattice,
            mechanics=mechanics,
            growth=growth,
            integrator=self.strategies["integrator"],
            breakers=[self.strategies["breaker"]] if "fracture" in has else [],
            analyzers=[self.strategies["analyzer"]] if "patch-statistics" in has else [],
            record_breaks="break-log" in has,
            dt=self.run.dt,
            seed=self.run.seed,
            degenerate_fraction=self.run.degenerate_fraction,
            on_degenerate=self.run.on_degenerate,
            stepping=self.run.stepping,
            overshoot_tol=self.run.overshoot_tol,
            max_halvings=self.run.max_halvings,
            backend=self.run.backend,
        )

    def stop(self) -> Stop:
        return self.run.stop()

    def to_dict(self) -> dict[str, Any]:
        """Every setting, resolved (defaults filled in): the same shape as a scene file."""
        out: dict[str, Any] = {"scene": {"name": self.name, "description": self.description}}
        for section in PARAM_SECTIONS:
            out[section] = attrs.asdict(getattr(self, section))
        for section, strategy in self.strategies.items():
            out[section] = {"name": self.names[section], **_plain(strategy.params())}
        out["effects"] = {"want": list(self.wanted), "frame_every": self.frame_every, "series_every": self.series_every}
        return out


def _plain(value):
    """Strategy parameters as TOML/JSON-shaped data (nested attrs objects become tables)."""
    if attrs.has(type(value)):
        params = {a.name: _plain(getattr(value, a.name)) for a in attrs.fields(type(value)) if a.init}
        from bark.strategies import Strategy

        if isinstance(value, Strategy):  # a nested strategy (a bulge law's base) is named as in a scene
            from bark import effects, registry

            name = next((n for n, ep in registry.available(value.kind).items()
                         if ep.value.endswith(":" + type(value).__name__)), type(value).__name__)
            params = {"name": name, **params}
        return params
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a scene file; a missing or malformed file gives one line naming it."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise BarkError(f"scene file {str(path)!r} does not exist") from None
    except IsADirectoryError:
        raise BarkError(f"scene file {str(path)!r} is a directory") from None
    except tomllib.TOMLDecodeError as err:
        raise BarkError(f"scene file {str(path)!r} is not valid TOML: {err}") from None
    except UnicodeDecodeError:
        raise BarkError(f"scene file {str(path)!r} is not UTF-8 text") from None
