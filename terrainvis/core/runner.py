"""Running independent units of work: in this process, on a local process pool, or on dask.

:func:`run_units` is the one interface the experiments use. It calls ``fn(*args)`` for
every task, wherever it runs (in this process, one after the other or on threads; on a
local process pool; on dask), and hands each result to ``on_result`` in this process as
soon as it arrives (in completion order), so the caller can save it at once.

Interrupts stop everything promptly and leave no orphan: Ctrl-C (SIGINT to the whole
process group), SIGINT to this process only (a notebook's interrupt) and SIGTERM all
end the run within seconds. Pending tasks are cancelled, worker processes are
terminated, and :class:`Interrupted` (a :class:`KeyboardInterrupt`) is raised after the
results that arrived before the interrupt have been handed to ``on_result``. Workers
ignore SIGINT themselves (the parent decides) and exit on their own when the parent
disappears (SIGKILL, a crash).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from ..errors import Interrupted, WorkersDied  # noqa: F401  (defined there: the CLI catches them without numpy)
from .validate import as_int, describe

__all__ = ["run_units", "Interrupted", "check_client", "check_workers"]


def check_workers(workers) -> int | None:
    """``workers`` as None (one per CPU) or an int >= 1."""
    return None if workers is None else as_int(workers, "workers", minimum=1)


def check_client(client):
    """``client`` as None or something that looks like a dask.distributed.Client."""
    if client is not None and not all(hasattr(client, a) for a in ("submit", "scatter", "cancel")):
        raise TypeError(f"client must be a dask.distributed.Client, got {describe(client)}")
    return client


def run_units(tasks, fn, *, on_result, workers=None, client=None, threads: int = 1) -> None:
    """Run ``fn(*args)`` for every ``(key, args)`` in ``tasks``; pass each result to ``on_result(key, result)``.

    Parameters
    ----------
    tasks : list of (key, tuple)
        The units, in the order they should start.
    fn : callable
        A module-level function (it is pickled to the workers).
    on_result : callable
        Called in this process with ``(key, result)`` as each unit finishes.
    workers : int, optional
        Local worker processes (default: the number of CPUs; 1 runs here).
    client : dask.distributed.Client, optional
        Run on this cluster instead.
    threads : int, default 1
        With ``workers=1``: how many units run at once in this process, each in its own
        thread with numba on one thread (1: one after the other, in this thread). For
        units that spend their time in ``nogil`` kernels started by
        :func:`terrainvis.core.interrupt.call`; an interrupt sets their shared stop flag,
        and the threads have ended when this raises.

    Raises
    ------
    Interrupted
        On SIGINT or SIGTERM, after cleaning up (see the module docstring).
    WorkersDied
        A :class:`RuntimeError`: the worker processes died (e.g. an unguarded script
        re-imported by spawn, or one killed for memory).
    """
    if not tasks:
        return
    if client is not None:
        signals = _Signals(defer=True)
        with signals.installed():
            _run_dask(tasks, fn, _deliver(on_result, signals), client, signals)
        return
    n = (os.cpu_count() or 1) if workers is None else workers
    if n == 1 and threads > 1 and len(tasks) > 1:
        signals = _Signals(defer=True)
        with signals.installed():
            _run_threads(tasks, fn, _deliver(on_result, signals), min(threads, len(tasks)), signals)
        return
    if n == 1 or len(tasks) == 1:
        # the units run here: a signal interrupts them at once (outside a save)
        signals = _Signals(defer=False)
        deliver = _deliver(on_result, signals)
        with signals.installed():
            try:
                for key, args in tasks:
                    result = fn(*args)
                    # a signal whose exception was swallowed on its way up (numba's compiler runs
                    # Python callbacks from C, where an exception is printed and dropped) still
                    # stops the run; this unit's result may be a failure it caused: not saved
                    signals.check(dropped=True)
                    deliver(key, result)
            except KeyboardInterrupt as exc:
                raise _as_interrupted(exc) from None
        return
    signals = _Signals(defer=True)
    with signals.installed():
        _run_pool(tasks, fn, _deliver(on_result, signals), min(n, len(tasks)), signals)


def _deliver(on_result, signals):
    def deliver(key, result):
        with signals.saving():
            on_result(key, result)
    return deliver


class _Signals:
    """SIGINT and SIGTERM during a run become :class:`Interrupted`.

    ``defer=False`` (units running in this thread): the handler raises at once, except
    inside :meth:`saving` (a finished unit being written), where the signal waits for
    the block to end, so a finished unit is never lost half-saved.

    ``defer=True`` (units running elsewhere, this thread waiting for them): the handler
    only records the signal, and the waiting loop calls :meth:`check` between waits.
    Raising inside the executors' own waits could leave their locks held and hang the
    clean-up; checking between waits never does.

    Only the main thread can install handlers; elsewhere the default behaviour stays.
    """

    def __init__(self, defer: bool):
        self.defer = defer
        self.pending = None
        self.dropped = None
        self.depth = 0

    def handler(self, signum, frame):
        if self.defer or self.depth:
            self.pending = signum
            return
        self.dropped = signum  # kept: if the exception is swallowed on its way up, the run stops after the unit
        raise Interrupted(signum)

    def check(self, dropped: bool = False) -> None:
        """Raise :class:`Interrupted` when a signal arrived (outside a save); with ``dropped``,
        also for a signal whose exception never reached the run (see :meth:`handler`)."""
        if dropped and self.dropped is not None:
            signum, self.dropped = self.dropped, None
            raise Interrupted(signum)
        if self.pending is not None and not self.depth:
            signum, self.pending = self.pending, None
            raise Interrupted(signum)

    @contextlib.contextmanager
    def installed(self):
        if threading.current_thread() is not threading.main_thread():
            yield self
            return
        previous = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(ValueError, OSError):
                previous[sig] = signal.signal(sig, self.handler)
        try:
            yield self
        finally:
            for sig, old in previous.items():
                with contextlib.suppress(ValueError, OSError, TypeError):
                    signal.signal(sig, old)

    @contextlib.contextmanager
    def saving(self):
        self.depth += 1
        try:
            yield
        finally:
            self.depth -= 1
        self.check()


def _as_interrupted(exc: BaseException) -> Interrupted:
    return exc if isinstance(exc, Interrupted) else Interrupted(signal.SIGINT)


def _collect(futures: dict, on_result, signals: _Signals) -> None:
    """Hand each future's result to ``on_result(key, result)`` as it finishes (``futures``:
    future -> key), checking for a signal between waits of at most 0.2 s."""
    pending = set(futures)
    while pending:
        done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
        for fut in done:
            on_result(futures[fut], fut.result())
        signals.check()


# ---------------------------------------------------------------- threads of this process
def _run_threads(tasks, fn, on_result, n_threads: int, signals: _Signals) -> None:
    """The units on ``n_threads`` threads of this process, numba on one thread in each."""
    from concurrent.futures import ThreadPoolExecutor

    from .interrupt import new_flag, thread_flag

    stop = new_flag()

    def one(args):
        import numba

        numba.set_num_threads(1)  # per thread: the main thread keeps its own number
        with thread_flag(stop):
            return fn(*args)

    pool = ThreadPoolExecutor(max_workers=n_threads, thread_name_prefix="terrainvis-unit")
    futures = {}
    try:
        for key, args in tasks:
            futures[pool.submit(one, args)] = key
        _collect(futures, on_result, signals)
    except BaseException as exc:
        stop[0] = 1  # running kernels return within a ring; the next call() in those threads raises
        pool.shutdown(wait=True, cancel_futures=True)  # signals only note themselves meanwhile (defer)
        if isinstance(exc, KeyboardInterrupt):
            raise _as_interrupted(exc) from None
        raise
    pool.shutdown(wait=True)


# ---------------------------------------------------------------- local pool
def _worker_init(threads: int, parent: int) -> None:
    """Set up a worker: numba threads, ignore SIGINT, die with the parent."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # already ignored since exec (see above)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # a pending one is dropped
    if sys.platform.startswith("linux"):
        with contextlib.suppress(Exception):  # best effort: the watchdog below covers the rest
            import ctypes

            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True, name="terrainvis-watch-parent").start()
    # the main process says what is compiled (its warm-up, or compare's progress): not every worker again
    os.environ["TERRAINVIS_COMPILE_NOTICE"] = "0"
    import numba

    numba.set_num_threads(max(1, threads))


