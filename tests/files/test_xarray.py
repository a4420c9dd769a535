"""HeightGrid.from_xarray / to_xarray and simplifiers.blockwise.simplify_dataarray."""

from __future__ import annotations

import sys
import warnings

import numpy as np
import pytest
from conftest import shared_dem_path

from simplifiers import simplify
from terrainvis import HeightGrid, load_dem, synthetic_terrain
from terrainvis.io import native_coords

xr = pytest.importorskip("xarray", reason="xarray (the optional xarray extra) is not installed")


def _raster_order(g: HeightGrid, **attrs):
    """A DataArray as rasters come: y descending (north first)."""
    return xr.DataArray(g.z[::-1], dims=("y", "x"), coords={"y": g.ys[::-1], "x": g.xs}, attrs=attrs)


def test_round_trip_exact():
    g = HeightGrid.from_coords(
        np.random.default_rng(0).normal(size=(4, 6)), [0.0, 1.0, 2.5, 3.0, 9.0, 10.0], [5.0, 6.0, 8.0, 8.5],
        attrs={"name": "r", "shape": (4, 6)},
    )
    da = g.to_xarray()
    assert da.dims == ("y", "x") and da.name == "z"
    np.testing.assert_array_equal(da.y.values, g.ys)
    da.values[0, 0] = 123.0  # a copy: the grid is untouched
    assert g.z[0, 0] != 123.0
    back = HeightGrid.from_xarray(g.to_xarray())
    np.testing.assert_array_equal(back.z, g.z)
    np.testing.assert_array_equal(back.xs, g.xs)
    np.testing.assert_array_equal(back.ys, g.ys)
    assert back.attrs == g.attrs


def test_descending_y_and_transposed_dims():
    g = synthetic_terrain("hills", size=9)
    da = _raster_order(g)
    for arr in (da, da.transpose("x", "y")):
        back = HeightGrid.from_xarray(arr)
        np.testing.assert_array_equal(back.z, g.z)
        np.testing.assert_array_equal(back.ys, g.ys)
    # Descending x too, and lon/lat dim names with a CRS: converted to local metres.
    lon = -84.4 + np.arange(9) / 1200
    lat = 36.5 + np.arange(9) / 1200
    ll = xr.DataArray(g.z[::-1, ::-1], dims=("lat", "lon"), coords={"lat": lat[::-1], "lon": lon[::-1]})
    back = HeightGrid.from_xarray(ll, crs="EPSG:4326")
    np.testing.assert_array_equal(back.z, g.z)
    assert back.attrs["geographic"] is True and back.xs[0] == 0.0
    got_lon, got_lat = native_coords(back)
    np.testing.assert_allclose(got_lon, lon, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got_lat, lat, rtol=0, atol=1e-12)


def test_lon_lat_without_crs_warn():
    g = synthetic_terrain("hills", size=5)
    da = xr.DataArray(g.z, dims=("y", "x"), coords={"y": 36.5 + np.arange(5) / 1200, "x": -84.4 + np.arange(5) / 1200})
    with pytest.warns(UserWarning, match="look like lon/lat degrees"):
        HeightGrid.from_xarray(da)


def test_rioxarray_geotiff_equals_load_dem():
    rioxarray = pytest.importorskip("rioxarray", reason="rioxarray is not installed")
    path = shared_dem_path("green_mountains_vt", ".tif")
    da = rioxarray.open_rasterio(path)  # (band, y, x), y descending, _FillValue and scale attrs
    g = HeightGrid.from_xarray(da)
    ref = load_dem(path)
    np.testing.assert_array_equal(g.z, ref.z)
    np.testing.assert_array_equal(g.xs, ref.xs)
    np.testing.assert_array_equal(g.ys, ref.ys)
    assert g.attrs["crs"] == "EPSG:26918" and g.attrs["xy_to_native"] == (1.0, 0.0, 1.0, 0.0)
    assert "_FillValue" not in g.attrs and "scale_factor" not in g.attrs
    # to_xarray writes the CRS where rioxarray looks, and keeps the text in attrs.
    out = g.to_xarray()
    assert out.rio.crs.to_epsg() == 26918 and out.attrs["crs"] == "EPSG:26918"
    back = HeightGrid.from_xarray(out)
    assert back.attrs == g.attrs


def test_nodata_scale_and_offset_attributes():
    raw = np.array([[0, 100], [-1, 190]], dtype=np.int16)
    da = xr.DataArray(raw, dims=("y", "x"), coords={"y": [10.0, 0.0], "x": [0.0, 10.0]},
                      attrs={"_FillValue": -1, "scale_factor": 0.1, "add_offset": 100.0, "units": "m"})
    g = HeightGrid.from_xarray(da)
    np.testing.assert_allclose(g.z, [[np.nan, 119.0], [100.0, 110.0]], rtol=0, atol=1e-12)
    assert g.attrs == {"units": "m"}


