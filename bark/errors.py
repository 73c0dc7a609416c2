"""The exceptions a user of bark is meant to see.

A :class:`BarkError` carries a single line that names what is wrong (the setting, its value and
what would be allowed).  The command line prints that line and exits with status 2; library callers
can catch it like any ``ValueError``.

A message about a setting does not spell the setting out itself: it holds :class:`Ref` s (section,
key, value) in ``{}`` placeholders, so that each front end names the setting in its user's terms.
``str(err)`` names it as a scene file does (``[run] dt = 1e+308``); the command line names the
option the user typed (``--dt 1e+308``), or the scene file the value came from.
"""

from __future__ import annotations

from typing import Any, Callable

import attrs

__all__ = ["Ref", "BarkError", "BarkWarning", "StateWriteError", "NonFiniteStateError", "StepFailedError", "show",
           "one_line"]


def show(value: Any) -> str:
    """A value as a scene file (TOML) writes it: floats by ``repr``, strings quoted, lists in brackets."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(show(v) for v in value) + "]"
    return repr(value)


def one_line(err: BaseException) -> str:
    """An unexpected error in one line, to report and go on (a picture that could not be drawn): its
    type and the first line of its message, at most 200 characters of it."""
    text = str(err)
    return f"{type(err).__name__}: {text.splitlines()[0][:200] if text else ''}"


class BarkWarning(UserWarning):
    """A condition bark works around and says so in one line (a setting of the environment it ignores,
    a cache it moves): the command line prints it as ``bark: warning: ...``."""


@attrs.frozen
class Ref:
    """One setting a message is about: its scene table (``None`` until known), key and value.

    ``key`` may be a path into a nested value (``bulges[0].G``); its first part is the table's key."""

    section: str | None
    key: str
    value: Any

    @property
    def top_key(self) -> str:
        """The key in the scene table (``bulges`` for ``bulges[0].G``)."""
        return self.key.split("[", 1)[0].split(".", 1)[0]

    @property
    def given(self) -> bool:
        """Whether the setting has a value (a required one that is missing has none)."""
        return self.value is not attrs.NOTHING

    def __str__(self) -> str:
        where = f"[{self.section}] " if self.section else ""
        return f"{where}{self.key} = {show(self.value)}" if self.given else f"{where}{self.key}"


class BarkError(ValueError):
    """Bad input: a parameter, a scene key, a strategy name or a file.  ``str(err)`` is one line.

    ``BarkError("{0}: must be > 0", Ref("run", "dt", -1.0))`` renders ``[run] dt = -1.0: must be > 0``;
    :meth:`render` takes another way of naming settings (the CLI's options)."""

    def __init__(self, message: str, *refs: Ref) -> None:
        super().__init__(message)
        self.template = message
        self.refs = refs

    def render(self, name: Callable[[Ref], str] = str) -> str:
        """The message with each setting named by ``name(ref)``."""
        if not self.refs:
            return self.template
        return self.template.format(*(name(r) for r in self.refs))

    def __str__(self) -> str:
        return self.render()

    def within(self, section: str | None = None, prefix: str = "") -> "BarkError":
        """The same error with refs placed: ``section`` filled in where unknown, ``prefix`` put before
        each key (``bulges[0].`` for a value inside a bulge).  Errors with no refs come back as they are."""
        if not self.refs:
            return self
        refs = tuple(attrs.evolve(r, section=r.section or section, key=prefix + r.key) for r in self.refs)
        return type(self)(self.template, *refs)


class StateWriteError(BarkError, AttributeError):
    """A write to a field of the state that the writer has not declared (``state.rest[0] = 1.0`` in a
    strategy's Python or a script): the state's fields are read-only outside the engine and outside
    the writes declared to it, so that no backend's copy of a field can silently go stale.  A
    ``ValueError`` (as numpy's read-only error) and an ``AttributeError`` (as a read-only property's)."""


class NonFiniteStateError(FloatingPointError):
    """The mechanical state became NaN or infinite; the run stops rather than go on silently."""


class StepFailedError(NonFiniteStateError):
    """A step could not be computed to its own tolerance (an iterative solve that did not converge
    in its iterations): raised by a strategy before it changes the state, so the run stops at the
    last good one, as for a non-finite state, rather than go on with a wrong step."""
