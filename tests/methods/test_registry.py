"""The simplifier registry: names, budgets, levels, and the height-field rules for TINs."""

from __future__ import annotations

import numpy as np
import pytest

import simplifiers
from simplifiers import available, check_height_field, max_level, simplify, vertex_budget
from terrainvis import TIN, HeightGrid, synthetic_terrain
from terrainvis.errors import NodataError, SimplificationError


def test_available_lists_the_papers_seven_in_its_order_then_visopt_then_the_plugins():
    listed = [(name, simplifiers.METHODS[name].kind) for name in available()]
    assert listed[:8] == [
        ("qec", "irregular"), ("greedy-cuts", "irregular"), ("greedy-insertion", "irregular"),
        ("simple", "regular"), ("gls", "regular"), ("lls", "regular"), ("feature", "regular"),
        ("visopt", "regular"),
    ]
    assert set(simplifiers.METHODS[m].name for m, _ in listed[:8]) == simplifiers.registry.BUILTIN
    # then terrainvis's own plugins, the practitioners' simplifiers (entry points: no order promised)
    assert set(listed[8:]) == {("delatin", "irregular"), ("fqmr", "irregular"), ("fqmr-free", "irregular"),
                               ("meshopt", "irregular"), ("rtin", "semi-regular"), ("vtk-greedy", "irregular")}
    assert list(simplifiers.METHODS) == list(available())


def test_budgets_and_levels():
    assert [vertex_budget((120, 120), k) for k in range(4)] == [14400, 3600, 900, 225]
    assert vertex_budget((121, 121), 3) == 16 * 16
    assert max_level((120, 120)) == 6  # 120 60 30 15 8 4 2
    assert max_level((2, 50)) == 0 and max_level((3, 3)) == 1


def test_unknown_method_lists_available():
    g = synthetic_terrain("hills", size=9)
    with pytest.raises(ValueError, match=r"method must be one of \['qec', 'greedy-cuts', 'greedy-insertion', "
                                         r"'simple', 'gls', 'lls', 'feature', 'visopt', .*'rtin'.*\] \(see simplifiers.available\(\)\)"):
        simplify(g, "decimate")


def test_level_errors_state_the_maximum():
    g = synthetic_terrain("hills", size=9)
    with pytest.raises(ValueError, match=r"level must be in \[0, 3\] for a 9x9 grid.*got 4"):
        simplify(g, "lls", 4)
    with pytest.raises(ValueError, match=r"level must be in \[0, 3\] for a 9x9 grid"):
        simplify(g, "greedy-insertion", 4)


@pytest.mark.parametrize("method", ["qec", "greedy-insertion", "greedy-cuts"])
def test_irregular_budget_errors_and_2x2(method):
    g = synthetic_terrain("rough", size=9)
    with pytest.raises(ValueError, match=r"n_vertices must be in \[4, 81\] for a 9x9 grid, got 3"):
        simplify(g, method, n_vertices=3)
    with pytest.raises(ValueError, match=r"n_vertices must be in \[4, 81\] for a 9x9 grid, got 82"):
        simplify(g, method, n_vertices=82)
    two = HeightGrid([[0.0, 1.0], [2.0, 5.0]], dx=3.0)
    tin = simplify(two, method, level=0)
    np.testing.assert_array_equal(tin.faces, two.to_tin().faces)
    assert tin.attrs["max_error"] == 0.0 and tin.attrs["method"] == method


@pytest.mark.parametrize("method", list(available()))
def test_nan_gives_the_nodata_error(method):
    z = synthetic_terrain("hills", size=9).z.copy()
    z[3, 3] = np.nan
    with pytest.raises(NodataError, match="1 NaN cell"):
        simplify(HeightGrid(z), method, 1)


def test_greedy_insertion_max_error_stops_early():
    g = synthetic_terrain("hills", size=60)
    tin = simplify(g, "greedy-insertion", 1, max_error=2.0)
    assert tin.attrs["stopped_by"] == "max_error" and tin.n_vertices < tin.attrs["budget"]
    assert tin.attrs["max_error"] <= 2.0


def test_metadata_recorded():
    g = synthetic_terrain("mountains", size=33)
    for method in ("lls", "greedy-insertion"):
        out = simplify(g, method, 2)
        meta = out.attrs
        for key in ("method", "kind", "level", "n_vertices", "nbytes", "max_error", "rms_error", "seconds"):
            assert key in meta
        assert meta["n_vertices"] == 81 and meta["nbytes"] == out.nbytes
        # independent reference: the surface located point by point at every sample
        diff = out.height_at(g.sample_xy()) - g.z.ravel()
        assert meta["max_error"] == pytest.approx(np.abs(diff).max(), rel=1e-12, abs=1e-9)
        assert meta["rms_error"] == pytest.approx(np.sqrt(np.mean(diff**2)), rel=1e-12, abs=1e-9)


# ----------------------------------------------------- the height-field rules
GRID = HeightGrid(np.zeros((3, 3)), dx=1.0, dy=1.0)  # extent [0, 2] x [0, 2]


def _square(vertices, faces):
    return TIN(np.asarray(vertices, float), np.asarray(faces))


def test_valid_tin_passes():
    tin = _square([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [1, 1, 0]],
                  [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    check_height_field(tin, GRID, method="m", budget=5)


@pytest.mark.parametrize(
    "vertices, faces, budget, match",
    [
        # a corner missing: the footprint is a triangle
        ([[0, 0, 0], [2, 0, 0], [0, 2, 0], [1, 1, 0]], [[0, 1, 3], [0, 3, 2]], None, r"corner \(2, 2\) is missing"),
        # a fold-over: one face is clockwise
        ([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [1, 1, 0]], [[0, 1, 4], [1, 2, 4], [2, 3, 4], [0, 3, 4]],
         None, "fold over"),
        # a boundary vertex off the boundary lines (the border shrank inwards)
        ([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [1, 0.2, 0]], [[0, 4, 3], [4, 1, 2], [4, 2, 3]],
         None, "boundary edges lie off the boundary lines"),
        # right shape, wrong vertex count for the budget
        ([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], [[0, 1, 2], [0, 2, 3]], 6, "4 vertices for a budget of 6"),
        # a vertex outside the extent
        ([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [3, 1, 0]], [[0, 1, 2], [0, 2, 3], [1, 4, 2]],
         None, "outside the extent"),
    ],
)
def test_each_rule_is_enforced(vertices, faces, budget, match):
    with pytest.raises(SimplificationError, match=match):
        check_height_field(_square(vertices, faces), GRID, method="m", budget=budget)
