"""Tests of exact line of sight (terrainvis.visibility).

References used here, all independent of the grid walk:
* Embree (float32 ray casting on the grid's TIN, with the underground fix);
* a numpy brute force that evaluates the clearance (with ``HeightGrid.height_at`` /
  ``TIN.height_at``) at every crossing of the ground track with a grid line, a cell
  diagonal line or a TIN edge, plus both trimmed ends;
* the exact TIN clipper (min_clearance on ``grid.to_tin()``);
* cases worked out by hand on 3x3 and 5x5 grids.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from terrainvis.visibility import engine_names
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from conftest import DEM_NAMES, shared_dem_path
from terrainvis import HeightGrid, TIN
from terrainvis.errors import NodataError, OutsideFootprintError
from terrainvis.core.sampling import sample_points
from terrainvis.visibility import (
    ENGINES,
    clearance_tolerance,
    embree_tolerance,
    line_of_sight,
    min_clearance,
    terrain_scale,
    trim_length,
    visibility_matrix,
)
from terrainvis.visibility.embree import embree_scene
from terrainvis.visibility.grid import grid_accel

N_PAIRS = 1000


# ----------------------------------------------------------------- terrains
def _kinds():
    from terrainvis.core.synthetic import KINDS

    return KINDS


def _synthetic(kind):
    from terrainvis.core.synthetic import synthetic_terrain

    return synthetic_terrain(kind)


def _dem(name):
    from terrainvis import load_dem

    g = load_dem(shared_dem_path(name))
    rs, cs = g.valid_window()
    g = g.crop(rs, cs)
    step = max(1, int(np.ceil(max(g.shape) / 200)))
    return g.subsample(step) if step > 1 else g


def _rectilinear(seed=3):
    """A synthetic terrain on random, strongly non-uniform coordinates (last gap wider)."""
    g = _synthetic("mountains")
    rng = np.random.default_rng(seed)
    rows, cols = g.shape
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(5.0, 60.0, cols - 1))])
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(5.0, 60.0, rows - 1))])
    xs[-1] = xs[-2] + 90.0
    return HeightGrid.from_coords(g.z, xs + 1000.0, ys - 500.0)


def _utm():
    g = _synthetic("rough")
    return HeightGrid(g.z, dx=30.0, dy=30.0, origin=(560000.0, 5.1e6))


_CACHE = {}


def terrain(name):
    if name not in _CACHE:
        if name.startswith("dem:"):
            _CACHE[name] = _dem(name[4:])
        elif name == "rectilinear":
            _CACHE[name] = _rectilinear()
        elif name == "utm":
            _CACHE[name] = _utm()
        else:
            _CACHE[name] = _synthetic(name)
    return _CACHE[name]


TERRAINS = ["hills", "mountains", "rough", "ridges", "mesas"] + [f"dem:{n}" for n in DEM_NAMES] + ["rectilinear", "utm"]


# ----------------------------------------------------------------- brute force
def brute_interval(a, b, delta, end_radius):
    """The tested interval [t0, t1] of the segment a -> b, as the definition writes it
    (``[max(tau, r / L_h), min(1 - tau, 1 - r / L_h)]``), or None when nothing is tested."""
    d = b - a
    length = np.linalg.norm(d)
    lh = np.hypot(d[0], d[1])
    if length <= 2 * delta or (end_radius > 0 and lh <= 2 * end_radius):
        return None
    tau = delta / length
    if end_radius == 0:
        return tau, 1 - tau
    return max(tau, end_radius / lh), min(1 - tau, 1 - end_radius / lh)


def brute_min_clearance(grid: HeightGrid, a, b, end_radius=0.0) -> np.ndarray:
    """Clearance at every crossing with x = xs[c], y = ys[r] and every cell-diagonal line.

    Extra points on the segment only add true clearance values, so evaluating at the
    crossings with every diagonal *line* (inside its cell or not) still gives the exact
    minimum. The surface comes from ``HeightGrid.height_at``. Only crossings inside the
    tested interval count, plus the interval's two ends.
    """
    delta = trim_length(grid)
    xs, ys = grid.xs, grid.ys
    X0, Y0 = np.meshgrid(xs[:-1], ys[:-1])
    WX, WY = np.meshgrid(np.diff(xs), np.diff(ys))
    X0, Y0, WX, WY = X0.ravel(), Y0.ravel(), WX.ravel(), WY.ravel()
    out = np.empty(a.shape[0])
    for i in range(a.shape[0]):
        d = b[i] - a[i]
        iv = brute_interval(a[i], b[i], delta, end_radius)
        if iv is None:
            out[i] = np.inf
            continue
        t0, t1 = iv
        ts = [np.array([t0, t1])]
        with np.errstate(divide="ignore", invalid="ignore"):
            if d[0] != 0:
                ts.append((xs - a[i, 0]) / d[0])
            if d[1] != 0:
                ts.append((ys - a[i, 1]) / d[1])
            den = d[0] / WX - d[1] / WY
            td = ((a[i, 1] - Y0) / WY - (a[i, 0] - X0) / WX) / den
            ts.append(td[np.isfinite(td)])
        t = np.concatenate(ts)
        t = t[(t >= t0) & (t <= t1)]
        p = a[i] + t[:, None] * d
        out[i] = (p[:, 2] - grid.height_at(p[:, :2])).min()
    return out


def brute_tin_min_clearance(tin: TIN, a, b, end_radius=0.0) -> np.ndarray:
    """Clearance at every crossing of the ground track with a TIN edge (plus the ends of
    the tested interval)."""
    delta = trim_length(tin)
    e = np.concatenate([tin.faces[:, [0, 1]], tin.faces[:, [1, 2]], tin.faces[:, [2, 0]]])
    P = tin.vertices[e[:, 0], :2]
    Q = tin.vertices[e[:, 1], :2]
    E = Q - P
    out = np.empty(a.shape[0])
    for i in range(a.shape[0]):
        d = b[i] - a[i]
        iv = brute_interval(a[i], b[i], delta, end_radius)
        if iv is None:
            out[i] = np.inf
            continue
        t0, t1 = iv
        # a + t d = P + s E  (2-D)
        den = d[0] * E[:, 1] - d[1] * E[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((P[:, 0] - a[i, 0]) * E[:, 1] - (P[:, 1] - a[i, 1]) * E[:, 0]) / den
            s = ((P[:, 0] - a[i, 0]) * d[1] - (P[:, 1] - a[i, 1]) * d[0]) / den
        ok = np.isfinite(t) & (s >= -1e-12) & (s <= 1 + 1e-12) & (t >= t0) & (t <= t1)
        t = np.concatenate([[t0, t1], t[ok]])
        p = a[i] + t[:, None] * d
        h = tin.height_at(p[:, :2])
        out[i] = np.nanmin(p[:, 2] - h)
    return out


def random_pairs(grid, n, offset, seed=0):
    a = sample_points(grid, n, seed=seed, offset=offset)
    b = sample_points(grid, n, seed=seed + 1000, offset=offset)
    return a, b


# ----------------------------------------------------------------- cross-checks
@pytest.mark.parametrize("offset", [0.0, 1.0])
@pytest.mark.parametrize("name", TERRAINS)
def test_grid_embree_tin_agree(name, offset):
    g = terrain(name)
    a, b = random_pairs(g, N_PAIRS, offset, seed=11)
    tol = clearance_tolerance(g)
    m = min_clearance(g, a, b)
    los = line_of_sight(g, a, b, engine="grid")
    emb = line_of_sight(g, a, b, engine="embree")
    # the early-exit LOS walk agrees exactly with the exact minimum
    np.testing.assert_array_equal(los, m >= -tol)
    # Embree agrees outside the float32 degeneracy band
    band = embree_tolerance(g)
    clear = np.abs(m) > band
    bad = np.flatnonzero(clear & (los != emb))
    n_deg = int((~clear).sum())
    print(f"{name} offset {offset}: {n_deg} degenerate pairs of {N_PAIRS} (|min clearance| <= {band:.2e})")
    assert bad.size == 0, (
        f"{bad.size} non-degenerate disagreements (first {bad[:5]}, clearances {m[bad[:5]]}); "
        f"{n_deg} degenerate pairs excluded"
    )
    # the comparison is not vacuous
    assert clear.sum() >= N_PAIRS // 2
    # the grid and its TIN are the same surface: both exact minima agree
    mt = min_clearance(g.to_tin(), a, b)
    np.testing.assert_allclose(mt, m, rtol=0, atol=tol)


@pytest.mark.parametrize("name", ["mountains", "mesas", "rectilinear", "utm", "dem:west_bijou_escarpment_co"])
def test_min_clearance_equals_brute_force(name):
    g = terrain(name)
    a, b = random_pairs(g, 150, 0.5, seed=5)
    # include short pairs, which stay within a few cells
    a2 = sample_points(g, 50, seed=6, offset=0.0)
    xmin, xmax, ymin, ymax = g.extent
    rng = np.random.default_rng(7)
    xy = np.clip(a2[:, :2] + rng.normal(scale=3 * g.dx, size=(50, 2)), [xmin, ymin], [xmax, ymax])
    b2 = np.column_stack([xy, g.height_at(xy) + rng.uniform(-2, 2, 50)])
    a = np.concatenate([a, a2])
    b = np.concatenate([b, b2])
    got = min_clearance(g, a, b)
    ref = brute_min_clearance(g, a, b)
    np.testing.assert_allclose(got, ref, rtol=0, atol=clearance_tolerance(g))


def test_tin_min_clearance_on_irregular_tin():
    from scipy.spatial import Delaunay

    g = terrain("ridges")
    rng = np.random.default_rng(2)
    xmin, xmax, ymin, ymax = g.extent
    xy = np.column_stack([rng.uniform(xmin, xmax, 400), rng.uniform(ymin, ymax, 400)])
    xy = np.concatenate([xy, [[xmin, ymin], [xmax, ymin], [xmin, ymax], [xmax, ymax]]])
    faces = Delaunay(xy).simplices
    v = np.column_stack([xy, g.height_at(xy)])
    # counter-clockwise faces
    e1 = v[faces[:, 1], :2] - v[faces[:, 0], :2]
    e2 = v[faces[:, 2], :2] - v[faces[:, 0], :2]
    cross = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    faces[cross < 0] = faces[cross < 0][:, [0, 2, 1]]
    tin = TIN(v, faces)
    a = sample_points(tin, 200, seed=1, offset=0.0)
    b = sample_points(tin, 200, seed=2, offset=0.0)
    # points of the grid (not the TIN): some lie below the TIN, as after simplification
    a[:100, 2] = g.height_at(a[:100, :2])
    b[:100, 2] = g.height_at(b[:100, :2])
    m = min_clearance(tin, a, b)
    np.testing.assert_allclose(m, brute_tin_min_clearance(tin, a, b), rtol=0, atol=clearance_tolerance(tin))
    emb = line_of_sight(tin, a, b)  # auto -> Embree on a TIN
    clear = np.abs(m) > embree_tolerance(tin)
    np.testing.assert_array_equal(emb[clear], (m >= -clearance_tolerance(tin))[clear])
    assert clear.sum() > 100


@pytest.mark.parametrize("engine", ["grid", "embree"])
def test_matrix_symmetric_and_matches_pairs(engine):
    g = terrain("hills")
    pts = sample_points(g, 70, seed=9, offset=1.0)
    vm = visibility_matrix(g, pts, engine=engine)
    assert vm.shape == (70, 70) and vm.dtype == np.bool_
    np.testing.assert_array_equal(vm, vm.T)
    assert vm.diagonal().all()
    i, j = np.triu_indices(70, 1)
    np.testing.assert_array_equal(vm[i, j], line_of_sight(g, pts[i], pts[j], engine=engine))
    assert 0 < vm[i, j].mean() < 1  # a mix of visible and blocked pairs


def test_matrix_engines_agree_on_utm_grid():
    g = terrain("utm")
    pts = sample_points(g, 80, seed=4, offset=1.0)
    vg = visibility_matrix(g, pts, engine="grid")
    ve = visibility_matrix(g, pts, engine="embree")
    i, j = np.triu_indices(80, 1)
    m = min_clearance(g, pts[i], pts[j])
    clear = np.abs(m) > embree_tolerance(g)
    np.testing.assert_array_equal(vg[i, j][clear], ve[i, j][clear])
    np.testing.assert_array_equal(vg[i, j], m >= -clearance_tolerance(g))


def test_utm_origin_matches_local_origin():
    g = terrain("utm")
    local = HeightGrid(g.z, dx=30.0, dy=30.0)
    a, b = random_pairs(g, 500, 1.0, seed=8)
    shift = np.array([560000.0, 5.1e6, 0.0])
    m_utm = min_clearance(g, a, b)
    m_loc = min_clearance(local, a - shift, b - shift)
    np.testing.assert_allclose(m_utm, m_loc, rtol=0, atol=clearance_tolerance(g))
    for engine in [name for name, e in ENGINES.items() if e.runs_on(g)]:
        l_utm = line_of_sight(g, a, b, engine=engine)
        l_loc = line_of_sight(local, a - shift, b - shift, engine=engine)
        clear = np.abs(m_loc) > embree_tolerance(g)
        np.testing.assert_array_equal(l_utm[clear], l_loc[clear])


# ----------------------------------------------------------------- simple terrains
@pytest.mark.parametrize("engine", ["grid", "embree"])
def test_flat_and_planar_terrain_everything_visible(engine):
    rng = np.random.default_rng(0)
    X, Y = np.meshgrid(np.arange(40) * 25.0, np.arange(30) * 25.0)
    for z in (np.zeros((30, 40)), 0.3 * X - 0.7 * Y + 100.0):
        g = HeightGrid(z, dx=25.0, dy=25.0)
        pts = sample_points(g, 60, seed=rng, offset=0.0)
        assert visibility_matrix(g, pts, engine=engine).all()
        a, b = random_pairs(g, 300, 0.0, seed=1)
        assert line_of_sight(g, a, b, engine=engine).all()
    np.testing.assert_allclose(min_clearance(g, a, b), 0.0, atol=clearance_tolerance(g))


@pytest.mark.parametrize("engine", ["grid", "embree"])
@pytest.mark.parametrize("rectilinear", [False, True])
def test_wall_blocks_exactly_the_opposite_pairs(engine, rectilinear):
    rows, cols, cw = 25, 31, 14
    z = np.zeros((rows, cols))
    z[:, cw] = 10.0
    if rectilinear:
        xs = np.concatenate([[0.0], np.cumsum(np.random.default_rng(1).uniform(1.0, 9.0, cols - 1))])
        g = HeightGrid.from_coords(z, xs, np.arange(rows) * 4.0)
    else:
        g = HeightGrid(z, dx=5.0, dy=4.0)
    rng = np.random.default_rng(5)
    n = 600
    left = (g.xs[0], g.xs[cw - 1])
    right = (g.xs[cw + 1], g.xs[-1])
    side_a = rng.random(n) < 0.5
    side_b = rng.random(n) < 0.5

    def pts(side):
        x = np.where(side, rng.uniform(*left, n), rng.uniform(*right, n))
        y = rng.uniform(g.ys[0], g.ys[-1], n)
        return np.column_stack([x, y, rng.uniform(0.0, 2.0, n)])

    a, b = pts(side_a), pts(side_b)
    np.testing.assert_array_equal(line_of_sight(g, a, b, engine=engine), side_a == side_b)


# ----------------------------------------------------------------- hand-worked cases
def _spike3():
    return HeightGrid([[0.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 0.0]])


@pytest.mark.parametrize("as_tin", [False, True])
def test_hand_cases_3x3(as_tin):
    g = _spike3()
    t = g.to_tin() if as_tin else g
    a = np.array([[0, 1, 1], [0, 0, 0], [0, 0, 0], [0, 2, 0], [0, 0.5, 6], [0, 0.5, 4.5], [0, 0, 2]], float)
    b = np.array([[2, 1, 1], [2, 0, 0], [2, 2, 0], [2, 0, 0], [2, 0.5, 6], [2, 0.5, 4.5], [2, 2, 22]], float)
    # along y = 0.5 the surface rises 0 -> 5 over x in [0, 0.5] (upper triangle of cell
    # (0, 0)), stays 5 up to x = 1 (lower triangle, z = 10 v), falls 5 -> 0 over [1, 1.5]
    # and is 0 beyond. The last segment climbs the diagonal: z_seg(x) = 2 + 10 x vs 10 x.
    expect = np.array([-9.0, 0.0, -10.0, -10.0, 1.0, -0.5, 2.0])
    np.testing.assert_allclose(min_clearance(t, a, b), expect, atol=1e-6)
    vis = expect >= 0
    for engine in ("auto", "embree") + (() if as_tin else ("grid",)):
        np.testing.assert_array_equal(line_of_sight(t, a, b, engine=engine), vis)


@pytest.mark.parametrize("as_tin", [False, True])
def test_hand_cases_5x5_rectilinear(as_tin):
    z = np.zeros((5, 5))
    z[2, 2] = 8.0
    g = HeightGrid.from_coords(z, [0.0, 1.0, 2.0, 4.0, 8.0], [0.0, 1.0, 2.0, 3.0, 4.0])
    t = g.to_tin() if as_tin else g
    # along y = 2 the spike vertex (2, 2) is 8 high. Along y = 2.5 (v = 0.5 in row 2) the
    # surface is 0 up to x = 1.5, rises to 4 at x = 2 (cell (2, 1) lower triangle: 8u - 4),
    # stays 4 up to x = 3 (cell (2, 2) upper triangle: 8 - 8v) and falls to 0 at x = 4.
    a = np.array([[0, 2, 8.5], [0, 2.5, 3], [0, 2.5, 0], [0, 2.5, 4], [5, 0, 0]], float)
    b = np.array([[8, 2, 8.5], [8, 2.5, 3], [8, 2.5, 8], [8, 2.5, 4], [5, 4, 0]], float)
    expect = np.array([0.5, -1.0, -2.0, 0.0, 0.0])
    np.testing.assert_allclose(min_clearance(t, a, b), expect, atol=1e-6)
    for engine in ("auto", "embree") + (() if as_tin else ("grid",)):
        np.testing.assert_array_equal(line_of_sight(t, a, b, engine=engine), expect >= 0)


@pytest.mark.parametrize("engine", ["grid", "embree"])
def test_underground_segment_is_blocked(engine):
    # a dome: the chord between two surface points runs below the surface and meets it
    # only at its ends
    r, c = np.mgrid[0:5, 0:5]
    g = HeightGrid(10.0 - (r - 2.0) ** 2 - (c - 2.0) ** 2, dx=10.0, dy=10.0)
    a = np.array([[0.0, 20.0, 6.0], [20.0, 0.0, 6.0], [5.0, 5.0, 0.0]])
    b = np.array([[40.0, 20.0, 6.0], [20.0, 40.0, 6.0], [35.0, 35.0, 0.0]])
    a[2, 2] = g.height_at(a[2:3, :2])[0]
    b[2, 2] = g.height_at(b[2:3, :2])[0]
    m = min_clearance(g, a, b)
    np.testing.assert_allclose(m[:2], -4.0, atol=1e-9)
    assert (m < -1.0).all()
    assert not line_of_sight(g, a, b, engine=engine).any()
    if engine == "embree":
        # the trap: a surface-crossing query alone sees no hit for these segments
        sc = embree_scene(g.to_tin())
        d = b - a
        tau = trim_length(g) / np.linalg.norm(d, axis=1)
        assert not sc.run(a + tau[:, None] * d, d, 1 - 2 * tau).any()


# ----------------------------------------------------------------- pyramid
def test_pyramid_bounds_and_memory():
    g = terrain("rectilinear")
    acc = grid_accel(g)
    assert acc.nbytes <= 1.5 * g.z.nbytes
    assert grid_accel(g) is acc  # cached
    z = g.z
    ncy, ncx = z.shape[0] - 1, z.shape[1] - 1
    for L in range(1, acc.ltop + 1):
        nx, ny = int(acc.nxl[L]), int(acc.nyl[L])
        lev = acc.pyr[acc.off[L] : acc.off[L] + 2 * nx * ny].reshape(ny, nx, 2)
        for R, C in [(0, 0), (ny - 1, nx - 1), (ny // 2, nx // 3)]:
            block = z[R << L : min((R + 1) << L, ncy) + 1, C << L : min((C + 1) << L, ncx) + 1]
            assert lev[R, C, 0] <= block.min() and lev[R, C, 1] >= block.max()
            # tight: within one float32 ulp
            assert block.min() - lev[R, C, 0] <= np.spacing(np.float32(abs(block.min())))
            assert lev[R, C, 1] - block.max() <= np.spacing(np.float32(abs(block.max())))
    assert acc.nxl[acc.ltop] == 1 and acc.nyl[acc.ltop] == 1


def _outward(lo: float, hi: float) -> tuple:
    """lo and hi as float32, rounded down and up, one value at a time."""
    flo, fhi = np.float32(lo), np.float32(hi)
    if float(flo) > lo:
        flo = np.nextafter(flo, np.float32(-np.inf))
    if float(fhi) < hi:
        fhi = np.nextafter(fhi, np.float32(np.inf))
    return flo, fhi


@settings(max_examples=60, deadline=None)
@given(rows=st.integers(2, 40), cols=st.integers(2, 40), seed=st.integers(0, 10_000),
       scale=st.sampled_from([1e-3, 1.0, 1e4]), offset=st.sampled_from([0.0, -431.7, 8848.86, 5e5]))
def test_pyramid_is_every_blocks_outward_rounded_range(rows, cols, seed, scale, offset):
    """Every entry of every level, block by block: the lowest and highest sample under the block
    (level L: 2^L x 2^L cells, the samples on its edges included, clamped to the grid), as
    float32 rounded outwards. Brute force, one block at a time."""
    z = np.random.default_rng(seed).normal(0.0, scale, (rows, cols)) + offset
    g = HeightGrid.from_coords(z, np.arange(cols) * 1.5, np.arange(rows) * 2.0)
    acc = grid_accel(g)
    ncy, ncx = rows - 1, cols - 1
    for L in range(1, acc.ltop + 1):
        nx, ny = int(acc.nxl[L]), int(acc.nyl[L])
        assert (nx, ny) == (-(-ncx // (1 << L)), -(-ncy // (1 << L)))
        lev = acc.pyr[acc.off[L] : acc.off[L] + 2 * nx * ny].reshape(ny, nx, 2)
        for R in range(ny):
            for C in range(nx):
                block = z[R << L : min((R + 1) << L, ncy) + 1, C << L : min((C + 1) << L, ncx) + 1]
                want = _outward(float(block.min()), float(block.max()))
                assert (lev[R, C, 0], lev[R, C, 1]) == want, (L, R, C)


# ----------------------------------------------------------------- properties
def _small_grid(seed):
    rng = np.random.default_rng(seed)
    z = rng.normal(scale=3.0, size=(9, 11)).cumsum(axis=0)
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5, 3.0, 10))])
    return HeightGrid.from_coords(z, xs, np.arange(9) * 2.0)


_G = _small_grid(0)
_unit = st.floats(0.0, 1.0)
_pt = st.tuples(_unit, _unit, st.floats(-2.0, 6.0))


def _world(g, p):
    xmin, xmax, ymin, ymax = g.extent
    x = xmin + p[0] * (xmax - xmin)
    y = ymin + p[1] * (ymax - ymin)
    return [x, y, float(g.height_at([[x, y]])[0]) + p[2]]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(_pt, _pt), min_size=1, max_size=20))
@example([((0.0, 0.0, 0.0), (1.0, 1.0, 0.0)), ((0.5, 0.5, 0.0), (0.5, 0.5, 0.0))])
def test_los_symmetric(pairs):
    a = np.array([_world(_G, p) for p, _ in pairs])
    b = np.array([_world(_G, q) for _, q in pairs])
    for engine in ("grid", "embree"):
        np.testing.assert_array_equal(line_of_sight(_G, a, b, engine=engine), line_of_sight(_G, b, a, engine=engine))
    np.testing.assert_array_equal(min_clearance(_G, a, b), min_clearance(_G, b, a))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(_pt, _pt), min_size=1, max_size=20), st.floats(-5000.0, 5000.0))
@example([((0.0, 0.5, 0.0), (1.0, 0.5, 0.0))], 1234.5)
def test_los_unchanged_by_vertical_shift(pairs, shift):
    a = np.array([_world(_G, p) for p, _ in pairs])
    b = np.array([_world(_G, q) for _, q in pairs])
    g2 = HeightGrid.from_coords(_G.z + shift, _G.xs, _G.ys)
    up = np.array([0.0, 0.0, shift])
    np.testing.assert_array_equal(line_of_sight(_G, a, b), line_of_sight(g2, a + up, b + up))
    assert clearance_tolerance(g2) == pytest.approx(clearance_tolerance(_G), rel=1e-9)


# ----------------------------------------------------------------- bad input
def test_bad_input():
    g = _spike3()
    ok = np.array([[0.5, 0.5, 1.0]])
    with pytest.raises(OutsideFootprintError, match=r"b has 2 point\(s\) outside.*first at index 1"):
        line_of_sight(g, np.repeat(ok, 3, 0), np.array([[0.5, 0.5, 1], [3.0, 0.5, 1], [0.5, -1.0, 1]]))
    with pytest.raises(OutsideFootprintError, match="points has 1"):
        visibility_matrix(g, [[0.5, 0.5, 0.0], [0.5, 9.0, 0.0]])
    with pytest.raises(OutsideFootprintError):
        line_of_sight(g.to_tin(), ok, [[5.0, 5.0, 0.0]])
    with pytest.raises(ValueError, match="a must be finite"):
        min_clearance(g, [[np.nan, 0.5, 1.0]], ok)
    with pytest.raises(ValueError, match=r"a must be a 2-D array of shape \(m, 3\)"):
        line_of_sight(g, [0.5, 0.5, 1.0], ok)
    with pytest.raises(ValueError, match=r"shape \(m, 3\)"):
        line_of_sight(g, [[0.5, 0.5]], [[0.5, 0.5]])
    with pytest.raises(ValueError, match="same shape"):
        line_of_sight(g, np.repeat(ok, 2, 0), ok)
    with pytest.raises(ValueError, match=re.escape(f"engine must be one of {engine_names()}, got 'bvh'")):
        line_of_sight(g, ok, ok, engine="bvh")
    with pytest.raises(ValueError, match="engine 'grid' needs a HeightGrid"):
        visibility_matrix(g.to_tin(), ok, engine="grid")
    with pytest.raises(TypeError, match="terrain must be"):
        line_of_sight(np.zeros((3, 3)), ok, ok)
    z = np.zeros((3, 3))
    z[0, 0] = np.nan
    with pytest.raises(NodataError, match="line_of_sight"):
        line_of_sight(HeightGrid(z), ok, ok)
    with pytest.raises(NodataError, match="visibility_matrix"):
        visibility_matrix(HeightGrid(z), ok)


@pytest.mark.parametrize("engine", ["grid", "embree"])
def test_degenerate_inputs(engine):
    g = _spike3()
    # zero-length segments are visible, even underground
    p = np.array([[1.0, 1.0, 10.0], [0.2, 0.7, -50.0]])
    assert line_of_sight(g, p, p, engine=engine).all()
    assert np.isinf(min_clearance(g, p, p)).all()
    empty = np.zeros((0, 3))
    assert line_of_sight(g, empty, empty, engine=engine).shape == (0,)
    assert min_clearance(g, empty, empty).shape == (0,)
    assert visibility_matrix(g, empty, engine=engine).shape == (0, 0)
    assert visibility_matrix(g, p[:1], engine=engine).tolist() == [[True]]
    # vertical segments: clearance is linear along them (the surface is 2.5 at
    # (0.5, 0.25) and 10 at (1, 1))
    a = np.array([[0.5, 0.25, 3.0], [1.0, 1.0, 5.0]])
    b = np.array([[0.5, 0.25, 4.0], [1.0, 1.0, 20.0]])
    m = min_clearance(g, a, b)
    h = g.height_at(a[:, :2])
    tau = trim_length(g) / np.abs(b[:, 2] - a[:, 2])
    np.testing.assert_allclose(m, a[:, 2] + tau * (b[:, 2] - a[:, 2]) - h, atol=1e-9)
    np.testing.assert_array_equal(line_of_sight(g, a, b, engine=engine), [True, False])


def test_definitions():
    g = HeightGrid(np.array([[0.0, 50.0], [10.0, 20.0]]), dx=30.0, dy=40.0)
    assert trim_length(g) == pytest.approx(1e-5 * 50.0)
    assert terrain_scale(g) == 50.0
    assert clearance_tolerance(g) == pytest.approx(5e-8)
    assert embree_tolerance(g) == pytest.approx(50.0 * 2.0**-20)


@pytest.mark.parametrize("shape", [(2, 2), (2, 41), (37, 2), (3, 64), (65, 5)])
def test_thin_and_tiny_grids_match_brute_force(shape):
    rng = np.random.default_rng(sum(shape))
    g = HeightGrid(rng.normal(scale=5.0, size=shape), dx=7.0, dy=3.0, origin=(-100.0, 40.0))
    a, b = random_pairs(g, 200, 0.3, seed=2)
    m = min_clearance(g, a, b)
    np.testing.assert_allclose(m, brute_min_clearance(g, a, b), rtol=0, atol=clearance_tolerance(g))
    np.testing.assert_array_equal(line_of_sight(g, a, b), m >= -clearance_tolerance(g))
    vm = visibility_matrix(g, a[:30])
    i, j = np.triu_indices(30, 1)
    np.testing.assert_array_equal(vm[i, j], line_of_sight(g, a[:30][i], a[:30][j]))


def test_morton_sorted_queries_give_the_same_answers(monkeypatch):
    from terrainvis.visibility import grid as grid_module

    g = terrain("rough")
    a, b = random_pairs(g, 2000, 1.0, seed=21)
    m_plain = min_clearance(g, a, b)
    los_plain = line_of_sight(g, a, b)
    monkeypatch.setattr(grid_module, "SORT_MIN_BYTES", 0)
    order = grid_module._morton_order(a[:, :2], g.extent)
    assert sorted(order.tolist()) == list(range(2000)) and (order != np.arange(2000)).any()
    np.testing.assert_array_equal(min_clearance(g, a, b), m_plain)
    np.testing.assert_array_equal(line_of_sight(g, a, b), los_plain)


# ----------------------------------------------------------------- end radius
def _cell(g):
    """Mean cell width in x (one cell of the surface under test)."""
    return float(np.diff(g.xs).mean())


def _golden_case():
    """A small rectilinear grid with 24 pairs (a mix of visible and blocked), built from
    integer arithmetic and numpy's PCG64 stream only, so its answers are reproducible."""
    r, c = np.mgrid[0:9, 0:11]
    z = ((r * 7 + c * 13) % 17) * 1.5 + 0.25 * r
    xs = np.concatenate([[0.0], np.cumsum(np.tile([1.5, 2.0, 2.5, 3.0, 1.0], 2))]) + 100.0
    ys = np.arange(9) * 2.0 - 7.0
    g = HeightGrid.from_coords(z, xs, ys)
    rng = np.random.default_rng(2012)
    xy = rng.random((2, 24, 2)) * [xs[-1] - xs[0], ys[-1] - ys[0]] + [xs[0], ys[0]]
    a = np.column_stack([xy[0], g.height_at(xy[0]) + rng.uniform(-1.0, 15.0, 24)])
    b = np.column_stack([xy[1], g.height_at(xy[1]) + rng.uniform(-1.0, 15.0, 24)])
    return g, a, b