def _watch_parent(parent: int) -> None:
    while True:
        time.sleep(0.5)
        if os.getppid() != parent:
            os._exit(3)


def _run_pool(tasks, fn, on_result, n_workers: int, signals: _Signals) -> None:
    import multiprocessing as mp

    threads = max(1, (os.cpu_count() or 1) // n_workers)
    pool = ProcessPoolExecutor(
        max_workers=n_workers, mp_context=mp.get_context("spawn"), initializer=_worker_init,
        initargs=(threads, os.getpid()),
    )
    futures = {}
    try:
        with _workers_start_ignoring_sigint():
            for key, args in tasks:  # the pool starts its workers inside submit()
                futures[pool.submit(fn, *args)] = key
        signals.check()
        _collect(futures, on_result, signals)
    except BrokenProcessPool as exc:
        _stop_pool(pool)
        if signals.pending is not None:  # the same signal reached a worker too: the user's stop
            raise Interrupted(signals.pending) from None
        raise WorkersDied(str(exc)) from exc
    except BaseException as exc:
        _stop_pool(pool)
        if isinstance(exc, KeyboardInterrupt):
            raise _as_interrupted(exc) from None
        raise
    pool.shutdown(wait=True)


@contextlib.contextmanager
def _workers_start_ignoring_sigint():
    """Start processes in this block with SIGINT ignored from their first instruction.

    A worker sets SIGINT aside in its initializer, but that runs only after it has
    imported terrainvis (seconds on a fresh install): a Ctrl-C in between would kill it
    with a KeyboardInterrupt traceback and break the pool. An ignored disposition
    survives exec, so the spawned interpreter starts with SIGINT ignored. Here SIGINT is
    blocked meanwhile, so one that arrives in the block stays pending (Linux never
    discards a blocked signal) and reaches this process's handler on the way out.
    """
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)
        if signal.SIGINT not in blocked:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _stop_pool(pool: ProcessPoolExecutor) -> None:
    """Cancel what has not started and terminate the workers now (no waiting for running units).

    The pool's own ``shutdown(cancel_futures=True)`` cancels the pending units, in its
    manager thread. Cancelling them here as well raced with that thread: once the workers
    die it marks every unit it still holds as broken, and on Python 3.11 a unit cancelled
    from this thread made it raise ``InvalidStateError`` and print a traceback after the
    "interrupted" line (seen once in CI, Ctrl-C while the workers were starting).
    """
    processes = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        with contextlib.suppress(Exception):
            p.terminate()
    deadline = time.monotonic() + 5.0
    for p in processes:
        with contextlib.suppress(Exception):
            p.join(max(0.0, deadline - time.monotonic()))
            if p.is_alive():
                p.kill()
                p.join(1.0)
    # The pool's manager thread closes its wake-up pipe once it has seen the workers die.
    # Wait for it: at exit Python writes to that pipe, and a close racing with the write
    # printed "Exception ignored ... OSError: [Errno 9] Bad file descriptor" after the
    # "interrupted" line (seen in a full test run, Ctrl-C in a cumulative viewshed).
    manager = getattr(pool, "_executor_manager_thread", None)
    if manager is not None:
        with contextlib.suppress(Exception):
            manager.join(max(1.0, deadline - time.monotonic()))


