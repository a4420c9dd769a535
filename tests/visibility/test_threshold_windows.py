"""Windows of the threshold engine: thresholds walked exactly only near a point's height.

A window walk (``grid_clamped``, ``tin_clamped``) skips what cannot exceed its floor and
stops at its cap; the best height chosen from a window's thresholds is kept only when
the most favourable thresholds the window allows (``optimistic``) still choose inside it,
and every threshold is walked exactly otherwise. So a window changes the cost, never the
heights: these tests hold the windowed kernels to the exact ones bit for bit, on grids
walked cell by cell and through the pyramid, on TINs, flat and curved, with and without
an end radius, with windows from far too narrow (every row walked again) to wide.
"""

from __future__ import annotations

import numpy as np
import pytest

import simplifiers
import terrainvis as tv
from terrainvis.core.compiling import from_python
from terrainvis.core.surface import face_at
from terrainvis.core.synthetic import synthetic_terrain
from terrainvis.relocation import calibrated as cal
from terrainvis.visibility import _threshold_kernels as tk
from terrainvis.visibility import thresholds
from terrainvis.visibility._kernels import new_stack

# kernels without a Python entry of their own (terrainvis.core.compiling.KERNEL_ONLY) or inlined by
# numba into their callers (the clamped walks), called here through one made for them
face_at = from_python(face_at)
new_stack = from_python(new_stack)
grid_threshold = from_python(tk.grid_threshold)
tin_threshold = from_python(tk.tin_threshold)
grid_clamped = from_python(tk.grid_clamped)
tin_clamped = from_python(tk.tin_clamped)
optimistic = from_python(tk.optimistic)

EARTH = 6378137.0 / 400.0  # a small earth: a bulge of metres on these terrains


def _surfaces():
    """A small grid (cell walk), a large one (pyramid walk) and a TIN, with their names."""
    small = synthetic_terrain("hills", size=40, seed=3)
    large = synthetic_terrain("rough", size=300, seed=4)
    tin = simplifiers.simplify(synthetic_terrain("mountains", size=60, seed=5), "qec", 1)
    return {"small grid": small, "large grid": large, "tin": tin}


SURFACES = _surfaces()


def _inside(terrain, n, rng):
    xmin, xmax, ymin, ymax = terrain.extent
    return np.column_stack([rng.uniform(xmin, xmax, n), rng.uniform(ymin, ymax, n)])


def _points(terrain, n, rng, above):
    xy = _inside(terrain, n, rng)
    return np.column_stack([xy, terrain.height_at(xy) + rng.uniform(0.0, above, n)])


@pytest.mark.parametrize("name", list(SURFACES))
@pytest.mark.parametrize("curved", [False, True])
@pytest.mark.parametrize("end_radius", [0.0, 1.5])
def test_a_window_walk_is_exact_inside_and_a_bound_outside(name, curved, end_radius):
    terrain = SURFACES[name]
    surf = thresholds.ThresholdSurface(terrain)
    kc = tv.visibility.curvature_coefficient(0.85714, EARTH) if curved else 0.0
    rules = surf.rules(end_radius=end_radius, kc=kc)
    rng = np.random.default_rng(7)
    p = surf.local(_points(terrain, 60, rng, 20.0))
    q = surf.local(_points(terrain, 60, rng, 20.0))
    stack = new_stack(surf.ltop)
    states = set()
    for i in range(p.shape[0]):
        pi = (p[i, 0], p[i, 1], p[i, 2])
        for k in range(q.shape[0]):
            qk = (q[k, 0], q[k, 1], q[k, 2])
            if surf.grid:
                exact = grid_threshold(surf.data, stack, pi, qk, rules)
            else:
                exact = tin_threshold(surf.data, None, pi, qk, rules)
            for half in (0.05, 2.0, 30.0):
                lo, hi = p[i, 2] - half, p[i, 2] + half
                if surf.grid:
                    z, state = grid_clamped(surf.data, stack, pi, qk, rules, lo, hi, -1)
                else:
                    z, state = tin_clamped(surf.data, None, pi, qk, rules, lo, hi, face_at(surf.data, pi[0], pi[1]))
                states.add(int(state))
                if state == 0:
                    assert z == exact  # bit for bit
                    assert exact == -np.inf or lo < exact < hi
                elif state < 0:
                    assert exact <= z and z == pytest.approx(lo, abs=1e-9 * (1.0 + abs(lo)))
                else:
                    assert exact >= z and z >= hi - 1e-9 * (1.0 + abs(hi))
    assert states == {-1, 0, 1}  # every case was met