# min_clearance of _golden_case() computed by the code before end_radius existed
# (commit 9363b43), as float.hex: end_radius = 0 must reproduce these bits.
_GOLDEN_MIN_CLEARANCE = [
    "-0x1.2a57ce7fb99c2p+3", "-0x1.0c10f897ae382p+3", "0x1.08c8831398180p-3", "0x1.02a7640948e00p-3",
    "0x1.254ed561332d8p+2", "0x1.c124dcc3efe40p-3", "0x1.5bfc3ab8be840p+0", "-0x1.7a4ee1f2a6f20p-1",
    "-0x1.ed684392b3630p+0", "0x1.6dd7de7ccb398p+1", "0x1.3666237d6a550p+2", "-0x1.b05304ac3bb00p-2",
    "0x1.b11f95705e520p+1", "0x1.b3740ec65d100p-2", "-0x1.f4df6c4df6cd0p+1", "0x1.79e811f67109cp+2",
    "0x1.08cfb0e4c5c12p+2", "0x1.69d2459d8a4c8p+1", "-0x1.5edde0b394000p-3", "0x1.6b9e0316e7f8cp+2",
    "-0x1.6084a6240d820p-1", "-0x1.af3765c737e24p+2", "0x1.ca73fd586fb70p+0", "-0x1.183c818095040p+2",
]
_GOLDEN_LOS = [0, 0, 1, 1, 1, 1, 1, 0, 0, 1, 1, 0, 1, 1, 0, 1, 1, 1, 0, 1, 0, 0, 1, 0]


