"""Greedy insertion (Garland & Heckbert 1995): height-field rules, budget, pydelatin, Delaunay."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

import simplifiers
from simplifiers import vertex_budget
from simplifiers.greedy_insertion import GreedyInserter, build
from terrainvis import TIN, HeightGrid, bundled_terrain
from terrainvis.errors import NodataError
from terrainvis.core.deviation import vertical_errors
from terrainvis.core.synthetic import KINDS

from conftest import REAL_DEM_NAMES, shared_dem_120

METHOD = "greedy-insertion"


# ------------------------------------------------------------------ helpers
def assert_valid_tin(tin, grid, n_expected):
    """The registry's height-field rules, asserted directly, plus the exact count."""
    xmin, xmax, ymin, ymax = grid.extent
    v = tin.vertices
    assert tin.n_vertices == n_expected
    assert tin.is_height_field()
    assert (tin.face_areas() > 0).all()
    assert tin.footprint_area() == pytest.approx((xmax - xmin) * (ymax - ymin), rel=1e-9)
    for cx, cy in ((xmin, ymin), (xmax, ymin), (xmin, ymax), (xmax, ymax)):
        assert ((v[:, 0] == cx) & (v[:, 1] == cy)).any()
    # every vertex is a distinct grid sample with its height
    c = np.searchsorted(grid.xs, v[:, 0])
    r = np.searchsorted(grid.ys, v[:, 1])
    assert (grid.xs[c] == v[:, 0]).all() and (grid.ys[r] == v[:, 1]).all()
    assert (grid.z[r, c] == v[:, 2]).all()
    assert np.unique(r * grid.shape[1] + c).size == tin.n_vertices
    # boundary edges (used once) lie on the boundary lines; no edge used three times
    edges = np.sort(tin.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    assert counts.max() <= 2
    b = np.unique(uniq[counts == 1])
    assert ((v[b, 0] == xmin) | (v[b, 0] == xmax) | (v[b, 1] == ymin) | (v[b, 1] == ymax)).all()
    # Euler: a triangulated disc with nb boundary vertices has 2n - nb - 2 faces
    assert tin.n_faces == 2 * tin.n_vertices - b.size - 2
    assert not np.isnan(tin.height_on_grid(grid.xs, grid.ys)).any()


def empty_circle_violations(tin, sx=1.0, sy=1.0, rtol=1e-9):
    """Number of faces whose circumcircle (in the space (x * sx, y * sy)) strictly holds a vertex."""
    p = tin.vertices[:, :2] * np.array([sx, sy])
    a, b, c = p[tin.faces[:, 0]], p[tin.faces[:, 1]], p[tin.faces[:, 2]]
    bb, cc = b - a, c - a
    d = 2.0 * (bb[:, 0] * cc[:, 1] - bb[:, 1] * cc[:, 0])
    nb, nc = (bb**2).sum(1), (cc**2).sum(1)
    ux = (cc[:, 1] * nb - bb[:, 1] * nc) / d
    uy = (bb[:, 0] * nc - cc[:, 0] * nb) / d
    centre = a + np.column_stack([ux, uy])
    r2 = ux**2 + uy**2
    tree = cKDTree(p)
    bad = 0
    for f in range(tin.n_faces):
        near = tree.query_ball_point(centre[f], np.sqrt(r2[f]) * (1.0 - rtol))
        near = [k for k in near if k not in tin.faces[f]]
        bad += bool(near)
    return bad


def pydelatin_max_error(grid, n_vertices):
    """Max vertical error of pydelatin's greedy TIN with ``n_vertices`` vertices on a unit grid.

    pydelatin reads the array with y = H - 1 - row, so vertex (x, y) is our sample
    (row H - 1 - y, col x); this keeps its starting diagonal on ours. The error is measured
    by our own surface evaluator on the float64 heights (pydelatin stores float32).
    """
    pydelatin = pytest.importorskip("pydelatin")
    z = grid.z
    rows = z.shape[0]
    d = pydelatin.Delatin(np.ascontiguousarray(z), max_error=0.0, max_points=int(n_vertices))
    xy = np.rint(d.vertices[:, :2]).astype(np.int64)
    assert xy.shape[0] == n_vertices
    c, r = xy[:, 0], rows - 1 - xy[:, 1]
    faces = d.triangles.astype(np.int64)
    vert = np.column_stack([c, r, z[r, c]]).astype(np.float64)
    e = vert[faces]
    nz = (e[:, 1, 0] - e[:, 0, 0]) * (e[:, 2, 1] - e[:, 0, 1]) - (e[:, 2, 0] - e[:, 0, 0]) * (e[:, 1, 1] - e[:, 0, 1])
    faces = np.where((nz < 0)[:, None], faces[:, ::-1], faces)
    return vertical_errors(grid, TIN(vert, faces))[0]


@pytest.fixture(scope="module")
def bundled():
    return {k: bundled_terrain(k) for k in KINDS}


# ------------------------------------------------------------- hand-worked
def test_peak_on_the_diagonal_splits_both_triangles_in_four():
    z = np.zeros((3, 3))
    z[1, 1] = 5.0  # on the initial diagonal (0, 0)-(2, 2): split in 4
    g = HeightGrid(z, dx=10.0, dy=10.0)
    tin = build(g, 5)
    assert_valid_tin(tin, g, 5)
    assert tuple(tin.vertices[4]) == (10.0, 10.0, 5.0)
    assert tin.n_faces == 4
    assert (tin.faces == 4).any(axis=1).all()  # every face touches the peak
    assert tin.attrs["n_edge_splits"] == 1
    assert vertical_errors(g, tin)[0] == 0.0


def test_point_on_a_boundary_edge_splits_one_triangle_in_two():
    z = np.zeros((3, 3))
    z[0, 1] = -3.0  # middle of the bottom edge (y = ymin)
    g = HeightGrid(z)
    gi = GreedyInserter(g)
    assert gi.max_error == 3.0
    tin = gi.run(n_vertices=5).to_tin()
    assert_valid_tin(tin, g, 5)
    assert tuple(tin.vertices[4]) == (1.0, 0.0, -3.0)
    assert tin.n_faces == 3  # 2 + 1: the bottom triangle split in two
    assert tin.attrs["n_edge_splits"] == 1
    # (0, 2) lies inside the circle through (0, 0), (1, 0), (2, 2) (centre (0.5, 1.5),
    # r^2 = 2.5), so the diagonal flips to (1, 0)-(0, 2) and the sample (1, 1) is
    # interpolated halfway between -3 and 0
    assert tin.attrs["n_flips"] == 1
    edges = {tuple(sorted(e)) for f in tin.faces.tolist() for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    assert (3, 4) in edges and (0, 2) not in edges
    assert gi.max_error == 1.5
    assert vertical_errors(g, tin)[0] == 1.5


def test_interior_point_splits_in_three_and_flips_to_delaunay():
    z = np.zeros((4, 4))
    z[1, 2] = 7.0  # (col 2, row 1): strictly inside the lower triangle
    g = HeightGrid(z)
    tin = build(g, 5)
    assert_valid_tin(tin, g, 5)
    assert tuple(tin.vertices[4]) == (2.0, 1.0, 7.0)
    assert tin.attrs["n_edge_splits"] == 0
    # the new point is inside the circle of the upper triangle: the diagonal flips away
    assert tin.attrs["n_flips"] >= 1
    assert (tin.faces == 4).any(axis=1).all()
    assert empty_circle_violations(tin) == 0


def test_plane_is_exact_with_four_vertices():
    X, Y = np.meshgrid(np.arange(9.0), np.arange(7.0))
    g = HeightGrid(3.0 * X - 2.0 * Y + 5.0, dx=2.0, dy=3.0)
    gi = GreedyInserter(g)
    assert gi.max_error < 1e-12
    tin = build(g, 4)
    assert tin.n_vertices == 4 and tin.n_faces == 2
    assert vertical_errors(g, tin)[0] < 1e-12
    # a zero-error terrain still fills any budget (zero-error candidates are inserted)
    assert_valid_tin(build(g, 30), g, 30)


def test_full_budget_reproduces_the_grid():
    rng = np.random.default_rng(3)
    g = HeightGrid(rng.normal(size=(9, 11)), dx=2.0, dy=1.0)
    tin = build(g, g.size)
    assert_valid_tin(tin, g, g.size)
    assert vertical_errors(g, tin)[0] < 1e-12


# ------------------------------------------------- height-field rules, budget
@pytest.mark.parametrize("level", [1, 2, 3])
def test_bundled_terrains_meet_the_rules(bundled, level):
    for kind, g in bundled.items():
        tin = simplifiers.simplify(g, METHOD, level)
        budget = vertex_budget(g.shape, level)
        assert_valid_tin(tin, g, budget)
        assert tin.attrs["method"] == METHOD and tin.attrs["stopped_by"] == "budget"
        # the kernel's running maximum is the true max vertical error over every sample
        assert tin.attrs["greedy_max_error"] == pytest.approx(tin.attrs["max_error"], rel=1e-9, abs=1e-9), kind


@pytest.mark.parametrize("name", REAL_DEM_NAMES)
def test_real_dems_meet_the_rules(name):
    g = shared_dem_120(name)
    for level in (1, 2, 3):
        tin = simplifiers.simplify(g, METHOD, level)
        assert_valid_tin(tin, g, vertex_budget(g.shape, level))
        assert tin.attrs["greedy_max_error"] == pytest.approx(tin.attrs["max_error"], rel=1e-9, abs=1e-9)
    # Delaunay in world space even with non-square cells (dx != dy on some DEMs)
    assert empty_circle_violations(simplifiers.simplify(g, METHOD, 3)) == 0


def test_rectilinear_grid():
    rng = np.random.default_rng(5)
    xs = np.cumsum(rng.uniform(20.0, 40.0, 40))
    ys = 1000.0 + np.cumsum(rng.uniform(25.0, 35.0, 30))
    X, Y = np.meshgrid(xs, ys)
    z = 50.0 * np.sin(X / 300.0) * np.cos(Y / 200.0)
    g = HeightGrid.from_coords(z, xs, ys)
    tin = simplifiers.simplify(g, METHOD, n_vertices=150)
    assert_valid_tin(tin, g, 150)


def test_strongly_non_uniform_grid_never_returns_a_fold_over():
    # the triangulation is built in the scaled index space; on a strongly non-uniform
    # grid a thin triangle can fold over in world space: build must then raise, naming
    # the method and the cause, never hand back a bad TIN
    from terrainvis.errors import SimplificationError

    rng = np.random.default_rng(1)
    outcomes = []
    for _ in range(6):
        xs = np.cumsum(rng.uniform(1.0, 20.0, 40))
        ys = np.cumsum(rng.uniform(1.0, 20.0, 30))
        g = HeightGrid.from_coords(rng.normal(size=(30, 40)).cumsum(0).cumsum(1), xs, ys)
        for n in (60, 400):
            try:
                tin = build(g, n)
            except SimplificationError as exc:
                assert "greedy-insertion" in str(exc) and "fold over" in str(exc)
                outcomes.append("raised")
            else:
                assert_valid_tin(tin, g, n)
                outcomes.append("valid")
    assert "valid" in outcomes


# ------------------------------------------------------------- pydelatin
@pytest.mark.parametrize("kind", KINDS)
def test_max_error_matches_pydelatin(bundled, kind):
    g = HeightGrid(bundled[kind].z)  # pydelatin works on unit-spaced grids
    for n in (225, 900, 1000, 3600):
        ours = vertical_errors(g, build(g, n))[0]
        ref = pydelatin_max_error(g, n)
        assert abs(ours - ref) <= 0.05 * ref, (kind, n, ours, ref)


def test_max_error_matches_pydelatin_on_a_real_dem():
    g = HeightGrid(shared_dem_120("mount_st_helens_wa").z)
    for n in (225, 900, 3600):
        ours = vertical_errors(g, build(g, n))[0]
        ref = pydelatin_max_error(g, n)
        assert abs(ours - ref) <= 0.05 * ref, (n, ours, ref)


# ---------------------------------------------------- properties, options
@settings(max_examples=40, deadline=None)
@given(
    rows=st.integers(2, 9),
    cols=st.integers(2, 9),
    seed=st.integers(0, 2**31 - 1),
    frac=st.floats(0.0, 1.0),
    aspect=st.sampled_from([1.0, 0.5, 3.0]),
)
@example(rows=3, cols=3, seed=0, frac=1.0, aspect=1.0)
@example(rows=2, cols=9, seed=1, frac=0.5, aspect=3.0)
def test_random_small_grids(rows, cols, seed, frac, aspect):
    rng = np.random.default_rng(seed)
    z = rng.integers(-3, 4, size=(rows, cols)).astype(float)  # many ties and flat spots
    g = HeightGrid(z, dx=1.0, dy=aspect)
    n = 4 + int(round(frac * (g.size - 4)))
    gi = GreedyInserter(g).run(n_vertices=n)
    tin = gi.to_tin()
    assert_valid_tin(tin, g, n)
    assert gi.max_error == pytest.approx(vertical_errors(g, tin)[0], abs=1e-9)
    assert empty_circle_violations(tin) == 0


def test_max_error_stops_early_and_is_a_prefix(bundled):
    g = bundled["mountains"]
    full = build(g, 900)
    eps = 20.0
    tin = build(g, 900, max_error=eps)
    assert tin.attrs["stopped_by"] == "max_error"
    assert tin.n_vertices < 900
    assert vertical_errors(g, tin)[0] <= eps
    # it stopped at the first count meeting eps: one vertex fewer does not
    n = tin.n_vertices
    assert vertical_errors(g, build(g, n - 1))[0] > eps
    np.testing.assert_array_equal(tin.vertices, full.vertices[:n])
    # max_error that the budget reaches first: the budget wins
    assert build(g, 225, max_error=1e-3).attrs["stopped_by"] == "budget"


def test_resume_equals_single_run(bundled):
    g = bundled["ridges"]
    gi = GreedyInserter(g)
    gi.run(n_vertices=100)
    gi.run(n_vertices=700)
    one = build(g, 700)
    np.testing.assert_array_equal(gi.to_tin().vertices, one.vertices)
    np.testing.assert_array_equal(gi.to_tin().faces, one.faces)
    gi.run(max_error=gi.max_error / 2)
    assert gi.max_error <= vertical_errors(g, build(g, 700))[0] / 2
    with pytest.raises(ValueError, match="n_vertices"):
        gi.run(n_vertices=50)


def test_deterministic(bundled):
    g = bundled["rough"]
    a = simplifiers.simplify(g, METHOD, 2)
    b = simplifiers.simplify(g, METHOD, 2)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)


def test_input_arrays_untouched():
    z = np.random.default_rng(0).normal(size=(12, 10))
    keep = z.copy()
    g = HeightGrid(z)
    build(g, 40)
    np.testing.assert_array_equal(g.z, keep)


# -------------------------------------------------------------- bad input
def test_bad_budget_via_simplify(bundled):
    g = bundled["hills"]
    with pytest.raises(ValueError, match=r"n_vertices must be in \[4, 14400\] for a 120x120 grid, got 3"):
        simplifiers.simplify(g, METHOD, n_vertices=3)
    with pytest.raises(ValueError, match=r"n_vertices must be in \[4, 14400\] for a 120x120 grid, got 14401"):
        simplifiers.simplify(g, METHOD, n_vertices=g.size + 1)


def test_bad_input_to_build():
    g = HeightGrid(np.zeros((5, 5)))
    with pytest.raises(TypeError, match="grid"):
        build(np.zeros((5, 5)), 10)
    with pytest.raises(ValueError, match="n_vertices"):
        build(g, 3)
    with pytest.raises(ValueError, match="n_vertices"):
        build(g, 26)
    with pytest.raises(TypeError, match="n_vertices"):
        build(g, 10.0)
    with pytest.raises(ValueError, match="max_error"):
        build(g, 10, max_error=-1.0)
    with pytest.raises(TypeError, match="max_error"):
        build(g, 10, max_error="big")
    z = np.zeros((5, 5))
    z[2, 2] = np.nan
    with pytest.raises(NodataError):
        build(HeightGrid(z), 10)
    with pytest.raises(TypeError, match="n_vertices, max_error"):
        GreedyInserter(g).run()
