"""numba's settings, made safe before numba is imported.

A shared node hands a job whatever its environment holds.  numba reads three things from it when it
is first imported, and fails on ordinary values of each: ``NUMBA_NUM_THREADS`` of 0, a negative
number or text (a ``ValueError``, or silently all cores), ``NUMBA_THREADING_LAYER`` naming no layer
(a ``ValueError`` at the first threaded step), and a cache it cannot write (no writable
``__pycache__`` beside bark's source and no writable home: a ``RuntimeError`` for the first cached
function).  :func:`settle` runs before the numba backend imports numba and makes them usable: a
thread count or layer numba would fail on is ignored, and compiled code goes to the first place that can be
written — ``NUMBA_CACHE_DIR`` if set, beside the source, the user's cache, bark's cache folder, the
temporary folder.  Each change is said once, in one line (:class:`~bark.errors.BarkWarning`).
"""

from __future__ import annotations

import os
import tempfile
import warnings
from pathlib import Path

from bark.errors import BarkWarning

__all__ = ["settle", "thread_count", "cache_dir", "user_cache", "writable"]

_SETTLED = False


def thread_count() -> int | None:
    """``NUMBA_NUM_THREADS`` as a count of threads, ``None`` where it is not set; a value that is not
    a whole number of at least 1 is removed from the environment (numba then takes the cores it sees),
    with one line."""
    text = os.environ.get("NUMBA_NUM_THREADS")
    if text is None:
        return None
    try:
        count = int(text.strip())
    except ValueError:
        count = 0
    if count >= 1:
        return count
    del os.environ["NUMBA_NUM_THREADS"]
    warnings.warn(f"NUMBA_NUM_THREADS={text!r} is not a whole number of threads of at least 1: ignored "
                  f"(numba takes the {os.cpu_count() or 1} cores it sees)", BarkWarning, stacklevel=2)
    return None


THREADING_LAYERS = ("default", "safe", "forksafe", "threadsafe", "tbb", "omp", "workqueue")
"""What numba takes as ``NUMBA_THREADING_LAYER``: a layer's name, or a kind of safety it finds one for."""


def threading_layer() -> None:
    """``NUMBA_THREADING_LAYER`` that numba would fail on at its first threaded step (a ``ValueError``
    from deep in a run, after any compile) is removed from the environment, with one line: numba
    then chooses a layer itself."""
    text = os.environ.get("NUMBA_THREADING_LAYER")
    if text is None or text.strip().lower() in THREADING_LAYERS:
        return
    del os.environ["NUMBA_THREADING_LAYER"]
    warnings.warn(f"NUMBA_THREADING_LAYER={text!r} is not a threading layer numba knows ({', '.join(THREADING_LAYERS)}): "
                  "ignored (numba chooses one)", BarkWarning, stacklevel=2)


def writable(folder: Path) -> bool:
    """Whether files can be made in ``folder`` (made if missing), by the test numba's cache applies."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
        return True
    except (OSError, ValueError):  # ValueError: a path with a NUL byte
        return False


def user_cache() -> Path:
    """The user's cache folder: ``$XDG_CACHE_HOME``, else ``~/.cache`` (numba's and bark's live in it)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"))


def cache_dir() -> Path:
    """bark's cache folder: ``$BARK_CACHE_DIR``, else ``$XDG_CACHE_HOME/bark``, else
    ``~/.cache/bark`` (generated kernels, and numba's compiled code where it has nowhere else)."""
    given = os.environ.get("BARK_CACHE_DIR")
    return Path(given) if given else user_cache() / "bark"


def _numba_cache() -> None:
    """Point numba's cache at a folder it can write, unless the one it would choose can be."""
    given = os.environ.get("NUMBA_CACHE_DIR")
    if given:  # numba takes an empty one as not set
        if writable(Path(given)):
            return
        del os.environ["NUMBA_CACHE_DIR"]
        warnings.warn(f"NUMBA_CACHE_DIR={given!r} cannot be written: ignored", BarkWarning, stacklevel=3)
    home_cache = user_cache()
    if writable(Path(__file__).parent / "__pycache__") or writable(home_cache / "numba"):
        return  # numba's own choice works
    temp = Path(tempfile.gettempdir()) / f"bark-numba-{os.getuid() if hasattr(os, 'getuid') else 0}"
    for folder in (cache_dir() / "numba", temp):
        if writable(folder):
            os.environ["NUMBA_CACHE_DIR"] = str(folder)
            warnings.warn(f"numba cannot cache compiled code beside bark or in {str(home_cache)!r}: caching it in "
                          f"{str(folder)!r}", BarkWarning, stacklevel=3)
            return
    warnings.warn("no folder can be written to cache compiled code in: the numba backend is unavailable",
                  BarkWarning, stacklevel=3)
    raise OSError("no writable folder for numba's cache")


def settle() -> None:
    """Make numba's settings usable (see the module's docstring); once per process, before numba is
    imported.  Raises ``OSError`` where no folder at all can hold numba's cache."""
    global _SETTLED
    if not _SETTLED:
        thread_count()
        threading_layer()
        _numba_cache()
        _SETTLED = True
