"""The one exception type a user of bark is meant to see.

A :class:`BarkError` carries a single line that names what is wrong (the key, the value and what
would be allowed).  The command line prints that line and exits with status 2; library callers can
catch it like any ``ValueError``.
"""

from __future__ import annotations


class BarkError(ValueError):
    """Bad input: a parameter, a scene key, a strategy name or a file.  ``str(err)`` is one line."""


class NonFiniteStateError(FloatingPointError):
    """The mechanical state became NaN or infinite; the run stops rather than go on silently."""
