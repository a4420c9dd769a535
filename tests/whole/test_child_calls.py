"""Library passes that cannot be interrupted run in a child process inside the commands.

pymeshlab's quadric collapse takes no stop flag; in the main thread an interrupt had to
wait for the pass to end (4.3 s after SIGINT on a 600² DEM here, 21–23 s on a 0.77 Mpx
DEM in issue 42). Inside :func:`terrainvis.core.interrupt.child_calls` (every command) a
pass of :data:`~terrainvis.core.interrupt.CHILD_MIN_WORK` vertices or more runs in a child
process, which the interrupt kills. The stand-in for the library here is a function that
blocks SIGINT and sleeps, in a module the child imports by name.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from terrainvis.core import interrupt

#: A module the spawned children import: the stand-ins for a library call.
_HELPERS = """
import os, signal, time

def add(a, b):
    return a + b

def refuse(text):
    raise ValueError(text)

def die(code):
    os._exit(code)

def unpicklable():
    return lambda: None

def stubborn(marker, seconds):
    # a C++ library's pass: no signal reaches Python until it returns
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    with open(marker, "w") as fh:
        fh.write(str(os.getpid()))
    time.sleep(seconds)
    return "finished"
"""


@pytest.fixture
def helpers(tmp_path, monkeypatch):
    (tmp_path / "childhelpers.py").write_text(_HELPERS)
    monkeypatch.syspath_prepend(str(tmp_path))  # a spawned child starts with the parent's sys.path
    import importlib

    return importlib.import_module("childhelpers")


def test_a_child_call_returns_the_result_and_raises_the_childs_error(helpers):
    assert interrupt.call_in_child(helpers.add, np.arange(3), 1, what="adding").tolist() == [1, 2, 3]
    with pytest.raises(ValueError, match="no thanks"):
        interrupt.call_in_child(helpers.refuse, "no thanks", what="refusing")
    with pytest.raises(RuntimeError, match=r"dying ended in its child process without an answer \(exit code 3\)"):
        interrupt.call_in_child(helpers.die, 3, what="dying")
    with pytest.raises(RuntimeError, match="could not be sent back"):
        interrupt.call_in_child(helpers.unpicklable, what="a lambda")


def test_child_calls_only_inside_the_block_in_the_main_thread_from_the_threshold():
    import threading

    work = interrupt.CHILD_MIN_WORK
    assert not interrupt.abandonable(work)
    with interrupt.child_calls():
        assert interrupt.abandonable(work) and not interrupt.abandonable(work - 1)
        seen = []
        t = threading.Thread(target=lambda: seen.append(interrupt.abandonable(work)))
        t.start()
        t.join()
        assert seen == [False]
    assert not interrupt.abandonable(work)


def test_sigint_kills_a_stubborn_child_at_once(helpers, tmp_path):
    """The caller raises KeyboardInterrupt within a second of SIGINT, and the child is gone."""
    marker = tmp_path / "child.pid"
    script = textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {str(tmp_path)!r})
        import childhelpers
        from terrainvis.core import interrupt
        if __name__ == "__main__":
            with interrupt.child_calls():
                t0 = time.perf_counter()
                try:
                    interrupt.call_in_child(childhelpers.stubborn, {str(marker)!r}, 30.0, what="a stubborn pass")
                except KeyboardInterrupt:
                    print("caught", time.time(), flush=True)
                    sys.exit(130)
            print("not interrupted", time.perf_counter() - t0, flush=True)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.monotonic() + 60.0
    while not (marker.exists() and marker.read_text()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert marker.exists(), "the child never started"
    child = int(marker.read_text())
    sent = time.time()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, (out, err)
    caught = float(out.split()[1])
    assert caught - sent < 1.0, f"the caller took {caught - sent:.2f} s to raise"
    with pytest.raises(ProcessLookupError):  # killed and reaped: no such process any more
        os.kill(child, 0)


def test_qec_in_a_child_is_qec_here(monkeypatch):
    """A pass in the child gives the same mesh as in this process (pymeshlab is deterministic)."""
    import simplifiers.quadric as quadric
    from simplifiers import simplify
    from terrainvis import bundled_terrain

    g = bundled_terrain("ridges")
    here = simplify(g, "qec", 2)
    ran = []
    real = quadric.call_in_child

    def counted(fn, *args, **kwargs):
        ran.append(fn.__name__)
        return real(fn, *args, **kwargs)

    monkeypatch.setattr(quadric, "call_in_child", counted)
    monkeypatch.setattr(interrupt, "CHILD_MIN_WORK", 1000)
    with interrupt.child_calls():
        there = simplify(g, "qec", 2)
    assert ran and set(ran) == {"_pymeshlab_pass"}
    np.testing.assert_array_equal(there.vertices, here.vertices)
    np.testing.assert_array_equal(there.faces, here.faces)