def test_end_radius_zero_is_bit_identical_to_before():
    g, a, b = _golden_case()
    golden = np.array([float.fromhex(h) for h in _GOLDEN_MIN_CLEARANCE])
    # the invariant beside the golden numbers: they are the exact minima
    np.testing.assert_allclose(golden, brute_min_clearance(g, a, b), rtol=0, atol=clearance_tolerance(g))
    for kw in ({}, {"end_radius": 0.0}, {"end_radius": 0}, {"end_radius": np.float32(0.0)}):
        m = min_clearance(g, a, b, **kw)
        assert [float(v).hex() for v in m] == _GOLDEN_MIN_CLEARANCE, kw
        assert min_clearance(g.to_tin(), a, b, **kw).tobytes() == min_clearance(g.to_tin(), a, b).tobytes()
        for engine in ("grid", "embree"):
            assert line_of_sight(g, a, b, engine=engine, **kw).astype(int).tolist() == _GOLDEN_LOS, (engine, kw)
            np.testing.assert_array_equal(
                visibility_matrix(g, a, engine=engine, **kw), visibility_matrix(g, a, engine=engine)
            )
    # a radius shorter than the trim leaves the interval unchanged: the same bits again
    tiny = 0.5 * trim_length(g) * np.hypot(*(b - a)[:, :2].T).min() / np.linalg.norm(b - a, axis=1).max()
    assert min_clearance(g, a, b, end_radius=tiny).tobytes() == golden.tobytes()


