"""A float32 raster's heights kept as float32 (``HeightGrid.heights``): the viewshed's verdicts are
the float64 grid's bit for bit, and nothing on the viewshed's path asks for the float64 copy.

The reference is the same samples held as float64 (``HeightGrid.from_coords`` of the float32
values, as every grid was held before): every float32 value is a float64 value, so the two
grids are one surface, and the kernels must read each height as float64 (a difference of two
float32 heights computed in float32 is rounded).
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from terrainvis import HeightGrid
from terrainvis.core.synthetic import synthetic_terrain
from terrainvis.visibility.viewsheds import _bound_kernels as bk
from terrainvis.visibility.viewsheds.sweep import _viewshed, viewshed


def _held32(z, xs, ys, attrs=None) -> HeightGrid:
    """A grid holding float32 heights, as the GeoTIFF reader makes one (its own fresh buffer)."""
    return HeightGrid._from_coords(np.array(z, dtype=np.float32), xs, ys, attrs, owned=True)


def _pair(seed: int, rows: int, cols: int, *, holes: bool, rectilinear: bool, offset: float):
    """The same float32 samples as a float32-held grid and a float64 one (UTM-sized offsets:
    heights whose float32 differences round)."""
    rng = np.random.default_rng(seed)
    z = synthetic_terrain("rough", size=max(rows, cols), seed=seed).z[:rows, :cols] * rng.uniform(0.5, 3.0) + offset
    z = z.astype(np.float32)
    if holes:
        z[rng.random(z.shape) < 0.03] = np.nan
    xs = 500000.0 + 30.0 * np.arange(cols)
    ys = 4000000.0 + 30.0 * np.arange(rows)
    if rectilinear:
        xs = 500000.0 + np.cumsum(rng.uniform(20.0, 40.0, cols))
    return _held32(z, xs, ys), HeightGrid.from_coords(z.astype(np.float64), xs, ys)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 10_000),
    rows=st.integers(3, 48),
    cols=st.integers(3, 48),
    holes=st.booleans(),
    rectilinear=st.booleans(),
    offset=st.sampled_from([0.0, 1234.567, 8848.86]),
    where=st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
    options=st.sampled_from([
        {},
        {"observer_height": 0.0},
        {"target_height": 2.5, "max_distance": 700.0},
        {"curvature": 0.857},
        {"azimuth": (20.0, 250.0), "vertical": (-3.0, 8.0), "min_distance": 60.0},
    ]),
)
def test_viewshed_of_float32_heights_is_the_float64_grids(seed, rows, cols, holes, rectilinear, offset, where,
                                                         options):
    g32, g64 = _pair(seed, rows, cols, holes=holes, rectilinear=rectilinear, offset=offset)
    obs = (g64.xs[0] + where[0] * (g64.xs[-1] - g64.xs[0]), g64.ys[0] + where[1] * (g64.ys[-1] - g64.ys[0]))
    try:
        want = viewshed(g64, obs, **options)
    except ValueError as exc:  # an observer on nodata: the float32 grid refuses it alike
        with pytest.raises(type(exc), match="nodata"):
            viewshed(g32, obs, **options)
        return
    got = viewshed(g32, obs, **options)
    assert got.dtype == want.dtype and np.array_equal(got, want)
    assert g32.heights.dtype == np.float32, "the viewshed asked for the float64 copy (HeightGrid.z)"


def test_sweep_counts_are_the_float64_grids_on_a_large_grid():
    """Past the small grids' shortcuts (the threads, the tables built side by side): the same
    verdicts, decided the same way (the counts of the sweep's bounds and walks)."""
    g32, g64 = _pair(7, 300, 257, holes=False, rectilinear=False, offset=2500.25)
    obs = (g64.xs[90] + 11.0, g64.ys[200] + 4.0)
    a, ia = _viewshed(g64, obs, curvature=0.857)
    b, ib = _viewshed(g32, obs, curvature=0.857)
    assert np.array_equal(a, b) and ia == ib
    assert ia["lb"] > 0 and ia["walk"] + ia["ub"] > 0  # the bounds and the walks both took part
    assert g32.heights.dtype == np.float32


def test_heights_and_z_of_a_float32_grid():
    z = np.array([[1.1, 2.2, np.nan], [3.3, 4.4, 5.5]], dtype=np.float32)
    g = _held32(z, [0.0, 1.0, 2.0], [0.0, 1.0])
    assert g.heights.dtype == np.float32 and not g.heights.flags.writeable
    assert g.nbytes == z.nbytes + 5 * 8 and g.n_nodata == 1 and g.shape == (2, 3)
    assert "z [1.1, 5.5]" in repr(g)
    # the surface at a point reads the float32 samples as float64
    assert g.height_at([[0.5, 0.25]])[0] == HeightGrid.from_coords(z.astype(np.float64), g.xs, g.ys).height_at(
        [[0.5, 0.25]])[0]
    # a pickled grid keeps its float32 heights
    back = pickle.loads(pickle.dumps(g))
    assert back.heights.dtype == np.float32 and np.array_equal(back.heights, z, equal_nan=True)
    # z: the float64 values, read-only, made once; the grid then holds them instead
    zz = g.z
    assert zz.dtype == np.float64 and not zz.flags.writeable
    assert np.array_equal(zz, z.astype(np.float64), equal_nan=True)
    assert g.z is zz and g.heights is zz


def test_public_constructors_still_hold_float64():
    z = np.ones((3, 3), dtype=np.float32)
    assert HeightGrid(z).heights.dtype == np.float64
    assert HeightGrid.from_coords(z, [0.0, 1.0, 2.0], [0.0, 1.0, 2.0]).heights.dtype == np.float64


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), rows=st.integers(2, 30), cols=st.integers(2, 30),
       float32=st.booleans(), holes=st.booleans(), scale=st.sampled_from([1e-3, 1.0, 1e4]))
