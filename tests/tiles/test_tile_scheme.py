"""Cesium's geographic tiling scheme: hand-worked tiles, and the covering tiles checked against their bounds."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from terrainvis.tiles import tile_bounds, tile_count, tile_ranges, tile_size, tiles_covering


def test_counts_and_sizes_by_hand():
    assert tile_count(0) == (2, 1)
    assert tile_count(1) == (4, 2)
    assert tile_count(5) == (64, 32)
    assert tile_size(0) == 180.0
    assert tile_size(3) == 22.5


def test_bounds_by_hand():
    assert tile_bounds(0, 0, 0) == (-180.0, -90.0, 0.0, 90.0)
    assert tile_bounds(0, 1, 0) == (0.0, -90.0, 180.0, 90.0)
    # zoom 3: 22.5 degrees; column 9 starts at -180 + 9 * 22.5 = 22.5, row 5 (from the south) at -90 + 5 * 22.5 = 22.5
    assert tile_bounds(3, 9, 5) == (22.5, 22.5, 45.0, 45.0)
    assert tile_bounds(1, 3, 1) == (90.0, 0.0, 180.0, 90.0)


def test_covering_by_hand():
    # zoom 3, 22.5 degrees: 10 -> column floor(190 / 22.5) = 8, 50 -> ceil(230 / 22.5) - 1 = 10;
    # -5 -> row floor(85 / 22.5) = 3, 30 -> ceil(120 / 22.5) - 1 = 5
    assert tiles_covering(3, (10.0, -5.0, 50.0, 30.0)) == (8, 3, 10, 5)
    # edges on tile edges: the tiles beyond only touch it
    assert tiles_covering(2, (0.0, 0.0, 45.0, 45.0)) == (4, 2, 4, 2)
    assert tiles_covering(1, (-180.0, -90.0, 180.0, 90.0)) == (0, 0, 3, 1)
    # the bundled DEM's rectangle (about 84.40 to 84.09 W, 36.46 to 36.72 N) at zoom 10 (0.17578125 degrees):
    # (180 - 84.40) / 0.17578125 = 543.9, (180 - 84.09) / 0.17578125 = 545.6, 126.46 / 0.17578125 = 719.4, 126.72 / ... = 720.9
    assert tiles_covering(10, (-84.40, 36.46, -84.09, 36.72)) == (543, 719, 545, 720)


def test_refusals_name_the_argument():
    with pytest.raises(ValueError, match="zoom must be in"):
        tile_count(25)
    with pytest.raises(ValueError, match="x must be in"):
        tile_bounds(0, 2, 0)
    with pytest.raises(ValueError, match="y must be in"):
        tile_bounds(1, 0, 2)
    with pytest.raises(ValueError, match="bounds must have"):
        tiles_covering(1, (10.0, 0.0, 5.0, 1.0))


def _overlap(a, b) -> bool:
    return min(a[2], b[2]) > max(a[0], b[0]) and min(a[3], b[3]) > max(a[1], b[1])


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 6), st.floats(-180, 180), st.floats(-180, 180), st.floats(-90, 90), st.floats(-90, 90))
def test_covering_is_exactly_the_tiles_that_meet(z, a, b, c, d):
    w, e = sorted((a, b))
    s, n = sorted((c, d))
    if w == e or s == n:
        return
    rect = (w, s, e, n)
    x0, y0, x1, y1 = tiles_covering(z, rect)
    nx, ny = tile_count(z)
    for x in range(nx):
        for y in range(ny):
            inside = x0 <= x <= x1 and y0 <= y <= y1
            assert inside == _overlap(tile_bounds(z, x, y), rect), (z, x, y, rect)


def test_ranges_by_hand():
    assert tile_ranges([(2, 1), (3, 1), (2, 2), (3, 2), (5, 2)]) == [
        {"startX": 2, "startY": 1, "endX": 3, "endY": 2}, {"startX": 5, "startY": 2, "endX": 5, "endY": 2}]
    assert tile_ranges([(0, 0), (1, 0)]) == [{"startX": 0, "startY": 0, "endX": 1, "endY": 0}]
    assert tile_ranges([]) == []


@settings(max_examples=200, deadline=None)
@given(st.sets(st.tuples(st.integers(0, 7), st.integers(0, 5)), max_size=30))
def test_ranges_cover_exactly_the_tiles(tiles):
    ranges = tile_ranges(tiles)
    cells = [(x, y) for r in ranges for x in range(r["startX"], r["endX"] + 1) for y in range(r["startY"], r["endY"] + 1)]
    assert len(cells) == len(set(cells))  # no tile twice
    assert set(cells) == set(tiles)
