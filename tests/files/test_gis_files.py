"""Files as a GIS writes them: rasters from TINs, GeoTIFF dtype/nodata/compression/tiles, memory
checks before reading, names that are not UTF-8, and the messages of bad input."""

from __future__ import annotations

import io
import os
import shutil
import subprocess
import warnings
import zipfile

import numpy as np
import pytest
from conftest import shared_dem_path

import simplifiers
from terrainvis import TIN, HeightGrid, load_dem, save_dem, synthetic_terrain
from terrainvis.core.validate import FLOAT64_EPS, as_height, height_limit
from terrainvis.errors import NotEnoughMemoryError
from terrainvis.io import load_terrain, save_terrain, write_mask_geotiff


def _rasterio():
    return pytest.importorskip("rasterio", reason="the geo extra (rasterio) is not installed")


@pytest.fixture(scope="module")
def gm():
    _rasterio()
    return load_dem(shared_dem_path("green_mountains_vt", ".tif"))


# ------------------------------------------------------------------ rasters from TINs
@pytest.mark.parametrize("suffix", [".tif", ".asc"])
def test_a_tin_is_written_as_its_surface_on_the_grid(tmp_path, gm, suffix):
    tin = simplifiers.simplify(gm, "greedy-insertion", 2)
    p = save_terrain(tin, tmp_path / f"gi{suffix}", like=gm)
    back = load_dem(p)
    assert back.shape == gm.shape
    np.testing.assert_allclose(back.xs, gm.xs, rtol=0, atol=1e-6)
    np.testing.assert_allclose(back.ys, gm.ys, rtol=0, atol=1e-6)
    assert back.attrs["crs"] == gm.attrs["crs"]
    want = tin.height_on_grid(gm.xs, gm.ys)
    np.testing.assert_array_equal(back.z, want) if suffix == ".tif" else np.testing.assert_allclose(back.z, want, rtol=1e-15)
    # the TIN's vertices are grid samples: the raster holds their heights exactly there
    r = np.searchsorted(gm.ys, tin.vertices[:, 1])
    c = np.searchsorted(gm.xs, tin.vertices[:, 0])
    np.testing.assert_allclose(back.z[r, c], tin.vertices[:, 2], rtol=1e-12)


def test_samples_outside_the_tin_are_nodata(tmp_path):
    _rasterio()
    g = HeightGrid(np.arange(30.0).reshape(5, 6), dx=10.0, dy=10.0, attrs={"crs": "EPSG:32633"})
    half = TIN([[0, 0, 0], [20, 0, 2], [20, 40, 26], [0, 40, 24]], [[0, 1, 2], [0, 2, 3]])  # z = x / 10 + 0.6 y, x <= 20
    p = save_terrain(half, tmp_path / "half.tif", like=g)
    back = load_dem(p)
    assert np.isnan(back.z[:, 3:]).all() and np.isfinite(back.z[:, :3]).all()
    np.testing.assert_allclose(back.z[:, :3], g.z[:, :3])  # the same plane
    rasterio = _rasterio()
    with rasterio.open(p) as src:
        assert src.nodata == -9999.0 and src.crs.to_epsg() == 32633


def test_a_tin_to_a_raster_needs_the_grid(tmp_path):
    tin = synthetic_terrain("hills", size=9).to_tin()
    with pytest.raises(ValueError, match=r"pass like=<the grid>"):
        save_terrain(tin, tmp_path / "t.tif")
    with pytest.raises(TypeError, match="like must be a terrainvis.HeightGrid"):
        save_terrain(tin, tmp_path / "t.tif", like=tin)
    with pytest.raises(TypeError, match="like must be a terrainvis.HeightGrid"):
        tin.to_grid(np.zeros((3, 3)))


# ------------------------------------------------------------------ GeoTIFFs as GDAL writes them
def test_float32_dem_stays_float32_with_nodata_deflate(tmp_path, gm):
    rasterio = _rasterio()
    with rasterio.open(shared_dem_path("green_mountains_vt", ".tif")) as src:
        assert src.dtypes[0] == "float32"
    p = save_dem(gm, tmp_path / "gm.tif")
    with rasterio.open(p) as src:
        assert src.dtypes[0] == "float32"
        assert src.nodata == -9999.0  # the tag even without a nodata sample
        assert src.compression.name.lower() == "deflate"
    np.testing.assert_array_equal(load_dem(p).z, gm.z)


