"""simplify(grid, method, max_error=E): the smallest result within a target error, for every method."""

from __future__ import annotations

import numpy as np
import pytest

import simplifiers
from simplifiers import max_level, simplify, vertex_budget
from simplifiers.greedy_insertion import build as gi_build
from terrainvis import HeightGrid, bundled_terrain, vertical_errors

from conftest import shared_dem_120

# visopt computes every level from the grid with 1200 training points (about a minute a level at
# 120x120): its max_error search is tested on a small case in tests/methods/test_visopt.py
# the built-in methods; the practitioners' simplifiers' error targets are tested in tests/methods/test_peer_methods.py
METHODS = [m for m in simplifiers.METHODS if m in simplifiers.registry.BUILTIN and m != "visopt"]
REGULAR = [m for m in METHODS if simplifiers.METHODS[m].regular]


@pytest.fixture(scope="module")
def terrains():
    return {"hills": bundled_terrain("hills"), "mountains": bundled_terrain("mountains")}


def _check(g, out, target):
    """The result is within the target by its attrs and by an independent measurement.

    Greedy cuts decides in its plane space (grid indices) and the measurement is in world
    coordinates (UTM northings on the shared DEMs): on whole-metre heights with ties at
    exactly E the two differ by rounding, 1e-12 of the heights at most (as in
    test_greedy_cuts.assert_guarantee).
    """
    err = vertical_errors(g, out)[0]
    assert err <= target + 1e-12 * max(1.0, float(np.abs(g.z).max()))
    a = out.attrs
    assert a["max_error"] == pytest.approx(err, abs=1e-12)
    assert a["max_error_target"] == target and a["stopped_by"] == "max_error"
    assert len(a["notes"]) == 1 and f"max_error {target:g}" in a["notes"][0]
    return err


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name, target", [("hills", 4.0), ("mountains", 25.0)])
def test_every_method_meets_the_target(terrains, method, name, target):
    g = terrains[name]
    out = simplify(g, method, max_error=target)
    _check(g, out, target)
    if simplifiers.METHODS[method].regular:
        assert isinstance(out.attrs["level"], int)
    else:
        assert out.attrs["level"] is None and out.attrs["budget"] == g.size  # no size limit was given
        assert out.n_vertices < g.size


@pytest.mark.parametrize("method", ["greedy-insertion", "greedy-cuts", "qec", "lls", "feature"])
def test_a_shared_dem_crop(method):
    g = shared_dem_120("mount_st_helens_wa")
    _check(g, simplify(g, method, max_error=10.0), 10.0)


@pytest.mark.parametrize("method", REGULAR)
def test_regular_methods_return_the_coarsest_level_within(terrains, method):
    g = terrains["mountains"]
    target = 30.0
    out = simplify(g, method, max_error=target)
    _check(g, out, target)
    # independently: every level simplified on its own
    errors = {k: simplify(g, method, k).attrs["max_error"] for k in range(max_level(g.shape) + 1)}
    within = [k for k, e in errors.items() if e <= target]
    assert out.attrs["level"] == max(within)
    assert out.shape == simplify(g, method, max(within)).shape
    assert [lv for lv, _ in out.attrs["level_errors"]] == list(range(max_level(g.shape) + 1))
    for lv, e in out.attrs["level_errors"]:
        assert e == pytest.approx(errors[lv], abs=1e-12)
    assert f"level {out.attrs['level']} is the coarsest" in out.attrs["notes"][0]


def test_regular_level_is_a_size_limit(terrains):
    g = terrains["hills"]
    loose = simplify(g, "lls", 2, max_error=1e6)  # everything is within: the deepest level
    assert loose.attrs["level"] == max_level(g.shape) and loose.attrs["stopped_by"] == "max_error"
    tight = simplify(g, "lls", 2, max_error=0.1)  # even level 2 is not: level 2, said so
    assert tight.attrs["level"] == 2 and tight.attrs["stopped_by"] == "budget"
    assert tight.attrs["max_error"] > 0.1 and "not met" in tight.attrs["notes"][0]
    assert simplify(g, "gls", max_error=0.0).attrs["level"] == 0  # only the grid itself has no error


def test_greedy_insertion_is_minimal_and_matches_pydelatin(terrains):
    pydelatin = pytest.importorskip("pydelatin")
    for name, target in (("hills", 2.0), ("mountains", 10.0)):
        g = HeightGrid(terrains[name].z)  # unit spacing, as pydelatin
        out = simplify(g, "greedy-insertion", max_error=target)
        _check(g, out, target)
        n = out.n_vertices
        # one vertex fewer exceeds the target: the first count of the insertion order within it
        assert vertical_errors(g, gi_build(g, n - 1))[0] > target
        # pydelatin's max_error mode (the same algorithm, float32 heights) stops at about the same count
        ref = pydelatin.Delatin(np.ascontiguousarray(g.z), max_error=target)
        assert abs(ref.vertices.shape[0] - n) <= 0.02 * n, (name, ref.vertices.shape[0], n)


def test_greedy_cuts_uses_the_target_as_epsilon(terrains):
    from simplifiers.greedy_cuts import greedy_cuts

    g = terrains["mountains"]
    out = simplify(g, "greedy-cuts", max_error=12.0)
    _check(g, out, 12.0)
    ref = greedy_cuts(g, 12.0)
    np.testing.assert_array_equal(out.vertices, ref.vertices)
    assert out.attrs["epsilon"] == 12.0


def test_qec_searches_the_count(terrains):
    g = terrains["mountains"]
    out = simplify(g, "qec", max_error=20.0)
    _check(g, out, 20.0)
    probes = out.attrs["probes"]
    assert [out.n_vertices, out.attrs["max_error"]] in probes
    within = [n for n, e in probes if e <= 20.0]
    over = [n for n, e in probes if e > 20.0]
    assert out.n_vertices == min(within)
    # the largest count found over the target is within 1 % (and a vertex) of the one returned
    assert max(n for n in over if n < out.n_vertices) >= 0.98 * out.n_vertices - 1


def test_irregular_level_caps_the_size(terrains):
    g = terrains["mountains"]
    budget = vertex_budget(g.shape, 3)
    for method in ("greedy-insertion", "greedy-cuts", "qec"):
        out = simplify(g, method, 3, max_error=0.5)  # 225 vertices cannot hold 0.5 m
        assert out.attrs["stopped_by"] == "budget" and out.attrs["level"] == 3
        assert abs(out.n_vertices - budget) <= 2 and out.attrs["max_error"] > 0.5
        assert "not met" in out.attrs["notes"][0]
        early = simplify(g, method, 1, max_error=40.0)  # far fewer than level 1's 3,600 are needed
        _check(g, early, 40.0)
        assert early.n_vertices < vertex_budget(g.shape, 1) and early.attrs["level"] == 1


def test_bad_targets(terrains):
    g = terrains["hills"]
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="max_error"):
            simplify(g, "lls", max_error=bad)
    with pytest.raises(TypeError, match="max_error"):
        simplify(g, "greedy-insertion", max_error="5 m")
