"""Vertical errors and the volume between two surfaces (terrainvis.core.deviation).

The exact volume (the default) is checked against manifold3d's boolean volume (the
``method="manifold"`` reference) on the bundled terrains, real DEM crops, every
simplification method at levels 1-3 and random grids and TINs; against closed forms
(parallel planes, a hat, two crossing planes); and for the invariant that the pieces it
integrates tile the footprint.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from simplifiers import simplify
from simplifiers.levels import max_level
from terrainvis import TIN, HeightGrid, bundled_terrain, synthetic_terrain
from terrainvis.core.mesh import signed_area2
from terrainvis.core._volume_kernels import abs_integral_tri, inside_one_edge
from terrainvis.core.compiling import from_python
from terrainvis.core.deviation import _volume_exact, vertical_errors, volume_error
from terrainvis.errors import NodataError

from conftest import shared_dem_120

# kernel-only kernels (no Python entry of their own: terrainvis.core.compiling.KERNEL_ONLY), called
# here through one made for them
abs_integral_tri = from_python(abs_integral_tri)
inside_one_edge = from_python(inside_one_edge)

REL = 1e-9  # the brief's agreement with manifold3d; measured agreement is ~1e-12 or better


# ------------------------------------------------------------------ helpers
def footprint(grid: HeightGrid) -> float:
    xmin, xmax, ymin, ymax = grid.extent
    return (xmax - xmin) * (ymax - ymin)


def assert_matches_manifold(fine: HeightGrid, coarse) -> float:
    """Exact == manifold3d to REL, and the integrated pieces tile the footprint."""
    exact = volume_error(fine, coarse)
    ref = volume_error(fine, coarse, method="manifold")
    relief = float(np.ptp(fine.z)) + 1.0
    # an absolute floor for (near) zero volumes: manifold3d's own cancellation error
    assert exact == pytest.approx(ref, rel=REL, abs=1e-12 * footprint(fine) * relief)
    tin = coarse.to_tin() if isinstance(coarse, HeightGrid) else coarse
    volume, covered = _volume_exact(fine, tin)
    assert volume == exact
    assert covered == pytest.approx(footprint(fine), rel=1e-12)
    return exact


def tin_from_points(xy: np.ndarray, z: np.ndarray) -> TIN:
    """A Delaunay TIN of the points with counter-clockwise faces (scipy).

    Triangulated relative to the points' lowest corner: with UTM-sized coordinates
    (5.3e5, 5.1e6) over a footprint of a few units, Qhull returned overlapping triangles
    in 31 of 4,000 random sets of this file's TIN generator (their faces covering 9.05 of a
    9.0 footprint: an invalid TIN, which volume_error rightly refuses), and none when shifted."""
    from scipy.spatial import Delaunay

    faces = Delaunay(xy - xy.min(axis=0)).simplices.astype(np.int64)
    v = np.column_stack([xy, z])
    a = signed_area2(v, faces)
    faces[a < 0] = faces[a < 0][:, ::-1]
    return TIN(v, faces)


def plane_abs_integral(alpha, beta, gamma, x0, x1, y0, y1) -> float:
    """Closed form of the integral of |alpha x + beta y + gamma| over [x0, x1] x [y0, y1].

    With G(u) = u|u|/2 the antiderivative of |u| and H(u) = u^2 |u| / 6 that of G,
    the integral is (H(u11) - H(u10) - H(u01) + H(u00)) / (alpha beta), u_ij = u(x_i, y_j).
    """

    def H(x, y):
        u = alpha * x + beta * y + gamma
        return u * u * abs(u) / 6.0

    return (H(x1, y1) - H(x1, y0) - H(x0, y1) + H(x0, y0)) / (alpha * beta)


def antidiagonal_tin(grid: HeightGrid) -> TIN:
    """The grid's samples triangulated along the other diagonal, (r, c+1)-(r+1, c)."""
    rows, cols = grid.shape
    X, Y = np.meshgrid(grid.xs, grid.ys)
    v = np.column_stack([X.ravel(), Y.ravel(), grid.z.ravel()])
    idx = np.arange(rows * cols).reshape(rows, cols)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    faces = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])
    return TIN(v, faces)


