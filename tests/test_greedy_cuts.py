"""Greedy cuts (Silva, Mitchell & Kaufman 1995): the ε guarantee, height-field rules, budget."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import simplifiers
from conftest import DEM_NAMES, shared_dem_120
from simplifiers import budget_tolerance, check_height_field, vertex_budget
from simplifiers.greedy_cuts import build, greedy_cuts
from terrainvis import HeightGrid
from terrainvis.errors import NodataError, SimplificationError
from terrainvis.synthetic import KINDS, bundled_terrain


# ------------------------------------------------------------- brute-force references
def brute_force_errors(tin, grid):
    """|TIN - z| at every sample, from each face's own plane, independent of any kernel.

    For every face, every sample in its bounding box is tested with barycentric
    coordinates in world space (inclusive, to 1e-12); a sample in several faces (on a
    shared edge) keeps its largest error. Returns the (rows, cols) errors (NaN where no
    face covers the sample).
    """
    xs, ys, z = grid.xs, grid.ys, grid.z
    v = tin.vertices
    err = np.full(grid.shape, np.nan)
    for f in tin.faces:
        p = v[f]
        c0 = np.searchsorted(xs, p[:, 0].min())
        c1 = np.searchsorted(xs, p[:, 0].max(), side="right")
        r0 = np.searchsorted(ys, p[:, 1].min())
        r1 = np.searchsorted(ys, p[:, 1].max(), side="right")
        X, Y = np.meshgrid(xs[c0:c1], ys[r0:r1])
        (x0, y0, z0), (x1, y1, z1), (x2, y2, z2) = p
        det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        l1 = ((X - x0) * (y2 - y0) - (x2 - x0) * (Y - y0)) / det
        l2 = ((x1 - x0) * (Y - y0) - (X - x0) * (y1 - y0)) / det
        l0 = 1.0 - l1 - l2
        inside = (l0 >= -1e-12) & (l1 >= -1e-12) & (l2 >= -1e-12)
        e = np.abs(l0 * z0 + l1 * z1 + l2 * z2 - z[r0:r1, c0:c1])
        block = err[r0:r1, c0:c1]
        block[inside] = np.fmax(block[inside], e[inside])
    return err


def vertex_cells(tin, grid):
    """(row, col) of every vertex, asserting that it is exactly a grid sample (a subset TIN)."""
    v = tin.vertices
    c = np.searchsorted(grid.xs, v[:, 0])
    r = np.searchsorted(grid.ys, v[:, 1])
    assert (c < grid.shape[1]).all() and (r < grid.shape[0]).all()
    np.testing.assert_array_equal(grid.xs[c], v[:, 0])
    np.testing.assert_array_equal(grid.ys[r], v[:, 1])
    np.testing.assert_array_equal(grid.z[r, c], v[:, 2])
    return r, c


def assert_conforming(tin):
    """No T-junction: no vertex lies inside an edge it does not end (exact, brute force)."""
    v = tin.vertices[:, :2]
    edges = np.unique(np.sort(tin.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    a, b = v[edges[:, 0]], v[edges[:, 1]]
    for k in range(v.shape[0]):
        p = v[k]
        cross = (b[:, 0] - a[:, 0]) * (p[1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (p[0] - a[:, 0])
        dot = (p[0] - a[:, 0]) * (b[:, 0] - a[:, 0]) + (p[1] - a[:, 1]) * (b[:, 1] - a[:, 1])
        len2 = (b[:, 0] - a[:, 0]) ** 2 + (b[:, 1] - a[:, 1]) ** 2
        on = (cross == 0) & (dot > 0) & (dot < len2) & (edges[:, 0] != k) & (edges[:, 1] != k)
        assert not on.any(), f"vertex {k} lies inside edge {edges[np.flatnonzero(on)[0]]}"


def assert_rules(tin, grid, budget=None):
    """The registry's rules, asserted directly."""
    xmin, xmax, ymin, ymax = grid.extent
    v = tin.vertices
    for cx, cy in ((xmin, ymin), (xmax, ymin), (xmin, ymax), (xmax, ymax)):
        assert ((v[:, 0] == cx) & (v[:, 1] == cy)).any()
    assert tin.is_height_field()
    assert (tin.face_areas() > 0).all()
    assert tin.extent == grid.extent
    edges = np.sort(tin.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    assert counts.max() <= 2
    bverts = np.unique(uniq[counts == 1])
    assert ((v[bverts, 0] == xmin) | (v[bverts, 0] == xmax) | (v[bverts, 1] == ymin) | (v[bverts, 1] == ymax)).all()
    assert not np.isnan(tin.height_on_grid(grid.xs, grid.ys)).any()
    if budget is not None:
        assert abs(tin.n_vertices - budget) <= budget_tolerance(budget)
    check_height_field(tin, grid, method="greedy-cuts", budget=budget)


def assert_guarantee(tin, grid, eps):
    err = brute_force_errors(tin, grid)
    assert not np.isnan(err).any(), "a sample is covered by no face"
    scale = max(1.0, float(np.abs(grid.z).max()))
    assert err.max() <= eps + 1e-12 * scale, f"max error {err.max()} exceeds epsilon {eps}"
    return err.max()


@pytest.fixture(scope="module")
def bundled():
    return {k: bundled_terrain(k) for k in KINDS}


# ------------------------------------------------------------- hand-worked
def test_a_plane_needs_only_its_corners():
    z = np.add.outer(2.0 * np.arange(7.0), -3.0 * np.arange(9.0)) + 5.0  # z = 2 r - 3 c + 5
    g = HeightGrid(z, dx=10.0, dy=20.0)
    tin = greedy_cuts(g, 0.0)
    assert tin.n_vertices == 4 and tin.n_faces == 2
    assert_rules(tin, g)
    assert assert_guarantee(tin, g, 0.0) == pytest.approx(0.0, abs=1e-12)


def test_a_single_peak_is_kept_at_small_epsilon_and_dropped_at_its_height():
    z = np.zeros((5, 5))
    z[2, 2] = 4.0
    g = HeightGrid(z)
    tin = greedy_cuts(g, 0.0)
    r, c = vertex_cells(tin, g)
    assert ((r == 2) & (c == 2)).any()  # the peak must be a vertex for error 0
    assert assert_guarantee(tin, g, 0.0) == 0.0
    assert_rules(tin, g)
    # at eps = 4 the two corner triangles are valid (every plane value is 0)
    flat = greedy_cuts(g, 4.0)
    assert flat.n_vertices == 4
    assert assert_guarantee(flat, g, 4.0) == 4.0
    # just below, the peak cannot be skipped by any triangle that covers it
    tin = greedy_cuts(g, 3.999)
    r, c = vertex_cells(tin, g)
    assert ((r == 2) & (c == 2)).any()


def test_boundary_is_simplified_to_eps_valid_segments():
    # a bump in the middle of the bottom edge, elsewhere flat
    z = np.zeros((6, 11))
    z[0, 5] = 1.0
    g = HeightGrid(z)
    tin = greedy_cuts(g, 0.5)
    r, c = vertex_cells(tin, g)
    bottom = sorted(c[r == 0])
    assert 5 in bottom  # the bump is 1 > 0.5 off any segment that skips it
    assert assert_guarantee(tin, g, 0.5) <= 0.5
    tin = greedy_cuts(g, 1.0)
    r, c = vertex_cells(tin, g)
    assert sorted(c[r == 0]) == [0, 10]  # removable along the boundary
    assert tin.n_vertices == 4


def test_meta_and_subset_vertices(bundled):
    g = bundled["hills"]
    tin = greedy_cuts(g, 1.0)
    vertex_cells(tin, g)
    assert tin.attrs["epsilon"] == 1.0
    assert tin.attrs["n_ears"] + tin.attrs["n_bites"] == tin.n_faces
    # every face adding a vertex adds exactly one, to the boundary's vertices
    assert tin.attrs["plane_space"] == "index"


# ------------------------------------------------------------- the ε guarantee
@pytest.mark.parametrize("kind", KINDS)
def test_epsilon_guarantee_brute_force(bundled, kind):
    g = bundled[kind]
    ptp = float(np.ptp(g.z))
    for frac in (0.005, 0.02, 0.2):
        eps = frac * ptp
        tin = greedy_cuts(g, eps)
        assert_rules(tin, g)
        assert_guarantee(tin, g, eps)
        if tin.n_vertices < 3000:  # the brute-force T-junction check is O(vertices x edges)
            assert_conforming(tin)


def test_epsilon_zero_reproduces_the_grid(bundled):
    g = bundled["rough"].crop(rows=(0, 40), cols=(0, 50))
    tin = greedy_cuts(g, 0.0)
    assert assert_guarantee(tin, g, 0.0) == pytest.approx(0.0, abs=1e-9)
    assert_rules(tin, g)


def test_count_falls_with_epsilon_overall(bundled):
    g = bundled["mountains"]
    ptp = float(np.ptp(g.z))
    n = [greedy_cuts(g, f * ptp).n_vertices for f in (0.001, 0.01, 0.1, 1.0)]
    assert n[0] > n[1] > n[2] > n[3] == 4


grids = st.tuples(st.integers(2, 12), st.integers(2, 12), st.integers(0, 2**32 - 1), st.sampled_from(["int", "float", "smooth"]))


def _random_grid(rows, cols, seed, kind, rectilinear):
    rng = np.random.default_rng(seed)
    if kind == "int":
        z = rng.integers(0, 4, size=(rows, cols)).astype(float)
    elif kind == "float":
        z = rng.normal(size=(rows, cols))
    else:
        z = np.cumsum(np.cumsum(rng.normal(size=(rows, cols)), axis=0), axis=1)
    if rectilinear:
        xs = np.cumsum(rng.uniform(0.2, 3.0, cols))
        ys = np.cumsum(rng.uniform(0.2, 3.0, rows))
        return HeightGrid.from_coords(z, xs, ys)
    return HeightGrid(z, dx=float(rng.uniform(0.5, 3)), dy=float(rng.uniform(0.5, 3)))


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(grids, st.sampled_from([0.0, 0.1, 0.5, 1.0, 2.0]), st.booleans())
@example((3, 3, 0, "int"), 0.0, False)
@example((12, 12, 7, "int"), 0.5, True)
@example((2, 12, 1, "float"), 0.1, False)
def test_property_valid_subset_tin_within_epsilon(shape_seed, eps, rectilinear):
    rows, cols, seed, kind = shape_seed
    g = _random_grid(rows, cols, seed, kind, rectilinear)
    tin = greedy_cuts(g, eps)
    vertex_cells(tin, g)
    assert_rules(tin, g)
    assert_guarantee(tin, g, eps)
    assert_conforming(tin)


# ------------------------------------------------------------- budget through the registry
def _check_simplified(g, level):
    tin = simplifiers.simplify(g, "greedy-cuts", level)
    budget = vertex_budget(g.shape, level)
    assert_rules(tin, g, budget)
    vertex_cells(tin, g)
    err = assert_guarantee(tin, g, tin.attrs["epsilon"])
    assert tin.attrs["max_error"] == pytest.approx(err, rel=1e-9, abs=1e-12)
    assert tin.attrs["method"] == "greedy-cuts" and tin.attrs["budget"] == budget
    return tin


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("level", [1, 2, 3])
def test_budget_on_bundled_terrains(bundled, kind, level):
    _check_simplified(bundled[kind], level)


@pytest.mark.parametrize("name", DEM_NAMES)
def test_budget_on_real_dems(name):
    g = shared_dem_120(name)
    for level in (1, 2, 3):
        _check_simplified(g, level)


def test_rectilinear_and_non_square_cells(bundled):
    z = bundled["ridges"].z
    rng = np.random.default_rng(3)
    rect = HeightGrid.from_coords(z, np.cumsum(rng.uniform(5, 40, z.shape[1])), np.cumsum(rng.uniform(5, 60, z.shape[0])))
    tin = _check_simplified(rect, 2)
    assert tin.attrs["plane_space"] == "world"
    # on a uniform grid the cell aspect is an affine map: the same triangulation
    a = build(HeightGrid(z, dx=10.0, dy=37.0), 900)
    b = build(HeightGrid(z, dx=30.0, dy=30.0), 900)
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_array_equal(a.vertices[:, 2], b.vertices[:, 2])
    np.testing.assert_array_equal(a.vertices[:, 0] / 10.0, b.vertices[:, 0] / 30.0)


def test_deterministic(bundled):
    g = bundled["mountains"]
    a = simplifiers.simplify(g, "greedy-cuts", 2)
    b = simplifiers.simplify(g, "greedy-cuts", 2)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)
    assert a.attrs["epsilon"] == b.attrs["epsilon"]


