"""A threaded kernel compiled alongside a run: in a process of its own, while the run steps with the
serial kernel of the same parts, which gives the same bits.

numba compiles a kernel's parallel loops (``prange``) several times more slowly than its serial
ones, so on an empty cache a large lattice's first run would wait for the threaded kernel before
its first step.  Instead the numba backend (``threaded_ready``) starts a process that compiles it
into numba's cache from the generated module's file and the types of a call's arguments, and runs
its calls on one thread until that process has finished; the next call then loads the threaded
kernel and goes on with every thread.  Only the speed changes.  A process still compiling when the
run's process leaves is ended with it (``bark compile`` waits for it instead: :func:`wait`), and
one that fails is reported and its kernel compiled in the run's process, as without this module.
Processes that start the same kernel's compile at once (a sweep's or a fit's workers) compile it
once: each compile — alongside, or in a run's process at the kernel's first call — holds a lock on
the kernel's file (:func:`alone`), the others wait for it and then find the kernel in the cache.

This module imports neither numba nor the backend; the compiling process runs the backend's
``compile_alongside``.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import pickle
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover — no flock on this system: compiles are not shared
    fcntl = None

CODE = "from bark.engine.kernels.numba_backend import compile_alongside; compile_alongside()"
"""The program of the compiling process (a test puts another here), run with ``-P``: the folder it
starts in is not on its path (a ``bark`` folder there would stand for the package); the run's
``sys.path`` is given to it instead."""

ORPHAN_CHECK_S = 1.0
"""How often the compiling process checks that the process that started it is still there (it ends
itself when not: a run killed outright leaves no compile behind)."""


class Job:
    """One kernel's compile in a process of its own."""

    def __init__(self, path: Path, process: subprocess.Popen, errors) -> None:
        self.path, self.process, self.errors = path, process, errors
        self.started = time.monotonic()

    def running_for(self) -> float:
        """Seconds since it started."""
        return time.monotonic() - self.started

    def done(self) -> bool | None:
        """``None`` while it compiles; then whether the kernel is in the cache."""
        code = self.process.poll()
        return None if code is None else code == 0

    def why(self) -> str:
        """The error the compiling process stopped on (its last line naming one), or its exit status."""
        self.errors.seek(0)
        lines = [line.strip() for line in self.errors.read().decode(errors="replace").splitlines() if line.strip()]
        named = [line for line in lines if "Error" in line.split(":")[0]]
        return (named or lines or [f"exit status {self.process.returncode}"])[-1]


_JOBS: dict[str, Job] = {}


def job(path: Path) -> Job | None:
    """The compile of the generated module ``path``'s kernel started in this process, if any."""
    return _JOBS.get(str(path))


def start(path: Path, types: tuple, helpers: list[tuple[str, str]]) -> Job:
    """Compile the kernel ``steps`` of the generated module ``path`` for the argument ``types`` (numba
    types) in a process of its own, the parts' ``helpers`` (``(module, qualname)`` each) made
    jitable there first, as the backend does before it imports the module; the job.  Raises where
    the order cannot be written or no process started (the process limit, memory)."""
    order = pickle.dumps((str(path), types, helpers, list(sys.path), os.getpid()))
    errors = tempfile.TemporaryFile()
    try:
        process = subprocess.Popen([sys.executable, "-P", "-c", CODE], stdin=subprocess.PIPE,
                                   stdout=subprocess.DEVNULL, stderr=errors)
    except BaseException:
        errors.close()
        raise
    try:
        process.stdin.write(order)
        process.stdin.close()
    except OSError:  # it ended before reading (its failure is reported as any other)
        pass
    made = _JOBS[str(path)] = Job(path, process, errors)
    return made


def wait() -> list[str]:
    """Wait for every compile still running; the failures, one line each."""
    failed = []
    for made in list(_JOBS.values()):
        made.process.wait()
        if not made.done():
            failed.append(f"{made.path.name}: {made.why()}")
    return failed


@atexit.register
def _end_all() -> None:
    """Compiles still running end with the process that started them."""
    for made in _JOBS.values():
        if made.process.poll() is None:
            made.process.kill()
            made.process.wait()


def _orphaned(parent: int) -> None:
    """End this process once the one that started it is gone (killed outright: no exit hook ran)."""
    while not threading.Event().wait(ORPHAN_CHECK_S):
        if os.getppid() != parent:
            os._exit(1)


@contextlib.contextmanager
def alone(path: str | Path):
    """Held while a process compiles the kernel of the generated module ``path``: an
    exclusive ``flock`` on ``path`` with ``.lock`` for its suffix, waited for while another process
    holds it (which ends by putting the kernel in numba's cache, where this one then finds it; or,
    ended early, leaves this one to compile it).  The lock goes with the process, however it ends.
    Where the system or its file system has no ``flock``, nothing is held."""
    lock = Path(path).with_suffix(".lock")
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        fd = None
    try:
        if fd is not None and fcntl is not None:
            with contextlib.suppress(OSError):  # a file system without flock: not shared
                fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        if fd is not None:
            os.close(fd)  # releases the flock


def read_order() -> tuple[str, tuple, list]:
    """In the compiling process (``CODE``: ``numba_backend.compile_alongside``): its order read from
    stdin, ``(path, types, helpers)``; the run's ``sys.path`` taken, Ctrl-C left to the run (whose
    process ends this one as it leaves), and the watch over the run's process started."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    path, types, helpers, search, parent = pickle.load(sys.stdin.buffer)
    threading.Thread(target=_orphaned, args=(parent,), daemon=True).start()
    sys.path[:] = search
    return path, types, helpers