@pytest.mark.parametrize("cells", [1.0, 3.7])
@pytest.mark.parametrize("name", ["mountains", "rectilinear", "utm", "dem:west_bijou_escarpment_co"])
def test_end_radius_matches_brute_force(name, cells):
    g = terrain(name)
    r = cells * _cell(g)
    a, b = random_pairs(g, 100, 0.5, seed=15)
    # short pairs (a few cells, some shorter than 2 r) with ends up to 3 below or above the surface
    a2 = sample_points(g, 60, seed=16, offset=0.0)
    xmin, xmax, ymin, ymax = g.extent
    rng = np.random.default_rng(17)
    a2[:, 2] += rng.uniform(-3.0, 3.0, 60)
    xy = np.clip(a2[:, :2] + rng.normal(scale=3 * r, size=(60, 2)), [xmin, ymin], [xmax, ymax])
    b2 = np.column_stack([xy, g.height_at(xy) + rng.uniform(-3.0, 3.0, 60)])
    a = np.concatenate([a, a2])
    b = np.concatenate([b, b2])
    tol = clearance_tolerance(g)
    got = min_clearance(g, a, b, end_radius=r)
    ref = brute_min_clearance(g, a, b, end_radius=r)
    np.testing.assert_array_equal(np.isinf(got), np.isinf(ref))
    fin = np.isfinite(ref)
    np.testing.assert_allclose(got[fin], ref[fin], rtol=0, atol=tol)
    assert 0 < (~fin).sum() < 60  # some short pairs have nothing to test, most do
    np.testing.assert_array_equal(line_of_sight(g, a, b, engine="grid", end_radius=r), got >= -tol)
    # the radius matters on these pairs (it is not a no-op)
    assert (got > min_clearance(g, a, b) + tol).sum() >= 20


