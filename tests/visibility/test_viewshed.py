"""Tests of exact viewsheds (terrainvis.visibility.viewsheds.sweep).

References, all independent of the viewshed sweep:
* the pair engine, one segment per target (``line_of_sight(..., engine="grid")``): the grid
  engine must give its verdict for every sample, bit for bit;
* Embree on the grid's own TIN (agreement outside the float32 band);
* the exact TIN clipper (``min_clearance`` on ``grid.to_tin()``), for grids with nodata
  and for TINs;
* cases worked out by hand on 3x3 and 5x5 grids.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from terrainvis.visibility import engine_names
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from conftest import REAL_DEM_NAMES, shared_dem_120
from terrainvis import HeightGrid, TIN
from terrainvis.errors import OutsideFootprintError
from terrainvis.core.synthetic import KINDS, synthetic_terrain
from terrainvis.visibility import clearance_tolerance, embree_tolerance, line_of_sight, min_clearance
from terrainvis.core.compiling import from_python
from terrainvis.visibility.viewsheds.sweep import _surface_at, _viewshed, viewshed
from terrainvis.visibility.viewsheds import _walk_kernels

walk_cells = from_python(_walk_kernels._walk_cells)  # a kernel-only kernel, called through a Python entry made here


# ----------------------------------------------------------------- references
def _eye(terrain, obs, h_o):
    """The eye as the viewshed places it (the surface there, a sample's own height on a sample)."""
    return np.array([obs[0], obs[1], _surface_at(terrain, float(obs[0]), float(obs[1])) + h_o])


def _targets(at, z, h_t):
    X, Y = np.meshgrid(at.xs, at.ys)
    return np.column_stack([X.ravel(), Y.ravel(), z.ravel() + h_t])


def _nearest(at, obs):
    return int(np.argmin(np.abs(at.ys - obs[1]))), int(np.argmin(np.abs(at.xs - obs[0])))


def _pairwise(grid, obs, h_o=1.7, h_t=0.0, max_distance=None, engine="grid"):
    """Per-target line_of_sight from the eye, with the viewshed's rules for the rest."""
    b = _targets(grid, grid.z, h_t)
    a = np.repeat(_eye(grid, obs, h_o)[None, :], b.shape[0], axis=0)
    ref = line_of_sight(grid, a, b, engine=engine).reshape(grid.shape)
    own = ref[_nearest(grid, obs)]  # the ground the observer stands on: its verdict at any distance
    if max_distance is not None:
        X, Y = np.meshgrid(grid.xs, grid.ys)
        ref &= (X - obs[0]) ** 2 + (Y - obs[1]) ** 2 <= max_distance**2
    ref[_nearest(grid, obs)] = own
    return ref


def _observers(g):
    """Observers: inside a cell, on a sample, on the boundary, in two corners."""
    xmin, xmax, ymin, ymax = g.extent
    rows, cols = g.shape
    return [
        (xmin + 0.37 * (xmax - xmin), ymin + 0.61 * (ymax - ymin)),
        (float(g.xs[cols // 2]), float(g.ys[rows // 3])),
        (xmin, 0.5 * (ymin + ymax)),
        (xmin, ymin),
        (xmax, ymax),
    ]


def _check_pairwise(g, heights=((1.7, 0.0), (0.0, 0.0), (25.0, 3.0))):
    n_sweep = 0
    for obs in _observers(g):
        for h_o, h_t in heights:
            out, info = _viewshed(g, obs, observer_height=h_o, target_height=h_t)
            ref = _pairwise(g, obs, h_o, h_t)
            np.testing.assert_array_equal(out, ref, err_msg=f"observer {obs}, heights {h_o}, {h_t}")
            n_sweep += info["lb"] + info["ub"] + info["walk"]
    return n_sweep


# ----------------------------------------------------------------- hand cases
def test_hand_case_wall():
    # a 5 m wall along x = 2; the eye 1 m above the ground at (0, 1). The wall's top is
    # visible (the ray climbs 2 m per unit, the wall face 5 m per unit from x = 1, so the
    # clearance 6 - 3x vanishes only at the top); behind it the ray is below 5 m.
    z = np.zeros((3, 5))
    z[:, 2] = 5.0
    g = HeightGrid(z)
    expect = np.array([[1, 1, 1, 0, 0]] * 3, dtype=bool)
    for engine in ("grid", "embree"):
        np.testing.assert_array_equal(viewshed(g, (0.0, 1.0), observer_height=1.0, engine=engine), expect)
    # standing on the wall's top, everything is visible
    np.testing.assert_array_equal(viewshed(g, (2.0, 1.0), observer_height=1.0), np.ones((3, 5), bool))


def test_hand_case_flat():
    g = HeightGrid(np.full((5, 5), 7.0), dx=2.0, dy=3.0)
    for engine in ("grid", "embree"):
        for h_o in (0.0, 1.7):
            out = viewshed(g, (3.1, 5.2), observer_height=h_o, engine=engine)
            np.testing.assert_array_equal(out, np.ones((5, 5), bool))


def test_hand_case_pit():
    # a 10 m deep pit at the centre of flat ground. From the left edge (eye 1.7 m up) the
    # pit's bottom is hidden: at x = 1 the ray to (2, 2, -10) is at 1.7 - 11.7 / 2 < 0
    # while the rim is at 0; the far rim and the ground behind are visible (the ray stays
    # above the pit's walls, which only fall below the ground).
    z = np.zeros((5, 5))
    z[2, 2] = -10.0
    g = HeightGrid(z)
    out = viewshed(g, (0.0, 2.0), observer_height=1.7)
    expect = np.ones((5, 5), bool)
    expect[2, 2] = False
    np.testing.assert_array_equal(out, expect)
    # from the rim at (1, 1) looking down the diagonal, the bottom is visible: the surface
    # falls 10 m per unit of t along the diagonal and the ray 11.7 m, from 1.7 m above.
    assert viewshed(g, (1.0, 1.0), observer_height=1.7)[2, 2]
    # on the ground at the rim, the pit's far wall (3, 2) cannot be seen over the pit's
    # near rim? It can: the ray from (1, 2, 0) to (3, 2, 0) passes over the pit.
    assert viewshed(g, (1.0, 2.0), observer_height=0.0)[2, 3]


def test_hand_case_peak():
    # a pyramid (planar faces meeting along the grid lines through the apex): from the apex
    # every ray stays on one face, so the clearance is 0 (the ground) or positive (raised eye).
    r, c = np.mgrid[0:5, 0:5]
    g = HeightGrid(20.0 - 3.0 * (np.abs(r - 2) + np.abs(c - 2)))
    for h_o in (0.0, 1.7):
        np.testing.assert_array_equal(viewshed(g, (2.0, 2.0), observer_height=h_o), np.ones((5, 5), bool))
    # from the foot corner (0, 0) (ground 8, eye 9.7) the ray up the diagonal to the apex
    # (20) has clearance 1.7 (1 - t): the apex is visible and hides the far corner (4, 4).
    # Along the edge y = 0 the ground rises 8 -> 14 at x = 2: (1, 0) is visible (clearance
    # 1.7 (1 - t) again) but (4, 0) is hidden behind the edge's top.
    out = viewshed(g, (0.0, 0.0), observer_height=1.7)
    assert out[2, 2] and out[0, 1] and out[1, 0]
    assert not out[4, 4] and not out[0, 4] and not out[4, 0]


def test_observer_cell_always_visible():
    # the eye buried in a narrow pit's corner still "sees" the sample it stands on
    z = np.zeros((4, 4))
    z[1, 1] = -50.0
    g = HeightGrid(z)
    out = viewshed(g, (0.9, 1.05), observer_height=0.0)
    assert out[1, 1]


# ----------------------------------------------------------------- against the pair engine
@pytest.mark.parametrize("kind", KINDS)
def test_matches_pair_engine_synthetic(kind):
    n_sweep = 0
    for size in (20, 47, 80):
        n_sweep += _check_pairwise(synthetic_terrain(kind, size, seed=3))
    assert n_sweep > 0  # the sweep decided samples (not only the exact fallback)


@pytest.mark.parametrize("name", REAL_DEM_NAMES)
def test_matches_pair_engine_dem(name):
    assert _check_pairwise(shared_dem_120(name), heights=((1.7, 0.0), (30.0, 2.0))) > 0


def test_matches_pair_engine_rectilinear_and_utm():
    rng = np.random.default_rng(7)
    base = synthetic_terrain("mountains", 50, seed=1)
    xs = np.cumsum(rng.uniform(5.0, 60.0, 50))
    ys = np.cumsum(rng.uniform(10.0, 40.0, 50))
    _check_pairwise(HeightGrid.from_coords(base.z, xs, ys))
    _check_pairwise(HeightGrid(base.z, dx=30.0, dy=30.0, origin=(560000.0, 5.1e6)))
    # elongated cells: an observer in a corner sends rays along the grid boundary lines
    _check_pairwise(HeightGrid(base.z, dx=74.57, dy=92.47))


#: Visible samples of ``synthetic_terrain("ridges", 300, seed=2)`` from (15, 22), eye 1.7 m up.
GOLDEN_LARGE_VISIBLE = 25427


def test_matches_pair_engine_large_grid():
    # 300 x 300 from a corner: rings up to 299, so the wedges are refined three times
    g = synthetic_terrain("ridges", 300, seed=2)
    for obs, h_o in (((15.0, 22.0), 1.7), ((4500.0, 4500.0), 40.0)):
        out, info = _viewshed(g, obs, observer_height=h_o)
        np.testing.assert_array_equal(out, _pairwise(g, obs, h_o))
        # most samples are decided by the sweep's bounds, not by the exact fallback
        assert info["lb"] + info["ub"] + info["walk"] >= 0.8 * info["targets"]
    # golden numbers (this grid, observer and heights)
    out, info = _viewshed(g, (15.0, 22.0), observer_height=1.7)
    assert int(out.sum()) == GOLDEN_LARGE_VISIBLE
    assert info["targets"] == 90000


@pytest.mark.parametrize("curvature", [0.0, 1.0])
def test_last_ring_bound_matches_pair_engine(curvature):
    """Visible samples whose last ring the sweep clears with the bound of its cells'
    corners (no exact walk there): cells up to 3:1 either way, where a ray crosses several
    cells of its last ring, and a bulge of metres (earth radius 3 km)."""
    rng = np.random.default_rng(19)
    base = synthetic_terrain("mountains", 64, seed=3)
    xs = np.cumsum(rng.uniform(10.0, 30.0, 64))
    ys = np.cumsum(rng.uniform(10.0, 30.0, 64))
    g = HeightGrid.from_coords(base.z, xs, ys)
    X, Y = np.meshgrid(g.xs, g.ys)
    by_bound = 0
    for obs in _observers(g):
        for h_o in (3.0, 300.0):
            out, info = _viewshed(g, obs, observer_height=h_o, curvature=curvature, earth_radius=3000.0)
            b = np.column_stack([X.ravel(), Y.ravel(), g.z.ravel()])
            a = np.repeat(_eye(g, obs, h_o)[None, :], b.shape[0], axis=0)
            ref = line_of_sight(g, a, b, engine="grid", curvature=curvature, earth_radius=3000.0).reshape(g.shape)
            ref[_nearest(g, obs)] = True
            np.testing.assert_array_equal(out, ref, err_msg=f"observer {obs}, height {h_o}")
            by_bound += info["ub_bound"]
    assert by_bound > 1000


def test_max_distance():
    g = synthetic_terrain("hills", 60, seed=4)
    obs = (700.0, 900.0)
    for dmax in (0.0, 95.0, 400.0, 5000.0):
        out = viewshed(g, obs, observer_height=5.0, max_distance=dmax)
        np.testing.assert_array_equal(out, _pairwise(g, obs, 5.0, max_distance=dmax))
    # the observer's own sample stays visible even at distance 0
    assert viewshed(g, obs, max_distance=0.0).sum() == 1


# ----------------------------------------------------------------- against Embree
@pytest.mark.parametrize("kind", ["mountains", "mesas"])
def test_grid_vs_embree_on_own_tin(kind):
    g = synthetic_terrain(kind, 90, seed=5)
    band = embree_tolerance(g)
    in_band = 0
    for obs in _observers(g)[:3]:
        for h_o, h_t in ((1.7, 0.0), (20.0, 2.0)):
            exact = viewshed(g, obs, observer_height=h_o, target_height=h_t, engine="grid")
            fast = viewshed(g, obs, observer_height=h_o, target_height=h_t, engine="embree")
            b = _targets(g, g.z, h_t)
            a = np.repeat(_eye(g, obs, h_o)[None, :], b.shape[0], axis=0)
            mc = min_clearance(g, a, b).reshape(g.shape)
            differ = exact != fast
            assert np.all(np.abs(mc[differ]) <= band), f"{differ.sum()} differ, max |c| {np.abs(mc[differ]).max()}"
            in_band += int((np.abs(mc) <= band).sum())
    assert in_band < 0.05 * 6 * g.z.size  # the comparison is not decided by the band


# ----------------------------------------------------------------- TIN
def test_tin_engine():
    from simplifiers import simplify

    g = synthetic_terrain("mountains", 60, seed=6)
    tin = simplify(g, "greedy-insertion", 2)
    assert isinstance(tin, TIN)
    band = embree_tolerance(tin)
    tol = clearance_tolerance(tin)
    for obs in _observers(g)[:3]:
        for h_o, h_t in ((1.7, 0.0), (15.0, 2.0)):
            out = viewshed(tin, obs, observer_height=h_o, target_height=h_t, at=g)
            assert out.shape == g.shape
            # targets stand on the TIN's surface at the grid's samples
            b = _targets(g, tin.height_on_grid(g.xs, g.ys), h_t)
            a = np.repeat(_eye(tin, obs, h_o)[None, :], b.shape[0], axis=0)
            ref = line_of_sight(tin, a, b).reshape(g.shape)
            ref[_nearest(g, obs)] = True
            np.testing.assert_array_equal(out, ref)
            mc = min_clearance(tin, a, b).reshape(g.shape)
            exact = mc >= -tol
            exact[_nearest(g, obs)] = True
            differ = out != exact
            assert np.all(np.abs(mc[differ] + tol) <= band)


def _pairwise_at(terrain, at, obs, h_o, h_t):
    """Per-target exact verdicts at ``at``'s samples standing on ``terrain``'s surface."""
    zt = terrain.height_on_grid(at.xs, at.ys)
    b = _targets(at, zt, h_t)
    ok = np.isfinite(b[:, 2])
    if at.n_nodata:
        ok &= np.isfinite(at.z.ravel())
    a = np.repeat(_eye(terrain, obs, h_o)[None, :], b.shape[0], axis=0)
    ref = np.zeros(b.shape[0], bool)
    ref[ok] = line_of_sight(terrain, a[ok], b[ok], engine="grid")
    return ref.reshape(at.shape)  # the nearest sample too: the pair engine's verdict


def test_at_other_grid():
    # a simplified HeightGrid judged at the original's samples (targets on the coarse
    # surface): the sweep with targets sorted by sector and ring, then the pair engine
    from simplifiers import simplify

    g = synthetic_terrain("ridges", 81, seed=9)
    n_sweep = 0
    for method, level in (("gls", 1), ("simple", 2)):
        coarse = simplify(g, method, level)
        for obs in _observers(g)[:4]:
            for h_o, h_t in ((1.7, 0.0), (30.0, 2.0)):
                out, info = _viewshed(coarse, obs, observer_height=h_o, target_height=h_t, at=g)
                np.testing.assert_array_equal(out, _pairwise_at(coarse, g, obs, h_o, h_t))
                n_sweep += info["lb"] + info["ub"] + info["walk"]
    assert n_sweep > 0.5 * 16 * g.z.size
    # an ``at`` grid reaching beyond the terrain, with nodata: those samples are False
    z = np.array(g.z)
    z[40:45, 10:30] = np.nan
    wide = HeightGrid(z, dx=37.0, dy=33.0, origin=(-200.0, 150.0))
    out = viewshed(g, (1000.0, 1100.0), at=wide)
    np.testing.assert_array_equal(out, _pairwise_at(g, wide, (1000.0, 1100.0), 1.7, 0.0))
    X, Y = np.meshgrid(wide.xs, wide.ys)
    assert not out[(X < 0) | (Y > g.ys[-1]) | np.isnan(z)].any()


# ----------------------------------------------------------------- nodata
def _holey_grid():
    g = synthetic_terrain("rough", 45, seed=8)
    z = g.z.copy()
    z[10:14, 20:27] = np.nan
    z[30, 5] = np.nan
    z[0:3, 40:] = np.nan
    z[25, 25] = np.nan
    return HeightGrid(z, dx=30.0, dy=30.0)


def test_nodata_matches_tin():
    g = _holey_grid()
    tin = g.to_tin()
    tol = clearance_tolerance(g)
    for obs in [(400.0, 700.0), (0.0, 0.0), (1000.0, 350.0)]:
        for h_o, h_t in ((1.7, 0.0), (25.0, 2.0)):
            out, info = _viewshed(g, obs, observer_height=h_o, target_height=h_t)
            assert info["lb"] + info["ub"] + info["walk"] > 0.5 * info["targets"]
            assert not out[np.isnan(g.z)].any()
            z = tin.height_on_grid(g.xs, g.ys)
            ok = np.isfinite(z).ravel()
            b = _targets(g, z, h_t)[ok]
            a = np.repeat(_eye(g, obs, h_o)[None, :], b.shape[0], axis=0)
            mc = min_clearance(tin, a, b)
            ref = np.zeros(g.z.size, bool)
            ref[ok] = mc >= -tol
            ref = ref.reshape(g.shape)
            ref[_nearest(g, obs)] = True
            np.testing.assert_array_equal(out, ref)


def test_nodata_other_targets_match_tin():
    # targets at another grid's samples over a grid with nodata: the sweep, then the
    # nodata-aware exact walk, against the exact TIN clipper
    g = _holey_grid()
    tin = g.to_tin()
    tol = clearance_tolerance(g)
    at = HeightGrid(np.zeros((50, 47)), dx=27.0, dy=26.0, origin=(5.0, 7.0))
    obs = (400.0, 700.0)
    out, info = _viewshed(g, obs, observer_height=3.0, at=at)
    assert info["lb"] + info["ub"] + info["walk"] > 0.5 * info["targets"]
    z = g.height_on_grid(at.xs, at.ys)
    ok = np.isfinite(z).ravel()
    b = _targets(at, z, 0.0)[ok]
    a = np.repeat(_eye(g, obs, 3.0)[None, :], b.shape[0], axis=0)
    ref = np.zeros(at.z.size, bool)
    ref[ok] = min_clearance(tin, a, b) >= -tol
    ref = ref.reshape(at.shape)
    ref[_nearest(at, obs)] = True
    np.testing.assert_array_equal(out, ref)


def test_nodata_observer_and_embree():
    g = _holey_grid()
    with pytest.raises(OutsideFootprintError, match="nodata"):
        viewshed(g, (22 * 30.0, 12 * 30.0))
    fast = viewshed(g, (400.0, 700.0), engine="embree")
    assert not fast[np.isnan(g.z)].any()


# ----------------------------------------------------------------- properties
def _int_grid(seed, rows=7, cols=9):
    rng = np.random.default_rng(seed)
    z = rng.integers(0, 12, size=(rows, cols)).astype(float)
    return HeightGrid(z, dx=2.0, dy=3.0)


_cell = st.tuples(st.integers(0, 8), st.integers(0, 6))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 50), _cell, st.sampled_from([0.0, 1.5, 4.0]), st.integers(-3000, 3000))
@example(0, (4, 3), 1.5, 1234)
def test_unchanged_by_vertical_shift(seed, cell, h_o, shift):
    g = _int_grid(seed)
    obs = (min(2.0 * cell[0] + 0.5, 16.0), min(3.0 * cell[1] + 1.0, 18.0))
    g2 = HeightGrid(g.z + shift, dx=2.0, dy=3.0)
    np.testing.assert_array_equal(viewshed(g, obs, observer_height=h_o), viewshed(g2, obs, observer_height=h_o))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 50), _cell, _cell, st.sampled_from([0.0, 1.5, 4.0]))
