"""bark's command line (installed as ``bark_cli``; the console command is ``bark``).

This package sits on top of the core: it imports click, rich and matplotlib, and ``bark`` never
imports it.
"""

import signal

REASONS = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated", signal.SIGHUP: "terminated"}
"""The signals that stop a command, in the words its one line says."""


class Interrupted(KeyboardInterrupt):
    """What bark's signal handlers raise to stop the command at once (while it loads, before a run
    begins, while a picture is drawn), with the signal's number (``signum``).  A ``KeyboardInterrupt``,
    so every ``except KeyboardInterrupt`` takes it, but of its own type: under ``python -m``, CPython
    takes an exact ``KeyboardInterrupt`` that left code run by a string ``exec`` (importing scipy or
    numba runs such code) as unhandled, and at exit ends the interpreter by SIGINT whatever status
    bark gave (−2 instead of 130: seen with SIGINT 0.3–0.5 s into a resumed run).  A subclass is not."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum
