"""Fault injection: interrupt ``terrainvis compare`` at random moments, resume, and get the same table.

Every kind of stop a user meets: Ctrl-C (SIGINT to the whole process group), a notebook's
interrupt (SIGINT to the main process only), SIGTERM (a scheduler or ``kill``) and SIGKILL
(nothing can be cleaned up). After each, no worker process may survive, and ``--resume``
must finish the run; the final ``results.csv`` must equal an uninterrupted run's on every
column that is not a timing.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest

from terrainvis.experiment.collect import COLUMNS, TIMING_COLUMNS

psutil = pytest.importorskip("psutil", reason="psutil (installed with the dask extra) lists the worker processes")

ARGS = ["compare", "--terrain", "hills", "ridges", "--levels", "1", "2", "--methods", "simple", "lls",
        "greedy-insertion", "--points", "10", "--sets", "2", "--repeats", "1", "--no-plots", "--no-volume",
        "--workers", "2", "--partners", "512"]  # the calibrated relocation's core alone: units of about a second
STABLE = [c for c in COLUMNS if c not in TIMING_COLUMNS]


def _start(out, resume: bool):
    cmd = [sys.executable, "-m", "terrainvis.cli", *ARGS, "--out", str(out)] + (["--resume"] if resume else [])
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True)


def _family(p):
    try:
        return psutil.Process(p.pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def _stop(p, how: str, after: float):
    """Wait ``after`` seconds, send the signal, and return (exit code, the processes that were running)."""
    time.sleep(after)
    children = _family(p)
    if how == "ctrl-c":
        os.killpg(p.pid, signal.SIGINT)
    elif how == "sigint":
        p.send_signal(signal.SIGINT)
    elif how == "sigterm":
        p.send_signal(signal.SIGTERM)
    else:
        p.kill()
    try:
        p.wait(timeout=20)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        pytest.fail(f"terrainvis compare did not stop within 20 s of {how}")
    return p.returncode, children


def _table(path):
    df = pd.read_csv(path, dtype={"error": str})
    return df[STABLE].sort_values(["terrain", "method", "level", "set", "relocation"]).reset_index(drop=True)


def _finished(out, expected) -> bool:
    """Whether ``out`` holds the whole run (every row of the uninterrupted one)."""
    path = out / "results.csv"
    return path.exists() and _table(path).shape == expected.shape


@pytest.mark.slow
def test_interrupted_runs_resume_to_the_uninterrupted_result(tmp_path):
    t0 = time.perf_counter()
    ref = _start(tmp_path / "ref", resume=False)
    assert ref.wait(timeout=300) == 0, ref.stderr.read()
    whole = time.perf_counter() - t0
    expected = _table(tmp_path / "ref" / "results.csv")

    out = tmp_path / "run"
    rng = np.random.default_rng(20261123)
    codes = {"ctrl-c": 130, "sigint": 130, "sigterm": 143, "sigkill": -signal.SIGKILL}
    late = {"ctrl-c": -signal.SIGINT, "sigint": -signal.SIGINT, "sigterm": -signal.SIGTERM}
    interrupted = []
    for how in ("ctrl-c", "sigterm", "sigkill", "sigint"):
        p = _start(out, resume=True)
        # between a third and four fifths of an uninterrupted run: start-up included, so
        # some units finish before the signal and some do not
        code, children = _stop(p, how, after=float(rng.uniform(0.35, 0.8)) * whole)
        err = p.stderr.read()
        if code == 0:  # the run finished before the signal: nothing left to interrupt
            break
        if code == late.get(how) and _finished(out, expected):
            # the run had finished and was exiting: once Python is finalising, the signal's
            # default action ends the process (a shell reports SIGINT's as 130 all the same)
            break
        interrupted.append(how)
        assert code == codes[how], (how, code, err)
        if how != "sigkill":
            assert "interrupted" in err and "Traceback" not in err, err
        _, alive = psutil.wait_procs(children, timeout=10)
        assert not alive, f"worker processes survived {how}: {alive}"
    assert len(interrupted) >= 2, f"only {interrupted} stopped a run before it finished; the test proved little"
    final = _start(out, resume=True)
    assert final.wait(timeout=300) == 0, final.stderr.read()
    pd.testing.assert_frame_equal(_table(out / "results.csv"), expected, check_dtype=False)


_POOL_SCRIPT = """
import sys, time
from terrainvis.core.runner import Interrupted, run_units

def nap(i):
    time.sleep(60)
    return i

if __name__ == "__main__":
    print("running", flush=True)
    try:
        run_units([(i, (i,)) for i in range(4)], nap, on_result=lambda key, result: None, workers=2)
    except Interrupted as exc:
        print(exc, file=sys.stderr)
        sys.exit(130)