@example(1, (0, 0), (8, 6), 0.0)
def test_symmetric_with_equal_heights(seed, ca, cb, h):
    g = _int_grid(seed)
    a = (2.0 * ca[0], 3.0 * ca[1])
    b = (2.0 * cb[0], 3.0 * cb[1])
    # A sees B (both h above the ground) iff B sees A
    assert viewshed(g, a, observer_height=h, target_height=h)[cb[1], cb[0]] == viewshed(
        g, b, observer_height=h, target_height=h
    )[ca[1], ca[0]]


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 50), st.floats(0.0, 16.0), st.floats(0.0, 18.0))
def test_observer_sample_visible_and_nodata_false(seed, x, y):
    g = _int_grid(seed)
    z = g.z.copy()
    z[3, 6] = np.nan
    g = HeightGrid(z, dx=2.0, dy=3.0)
    if not np.isfinite(_surface_at(g, x, y)):
        with pytest.raises(OutsideFootprintError):
            viewshed(g, (x, y))
        return
    out = viewshed(g, (x, y))
    assert not out[3, 6]
    r, c = _nearest(g, (x, y))
    assert out[r, c] or not np.isfinite(g.z[r, c])


def test_inputs_not_modified():
    g = synthetic_terrain("hills", 30, seed=1)
    z = g.z.copy()
    obs = np.array([300.0, 400.0])
    viewshed(g, obs, at=g)
    np.testing.assert_array_equal(g.z, z)
    np.testing.assert_array_equal(obs, [300.0, 400.0])


