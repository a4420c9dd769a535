"""Interrupting long numba kernels: Ctrl-C and SIGTERM stop them within about a second.

numba's compiled code never runs Python's signal handlers, so a kernel that runs for a
minute ignores Ctrl-C for a minute; worse, the handler then runs while numba turns the
kernel's result into Python objects, and the interrupt surfaces as a ``SystemError``
("returned a result with an exception set") or a segmentation fault. Module-level
arrays are frozen into a kernel as constants, so a kernel cannot watch a global flag.
This module is the one mechanism every long kernel uses instead:

1. The kernel takes a *stop flag*, a ``(1,)`` int64 array, as its last argument, and at a
   bounded interval (an outer loop iteration, a chunk of its loop) checks
   ``if stopped(stop)`` (:func:`terrainvis.core.stopflag.stopped`, an atomic read) and
   returns early. Its partial result is never used.
2. The Python wrapper runs it with :func:`call` (``call(kernel, *args, work=n)``), which
   appends a fresh flag. Above :data:`THREAD_MIN_WORK` units of work, and only in the
   main thread (the only one that receives signals), :func:`call` runs the kernel in a
   helper thread (the kernels are ``nogil``) while the main thread waits on an event in
   short steps, where Python runs its signal handlers. When the wait raises (the
   ``KeyboardInterrupt`` of SIGINT, the :class:`terrainvis.core.runner.Interrupted` that the
   CLI's SIGTERM handler raises, or anything else), :func:`call` sets the flag, waits
   for the kernel to return (at most :data:`_STOP_GRACE` seconds, a safety net: a kernel
   that does not see its flag in time finishes in its daemon thread) and re-raises the
   same exception. The result is boxed in
   the helper thread, where no signal handler runs, so an interrupt can no longer land
   inside numba's boxing.
3. Small calls run directly in the calling thread: starting a thread costs about
   0.1 ms, far more than a kernel over a few thousand samples.
4. Outside the main thread :func:`call` runs the kernel directly. A thread that runs
   units for :func:`terrainvis.core.runner.run_units` (its ``threads`` mode) first
   passes a flag shared by the run to :func:`thread_flag`; its kernels then take that
   flag, and :func:`call` raises :class:`terrainvis.errors.Interrupted` once it is set, so
   the main thread stops every unit within a ring of a sweep.

Libraries in C++ (pymeshlab, fast-simplification) take no flag, and are interrupted
between their passes, when the call returns. Leaving such a call running in an
abandoned thread is not safe: a process that exits while pymeshlab still works in
another thread was seen to wait for it and then abort on a corrupted heap. A command
(inside :func:`child_calls`) runs a long library pass in a child process instead
(:func:`abandonable`, :func:`call_in_child`), which an interrupt kills at once: Ctrl-C
under pymeshlab's 20 s pass on a 0.6 Mpx DEM waited for the pass to end.

A kernel that calls other kernels passes its flag down to the ones that loop long. The
flag is read with :func:`~terrainvis.core.stopflag.stopped`, never as a plain ``stop[0]``:
another thread writes it, and a plain read in a ``prange`` body was hoisted out of the
loop by the compiler, so those kernels ran to their end (see :mod:`terrainvis.core.stopflag`).

Parallel loops are serial kernels too: a kernel over a range of a loop's iterations
(``kernel(*args, lo, hi, stop)``), which :func:`call` runs on numba's number of threads
(``items=``), each thread taking the next chunk of iterations when it is done with one,
all of them reading the one flag. terrainvis has no ``prange`` loop: numba's parfor
passes cost a first run seconds per loop (the pair walk's took 11.6 s of the 13.7 s that
``assert_visibility_kept`` compiled), and one thread needed a serial twin. The tests in ``tests/whole/test_interrupt_kernels.py``
interrupt every long kernel in a subprocess and check that the caller raises and that
the kernel's own thread ends, both within two seconds.

Examples
--------
>>> import numba, numpy as np
>>> from terrainvis.core.stopflag import stopped
>>> @numba.njit(nogil=True)
... def total(a, stop):
...     s = 0.0
...     for i in range(a.shape[0]):
...         if i % 4096 == 0 and stopped(stop):
...             return s
...         s += a[i]
...     return s
>>> call(total, np.ones(10), work=10)
10.0
"""

from __future__ import annotations

import contextlib
import importlib
import os
import signal
import sys
import threading

