"""The ``bark`` command (also ``python -m bark_cli``).

Loading the program takes a moment (numpy, scipy, networkx, click).  A signal in that moment ends
it the way a signal before the first step does: one line, exit 128 + signal, nothing run; never a
traceback from the middle of an import.

Leaving takes a moment too: Python's teardown of numba, scipy and the rest of what a run loaded
(measured after the whole tree: paid on every run and every sweep point).  Once the command has
finished (its outputs written and closed, its drawing processes ended) and no other thread is left,
the process runs the exit handlers, flushes its output and leaves without that teardown (``_leave``).
"""

from __future__ import annotations

import signal
import sys

from bark_cli import REASONS, Interrupted


def main() -> None:
    """The ``bark`` command: a signal while the program loads ends it in one line, then the command line runs."""
    def stop(signum, frame):
        raise Interrupted(signum)

    for sig in REASONS:  # kept until the command's own handlers take over (``bark_cli.main.Signals``)
        signal.signal(sig, stop)
    _closed_streams_to_devnull()
    _few_threads_where_processes_are_few()
    problem = _not_our_bark()
    if problem is not None:
        sys.stderr.write(f"bark: error: {problem}\n")
        sys.exit(1)
    try:
        from bark_cli.main import main as command
    except KeyboardInterrupt as err:
        signum = getattr(err, "signum", signal.SIGINT)
        sys.stderr.write(f"bark: {REASONS[signum]} before the run began: nothing was run\n")
        sys.exit(128 + int(signum))
    try:
        command()
        code = 0
    except SystemExit as done:  # how click ends every command
        code = done.code
    _leave(code)


def _not_our_bark() -> str | None:
    """What is wrong, in one line, when ``import bark`` would not give bark-grasstree's package:
    another project on the package index is also called "bark" (text to audio), and installing it
    (``pip install bark``, or a plugin that depends on "bark" instead of "bark-grasstree") puts its
    package where bark's was.  Found without importing it (that project's import loads PyTorch)."""
    import importlib.util
    from pathlib import Path

    try:
        spec = importlib.util.find_spec("bark")
    except (ImportError, ValueError):
        spec = None
    fix = "reinstall bark with `pip install --force-reinstall --no-deps bark-grasstree`"
    if spec is None or not spec.submodule_search_locations:
        return f"no Python package 'bark' is importable here: {fix}"
    where = [Path(p) for p in spec.submodule_search_locations]
    if not any((p / "engine" / "simulation.py").is_file() and (p / "contract" / "strategies.py").is_file() for p in where):
        return (f"the Python package 'bark' in {str(where[0])!r} is another project's (the package index's "
                f"\"bark\" is not this one, whose distribution is bark-grasstree): {fix}")
    return None


def _closed_streams_to_devnull() -> None:
    """A standard stream the caller closed (``bark ... >&-``: Python then has ``None`` for it) writes
    to ``/dev/null``; standard output that the system refuses to write (``> /dev/full``, a full disk,
    a closed pipe) stops being written, said once (``_Guarded``).  What would be said there is lost,
    the command's files and its exit status are not."""
    import os

    for name in ("stdout", "stderr"):
        if getattr(sys, name) is None:
            setattr(sys, name, open(os.devnull, "w", encoding="utf-8"))
    sys.stdout = _Guarded(sys.stdout)
    sys.stderr = _Guarded(sys.stderr, said=False)


class _Guarded:
    """A standard stream whose writes stop when the system refuses them: standard output says so
    once on stderr; stderr (a terminal that went away: its session killed, its window closed, EIO)
    says nothing, having nowhere to say it, and the command ends as it would have."""

    def __init__(self, stream, said: bool = True) -> None:
        self._stream, self._failed, self._said = stream, False, said
        self.refused = False
        """Whether the system refused a write (a full disk; not a reader that stopped reading):
        the command then ends with status 1, as for any output it could not write."""

    def write(self, text: str) -> int:
        if not self._failed:
            try:
                return self._stream.write(text)
            except OSError as err:
                self._fail(err)
        return len(text)

    def flush(self) -> None:
        if not self._failed:
            try:
                self._stream.flush()
            except OSError as err:
                self._fail(err)

    def _fail(self, err: OSError) -> None:
        self._failed = True
        if self._said and not isinstance(err, BrokenPipeError):  # a reader that stopped reading (| head) wants no more
            self.refused = True
            sys.stderr.write(f"bark: warning: the command's output could not be written ({err.strerror or err}); "
                             "its files are written all the same\n")

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _few_threads_where_processes_are_few() -> None:
    """Under a process limit (``ulimit -u``) that leaves little room, numpy's OpenBLAS cannot start
    its threads when it loads, and then raises SIGINT in the middle of the import (a run that never
    began would read "interrupted"): its thread pools are kept to one thread, unless the user set
    them.  A thread counts against that limit as a process does."""
    import os

    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_NPROC)
    except (ImportError, AttributeError, OSError, ValueError):
        return
    if soft == resource.RLIM_INFINITY:
        return
    uid = os.getuid()
    try:  # the user's processes now (Linux: /proc), each counted against the limit
        mine = sum(1 for p in os.listdir("/proc") if p.isdigit() and os.stat(f"/proc/{p}").st_uid == uid)
    except OSError:
        mine = 0
    if soft - mine < (os.cpu_count() or 1) + 8:
        for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(name, "1")


def _leave(code) -> None:
    """End the process as ``sys.exit(code)`` would, without the interpreter's teardown: the exit
    handlers run (``atexit``: multiprocessing's, logging's), output is flushed, then ``os._exit``.
    While another thread is alive (a sweep's process pool winding down) the interpreter's own exit
    is taken: it joins threads and runs their exit hooks before the handlers."""
    import atexit
    import os
    import threading

    if threading.active_count() > 1:
        sys.exit(code)
    if code is not None and not isinstance(code, int):  # sys.exit's message: to stderr, status 1
        sys.stderr.write(f"{code}\n")
        code = 1
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (bark ... | head): nothing more can be said
            pass
    if not code and getattr(sys.stdout, "refused", False):  # its output is one of a command's outputs
        code = 1
    os._exit(code or 0)


if __name__ == "__main__":
    main()
