"""attrs validators whose messages name the field, the value and what is allowed (public: plugins
validate their fields with these, ``attrs.field(default=0.05, validator=positive)``).

Every strategy and parameter object in bark validates its constructor keywords with these, so that
a bad value anywhere (Python call, scene file, command line) produces the same one-line
:class:`~bark.errors.BarkError`, whose :class:`~bark.errors.Ref` lets each front end name the
setting in its own terms.

Domains are bounded to what the arithmetic represents reliably, and the bound is in the message:
a real parameter lies in ``[1e-12, 1e12]`` (``positive``) or ``[0, 1e12]`` (``non_negative``), so
that products and squares of a few of them stay far from overflow and underflow; an integer count
fits the 32-bit indices the kernels use.  Limits that depend on several settings at once (a lattice
with no springs, a stop condition that can never hold, more steps than time can count) are checked
where those settings meet (``bark.engine.scene``, ``bark.engine.simulation``).
"""

from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any, Callable

import attrs

from bark.errors import BarkError, Ref

__all__ = [
    "REAL_MIN", "REAL_MAX", "INT_MAX", "positive", "non_negative", "positive_int", "int_in", "in_range", "one_of",
    "optional", "table_of", "finite", "number", "construct", "keywords", "MISSING",
]

Validator = Callable[[Any, Any, Any], None]

REAL_MIN = 1e-12
"""Smallest magnitude of a positive real parameter."""
REAL_MAX = 1e12
"""Largest magnitude of a real parameter."""
INT_MAX = 2**31 - 1
"""Largest count (bases, springs, patches): spring ends and patch labels are 32-bit in the kernels."""


def _fail(attribute, value, problem: str) -> BarkError:
    return BarkError("{0}: " + problem, Ref(None, attribute.name, value))


def number(attribute, value) -> float:
    """``value`` as a finite float, or a BarkError naming ``attribute``."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise _fail(attribute, value, "must be a number")
    if not math.isfinite(value):
        raise _fail(attribute, value, "must be a finite number")
    return float(value)


def _bounded(lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False) -> Validator:
    """A finite number in [lo, hi] (either end may be open); the message says which end was crossed."""

    def check(instance, attribute, value) -> None:
        v = number(attribute, value)
        if (v <= lo) if lo_open else (v < lo):
            raise _fail(attribute, value, f"must be {'>' if lo_open else '>='} {lo:g}")
        if (v >= hi) if hi_open else (v > hi):
            raise _fail(attribute, value, f"must be {'<' if hi_open else '<='} {hi:g}")

    check.__doc__ = (f"A finite number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'} "
                     "(an attrs validator: a value outside is one line naming the field).")
    return check


def finite(instance, attribute, value) -> None:
    """A finite real number of magnitude at most ``REAL_MAX``."""
    _bounded(-REAL_MAX, REAL_MAX)(instance, attribute, value)


def positive(instance, attribute, value) -> None:
    """A number in ``[REAL_MIN, REAL_MAX]``."""
    v = number(attribute, value)
    if v <= 0:
        raise _fail(attribute, value, "must be > 0")
    _bounded(REAL_MIN, REAL_MAX)(instance, attribute, value)


non_negative: Validator = _bounded(0.0, REAL_MAX)
"""A number in ``[0, REAL_MAX]``."""


def int_in(lo: int, hi: int) -> Validator:
    """An integer in ``[lo, hi]``."""

    def check(instance, attribute, value) -> None:
        if isinstance(value, bool) or not isinstance(value, Integral):
            raise _fail(attribute, value, "must be an integer")
        if value < lo:
            raise _fail(attribute, value, f"must be an integer >= {lo}")
        if value > hi:
            raise _fail(attribute, value, f"must be an integer <= {hi}")

    check.__doc__ = f"An integer in [{lo}, {hi}] (an attrs validator: a value outside is one line naming the field)."
    return check


positive_int: Validator = int_in(1, INT_MAX)
"""An integer in ``[1, INT_MAX]``."""


def in_range(lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False) -> Validator:
    """A finite number in [lo, hi] (either end may be open)."""
    return _bounded(lo, hi, lo_open=lo_open, hi_open=hi_open)


def one_of(*allowed: str) -> Validator:
    """One of a fixed set of strings (``check.allowed`` lists them, for the CLI's choices)."""

    def check(instance, attribute, value) -> None:
        if value not in allowed:
            raise _fail(attribute, value, f"must be one of {', '.join(allowed)}")

    check.allowed = allowed
    return check


def optional(inner: Validator) -> Validator:
    """``None`` or whatever ``inner`` accepts."""

    def check(instance, attribute, value) -> None:
        if value is not None:
            inner(instance, attribute, value)

    check.inner = inner
    return check


@attrs.frozen
class _Named:
    """What a validator needs of an attribute: its name (an entry of a table field: ``field.key``)."""

    name: str


def table_of(inner: Validator) -> Validator:
    """A table (``dict``) from names (strings) to values ``inner`` accepts, each named in a message
    as ``field.name``."""

    def check(instance, attribute, value) -> None:
        if not isinstance(value, dict):
            raise _fail(attribute, value, "must be a table of names and values, e.g. {{ bulge = 0.006 }}")
        for key, item in value.items():
            if not isinstance(key, str) or not key:
                raise _fail(attribute, value, f"its keys must be names, not {key!r}")
            inner(instance, _Named(f"{attribute.name}.{key}"), item)

    check.inner = inner
    return check


MISSING = attrs.NOTHING
"""The value of a :class:`~bark.errors.Ref` to a required setting that was not given."""


def keywords(cls) -> list[str]:
    """The keywords an attrs class takes: the aliases of the fields its ``__init__`` sets."""
    return [a.alias for a in attrs.fields(cls) if a.init]


def construct(cls, params: dict[str, Any], what: str, prefix: str = ""):
    """``cls(**params)`` for an attrs class, every problem a one-line :class:`BarkError` naming the
    key: an unknown key (with the allowed ones), a missing required one, a bad value (the field's
    validator).  ``what`` names the thing built in messages (``"growth 'bulge'"``); ``prefix`` is put
    before each key (``bulges[0].``) for a value nested in another."""
    fields = [a for a in attrs.fields(cls) if a.init]
    allowed = keywords(cls)
    if not isinstance(params, dict):
        raise BarkError("{0}: must be a table of " + what + " settings (" + ", ".join(allowed) + ")",
                        Ref(None, prefix.rstrip(".") or what, params))
    unknown = sorted(set(params) - set(allowed), key=str)
    if unknown:
        raise BarkError("{0}: not a setting of " + what + "; allowed are " + (", ".join(allowed) or "(none)"),
                        Ref(None, prefix + str(unknown[0]), params[unknown[0]]))
    required = [a.alias for a in fields if a.default is attrs.NOTHING]
    missing = [name for name in required if name not in params]
    if missing:
        raise BarkError("{0} is missing: " + what + " needs " + ", ".join(required), Ref(None, prefix + missing[0], MISSING))
    try:
        return cls(**params)
    except BarkError as err:
        raise err.within(prefix=prefix) from None
    except (TypeError, ValueError, ArithmeticError) as err:  # a plugin's own check, in its own words
        raise BarkError(f"{what}: {err}") from None