# ----------------------------------------------------------------- bad input
def test_bad_input():
    g = synthetic_terrain("hills", 20, seed=0)
    tin = g.to_tin()
    with pytest.raises(TypeError, match="terrain must be"):
        viewshed(g.z, (1.0, 1.0))
    with pytest.raises(OutsideFootprintError, match=r"observer \(-5.0, 1.0\) is outside"):
        viewshed(g, (-5.0, 1.0))
    with pytest.raises(ValueError, match=r"observer must have 2 values \(x, y\) or 3 \(x, y, z\), got shape \(1,\)"):
        viewshed(g, (1.0,))
    with pytest.raises(ValueError, match="observer must be a 1-D pair"):
        viewshed(g, [[1.0, 2.0]])
    with pytest.raises(TypeError, match="observer must be a pair of numbers"):
        viewshed(g, ("a", "b"))
    with pytest.raises(ValueError, match="observer must be finite"):
        viewshed(g, (np.nan, 1.0))
    with pytest.raises(ValueError, match="observer_height must be finite and >= 0"):
        viewshed(g, (1.0, 1.0), observer_height=-1.0)
    with pytest.raises(TypeError, match="target_height must be a real number"):
        viewshed(g, (1.0, 1.0), target_height="high")
    with pytest.raises(ValueError, match="max_distance must be finite and >= 0"):
        viewshed(g, (1.0, 1.0), max_distance=-3.0)
    with pytest.raises(ValueError, match=re.escape(f"engine must be one of {engine_names()}, got 'fast'")):
        viewshed(g, (1.0, 1.0), engine="fast")
    with pytest.raises(ValueError, match="engine 'grid' needs a HeightGrid"):
        viewshed(tin, (1.0, 1.0), at=g, engine="grid")
    with pytest.raises(ValueError, match="at is required for a TIN"):
        viewshed(tin, (1.0, 1.0))
    with pytest.raises(TypeError, match="at must be a terrainvis.HeightGrid"):
        viewshed(g, (1.0, 1.0), at=g.z)
    far = HeightGrid(g.z, dx=30.0, dy=30.0, origin=(1e6, 1e6))
    with pytest.raises(ValueError, match="does not overlap"):
        viewshed(g, (1.0, 1.0), at=far)