def _ridge_grid():
    """5 x 11 samples, 1 m cells, a 10 m wall along x = 2 (the surface falls to 0 at x = 1 and 3)."""
    z = np.zeros((5, 11))
    z[:, 2] = 10.0
    return HeightGrid(z, dx=1.0, dy=1.0)


def _engines(as_tin):
    return ("auto", "embree") + (() if as_tin else ("grid",))


@pytest.mark.parametrize("as_tin", [False, True])
def test_end_radius_hand_cases_ridge(as_tin):
    g = _ridge_grid()
    t = g.to_tin() if as_tin else g
    # a level segment 1 m high from x = 0 to x = 10 along y = 2; the wall is 2 m from a.
    # r <= 2 keeps the crest in; r = 2.5 and 2.95 keep part of its far slope (surface
    # 5 and 0.5); r >= 3 cuts the wall out; r = 5 leaves nothing (L_h = 10 = 2 r).
    a = np.array([[0.0, 2.0, 1.0]])
    b = np.array([[10.0, 2.0, 1.0]])
    radii = [0.0, 1.5, 2.0, 2.5, 2.95, 3.0, 4.9, 5.0]
    expect = [-9.0, -9.0, -9.0, -4.0, 0.5, 1.0, 1.0, np.inf]
    # the radius is horizontal: a steep segment from (0, -30) to (10, 50) rises 8 per
    # metre of x, crosses z = 0 at x = 3.75 and is above the flat ground from there;
    # as a 3-D length, r = 3.75 would start the test at x = 0.47 instead
    a2 = np.array([[0.0, 2.0, -30.0]])
    b2 = np.array([[10.0, 2.0, 50.0]])
    radii2 = [3.5, 3.75, 4.0]
    expect2 = [-2.0, 0.0, 2.0]
    for p, q, rr, ee in ((a, b, radii, expect), (a2, b2, radii2, expect2)):
        for r, e in zip(rr, ee):
            for u, v in ((p, q), (q, p)):
                m = min_clearance(t, u, v, end_radius=r)
                np.testing.assert_allclose(m, [e], rtol=0, atol=1e-9, err_msg=f"r = {r}")
                for engine in _engines(as_tin):
                    assert line_of_sight(t, u, v, engine=engine, end_radius=r).tolist() == [e >= 0], (engine, r)


