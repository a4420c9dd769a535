"""Tests for simplifiers.quadric: quadric edge collapse (pymeshlab and fast-simplification).

Every TIN is checked against the height-field rules directly (independently of
``check_height_field``), its surface against matplotlib's triangulation interpolator, its
vertex count against the budget, and its error against the regular grid of equal size.
"""

from __future__ import annotations

import functools

import matplotlib.tri as mtri
import numpy as np
import pytest
from conftest import DEM_NAMES, shared_dem_120
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import simplifiers
from simplifiers import quadric
from terrainvis import HeightGrid, TIN
from terrainvis.errors import NodataError, SimplificationError
from terrainvis.synthetic import KINDS, bundled_terrain

BACKENDS = quadric.BACKENDS
LEVELS = (1, 2, 3)


# --------------------------------------------------------------------------- helpers
@functools.lru_cache(maxsize=None)
def _terrain(name: str) -> HeightGrid:
    if name in KINDS:
        return bundled_terrain(name)
    if name == "rectilinear":
        # non-uniform, non-square cells at UTM-sized coordinates
        z = bundled_terrain("ridges").z[:90, :110]
        rng = np.random.default_rng(7)
        xs = 512_345.25 + np.concatenate([[0.0], np.cumsum(rng.uniform(12.0, 48.0, 109))])
        ys = 4_987_654.5 + np.concatenate([[0.0], np.cumsum(rng.uniform(25.0, 35.0, 89))])
        return HeightGrid.from_coords(z, xs, ys)
    return shared_dem_120(name)


@functools.lru_cache(maxsize=None)
def _qec(name: str, level: int, backend: str) -> TIN:
    return simplifiers.simplify(_terrain(name), "qec", level, backend=backend)


def _budget(grid: HeightGrid, level: int) -> int:
    rows, cols = grid.shape
    for _ in range(level):
        rows, cols = (rows + 1) // 2, (cols + 1) // 2
    return rows * cols


def assert_height_field(tin: TIN, grid: HeightGrid, budget: int) -> None:
    """The rules of a valid irregular result, checked from scratch."""
    v, f = tin.vertices, tin.faces.astype(np.int64)
    xmin, xmax, ymin, ymax = float(grid.xs[0]), float(grid.xs[-1]), float(grid.ys[0]), float(grid.ys[-1])
    assert abs(tin.n_vertices - budget) <= max(1, int(0.01 * budget))
    assert np.array_equal(np.unique(f), np.arange(v.shape[0])), "every vertex is used by a face"
    for cx, cy in ((xmin, ymin), (xmax, ymin), (xmax, ymax), (xmin, ymax)):
        assert ((v[:, 0] == cx) & (v[:, 1] == cy)).sum() == 1, f"corner ({cx}, {cy})"
    assert (v[:, 0] >= xmin).all() and (v[:, 0] <= xmax).all()
    assert (v[:, 1] >= ymin).all() and (v[:, 1] <= ymax).all()
    # counter-clockwise faces, no fold-overs
    a, b, c = v[f[:, 0], :2], v[f[:, 1], :2], v[f[:, 2], :2]
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert (cross > 0).all(), f"{int((cross <= 0).sum())} faces fold over"
    assert tin.is_height_field()
    area = (xmax - xmin) * (ymax - ymin)
    assert abs(0.5 * cross.sum() - area) <= 1e-9 * area
    # manifold: each directed half-edge once, each edge in at most two faces
    he = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert np.unique(he, axis=0).shape[0] == he.shape[0]
    edges, counts = np.unique(np.sort(he, axis=1), axis=0, return_counts=True)
    assert counts.max() <= 2
    bv = np.unique(edges[counts == 1])
    on_line = (v[bv, 0] == xmin) | (v[bv, 0] == xmax) | (v[bv, 1] == ymin) | (v[bv, 1] == ymax)
    assert on_line.all(), f"{int((~on_line).sum())} boundary vertices off the boundary lines"
    # a disk: V - E + F = 1
    assert v.shape[0] - edges.shape[0] + f.shape[0] == 1
    # every sample is covered, and the project's rasteriser agrees with matplotlib's
    tri = mtri.Triangulation(v[:, 0] - xmin, v[:, 1] - ymin, f)
    X, Y = np.meshgrid(grid.xs - xmin, grid.ys - ymin)
    ref = mtri.LinearTriInterpolator(tri, v[:, 2])(X, Y)
    assert np.ma.count_masked(ref) == 0, "grid samples outside the footprint"
    ours = tin.height_on_grid(grid.xs, grid.ys)
    scale = max(1.0, float(np.abs(v[:, 2]).max()))
    np.testing.assert_allclose(ours, np.ma.getdata(ref), rtol=0, atol=1e-7 * scale)