def test_bad_input():
    with pytest.raises(TypeError, match=r"da must be an xarray.DataArray, got array of shape \(3, 3\)"):
        HeightGrid.from_xarray(np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"must be a 2-D DataArray \(y, x\), got 3-D"):
        HeightGrid.from_xarray(xr.DataArray(np.zeros((2, 3, 3)), dims=("t", "y", "x")))
    with pytest.raises(ValueError, match=r"has 2 bands; a DEM has one: pick it first, e.g. da.sel\(band=1\)"):
        HeightGrid.from_xarray(xr.DataArray(np.zeros((2, 3, 3)), dims=("band", "y", "x")))
    with pytest.raises(ValueError, match=r"cannot tell which dim of da \['row', 'col'\] is x"):
        HeightGrid.from_xarray(xr.DataArray(np.zeros((3, 3)), dims=("row", "col")))
    with pytest.raises(ValueError, match="has no coordinate for its dim 'x'"):
        HeightGrid.from_xarray(xr.DataArray(np.zeros((3, 3)), dims=("y", "x"), coords={"y": [0.0, 1.0, 2.0]}))
    named = xr.DataArray(np.zeros((3, 3)), dims=("row", "col"), coords={"row": [0.0, 1.0, 2.0], "col": [0.0, 2.0, 4.0]})
    assert HeightGrid.from_xarray(named, x="col", y="row").xs.tolist() == [0.0, 2.0, 4.0]
    with pytest.raises(ValueError, match=r"x must name a dim of da \['row', 'col'\], got 'x'"):
        HeightGrid.from_xarray(named, x="x", y="row")
    with pytest.raises(ValueError, match="x and y must be different dims"):
        HeightGrid.from_xarray(named, x="col", y="col")


def test_missing_xarray_gives_an_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ImportError, match="need xarray: pip install xarray"):
        HeightGrid(np.zeros((2, 2))).to_xarray()


# ------------------------------------------------------------------------ simplify_dataarray
da_mod = pytest.importorskip("dask.array", reason="the dask extra is not installed")
from simplifiers.blockwise import simplify_dataarray  # noqa: E402


@pytest.mark.parametrize("shape", [(101, 131), (120, 90)])
def test_simplify_dataarray_equals_simplify_lazily(shape):
    rng = np.random.default_rng(3)
    z = rng.normal(size=shape).cumsum(0).cumsum(1)
    g = HeightGrid(z, dx=30.0, dy=30.0, origin=(500000.0, 4e6))
    lazy_input = _raster_order(g, units="m").chunk({"y": 40, "x": 37})
    out = simplify_dataarray(lazy_input, "lls", 2)
    assert isinstance(out.data, da_mod.Array)  # nothing computed yet
    assert out.dims == ("y", "x") and out.attrs == {"units": "m", "method": "lls", "level": 2}
    ref = simplify(g, "lls", 2)
    np.testing.assert_array_equal(out.values, ref.z[::-1])  # bit for bit, in the input's (raster) order
    np.testing.assert_array_equal(out.y.values, ref.ys[::-1])
    np.testing.assert_array_equal(out.x.values, ref.xs)
    # In memory and transposed: the same numbers, in that order.
    mem = simplify_dataarray(_raster_order(g).transpose("x", "y"), "simple", 1, chunks=50)
    assert mem.dims == ("x", "y")
    np.testing.assert_array_equal(mem.transpose("y", "x").values, simplify(g, "simple", 1).z[::-1])


def test_simplify_dataarray_on_a_rioxarray_geotiff():
    rioxarray = pytest.importorskip("rioxarray", reason="rioxarray is not installed")
    path = shared_dem_path("green_mountains_vt", ".tif")
    da = rioxarray.open_rasterio(path, chunks=64).isel(y=slice(0, 101), x=slice(0, 131))  # odd sizes
    out = simplify_dataarray(da, "lls", 1)
    assert "GeoTransform" not in out.spatial_ref.attrs  # the source's transform would be stale
    assert out.rio.crs.to_epsg() == 26918
    ref = simplify(HeightGrid.from_xarray(da), "lls", 1)
    np.testing.assert_array_equal(out.values[::-1], ref.z)
    t = out.rio.transform()
    assert (t.a, t.e) == (180.0, -180.0)  # odd sizes: uniform coarse coordinates, a clean transform
    assert t.c + 0.5 * t.a == pytest.approx(ref.xs[0]) and t.f + 0.5 * t.e == pytest.approx(ref.ys[-1])


def test_simplify_dataarray_errors():
    g = synthetic_terrain("hills", size=9)
    with pytest.raises(ValueError, match=r"method must be one of \['simple', 'gls', 'lls'\]"):
        simplify_dataarray(g.to_xarray(), "feature", 1)
    with pytest.raises(TypeError, match="da must be an xarray.DataArray"):
        simplify_dataarray(g.z, "lls", 1)
    with pytest.raises(ValueError, match="level must be >= 0"):
        simplify_dataarray(g.to_xarray(), "lls", -1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert simplify_dataarray(g.to_xarray(), "lls", 0).shape == (9, 9)