def _slope_grid():
    """6 x 11 samples, 1 m cells: a 2 m ridge along x = 2 (all rows) and a 5 m wall along
    x = 6 in rows 3..5 only."""
    z = np.zeros((6, 11))
    z[:, 2] = 2.0
    z[3:, 6] = 5.0
    return HeightGrid(z, dx=1.0, dy=1.0)


@pytest.mark.parametrize("as_tin", [False, True])
def test_end_radius_point_below_the_surface(as_tin):
    # The identity-relocation case: a sits 1 m below the ridge crest (x = 2, surface 2) and
    # looks along +x at b, 1 m above flat ground. The surface falls as 2 (3 - x), so the
    # segment (z = 1) is underground for x in [2, 2.5): blocked while r < 0.5, visible
    # (grazing at r = 0.5) once r covers that part. Along y = 4 the wall at x = 6 blocks
    # whatever r leaves it in.
    g = _slope_grid()
    t = g.to_tin() if as_tin else g
    cases = [
        # (y, r, expected min clearance)
        (1.0, 0.25, -0.5),
        (1.0, 0.5, 0.0),
        (1.0, 0.75, 0.5),
        (1.0, 2.0, 1.0),
        (1.0, 4.0, np.inf),  # L_h = 8 = 2 r
        (4.0, 0.75, -4.0),
        (4.0, 3.5, -4.0),
        (4.0, 3.9, -4.0),  # x in [5.9, 6.1] still holds the wall's crest
    ]
    for y, r, e in cases:
        a = np.array([[2.0, y, 1.0]])
        b = np.array([[10.0, y, 1.0]])
        for u, v in ((a, b), (b, a)):
            np.testing.assert_allclose(min_clearance(t, u, v, end_radius=r), [e], rtol=0, atol=1e-9, err_msg=f"{y} {r}")
            for engine in _engines(as_tin):
                assert line_of_sight(t, u, v, engine=engine, end_radius=r).tolist() == [e >= 0], (engine, y, r)
    # without a radius the point is blocked by the surface right above it (clearance -1
    # at a, raised by the trim only)
    a = np.array([[2.0, 1.0, 1.0]])
    b = np.array([[10.0, 1.0, 1.0]])
    m0 = min_clearance(t, a, b)[0]
    assert -1.0 < m0 < -0.999
    for engine in _engines(as_tin):
        assert not line_of_sight(t, a, b, engine=engine)[0]
    # the same pair through the matrix
    for engine in _engines(as_tin):
        vm = visibility_matrix(t, np.concatenate([a, b]), engine=engine, end_radius=0.75)
        assert vm.all()