__all__ = ["call", "new_flag", "THREAD_MIN_WORK", "PARALLEL_MIN_WORK", "deferred_signals", "import_library",
           "kept_interrupts", "raise_pending", "call_library", "thread_flag", "alongside", "child_calls",
           "abandonable", "call_in_child", "CHILD_MIN_WORK"]

#: Units of work (samples, faces, cells: what the caller counts) from which :func:`call`
#: runs a kernel in a helper thread. Below it a kernel takes well under 10 ms.
THREAD_MIN_WORK = 1 << 18

#: Units of work from which :func:`call` spreads a loop (``items``) over threads: starting
#: a thread costs about 0.1 ms, a unit (a sight line, a sample) a microsecond or more.
PARALLEL_MIN_WORK = 1 << 12

#: Seconds between two wakes of the waiting main thread (signals wake it at once anyway).
_JOIN_STEP = 0.25

#: Seconds an interrupted caller waits for a kernel to see its stop flag before it raises anyway.
_STOP_GRACE = 1.0


#: The signals that :func:`kept_interrupts`' handlers received, first first (empty outside the CLI).
_pending: list[int] = []

#: Per thread: the stop flag that :func:`thread_flag` set for the kernels :func:`call` starts there.
_local = threading.local()


@contextlib.contextmanager
def kept_interrupts():
    """SIGINT and SIGTERM end the block, even when C code swallows the exception they raise.

    The handlers raise as Python's own do (``KeyboardInterrupt`` for SIGINT,
    :class:`terrainvis.errors.Interrupted` for SIGTERM), and they also note the signal. A
    Ctrl-C that lands while llvmlite runs one of its ctypes callbacks (when numba loads
    or compiles a kernel) raises inside the callback: ctypes prints "Exception ignored on
    calling ctypes callback function" and the run went on to the end, exit status 0.
    The note survives: the next :func:`call` raises it again (:func:`raise_pending`), and
    the CLI checks it when the command returns. Only the main thread can install
    handlers; elsewhere the block runs as it is. Used by :func:`terrainvis.cli.main`.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        _pending.append(signum)
        _raise(signum)

    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(ValueError, OSError, TypeError):
            previous[sig] = signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig, old in previous.items():
            with contextlib.suppress(ValueError, OSError, TypeError):
                signal.signal(sig, old)
        _pending.clear()


def _raise(signum: int):
    from ..errors import Interrupted

    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Interrupted(signum)


def raise_pending() -> None:
    """Raise the first interrupt :func:`kept_interrupts` noted, if any (a no-op outside it)."""
    if _pending:
        _raise(_pending[0])


def new_flag():
    """A fresh stop flag: a ``(1,)`` int64 array holding 0 (go on)."""
    import numpy as np  # here: the CLI imports this module before it knows it needs numpy

    return np.zeros(1, dtype=np.int64)


def call(kernel, *args, work: int, items: int | None = None, grain: int = 1, min_parallel: int | None = None):
    """``kernel(*args, stop)``, interruptible by SIGINT and SIGTERM (see the module docstring);
    with ``items``, a loop of independent iterations spread over threads.

    Parameters
    ----------
    kernel : numba dispatcher
        A ``nogil`` kernel whose last parameter is the stop flag. With ``items`` it takes
        ``(*args, lo, hi, stop)`` and runs iterations ``lo .. hi - 1`` of a loop of
        ``items`` iterations that write disjoint parts of its outputs.
    *args
        Its other arguments.
    work : int
        The size of the call (samples, faces, sight lines: any count proportional to its
        time). Calls of at least :data:`THREAD_MIN_WORK` run in a helper thread; with
        ``items``, calls of at least :data:`PARALLEL_MIN_WORK` run on
        ``numba.get_num_threads()`` helper threads.
    items : int, optional
        The loop's number of iterations. Run on several threads, the threads take
        chunks of iterations in turn (:func:`_chunks`) until none is left, so that
        iterations of uneven cost still keep every thread busy to the end. This is how
        terrainvis runs a loop in parallel: one serial kernel, compiled once, with no
        ``prange`` (whose parfor compilation cost seconds per loop on a first run) and
        no serial twin for one thread.
    grain : int
        The fewest iterations a chunk holds (one call of the kernel costs a few
        microseconds: a chunk should be worth far more).
    min_parallel : int, optional
        The least ``work`` spread over threads (default :data:`PARALLEL_MIN_WORK`).

    Returns
    -------
    What the kernel returns; with ``items``, the sum of what its calls return (a kernel
    that counts returns the count over every iteration, in any order; one that returns
    nothing, None).

    Raises
    ------
    BaseException
        Whatever interrupted the wait (``KeyboardInterrupt``,
        :class:`terrainvis.core.runner.Interrupted`), after the kernel has returned; or the
        kernel's own exception.
    """
    raise_pending()  # an interrupt swallowed by C code since the last call (see kept_interrupts)
    whole = () if items is None else (0, int(items))
    spread = items is not None and items > 1 and work >= (PARALLEL_MIN_WORK if min_parallel is None else min_parallel)
    if threading.current_thread() is not threading.main_thread():
        shared = getattr(_local, "flag", None)
        if shared is None:
            shared = new_flag()
        else:
            _raise_if_set(shared)
        if spread and _threads() > 1:
            out = _run_chunks(kernel, args, int(items), grain, shared)
        else:
            out = kernel(*args, *whole, shared)
        if getattr(_local, "flag", None) is not None:
            _raise_if_set(shared)  # its result may be partial: never used
        return out
    stop = new_flag()
    if spread and _threads() > 1:
        return _run_chunks(kernel, args, int(items), grain, stop)
    if work < THREAD_MIN_WORK:
        return kernel(*args, *whole, stop)
    job = _Job(kernel, *args, *whole, stop)
    try:
        job.wait()
    except BaseException:
        stop[0] = 1
        # a kernel returns within a second of its flag (read with stopflag.stopped); one that
        # did not would be left to finish in its daemon thread, which is safe for numba code
        # (it touches only its own arrays), unlike a C++ library
        job.wait_through(limit=_STOP_GRACE)
        raise
    return job.result()


def _threads() -> int:
    """The threads a parallel loop may use: numba's number for this thread (``NUMBA_NUM_THREADS``,
    :func:`numba.set_num_threads`; a worker of a compare run has one)."""
    import numba

    return max(1, numba.get_num_threads())


#: Chunks per thread a loop is cut into at most: enough for threads that finish early to
#: take over the rest of uneven work, few enough that the calls cost nothing.
CHUNKS_PER_THREAD = 16


def _chunks(items: int, threads: int, grain: int) -> list[tuple[int, int]]:
    """``[0, items)`` cut into consecutive chunks of at least ``grain`` iterations, at most
    :data:`CHUNKS_PER_THREAD` per thread.

    >>> _chunks(10, 2, 1)[:3], len(_chunks(10_000, 2, 1)), _chunks(5, 4, 4)
    ([(0, 1), (1, 2), (2, 3)], 32, [(0, 4), (4, 5)])
    """
    size = max(grain, -(-items // (CHUNKS_PER_THREAD * threads)), 1)
    return [(lo, min(items, lo + size)) for lo in range(0, items, size)]


def _run_chunks(kernel, args, items: int, grain: int, stop):
    """``kernel(*args, lo, hi, stop)`` over the chunks of ``[0, items)`` on helper threads, each
    taking the next chunk when it is done with one; the calling thread waits (in the main
    thread, where signals arrive, as :func:`call` waits for one helper)."""
    threads = _threads()
    todo = _chunks(items, threads, grain)
    lock = threading.Lock()
    position = [0]

    def work():
        total = None
        while not stop[0]:
            with lock:
                k = position[0]
                position[0] += 1
            if k >= len(todo):
                break
            try:
                out = kernel(*args, *todo[k], stop)
            except BaseException:
                with lock:  # no thread takes another chunk: the call has failed
                    position[0] = len(todo)
                raise
            if out is not None:
                total = out if total is None else total + out
        return total

    jobs = [_Job(work) for _ in range(min(threads, len(todo)))]
    try:
        for job in jobs:
            job.wait()
    except BaseException:
        stop[0] = 1
        for job in jobs:
            job.wait_through(limit=_STOP_GRACE)
        raise
    total = None
    for job in jobs:
        out = job.result()
        if out is not None:
            total = out if total is None else total + out
    return total


@contextlib.contextmanager
def thread_flag(flag):
    """In this block, the kernels that :func:`call` starts in this thread take ``flag`` (a
    :func:`new_flag` that another thread may set), and :func:`call` raises
    :class:`terrainvis.errors.Interrupted` before and after a kernel once it is set.

    For threads that run units beside a waiting main thread (signals reach only the main
    thread, which stops the units by setting the flag). In the main thread the block does
    nothing: :func:`call` makes its own flag there.
    """
    if threading.current_thread() is threading.main_thread():
        yield
        return
    previous = getattr(_local, "flag", None)
    _local.flag = flag
    try:
        yield
    finally:
        _local.flag = previous


def _raise_if_set(flag) -> None:
    if flag[0]:
        from ..errors import Interrupted

        raise Interrupted(signal.SIGINT)


@contextlib.contextmanager
def alongside(fn, *, on_interrupt=None):
    """``fn()`` in a helper thread while the block runs in this one; its error, if any, is
    raised when the block ends.

    For work that can overlap (loading kernels while a file is read, building one table
    while another is built). The block's own error or an interrupt still waits for ``fn``
    to return before it propagates, calling ``on_interrupt()`` first on an interrupt that
    finds ``fn`` still running: a process must not exit while a kernel, LLVM or a library
    works in another thread (see :func:`call_library`). ``fn`` takes no stop flag, so it
    should take well under a second or two.
    """
    job = _Job(fn)
    try:
        yield
        job.wait()
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt) and on_interrupt is not None and not job.finished():
            on_interrupt()
        job.wait_through()
        raise
    job.result()


#: Units of work (a mesh's vertices) from which a library pass runs in a child process
#: inside :func:`child_calls`: pymeshlab's quadric collapse takes about 3 s there on this
#: project's machine, and starting the child about 1 s.
CHILD_MIN_WORK = 1 << 17

#: Whether library passes may run in a child process (only inside :func:`child_calls`).
_child_calls = threading.local()


@contextlib.contextmanager
def child_calls():
    """Inside the block, :func:`abandonable` passes of the main thread run in a child process.

    The commands use it. The Python API does not: a spawned child imports the caller's
    main module again, and a user's script without ``if __name__ == "__main__":`` would
    run again there.
    """
    before = getattr(_child_calls, "on", False)
    _child_calls.on = True
    try:
        yield
    finally:
        _child_calls.on = before


def abandonable(work: int) -> bool:
    """Whether a library pass over ``work`` units should run in a child process: inside
    :func:`child_calls`, in the main thread, from :data:`CHILD_MIN_WORK` units of work."""
    return (getattr(_child_calls, "on", False) and work >= CHILD_MIN_WORK
            and threading.current_thread() is threading.main_thread())


def call_in_child(fn, *args, what: str, **kwargs):
    """``fn(*args, **kwargs)`` in a spawned child process, killed at once by an interrupt.

    ``fn`` must be importable by name (a module-level function) and its arguments and
    result picklable. The child ignores SIGINT (a terminal sends it to the whole process
    group): the parent decides, kills the child and re-raises. An exception in ``fn`` is
    raised here; a child that dies without an answer raises a ``RuntimeError`` naming
    ``what`` and its exit code.
    """
    import multiprocessing

    raise_pending()
    ctx = multiprocessing.get_context("spawn")
    receiver, sender = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child_main, args=(sender, fn, args, kwargs), daemon=True,
                        name=f"terrainvis: {what}")
    child.start()
    sender.close()
    try:
        while not receiver.poll(_JOIN_STEP / 5):  # signal handlers run between the polls
            pass
        try:
            ok, value = receiver.recv()
        except EOFError:  # the child ended without sending (a crash, os._exit, killed by the system)
            child.join()
            raise RuntimeError(f"{what} ended in its child process without an answer (exit code "
                               f"{child.exitcode})") from None
    except BaseException:
        if child.is_alive():
            child.kill()
        child.join()
        raise
    finally:
        receiver.close()
    child.join()
    if not ok:
        raise value
    return value


def _child_main(sender, fn, args, kwargs) -> None:
    """The child of :func:`call_in_child`: run ``fn``, send ``(ok, result or exception)``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        answer = (True, fn(*args, **kwargs))
    except BaseException as exc:  # handed to the parent
        answer = (False, exc)
    try:
        sender.send(answer)
    except Exception as exc:  # an unpicklable result or exception: say what it was
        sender.send((False, RuntimeError(f"the child's answer could not be sent back: {exc!r}")))
    sender.close()