def test_max_slope_on_even_columns_is_the_edge_by_edge_maximum(seed, rows, cols, float32, holes, scale):
    """The even-spacing path divides each row's largest step once; the edge-by-edge loop
    divides every step: the same bits (a correctly rounded division keeps the order)."""
    rng = np.random.default_rng(seed)
    z = rng.normal(0.0, scale, (rows, cols))
    if holes:
        z[rng.random(z.shape) < 0.2] = np.nan
    if float32:
        z = z.astype(np.float32)
    dx = float(rng.choice([0.25, 1.0, 30.0, 0.1]))
    xs = 1000.0 + dx * np.arange(cols)  # 0.1: steps of one number (checked below) or not
    ys = np.cumsum(rng.uniform(0.05, 50.0, rows))  # rows: any spacing
    hx = np.diff(xs)
    even = bool((hx == hx[0]).all())
    edge_by_edge = np.empty(rows)
    bk.max_slope(z, xs, ys, False, edge_by_edge)
    if even:  # dx 0.25, 1 and 30 always; 0.1 rarely
        once = np.empty(rows)
        bk.max_slope(z, xs, ys, True, once)
        assert np.array_equal(once, edge_by_edge)
    # and the loop itself against numpy's slopes
    zf = z.astype(np.float64)
    with np.errstate(invalid="ignore"):
        cand = [np.abs(np.diff(zf, axis=1)) / hx[None, :]]
        rowmax = np.nanmax(np.where(np.isnan(cand[0]), 0.0, cand[0]), axis=1)
        if rows > 1:
            dy = np.diff(ys)[:, None]
            vert = np.abs(np.diff(zf, axis=0)) / dy
            diag = np.abs(zf[1:, 1:] - zf[:-1, :-1]) / np.sqrt(hx[None, :] ** 2 + dy ** 2)
            rowmax[:-1] = np.maximum(rowmax[:-1], np.nanmax(np.where(np.isnan(vert), 0.0, vert), axis=1))
            rowmax[:-1] = np.maximum(rowmax[:-1], np.nanmax(np.where(np.isnan(diag), 0.0, diag), axis=1))
    assert np.array_equal(edge_by_edge, rowmax)



@pytest.mark.parametrize("slope", [(0.1, 0.3), (-0.7, 0.013), (2.9, -1.1)])
def test_viewshed_on_a_rounded_plane_is_the_float64_grids(slope):
    """The grazing case: a plane's float32 samples, seen from its own ground. Every sight line
    runs within rounding of the surface, so any height computed in float32 (a difference of
    two samples, a target's height) moves verdicts; the float64 grid is the reference."""
    rows, cols = 41, 53
    r, c = np.mgrid[0:rows, 0:cols]
    z = (slope[0] * c + slope[1] * r + 0.37).astype(np.float32)  # crosses 0: float32 differences round
    xs = 10.0 * np.arange(cols)
    ys = 10.0 * np.arange(rows)
    g32, g64 = _held32(z, xs, ys), HeightGrid.from_coords(z.astype(np.float64), xs, ys)
    for obs in ((xs[7], ys[30]), (xs[26] + 3.3, ys[20] + 1.1), (xs[50], ys[2])):
        for h_o, h_t in ((0.0, 0.0), (0.0, 1e-6), (1e-6, 0.0)):
            want = viewshed(g64, obs, observer_height=h_o, target_height=h_t)
            got = viewshed(g32, obs, observer_height=h_o, target_height=h_t)
            assert np.array_equal(got, want), (obs, h_o, h_t, int((got != want).sum()))
    assert g32.heights.dtype == np.float32


def _tif(path, z, dtype, **extra):
    rasterio = pytest.importorskip("rasterio", reason="the geo extra (rasterio) is not installed")
    from rasterio.transform import Affine

    rows, cols = z.shape
    with rasterio.open(path, "w", driver="GTiff", height=rows, width=cols, count=1, dtype=dtype, crs="EPSG:32617",
                       transform=Affine(30.0, 0, 500000.0, 0, -30.0, 4000000.0 + 30.0 * rows), nodata=-9999.0,
                       **extra) as dst:
        dst.write(np.where(np.isnan(z), -9999.0, z).astype(dtype), 1)
        if "scales" in extra:
            dst.scales = extra["scales"]
    return path


