"""Greedy cuts (Silva, Mitchell & Kaufman 1995): the ε guarantee, height-field rules, budget."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import simplifiers
from conftest import REAL_DEM_NAMES, shared_dem_120
from simplifiers import _gc_kernels as K
from simplifiers import budget_tolerance, check_height_field, vertex_budget
from simplifiers.greedy_cuts import _Triangulator, build, greedy_cuts
from terrainvis import HeightGrid, synthetic_terrain
from terrainvis.errors import NodataError, SimplificationError
from terrainvis.core.synthetic import KINDS
from terrainvis.io import bundled_terrain


# ------------------------------------------------------------- brute-force references
def brute_force_errors(tin, grid):
    """|TIN - z| at every sample, from each face's own plane, independent of any kernel.

    For every face, every sample in its bounding box is tested with barycentric
    coordinates in world space (inclusive, to 1e-12); a sample in several faces (on a
    shared edge) keeps its largest error. All faces at once: the bounding boxes' samples
    are listed face by face. Returns the (rows, cols) errors (NaN where no face covers
    the sample).
    """
    xs, ys, z = grid.xs, grid.ys, grid.z
    p = tin.vertices[tin.faces]  # (F, 3 corners, xyz)
    c0 = np.searchsorted(xs, p[:, :, 0].min(axis=1))
    c1 = np.searchsorted(xs, p[:, :, 0].max(axis=1), side="right")
    r0 = np.searchsorted(ys, p[:, :, 1].min(axis=1))
    r1 = np.searchsorted(ys, p[:, :, 1].max(axis=1), side="right")
    width, count = c1 - c0, (c1 - c0) * (r1 - r0)
    f = np.repeat(np.arange(len(p)), count)
    local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    r = r0[f] + local // width[f]
    c = c0[f] + local % width[f]
    X, Y = xs[c], ys[r]
    (x0, y0, z0), (x1, y1, z1), (x2, y2, z2) = (p[f, k].T for k in range(3))
    det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    l1 = ((X - x0) * (y2 - y0) - (x2 - x0) * (Y - y0)) / det
    l2 = ((x1 - x0) * (Y - y0) - (X - x0) * (y1 - y0)) / det
    l0 = 1.0 - l1 - l2
    inside = (l0 >= -1e-12) & (l1 >= -1e-12) & (l2 >= -1e-12)
    e = np.abs(l0 * z0 + l1 * z1 + l2 * z2 - z[r, c])
    err = np.full(grid.size, -np.inf)
    np.maximum.at(err, (r * grid.shape[1] + c)[inside], e[inside])
    err[np.isneginf(err)] = np.nan
    return err.reshape(grid.shape)


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


@pytest.mark.parametrize("name", REAL_DEM_NAMES)
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


def _whole_multiple_grid(z, ux=149.146261, uy=184.949905):
    """``z`` on coordinates that are whole multiples of ``ux`` and ``uy``: steps of 2 units and a
    last step of 3 (as the reverse Faber methods' S(T) of an even grid has), none of them
    exact in float64."""
    rows, cols = z.shape
    xs = np.r_[np.arange(cols - 1) * 2.0 * ux, (2 * cols - 1) * ux]
    ys = np.r_[np.arange(rows - 1) * 2.0 * uy, (2 * rows - 1) * uy]
    return HeightGrid.from_coords(z, xs, ys)


def test_whole_multiples_of_a_unit_are_computed_on_their_lattice(bundled, monkeypatch):
    """A rectilinear grid on whole multiples of a unit is triangulated in those whole numbers,
    where the orientation tests are exact: valid TINs within epsilon. In its world
    coordinates the same runs get stuck (rounded orientation tests disagree about samples on
    a line, so no candidate triangle is valid), which is what S(T) grids met before."""
    from simplifiers import greedy_cuts as gc

    grids = [_whole_multiple_grid(bundled[kind].z[:41, :41]) for kind in ("mountains", "ridges")]
    for g in grids:
        for eps in (0.5, 5.0):
            tin = greedy_cuts(g, eps)
            assert tin.attrs["plane_space"] == "lattice"
            vertex_cells(tin, g)
            assert_rules(tin, g)
            assert_guarantee(tin, g, eps)
            assert_conforming(tin)
    monkeypatch.setattr(gc, "_plane_coords", lambda g: (g.xs - g.xs[0], g.ys - g.ys[0], "world"))
    for g in grids:
        for eps in (0.5, 5.0):
            with pytest.raises(SimplificationError, match="got stuck"):
                greedy_cuts(g, eps)


def test_whole_units_worked_by_hand():
    from simplifiers.greedy_cuts import _whole_units

    u = 0.1  # not exact in float64
    np.testing.assert_array_equal(_whole_units(np.array([3.0, 3.0 + 2 * u, 3.0 + 4 * u, 3.0 + 7 * u])), [0, 2, 4, 7])
    np.testing.assert_array_equal(_whole_units(np.array([0.0, 1.0, 1.5, 2.5])), [0, 2, 3, 5])
    assert _whole_units(np.array([0.0, 1.0, 1.0 + np.sqrt(2.0)])) is None  # no common unit
    assert _whole_units(np.array([0.0, 1.0, 2.0**26])) is None  # multiples past 2**25


def test_budget_on_a_faber_grid_of_a_real_dem():
    """The S(T) of LLS level 1 on compare's Jacksboro window (60x60, its last steps 1.5 times the
    others): greedy cuts at level 2 got stuck there in world coordinates."""
    S = simplifiers.simplify(shared_dem_120("jacksboro_window"), "lls", 1)
    assert not S.is_uniform
    tin = _check_simplified(S, 2)
    assert tin.attrs["plane_space"] == "lattice"


def test_deterministic(bundled):
    g = bundled["mountains"]
    a = simplifiers.simplify(g, "greedy-cuts", 2)
    b = simplifiers.simplify(g, "greedy-cuts", 2)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)
    assert a.attrs["epsilon"] == b.attrs["epsilon"]


def test_vertices_override_and_epsilon_guess(bundled):
    g = bundled["hills"]
    tin = simplifiers.simplify(g, "greedy-cuts", None, n_vertices=500)
    assert abs(tin.n_vertices - 500) <= budget_tolerance(500)
    guessed = build(g, 500, epsilon_guess=tin.attrs["epsilon"])
    assert guessed.attrs["runs"] == 1  # the given ε is tried first and lands at once
    np.testing.assert_array_equal(guessed.faces, tin.faces)


def test_a_larger_grid(rng):
    """256^2 at level 2 (4,096 vertices): bucket-pool reuse, queue compaction and array growth."""
    g = synthetic_terrain("mountains", 256, seed=3)
    tin = _check_simplified(g, 2)
    assert tin.attrs["search_stage"] in ("bracket", "mixed", "probe")


# ------------------------------------------------------------- max_error: the meaning greedy insertion gives it
def test_max_error_stops_early_with_the_fixed_tolerance_tin(bundled):
    g = bundled["hills"]
    budget = vertex_budget(g.shape, 2)
    loose = 3.0  # far fewer vertices than 900 are needed for 3 m on hills
    tin = build(g, budget, max_error=loose)
    assert tin.attrs["stopped_by"] == "max_error" and tin.attrs["search_stage"] == "max_error"
    assert tin.n_vertices < budget - budget_tolerance(budget) and tin.attrs["runs"] == 1
    assert tin.attrs["epsilon"] == tin.attrs["max_error_threshold"] == loose
    assert assert_guarantee(tin, g, loose) <= loose
    fixed = greedy_cuts(g, loose)
    np.testing.assert_array_equal(tin.faces, fixed.faces)
    np.testing.assert_array_equal(tin.vertices, fixed.vertices)
    # through the registry, which accepts fewer vertices when stopped by max_error
    reg = simplifiers.simplify(g, "greedy-cuts", 2, max_error=loose)
    assert reg.attrs["stopped_by"] == "max_error" and reg.attrs["max_error"] <= loose
    assert reg.n_vertices == tin.n_vertices and reg.attrs["budget"] == budget


def test_max_error_too_tight_searches_for_the_budget(bundled):
    g = bundled["hills"]
    tight = 0.05  # needs far more than 900 vertices
    tin = build(g, 900, max_error=tight)
    assert tin.attrs["stopped_by"] == "budget" and tin.attrs["search_stage"] != "max_error"
    assert abs(tin.n_vertices - 900) <= budget_tolerance(900)
    assert tin.attrs["epsilon"] > tight and tin.attrs["max_error_threshold"] == tight
    assert_guarantee(tin, g, tin.attrs["epsilon"])
    assert greedy_cuts(g, tight).n_vertices > 900 + budget_tolerance(900)


def test_max_error_landing_in_the_window_is_a_budget_result(bundled):
    g = bundled["hills"]
    ref = build(g, 900)
    n = ref.n_vertices  # the fixed-tolerance TIN at ref's ε has n vertices
    if n > 900:  # over the budget but inside the window: it is the budget's result
        tin = build(g, 900, max_error=ref.attrs["epsilon"])
        assert tin.attrs["stopped_by"] == "budget" and tin.attrs["runs"] == 1
    else:  # at or under the budget: stopped by max_error
        tin = build(g, 900, max_error=ref.attrs["epsilon"])
        assert tin.attrs["stopped_by"] == "max_error" and tin.attrs["runs"] == 1
    np.testing.assert_array_equal(tin.faces, ref.faces)


# ------------------------------------------------------------- kernel state, early stops, mixed tolerance
def test_kernel_counters_by_name(bundled):
    g = bundled["mountains"]
    run = _Triangulator(g).run(5.0)
    c = run.counts
    assert c[K.STATUS] == K.DONE and run.complete
    assert c[K.N_VERTICES] == np.unique(run.tris).size == run.n
    assert c[K.N_COVERED] == g.size  # every sample ends in a triangle
    assert c[K.N_EARS] + c[K.N_BITES] == run.tris.shape[0]
    assert c[K.N_SPLITS] <= c[K.N_BITES] and c[K.N_EVAL_SPLIT] <= c[K.N_CANDIDATES]
    assert c[K.N_EVAL_EAR] >= run.tris.shape[0] and c[K.N_EVAL_BITE] > 0  # every step tries an ear first
    # Euler: a triangulated disk with V vertices, B of them on its boundary, has 2V - B - 2 faces
    tin = _Triangulator(g).tin(run)
    xmin, xmax, ymin, ymax = g.extent
    v = tin.vertices
    b = ((v[:, 0] == xmin) | (v[:, 0] == xmax) | (v[:, 1] == ymin) | (v[:, 1] == ymax)).sum()
    assert tin.n_faces == 2 * tin.n_vertices - b - 2


def test_a_run_stops_once_over_the_limit(bundled):
    g = bundled["rough"]
    tri = _Triangulator(g)
    full = tri.run(10.0)
    same = tri.run(10.0, max_vertices=full.n)  # never passes the limit: the same run
    assert same.complete
    np.testing.assert_array_equal(same.tris, full.tris)
    limit = full.n // 2
    part = tri.run(10.0, max_vertices=limit)
    assert not part.complete and part.counts[K.STATUS] == K.OVER_BUDGET
    assert part.counts[K.N_VERTICES] == limit + 1
    # the stopped run made exactly the first triangles of the full run
    np.testing.assert_array_equal(part.tris, full.tris[: part.tris.shape[0]])
    assert part.counts[K.N_COVERED] < g.size
    # its extrapolated count is a fair estimate of the full one
    assert limit < part.n and 0.6 * full.n < part.n < 1.4 * full.n
    assert tri.runs == 3


def test_mixed_tolerance_keeps_each_samples_own_tolerance(bundled):
    g = bundled["hills"]
    tri = _Triangulator(g)
    k = g.size // 3
    order = np.random.default_rng(1).permutation(g.size)
    run = tri.run(0.5, eps_rest=0.1, k=k, order=order, order_name="test order")
    tin = tri.tin(run)
    assert tin.attrs["epsilon"] == 0.5 and tin.attrs["epsilon_rest"] == 0.1
    assert tin.attrs["n_samples_at_epsilon"] == k and tin.attrs["mixed_order"] == "test order"
    err = brute_force_errors(tin, g).ravel()
    loose = np.zeros(g.size, dtype=bool)
    loose[order[:k]] = True
    assert err[~loose].max() <= 0.1 + 1e-12
    assert 0.1 < err[loose].max() <= 0.5 + 1e-12  # the loose samples use their larger allowance
    assert_rules(tin, g)


def test_quantised_heights_need_the_mixed_tolerance(bundled):
    """Whole-metre heights: many samples are exactly 1 off, and the count jumps over the
    window at ε = 1; the mixed tolerance lets only some of them be 1 off."""
    g = HeightGrid(np.round(bundled["hills"].z), dx=30.0)
    tin = _check_simplified(g, 2)
    a = tin.attrs
    assert a["search_stage"] == "mixed" and a["mixed_order"] == "row-major"
    assert a["epsilon_rest"] < 1.0 <= a["epsilon"] < 1.001
    assert a["max_error"] == pytest.approx(1.0, abs=1e-9)  # met with ties exactly at 1
    assert greedy_cuts(g, 1.0).n_vertices < 900 - 9 < 900 + 9 < greedy_cuts(g, a["epsilon_rest"]).n_vertices
    err = brute_force_errors(tin, g).ravel()
    assert (err[a["n_samples_at_epsilon"]:] <= a["epsilon_rest"] + 1e-12).all()  # row-major: the rest


# ------------------------------------------------------------- the search's parts
def test_line_segments_match_the_boundary_chain():
    """The O(length) 1-D chain of the first guess against the O(length^3) boundary chain."""
    rng = np.random.default_rng(11)
    for trial in range(40):
        rows, cols = rng.integers(2, 40, size=2)
        z = np.cumsum(rng.normal(size=(rows, cols)), axis=1) + rng.normal(size=(rows, cols))
        gx = np.cumsum(rng.uniform(0.2, 3.0, cols)) if trial % 2 else np.arange(cols, dtype=float)
        gy = np.cumsum(rng.uniform(0.2, 3.0, rows)) if trial % 2 else np.arange(rows, dtype=float)
        eps = float(rng.uniform(0.05, 3.0))
        r_idx = np.arange(rows, dtype=np.int64)
        c_idx = np.arange(cols, dtype=np.int64)
        along_r, along_c = K.line_segments(z, gx, gy, r_idx, c_idx, eps)
        idx = np.arange(z.size).reshape(z.shape)
        eps_map = np.full(z.size, eps)
        ref_r = sum(K.boundary_chain(idx[r].copy(), gx, gy, z.ravel(), cols, eps_map).size - 1 for r in range(rows))
        ref_c = sum(K.boundary_chain(idx[:, c].copy(), gx, gy, z.ravel(), cols, eps_map).size - 1 for c in range(cols))
        assert (along_r, along_c) == (ref_r, ref_c)


@pytest.mark.parametrize("kind", KINDS)
def test_first_guess_is_close(bundled, kind):
    from simplifiers.greedy_cuts import _first_guess, _Search

    g = bundled[kind]
    tin = build(g, 900)
    search = _Search(_Triangulator(g), 900)
    assert 0.6 < _first_guess(search) / tin.attrs["epsilon"] < 1.6


# golden searches: (terrain, level) -> vertices, ε, runs, landing stage (the invariants are checked above)
GOLDEN = [
    ("hills", 2, 897, 0.7250886861302522, 3, "bracket"),
    ("rough", 2, 900, 26.526873075754295, 13, "probe"),
    ("ridges", 3, 226, 52.90765292081152, 12, "mixed"),
    ("mesas", 1, 3603, 1.0435705702007743, 2, "bracket"),
]


@pytest.mark.parametrize("kind, level, n, eps, runs, stage", GOLDEN)
def test_golden_searches(bundled, kind, level, n, eps, runs, stage):
    tin = build(bundled[kind], vertex_budget((120, 120), level))
    a = tin.attrs
    assert (tin.n_vertices, a["runs"], a["search_stage"]) == (n, runs, stage)
    assert a["epsilon"] == pytest.approx(eps, rel=1e-12)


@pytest.mark.parametrize("kind, step, level", [("mountains", 2, 2), ("mesas", 2, 2), ("rough", 4, 1)])
def test_a_chaotic_count_lands_with_the_wide_mixed_tolerance(bundled, kind, step, level, monkeypatch):
    """Where the runs near the jump land on two modes either side of the window (these
    subsampled bundled terrains), the first three stages miss it and the wide mixed
    tolerance lands: a valid TIN within its epsilon and the budget's tolerance. Without
    stage 4 the same search raises."""
    from simplifiers import greedy_cuts as gc

    g = bundled[kind].subsample(step)
    tin = _check_simplified(g, level)
    assert tin.attrs["search_stage"] == "wide"
    assert tin.attrs["epsilon_rest"] < tin.attrs["epsilon"]
    monkeypatch.setattr(gc, "_stage_wide", lambda search: None)
    with pytest.raises(SimplificationError, match="no epsilon gave") as without:
        simplifiers.simplify(g, "greedy-cuts", level)
    # where stage 4 misses too (its mixed runs made to miss), the error names the same jump
    monkeypatch.undo()
    monkeypatch.setattr(gc, "_stage_mixed", lambda search: None)
    with pytest.raises(SimplificationError, match="no epsilon gave") as missed:
        simplifiers.simplify(g, "greedy-cuts", level)
    jump = str(without.value).split("; ")[1]
    assert jump.startswith("the count jumps from") and str(missed.value).endswith(jump)


# ------------------------------------------------------------- bad input
@pytest.mark.parametrize("budget", [3, 120 * 120 + 1, -5])
def test_bad_budget(bundled, budget):
    with pytest.raises(ValueError, match="n_vertices must be in"):
        simplifiers.simplify(bundled["hills"], "greedy-cuts", None, n_vertices=budget)


def test_bad_arguments(bundled):
    g = bundled["hills"]
    with pytest.raises(ValueError, match="max_error"):
        greedy_cuts(g, -1.0)
    with pytest.raises(ValueError, match="max_error"):
        greedy_cuts(g, float("nan"))
    with pytest.raises(TypeError, match="max_error"):
        greedy_cuts(g, "big")
    with pytest.raises(TypeError, match="grid"):
        greedy_cuts(g.z, 1.0)
    z = g.z.copy()
    z[3, 4] = np.nan
    with pytest.raises(NodataError):
        greedy_cuts(HeightGrid(z), 1.0)
    with pytest.raises(NodataError):
        build(HeightGrid(z), 100)
    with pytest.raises(TypeError, match="unexpected option.*epsilon"):
        simplifiers.simplify(g, "greedy-cuts", 1, epsilon=1.0)
    with pytest.raises(TypeError, match="max_error"):
        simplifiers.simplify(g, "greedy-cuts", 1, max_error="x")
    with pytest.raises(ValueError, match="max_error"):
        build(g, 100, max_error=-2.0)
    with pytest.raises(ValueError, match="epsilon_guess"):
        build(g, 100, epsilon_guess=float("inf"))
    with pytest.raises(ValueError, match=r"n_vertices must be in \[4, 14400\] for a 120x120 grid, got 3"):
        build(g, 3)
    with pytest.raises(TypeError, match="n_vertices"):
        build(g, 100.5)


def test_unreachable_budget_on_a_flat_grid():
    g = HeightGrid(np.full((10, 10), 3.0))
    with pytest.raises(SimplificationError, match="greedy-cuts: the grid is flat"):
        simplifiers.simplify(g, "greedy-cuts", None, n_vertices=50)
    assert simplifiers.simplify(g, "greedy-cuts", None, n_vertices=4).n_vertices == 4


def test_planar_parts_make_a_large_budget_unreachable():
    z = np.zeros((20, 20))
    z[5, 5] = 1.0  # one bump on a plane: at most a handful of vertices at any ε
    with pytest.raises(SimplificationError, match="even epsilon = 0 gives only"):
        build(HeightGrid(z), 200)
