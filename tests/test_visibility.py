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

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from conftest import DEM_NAMES, shared_dem_path
from terrainvis import HeightGrid, TIN
from terrainvis.errors import NodataError, OutsideFootprintError
from terrainvis.sampling import sample_points
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
    from terrainvis.synthetic import KINDS

    return KINDS


def _synthetic(kind):
    from terrainvis.synthetic import synthetic_terrain

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
def brute_min_clearance(grid: HeightGrid, a, b) -> np.ndarray:
    """Clearance at every crossing with x = xs[c], y = ys[r] and every cell-diagonal line.

    Extra points on the segment only add true clearance values, so evaluating at the
    crossings with every diagonal *line* (inside its cell or not) still gives the exact
    minimum. The surface comes from ``HeightGrid.height_at``.
    """
    delta = trim_length(grid)
    xs, ys = grid.xs, grid.ys
    X0, Y0 = np.meshgrid(xs[:-1], ys[:-1])
    WX, WY = np.meshgrid(np.diff(xs), np.diff(ys))
    X0, Y0, WX, WY = X0.ravel(), Y0.ravel(), WX.ravel(), WY.ravel()
    out = np.empty(a.shape[0])
    for i in range(a.shape[0]):
        d = b[i] - a[i]
        length = np.linalg.norm(d)
        if length <= 2 * delta:
            out[i] = np.inf
            continue
        tau = delta / length
        ts = [np.array([tau, 1 - tau])]
        with np.errstate(divide="ignore", invalid="ignore"):
            if d[0] != 0:
                ts.append((xs - a[i, 0]) / d[0])
            if d[1] != 0:
                ts.append((ys - a[i, 1]) / d[1])
            den = d[0] / WX - d[1] / WY
            td = ((a[i, 1] - Y0) / WY - (a[i, 0] - X0) / WX) / den
            ts.append(td[np.isfinite(td)])
        t = np.concatenate(ts)
        t = t[(t >= tau) & (t <= 1 - tau)]
        p = a[i] + t[:, None] * d
        out[i] = (p[:, 2] - grid.height_at(p[:, :2])).min()
    return out


def brute_tin_min_clearance(tin: TIN, a, b) -> np.ndarray:
    """Clearance at every crossing of the ground track with a TIN edge (plus the trimmed ends)."""
    delta = trim_length(tin)
    e = np.concatenate([tin.faces[:, [0, 1]], tin.faces[:, [1, 2]], tin.faces[:, [2, 0]]])
    P = tin.vertices[e[:, 0], :2]
    Q = tin.vertices[e[:, 1], :2]
    E = Q - P
    out = np.empty(a.shape[0])
    for i in range(a.shape[0]):
        d = b[i] - a[i]
        length = np.linalg.norm(d)
        tau = delta / length
        # a + t d = P + s E  (2-D)
        den = d[0] * E[:, 1] - d[1] * E[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((P[:, 0] - a[i, 0]) * E[:, 1] - (P[:, 1] - a[i, 1]) * E[:, 0]) / den
            s = ((P[:, 0] - a[i, 0]) * d[1] - (P[:, 1] - a[i, 1]) * d[0]) / den
        ok = np.isfinite(t) & (s >= -1e-12) & (s <= 1 + 1e-12) & (t >= tau) & (t <= 1 - tau)
        t = np.concatenate([[tau, 1 - tau], t[ok]])
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
    for engine in ENGINES[1:]:
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
    with pytest.raises(ValueError, match=r"engine must be one of \['auto', 'grid', 'embree'\], got 'bvh'"):
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
