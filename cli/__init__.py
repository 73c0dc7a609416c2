"""bark's command line (installed as ``bark_cli``; the console command is ``bark``).

This package sits on top of the core: it imports click, rich and matplotlib, and ``bark`` never
imports it.
"""

import os
import signal
import sys
import tempfile
import warnings
from pathlib import Path

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


def matplotlib_folder() -> None:
    """Give matplotlib a folder it can write its settings and font cache to, before it is imported:
    where the home cannot be written (a cluster job, a service user) a temporary one, said in one
    line, instead of matplotlib's own paragraph (``MPLCONFIGDIR``, if set, is left as it is)."""
    if os.environ.get("MPLCONFIGDIR"):  # matplotlib takes an empty one as not set
        return
    from bark.engine.kernels.numba_env import writable

    home = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    cache = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    if writable(Path(home) / "matplotlib") and writable(Path(cache) / "matplotlib"):  # its settings, its font cache
        return
    home = home if not writable(Path(home) / "matplotlib") else cache
    folder = Path(tempfile.gettempdir()) / f"bark-matplotlib-{os.getuid() if hasattr(os, 'getuid') else 0}"
    if writable(folder):
        os.environ["MPLCONFIGDIR"] = str(folder)
        from bark.errors import BarkWarning

        warnings.warn(f"matplotlib cannot write its settings in {home!r}: keeping them in {str(folder)!r}",
                      BarkWarning, stacklevel=2)


def write_owned(folder: Path, owned: tuple, writers: dict) -> list[str]:
    """Write a command's files into ``folder``: ``writers`` maps a file name to what writes it there
    (called with its path), ``owned`` names every file the command may write.  One it does not write
    this time is removed, so that nothing of an earlier call is left beside this one's; one the file
    system refuses (a full disk, a file-size limit) is said in one line, and its earlier version
    removed too.  Returns the files written."""
    import contextlib

    from bark.io.files import attempt

    failed: list[str] = []
    written = []
    for name in owned:
        if name not in writers:
            with contextlib.suppress(OSError):
                (folder / name).unlink(missing_ok=True)
    for name, write in writers.items():
        if attempt(name, lambda: write(folder / name), failed):
            written.append(name)
        else:
            with contextlib.suppress(OSError):
                (folder / name).unlink(missing_ok=True)
    for problem in failed:
        sys.stderr.write(f"bark: error: {problem}\n")
    return written