@pytest.mark.parametrize("dz", [-3.0, -0.5, 0.0, 4.0])
def test_an_eye_given_explicitly_even_below_the_surface(dz):
    """observer (x, y, z): a relocated observer, possibly under the surface under test."""
    from simplifiers import simplify

    T = synthetic_terrain("hills", size=41, seed=2)
    S = simplify(T, "lls", 2)
    for obs in _observers(S)[:3]:
        eye = np.array([obs[0], obs[1], _surface_at(S, *obs) + dz])
        out = viewshed(S, eye, at=T)
        # reference: per-target line_of_sight from that eye to T's samples standing on S
        X, Y = np.meshgrid(T.xs, T.ys)
        b = np.column_stack([X.ravel(), Y.ravel(), S.height_at(np.column_stack([X.ravel(), Y.ravel()]))])
        ref = line_of_sight(S, np.repeat(eye[None], b.shape[0], axis=0), b).reshape(T.shape)
        np.testing.assert_array_equal(out, ref, err_msg=f"observer {obs}, eye {dz:+} m")  # the nearest sample too
        if dz < 0:  # an eye under the ground sees (almost) nothing
            assert out.sum() <= 9
    with pytest.raises(ValueError, match=r"observer must have 2 values \(x, y\) or 3 \(x, y, z\)"):
        viewshed(S, (1.0, 2.0, 3.0, 4.0))


