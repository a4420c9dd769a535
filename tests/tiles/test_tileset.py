"""``write_tileset`` from Python: a lon/lat DEM placed right, the refusals (ValueError naming the argument),
an interrupted run that leaves no layer.json, and the rectangle search on a hand-made mask."""

from __future__ import annotations

import json

import numpy as np
import pytest

from terrainvis import HeightGrid
from terrainvis.tiles import decode_tile, tile_bounds, write_tileset
from terrainvis.tiles.tileset import _largest_true_rectangle

pytest.importorskip("pyproj", reason="the tiles extra (pyproj) is not installed")


def _lonlat_dem(nodata: bool = False) -> HeightGrid:
    """A 0.5 x 0.4 degree DEM in EPSG:4326 (local metres, as load_dem makes them), heights a smooth function."""
    from terrainvis.core._georef import lonlat_to_local

    lon = np.linspace(-100.5, -100.0, 101)
    lat = np.linspace(40.0, 40.4, 81)
    L, P = np.meshgrid(lon, lat)
    z = 1000.0 + 300.0 * np.sin(8 * L) * np.cos(9 * P)
    if nodata:
        z[:, :20] = np.nan  # the western fifth
    xs, ys, affine = lonlat_to_local(lon, lat)
    return HeightGrid.from_coords(z, xs, ys, attrs={"crs": "EPSG:4326", "geographic": True, "xy_to_native": affine})


def test_a_lonlat_dem_is_placed_where_it_is(tmp_path):
    dem = _lonlat_dem()
    ts = write_tileset(dem, tmp_path / "t", method="greedy-insertion", zooms=(8, 9))
    np.testing.assert_allclose(ts.bounds, (-100.5, 40.0, -100.0, 40.4), rtol=0, atol=1e-6)
    n = 0
    for f in (tmp_path / "t").glob("9/*/*.terrain"):
        x, y = int(f.parent.name), int(f.stem)
        t = decode_tile(f.read_bytes(), tile_bounds(9, x, y))
        # every vertex inside the rectangle is a lattice point, so its height is the DEM's surface at its
        # lon/lat (up to the rounding); the others extend the rectangle's edge to the tile's (test_whole_tile)
        w, s, e, nn = ts.bounds
        inside = (t.lon >= w - 1e-9) & (t.lon <= e + 1e-9) & (t.lat >= s - 1e-9) & (t.lat <= nn + 1e-9)
        want = dem.height_at(dem.from_native(np.column_stack([t.lon[inside], t.lat[inside]])))
        step = (t.max_height - t.min_height) / 32767
        assert np.abs(t.height[inside] - want).max() <= 0.5 * step + 1e-6
        n += 1
    assert n >= 2
    assert ts.largest_error <= 77067.0 / 2 ** 8 + 1.0


def test_nodata_is_left_outside_the_rectangle(tmp_path):
    ts = write_tileset(_lonlat_dem(nodata=True), tmp_path / "t", method="simple", zooms=(0, 0))
    west = -100.5 + 20 * 0.005  # the first valid column
    assert west - 1e-6 <= ts.bounds[0] <= west + 0.005
    np.testing.assert_allclose(ts.bounds[1:], (40.0, -100.0, 40.4), rtol=0, atol=1e-6)


@pytest.mark.parametrize("kwargs, match", [
    ({"method": "nope", "zooms": (0, 1)}, "method must be one of"),
    ({"method": "simple", "zooms": (2, 1)}, "zooms must run from the lower zoom"),
    ({"method": "simple", "zooms": (0, 25)}, r"zooms must be integers in \[0, 24\]"),
    ({"method": "simple", "zooms": 3}, "zooms must be two zooms"),
    ({"method": "simple", "zooms": (0, 1), "max_error0": -1.0}, "max_error0 must be a finite number"),
    ({"method": "simple", "zooms": (0, 1), "lattice": 0}, "lattice must be an integer"),
])
def test_refusals_name_the_argument(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        write_tileset(_lonlat_dem(), tmp_path / "t", **kwargs)
    assert not (tmp_path / "t").exists()


def test_a_dem_without_a_crs_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"grid has no CRS \(attrs\['crs'\]\)"):
        write_tileset(HeightGrid(np.zeros((5, 5))), tmp_path / "t", method="simple", zooms=(0, 0))


def test_an_interrupted_run_leaves_no_layer_json(tmp_path, monkeypatch):
    from terrainvis.tiles import tileset as module

    real, calls = module._make_tile, []

    def stopping(*a, **k):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(module, "_make_tile", stopping)
    out = tmp_path / "t"
    with pytest.raises(KeyboardInterrupt):
        write_tileset(_lonlat_dem(), out, method="simple", zooms=(0, 3))
    assert not (out / "layer.json").exists()
    finished = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    # the two root tiles (the eastern one flat, made without _make_tile) and zoom 1's tile: lon -100.5 is in
    # column floor(79.5 / 90) = 0, lat 40 in row floor(130 / 90) = 1; whole files only, no temporary left
    # and the run's settings, for resume
    assert finished == ["0/0/0.terrain", "0/1/0.terrain", "1/0/1.terrain", "terrainvis-tiles.partial.json"]
    assert json.loads((out / "terrainvis-tiles.partial.json").read_text())["settings"]["method"] == "simple"
    monkeypatch.setattr(module, "_make_tile", real)
    with pytest.raises(ValueError, match="holds an unfinished run's 3 tiles; resume=True continues it"):
        write_tileset(_lonlat_dem(), out, method="simple", zooms=(0, 3))
    with pytest.raises(ValueError, match=r"other settings \(method: 'simple' then, 'lls' now\)"):
        write_tileset(_lonlat_dem(), out, method="lls", zooms=(0, 3), resume=True)
    # resume: the finished tiles are kept as they are (not written again), the others made
    kept = {p: p.stat().st_mtime_ns for p in out.rglob("*.terrain") if p.parent.parent.name != "0"}
    assert kept
    ts = write_tileset(_lonlat_dem(), out, method="simple", zooms=(0, 3), resume=True)
    assert {p: p.stat().st_mtime_ns for p in kept} == kept
    assert ts.removed == 0 and not (out / "terrainvis-tiles.partial.json").exists()
    fresh = tmp_path / "fresh"
    write_tileset(_lonlat_dem(), fresh, method="simple", zooms=(0, 3))
    assert json.loads((out / "layer.json").read_text()) == json.loads((fresh / "layer.json").read_text())
    assert sorted(p.relative_to(out) for p in out.rglob("*.terrain")) == \
        sorted(p.relative_to(fresh) for p in fresh.rglob("*.terrain"))