def test_vertices_override_and_epsilon_guess(bundled):
    g = bundled["hills"]
    tin = simplifiers.simplify(g, "greedy-cuts", None, vertices=500)
    assert abs(tin.n_vertices - 500) <= budget_tolerance(500)
    guessed = build(g, 500, epsilon=tin.attrs["epsilon"])
    assert guessed.attrs["runs"] == 1  # the given ε is tried first and lands at once
    np.testing.assert_array_equal(guessed.faces, tin.faces)


# ------------------------------------------------------------- bad input
@pytest.mark.parametrize("budget", [3, 120 * 120 + 1, -5])
def test_bad_budget(bundled, budget):
    with pytest.raises(ValueError, match="vertex budget"):
        simplifiers.simplify(bundled["hills"], "greedy-cuts", None, vertices=budget)


def test_bad_arguments(bundled):
    g = bundled["hills"]
    with pytest.raises(ValueError, match="epsilon"):
        greedy_cuts(g, -1.0)
    with pytest.raises(ValueError, match="epsilon"):
        greedy_cuts(g, float("nan"))
    with pytest.raises(TypeError, match="epsilon"):
        greedy_cuts(g, "big")
    with pytest.raises(TypeError, match="grid"):
        greedy_cuts(g.z, 1.0)
    z = g.z.copy()
    z[3, 4] = np.nan
    with pytest.raises(NodataError):
        greedy_cuts(HeightGrid(z), 1.0)
    with pytest.raises(TypeError, match="epsilon"):
        simplifiers.simplify(g, "greedy-cuts", 1, epsilon="x")
    with pytest.raises(ValueError, match="n_vertices"):
        build(g, 3)
    with pytest.raises(TypeError, match="n_vertices"):
        build(g, 100.5)


def test_unreachable_budget_on_a_flat_grid():
    g = HeightGrid(np.full((10, 10), 3.0))
    with pytest.raises(SimplificationError, match="greedy-cuts"):
        simplifiers.simplify(g, "greedy-cuts", None, vertices=50)
    assert simplifiers.simplify(g, "greedy-cuts", None, vertices=4).n_vertices == 4