# ----------------------------------------------------------------- the walks
@pytest.mark.parametrize("spacing", [(30.0, 30.0), (74.57, 92.47), "rectilinear"])
@pytest.mark.parametrize("bulge", [0.0, 3e-5])
def test_edge_walk_matches_cell_walk_from_any_ring(spacing, bulge):
    """The sweep's walk for NaN-free grids (grid lines and diagonals crossed, a DDA) gives
    the nodata-aware cell walk's minimum over any part of a ray, in particular over the
    parts that start where the ray leaves a box of rings: such a start lies on a grid
    line up to rounding, and the crossing the DDA meets first is then 'behind' it (an
    earlier version took the row line for the column line there and read a corner's
    height, 0.34 m too low, blocking a visible sample)."""
    from terrainvis.visibility.viewsheds import _bound_kernels as bk
    from terrainvis.visibility.viewsheds import _geometry_kernels as geo
    from terrainvis.visibility.viewsheds import _sector_kernels as sectors
    from terrainvis.visibility.viewsheds import _walk_kernels as wk
    from terrainvis.visibility.viewsheds.sweep import _sweep_grid

    rng = np.random.default_rng(11)
    base = synthetic_terrain("mountains", 40, seed=3)
    if spacing == "rectilinear":
        g = HeightGrid.from_coords(base.z, np.cumsum(rng.uniform(5.0, 60.0, 40)),
                                   np.cumsum(rng.uniform(10.0, 40.0, 40)))
    else:
        g = HeightGrid(base.z, dx=spacing[0], dy=spacing[1])
    sg = _sweep_grid(g)
    assert not sg.has_nan
    n_starts = 0
    for _ in range(300):
        re, ce = (int(v) for v in rng.integers(1, 38, 2))
        ex = sg.xs[ce] + rng.uniform(0.0, 1.0) * (sg.xs[ce + 1] - sg.xs[ce]) * rng.integers(0, 2)
        ey = sg.ys[re] + rng.uniform(0.0, 1.0) * (sg.ys[re + 1] - sg.ys[re]) * rng.integers(0, 2)
        ez = float(g.z[re, ce]) + rng.uniform(0.0, 30.0)
        tr, tc = (int(v) for v in rng.integers(0, 40, 2))
        ray = (ex, ey, ez, sg.xs[tc] - ex, sg.ys[tr] - ey, float(g.z[tr, tc]) - ez)
        if ray[3] == 0.0 and ray[4] == 0.0:
            continue
        eye = geo.Eye(re, ce, ex, ey, ez)
        starts = [0.02] + [sectors._box_exit(sg, eye, k, ray[3], ray[4]) for k in range(0, 40)]
        for t0 in starts:
            if not 0.0 <= t0 < 0.98:
                continue
            n_starts += 1
            e_edges = wk._walk_edges(sg, ray, t0, 0.98, -np.inf, bulge)
            e_cells = walk_cells(sg, ray, t0, 0.98, -np.inf, bulge)
            assert e_edges == pytest.approx(e_cells, abs=1e-9), (ray, t0)
    assert n_starts > 1000


