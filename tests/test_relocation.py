"""relocate: the three strategies, offsets, and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from terrainvis import HeightGrid, relocate, sample_points, synthetic_terrain
from terrainvis.errors import OutsideFootprintError


def _plane(z0=10.0):
    return HeightGrid(np.full((3, 3), z0), dx=5.0, dy=5.0)


def test_hand_cases():
    S = _plane(10.0)
    P = np.array([[1.0, 1.0, 8.0], [2.0, 3.0, 12.0], [4.0, 4.0, 10.0]])
    before = P.copy()
    np.testing.assert_array_equal(relocate(P, S, "identity"), P)
    np.testing.assert_array_equal(relocate(P, S, "full")[:, 2], [10.0, 10.0, 10.0])
    np.testing.assert_array_equal(relocate(P, S, "half")[:, 2], [10.0, 12.0, 10.0])
    np.testing.assert_array_equal(P, before)  # never modified
    assert relocate(P, S, "identity") is not P


def test_offset_acts_on_the_ground_point():
    S = _plane(10.0)
    # An observer 2 m above a ground point 1 m below S: its ground point is lifted to S.
    P = np.array([[1.0, 1.0, 11.0], [1.0, 1.0, 15.0]])
    np.testing.assert_array_equal(relocate(P, S, "half", offset=2.0)[:, 2], [12.0, 15.0])
    np.testing.assert_array_equal(relocate(P, S, "full", offset=2.0)[:, 2], [12.0, 12.0])


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from(["simple", "lls", "greedy-insertion"]))
def test_properties_on_real_simplifications(seed, method):
    from simplifiers import simplify

    T = synthetic_terrain("mountains", size=33, seed=seed % 7)
    S = simplify(T, method, 2)
    P = sample_points(T, 40, seed=seed)
    full = relocate(P, S, "full")
    half = relocate(P, S, "half")
    ground = S.height_at(P[:, :2])
    np.testing.assert_allclose(full[:, 2], ground)
    # half = max(original, simplified surface), and x, y never move
    np.testing.assert_allclose(half[:, 2], np.maximum(P[:, 2], ground))
    np.testing.assert_array_equal(half[:, :2], P[:, :2])
    assert (half[:, 2] >= full[:, 2] - 1e-12).all()


def test_bad_input():
    S = _plane()
    P = np.array([[1.0, 1.0, 8.0]])
    with pytest.raises(ValueError, match=r"how must be one of \['identity', 'full', 'half'\], got 'up'"):
        relocate(P, S, "up")
    with pytest.raises(OutsideFootprintError, match=r"1 of 2 do not \(first at index 1\)"):
        relocate(np.array([[1.0, 1.0, 0.0], [50.0, 1.0, 0.0]]), S, "full")
    with pytest.raises(ValueError, match=r"points must have shape \(m, 3\)"):
        relocate(np.zeros((2, 2)), S, "full")
    with pytest.raises(TypeError, match="simplified must be"):
        relocate(P, np.zeros((3, 3)), "full")
    assert relocate(np.empty((0, 3)), S, "half").shape == (0, 3)