def test_values_that_float32_cannot_hold_are_float64(tmp_path, gm):
    rasterio = _rasterio()
    lls = simplifiers.simplify(gm.crop(rows=(0, 101), cols=(0, 101)), "lls", 1)  # odd: uniform, no resample
    assert not np.array_equal(lls.z.astype(np.float32).astype(np.float64), lls.z)
    p = save_dem(lls, tmp_path / "lls.tif")
    with rasterio.open(p) as src:
        assert src.dtypes[0] == "float64"
    np.testing.assert_array_equal(load_dem(p).z, lls.z)


def test_large_rasters_are_tiled_small_ones_striped(tmp_path):
    rasterio = _rasterio()
    big = synthetic_terrain("hills", size=600)
    small = synthetic_terrain("hills", size=100)
    for g, name, tiled in ((big, "big.tif", True), (small, "small.tif", False)):
        p = save_dem(g, tmp_path / name)
        with rasterio.open(p) as src:
            assert src.profile.get("tiled", False) == tiled
            assert src.block_shapes[0] == ((256, 256) if tiled else src.block_shapes[0])
            assert src.compression.name.lower() == "deflate"
    mask = write_mask_geotiff(big, big.z > 50, tmp_path / "mask.tif")
    with rasterio.open(mask) as src:
        assert src.dtypes[0] == "uint8" and src.profile["tiled"] and src.compression.name.lower() == "deflate"
        assert src.nodata == 255


@pytest.mark.skipif(shutil.which("gdalinfo") is None, reason="gdalinfo (Debian's gdal-bin) is not installed")
def test_gdalinfo_shows_them(tmp_path):
    _rasterio()
    g = synthetic_terrain("hills", size=600)
    p = save_dem(g, tmp_path / "g.tif")
    info = subprocess.run(["gdalinfo", str(p)], capture_output=True, text=True, check=True).stdout
    assert "COMPRESSION=DEFLATE" in info and "Block=256x256" in info and "NoData Value=-9999" in info


# ------------------------------------------------------------------ memory before allocation
def _huge_npy_header() -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": (100000, 100000)})
    return buf.getvalue()


def test_a_header_claiming_too_much_is_refused_before_reading(tmp_path):
    npy = tmp_path / "huge.npy"
    npy.write_bytes(_huge_npy_header())
    assert npy.stat().st_size < 200
    npz = tmp_path / "huge.npz"
    with zipfile.ZipFile(npz, "w") as zf:
        zf.writestr("z.npy", _huge_npy_header())
    for p in (npy, npz):
        with pytest.raises(NotEnoughMemoryError, match=r"needs about .* GiB; this machine has .* available"):
            load_dem(p)
    assert issubclass(NotEnoughMemoryError, MemoryError) and issubclass(NotEnoughMemoryError, ValueError)
    asc = tmp_path / "huge.asc"
    asc.write_text("ncols 100000\nnrows 100000\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n")
    with pytest.raises(ValueError, match=r"the header claims 100000x100000 values, but the file of \d+ bytes"):
        load_dem(asc)


def test_simplify_checks_its_memory_first(monkeypatch):
    import terrainvis.core.memory as mem

    g = synthetic_terrain("hills", size=65)
    monkeypatch.setattr(mem, "available_memory", lambda: 10_000)
    for method in ("lls", "greedy-insertion", "qec"):
        with pytest.raises(NotEnoughMemoryError, match=rf"simplify\('{method}'\) of a 65x65 grid.*needs about"):
            simplifiers.simplify(g, method, 1)
    monkeypatch.setattr(mem, "available_memory", lambda: None)  # unknown: nothing is refused
    assert simplifiers.simplify(g, "lls", 1).shape == (33, 33)