def test_a_large_grid_s_tables_built_on_two_threads_are_the_tables():
    """From 512² samples on, the first viewshed builds the steepest slope in a helper thread
    beside the strips' maxima: the same tables, and the same viewshed, as one after the
    other. The pair engine's pyramid is not built: the viewshed does not walk with it."""
    import numba

    from terrainvis.core.interrupt import THREAD_MIN_WORK
    from terrainvis.visibility.viewsheds import sweep

    z = synthetic_terrain("mountains", 520, seed=2).z
    assert z.size >= THREAD_MIN_WORK
    threaded, serial = HeightGrid(z.copy(), 30.0, 30.0), HeightGrid(z.copy(), 30.0, 30.0)
    sweep._build_tables(threaded)
    if numba.get_num_threads() >= 2:  # otherwise nothing is built ahead
        assert {"viewshed_max_slope", "viewshed_strip_max"} <= set(threaded._cache)
    sweep._strip_max(serial), sweep._max_slope(serial)
    assert threaded._cache["viewshed_max_slope"] == serial._cache["viewshed_max_slope"]
    for a, b in zip(threaded._cache["viewshed_strip_max"], serial._cache["viewshed_strip_max"]):
        np.testing.assert_array_equal(a, b)
    eye = (threaded.xs[100], threaded.ys[300])
    np.testing.assert_array_equal(viewshed(threaded, eye, observer_height=5.0), viewshed(serial, eye, observer_height=5.0))
    assert "visibility" not in threaded._cache and "visibility" not in serial._cache


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), rows=st.integers(3, 40), cols=st.integers(3, 40))
def test_strip_maxima_are_float32_upper_bounds_of_each_segment(seed, rows, cols):
    """The sweep's strip maxima (float32, half the memory of float64 tables) are the float32
    rounded up of each segment's largest height: never below it, and exact for heights
    a float32 raster holds."""
    from terrainvis.visibility.viewsheds import _bound_kernels as bk
    from terrainvis.visibility.viewsheds import _geometry_kernels as geo
    from terrainvis.visibility.viewsheds import _sector_kernels as sectors
    from terrainvis.visibility.viewsheds import _walk_kernels as wk
    from terrainvis.visibility.viewsheds import sweep

    rng = np.random.default_rng(seed)
    z = rng.normal(300.0, 50.0, (rows, cols))
    z[rng.random(z.shape) < 0.1] = np.nan
    g = HeightGrid(z)
    cmax, rmax = sweep._strip_max(g)
    assert cmax.dtype == np.float32 and rmax.dtype == np.float32
    seg = bk.SEG
    for k in range(cmax.shape[0]):
        for c in range(cols):
            part = z[seg * k: seg * k + seg + 1, c]
            true = np.nanmax(part) if np.isfinite(part).any() else -np.inf
            assert cmax[k, c] >= true and (not np.isfinite(true) or np.float32(cmax[k, c]) == _f32_up(true))
    for r in range(rows):
        for k in range(rmax.shape[1]):
            part = z[r, seg * k: seg * k + seg + 1]
            true = np.nanmax(part) if np.isfinite(part).any() else -np.inf
            assert rmax[r, k] >= true and (not np.isfinite(true) or np.float32(rmax[r, k]) == _f32_up(true))
    z32 = HeightGrid(z.astype(np.float32).astype(np.float64))
    c32, _ = sweep._strip_max(z32)
    for k in range(c32.shape[0]):
        for c in range(cols):
            part = z32.z[seg * k: seg * k + seg + 1, c]
            if np.isfinite(part).any():
                assert float(c32[k, c]) == np.nanmax(part)


