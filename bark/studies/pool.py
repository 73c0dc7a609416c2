"""Where a study's runs go: local worker processes, or the workers of a Dask distributed cluster.

Both pools take a module-level function and its arguments (``submit``) and say which of the futures
given have finished (``wait_any``); a sweep and a fit submit pure functions, so the results do not
depend on which pool, or which of its workers, ran them.
"""

from __future__ import annotations

import os


class WorkerDied(RuntimeError):
    """A local worker process died in the middle of a run (killed, out of memory); what finished
    before is kept."""


TRACKER_WARNINGS = "ignore::UserWarning:multiprocessing.resource_tracker"
"""The warning filter multiprocessing's resource tracker runs with (:func:`quiet_resource_tracker`)."""


def quiet_resource_tracker() -> None:
    """Start multiprocessing's resource tracker — the process that removes what a dead worker left
    behind (its semaphores) — with its own warnings off.  After a worker is killed it warns, on the
    command's stderr and after the command's own one-line message, of each semaphore it finds gone
    (``resource_tracker: '/mp-…': No such file or directory``): four lines of Python the user did
    not ask for.  The filter is given to the tracker alone (its command line is made from
    ``sys.warnoptions`` when it starts); a tracker already running is left as it is."""
    import sys
    from multiprocessing import resource_tracker

    sys.warnoptions.append(TRACKER_WARNINGS)
    try:
        resource_tracker.ensure_running()
    finally:
        sys.warnoptions.remove(TRACKER_WARNINGS)


CLOSE_S = 30.0
"""At most how long closing a local pool waits for its executor's manager thread to end once the
workers are ended (it ends as soon as it sees them gone; the bound is for a worker the system has
not yet let die)."""


WATCH_S = 1.0
"""How often a wait on local workers looks whether one died unseen (:meth:`LocalPool._unstick`)."""