def call_library(fn, *args, what: str, **kwargs):
    """``fn(*args, **kwargs)``, a library's call that takes no stop flag, with an interrupt answered at once.

    In the main thread the call runs in a helper thread (pymeshlab and fast-simplification
    release the GIL) and the main thread waits on an event in short steps. An interrupt meanwhile is
    answered at once on stderr, saying that the stop waits for ``what`` to return and
    why (leaving a C++ library running while the process exits was seen to abort on a
    corrupted heap); the call is then waited for, further interrupts repeat the note, and
    the first is raised. Elsewhere the call runs as it is.
    """
    raise_pending()
    if threading.current_thread() is not threading.main_thread():
        return fn(*args, **kwargs)
    job = _Job(fn, *args, **kwargs)
    try:
        job.wait()
    except BaseException:
        note = (f"terrainvis: stopping once {what} returns: it cannot be interrupted, and a process must not "
                "exit while it runs")
        print(note, file=sys.stderr, flush=True)
        job.wait_through(lambda: print(note, file=sys.stderr, flush=True))
        raise
    return job.result()


class _Job:
    """``fn(*args, **kwargs)`` started in a daemon helper thread, its result or exception boxed there.

    Waiting uses an Event, not ``Thread.join``: in Python 3.11 a join that an interrupt
    cuts short marks a thread that is still running as stopped (the bpo-45274 fix
    releases its state lock), so later joins return at once and the caller would stop
    waiting for a kernel or a library that still works.

    The helper thread runs numba's parallel kernels on as many threads as the caller
    would: numba keeps that number per thread, and a new thread starts from the default
    (all cores), so a worker of a compare run, set to one thread, ran its large parallel
    calls on every core beside the other workers.
    """

    def __init__(self, fn, *args, **kwargs):
        self._box = {}
        self._done = threading.Event()
        numba = sys.modules.get("numba")  # not imported for it: a library call needs none
        threads = numba.get_num_threads() if hasattr(numba, "get_num_threads") else None  # (None: not yet imported)

        def target():
            try:
                if threads is not None:
                    numba.set_num_threads(threads)
                self._box["value"] = fn(*args, **kwargs)
            except BaseException as exc:  # handed to the caller's thread
                self._box["error"] = exc
            finally:
                self._done.set()

        threading.Thread(target=target, name="terrainvis-call", daemon=True).start()

    def finished(self) -> bool:
        """Whether the call has returned (or raised)."""
        return self._done.is_set()

    def wait(self) -> None:
        """Until the call returns; an interrupt (a signal handler's exception) ends the wait."""
        while not self._done.wait(_JOIN_STEP):
            pass

    def wait_through(self, on_interrupt=None, limit: float | None = None) -> None:
        """Until the call returns (or ``limit`` seconds), whatever interrupts meanwhile (each calls ``on_interrupt``)."""
        import math
        import time

        end = math.inf if limit is None else time.monotonic() + limit
        while True:
            try:
                while not self._done.wait(max(0.0, min(_JOIN_STEP, end - time.monotonic()))):
                    if time.monotonic() >= end:
                        return
                return
            except BaseException:
                if on_interrupt is not None:
                    on_interrupt()

    def result(self):
        if "error" in self._box:
            raise self._box["error"]
        return self._box["value"]


@contextlib.contextmanager
def deferred_signals():
    """Hold SIGINT and SIGTERM until the block ends, then deliver them to the handlers that were installed.

    For code that turns an interrupt into something else: ``import pymeshlab`` interrupted
    by Ctrl-C fails with "ImportError: initialization failed", which would be reported as
    a broken install instead of the user's stop. Only the main thread can change signal
    handlers; elsewhere the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught = []
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(ValueError, OSError, TypeError):
            previous[sig] = signal.signal(sig, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        for sig, old in previous.items():
            with contextlib.suppress(ValueError, OSError, TypeError):
                signal.signal(sig, old)
        for signum in caught[:1]:
            old = previous.get(signum)
            if callable(old):
                old(signum, sys._getframe())
            elif old == signal.SIG_DFL:
                os.kill(os.getpid(), signum)  # the default action, now that it is back


def import_library(name: str):
    """``importlib.import_module(name)`` with interrupts held until the import ends (:func:`deferred_signals`)."""
    module = sys.modules.get(name)
    if module is not None:
        return module
    with deferred_signals():
        return importlib.import_module(name)
