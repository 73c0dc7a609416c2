"""attrs validators whose messages name the field, the value and what is allowed.

Every strategy and parameter object in bark validates its constructor keywords with these, so that
a bad value anywhere (Python call, scene file, command line) produces the same one-line message.
"""

from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any, Callable

__all__ = ["positive", "non_negative", "positive_int", "in_range", "one_of", "optional", "finite"]

Validator = Callable[[Any, Any, Any], None]


def _real(attribute, value) -> float:
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"{attribute.name} = {value!r}: must be a number")
    if not math.isfinite(value):
        raise ValueError(f"{attribute.name} = {value!r}: must be finite")
    return float(value)


def finite(instance, attribute, value) -> None:
    """Any finite real number."""
    _real(attribute, value)


def positive(instance, attribute, value) -> None:
    """A finite number > 0."""
    if _real(attribute, value) <= 0:
        raise ValueError(f"{attribute.name} = {value!r}: must be > 0")


def non_negative(instance, attribute, value) -> None:
    """A finite number >= 0."""
    if _real(attribute, value) < 0:
        raise ValueError(f"{attribute.name} = {value!r}: must be >= 0")


def positive_int(instance, attribute, value) -> None:
    """An integer >= 1."""
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
        raise ValueError(f"{attribute.name} = {value!r}: must be an integer >= 1")


def in_range(lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False) -> Validator:
    """A finite number in [lo, hi] (either end may be open)."""
    left, right = ("(" if lo_open else "["), (")" if hi_open else "]")

    def check(instance, attribute, value) -> None:
        v = _real(attribute, value)
        bad = (v <= lo if lo_open else v < lo) or (v >= hi if hi_open else v > hi)
        if bad:
            raise ValueError(f"{attribute.name} = {value!r}: must be in {left}{lo}, {hi}{right}")

    return check


def one_of(*allowed: str) -> Validator:
    """One of a fixed set of strings."""

    def check(instance, attribute, value) -> None:
        if value not in allowed:
            raise ValueError(f"{attribute.name} = {value!r}: must be one of {', '.join(allowed)}")

    return check


def optional(inner: Validator) -> Validator:
    """``None`` or whatever ``inner`` accepts."""

    def check(instance, attribute, value) -> None:
        if value is not None:
            inner(instance, attribute, value)

    return check
