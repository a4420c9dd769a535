"""``write_tileset(..., format="terrain-rgb")`` / ``terrainvis tiles --format terrain-rgb``: Mapbox's terrain-RGB
PNG tiles in Web Mercator (XYZ rows), each simplified by a method.

The checks are made here from the documented rules, not from the writer's helpers: the tiles
written are those whose Web Mercator square meets the tileset's rectangle (computed with the
spherical Mercator formulas), each pixel decoded with Mapbox's formula from the PNG read by
Pillow lies within its zoom's budget plus half the 0.1 m step of the DEM's surface at the pixel's
position (the pixel's corner, deck.gl's placement, clamped to the rectangle, through pyproj), and
the tileset reads back through :func:`terrainvis.tiles.read.stitch_zoom` onto the same heights."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tests.conftest import one_line_error
from terrainvis.tiles import write_tileset

pyproj = pytest.importorskip("pyproj", reason="the tiles extra (pyproj) is not installed")
Image = pytest.importorskip("PIL.Image", reason="the tiles extra (Pillow) is not installed")

ZOOMS = (10, 11)
W = 32
R = 6378137.0
E0 = 77067.0


def _cumberland():
    from terrainvis.io import bundled_terrain

    return bundled_terrain("cumberland")


def _lon(x):
    return np.degrees(np.asarray(x) / R)


def _lat(y):
    return np.degrees(2 * np.arctan(np.exp(np.asarray(y) / R)) - np.pi / 2)


def _merc(lon, lat):
    return np.radians(lon) * R, R * np.log(np.tan(np.pi / 4 + np.radians(lat) / 2))


@pytest.fixture(scope="module")
def rgb_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("rgb") / "t"
    ts = write_tileset(_cumberland(), out, method="greedy-insertion", zooms=ZOOMS, format="terrain-rgb", lattice=W)
    return out, ts, json.loads((out / "layer.json").read_text(encoding="utf-8"))


def _files(out):
    return {(int(f.parent.parent.name), int(f.parent.name), int(f.stem)) for f in out.glob("*/*/*.png")}


def test_layer_json_is_a_terrain_rgb_tilejson(rgb_run):
    out, ts, layer = rgb_run
    assert (layer["format"], layer["scheme"], layer["projection"], layer["encoding"], layer["tileSize"]) == \
        ("terrain-rgb", "xyz", "EPSG:3857", "mapbox", W)
    assert layer["tiles"] == ["{z}/{x}/{y}.png"] and layer["maxzoom"] == ZOOMS[1]
    assert not list(out.glob("*/*/*.terrain"))


def test_the_tiles_are_those_meeting_the_rectangle(rgb_run):
    out, ts, layer = rgb_run
    west, south, east, north = layer["bounds"]
    want = set()
    for z in range(ZOOMS[1] + 1):
        size = 2 * math.pi * R / 2 ** z
        (x0, x1), (ya, yb) = _merc(np.array([west, east]), np.array([south, north]))
        fx0, fx1 = (x0 + math.pi * R) / size, (x1 + math.pi * R) / size
        fy0, fy1 = (math.pi * R - yb) / size, (math.pi * R - ya) / size  # rows from the north
        want |= {(z, x, y) for x in range(math.floor(fx0), math.ceil(fx1)) for y in range(math.floor(fy0), math.ceil(fy1))}
    assert _files(out) == want


def test_every_pixel_is_within_its_zooms_budget_of_the_dem(rgb_run):
    out, ts, layer = rgb_run
    dem = _cumberland()
    from terrainvis.core._georef import xy_to_native

    sx, ox, sy, oy = xy_to_native(dem.attrs)
    to_dem = pyproj.Transformer.from_crs("EPSG:4326", pyproj.CRS.from_user_input(dem.attrs["crs"]), always_xy=True)
    west, south, east, north = layer["bounds"]
    checked = 0
    for z, x, y in sorted(_files(out)):
        a = np.asarray(Image.open(out / str(z) / str(x) / f"{y}.png").convert("RGB")).astype(np.int64)
        assert a.shape == (W, W, 3)
        got = -10000 + (a[..., 0] * 65536 + a[..., 1] * 256 + a[..., 2]) * 0.1
        size = 2 * math.pi * R / 2 ** z
        frac = np.arange(W) / W
        lon = np.clip(_lon(-math.pi * R + (x + frac) * size), west, east)
        lat = np.clip(_lat(math.pi * R - (y + frac) * size), south, north)  # rows from the north
        LON, LAT = np.meshgrid(lon, lat)
        ex, ny = to_dem.transform(LON.ravel(), LAT.ravel())
        want = dem.height_at(np.column_stack([(np.asarray(ex) - ox) / sx, (np.asarray(ny) - oy) / sy])).reshape(W, W)
        budget = E0 / 2 ** z if z >= ZOOMS[0] else 0.0
        assert np.abs(got - want).max() <= budget + 0.05 + 1e-6, (z, x, y)
        checked += 1
    assert checked == len(_files(out))
    simplified = [r for r in ts.zooms if r.simplified]
    assert all(0 < r.largest_error <= r.max_error + 0.05 + 1e-9 for r in simplified)
    assert all(r.n_vertices < r.n_tiles * (W + 1) ** 2 for r in simplified)  # the method did simplify


def test_read_back_the_stitched_zoom_holds_the_pixels(rgb_run):
    from terrainvis import HeightGrid
    from terrainvis.core._georef import lonlat_to_local
    from terrainvis.tiles.read import open_tileset, stitch_zoom

    out, ts, layer = rgb_run
    west, south, east, north = layer["bounds"]
    # a lon/lat DEM inside the rectangle: the stitched zoom covers it
    lon = np.linspace(west + 0.02, east - 0.02, 41)
    lat = np.linspace(south + 0.02, north - 0.02, 31)
    xs, ys, affine = lonlat_to_local(lon, lat)
    probe = HeightGrid.from_coords(np.zeros((lat.size, lon.size)), xs, ys,
                                   attrs={"crs": "EPSG:4326", "geographic": True, "xy_to_native": affine})
    tin = stitch_zoom(probe, open_tileset(out), ZOOMS[1], mesh="grid")
    # heights at pixel corners of zoom 11, decoded here from the PNGs
    z = ZOOMS[1]
    size = 2 * math.pi * R / 2 ** z
    pts, want = [], []
    for f in sorted((out / str(z)).glob("*/*.png")):
        x, y = int(f.parent.name), int(f.stem)
        a = np.asarray(Image.open(f).convert("RGB")).astype(np.int64)
        got = -10000 + (a[..., 0] * 65536 + a[..., 1] * 256 + a[..., 2]) * 0.1
        for r, c in ((3, 5), (17, 9), (W - 2, W - 3)):
            lo_, la_ = _lon(-math.pi * R + (x + c / W) * size), _lat(math.pi * R - (y + r / W) * size)
            if lon[0] < lo_ < lon[-1] and lat[0] < la_ < lat[-1]:
                pts.append((lo_, la_))
                want.append(got[r, c])
    assert pts
    pts = np.array(pts)
    local = np.column_stack([(pts[:, 0] - affine[1]) / affine[0], (pts[:, 1] - affine[3]) / affine[2]])
    np.testing.assert_allclose(tin.height_at(local), want, atol=1e-6)


def test_an_interrupted_run_resumes_to_the_same_tiles(rgb_run, tmp_path, monkeypatch):
    from terrainvis.tiles import terrain_rgb, tileset as module

    real, calls = terrain_rgb.make_rgb_tile, []

    def stopping(*a, **k):
        calls.append(1)
        if len(calls) == 20:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(module, "make_rgb_tile", stopping)
    out = tmp_path / "t"
    with pytest.raises(KeyboardInterrupt):
        write_tileset(_cumberland(), out, method="greedy-insertion", zooms=ZOOMS, format="terrain-rgb", lattice=W)
    assert not (out / "layer.json").exists()
    monkeypatch.setattr(module, "make_rgb_tile", real)
    kept = {p: p.stat().st_mtime_ns for p in out.rglob("*.png")}
    assert len(kept) == 19
    ts = write_tileset(_cumberland(), out, method="greedy-insertion", zooms=ZOOMS, format="terrain-rgb", lattice=W,
                       resume=True)
    assert {p: p.stat().st_mtime_ns for p in kept} == kept  # kept as they were
    fresh, fresh_ts, _ = rgb_run
    assert [r.as_json() for r in ts.zooms] == [r.as_json() for r in fresh_ts.zooms]
    for f in fresh.rglob("*.png"):
        assert (out / f.relative_to(fresh)).read_bytes() == f.read_bytes()
    again = write_tileset(_cumberland(), out, method="simple", zooms=(5, 6), format="terrain-rgb", lattice=W,
                          overwrite=True)
    assert again.removed == len(_files(fresh)) + 2  # the tiles, layer.json and the table
    assert max(int(p.name) for p in out.iterdir() if p.is_dir()) == 6


@pytest.mark.parametrize("kwargs, match", [
    ({"format": "png"}, "format must be one of quantized-mesh, terrain-rgb, got 'png'"),
    ({"format": "terrain-rgb", "gzip": True}, "gzip=True is for quantized-mesh tiles"),
    ({"format": "terrain-rgb", "keep_los": 0.9}, "keep_los chooses the budgets of quantized-mesh tiles only"),
])
def test_refusals_name_the_argument(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        write_tileset(_cumberland(), tmp_path / "t", method="simple", zooms=(9, 9), **kwargs)
    assert not (tmp_path / "t").exists()


def test_the_command_line(capsys, tmp_path):
    from terrainvis.cli import main

    err = one_line_error(capsys, 2, ["tiles", "cumberland", str(tmp_path / "a"), "-m", "simple", "--zoom", "9", "9",
                                     "--format", "terrain-rgb", "--gzip"])
    assert "--gzip is for quantized-mesh tiles" in err
    err = one_line_error(capsys, 2, ["tiles", "cumberland", str(tmp_path / "a"), "-m", "simple", "--zoom", "9", "9",
                                     "--format", "webp"])
    assert "argument --format: invalid choice: 'webp'" in err
    assert main(["tiles", "cumberland", str(tmp_path / "b"), "-m", "simple", "--zoom", "9", "10", "--format",
                 "terrain-rgb", "--lattice", "16"]) == 0
    out = capsys.readouterr().out
    assert "zoom 10:" in out and (tmp_path / "b" / "10").is_dir()
    assert json.loads((tmp_path / "b" / "layer.json").read_text())["tileSize"] == 16