# ---------------------------------------------------------------- dask
def _host_threads(client) -> dict:
    """``{worker address: the threads of every worker on its host}``, from the scheduler (empty when it cannot tell)."""
    with contextlib.suppress(Exception):
        workers = client.scheduler_info()["workers"]
        per_host = {}
        for w in workers.values():
            per_host[w["host"]] = per_host.get(w["host"], 0) + int(w["nthreads"])
        return {address: per_host[w["host"]] for address, w in workers.items()}
    return {}


def _on_dask_worker(host_threads: dict, fn, *args):
    """``fn(*args)`` in a dask worker's thread, numba on that thread's share of its machine's
    cores: the cores over the threads of every worker on the machine (``host_threads``, by
    worker address; the worker's own threads for one the scheduler had not listed), as
    :func:`_worker_init` gives a local worker its share.

    numba keeps its thread count per thread, and a thread that never set it runs parallel
    kernels on every core: two one-thread workers on two cores ran four. The share is set
    for each unit, since the thread may serve other work between units.
    """
    share = None
    with contextlib.suppress(Exception):  # not on a worker (a client's local thread), or another distributed API
        from distributed import get_worker

        w = get_worker()
        share = max(1, (os.cpu_count() or 1) // max(1, int(host_threads.get(w.address, w.state.nthreads))))
    if share is not None:
        import numba

        numba.set_num_threads(min(share, numba.config.NUMBA_NUM_THREADS))
    from .compiling import quiet

    with quiet():  # the client's process says what is compiled, not every worker
        return fn(*args)


def _run_dask(tasks, fn, on_result, client, signals: _Signals) -> None:
    from dask.distributed import wait as dask_wait

    futures = {}
    host_threads = _host_threads(client)
    try:
        scattered = {}
        for key, args in tasks:
            # large inputs (the terrains) are scattered once and shared by their units
            sent = []
            for a in args:
                if hasattr(a, "nbytes") and not isinstance(a, (int, float, str)) and getattr(a, "nbytes", 0) > (1 << 16):
                    if id(a) not in scattered:
                        scattered[id(a)] = client.scatter(a, broadcast=False)
                    sent.append(scattered[id(a)])
                else:
                    sent.append(a)
            futures[client.submit(_on_dask_worker, host_threads, fn, *sent, pure=False)] = key
            signals.check()
        pending = set(futures)
        while pending:
            try:
                done, pending = dask_wait(list(pending), timeout=0.2, return_when="FIRST_COMPLETED")
            except TimeoutError:
                done = set()
            for fut in done:
                on_result(futures[fut], fut.result())
            pending = set(pending)
            signals.check()
    except BaseException as exc:
        with contextlib.suppress(Exception):
            client.cancel(list(futures))
        if isinstance(exc, KeyboardInterrupt):
            raise _as_interrupted(exc) from None
        raise