def test_the_cgroup_limit_is_found_once_and_its_usage_read_at_every_check(monkeypatch):
    """The cgroup's memory files are looked up once per process (a compare run checks memory
    before every visibility matrix); the limit and the usage are read at every check. v2,
    the group's own ``memory.max`` unlimited, the namespace root's limit used."""
    import io

    import terrainvis.core.memory as mem

    files = {
        "/proc/self/cgroup": "0::/user.slice/job\n",
        "/sys/fs/cgroup/user.slice/job/memory.max": "max\n",
        "/sys/fs/cgroup/user.slice/job/memory.current": "5\n",
        "/sys/fs/cgroup/memory.max": "1000000\n",
        "/sys/fs/cgroup/memory.current": "250000\n",
    }
    opened = []

    def fake_open(path, encoding=None):
        opened.append(path)
        if path not in files:
            raise OSError(path)
        return io.StringIO(files[path])

    monkeypatch.setattr(mem, "open", fake_open, raising=False)
    monkeypatch.setattr(mem, "_CGROUP_FILES", None)
    assert mem._cgroup_room() == 750_000
    files["/sys/fs/cgroup/memory.current"] = "900000\n"
    assert mem._cgroup_room() == 100_000
    assert opened.count("/proc/self/cgroup") == 1
    assert mem._cgroup_files() == ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current")
    # no limit anywhere: none, and not looked up again
    files["/sys/fs/cgroup/memory.max"] = "max\n"
    monkeypatch.setattr(mem, "_CGROUP_FILES", None)
    assert mem._cgroup_room() is None and mem._cgroup_room() is None
    assert opened.count("/proc/self/cgroup") == 2 and mem._CGROUP_FILES == ()


# ------------------------------------------------------------------ names that are not UTF-8
def test_geotiff_names_that_are_not_utf8(tmp_path, gm):
    name = os.fsdecode(b"dem_\xff.tif")
    p = save_dem(gm, tmp_path / name)
    assert p.exists()
    back = load_dem(p)
    np.testing.assert_array_equal(back.z, gm.z)
    assert back.attrs["crs"] == gm.attrs["crs"]
    m = write_mask_geotiff(gm, gm.z > 500, tmp_path / os.fsdecode(b"mask_\xfe.tif"))
    rasterio = _rasterio()
    from rasterio.io import MemoryFile

    with MemoryFile(m.read_bytes()) as mem, mem.open() as src:
        np.testing.assert_array_equal(src.read(1)[::-1], (gm.z > 500).astype(np.uint8))
    assert rasterio is not None


# ------------------------------------------------------------------ messages that name things
def test_unknown_asc_header_key(tmp_path):
    p = tmp_path / "k.asc"
    p.write_text("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\nbyteorder lsb\n1 2\n3 4\n")
    with pytest.raises(ValueError, match=r"'k.asc'.*header line 6 has the unknown key 'byteorder'; an ESRI ASCII "
                                         r"grid header holds cellsize, dx, dy, ncols"):
        load_dem(p)


def test_urls_are_refused_by_name():
    for url in ("https://example.com/dem.tif", "s3://bucket/dem.tif"):
        with pytest.raises(ValueError, match=r"URLs are not supported, got '.*': download the file first"):
            load_dem(url)


def test_all_nan_dem_is_refused_at_load(tmp_path):
    p = tmp_path / "nan.npy"
    np.save(p, np.full((4, 5), np.nan))
    with pytest.raises(ValueError, match=r"'nan.npy' holds no height: all 4x5 samples are nodata"):
        load_dem(p)
    q = tmp_path / "flat.npz"
    save_dem(HeightGrid(np.full((3, 3), 7.0)), q)
    with pytest.raises(ValueError, match=r"holds no height.*nodata=7.0"):
        load_terrain(q, nodata=7.0)