"""


def test_ctrl_c_while_the_workers_are_still_starting(tmp_path):
    """Ctrl-C before the workers have imported terrainvis: an interrupt, not a broken pool."""
    script = tmp_path / "pool.py"
    script.write_text(_POOL_SCRIPT)
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, start_new_session=True)
    assert p.stdout.readline().strip() == "running"
    deadline = time.monotonic() + 30
    workers = []
    while len(workers) < 2 and time.monotonic() < deadline:  # both spawned, neither ready yet
        workers = [c for c in _family(p) if "spawn_main" in " ".join(c.cmdline())]
        time.sleep(0.005)
    assert len(workers) == 2, "the pool did not start its workers"
    assert not any(w.status() == psutil.STATUS_ZOMBIE for w in workers)
    os.killpg(p.pid, signal.SIGINT)
    try:
        p.wait(timeout=20)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        pytest.fail("the pool did not stop within 20 s of Ctrl-C")
    err = p.stderr.read()
    assert p.returncode == 130, err
    assert "interrupted by SIGINT" in err and "Traceback" not in err, err
    _, alive = psutil.wait_procs(workers, timeout=10)
    assert not alive, f"worker processes survived: {alive}"


def test_an_interrupt_swallowed_inside_a_unit_still_stops_a_serial_run():
    """numba's compiler runs Python callbacks from C, where the handler's exception is printed
    and dropped (seen as "Exception ignored on calling ctypes callback function"): the run
    must stop after that unit all the same, without saving what the unit returned."""
    from terrainvis.core.runner import Interrupted, run_units

    def unit(i):
        if i == 1:
            try:  # the signal lands where its exception goes nowhere
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(1.0)
            except KeyboardInterrupt:
                pass
            return "unit 1, run while the interrupt was lost"
        return f"unit {i}"

    saved = []
    with pytest.raises(Interrupted):
        run_units([(i, (i,)) for i in range(3)], unit, on_result=lambda key, result: saved.append(result), workers=1)
    assert saved == ["unit 0"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the run's handler is gone


# ----------------------------------------------------------------- units on threads of this process
def test_threads_run_the_units_beside_each_other_with_numba_on_one_thread():
    """``threads=2``: every unit runs in a unit thread with numba on one thread, two at a
    time (each waits for the other to start), and this thread keeps its own numba threads."""
    import threading

    import numba

    from terrainvis.core.runner import run_units

    before = numba.get_num_threads()
    started = threading.Barrier(2, timeout=20)

    def unit(i):
        started.wait()  # both units run at once, or this times out
        return threading.current_thread().name, numba.get_num_threads()

    got = {}
    run_units([(i, (i,)) for i in range(4)], unit, on_result=got.__setitem__, workers=1, threads=2)
    assert sorted(got) == [0, 1, 2, 3]
    assert all(name.startswith("terrainvis-unit") and n == 1 for name, n in got.values()), got
    assert numba.get_num_threads() == before


def test_a_failing_unit_on_a_thread_stops_the_others():
    """A unit's error reaches the caller; the other unit's kernel sees the shared flag and
    stops, and no unit thread outlives the call."""
    import threading

    import numba

    from terrainvis.core.interrupt import call
    from terrainvis.core.runner import run_units
    from terrainvis.core.stopflag import stopped

    @numba.njit(nogil=True)
    def spin(seconds_of_work, stop):
        s = 0.0
        for i in range(seconds_of_work):
            if stopped(stop):
                return -1.0
            for j in range(1_000_000):
                s += j * 1e-9
        return s

    ran = []

    def unit(i):
        if i == 0:
            time.sleep(0.5)
            raise ValueError("unit 0 failed")
        ran.append(i)
        return call(spin, 20_000, work=1)  # about 20 s of work, unless stopped

    t0 = time.monotonic()
    with pytest.raises(ValueError, match="unit 0 failed"):
        run_units([(i, (i,)) for i in range(2)], unit, on_result=lambda key, result: None, workers=1, threads=2)
    assert ran == [1]
    assert time.monotonic() - t0 < 10.0, "the spinning unit did not stop"
    assert not [t for t in threading.enumerate() if t.name.startswith("terrainvis-unit")]


def test_a_large_call_s_helper_thread_keeps_the_caller_s_numba_threads():
    """numba keeps its thread count per thread and a new thread starts from the default: the
    helper thread of a large :func:`call` takes the caller's (a worker of a compare run is
    set to one, and its large parallel calls ran on every core)."""
    import threading

    import numba

    from terrainvis.core.interrupt import THREAD_MIN_WORK, call

    def kernel(stop):
        return threading.current_thread().name, numba.get_num_threads()

    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert call(kernel, work=THREAD_MIN_WORK) == ("terrainvis-call", 1)
        if numba.config.NUMBA_NUM_THREADS >= 2:
            numba.set_num_threads(2)
            assert call(kernel, work=THREAD_MIN_WORK) == ("terrainvis-call", 2)
    finally:
        numba.set_num_threads(before)


def _numba_threads(i):
    import numba

    return numba.get_num_threads()


def test_a_unit_on_dask_runs_numba_on_its_thread_s_share_of_the_cores():
    """A dask worker's thread runs its unit's kernels on the cores over the threads of all
    the workers on its machine (numba's default in a fresh thread is every core)."""
    distributed = pytest.importorskip("distributed", reason="the dask extra is not installed")
    import numba

    from terrainvis.core.runner import run_units

    share = min(max(1, (os.cpu_count() or 1) // 2), numba.config.NUMBA_NUM_THREADS)
    for workers, threads in ((1, 2), (2, 1)):  # two threads of one worker, or two one-thread workers, on one machine
        got = {}
        with distributed.LocalCluster(n_workers=workers, threads_per_worker=threads, processes=False,
                                      dashboard_address=None) as cluster:
            with distributed.Client(cluster) as client:
                run_units([(i, (i,)) for i in range(4)], _numba_threads, on_result=got.__setitem__, client=client)
        assert got == {i: share for i in range(4)}, (workers, threads)


def test_a_thread_flag_once_set_stops_calls_in_that_thread():
    """:func:`call` in a unit thread hands the shared flag to the kernel, and raises once it is set."""
    import threading

    from terrainvis.core.interrupt import call, new_flag, thread_flag
    from terrainvis.errors import Interrupted

    flag = new_flag()
    seen = {"shared": []}

    def kernel(x, stop):
        seen["shared"].append(stop is flag)
        return x + 1

    def body():
        with thread_flag(flag):
            seen["before"] = call(kernel, 1, work=1)
            flag[0] = 1
            try:
                call(kernel, 2, work=1)
            except Interrupted:
                seen["raised"] = True
        seen["after"] = call(kernel, 3, work=1)  # outside the block: a fresh flag, no raise

    t = threading.Thread(target=body)
    t.start()
    t.join(10)
    # the set flag raised before its kernel ran; outside the block the kernel got its own flag
    assert seen == {"shared": [True, False], "before": 2, "raised": True, "after": 4}


def test_an_interrupt_that_c_code_swallows_still_ends_the_command():
    # issue 31 item 17: a Ctrl-C landing in one of llvmlite's ctypes callbacks was printed as
    # "Exception ignored on calling ctypes callback" and the command went on to exit 0
    import numba

    from terrainvis.core.interrupt import call, kept_interrupts, raise_pending

    @numba.njit(nogil=True)
    def one(stop):
        return 1

    with kept_interrupts():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)  # the handler runs here
        except KeyboardInterrupt:
            pass  # swallowed, as a ctypes callback does
        with pytest.raises(KeyboardInterrupt):
            call(one, work=1)  # the next kernel call raises it again
        with pytest.raises(KeyboardInterrupt):
            raise_pending()  # and so does the CLI when the command returns
    raise_pending()  # outside the block nothing is pending
    assert call(one, work=1) == 1
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the handler is put back


def test_a_library_call_that_cannot_stop_says_so_at_once_and_is_waited_for(capsys):
    # issue 31 item 17: QEC (pymeshlab) took 28-80 s to stop without a word
    import threading

    from terrainvis.core.interrupt import call_library

    done = []

    def slow(seconds, *, tag):  # releases the GIL, as pymeshlab does
        time.sleep(seconds)
        done.append(tag)
        return tag

    assert call_library(slow, 0.01, tag="a", what="x") == "a"
    timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT))
    second = threading.Timer(0.8, os.kill, (os.getpid(), signal.SIGINT))
    t0 = time.perf_counter()
    timer.start()
    second.start()
    with pytest.raises(KeyboardInterrupt):
        call_library(slow, 2.0, tag="b", what="the slow library")
    waited = time.perf_counter() - t0
    assert done == ["a", "b"] and waited >= 2.0  # the call was not abandoned
    err = capsys.readouterr().err.splitlines()
    note = "terrainvis: stopping once the slow library returns: it cannot be interrupted, and a process must not exit while it runs"
    assert err == [note, note]  # at once, and again for the second Ctrl-C
