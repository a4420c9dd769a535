"""Vertical errors and the volume between two surfaces (terrainvis.deviation)."""

from __future__ import annotations

import numpy as np
import pytest

from terrainvis import TIN, HeightGrid, synthetic_terrain
from terrainvis.deviation import vertical_errors, volume_error


def test_vertical_errors_grid_and_tin():
    fine = HeightGrid(np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 0.0]]))
    coarse = HeightGrid(np.zeros((2, 2)), dx=2.0, dy=2.0)
    mx, rms = vertical_errors(fine, coarse)
    assert mx == 3.0 and rms == pytest.approx(np.sqrt(9 / 9))
    assert vertical_errors(fine, coarse.to_tin()) == (mx, rms)
    with pytest.raises(ValueError, match="coarse must cover the fine grid"):
        vertical_errors(fine, HeightGrid(np.zeros((2, 2))))


def test_volume_error_hand_cases():
    base = HeightGrid(np.zeros((3, 4)), dx=10.0, dy=20.0, origin=(560000.0, 5.1e6))
    raised = HeightGrid(np.full((2, 2), 2.5), dx=30.0, dy=40.0, origin=(560000.0, 5.1e6))
    # two parallel planes 2.5 apart over a 30 x 40 footprint
    assert volume_error(base, raised) == pytest.approx(2.5 * 30 * 40, rel=1e-9)
    assert volume_error(base, base) == pytest.approx(0.0, abs=1e-9)
    # a single peak of height 6 at the middle sample of a 3x3 grid, against a flat plane:
    # the volume of the piecewise-linear bump is 6 * (area of its support) / 3
    peak = np.zeros((3, 3))
    peak[1, 1] = 6.0
    g = HeightGrid(peak)
    flat = HeightGrid(np.zeros((2, 2)), dx=2.0, dy=2.0)
    # the support of the hat function is the 6 triangles around (1, 1), total area 3
    assert volume_error(g, flat) == pytest.approx(6.0 * 3.0 / 3.0, rel=1e-9)


def test_volume_error_matches_integral_of_abs_difference():
    from simplifiers import simplify

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


def test_volume_error_bad_input():
    g = HeightGrid(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="coarse must cover the extent"):
        volume_error(g, HeightGrid(np.zeros((2, 2))))
    with pytest.raises(TypeError, match="coarse must be"):
        volume_error(g, np.zeros((3, 3)))
    z = np.zeros((3, 3))
    z[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        volume_error(HeightGrid(z), g)
    # a TIN over only half of the footprint does not cover the extent's corner (2, 2)
    half = TIN(np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], float), [[0, 1, 2]])
    with pytest.raises(ValueError, match="coarse must cover the extent"):
        volume_error(HeightGrid(np.zeros((3, 3))), TIN(half.vertices[[0, 1]].tolist() + [[2.0, 1.0, 0.0]], [[0, 1, 2]]))
    # same bounding box as the grid, but only half of its footprint
    corner = TIN(np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [2, 2, 0]], float), [[0, 1, 2]])
    with pytest.raises(ValueError, match="coarse must cover the footprint"):
        volume_error(HeightGrid(np.zeros((3, 3))), corner)