# ------------------------------------------------------------ vertical errors
def test_vertical_errors_grid_and_tin():
    fine = HeightGrid(np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 0.0]]))
    coarse = HeightGrid(np.zeros((2, 2)), dx=2.0, dy=2.0)
    mx, rms = vertical_errors(fine, coarse)
    assert mx == 3.0 and rms == pytest.approx(np.sqrt(9 / 9))
    assert vertical_errors(fine, coarse.to_tin()) == (mx, rms)
    with pytest.raises(ValueError, match="coarse must cover the fine grid"):
        vertical_errors(fine, HeightGrid(np.zeros((2, 2))))


@pytest.mark.parametrize("holes", [False, True])
@pytest.mark.parametrize("method", ["lls", "qec"])
def test_vertical_errors_against_every_sample_one_by_one(method, holes):
    """Max and RMS error against a plain loop over the fine samples (``height_at`` of each,
    nodata samples skipped); the fine grid with nodata takes the masked path."""
    fine = synthetic_terrain("hills", size=49, seed=3)
    coarse = simplify(fine, method, 2)
    if holes:
        z = fine.z.copy()
        z[5:9, 30:33] = np.nan
        z[40, 2] = np.nan
        fine = HeightGrid(z, fine.dx, fine.dy, (fine.xs[0], fine.ys[0]))
    diffs = []
    for r, y in enumerate(fine.ys):
        for c, x in enumerate(fine.xs):
            if np.isfinite(fine.z[r, c]):
                diffs.append(coarse.height_at([[x, y]])[0] - fine.z[r, c])
    diffs = np.array(diffs)
    mx, rms = vertical_errors(fine, coarse)
    assert diffs.size == fine.size - fine.n_nodata
    assert mx == np.abs(diffs).max()
    assert rms == pytest.approx(np.sqrt(np.mean(diffs ** 2)), rel=1e-12)


# ------------------------------------------------- the closed-form kernel pieces
def test_abs_integral_tri_hand_cases():
    # one sign: the mean of the vertex values times the area
    assert abs_integral_tri(6.0, 1.0, 2.0, 3.0) == 12.0
    assert abs_integral_tri(6.0, -1.0, -2.0, -3.0) == 12.0
    assert abs_integral_tri(6.0, 0.0, 0.0, 3.0) == 6.0
    # (1, -1, -1): the positive corner has area A/4 and integral A/12, the rest -A/3 + A/12
    assert abs_integral_tri(12.0, 1.0, -1.0, -1.0) == pytest.approx(6.0, rel=1e-15)
    # any order and either sign give the same value
    for d in [(1.0, -1.0, -1.0), (-1.0, 1.0, -1.0), (-1.0, -1.0, 1.0), (-1.0, 1.0, 1.0), (1.0, -1.0, 1.0)]:
        assert abs_integral_tri(12.0, *d) == pytest.approx(6.0, rel=1e-15)
    # a zero vertex on the zero line: (2, -2, 0) splits the triangle in two halves,
    # each a triangle with values (2, 0, 0) or (-2, 0, 0): 2 * (A/2) * 2/3
    assert abs_integral_tri(3.0, 2.0, -2.0, 0.0) == pytest.approx(2.0, rel=1e-15)


