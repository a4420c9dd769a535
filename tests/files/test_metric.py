"""Distances on lon/lat DEMs: the local frame's error, measured, and the metric grid of ``to_metric``.

The reference is geodesic distance on the WGS84 ellipsoid (``pyproj.Geod``: Karney's
algorithm, independent of the code under test) between lon/lat points on 1 x 1 degree
tiles at 45 N and 60 N. The local frame a lon/lat DEM is read into (one east-west scale,
the centre latitude's) is off by the golden figures of docs/user-guide.md (Georeferencing); the
transverse Mercator grid of ``terrainvis.io.to_metric`` is within 1e-5 everywhere, and
its heights are the DEM's surface at the lon/lat that PROJ gives for each sample.
"""

from __future__ import annotations

import numpy as np
import pytest

import terrainvis as tv
from terrainvis.cli import main
from terrainvis.io import to_metric

from conftest import shared_dem_path

rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
pyproj = pytest.importorskip("pyproj", reason="pyproj (with rioxarray, the xarray extra) is the geodesic reference")
from rasterio.transform import from_origin  # noqa: E402

GEOD = pyproj.Geod(ellps="WGS84")
CELL = 30.0 / 3600.0  # 30 arc-seconds: 121 x 121 samples per degree, enough for distances
N = 121


def _tile(path, lat_s: float, z=None, crs: str = "EPSG:4326"):
    """A 1 x 1 degree lon/lat GeoTIFF whose sample centres span lon [0, 1], lat [lat_s, lat_s + 1]."""
    if z is None:
        z = np.zeros((N, N))
    transform = from_origin(-0.5 * CELL, lat_s + 1.0 + 0.5 * CELL, CELL, CELL)
    with rasterio.open(path, "w", driver="GTiff", height=z.shape[0], width=z.shape[1], count=1, dtype="float64",
                       crs=crs, transform=transform) as dst:
        dst.write(np.asarray(z, dtype=np.float64), 1)
    return path


@pytest.fixture(scope="module", params=[44.5, 59.5], ids=["45N", "60N"])
def tile(request, tmp_path_factory):
    lat_s = request.param
    grid = tv.load_dem(_tile(tmp_path_factory.mktemp("tile") / "t.tif", lat_s))
    return lat_s, grid, to_metric(grid)


def _frame_distance(grid, a, b):
    pa, pb = grid.from_native(np.atleast_2d(a)), grid.from_native(np.atleast_2d(b))
    return np.hypot(*(pb - pa).T)


def _geodesic(a, b):
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    return GEOD.inv(a[:, 0], a[:, 1], b[:, 0], b[:, 1])[2]


#: Golden figures (docs/user-guide.md (Georeferencing)): the local frame's relative error of a whole east-west
#: edge (southern, northern) of the tile, against the geodesic between its ends.
LOCAL_EDGE_ERRORS = {44.5: (-0.008579, 0.008819), 59.5: (-0.014819, 0.015370)}


def test_the_local_frame_is_off_by_the_documented_figures(tile):
    lat_s, grid, _ = tile
    lat_n = lat_s + 1.0
    for (a, b), golden in zip((((0.0, lat_s), (1.0, lat_s)), ((0.0, lat_n), (1.0, lat_n))), LOCAL_EDGE_ERRORS[lat_s]):
        rel = _frame_distance(grid, a, b)[0] / _geodesic(a, b)[0] - 1
        assert rel == pytest.approx(golden, abs=2e-6)
    # north-south lengths and the centre row are right to a few 1e-6
    for a, b in (((0.0, lat_s), (0.0, lat_n)), ((0.0, lat_s + 0.5), (1.0, lat_s + 0.5))):
        assert abs(_frame_distance(grid, a, b)[0] / _geodesic(a, b)[0] - 1) < 1e-5
    # the error info prints is the same figure, from the scales alone
    from terrainvis.core._georef import local_frame_error

    south, north = local_frame_error(grid.attrs, grid.ys)
    assert south == pytest.approx(LOCAL_EDGE_ERRORS[lat_s][0], abs=3e-5)
    assert north == pytest.approx(LOCAL_EDGE_ERRORS[lat_s][1], abs=3e-5)