# --------------------------------------------------------------------------- rules and budget
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("name", KINDS)
def test_bundled_terrains(name, level, backend):
    grid = _terrain(name)
    tin = _qec(name, level, backend)
    assert_height_field(tin, grid, _budget(grid, level))
    assert tin.attrs["backend"] == backend and tin.attrs["method"] == "qec"
    assert tin.attrs["n_vertices"] == tin.n_vertices


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("name", DEM_NAMES)
def test_real_dems(name, level, backend):
    grid = _terrain(name)
    tin = _qec(name, level, backend)
    assert_height_field(tin, grid, _budget(grid, level))


@pytest.mark.parametrize("backend", BACKENDS)
def test_rectilinear_grid_at_utm_coordinates(backend):
    grid = _terrain("rectilinear")
    assert not grid.is_uniform
    for level in (1, 3):
        tin = _qec("rectilinear", level, backend)
        assert_height_field(tin, grid, _budget(grid, level))
        assert tin.extent == grid.extent


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("shape,budget", [((3, 3), 4), ((5, 5), 4), ((5, 5), 6), ((9, 9), 4), ((9, 7), 20)])
def test_small_grids_down_to_the_four_corners(shape, budget, backend):
    rng = np.random.default_rng(sum(shape) + budget)
    grid = HeightGrid(rng.normal(size=shape) * 10.0, dx=30.0, dy=20.0, origin=(100.0, -50.0))
    tin = simplifiers.simplify(grid, "qec", None, vertices=budget, backend=backend)
    assert_height_field(tin, grid, budget)


def test_explicit_vertex_budget():
    grid = _terrain("hills")
    tin = simplifiers.simplify(grid, "qec", None, vertices=500)
    assert_height_field(tin, grid, 500)
    assert tin.attrs["budget"] == 500


# --------------------------------------------------------------------------- error sanity
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", KINDS)
def test_error_decreases_as_the_budget_grows(name, backend):
    errs = [_qec(name, level, backend).attrs for level in (3, 2, 1)]  # 225, 900, 3600 vertices
    max_err = [m["max_error"] for m in errs]
    rms_err = [m["rms_error"] for m in errs]
    assert max_err[0] > max_err[1] > max_err[2] > 0
    assert rms_err[0] > rms_err[1] > rms_err[2] > 0


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("name", KINDS)
def test_beats_the_regular_grid_of_equal_size(name, level, backend):
    """An adaptive TIN has a lower RMS error than the subsampled grid with as many vertices."""
    grid = _terrain(name)
    regular = simplifiers.simplify(grid, "simple", level)
    tin = _qec(name, level, backend)
    assert tin.attrs["rms_error"] < regular.attrs["rms_error"]


def test_errors_recorded_match_an_independent_evaluation():
    grid = _terrain("mountains")
    tin = _qec("mountains", 2, "pymeshlab")
    v = tin.vertices
    tri = mtri.Triangulation(v[:, 0], v[:, 1], tin.faces)
    X, Y = np.meshgrid(grid.xs, grid.ys)
    diff = np.ma.getdata(mtri.LinearTriInterpolator(tri, v[:, 2])(X, Y)) - grid.z
    assert tin.attrs["max_error"] == pytest.approx(np.abs(diff).max(), rel=1e-9, abs=1e-9)
    assert tin.attrs["rms_error"] == pytest.approx(np.sqrt(np.mean(diff**2)), rel=1e-9, abs=1e-9)


# --------------------------------------------------------------------------- determinism, meta
@pytest.mark.parametrize("backend", BACKENDS)
def test_deterministic(backend):
    grid = _terrain("rough")
    a = quadric.build(grid, 900, backend=backend)
    b = quadric.build(grid, 900, backend=backend)
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.faces, b.faces)
    c = _qec("rough", 2, backend)
    assert np.array_equal(a.vertices, c.vertices) and np.array_equal(a.faces, c.faces)


@pytest.mark.parametrize("backend", BACKENDS)
def test_meta_counts_the_post_processing(backend):
    tin = _qec("ridges", 3, backend)
    for key in ("stages", "snapped", "max_snap", "corners_inserted", "repairs", "collapses", "settings"):
        assert key in tin.attrs
    assert tin.attrs["stages"] >= 1
    assert tin.attrs["corners_inserted"] in range(5)


def test_input_is_not_modified():
    z = np.random.default_rng(3).normal(size=(20, 24)) * 50
    grid = HeightGrid(z, dx=30.0, dy=30.0)
    before = grid.z.copy()
    quadric.build(grid, 60)
    assert np.array_equal(grid.z, before)