def split_integral(xy: np.ndarray, d: np.ndarray) -> float:
    """Reference for the integral of |d| over a triangle: cut it along d = 0 into polygons.

    Each side is clipped out (Sutherland-Hodgman, in plain Python), fanned into triangles,
    and integrated with the one-sign rule (area times the mean of the vertex values).
    """
    total = 0.0
    for sign in (1.0, -1.0):
        poly = []
        pts = [(xy[k, 0], xy[k, 1], sign * d[k]) for k in range(3)]
        for k in range(3):
            p, q = pts[k], pts[(k + 1) % 3]
            if p[2] >= 0:
                poly.append(p)
            if (p[2] > 0 > q[2]) or (p[2] < 0 < q[2]):
                t = p[2] / (p[2] - q[2])
                poly.append(tuple(p[i] + t * (q[i] - p[i]) for i in range(3)))
        for k in range(1, len(poly) - 1):
            (x0, y0, a), (x1, y1, b), (x2, y2, c) = poly[0], poly[k], poly[k + 1]
            area = 0.5 * abs((x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0))
            total += area * (a + b + c) / 3.0
    return total


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-10, 10, allow_subnormal=False), min_size=3, max_size=3),
    st.lists(st.floats(-5, 5, allow_subnormal=False), min_size=6, max_size=6),
)
@example([0.0, 2.0, -1.0], [0.0, 0.0, 1.0, 0.0, 0.0, 1.0])
@example([1.0, -1.0, 1e-12], [0.0, 0.0, 1.0, 0.0, 0.0, 1.0])
@example([0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0, 1.0])
def test_abs_integral_tri_against_splitting(d, corners):
    xy = np.array(corners).reshape(3, 2)
    area = 0.5 * abs((xy[1, 0] - xy[0, 0]) * (xy[2, 1] - xy[0, 1]) - (xy[2, 0] - xy[0, 0]) * (xy[1, 1] - xy[0, 1]))
    ref = split_integral(xy, np.array(d))
    # the reference's own rounding: its pieces' areas are computed from cut points
    scale = (1.0 + np.abs(xy).max()) ** 2 * (1.0 + np.abs(d).max())
    assert abs_integral_tri(area, *d) == pytest.approx(ref, rel=1e-12, abs=1e-14 * scale)


def test_inside_one_edge_splits_the_triangle():
    # e = x on the triangle A (-1, 0), B (1, 0), C (1, 2) of area 2, and d = 1: the line
    # x = 0 cuts AB at (0, 0) and AC at (0, 1), so the corner at A has area 1/2 and the
    # part where x >= 0 is the quad (0, 0), B, C, (0, 1) of area 3/2
    v, a = inside_one_edge(2.0, 1.0, 1.0, 1.0, -1.0, 1.0, 1.0)
    assert (v, a) == (pytest.approx(1.5, rel=1e-15), pytest.approx(1.5, rel=1e-15))
    v2, a2 = inside_one_edge(2.0, 1.0, 1.0, 1.0, 1.0, -1.0, -1.0)
    assert a + a2 == 2.0 and v + v2 == pytest.approx(2.0, rel=1e-15)


# -------------------------------------------------------------- hand-worked cases
@pytest.mark.parametrize("method", ["exact", "manifold"])
def test_volume_error_hand_cases(method):
    base = HeightGrid(np.zeros((3, 4)), dx=10.0, dy=20.0, origin=(560000.0, 5.1e6))
    raised = HeightGrid(np.full((2, 2), 2.5), dx=30.0, dy=40.0, origin=(560000.0, 5.1e6))
    # two parallel planes 2.5 apart over a 30 x 40 footprint
    assert volume_error(base, raised, method=method) == pytest.approx(2.5 * 30 * 40, rel=1e-12)
    assert volume_error(base, base, method=method) == pytest.approx(0.0, abs=1e-9)
    # a single peak of height 6 at the middle sample of a 3x3 grid, against a flat plane:
    # the volume of the piecewise-linear bump is 6 * (area of its support) / 3
    peak = np.zeros((3, 3))
    peak[1, 1] = 6.0
    g = HeightGrid(peak)
    flat = HeightGrid(np.zeros((2, 2)), dx=2.0, dy=2.0)
    # the support of the hat function is the 6 triangles around (1, 1), total area 3
    assert volume_error(g, flat, method=method) == pytest.approx(6.0 * 3.0 / 3.0, rel=1e-12)