def test_metric_distances_are_right_across_the_tile(tile):
    lat_s, grid, metric = tile
    rng = np.random.default_rng(7)
    a = np.column_stack([rng.uniform(0, 1, 20000), rng.uniform(lat_s, lat_s + 1, 20000)])
    b = np.column_stack([rng.uniform(0, 1, 20000), rng.uniform(lat_s, lat_s + 1, 20000)])
    g = _geodesic(a, b)
    keep = g > 100.0
    rel_metric = np.abs(_frame_distance(metric, a, b)[keep] / g[keep] - 1)
    rel_local = np.abs(_frame_distance(grid, a, b)[keep] / g[keep] - 1)
    assert rel_metric.max() < 1.1e-5  # the transverse Mercator's scale, split evenly about 1 by k0
    assert rel_local.max() > 0.008  # the local frame is 800 times worse at the edges
    # cells: the grid's spacing is metres of the ground, whatever the row
    for lat in (lat_s, lat_s + 1.0):
        true = _geodesic((0.5, lat), (0.5 + CELL, lat))[0]
        assert _frame_distance(metric, (0.5, lat), (0.5 + CELL, lat))[0] == pytest.approx(true, rel=1.1e-5)


def test_sight_lines_follow_the_geodesic_on_the_metric_grid(tile):
    """The straight segment the engines walk: the geodesic leaves it by centimetres on the metric grid,
    by hundreds of metres in the local frame (a rhumb line there)."""
    lat_s, grid, metric = tile
    a, b = (0.0, lat_s), (1.0, lat_s + 1.0)
    pts = np.array(GEOD.npts(a[0], a[1], b[0], b[1], 99))

    def offset(g):
        p, (pa, pb) = g.from_native(pts), g.from_native(np.array([a, b]))
        d = pb - pa
        return np.abs((p[:, 0] - pa[0]) * d[1] - (p[:, 1] - pa[1]) * d[0]).max() / np.hypot(*d)

    assert offset(metric) < 0.5
    assert offset(grid) > 300.0


def test_metric_heights_are_the_dems_surface_at_the_lon_lat_proj_gives(tmp_path):
    """Heights linear in lon/lat: the DEM's surface is that plane exactly, so every sample of the metric grid
    must hold the plane at its own lon/lat (pyproj's inverse projection, not rasterio's)."""
    lon = np.arange(N) * CELL
    lat = 44.5 + 1.0 - np.arange(N) * CELL  # north-up rows
    plane = lambda lo, la: 100.0 + 300.0 * lo - 200.0 * (la - 44.5)  # noqa: E731
    grid = tv.load_dem(_tile(tmp_path / "plane.tif", 44.5, plane(lon[None, :], lat[:, None])))
    metric = to_metric(grid)
    to_lonlat = pyproj.Transformer.from_crs(metric.attrs["crs"], "EPSG:4326", always_xy=True)
    X, Y = np.meshgrid(metric.xs, metric.ys)
    plon, plat = to_lonlat.transform(X, Y)
    assert not np.isnan(metric.z).any()  # footprint "inside": no nodata added
    np.testing.assert_allclose(metric.z, plane(plon, plat), atol=1e-6)
    # the grid: uniform, samples at multiples of the cell, the local frame's cell sizes by default
    assert metric.is_uniform and metric.dx == pytest.approx(grid.dx) and metric.dy == pytest.approx(grid.dy)
    assert np.allclose(metric.xs / grid.dx, np.round(metric.xs / grid.dx), atol=1e-9)
    cover = to_metric(grid, footprint="cover", cell=200.0)
    outside = np.isnan(cover.z)
    assert outside.any() and cover.dx == cover.dy == 200.0
    X, Y = np.meshgrid(cover.xs, cover.ys)
    plon, plat = to_lonlat.transform(X, Y)
    beyond = (plon < 0) | (plon > 1.0 + 1e-12) | (plat < 44.5) | (plat > 45.5 + 1e-12)
    np.testing.assert_array_equal(outside, beyond)  # nodata exactly where the sample is off the DEM
    np.testing.assert_allclose(cover.z[~outside], plane(plon, plat)[~outside], atol=1e-6)


def test_metric_grids_take_lon_lat_and_round_trip(tile):
    lat_s, grid, metric = tile
    assert metric.attrs["source_crs"] == grid.attrs["crs"] and metric.attrs["geographic"] is False
    rng = np.random.default_rng(2)
    p = np.column_stack([rng.uniform(0.1, 0.9, 200), rng.uniform(lat_s + 0.1, lat_s + 0.9, 200)])
    back = metric.to_native(metric.from_native(p))
    assert np.abs(back - p).max() < 1e-10
    # and the other way: the metric grid's samples to lon/lat and back
    q = metric.sample_xy()[::97]
    np.testing.assert_allclose(metric.from_native(metric.to_native(q)), q, atol=1e-6)