# --------------------------------------------------------------------------- bad input
def test_bad_budget_through_simplify():
    grid = _terrain("hills")
    with pytest.raises(ValueError, match="vertex budget"):
        simplifiers.simplify(grid, "qec", None, vertices=3)
    with pytest.raises(ValueError, match="vertex budget"):
        simplifiers.simplify(grid, "qec", None, vertices=grid.size + 1)
    with pytest.raises(ValueError, match="level"):
        simplifiers.simplify(grid, "qec", 9)


def test_bad_arguments_to_build():
    grid = _terrain("hills")
    with pytest.raises(ValueError, match="n_vertices"):
        quadric.build(grid, 3)
    with pytest.raises(ValueError, match="n_vertices"):
        quadric.build(grid, grid.size + 1)
    with pytest.raises(TypeError, match="n_vertices"):
        quadric.build(grid, 100.0)
    with pytest.raises(TypeError, match="grid"):
        quadric.build(grid.z, 100)
    with pytest.raises(ValueError, match="backend"):
        quadric.build(grid, 100, backend="vtk")
    with pytest.raises(ValueError, match="backend"):
        simplifiers.simplify(grid, "qec", 2, backend="vtk")
    with pytest.raises(TypeError, match="unknown option 'agg'"):
        quadric.build(grid, 100, agg=5.0)  # a fast-simplification option given to pymeshlab
    with pytest.raises(TypeError, match="unknown option 'boundaryweight'"):
        quadric.build(grid, 100, backend="fast-simplification", boundaryweight=5.0)
    with pytest.raises(ValueError, match="boundaryweight"):
        quadric.build(grid, 100, boundaryweight=-1.0)
    with pytest.raises(TypeError, match="preservenormal"):
        quadric.build(grid, 100, preservenormal="yes")
    with pytest.raises(ValueError, match="corner_tol"):
        quadric.build(grid, 100, corner_tol=0.7)
    z = grid.z.copy()
    z[5, 5] = np.nan
    with pytest.raises(NodataError):
        quadric.build(HeightGrid.from_coords(z, grid.xs, grid.ys), 100)


def test_full_budget_returns_the_grid_surface():
    grid = HeightGrid(np.arange(12.0).reshape(3, 4) ** 2, dx=2.0, dy=3.0)
    tin = quadric.build(grid, grid.size)
    assert np.array_equal(tin.vertices, grid.to_tin().vertices)
    assert np.array_equal(tin.faces, grid.to_tin().faces)