def test_resume_remakes_a_damaged_tile_and_overwrite_starts_again(tmp_path, monkeypatch):
    from terrainvis.tiles import tileset as module

    real, calls = module._make_tile, []

    def stopping(*a, **k):
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(module, "_make_tile", stopping)
    out = tmp_path / "t"
    with pytest.raises(KeyboardInterrupt):
        write_tileset(_lonlat_dem(), out, method="simple", zooms=(0, 3), gzip=False)
    monkeypatch.setattr(module, "_make_tile", real)
    damaged = out / "1" / "0" / "1.terrain"
    damaged.write_bytes(damaged.read_bytes()[:50])
    write_tileset(_lonlat_dem(), out, method="simple", zooms=(0, 3), gzip=False, resume=True)
    fresh = tmp_path / "fresh"
    write_tileset(_lonlat_dem(), fresh, method="simple", zooms=(0, 3), gzip=False)
    assert damaged.read_bytes() == (fresh / "1" / "0" / "1.terrain").read_bytes()
    with pytest.raises(ValueError, match="no unfinished run of terrainvis tiles \\(a finished tileset"):
        write_tileset(_lonlat_dem(), out, method="simple", zooms=(0, 3), resume=True)
    ts = write_tileset(_lonlat_dem(), out, method="simple", zooms=(0, 2), overwrite=True)
    assert ts.removed == 5 + 2  # 5 tiles, layer.json and terrainvis-tiles.csv
    assert not (out / "3").exists()


def test_largest_rectangle_by_hand():
    mask = np.array([[1, 1, 0, 0],
                     [1, 1, 1, 1],
                     [0, 1, 1, 1],
                     [0, 1, 1, 0]], dtype=bool)
    # rows 1-2, columns 1-3 (6 cells) beats rows 0-3 column 1 (4) and rows 1-3 columns 1-2 (6, found later)
    assert _largest_true_rectangle(mask) == (1, 1, 2, 3)
    assert _largest_true_rectangle(np.zeros((3, 3), dtype=bool)) is None


@pytest.mark.parametrize("u_span, v_span", [((0, 32767), (0, 32767)), ((1200, 32767), (0, 32767)),
                                            ((0, 20000), (500, 32767)), ((9000, 13251), (4000, 30000))])
def test_whole_tile_extends_the_part_to_the_tiles_edges(u_span, v_span):
    """A mesh over part of a tile, extended to the whole tile: the part's triangles unchanged, the tile
    covered exactly once (triangle areas summing to the tile's, all counter-clockwise), and every added
    vertex at the height of the part's vertex it extends (the same v on the west and east sides, the
    same u on the south and north sides, the part's corner beyond its corners)."""
    from terrainvis.core.mesh import signed_area2
    from terrainvis.tiles.quantized_mesh import QUANTIZED_MAX as M
    from terrainvis.tiles.tileset import _whole_tile

    rng = np.random.default_rng(sum(u_span) + sum(v_span))
    (ua, ub), (va, vb) = u_span, v_span
    us = np.unique(np.concatenate([[ua, ub], rng.integers(ua + 1, ub, 6)]))
    vs = np.unique(np.concatenate([[va, vb], rng.integers(va + 1, vb, 5)]))
    U, V = np.meshgrid(us, vs)
    H = rng.normal(300.0, 50.0, U.shape)
    r, c = np.mgrid[0: vs.size - 1, 0: us.size - 1]
    k = (r * us.size + c).ravel()
    faces = np.concatenate([np.column_stack([k, k + 1, k + us.size + 1]), np.column_stack([k, k + us.size + 1, k + us.size])])
    u, v, h, f = _whole_tile(U.ravel(), V.ravel(), H.ravel(), faces, u_span, v_span)
    assert np.array_equal(f[: len(faces)], faces) and np.array_equal(h[: U.size], H.ravel())
    area = signed_area2(np.column_stack([u, v]), f)
    assert (area > 0).all() and area.sum() == 2 * M * M  # twice the tile's area: covered once, no overlap
    assert {u.min(), u.max(), v.min(), v.max()} == {0, M}
    part = {(int(a), int(b)): float(x) for a, b, x in zip(U.ravel(), V.ravel(), H.ravel())}
    for a, b, x in zip(u[U.size:], v[U.size:], h[U.size:]):
        src = (min(max(int(a), ua), ub), min(max(int(b), va), vb))  # the part's point it extends
        assert x == part[src], (a, b)
