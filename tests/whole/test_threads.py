"""Loops on threads: one serial kernel over a range of iterations, run by
``terrainvis.core.interrupt.call`` on numba's number of threads, gives the same bits on
one thread and on two, whatever the order in which the threads take its chunks.

Every kernel that ``call`` spreads over threads (``items=``) is exercised here: the grid
walk (segments, matrix), the viewshed sweep, the TIN clipper, the threshold engine's best
heights and one-eye thresholds, the volume, the reverse Faber filters and solves (LLS,
GLS, feature-aware) and visopt's pair loops.
"""

from __future__ import annotations

import threading

import numba
import numpy as np
import pytest

import simplifiers
import terrainvis as tv
from terrainvis.core import interrupt
from terrainvis.io import bundled_terrain

TWO = pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two numba threads")


def _with_threads(n, fn):
    before = numba.get_num_threads()
    numba.set_num_threads(n)
    try:
        return fn()
    finally:
        numba.set_num_threads(before)


@TWO
def test_one_thread_and_two_give_the_same_bits(monkeypatch):
    # every call here spreads over threads, however small (the chunks are then few and short)
    monkeypatch.setattr(interrupt, "PARALLEL_MIN_WORK", 1)
    t = bundled_terrain("hills")
    grid = simplifiers.simplify(t, "lls", 1)
    tin = simplifiers.simplify(t, "greedy-insertion", 1)
    pts = tv.sample_points(t, 30, seed=3, offset=2.0)

    def run():
        out = []
        for s in (grid, tin):
            s._cache.clear()  # the partners are cached on S(T): computed anew with these threads
            out.append(tv.relocate(pts, s, "calibrated", original=t, offset=2.0, n_partners=64))  # *_heights
        out.append(tv.min_clearance(tin, pts[:15], pts[15:]))  # tin_pairs
        out.append(tv.min_clearance(t, pts[:15], pts[15:]))  # grid_walks, segments
        out.append(tv.visibility_matrix(t, pts))  # grid_walks, matrix
        out.append(tv.viewshed(t, (t.xs[40], t.ys[50])))  # sweep
        out.append(np.array([tv.volume_error(t, grid), tv.volume_error(t, tin)]))  # volume_between
        out.append(tv.viewshed(t, (t.xs[40], t.ys[50]), output="min_height"))  # grid_eye_thresholds
        out.append(tv.viewshed(tin, (t.xs[40], t.ys[50]), at=t, output="angle"))  # tin_eye_thresholds
        for method in ("lls", "gls", "feature"):  # the filters, the solves, the feature-aware solve
            out.append(simplifiers.simplify(t, method, 2).z)
        out.append(simplifiers.simplify(t, "visopt", 2, n_train=40, rounds=1).z)  # visopt's pair loops
        return out

    one = _with_threads(1, run)
    two = _with_threads(2, run)
    for a, b in zip(one, two):
        assert np.array_equal(a, b)


def test_the_chunks_cover_the_loop_once():
    for items in (1, 2, 7, 31, 32, 33, 1000, 10_001):
        for threads in (1, 2, 3, 8):
            for grain in (1, 4, 100):
                chunks = interrupt._chunks(items, threads, grain)
                assert [lo for lo, _ in chunks] == [0] + [hi for _, hi in chunks[:-1]]
                assert chunks[-1][1] == items and all(lo < hi for lo, hi in chunks)
                assert len(chunks) <= max(1, interrupt.CHUNKS_PER_THREAD * threads)
                assert all(hi - lo >= grain for lo, hi in chunks[:-1])


@TWO
def test_call_runs_every_chunk_once_on_several_threads_and_sums_the_returns():
    seen = []
    names = set()
    lock = threading.Lock()

    def kernel(scale, lo, hi, stop):
        with lock:
            seen.extend(range(lo, hi))
            names.add(threading.current_thread().name)
        return scale * (hi - lo)

    total = _with_threads(2, lambda: interrupt.call(kernel, 3, work=10**6, items=1000))
    assert sorted(seen) == list(range(1000)) and total == 3000
    assert names == {"terrainvis-call"}  # the helper threads, not the caller
    # one thread: the whole range in one call (a large one in a helper thread, for Ctrl-C)
    seen.clear()
    assert _with_threads(1, lambda: interrupt.call(kernel, 1, work=10**6, items=1000)) == 1000
    assert seen == list(range(1000))
    # little work: the whole range in one call, in this thread
    names.clear()
    assert _with_threads(2, lambda: interrupt.call(kernel, 1, work=10, items=50)) == 50
    assert names == {threading.current_thread().name}


@TWO
def test_an_error_in_a_chunk_reaches_the_caller_and_stops_the_others():
    calls = []

    def kernel(lo, hi, stop):
        calls.append(lo)
        if lo == 0:
            raise ZeroDivisionError("in the first chunk")
        return None

    with pytest.raises(ZeroDivisionError, match="in the first chunk"):
        _with_threads(2, lambda: interrupt.call(kernel, work=10**6, items=10**5))
    assert len(calls) < interrupt.CHUNKS_PER_THREAD * 2