def test_from_xarray_warns_on_lon_lat_dims_without_crs():
    xr = pytest.importorskip("xarray")
    lat = np.linspace(45.0, 44.0, 5)
    lon = np.linspace(-120.0, -119.0, 6)  # 0.2-degree cells: too coarse for the cell-size rule alone
    da = xr.DataArray(np.zeros((5, 6)), dims=("lat", "lon"), coords={"lat": lat, "lon": lon})
    with pytest.warns(UserWarning, match=r"named lon/lat .*crs='EPSG:4326' to HeightGrid.from_xarray"):
        HeightGrid.from_xarray(da)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g = HeightGrid.from_xarray(da, crs="EPSG:4326") if _has_rasterio() else None
        projected = da.rename(lat="y", lon="x").assign_coords(x=np.arange(6.0) * 1e4, y=np.arange(5.0)[::-1] * 1e4)
        HeightGrid.from_xarray(projected)  # metres: no warning
    assert g is None or g.attrs["geographic"]


def _has_rasterio() -> bool:
    try:
        import rasterio  # noqa: F401
    except ImportError:
        return False
    return True


# ------------------------------------------------------------------ heights float64 resolves
def test_height_limit_is_the_tolerance_over_the_rounding():
    scale, ground = 5000.0, 1200.0
    limit = height_limit(scale, ground)
    assert limit == 1e-9 * scale / 2.0**-52 - ground
    assert FLOAT64_EPS == 2.0**-52
    # at the limit, one ulp of the end height is the predicate's tolerance
    assert np.spacing(limit + ground) <= 2 * 1e-9 * scale
    assert as_height(-limit, "h", scale=scale, ground=ground) == -limit
    for bad in (1e20, 1e16, 1e300, -1e308, limit * 1.001):
        with pytest.raises(ValueError, match=r"h must be within \[-.*\] for this terrain"):
            as_height(bad, "h", scale=scale, ground=ground)
    with pytest.raises(ValueError, match="offset must be a finite number, got nan"):
        as_height(float("nan"), "offset", scale=scale)
    with pytest.raises(ValueError, match=r"height must be within \[0, "):
        as_height(-50.0, "height", scale=scale, minimum=0.0)
    with pytest.raises(TypeError, match="height must be a real number"):
        as_height("2", "height", scale=scale)


@pytest.mark.parametrize(("dtype", "nodata", "flip_rows", "flip_cols", "scale", "offset"), [
    ("float32", -9999.0, True, False, 1.0, 0.0),
    ("int16", -32768, False, True, 0.5, 100.0),
    ("uint16", 0, True, True, 0.1, -5.0),
])
def test_a_large_band_read_in_strips_is_the_whole_band(tmp_path, dtype, nodata, flip_rows, flip_cols, scale, offset):
    """A band of 4.4 million samples is read in two strips of rows (an interrupt is answered
    between them); the heights are rasterio's whole read, flipped, nodata NaN, scaled."""
    rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
    from rasterio.transform import Affine

    rows = cols = 2100
    rng = np.random.default_rng(7)
    band = (rng.random((rows, cols)) * 1000).astype(dtype)
    band[rng.random((rows, cols)) < 0.05] = nodata
    t = Affine(-30.0 if flip_cols else 30.0, 0.0, 500000.0, 0.0, -30.0 if flip_rows else 30.0, 4000000.0)
    p = tmp_path / "big.tif"
    with rasterio.open(p, "w", driver="GTiff", height=rows, width=cols, count=1, dtype=dtype, crs="EPSG:32617",
                       transform=t, nodata=nodata, tiled=True, blockxsize=256, blockysize=256) as dst:
        dst.write(band, 1)
        dst.scales, dst.offsets = (scale,), (offset,)
    with rasterio.open(p) as src:
        whole = src.read(1).astype(np.float64)
    expected = np.where(whole == nodata, np.nan, whole)[::-1 if flip_rows else 1, ::-1 if flip_cols else 1]
    expected = expected * scale + offset if scale != 1.0 or offset != 0.0 else expected
    g = load_dem(p)
    np.testing.assert_allclose(g.z, expected, rtol=1e-15, atol=0.0, equal_nan=True)
    assert np.isnan(g.z).sum() == (band == nodata).sum()
    assert np.all(np.diff(g.xs) > 0) and np.all(np.diff(g.ys) > 0)
