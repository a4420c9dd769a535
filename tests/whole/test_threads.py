"""Kernels with a serial twin (used when numba has one thread, as in the workers of a
compare run, to spare the parfor compilation) give the same bits as the parallel ones."""

from __future__ import annotations

import numba
import numpy as np
import pytest

import simplifiers
import terrainvis as tv
from terrainvis.io import bundled_terrain


def _with_threads(n, fn):
    before = numba.get_num_threads()
    numba.set_num_threads(n)
    try:
        return fn()
    finally:
        numba.set_num_threads(before)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two numba threads")
def test_one_thread_and_two_give_the_same_bits():
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
        out.append(np.array([tv.volume_error(t, grid), tv.volume_error(t, tin)]))  # volume_between
        out.append(tv.viewshed(t, (t.xs[40], t.ys[50]), output="min_height"))  # grid_eye_thresholds
        out.append(tv.viewshed(tin, (t.xs[40], t.ys[50]), at=t, output="angle"))  # tin_eye_thresholds
        return out

    one = _with_threads(1, run)
    two = _with_threads(2, run)
    for a, b in zip(one, two):
        assert np.array_equal(a, b)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two numba threads")
def test_for_threads_picks_the_serial_twin_with_one_thread():
    from terrainvis.core.interrupt import for_threads

    assert _with_threads(1, lambda: for_threads("parallel", "serial")) == "serial"
    assert _with_threads(2, lambda: for_threads("parallel", "serial")) == "parallel"
