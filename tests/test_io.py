"""load_dem / save_dem / sample_dem and the synthetic terrains."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DEM_NAMES, shared_dem_path

from terrainvis import HeightGrid, bundled_terrain, load_dem, sample_dem, save_dem, synthetic_terrain
from terrainvis.io import metres_per_degree
from terrainvis.synthetic import KINDS

# Figures from shared/data/dem/README.md: shape, dx, dy, min, max, NaN cells.
SHARED = {
    "jacksboro_fault_tn": ((344, 403), 74.57, 92.47, 236.0, 1076.0, 0),
    "mount_st_helens_wa": ((468, 327), 30.0, 30.0, 682.0, 2543.0, 4151),
    "green_mountains_vt": ((188, 237), 90.0, 90.0, 212.23, 1232.88, 0),
    "west_bijou_escarpment_co": ((67, 129), 23.89, 30.84, 1690.0, 1807.0, 0),
}


@pytest.mark.parametrize("name", DEM_NAMES)
def test_load_shared_npz(name):
    grid = load_dem(shared_dem_path(name))
    shape, dx, dy, zmin, zmax, nans = SHARED[name]
    assert grid.shape == shape
    assert grid.dx == pytest.approx(dx, abs=0.006) and grid.dy == pytest.approx(dy, abs=0.006)
    assert np.nanmin(grid.z) == pytest.approx(zmin, abs=0.01)
    assert np.nanmax(grid.z) == pytest.approx(zmax, abs=0.01)
    assert grid.n_nodata == nans
    # North-up raster: grid row r is raster row rows-1-r.
    with np.load(shared_dem_path(name)) as raw:
        np.testing.assert_array_equal(grid.z, raw["z"][::-1].astype(np.float64))


def test_projected_dem_keeps_crs_coordinates():
    grid = load_dem(shared_dem_path("mount_st_helens_wa"))
    # README: E 557,805 ... 567,615 and N 5,107,965 ... 5,122,005 (cell edges)
    assert grid.xs[0] == pytest.approx(557805 + 15) and grid.xs[-1] == pytest.approx(567615 - 15)
    assert grid.ys[0] == pytest.approx(5107965 + 15) and grid.ys[-1] == pytest.approx(5122005 - 15)


def test_geotiff_matches_npz():
    pytest.importorskip("rasterio", reason="the geo extra (rasterio) is not installed")
    tif = load_dem(shared_dem_path("green_mountains_vt", ".tif"))
    npz = load_dem(shared_dem_path("green_mountains_vt"))
    np.testing.assert_array_equal(tif.z, npz.z)
    np.testing.assert_allclose(tif.xs, npz.xs)
    np.testing.assert_allclose(tif.ys, npz.ys)


def test_sample_dem_is_the_shared_jacksboro():
    grid = sample_dem("jacksboro")
    assert grid.dx == pytest.approx(74.57, abs=0.005) and grid.dy == pytest.approx(92.47, abs=0.005)
    shared = load_dem(shared_dem_path("jacksboro_fault_tn"))
    np.testing.assert_array_equal(grid.z, shared.z)
    with pytest.raises(ValueError, match="name must be one of"):
        sample_dem("everest")


def test_metres_per_degree_known_values():
    lon, lat = metres_per_degree(0.0)
    assert lon == pytest.approx(111319.5, abs=1.0) and lat == pytest.approx(110574.3, abs=1.0)
    lon, lat = metres_per_degree(45.0)
    assert lon == pytest.approx(78846.8, abs=1.0) and lat == pytest.approx(111131.7, abs=1.0)


def _grid_with_nodata():
    rng = np.random.default_rng(0)
    z = rng.normal(500, 50, (7, 9))
    z[2, 3] = np.nan
    return HeightGrid(z, dx=30.0, dy=25.0, origin=(560000.0, 5.1e6))


@pytest.mark.parametrize("suffix", [".npz", ".asc", ".tif"])
def test_round_trip(tmp_path, suffix):
    if suffix == ".tif":
        pytest.importorskip("rasterio", reason="the geo extra (rasterio) is not installed")
    grid = _grid_with_nodata()
    back = load_dem(save_dem(grid, tmp_path / f"dem{suffix}"))
    np.testing.assert_array_equal(np.isnan(back.z), np.isnan(grid.z))
    np.testing.assert_allclose(back.z, grid.z, equal_nan=True, rtol=1e-15)
    np.testing.assert_allclose(back.xs, grid.xs, rtol=1e-15)
    np.testing.assert_allclose(back.ys, grid.ys, rtol=1e-15)


def test_round_trip_npy_and_rectilinear_npz(tmp_path):
    g = HeightGrid(np.arange(12.0).reshape(3, 4))
    np.testing.assert_array_equal(load_dem(save_dem(g, tmp_path / "a.npy")).z, g.z)
    with pytest.raises(ValueError, match="unit spacing"):
        save_dem(HeightGrid(g.z, dx=2.0), tmp_path / "b.npy")
    r = HeightGrid.from_coords(g.z, [0.0, 1.0, 3.0, 7.0], [0.0, 2.0, 2.5])
    back = load_dem(save_dem(r, tmp_path / "r.npz"))
    np.testing.assert_array_equal(back.xs, r.xs)
    np.testing.assert_array_equal(back.z, r.z)
    with pytest.raises(ValueError, match="uniform grid"):
        save_dem(r, tmp_path / "r.asc")


def test_asc_header_variants(tmp_path):
    p = tmp_path / "corner.asc"
    p.write_text("ncols 3\nnrows 2\nxllcorner 100\nyllcorner 200\ncellsize 10\nNODATA_value -1\n1 2 3\n4 -1 6\n")
    g = load_dem(p)
    np.testing.assert_array_equal(g.xs, [105.0, 115.0, 125.0])
    np.testing.assert_array_equal(g.ys, [205.0, 215.0])
    np.testing.assert_array_equal(g.z, [[4.0, np.nan, 6.0], [1.0, 2.0, 3.0]])


@pytest.mark.parametrize(
    "name, content, match",
    [
        ("short.asc", "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n", "expected 2x3 = 6 values, found 3"),
        ("nocell.asc", "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\n1 2\n3 4\n", "cellsize"),
        ("junk.npz", "this is not a zip file", "could not read 'junk.npz'"),
        ("junk.npy", "not numpy", "could not read 'junk.npy'"),
        ("junk.tif", "not a tiff", "could not read 'junk.tif'"),
    ],
)
def test_corrupt_files(tmp_path, name, content, match):
    if name.endswith(".tif"):
        pytest.importorskip("rasterio", reason="the geo extra (rasterio) is not installed")
    p = tmp_path / name
    p.write_text(content)
    with pytest.raises(ValueError, match=match):
        load_dem(p)


def test_npz_missing_keys(tmp_path):
    p = tmp_path / "nokeys.npz"
    np.savez(p, elevation=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="missing key 'z'"):
        load_dem(p)
    np.savez(p, z=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="missing key 'dx'"):
        load_dem(p)


def test_bad_paths(tmp_path):
    with pytest.raises(ValueError, match=r"path must end in one of .*got 'dem.xyz'"):
        load_dem(tmp_path / "dem.xyz")
    with pytest.raises(FileNotFoundError):
        load_dem(tmp_path / "missing.npz")
    with pytest.raises(TypeError, match="path must be a str or pathlib.Path"):
        load_dem(42)
    with pytest.raises(ValueError, match="path must end in one of"):
        save_dem(HeightGrid(np.zeros((2, 2))), tmp_path / "x.png")


def test_extra_nodata_value(tmp_path):
    p = save_dem(HeightGrid(np.array([[1.0, -5.0], [3.0, 4.0]])), tmp_path / "n.npz")
    assert load_dem(p, nodata=-5.0).n_nodata == 1


# ------------------------------------------------------------------ synthetic
@pytest.mark.parametrize("kind", KINDS)
def test_synthetic_deterministic_and_plausible(kind):
    a = synthetic_terrain(kind, size=64, seed=7)
    np.testing.assert_array_equal(a.z, synthetic_terrain(kind, size=64, seed=7).z)
    assert not np.array_equal(a.z, synthetic_terrain(kind, size=64, seed=8).z)
    relief = a.z.max() - a.z.min()
    assert 100.0 <= relief <= 1500.0  # plausible for a 2 km map with 30 m cells
    gy, gx = np.gradient(a.z, a.dy, a.dx)
    assert np.degrees(np.arctan(np.hypot(gx, gy))).mean() < 45.0


def test_kinds_span_smooth_to_sharp():
    # Mean absolute second difference (curvature) in units of relief: hills smoothest.
    def roughness(g):
        z = (g.z - g.z.min()) / (g.z.max() - g.z.min())
        return np.abs(np.diff(z, 2, axis=1)).mean()

    r = {k: roughness(synthetic_terrain(k)) for k in KINDS}
    assert r["hills"] == min(r.values())
    assert r["rough"] > r["mountains"]


@pytest.mark.parametrize("name", KINDS)
def test_bundled_terrains_match_generator(name):
    g = bundled_terrain(name)
    assert g.shape == (120, 120)
    # Frozen with numpy 2.4/scipy 1.17; the generator must still reproduce them closely.
    np.testing.assert_allclose(g.z, synthetic_terrain(name, size=120, seed=0).z, rtol=0, atol=1e-6)


def test_synthetic_bad_input():
    with pytest.raises(ValueError, match=r"kind must be one of \['hills'"):
        synthetic_terrain("alps")
    with pytest.raises(ValueError, match="size must be >= 2"):
        synthetic_terrain("hills", size=1)
    with pytest.raises(TypeError, match="seed must be an integer"):
        synthetic_terrain("hills", seed=1.5)
    with pytest.raises(ValueError, match="name must be one of the bundled terrains"):
        bundled_terrain("alps")