@pytest.mark.parametrize("engine", ["grid", "embree"])
def test_end_radius_short_segments_are_visible(engine):
    g = _spike3()
    # a segment 5 below the ground, 1 m long horizontally: nothing to test once 2 r >= 1
    a = np.array([[0.5, 1.0, -5.0]])
    b = np.array([[1.5, 1.0, -5.0]])
    assert np.isinf(min_clearance(g, a, b, end_radius=0.5)).all()
    assert line_of_sight(g, a, b, engine=engine, end_radius=0.5).all()
    assert line_of_sight(g, a, b, engine=engine, end_radius=0.7).all()
    # just below half the length, the middle of the segment (under the spike) is tested
    m = min_clearance(g, a, b, end_radius=0.49)[0]
    assert m == pytest.approx(-15.0, abs=1e-9)  # the spike's crest at x = 1
    assert not line_of_sight(g, a, b, engine=engine, end_radius=0.49).any()
    # vertical segments have L_h = 0: nothing to test for any r > 0 (tested for r = 0)
    v0 = np.array([[0.5, 0.25, -3.0], [1.0, 1.0, 5.0]])
    v1 = np.array([[0.5, 0.25, 4.0], [1.0, 1.0, 20.0]])
    assert np.isinf(min_clearance(g, v0, v1, end_radius=1e-9)).all()
    assert line_of_sight(g, v0, v1, engine=engine, end_radius=1e-9).all()
    assert not line_of_sight(g, v0, v1, engine=engine).all()
    # in a matrix, points closer than 2 r (horizontally) see each other
    pts = np.array([[0.2, 0.2, -9.0], [0.6, 0.3, -9.0], [1.8, 1.9, -9.0]])
    vm = visibility_matrix(g, pts, engine=engine, end_radius=0.3)
    np.testing.assert_array_equal(vm, [[1, 1, 0], [1, 1, 0], [0, 0, 1]])


@pytest.mark.parametrize("name", ["mountains", "rough", "utm", "dem:mount_st_helens_wa"])
def test_end_radius_engines_agree_identity_relocation(name):
    # points of the terrain T, tested on a coarser surface S (every other sample) with
    # their own heights (the identity relocation), r = one cell of S
    g = terrain(name)
    s = g.subsample(2)
    r = _cell(s)
    rng = np.random.default_rng(31)
    xy = sample_points(s, 1200, seed=rng, offset=0.0)[:, :2]
    pts = np.column_stack([xy, g.height_at(xy)])
    a, b = pts[:600], pts[600:]
    tol = clearance_tolerance(s)
    m0 = min_clearance(s, a, b)
    m1 = min_clearance(s, a, b, end_radius=r)
    los = line_of_sight(s, a, b, engine="grid", end_radius=r)
    np.testing.assert_array_equal(los, m1 >= -tol)
    emb = line_of_sight(s, a, b, engine="embree", end_radius=r)
    clear = np.abs(m1) > embree_tolerance(s)
    bad = np.flatnonzero(clear & (los != emb))
    assert bad.size == 0, f"{bad.size} non-degenerate disagreements (clearances {m1[bad[:5]]})"
    assert clear.sum() >= 300
    # the TIN of S (the exact clipper) gives the same minima
    np.testing.assert_allclose(min_clearance(s.to_tin(), a, b, end_radius=r), m1, rtol=0, atol=tol)
    # the tested interval shrinks: no pair gets lower, several blocked pairs become visible
    assert (m1 >= m0 - tol).all()
    vis0 = m0 >= -tol
    assert not (vis0 & ~los).any()
    print(f"{name}: {int((~vis0 & los).sum())} of 600 pairs become visible with r = {r:g}")
    assert (~vis0 & los).sum() > 0