def test_parallel_tilted_planes_rectilinear():
    # z = 0.3 x - 0.2 y sampled on a rectilinear grid, against the same plane raised by 1.5
    # as a 2-triangle TIN: every piece is a parallelogram slice of constant d = 1.5
    xs = 5.0e5 + np.array([0.0, 7.0, 9.5, 30.0, 31.0, 44.0])
    ys = 5.0e6 + np.array([0.0, 2.0, 13.0, 40.0])
    X, Y = np.meshgrid(xs - xs[0], ys - ys[0])
    fine = HeightGrid.from_coords(0.3 * X - 0.2 * Y + 100.0, xs, ys)
    corners = np.array([[xs[0], ys[0]], [xs[-1], ys[0]], [xs[-1], ys[-1]], [xs[0], ys[-1]]])
    zc = 0.3 * (corners[:, 0] - xs[0]) - 0.2 * (corners[:, 1] - ys[0]) + 101.5
    coarse = TIN(np.column_stack([corners, zc]), [[0, 1, 3], [1, 2, 3]])
    assert volume_error(fine, coarse) == pytest.approx(1.5 * footprint(fine), rel=1e-12)


@pytest.mark.parametrize(
    "alpha, beta, gamma",
    [(0.3, -0.2, 1.7), (-0.05, 0.11, -0.9), (1.0, 1.0, -34.6)],
)
def test_crossing_planes_closed_form(alpha, beta, gamma):
    # fine: the plane alpha x + beta y + gamma on a rectilinear grid (any triangulation of
    # samples of a plane is that plane); coarse: z = 0 as a Delaunay TIN of random points.
    # The zero line of the difference crosses fine and coarse triangles alike.
    rng = np.random.default_rng(7)
    ox, oy = 4.2e5, 4.6e6
    # coordinates that survive the trip to UTM and back unchanged, so that the samples
    # lie exactly on the plane in the local frame volume_error works in
    xs = (np.concatenate([[0.0], np.sort(rng.uniform(0, 31.0, 9)), [31.0]]) + ox) - ox
    ys = (np.concatenate([[0.0], np.sort(rng.uniform(0, 23.0, 7)), [23.0]]) + oy) - oy
    X, Y = np.meshgrid(xs, ys)
    fine = HeightGrid.from_coords(alpha * X + beta * Y + gamma, xs + ox, ys + oy)
    pts = np.concatenate([[[0, 0], [31, 0], [31, 23], [0, 23]], rng.uniform([0, 0], [31, 23], (25, 2))])
    coarse = tin_from_points(pts + [ox, oy], np.zeros(len(pts)))
    ref = plane_abs_integral(alpha, beta, gamma, 0.0, 31.0, 0.0, 23.0)
    assert volume_error(fine, coarse) == pytest.approx(ref, rel=1e-12)
    assert volume_error(fine, coarse, method="manifold") == pytest.approx(ref, rel=1e-9)


def test_many_pieces_against_closed_form():
    # 2 million fine triangles and a 301 x 301 coarse grid on other lines: millions of
    # overlay pieces, all summed in float64, against the closed form to 1e-12
    n = 1001
    xs = np.linspace(0.0, 30000.0, n)  # multiples of 30: exact in UTM coordinates too
    ys = np.linspace(0.0, 30000.0, n)
    alpha, beta, gamma = 0.013, -0.021, 95.0
    X, Y = np.meshgrid(xs, ys)
    fine = HeightGrid.from_coords(alpha * X + beta * Y + gamma, xs + 5.0e5, ys + 5.0e6)
    cx = np.concatenate([[0.0], np.linspace(55.5, 29950.0, 299), [30000.0]])
    cy = np.concatenate([[0.0], np.linspace(71.0, 29930.5, 299), [30000.0]])
    CX, CY = np.meshgrid(cx, cy)
    coarse = HeightGrid.from_coords(np.zeros_like(CX), cx + 5.0e5, cy + 5.0e6)
    ref = plane_abs_integral(alpha, beta, gamma, 0.0, 30000.0, 0.0, 30000.0)
    volume, covered = _volume_exact(fine, coarse.to_tin())
    assert volume == pytest.approx(ref, rel=1e-12)
    assert covered == pytest.approx(30000.0**2, rel=1e-13)


def test_result_does_not_depend_on_threads_or_origin():
    g = bundled_terrain("ridges")
    S = simplify(g, "greedy-insertion", 2)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = volume_error(g, S)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = volume_error(g, S)
    finally:
        numba.set_num_threads(before)
    assert one == many  # fixed chunks and an exact final sum: bit for bit
    shift = np.array([6.1e5, 5.2e6])
    g2 = HeightGrid.from_coords(g.z, g.xs + shift[0], g.ys + shift[1])
    S2 = TIN(S.vertices + [shift[0], shift[1], 0.0], S.faces)
    assert volume_error(g2, S2) == pytest.approx(one, rel=1e-12)