class LocalPool:
    """``workers`` local processes, spawned (a clean interpreter: no threads or locks inherited from
    the caller) and started once for the whole study; each takes its share of the cores for its
    kernels' threads (:func:`worker_start`)."""

    def __init__(self, workers: int, what: str = "study", warm: tuple | None = None) -> None:
        """``warm``: ``(function, args)`` each worker runs as it starts (its imports, the kernel its
        runs load), the workers started at once — while the caller goes on with its own start-up —
        rather than at the first run handed out."""
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        from bark.engine.kernels import numba_env
        from bark.engine.stepping import cores

        numba_env.thread_count()  # a value numba would fail on is dropped here, once, not in every worker
        self.slots, self.what = workers, what
        quiet_resource_tracker()
        try:
            self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                            initializer=worker_start, initargs=(max(1, cores() // workers), warm))
            if warm is not None:  # the executor starts a process per task handed out while none is idle
                for _ in range(workers):
                    self.pool.submit(os.getpid)
        except OSError as err:
            raise self._cannot_start(err) from None

    def _cannot_start(self, err: OSError) -> OSError:
        """What an ``OSError`` starting a worker means: the process limit (ulimit -u), or memory for
        another process (the pool starts its processes as work is submitted, too)."""
        return OSError(err.errno, f"cannot start the {self.what}'s worker processes ({err.strerror or err}): the "
                       "process limit (ulimit -u) or memory is reached; try fewer --workers")

    def submit(self, fn, *args):
        """Run ``fn(*args)`` in a worker process; a future of its result."""
        try:
            return self.pool.submit(fn, *args)
        except OSError as err:
            raise self._cannot_start(err) from None

    def wait_any(self, futures) -> set:
        """The futures among ``futures`` that are done, waiting until at least one is — looking every
        ``WATCH_S`` whether a worker died where its executor cannot see it (:meth:`_unstick`)."""
        from concurrent.futures import FIRST_COMPLETED, wait

        while True:
            done = wait(futures, timeout=WATCH_S, return_when=FIRST_COMPLETED)[0]
            if done:
                return done
            self._unstick()

    def _unstick(self) -> None:
        """If a worker has died: the others ended, and this process's end of the pipe the workers
        send their results through closed.  A worker killed while it sent a result (its run's
        pattern, more than the pipe holds) leaves the rest of that message unsent and the pipe's
        lock held: the executor's reader waits for the rest for ever, and every other worker for
        the lock.  With no writer left the reader meets the pipe's end instead, and the executor
        fails the runs in flight as a worker's death (:meth:`died`)."""
        processes = self._workers()
        if not any(p.exitcode is not None for p in processes):
            return
        for p in processes:
            p.terminate()
        writer = getattr(getattr(self.pool, "_result_queue", None), "_writer", None)
        if writer is not None:
            writer.close()

    def _workers(self) -> list:
        """The executor's worker processes now (a private attribute of CPython's executor: none
        where a later Python drops it, and then nothing is ended early)."""
        return list((getattr(self.pool, "_processes", None) or {}).values())

    @staticmethod
    def died(error: BaseException | None) -> bool:
        """Whether ``error`` (a future's) says its worker died."""
        from concurrent.futures.process import BrokenProcessPool

        return isinstance(error, BrokenProcessPool)

    def close(self) -> None:
        """Stop at once: the runs in flight are lost either way, not waited for.  The workers are
        ended first, then the executor's manager thread (which notices them gone and closes its
        pipes) is given ``CLOSE_S`` to finish: a process that leaves while that thread is still
        closing races Python's own exit hook, which writes to the pipe being closed and prints an
        ``OSError: [Errno 9] Bad file descriptor`` traceback after bark's one line (CPython
        gh-125451, fixed in 3.12.8 and 3.13.1, not in 3.11)."""
        manager = getattr(self.pool, "_executor_manager_thread", None)
        for worker in self._workers():
            worker.terminate()
        self.pool.shutdown(wait=False, cancel_futures=True)
        if manager is not None:
            manager.join(CLOSE_S)


class DaskPool:
    """The workers of a Dask distributed cluster (``client``, a ``distributed.Client``): Dask
    schedules, bark submits."""

    def __init__(self, client) -> None:
        self.client = client
        self.slots = max(1, sum(client.nthreads().values()))

    def submit(self, fn, *args):
        """Run ``fn(*args)`` on the cluster (never cached: each call is a run); a future of its result."""
        return self.client.submit(fn, *args, pure=False)

    def wait_any(self, futures) -> set:
        """The futures among ``futures`` that are done, waiting until at least one is."""
        from distributed import wait

        return set(wait(list(futures), return_when="FIRST_COMPLETED").done)

    @staticmethod
    def died(error: BaseException | None) -> bool:
        """Whether ``error`` means the worker died: never here, since Dask runs a lost task again on another
        worker."""
        return False  # Dask runs a task again on another worker

    def close(self) -> None:
        """Nothing to close: the cluster is the caller's."""
        pass


def worker_start(threads: int, warm: tuple | None = None) -> None:
    """A local worker leaves signals to the study: Ctrl-C stops the study (which stops handing out
    runs), not the runs in flight mid-step with a traceback each.  Its kernels' threads are its share
    of the cores (``NUMBA_NUM_THREADS``, read when numba is imported, unless the user has set it), so
    that workers do not contend for them.  It runs many simulations (``kernels.expect_many``).  Then
    ``warm`` (``(function, args)``, :class:`LocalPool`): a warm-up only — whatever it fails on, the
    runs meet again and report as runs do, so its error is not the worker's (which would break the pool)."""
    import signal

    for sig in (signal.SIGINT, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)
    os.environ.setdefault("NUMBA_NUM_THREADS", str(threads))
    from bark.engine import kernels

    kernels.expect_many()  # its runs share a kernel's compile: ``auto`` takes numba for them
    if warm is not None:
        function, args = warm
        try:
            function(*args)
        except Exception:  # noqa: BLE001 (a warm-up: the runs report it)
            pass