def test_failing_library_is_a_simplification_error(monkeypatch):
    import fast_simplification
    import pymeshlab

    grid = _terrain("hills")

    def boom(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(fast_simplification, "simplify", boom)
    with pytest.raises(SimplificationError, match=r"fast-simplification.*RuntimeError: boom"):
        quadric.build(grid, 900, backend="fast-simplification")

    class BrokenMeshSet:
        def add_mesh(self, mesh):
            pass

        def meshing_decimation_quadric_edge_collapse(self, **kwargs):
            raise pymeshlab.PyMeshLabException("filter exploded")

    monkeypatch.setattr(pymeshlab, "MeshSet", BrokenMeshSet)
    with pytest.raises(SimplificationError, match=r"pymeshlab.*filter exploded"):
        simplifiers.simplify(grid, "qec", 2)


# --------------------------------------------------------------------------- post-processing
def _grid_5x5():
    yy, xx = np.mgrid[0:5, 0:5]
    return HeightGrid(np.sin(xx * 0.9) * 20 + yy * 3.0, dx=10.0, dy=10.0)


def test_snapping_by_hand():
    """A decimated fan with a drifted border and a missing corner, worked by hand."""
    grid = HeightGrid(np.arange(9.0).reshape(3, 3), dx=1.0, dy=1.0)  # extent [0, 2] x [0, 2]
    post = quadric._PostProcessor(grid, np.zeros(3), corner_tol=0.25)
    v = np.array(
        [
            [0.3, 0.02, 1.0],  # A: near the bottom line, 0.30 from corner (0, 0)
            [2.0, 0.0, 2.0],  # B: corner (2, 0)
            [2.01, 2.0, 8.0],  # C: 0.01 from corner (2, 2)
            [0.0, 2.0, 6.0],  # D: corner (0, 2)
            [-0.02, 0.35, 3.0],  # E: near the left line, 0.35 from corner (0, 0)
            [1.0, 1.0, 4.0],  # M: interior
        ]
    )
    f = np.array([[0, 1, 5], [1, 2, 5], [2, 3, 5], [3, 4, 5], [4, 0, 5]])
    out_v, out_f, side, stats = post.run(v, f, "test")
    expected = np.array(
        [[0.3, 0.0, 1.0], [2.0, 0.0, 2.0], [2.0, 2.0, 8.0], [0.0, 2.0, 6.0], [0.0, 0.35, 3.0], [1.0, 1.0, 4.0],
         [0.0, 0.0, 0.0]]  # the inserted corner takes the grid's height z[0, 0]
    )
    assert np.array_equal(out_v, expected)
    assert out_f.tolist() == f.tolist() + [[4, 6, 0]]
    assert side.tolist() == [0, 4 + 1, 4 + 2, 4 + 3, 3, -1, 4 + 0]
    assert stats["corners_inserted"] == 1 and stats["repairs"] == 0 and stats["collapses"] == 0
    assert stats["snapped"] == 3  # A, C (onto its corner) and E moved; B and D were exact
    assert stats["max_snap"] == pytest.approx(0.02)
    tin = TIN(out_v, out_f)
    assert_height_field(tin, grid, 7)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    r=st.integers(1, 3), c=st.integers(1, 3),
    du=st.floats(-1.9, 1.9), dv=st.floats(-1.9, 1.9),
)
@example(r=2, c=2, du=1.5, dv=1.5)  # across the diagonal neighbour: several faces fold
@example(r=1, c=3, du=0.0, dv=-1.2)  # past the bottom neighbour
@example(r=1, c=2, du=-1.0, dv=0.0)  # exactly onto a neighbour: two zero-area faces
def test_fold_over_repair_moves_only_vertices_of_folded_faces(r, c, du, dv):
    """Push one interior vertex of a grid TIN up to 1.9 cells away. The repair must give a
    valid height field with the same faces, moving only vertices of the folded faces (each
    once, into the kernel of its star) and leaving every other vertex untouched."""
    grid = _grid_5x5()
    base = grid.to_tin()
    v = base.vertices.copy()
    vid = r * 5 + c
    v[vid, 0] += du * 10.0
    v[vid, 1] += dv * 10.0
    f = base.faces.astype(np.int64)
    post = quadric._PostProcessor(grid, np.zeros(3), corner_tol=0.25)
    bad = quadric._signed_area2(v, f) <= post.area_eps
    out_v, out_f, side, stats = post.run(v, f, "test")
    assert np.array_equal(out_f, f)
    assert stats["collapses"] == 0 and stats["snapped"] == 0
    moved = np.flatnonzero((out_v[:, :2] != v[:, :2]).any(axis=1))
    assert set(moved.tolist()) <= set(np.unique(f[bad]).tolist())
    assert stats["repairs"] == moved.size
    assert (moved.size >= 1) == bool(bad.any())
    # a moved vertex takes the grid's height at its new position
    np.testing.assert_allclose(out_v[moved, 2], grid.height_at(out_v[moved, :2]), atol=1e-9)
    assert_height_field(TIN(out_v, out_f), grid, 25)


@settings(max_examples=40, deadline=None)
@given(k=st.integers(1, 3), along=st.floats(-0.45, 0.45), inward=st.floats(-0.2, 0.2), which=st.integers(0, 3))
@example(k=2, along=0.45, inward=0.2, which=0)
def test_boundary_vertices_snap_back_onto_their_line(k, along, inward, which):
    """A border vertex displaced along and across its side returns exactly onto the line,
    keeping its position along it (the corners stay where they are)."""
    grid = _grid_5x5()
    base = grid.to_tin()
    v = base.vertices.copy()
    # vertex k along side `which`, its direction along the side and inward normal
    r, c = [(0, k), (k, 4), (4, 4 - k), (4 - k, 0)][which]
    e = np.array([[1, 0], [0, 1], [-1, 0], [0, -1]][which], dtype=float)
    n = np.array([-e[1], e[0]])
    vid = r * 5 + c
    v[vid, :2] += 10.0 * (along * e + inward * n)
    post = quadric._PostProcessor(grid, np.zeros(3), corner_tol=0.25)
    out_v, out_f, side, stats = post.run(v, base.faces.astype(np.int64), "test")
    expected = base.vertices[vid, :2] + 10.0 * along * e
    assert out_v[vid, 0] == pytest.approx(expected[0], abs=1e-9)
    assert out_v[vid, 1] == pytest.approx(expected[1], abs=1e-9)
    assert side[vid] == which
    assert stats["corners_inserted"] == 0 and stats["collapses"] == 0 and stats["repairs"] == 0
    assert_height_field(TIN(out_v, out_f), grid, 25)