@pytest.mark.parametrize("engine", ["grid", "embree"])
def test_matrix_with_end_radius(engine):
    g = terrain("hills")
    s = g.subsample(3)
    xy = sample_points(s, 60, seed=12, offset=0.0)[:, :2]
    pts = np.column_stack([xy, g.height_at(xy)])
    r = _cell(s)
    vm = visibility_matrix(s, pts, engine=engine, end_radius=r)
    np.testing.assert_array_equal(vm, vm.T)
    assert vm.diagonal().all()
    i, j = np.triu_indices(60, 1)
    np.testing.assert_array_equal(vm[i, j], line_of_sight(s, pts[i], pts[j], engine=engine, end_radius=r))
    if engine == "grid":
        vm0 = visibility_matrix(s, pts, engine=engine)
        assert (vm >= vm0).all() and (vm > vm0).any()


def test_end_radius_bad_input():
    g = _spike3()
    ok = np.array([[0.5, 0.5, 1.0]])
    for fn, args in ((min_clearance, (ok, ok)), (line_of_sight, (ok, ok)), (visibility_matrix, (ok,))):
        for bad in (-1.0, np.nan, np.inf, -np.inf):
            with pytest.raises(ValueError, match=r"end_radius must be finite and >= 0 \(a horizontal distance"):
                fn(g, *args, end_radius=bad)
        for bad in ("1", None, True, [1.0, 2.0]):
            with pytest.raises(TypeError, match="end_radius must be a real number"):
                fn(g, *args, end_radius=bad)
    with pytest.raises(ValueError, match="got -0.5"):
        line_of_sight(g.to_tin(), ok, ok, end_radius=-0.5)


_radius = st.floats(0.0, 12.0)


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(_pt, _pt), min_size=1, max_size=20), _radius, _radius)
@example([((0.1, 0.5, -2.0), (0.9, 0.5, 1.0))], 0.0, 2.5)
def test_end_radius_monotone(pairs, r1, r2):
    """A larger radius tests a sub-interval: the minimum never drops, visible stays visible."""
    r1, r2 = sorted((r1, r2))
    a = np.array([_world(_G, p) for p, _ in pairs])
    b = np.array([_world(_G, q) for _, q in pairs])
    tol = clearance_tolerance(_G)
    m1 = min_clearance(_G, a, b, end_radius=r1)
    m2 = min_clearance(_G, a, b, end_radius=r2)
    # tol absorbs the rounding of the clearance at the new interval ends
    assert (m2 >= m1 - tol).all()
    v1 = line_of_sight(_G, a, b, end_radius=r1)
    v2 = line_of_sight(_G, a, b, end_radius=r2)
    assert not (v1 & ~v2).any()
    np.testing.assert_array_equal(v2, m2 >= -tol)


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(_pt, _pt), min_size=1, max_size=20), _radius)
@example([((0.0, 0.0, 0.0), (1.0, 1.0, 0.0)), ((0.5, 0.5, -1.0), (0.5, 0.5, 0.0))], 1.0)
def test_end_radius_symmetric(pairs, r):
    a = np.array([_world(_G, p) for p, _ in pairs])
    b = np.array([_world(_G, q) for _, q in pairs])
    np.testing.assert_array_equal(min_clearance(_G, a, b, end_radius=r), min_clearance(_G, b, a, end_radius=r))
    tin = _G.to_tin()
    np.testing.assert_array_equal(min_clearance(tin, a, b, end_radius=r), min_clearance(tin, b, a, end_radius=r))
    for engine in ("grid", "embree"):
        np.testing.assert_array_equal(
            line_of_sight(_G, a, b, engine=engine, end_radius=r), line_of_sight(_G, b, a, engine=engine, end_radius=r)
        )


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(_pt, _pt), min_size=1, max_size=20), _radius, st.floats(-5000.0, 5000.0))
@example([((0.0, 0.5, -1.0), (1.0, 0.5, 0.0))], 3.0, 1234.5)
def test_end_radius_unchanged_by_vertical_shift(pairs, r, shift):
    a = np.array([_world(_G, p) for p, _ in pairs])
    b = np.array([_world(_G, q) for _, q in pairs])
    g2 = HeightGrid.from_coords(_G.z + shift, _G.xs, _G.ys)
    up = np.array([0.0, 0.0, shift])
    np.testing.assert_array_equal(
        line_of_sight(_G, a, b, end_radius=r), line_of_sight(g2, a + up, b + up, end_radius=r)
    )


def test_the_exact_engine_is_the_grid_walk_on_grids_and_the_tin_clipper_on_tins():
    """engine='exact' runs on both kinds (compare and evaluate ask one engine for T and S(T)),
    and on each it is the exact engine of that kind, pair for pair and in the matrix."""
    g = terrain("rough")
    tin = g.to_tin()
    a, b = random_pairs(g, 400, 1.0, seed=11)
    pts = sample_points(g, 60, seed=12, offset=1.0)
    for surface, own in ((g, "grid"), (tin, "tin")):
        np.testing.assert_array_equal(line_of_sight(surface, a, b, engine="exact"),
                                      line_of_sight(surface, a, b, engine=own))
        np.testing.assert_array_equal(visibility_matrix(surface, pts, engine="exact"),
                                      visibility_matrix(surface, pts, engine=own))
        for kc in (0.0, 0.85714):
            np.testing.assert_array_equal(line_of_sight(surface, a, b, engine="exact", curvature=kc),
                                          line_of_sight(surface, a, b, engine=own, curvature=kc))
    # the TIN of the grid's own surface: the exact engines agree across the two kinds
    np.testing.assert_array_equal(line_of_sight(tin, a, b, engine="exact"), line_of_sight(g, a, b, engine="exact"))