def test_reader_keeps_a_float32_bands_samples(tmp_path):
    from terrainvis import load_dem

    z = synthetic_terrain("hills", size=40, seed=3).z[::-1] * 3.7 + 0.123
    z[5, 7] = np.nan
    z32 = _tif(tmp_path / "f32.tif", z, "float32")
    g = load_dem(z32)
    assert g.heights.dtype == np.float32 and g.n_nodata == 1
    want = z[::-1].astype(np.float32).astype(np.float64)  # north-up file, rows in increasing y
    assert np.array_equal(g.z, want, equal_nan=True) and g.z.dtype == np.float64
    # a float64 band, and a float32 band with a scale, are float64 heights
    assert load_dem(_tif(tmp_path / "f64.tif", z, "float64")).heights.dtype == np.float64
    scaled = _tif(tmp_path / "scaled.tif", z, "float32")
    import rasterio

    with rasterio.open(scaled, "r+") as dst:
        dst.scales = (0.5,)
    gs = load_dem(scaled)
    assert gs.heights.dtype == np.float64
    assert np.array_equal(gs.z, want * 0.5, equal_nan=True)


def test_viewshed_command_never_asks_for_float64_heights(tmp_path, monkeypatch, capsys):
    """The command's whole path (the read, the checks, the observer's ground, the sweep, the
    field of view, the GeoTIFF written) on a float32 DEM: HeightGrid.z is never asked for, and
    the result is that of the same DEM held as float64."""
    from terrainvis import load_dem
    from terrainvis.cli import main
    from terrainvis.core import terrain as terrain_module

    z = synthetic_terrain("ridges", size=64, seed=5).z * 2.3 + 100.7
    z[40:43, 10:14] = np.nan
    dem = _tif(tmp_path / "dem.tif", z, "float32")
    observer = ["500500", str(4000000.0 + 30.0 * 64 - 700.0)]
    args = ["viewshed", str(dem), "--observer", *observer, "--azimuth", "0", "300", "--curvature", "0.857"]
    float64 = terrain_module.HeightGrid.z

    def refused(self):
        if self.heights.dtype != np.float64:
            raise AssertionError("HeightGrid.z asked for on the viewshed's path")
        return float64.fget(self)

    monkeypatch.setattr(terrain_module.HeightGrid, "z", property(refused))
    assert main([*args, "-o", str(tmp_path / "out.tif")]) == 0
    monkeypatch.undo()
    # the same command on the DEM held as float64 (a .npz of its float64 heights)
    import rasterio

    from terrainvis.io import save_terrain

    g64 = load_dem(dem)
    save_terrain(terrain_module.HeightGrid.from_coords(g64.z, g64.xs, g64.ys, attrs=g64.attrs), tmp_path / "dem.npz")
    assert main(["viewshed", str(tmp_path / "dem.npz"), *args[2:], "-o", str(tmp_path / "out64.tif")]) == 0
    capsys.readouterr()
    with rasterio.open(tmp_path / "out.tif") as a, rasterio.open(tmp_path / "out64.tif") as b:
        got, want = a.read(1), b.read(1)
    assert np.array_equal(got, want) and 0 < int((got == 1).sum()) < int((got == 0).sum()) and (got == 255).any()


def test_heights_dtype_from_the_header_is_the_readers(tmp_path):
    """What the viewshed command loads its kernels for, beside the read, is what the read gives
    (a float32 grid's kernels are others: loading the float64 ones compiled both on a first run)."""
    import rasterio

    from terrainvis import load_dem
    from terrainvis.io import bundled_terrain, save_terrain
    from terrainvis.io._names import heights_dtype

    z = synthetic_terrain("mesas", size=24, seed=2).z
    files = [_tif(tmp_path / "a32.tif", z, "float32"), _tif(tmp_path / "a64.tif", z, "float64"),
             _tif(tmp_path / "i16.tif", np.round(z), "int16"), _tif(tmp_path / "s32.tif", z, "float32")]
    with rasterio.open(files[-1], "r+") as dst:
        dst.offsets = (100.0,)
    save_terrain(HeightGrid(z), tmp_path / "g.npz")
    for p in files + [tmp_path / "g.npz"]:
        assert heights_dtype(str(p)) == load_dem(p).heights.dtype, p
    assert [heights_dtype(str(p)) for p in files] == [np.float32, np.float64, np.float64, np.float64]
    assert heights_dtype("cumberland") == bundled_terrain("cumberland").heights.dtype
    assert heights_dtype("hills") == np.float64 and heights_dtype(str(tmp_path / "absent.tif")) == np.float64