def _f32_up(v: float) -> np.float32:
    f = np.float32(v)
    return f if float(f) >= v else np.nextafter(f, np.float32(np.inf))


@pytest.mark.parametrize("shape", [(1, 1), (3, 5), (700, 3000), (5, (1 << 20) + 3)])
def test_undecided_codes_found_block_by_block(shape):
    """The sweep's leftover targets, found a block of rows at a time: every UNDECIDED code's flat
    index, in order, as a comparison of the whole array finds them."""
    from terrainvis.visibility.viewsheds import _bound_kernels as bk
    from terrainvis.visibility.viewsheds import _geometry_kernels as geo
    from terrainvis.visibility.viewsheds import _sector_kernels as sectors
    from terrainvis.visibility.viewsheds import _walk_kernels as wk
    from terrainvis.visibility.viewsheds.sweep import _undecided

    rng = np.random.default_rng(shape[0] * 7 + shape[1])
    code = rng.choice(np.array([geo.UNDECIDED, geo.VISIBLE, geo.BLOCKED, geo.NOT_TARGET], dtype=np.int8), size=shape,
                      p=[0.01, 0.4, 0.4, 0.19])
    got = _undecided(code)
    assert np.array_equal(got, np.flatnonzero(code.ravel() == geo.UNDECIDED)) and got.dtype == np.int64
    code[:] = geo.VISIBLE
    assert _undecided(code).size == 0