def test_saved_metric_grids(tmp_path, tile):
    lat_s, _, metric = tile
    tv.save_dem(metric, tmp_path / "m.tif")
    tv.save_dem(metric, tmp_path / "m.npz")
    with rasterio.open(tmp_path / "m.tif") as src:
        assert src.crs.is_projected and src.res == pytest.approx((metric.dx, metric.dy))
    tif, npz = tv.load_dem(tmp_path / "m.tif"), tv.load_dem(tmp_path / "m.npz")
    np.testing.assert_allclose(tif.xs, metric.xs, rtol=0, atol=1e-9)  # x0 + dx * k: rounding only
    # the GeoTIFF's own CRS decides: its positions are the projection's metres; the .npz keeps the lon/lat source
    assert "source_crs" not in tif.attrs and tif.from_native([1.0, 2.0]).tolist() == [1.0, 2.0]
    assert npz.attrs["source_crs"] == metric.attrs["source_crs"]
    p = np.array([0.5, lat_s + 0.5])
    np.testing.assert_allclose(npz.from_native(p), metric.from_native(p), atol=1e-9)


def test_bad_requests_are_refused():
    gm = tv.load_dem(shared_dem_path("green_mountains_vt", ".tif"))
    with pytest.raises(ValueError, match=r"to_metric needs a lon/lat grid .* projected \(EPSG:26918\)"):
        to_metric(gm)
    with pytest.raises(ValueError, match="without a CRS"):
        to_metric(tv.bundled_terrain("hills"))
    j = tv.sample_dem()
    with pytest.raises(ValueError, match="a grid resampled onto a metric grid already"):
        to_metric(to_metric(j))
    with pytest.raises(ValueError, match="footprint must be one of"):
        to_metric(j, footprint="all")
    with pytest.raises(ValueError, match="cell must be finite and > 0"):
        to_metric(j, cell=-1.0)
    with pytest.raises(ValueError, match="fewer than 2 samples"):
        to_metric(j, cell=1e6)
    with pytest.raises(TypeError, match="grid must be a terrainvis.HeightGrid"):
        to_metric(j.to_tin())


def test_nad27_keeps_its_datum(tmp_path):
    """A lon/lat DEM on another datum: the projection is on that datum, so no datum shift moves the samples."""
    grid = tv.load_dem(_tile(tmp_path / "nad27.tif", 44.5, crs="EPSG:4267"))
    metric = to_metric(grid)
    assert "+datum=NAD27" in metric.attrs["crs"]
    centre = metric.from_native([0.5, 45.0])
    assert np.abs(centre).max() < 1e-6  # the tile's centre is the projection's origin


def test_metric_from_the_command_line(tmp_path, capsys):
    path = _tile(tmp_path / "t.tif", 44.5, z=np.random.default_rng(3).uniform(0, 50, (N, N)))
    grid = tv.load_dem(path)
    metric = to_metric(grid)
    assert main(["viewshed", str(path), "--observer", "0.4", "45.1", "--metric", "-o", str(tmp_path / "v.npz")]) == 0
    expected = tv.viewshed(metric, tuple(metric.from_native([0.4, 45.1])))
    np.testing.assert_array_equal(tv.load_terrain(tmp_path / "v.npz").z == 1.0, expected)
    assert main(["los", str(path), "--from", "0.4", "45.1", "--to", "0.6", "45.2", "--metric"]) == 0
    out = capsys.readouterr().out
    a = np.append(metric.from_native([0.4, 45.1]), 0.0)
    b = np.append(metric.from_native([0.6, 45.2]), 0.0)
    a[2], b[2] = metric.height_at([a[:2]])[0] + 1.7, metric.height_at([b[:2]])[0]
    from terrainvis.visibility.profile import lowest_point

    low = lowest_point(metric, a, b)
    assert f"{low['distance']:.6g} from the observer" in out and "(0.4, 45.1) -> (0.6, 45.2)" in out
    assert main(["info", str(path), "--metric"]) == 0
    out = capsys.readouterr().out
    assert "metric    resampled from the 121x121 lon/lat grid (EPSG:4326)" in out and "distances" not in out
    gm = shared_dem_path("green_mountains_vt", ".tif")
    capsys.readouterr()
    assert main(["info", str(gm), "--metric"]) == 2
    assert "--metric resamples lon/lat DEMs; " in capsys.readouterr().err
    assert main(["relocate", str(path), "--points", str(tmp_path / "p.csv"), "-o", str(tmp_path / "o.csv"),
                 "--simplified", str(tmp_path / "s.npz"), "--metric"]) == 2
    assert "simplify here with -m METHOD" in capsys.readouterr().err