# ------------------------------------------------------ degenerate clipping
def test_coarse_edges_on_fine_vertices_and_lines():
    g = synthetic_terrain("rough", size=17, seed=3)
    tin = g.to_tin()
    # the same surface: every coarse edge is a fine edge
    assert volume_error(g, tin) <= 1e-12 * footprint(g) * np.ptp(g.z)
    assert volume_error(g, g) <= 1e-12 * footprint(g) * np.ptp(g.z)
    # the same triangles raised by 0.75: exactly 0.75 times the area
    raised = TIN(tin.vertices + [0.0, 0.0, 0.75], tin.faces)
    assert volume_error(g, raised) == pytest.approx(0.75 * footprint(g), rel=1e-12)
    # the other diagonal: edges cross the fine diagonals at the cell centres
    assert_matches_manifold(g, antidiagonal_tin(g))
    # every other sample, split along the other diagonal: coarse edges run along fine
    # grid lines and through fine vertices (x2 steps) and cross fine diagonals
    assert_matches_manifold(g, antidiagonal_tin(g.subsample(2)))
    # a fan from the centre sample to every boundary sample: edges of slopes p/q that
    # pass exactly through fine vertices between their ends
    rows, cols = g.shape
    X, Y = np.meshgrid(g.xs, g.ys)
    ring = [(0, c) for c in range(cols - 1)] + [(r, cols - 1) for r in range(rows - 1)]
    ring += [(rows - 1, c) for c in range(cols - 1, 0, -1)] + [(r, 0) for r in range(rows - 1, 0, -1)]
    rc = np.array(ring + [(rows // 2, cols // 2)])
    v = np.column_stack([X[rc[:, 0], rc[:, 1]], Y[rc[:, 0], rc[:, 1]], g.z[rc[:, 0], rc[:, 1]] + 3.0])
    m = len(ring)
    fan = TIN(v, [[i, (i + 1) % m, m] for i in range(m)])
    assert_matches_manifold(g, fan)


# ---------------------------------------------- agreement with manifold3d
@pytest.mark.parametrize(
    "name, irregular, regular",
    [
        ("hills", ("qec", 2), ("lls", 1)),
        ("mountains", ("greedy-insertion", 1), ("gls", 2)),
        ("rough", ("greedy-cuts", 2), ("feature", 3)),
        ("ridges", ("greedy-insertion", 3), ("simple", 2)),
        ("mesas", ("greedy-cuts", 1), ("lls", 3)),
    ],
)
def test_bundled_terrains_match_manifold(name, irregular, regular):
    g = bundled_terrain(name)
    for method, level in (irregular, regular):
        assert_matches_manifold(g, simplify(g, method, level))


@pytest.mark.parametrize("name", ["jacksboro_fault_tn", "mount_st_helens_wa", "green_mountains_vt", "jacksboro_window"])
def test_real_dems_match_manifold(name):
    g = shared_dem_120(name)  # UTM coordinates (jacksboro: 75 m x 92 m cells)
    for method, level in (("lls", 1), ("greedy-insertion", 2), ("simple", 3)):
        assert_matches_manifold(g, simplify(g, method, level))


@pytest.mark.parametrize("size", [40, 41])
@pytest.mark.parametrize("method", ["qec", "greedy-insertion", "greedy-cuts", "simple", "gls", "lls", "feature"])
def test_every_method_and_level_matches_manifold(method, size):
    # 40 is even, so the regular coarse grids have a wider last gap (rectilinear)
    g = synthetic_terrain("mountains", size=size, seed=1)
    for level in (1, 2, 3):
        S = simplify(g, method, level)
        if isinstance(S, HeightGrid) and size == 40:
            assert not S.is_uniform
        assert_matches_manifold(g, S)


def test_golden_values():
    # pinned from this implementation, each equal to manifold3d to < 1e-13 relative
    g = bundled_terrain("mountains")
    assert volume_error(g, simplify(g, "simple", 2)) == pytest.approx(GOLDEN_SIMPLE_2, rel=1e-12)
    assert volume_error(g, simplify(g, "lls", 1)) == pytest.approx(GOLDEN_LLS_1, rel=1e-12)


GOLDEN_SIMPLE_2 = 75664468.96469298
GOLDEN_LLS_1 = 21309369.795145568


# ------------------------------------------------ random grids and TINs
@st.composite
def fine_grids(draw):
    rows = draw(st.integers(2, 9))
    cols = draw(st.integers(2, 9))
    seed = draw(st.integers(0, 2**31 - 1))
    rectilinear = draw(st.booleans())
    rng = np.random.default_rng(seed)
    if rectilinear:
        xs = np.concatenate([[0.0], np.cumsum(rng.uniform(0.2, 3.0, cols - 1))])
        ys = np.concatenate([[0.0], np.cumsum(rng.uniform(0.2, 3.0, rows - 1))])
    else:
        xs = np.arange(cols) * 1.5
        ys = np.arange(rows) * 2.0
    origin = draw(st.sampled_from([(0.0, 0.0), (5.3e5, 5.1e6)]))
    z = rng.normal(100.0, 5.0, (rows, cols))
    if draw(st.booleans()):
        z = np.round(z)  # ties: zero differences on whole edges and vertices
    return HeightGrid.from_coords(z, xs + origin[0], ys + origin[1]), rng


def _random_coarse(g: HeightGrid, rng, kind: str):
    xmin, xmax, ymin, ymax = g.extent
    if kind == "level":
        if max_level(g.shape) < 1:  # too small to simplify: the same lines, other heights
            return g.copy_with(g.z + rng.normal(0.0, 1.0, g.shape))
        level = int(rng.integers(1, max_level(g.shape) + 1))
        return simplify(g, ["simple", "gls", "lls", "feature"][int(rng.integers(4))], level)
    if kind == "subgrid":  # coarse lines on fine lines, other heights
        cs = np.unique(np.concatenate([[0, g.shape[1] - 1], rng.integers(0, g.shape[1], 2)]))
        rs = np.unique(np.concatenate([[0, g.shape[0] - 1], rng.integers(0, g.shape[0], 2)]))
        z = g.z[np.ix_(rs, cs)] + rng.normal(0.0, 3.0, (rs.size, cs.size))
        return HeightGrid.from_coords(z, g.xs[cs], g.ys[rs])
    if kind == "offgrid":  # coarse lines anywhere
        cx = np.unique(np.concatenate([[xmin, xmax], rng.uniform(xmin, xmax, 3)]))
        cy = np.unique(np.concatenate([[ymin, ymax], rng.uniform(ymin, ymax, 3)]))
        return HeightGrid.from_coords(rng.normal(100.0, 5.0, (cy.size, cx.size)), cx, cy)
    # a Delaunay TIN: the corners, fine samples, points on fine lines and random points
    X, Y = np.meshgrid(g.xs, g.ys)
    samples = np.column_stack([X.ravel(), Y.ravel()])
    k = int(rng.integers(0, 6))
    on_lines = np.column_stack([rng.choice(g.xs, k), rng.uniform(ymin, ymax, k)])
    pts = np.concatenate([
        [[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]],
        samples[rng.choice(samples.shape[0], int(rng.integers(0, 6)))],
        on_lines,
        rng.uniform([xmin, ymin], [xmax, ymax], (int(rng.integers(0, 6)), 2)),
    ])
    pts = np.unique(pts, axis=0)
    return tin_from_points(pts, rng.normal(100.0, 5.0, pts.shape[0]))


def _utm_case():
    """A grid at UTM-sized coordinates whose random TIN (seed 2 of ``_random_coarse``) Qhull
    triangulated with overlapping faces before :func:`tin_from_points` shifted the points."""
    rng = np.random.default_rng(2)
    return HeightGrid(rng.normal(100.0, 5.0, (4, 2)), 2.0, 1.5, (530000.0, 5.1e6)), rng


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(fine_grids(), st.sampled_from(["level", "subgrid", "offgrid", "tin"]))
@example((HeightGrid(np.arange(9.0).reshape(3, 3)), np.random.default_rng(0)), "tin")
@example(_utm_case(), "tin")
def test_random_grids_and_tins_match_manifold(grid_rng, kind):
    g, rng = grid_rng
    coarse = _random_coarse(g, rng, kind)
    # scipy's Delaunay may leave a flat face among collinear points; manifold3d rejects it
    assume(not isinstance(coarse, TIN) or (coarse.face_areas() > 1e-9 * footprint(g)).all())
    exact = assert_matches_manifold(g, coarse)
    if isinstance(coarse, HeightGrid):
        # between two grids the volume is symmetric
        assert volume_error(coarse, g) == pytest.approx(exact, rel=1e-12, abs=1e-12 * footprint(g))


# ------------------------------------------------------ a dense midpoint sum
def test_volume_error_matches_integral_of_abs_difference():
    T = synthetic_terrain("rough", size=40, seed=2)
    for S in (simplify(T, "lls", 2), simplify(T, "greedy-insertion", 2)):
        # reference: the mean of |S - T| on a dense sampling (midpoint rule), times the area
        xmin, xmax, ymin, ymax = T.extent
        n = 800
        xs = xmin + (np.arange(n) + 0.5) * (xmax - xmin) / n
        ys = ymin + (np.arange(n) + 0.5) * (ymax - ymin) / n
        X, Y = np.meshgrid(xs, ys)
        xy = np.column_stack([X.ravel(), Y.ravel()])
        ref = np.abs(S.height_at(xy) - T.height_at(xy)).mean() * (xmax - xmin) * (ymax - ymin)
        assert volume_error(T, S) == pytest.approx(ref, rel=2e-3)


# ------------------------------------------------------------------ bad input
def test_volume_error_bad_input():
    g = HeightGrid(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="coarse must cover the extent"):
        volume_error(g, HeightGrid(np.zeros((2, 2))))
    with pytest.raises(TypeError, match="coarse must be"):
        volume_error(g, np.zeros((3, 3)))
    with pytest.raises(TypeError, match="fine must be"):
        volume_error(g.to_tin(), g)
    with pytest.raises(ValueError, match=r"method must be one of \['exact', 'manifold'\], got 'fast'"):
        volume_error(g, g, method="fast")
    with pytest.raises(TypeError):
        volume_error(g, g, "exact")  # method is keyword-only
    z = np.zeros((3, 3))
    z[0, 0] = np.nan
    with pytest.raises(NodataError, match="NaN"):
        volume_error(HeightGrid(z), g)
    with pytest.raises(NodataError, match="NaN"):
        volume_error(g, HeightGrid(z))
    # a TIN over only half of the footprint does not cover the extent's corner (2, 2)
    half = TIN(np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], float), [[0, 1, 2]])
    with pytest.raises(ValueError, match="coarse must cover the extent"):
        volume_error(HeightGrid(np.zeros((3, 3))), TIN(half.vertices[[0, 1]].tolist() + [[2.0, 1.0, 0.0]], [[0, 1, 2]]))
    # same bounding box as the grid, but only half of its footprint
    corner = TIN(np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [2, 2, 0]], float), [[0, 1, 2]])
    with pytest.raises(ValueError, match="coarse must cover the footprint"):
        volume_error(HeightGrid(np.zeros((3, 3))), corner)
    # a clockwise face (a fold) is not a height field, whatever the total area says
    square = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], float)
    folded = TIN(square, [[0, 1, 2], [0, 2, 3], [0, 3, 2], [0, 2, 3]])
    with pytest.raises(ValueError, match="counter-clockwise faces.*1 face\\(s\\) are clockwise, the first is face 2"):
        volume_error(HeightGrid(np.zeros((3, 3))), folded)
    for method in ("exact", "manifold"):
        with pytest.raises(ValueError, match="clockwise"):
            volume_error(HeightGrid(np.zeros((3, 3))), folded, method=method)
