"""lowest_point / clearance_profile: where a segment comes closest to the surface."""

from __future__ import annotations

import numpy as np
import pytest

from terrainvis import HeightGrid, bundled_terrain, min_clearance, sample_points
from terrainvis.visibility.profile import clearance_profile, lowest_point


@pytest.mark.parametrize("radius_cells", [0.0, 1.0, 2.5])
def test_lowest_point_equals_the_exact_minimum_clearance(radius_cells):
    from simplifiers import simplify

    T = bundled_terrain("ridges")
    P = sample_points(T, 160, seed=4, offset=2.0)
    a, b = P[:80], P[80:]
    r = radius_cells * 30.0
    for surface in (T, simplify(T, "lls", 2), simplify(T, "greedy-insertion", 2)):
        exact = min_clearance(surface, a, b, end_radius=r)
        low = np.array([lowest_point(surface, a[i], b[i], end_radius=r)["clearance"] for i in range(80)])
        scale = np.abs(P[:, 2]).max()
        np.testing.assert_allclose(low, exact, rtol=0, atol=1e-9 * scale)


def test_the_lowest_point_is_where_the_clearance_is_lowest():
    T = bundled_terrain("mountains")
    a, b = np.array([100.0, 200.0, 1500.0]), np.array([3400.0, 3000.0, 1600.0])
    low = lowest_point(T, a, b)
    t, c = clearance_profile(T, a, b)
    assert (np.diff(t) > 0).all() and low["clearance"] == c.min()
    # the reported position is on the segment, and the surface there gives the clearance
    np.testing.assert_allclose([low["x"], low["y"], low["z"]], a + low["t"] * (b - a))
    assert low["z"] - T.height_at([[low["x"], low["y"]]])[0] == pytest.approx(low["clearance"], abs=1e-9)
    assert low["distance"] == pytest.approx(low["t"] * np.hypot(*(b - a)[:2]))


def test_hand_case_and_trimmed_segments():
    g = HeightGrid([[0.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 0.0]])
    low = lowest_point(g, [0.0, 1.0, 1.0], [2.0, 1.0, 1.0])
    assert (low["clearance"], low["x"], low["y"]) == (-9.0, 1.0, 1.0)
    # a segment shorter than twice the end radius is not tested at all
    assert lowest_point(g, [0.0, 1.0, 1.0], [2.0, 1.0, 1.0], end_radius=1.5)["clearance"] == np.inf
    t, c = clearance_profile(g, [1.0, 1.0, 20.0], [1.0, 1.0, 20.0])
    assert t.size == 0 and c.size == 0