def test_optimistic_thresholds_by_hand():
    # thresholds known: exact 1.0; at most 0.0 (seen on T / not); at least 3.0 (seen on T / not)
    thr = np.array([1.0, 0.0, 0.0, 3.0, 3.0])
    state = np.array([0, -1, -1, 1, 1], dtype=np.int8)
    vis = np.array([True, True, False, True, False])
    lo, hi = optimistic(thr, state, vis)
    assert (lo, hi) == (0.0, 3.0)
    assert thr.tolist() == [1.0, -np.inf, 0.0, 3.0, np.inf]


def _rows(terrain, rng, above, n_points=40, n_partners=120, neighbours=12):
    surf = thresholds.ThresholdSurface(terrain)
    p = surf.local(_points(terrain, n_points, rng, above))
    q = surf.local(_points(terrain, n_partners, rng, above))
    vis = rng.random((n_points, n_partners)) < 0.4
    lthr = p[:, 2:3] + rng.normal(0.0, 1.0, (n_points, neighbours))
    lthr[:, 0] = -np.inf
    lvis = rng.integers(-1, 2, (n_points, neighbours)).astype(np.int8)
    return surf, p, q, vis, lthr, lvis


@pytest.mark.parametrize("name", list(SURFACES))
@pytest.mark.parametrize("above", [0.0, 8.0])
@pytest.mark.parametrize("curved", [False, True])
def test_windows_choose_the_exact_best_heights(name, above, curved):
    """Points on the ground (every threshold at or above their height) and above it
    (thresholds below the window too); from far too narrow to wide windows."""
    terrain = SURFACES[name]
    rng = np.random.default_rng(11)
    surf, p, q, vis, lthr, lvis = _rows(terrain, rng, above)
    kc = tv.visibility.curvature_coefficient(0.85714, EARTH) if curved else 0.0
    kw = dict(neighbour_thresholds=lthr, neighbour_verdicts=lvis, weight=0.75, end_radius=0.5, kc=kc)
    exact_z, exact_score = thresholds.best_heights(surf, p, q, vis, **kw)
    moved = exact_z != p[:, 2]
    assert moved.any() and not moved.all()  # the case chooses heights both ways
    for window in (1e-6, 0.1, 1.0, 10.0, 1e3):
        z, score = thresholds.best_heights(surf, p, q, vis, window=window, **kw)
        np.testing.assert_array_equal(z, exact_z)
        np.testing.assert_array_equal(score, exact_score)


@pytest.mark.parametrize("name", list(SURFACES))
def test_windowed_sweeps_move_the_partners_exactly_as_exact_ones(name):
    terrain = SURFACES[name]
    rng = np.random.default_rng(5)
    surf = thresholds.ThresholdSurface(terrain)
    q0 = surf.local(_points(terrain, 80, rng, 0.0))
    vis = rng.random((80, 80)) < 0.5
    vis = vis | vis.T
    order = rng.permutation(80).astype(np.int64)
    exact = q0.copy()
    for _ in range(2):
        thresholds.gauss_seidel(surf, exact, order, vis)
    assert not np.array_equal(exact[:, 2], q0[:, 2])
    for window in (1e-6, 0.5, 50.0):
        q = q0.copy()
        for _ in range(2):
            thresholds.gauss_seidel(surf, q, order, vis, window=window)
        np.testing.assert_array_equal(q, exact)


@pytest.mark.parametrize("method", ["lls", "greedy-insertion"])
def test_the_calibrated_relocation_is_the_same_with_and_without_windows(method, monkeypatch):
    grid = tv.bundled_terrain("rough")
    simplified = simplifiers.simplify(grid, method, 2)
    pts = tv.sample_points(grid, 60, seed=3)
    with_windows = tv.relocate(pts, simplified, "calibrated", original=grid, n_partners=400)
    monkeypatch.setattr(cal, "WINDOW_ERRORS", np.inf)
    fresh = simplifiers.simplify(grid, method, 2)  # partners are cached on the simplified terrain
    without = tv.relocate(pts, fresh, "calibrated", original=grid, n_partners=400)
    np.testing.assert_array_equal(with_windows, without)


@pytest.mark.parametrize("window", [0.0, -1.0, np.nan])
def test_a_window_must_be_positive(window):
    surf = thresholds.ThresholdSurface(SURFACES["small grid"])
    q = np.zeros((2, 3))
    with pytest.raises(ValueError, match="window must be a positive number"):
        thresholds.gauss_seidel(surf, q, np.arange(2), np.ones((2, 2), dtype=bool), window=window)
