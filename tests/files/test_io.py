"""load_terrain / save_terrain / load_dem / save_dem, the .npz format, georeferencing, file faults."""

from __future__ import annotations

import hashlib
import json
import warnings

import numpy as np
import pytest
from conftest import DEM_NAMES, REPO, shared_dem_path

from terrainvis import TIN, HeightGrid, bundled_terrain, load_dem, sample_dem, save_dem, synthetic_terrain
from terrainvis.io import FORMAT_VERSION, load_terrain, metres_per_degree, native_coords, save_terrain
from terrainvis.core.synthetic import KINDS

# Figures from shared/data/dem/README.md: shape, dx, dy, min, max, NaN cells.
SHARED = {
    "jacksboro_fault_tn": ((344, 403), 74.57, 92.47, 236.0, 1076.0, 0),
    "mount_st_helens_wa": ((468, 327), 30.0, 30.0, 682.0, 2543.0, 4151),
    "green_mountains_vt": ((188, 237), 90.0, 90.0, 212.23, 1232.88, 0),
    "west_bijou_escarpment_co": ((67, 129), 23.89, 30.84, 1690.0, 1807.0, 0),
}


def _rasterio():
    return pytest.importorskip("rasterio", reason="the geo extra (rasterio) is not installed")


def assert_attrs_equal(got: dict, want: dict):
    """attrs equal, arrays by value (NaN equal to NaN), ``path`` (set by the readers) ignored."""
    got = {k: v for k, v in got.items() if k != "path"}
    want = {k: v for k, v in want.items() if k != "path"}
    assert sorted(got) == sorted(want)
    for key in want:
        a, b = got[key], want[key]
        if isinstance(b, np.ndarray):
            assert isinstance(a, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, key
            np.testing.assert_array_equal(a, b)
        elif isinstance(b, float) and np.isnan(b):
            assert isinstance(a, float) and np.isnan(a), key
        else:
            assert a == b and type(a) is type(b) or (isinstance(b, np.generic) and a == b), (key, a, b)


def assert_grid_equal(got: HeightGrid, want: HeightGrid, *, attrs: bool = True):
    assert isinstance(got, HeightGrid)
    np.testing.assert_array_equal(got.z, want.z)
    np.testing.assert_array_equal(got.xs, want.xs)
    np.testing.assert_array_equal(got.ys, want.ys)
    if attrs:
        assert_attrs_equal(got.attrs, want.attrs)


def assert_tin_equal(got: TIN, want: TIN, *, attrs: bool = True):
    assert isinstance(got, TIN)
    np.testing.assert_array_equal(got.vertices, want.vertices)
    np.testing.assert_array_equal(got.faces, want.faces)
    if attrs:
        assert_attrs_equal(got.attrs, want.attrs)


def _leftovers(folder):
    """Temporary files an atomic write would leave behind on failure."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


# =================================================================== shared DEMs (old dialect)
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
        assert grid.attrs["crs"] == str(raw["crs"]) and grid.attrs["geographic"] == bool(raw["geographic"])
        # The native coordinates of the samples are the geotransform's cell centres.
        gt = raw["geotransform"]
        x_native, y_native = native_coords(grid)
        rows, cols = grid.shape
        np.testing.assert_allclose(x_native, gt[0] + gt[1] * (np.arange(cols) + 0.5), rtol=0, atol=1e-9 * abs(gt[0]) + 1e-9)
        np.testing.assert_allclose(y_native, gt[3] + gt[5] * (rows - 0.5 - np.arange(rows)), rtol=0, atol=1e-9 * abs(gt[3]))


def test_projected_dem_keeps_crs_coordinates():
    grid = load_dem(shared_dem_path("mount_st_helens_wa"))
    # README: E 557,805 ... 567,615 and N 5,107,965 ... 5,122,005 (cell edges)
    assert grid.xs[0] == pytest.approx(557805 + 15) and grid.xs[-1] == pytest.approx(567615 - 15)
    assert grid.ys[0] == pytest.approx(5107965 + 15) and grid.ys[-1] == pytest.approx(5122005 - 15)
    assert grid.attrs["xy_to_native"] == (1.0, 0.0, 1.0, 0.0)


def test_geotiff_matches_npz():
    _rasterio()
    tif = load_dem(shared_dem_path("green_mountains_vt", ".tif"))
    npz = load_dem(shared_dem_path("green_mountains_vt"))
    np.testing.assert_array_equal(tif.z, npz.z)
    np.testing.assert_allclose(tif.xs, npz.xs)
    np.testing.assert_allclose(tif.ys, npz.ys)
    assert tif.attrs["crs"] == npz.attrs["crs"] == "EPSG:26918"


def test_sample_dem_is_the_shared_jacksboro():
    grid = sample_dem("jacksboro")
    assert grid.dx == pytest.approx(74.57, abs=0.005) and grid.dy == pytest.approx(92.47, abs=0.005)
    shared = load_dem(shared_dem_path("jacksboro_fault_tn"))
    np.testing.assert_array_equal(grid.z, shared.z)
    # Both map back to the same lon/lat: README extent -84.41375 ... -84.07792, 36.44625 ... 36.73292 (edges).
    for g in (grid, shared):
        lon, lat = native_coords(g)
        assert lon[0] == pytest.approx(-84.41375 + 0.5 / 1200, abs=1e-5)
        assert lon[-1] == pytest.approx(-84.07792 - 0.5 / 1200, abs=1e-5)
        assert lat[0] == pytest.approx(36.44625 + 0.5 / 1200, abs=1e-5)
        assert lat[-1] == pytest.approx(36.73292 - 0.5 / 1200, abs=1e-5)
        np.testing.assert_allclose(np.diff(lon), 1 / 1200, rtol=1e-6)
    with pytest.raises(ValueError, match="name must be one of"):
        sample_dem("everest")


def test_metres_per_degree_known_values():
    lon, lat = metres_per_degree(0.0)
    assert lon == pytest.approx(111319.5, abs=1.0) and lat == pytest.approx(110574.3, abs=1.0)
    lon, lat = metres_per_degree(45.0)
    assert lon == pytest.approx(78846.8, abs=1.0) and lat == pytest.approx(111131.7, abs=1.0)


# =================================================================== the bundled terrains
#: SHA-256 of z, xs and ys bytes (float64, HeightGrid order) of the five bundled terrains,
#: the same before and after they were rewritten in the terrainvis format.
BUNDLED_SHA256 = {
    "hills": "4b6980e1b5824a83e8d15dea41d63e3f5efc3aa0d56fdad60a3b3a502e480da7",
    "mountains": "049856b51c3516ea36b560ec9580c50e7ce9ea2d1556753657294ba930fad62f",
    "rough": "2e81fdad68b0560dd68a13375e4fd06666fc8aa588894b0e82aa672be620c404",
    "ridges": "1b031b58751071d77a5d9093b96e1e9987306543c39e79df6ed48dc9eea66d9e",
    "mesas": "358907059fc95a5c7e6196381273b43e111a846440995f6df7d14d34a1a43db5",
}
#: z[0, 0] (south-west corner) and z[119, 7] (north edge) of each bundled terrain.
BUNDLED_VALUES = {
    "hills": (300.1419331326389, 315.35409455454374),
    "mountains": (1579.564292079087, 1255.7436369867214),
    "rough": (762.2465214813468, 749.1036655425231),
    "ridges": (2127.5782970047276, 1510.8930106864186),
    "mesas": (1824.6386163539064, 1880.3263411536673),
}


@pytest.mark.parametrize("name", KINDS)
def test_bundled_files_are_pinned_and_read_one_way(name):
    g = bundled_terrain(name)
    digest = hashlib.sha256(g.z.tobytes() + g.xs.tobytes() + g.ys.tobytes()).hexdigest()
    assert digest == BUNDLED_SHA256[name]
    assert (g.z[0, 0], g.z[119, 7]) == BUNDLED_VALUES[name]
    assert g.attrs == {"name": name, "seed": 0, "synthetic": True, "bundled": True}
    path = REPO / "terrainvis" / "data" / f"{name}.npz"
    # load_dem and load_terrain read the file exactly as bundled_terrain does (not mirrored).
    assert_grid_equal(load_dem(path), g)
    assert_grid_equal(load_terrain(path), g)
    with np.load(path, allow_pickle=False) as raw:
        assert str(raw["format"]) == "terrainvis" and int(raw["format_version"]) == 1
        assert str(raw["kind"]) == "grid" and str(raw["orientation"]) == "y_increasing"
        np.testing.assert_array_equal(raw["z"], g.z)


#: SHA-256 of z, xs and ys bytes (float64, HeightGrid order) of the bundled GeoTIFF cumberland.
CUMBERLAND_SHA256 = "ede7fc391555f780e283deee22e410388f2b8df59a5324e97c1f676694f8a903"


def test_bundled_geotiff_is_pinned_and_georeferenced():
    pytest.importorskip("rasterio", reason="the bundled GeoTIFF is read with rasterio (the geo extra)")
    from terrainvis.io._names import resolve_one

    g = bundled_terrain("cumberland")
    digest = hashlib.sha256(g.z.tobytes() + g.xs.tobytes() + g.ys.tobytes()).hexdigest()
    assert digest == CUMBERLAND_SHA256
    assert g.shape == (337, 321) and (g.dx, g.dy) == (90.0, 90.0) and g.attrs["crs"] == "EPSG:26916"
    assert (g.xs[0], g.ys[-1]) == (731925.0, 4068045.0)  # sample centres: corners on whole multiples of 90 m
    assert np.isfinite(g.z).all()
    # sizes 16 k + 1: the coarse grids of levels 1-4 keep samples of the DEM's own grid
    assert all((n - 1) % 16 == 0 for n in g.shape)
    name, same = resolve_one(None, "cumberland", 0)
    assert name == "cumberland"
    assert_grid_equal(same, g)


@pytest.mark.parametrize("seed", range(4))
def test_the_largest_valid_rectangle_of_a_footprint_against_brute_force(seed):
    """make_bundled's cut of the warped footprint: a rotated rectangle's largest all-valid
    rectangle, against every rectangle of the mask; and the 16 k + 1 fit, by hand."""
    from terrainvis.data.make_bundled import _fit_levels, _largest_valid_rectangle

    rng = np.random.default_rng(seed)
    angle, (h, w) = rng.uniform(-0.3, 0.3), rng.integers(6, 14, 2)
    rr, cc = np.mgrid[0:20, 0:20] - 9.5
    u, v = np.cos(angle) * cc + np.sin(angle) * rr, -np.sin(angle) * cc + np.cos(angle) * rr
    valid = (np.abs(u) <= w / 2) & (np.abs(v) <= h / 2)
    r0, r1, c0, c1 = _largest_valid_rectangle(valid)
    assert valid[r0:r1 + 1, c0:c1 + 1].all()
    best = max((b - a + 1) * (d - c + 1) for a in range(20) for b in range(a, 20) for c in range(20)
               for d in range(c, 20) if valid[a:b + 1, c:d + 1].all())
    assert (r1 - r0 + 1) * (c1 - c0 + 1) == best
    assert _fit_levels(3, 346) == (3 + 3, 3 + 3 + 336)  # 344 samples -> 337 = 21 * 16 + 1, centred
    assert _fit_levels(0, 16) == (0, 16) and _fit_levels(0, 17) == (0, 16)


def test_bundled_geotiff_is_the_source_interpolated_bilinearly():
    """Each sample is matplotlib's lon/lat DEM interpolated bilinearly (by hand here) at the
    sample's position taken to NAD83, to float32 rounding."""
    pytest.importorskip("rasterio", reason="the bundled GeoTIFF is read with rasterio (the geo extra)")
    from rasterio.warp import transform

    from terrainvis.data.make_bundled import cumberland_source

    g = bundled_terrain("cumberland")
    z, lon, lat = cumberland_source()  # rows north to south, sample centres
    rng = np.random.default_rng(7)
    r, c = rng.integers(0, g.shape[0], 300), rng.integers(0, g.shape[1], 300)
    lons, lats = map(np.asarray, transform("EPSG:26916", "EPSG:4269", g.xs[c], g.ys[r]))
    fc = (lons - lon[0]) / (lon[1] - lon[0])
    fr = (lats - lat[0]) / (lat[1] - lat[0])
    c0, r0 = np.floor(fc).astype(int), np.floor(fr).astype(int)
    tc, tr = fc - c0, fr - r0
    expected = ((1 - tr) * ((1 - tc) * z[r0, c0] + tc * z[r0, c0 + 1])
                + tr * ((1 - tc) * z[r0 + 1, c0] + tc * z[r0 + 1, c0 + 1]))
    np.testing.assert_allclose(g.z[r, c], expected, rtol=0, atol=1e-3)


@pytest.mark.parametrize("name", KINDS)
def test_bundled_terrains_match_generator(name):
    g = bundled_terrain(name)
    assert g.shape == (120, 120)
    # Frozen with numpy 2.4/scipy 1.17; the generator must still reproduce them closely.
    np.testing.assert_allclose(g.z, synthetic_terrain(name, size=120, seed=0).z, rtol=0, atol=1e-6)


# =================================================================== the .npz format
def _rich_attrs():
    return {
        "name": "x", "flag": True, "count": 7, "big": 2**62, "ratio": 0.1 + 0.2, "missing": None,
        "nan": float("nan"), "inf": float("inf"), "shape": (3, 4), "nested": {"a": [1, (2.5, "b")], "c": {"d": None}},
        "list": [1, "two", 3.0], "arr": np.array([[1.5, np.nan], [3.0, -0.0]]), "ints": np.arange(4, dtype=np.int32),
        "mask": np.array([True, False]), "text": "ünïcode\nnewline",
    }


def test_npz_grid_round_trip_exact_rectilinear_nodata_and_attrs(tmp_path):
    z = np.random.default_rng(1).normal(100, 30, (4, 5))
    z[1, 2] = np.nan
    g = HeightGrid.from_coords(z, [0.0, 1.0, 3.5, 7.0, 7.25], [-5.0, 0.1, 0.2, 1e3], attrs=_rich_attrs())
    p = save_terrain(g, tmp_path / "g.npz")
    back = load_terrain(p)
    assert_grid_equal(back, g)
    assert back.attrs["path"] == str(p)
    # Numpy scalars are written as Python numbers (equal values).
    g2 = HeightGrid(z, attrs={"f": np.float64(2.5), "i": np.int16(3), "b": np.bool_(True)})
    back2 = load_terrain(save_terrain(g2, tmp_path / "g2.npz"))
    assert back2.attrs["f"] == 2.5 and back2.attrs["i"] == 3 and back2.attrs["b"] is True


def test_npz_layout_is_explicit(tmp_path):
    g = HeightGrid(np.arange(6.0).reshape(2, 3), dx=2.0, origin=(10.0, 20.0), attrs={"k": (1, 2)})
    with np.load(save_terrain(g, tmp_path / "g.npz"), allow_pickle=False) as raw:
        assert sorted(raw.files) == ["attrs", "format", "format_version", "kind", "orientation", "xs", "ys", "z"]
        assert str(raw["format"]) == "terrainvis" and int(raw["format_version"]) == FORMAT_VERSION == 1
        assert str(raw["kind"]) == "grid" and str(raw["orientation"]) == "y_increasing"
        np.testing.assert_array_equal(raw["z"], g.z)  # HeightGrid order: row 0 is the smallest y
        np.testing.assert_array_equal(raw["ys"], [20.0, 21.0])
        assert json.loads(str(raw["attrs"])) == {"k": {"__tuple__": [1, 2]}}
    tin = g.to_tin()
    with np.load(save_terrain(tin, tmp_path / "t.npz"), allow_pickle=False) as raw:
        assert sorted(raw.files) == ["attrs", "faces", "format", "format_version", "kind", "orientation", "vertices"]
        assert str(raw["kind"]) == "tin" and str(raw["orientation"]) == "z_up_ccw"


def test_npz_tin_round_trip(tmp_path):
    tin = synthetic_terrain("ridges", size=9).to_tin()
    t = TIN(tin.vertices, tin.faces, attrs=_rich_attrs())
    assert_tin_equal(load_terrain(save_terrain(t, tmp_path / "t.npz")), t)
    with pytest.raises(ValueError, match="holds a TIN, not a grid"):
        load_dem(tmp_path / "t.npz")


def test_npz_reads_y_decreasing_orientation(tmp_path):
    # Another writer may store raster order; the file says so, and the reader flips it.
    g = HeightGrid(np.arange(6.0).reshape(2, 3), dx=1.0, dy=5.0)
    np.savez(
        tmp_path / "r.npz", format="terrainvis", format_version=1, kind="grid", orientation="y_decreasing",
        z=g.z[::-1], xs=g.xs, ys=g.ys[::-1], attrs="{}",
    )
    assert_grid_equal(load_terrain(tmp_path / "r.npz"), g, attrs=False)


def test_unencodable_attrs_are_dropped_with_a_warning(tmp_path):
    g = HeightGrid(np.zeros((2, 2)), attrs={"ok": 1, "obj": object(), "keys": {1: "a"}, "cplx": np.array([1j])})
    with pytest.warns(UserWarning) as record:
        back = load_terrain(save_terrain(g, tmp_path / "g.npz"))
    messages = " | ".join(str(w.message) for w in record)
    assert "attrs['obj'] is a object" in messages and "non-string key 1" in messages and "attrs['cplx']" in messages
    assert_attrs_equal(back.attrs, {"ok": 1})


@pytest.mark.parametrize(
    "arrays, match",
    [
        ({"format": "terrainvis", "format_version": 2, "kind": "grid", "orientation": "y_increasing", "attrs": "{}",
          "z": np.zeros((2, 2)), "xs": np.arange(2.0), "ys": np.arange(2.0)},
         r"newer terrainvis \(format version 2; this one reads up to 1\)"),
        ({"format": "other", "format_version": 1}, "format' is 'other', not 'terrainvis'"),
        ({"format": "terrainvis", "format_version": 1, "kind": "grid", "orientation": "sideways", "attrs": "{}",
          "z": np.zeros((2, 2)), "xs": np.arange(2.0), "ys": np.arange(2.0)}, "orientation must be one of"),
        ({"format": "terrainvis", "format_version": 1, "kind": "mesh", "orientation": "z_up_ccw", "attrs": "{}"},
         "kind must be 'grid' or 'tin', got 'mesh'"),
        ({"format": "terrainvis", "format_version": 1, "kind": "grid", "orientation": "y_increasing",
          "attrs": "{not json", "z": np.zeros((2, 2)), "xs": np.arange(2.0), "ys": np.arange(2.0)}, "not valid JSON"),
        ({"format": "terrainvis", "format_version": 1, "kind": "grid", "orientation": "y_increasing", "attrs": "{}",
          "z": np.zeros((2, 2))}, r"a grid needs the keys \['z', 'xs', 'ys'\]"),
        ({"z": np.zeros((3, 3))}, "no coordinates: neither 'dx'/'dy'"),
        ({"elevation": np.zeros((3, 3))}, "neither a grid"),
        ({"z": np.zeros((3, 3)), "vertices": np.zeros((3, 3)), "faces": np.zeros((1, 3), int)}, "both a grid"),
        ({"z": np.zeros((3, 3)), "dx": 1.0}, r"needs the keys \['dx', 'dy'\], but \['dy'\] are missing"),
        ({"z": np.zeros((3, 3)), "xs": np.arange(3.0)}, r"\['ys'\] are missing"),
        ({"z": np.zeros((3, 3)), "dx": 2.0, "dy": 1.0, "xs": np.arange(3.0), "ys": np.arange(3.0)},
         "dx = 2.0 disagrees with the mean spacing 1.0 of xs"),
        ({"z": np.zeros((3, 3)), "xs": np.arange(3.0), "ys": np.arange(3.0), "kind": "tin"}, "'kind' is 'tin'"),
        ({"vertices": np.zeros((3, 3)), "faces": np.zeros((1, 3), int), "kind": "grid"}, "'kind' is 'grid'"),
    ],
)
def test_npz_ambiguous_or_inconsistent_files_are_refused(tmp_path, arrays, match):
    p = tmp_path / "bad.npz"
    np.savez(p, **arrays)
    with pytest.raises(ValueError, match=match):
        load_terrain(p)


def test_npz_older_dialects(tmp_path):
    g = HeightGrid.from_coords(np.arange(12.0).reshape(3, 4) ** 1.5, [0.0, 1.0, 3.0, 7.0], [10.0, 12.0, 12.5])
    # The bundled / save_simplified dialect: z in HeightGrid order with xs, ys (kind optional).
    np.savez(tmp_path / "a.npz", z=g.z, xs=g.xs, ys=g.ys)
    np.savez(tmp_path / "b.npz", kind="grid", z=g.z, xs=g.xs, ys=g.ys)
    # The same with descending coordinates: z[r, c] at (xs[c], ys[r]) still holds.
    np.savez(tmp_path / "c.npz", z=g.z[::-1, ::-1], xs=g.xs[::-1], ys=g.ys[::-1])
    # The former save_dem dialect: north-up z with dx, dy (mean spacing), xs, ys.
    np.savez(tmp_path / "d.npz", z=g.z[::-1], dx=g.dx, dy=g.dy, xs=g.xs, ys=g.ys, geographic=False, crs="EPSG:32633")
    for name in "abcd":
        assert_grid_equal(load_dem(tmp_path / f"{name}.npz"), g, attrs=False)
    assert load_dem(tmp_path / "d.npz").attrs["crs"] == "EPSG:32633"
    tin = g.to_tin()
    np.savez(tmp_path / "t.npz", kind="tin", vertices=tin.vertices, faces=tin.faces)
    assert_tin_equal(load_terrain(tmp_path / "t.npz"), tin, attrs=False)


def test_former_save_simplified_dialect(tmp_path):
    # experiment.save_simplified used to write kind + z, xs, ys (HeightGrid order) or kind + vertices, faces.
    from simplifiers import simplify

    g = synthetic_terrain("mesas", size=20)
    for terrain in (simplify(g, "lls", 1), simplify(g, "greedy-insertion", 1)):
        p = tmp_path / "s.npz"
        if isinstance(terrain, HeightGrid):
            assert not terrain.is_uniform  # even size: the last gap is 3 fine cells wide
            np.savez_compressed(p, kind="grid", z=terrain.z, xs=terrain.xs, ys=terrain.ys)
            assert_grid_equal(load_terrain(p), terrain, attrs=False)
        else:
            np.savez_compressed(p, kind="tin", vertices=terrain.vertices, faces=terrain.faces)
            assert_tin_equal(load_terrain(p), terrain, attrs=False)


# =================================================================== corrupt files
@pytest.mark.parametrize(
    "name, content, match",
    [
        ("short.asc", "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n", "expected 2x3 = 6 values, found 3"),
        ("nocell.asc", "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\n1 2\n3 4\n", "cellsize"),
        ("frac.asc", "ncols 3.7\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n4 5 6\n",
         "ncols must be a whole number >= 2, got 3.7"),
        ("word.asc", "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 x\n", "not all numbers"),
        ("junk.npz", "this is not a zip file", r"could not read 'junk.npz' as a .npz file: it is not a .npz file .*b'this is "),
        ("junk.npy", "not numpy", "could not read 'junk.npy'"),
        ("junk.tif", "not a tiff", "could not read 'junk.tif'"),
        ("junk.ply", "not a mesh", "could not read 'junk.ply'"),
    ],
)
def test_corrupt_files(tmp_path, name, content, match):
    if name.endswith(".tif"):
        _rasterio()
    p = tmp_path / name
    p.write_text(content)
    with pytest.raises(ValueError, match=match) as info:
        load_terrain(p)
    assert "allow_pickle" not in str(info.value)


def test_truncated_and_damaged_npz_give_value_errors(tmp_path):
    good = save_dem(HeightGrid(np.random.default_rng(0).normal(size=(40, 40))), tmp_path / "good.npz")
    data = good.read_bytes()
    (tmp_path / "trunc.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="could not read 'trunc.npz'.*truncated or corrupt"):
        load_dem(tmp_path / "trunc.npz")
    damaged = bytearray(data)
    mid = len(damaged) // 2
    damaged[mid : mid + 64] = bytes(64)  # zeros in the middle of the compressed z
    (tmp_path / "damaged.npz").write_bytes(bytes(damaged))
    with pytest.raises(ValueError, match="could not read 'damaged.npz'.*truncated or corrupt"):
        load_dem(tmp_path / "damaged.npz")
    np.save(tmp_path / "array.npy", np.zeros((3, 3)))
    (tmp_path / "array.npz").write_bytes((tmp_path / "array.npy").read_bytes())
    with pytest.raises(ValueError, match="it is a .npy file"):
        load_dem(tmp_path / "array.npz")
    np.savez(tmp_path / "obj.npz", z=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ValueError, match="object array, which only pickle can read"):
        load_dem(tmp_path / "obj.npz")


def test_bad_paths_and_arguments(tmp_path):
    with pytest.raises(ValueError, match=r"path must end in one of .*got 'dem.xyz'"):
        load_dem(tmp_path / "dem.xyz")
    with pytest.raises(ValueError, match=r"path must end in one of \['.npz', '.npy', '.asc', '.tif', '.tiff'\]"):
        load_dem(tmp_path / "dem.ply")
    with pytest.raises(FileNotFoundError):
        load_dem(tmp_path / "missing.npz")
    with pytest.raises(TypeError, match="path must be a str or pathlib.Path"):
        load_dem(42)
    with pytest.raises(ValueError, match="path must end in one of"):
        save_dem(HeightGrid(np.zeros((2, 2))), tmp_path / "x.png")
    (tmp_path / "d.npz").mkdir()
    with pytest.raises(ValueError, match="is a folder"):
        load_dem(tmp_path / "d.npz")
    with pytest.raises(ValueError, match="is a folder"):
        save_dem(HeightGrid(np.zeros((2, 2))), tmp_path / "d.npz")
    p = save_dem(HeightGrid(np.zeros((2, 2))), tmp_path / "ok.npz")
    with pytest.raises(TypeError, match=r"nodata must be a real number .*got str 'x'"):
        load_dem(p, nodata="x")
    with pytest.raises(TypeError, match="nodata must be a real number"):
        load_dem(p, nodata=True)
    with pytest.raises(ValueError, match="nodata must not be NaN"):
        load_dem(p, nodata=float("nan"))
    with pytest.raises(TypeError, match="crs must be a CRS string"):
        load_dem(p, crs=4326)
    if _has_rasterio():
        with pytest.raises(ValueError, match="crs 'lon/lat please' is not a CRS rasterio can read"):
            load_dem(p, crs="lon/lat please")
    with pytest.raises(ValueError, match="band applies to GeoTIFF files"):
        load_dem(p, band=1)
    with pytest.raises(TypeError, match="grid must be a terrainvis.HeightGrid"):
        save_dem(HeightGrid(np.zeros((2, 2))).to_tin(), tmp_path / "t.npz")
    with pytest.raises(TypeError, match="terrain must be a terrainvis.HeightGrid or terrainvis.TIN"):
        save_terrain(np.zeros((2, 2)), tmp_path / "t.npz")
    with pytest.raises(ValueError, match=r"a TIN is written to a raster \(.asc\) by sampling its surface on a grid: "
                                         r"pass like=<the grid>"):
        save_terrain(HeightGrid(np.zeros((2, 2))).to_tin(), tmp_path / "t.asc")


def test_upper_case_suffix_is_written_where_asked(tmp_path):
    g = HeightGrid(np.arange(4.0).reshape(2, 2))
    for name in ("x.NPZ", "y.Npy", "z.ASC"):
        p = save_dem(g, tmp_path / name)
        assert p == tmp_path / name and p.exists()
        assert_grid_equal(load_dem(p), g, attrs=False)
    assert sorted(q.name for q in tmp_path.iterdir()) == ["x.NPZ", "y.Npy", "z.ASC"]


def test_extra_nodata_value(tmp_path):
    p = save_dem(HeightGrid(np.array([[1.0, -5.0], [3.0, 4.0]])), tmp_path / "n.npz")
    assert load_dem(p, nodata=-5.0).n_nodata == 1
    assert load_dem(p, nodata=-5).n_nodata == 1


# =================================================================== rasters
def _grid_with_nodata():
    rng = np.random.default_rng(0)
    z = rng.normal(500, 50, (7, 9))
    z[2, 3] = np.nan
    return HeightGrid(z, dx=30.0, dy=25.0, origin=(560000.0, 5.1e6), attrs={"crs": "EPSG:32610", "name": "n"})


@pytest.mark.parametrize("suffix", [".npz", ".asc", ".tif"])
def test_round_trip(tmp_path, suffix):
    if suffix != ".npz":
        _rasterio()  # .tif, and the .prj of .asc
    grid = _grid_with_nodata()
    back = load_dem(save_dem(grid, tmp_path / f"dem{suffix}"))
    if suffix == ".tif":
        import rasterio

        with rasterio.open(tmp_path / "dem.tif") as src:
            # Exactly the grid's own coordinates: corner half a cell out, north-up.
            assert src.crs.to_epsg() == 32610
            assert tuple(src.transform)[:6] == (30.0, 0.0, 560000.0 - 15.0, 0.0, -25.0, 5.1e6 + 6 * 25.0 + 12.5)
            cx, cy = rasterio.transform.xy(src.transform, [6] * 9, list(range(9)))
            np.testing.assert_array_equal(cx, grid.xs)
            assert set(cy) == {grid.ys[0]}
    assert_grid_equal(back, grid, attrs=False)
    assert back.attrs["crs"] == "EPSG:32610"
    if suffix != ".asc":  # ESRI ASCII grids hold no other metadata
        want = dict(grid.attrs)
        if suffix == ".tif":  # the file's georeferencing, and its cells as stored
            want.update(geographic=False, xy_to_native=(1.0, 0.0, 1.0, 0.0),
                        native_lattice=(560000.0 - 15.0, 30.0, 5.1e6 + 6 * 25.0 + 12.5, 25.0))
        assert_attrs_equal(back.attrs, want)


def test_round_trip_npy_and_rectilinear_npz(tmp_path):
    g = HeightGrid(np.arange(12.0).reshape(3, 4))
    np.testing.assert_array_equal(load_dem(save_dem(g, tmp_path / "a.npy")).z, g.z)
    with pytest.raises(ValueError, match="unit spacing"):
        save_dem(HeightGrid(g.z, dx=2.0), tmp_path / "b.npy")
    r = HeightGrid.from_coords(g.z, [0.0, 1.0, 3.0, 7.0], [0.0, 2.0, 2.5])
    assert_grid_equal(load_dem(save_dem(r, tmp_path / "r.npz")), r)


def test_asc_header_variants(tmp_path):
    p = tmp_path / "corner.asc"
    p.write_text("ncols 3\nnrows 2\nxllcorner 100\nyllcorner 200\ncellsize 10\nNODATA_value -1\n1 2 3\n4 -1 6\n")
    g = load_dem(p)
    np.testing.assert_array_equal(g.xs, [105.0, 115.0, 125.0])
    np.testing.assert_array_equal(g.ys, [205.0, 215.0])
    np.testing.assert_array_equal(g.z, [[4.0, np.nan, 6.0], [1.0, 2.0, 3.0]])
    p.write_text("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ndx 2\ndy 3\nNODATA_value -9999\n-9999 2\n3 4\n")
    g = load_dem(p)  # files that use -9999 for nodata keep working
    np.testing.assert_array_equal(g.z, [[3.0, 4.0], [np.nan, 2.0]])
    np.testing.assert_array_equal(g.ys, [0.0, 3.0])


def test_real_minus_9999_heights_survive_asc_and_tif(tmp_path):
    _rasterio()
    z = np.array([[-9999.0, 1.0, 2.0], [3.0, np.nan, -32768.0]])
    g = HeightGrid(z, dx=10.0, dy=10.0, origin=(1000.0, 2000.0))
    for suffix in (".asc", ".tif"):
        p = save_dem(g, tmp_path / f"m{suffix}")
        back = load_dem(p)
        np.testing.assert_array_equal(back.z, g.z)  # -9999 and -32768 stay heights, NaN stays nodata
    assert "NODATA_value -99999.0" in (tmp_path / "m.asc").read_text()
    import rasterio

    with rasterio.open(tmp_path / "m.tif") as src:
        assert src.nodata == -99999.0
    # When every usual nodata value is a real height, float32's lowest value (never a height) is used.
    z = np.array([[-9999.0, -32768.0], [-99999.0, np.nan]])
    back = load_dem(save_dem(HeightGrid(z), tmp_path / "all.asc"))
    np.testing.assert_array_equal(back.z, z)
    assert "NODATA_value -3.4028234663852886e+38" in (tmp_path / "all.asc").read_text()


def test_geotiff_scale_and_offset_are_applied(tmp_path):
    rasterio = _rasterio()
    from rasterio.transform import Affine

    raw = np.array([[0, 100, 190], [10, 20, -1]], dtype=np.int16)
    p = tmp_path / "scaled.tif"
    with rasterio.open(p, "w", driver="GTiff", height=2, width=3, count=1, dtype="int16", nodata=-1,
                       transform=Affine(10, 0, 500000, 0, -10, 4000020), crs="EPSG:32633") as dst:
        dst.write(raw, 1)
        dst.scales = (0.1,)
        dst.offsets = (100.0,)
    g = load_dem(p)
    np.testing.assert_allclose(g.z, [[101.0, 102.0, np.nan], [100.0, 110.0, 119.0]], rtol=0, atol=1e-12)
    assert np.nanmin(g.z) == pytest.approx(100.0) and np.nanmax(g.z) == pytest.approx(119.0)


def test_multi_band_geotiff_needs_a_band(tmp_path):
    rasterio = _rasterio()
    from rasterio.transform import Affine

    p = tmp_path / "two.tif"
    with rasterio.open(p, "w", driver="GTiff", height=2, width=2, count=2, dtype="float64",
                       transform=Affine(10, 0, 0, 0, -10, 20), crs="EPSG:32633") as dst:
        dst.write(np.ones((2, 2)), 1)
        dst.write(np.full((2, 2), 2.0), 2)
    with pytest.raises(ValueError, match=r"'two.tif' has 2 bands; a DEM has one: pass band=k \(1..2\)"):
        load_dem(p)
    assert (load_dem(p, band=2).z == 2.0).all() and (load_dem(p, band=1).z == 1.0).all()
    with pytest.raises(ValueError, match=r"band must be in \[1, 2\] for 'two.tif', got 3"):
        load_dem(p, band=3)
    with pytest.raises(ValueError, match="band must be >= 1"):
        load_dem(p, band=0)


def test_degree_coordinates_without_crs_warn_and_crs_converts(tmp_path):
    # west_bijou_escarpment_snippet.asc: lon/lat with 1-arc-second cells and no CRS.
    cell = 1 / 3600
    text = (f"ncols 4\nnrows 3\nxllcorner -104.341806\nyllcorner 39.505972\ncellsize {cell!r}\n"
            "NODATA_value -32768\n1 2 3 4\n5 6 7 8\n9 10 11 12\n")
    p = tmp_path / "bijou.asc"
    p.write_text(text)
    with pytest.warns(UserWarning, match=r"records no CRS, but its coordinates look like lon/lat degrees.*crs='EPSG:4326'"):
        g = load_dem(p)
    assert g.dx == pytest.approx(cell)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        c = load_dem(p, crs="EPSG:4326")
        # Metres per arc-second at 39.5 deg N (shared README: 23.89 x 30.84 m).
        assert c.dx == pytest.approx(23.89, abs=0.01) and c.dy == pytest.approx(30.84, abs=0.01)
        assert c.xs[0] == 0.0 and c.ys[0] == 0.0 and c.attrs["geographic"] is True
        lon, lat = native_coords(c)
        np.testing.assert_allclose(lon, g.xs, rtol=0, atol=1e-12)
        np.testing.assert_allclose(lat, g.ys, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(c.z, g.z)
        # Metre coordinates do not warn.
        (tmp_path / "m.asc").write_text(text.replace("-104.341806", "500000").replace("39.505972", "4000000"))
        load_dem(tmp_path / "m.asc")
    # A .prj beside the .asc names the CRS: converted, no warning.
    pytest.importorskip("rasterio", reason="the geo extra (rasterio) is not installed")
    from rasterio.crs import CRS

    (tmp_path / "bijou.prj").write_text(CRS.from_epsg(4326).to_wkt(version="WKT1_ESRI"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        withprj = load_dem(p)
    assert_grid_equal(withprj, c, attrs=False)
    assert withprj.attrs["crs"] == "EPSG:4326"
    with pytest.raises(ValueError, match="records the CRS 'EPSG:4326'; crs= is only for files that record none"):
        load_dem(p, crs="EPSG:32613")


def test_geotiff_without_crs_in_degrees_warns(tmp_path):
    rasterio = _rasterio()
    from rasterio.transform import Affine

    p = tmp_path / "nocrs.tif"
    with rasterio.open(p, "w", driver="GTiff", height=3, width=3, count=1, dtype="float64",
                       transform=Affine(1 / 1200, 0, -84.4, 0, -1 / 1200, 36.7)) as dst:
        dst.write(np.arange(9.0).reshape(3, 3), 1)
    with pytest.warns(UserWarning, match="look like lon/lat degrees"):
        load_dem(p)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g = load_dem(p, crs="EPSG:4326")
    assert g.dx == pytest.approx(metres_per_degree(36.7 - 1.5 / 1200)[0] / 1200)


# ------------------------------------------------------------------- GeoTIFF georeferencing
def test_geographic_grid_is_written_in_lon_lat(tmp_path):
    rasterio = _rasterio()
    g = load_dem(shared_dem_path("jacksboro_fault_tn")).crop(rows=(10, 41), cols=(20, 61))
    p = save_dem(g, tmp_path / "j.tif")
    with np.load(shared_dem_path("jacksboro_fault_tn")) as raw:
        gt = raw["geotransform"]
        rows_total = raw["z"].shape[0]
    with rasterio.open(p) as src:
        assert src.crs.to_epsg() == 4326
        t = src.transform
        # Three arc-seconds, and the corner of the cropped window in the shared file's own geotransform.
        assert t.a == pytest.approx(gt[1], rel=1e-12) and t.e == pytest.approx(gt[5], rel=1e-12)
        assert t.c == pytest.approx(gt[0] + 20 * gt[1], abs=1e-10)
        assert t.f == pytest.approx(gt[3] + (rows_total - 41) * gt[5], abs=1e-10)
        np.testing.assert_array_equal(src.read(1), g.z[::-1].astype(np.float64))
    back = load_dem(p)
    np.testing.assert_array_equal(back.z, g.z)
    # Local metres restart at the crop's corner and use the crop's centre latitude.
    assert back.xs[0] == 0.0 and back.dx == pytest.approx(g.dx, rel=5e-3) and back.dy == pytest.approx(g.dy, rel=1e-4)
    assert back.attrs["crs"] == "EPSG:4326 (assumed; lon/lat degrees)"  # the remark is kept
    for a, b in zip(native_coords(back), native_coords(g)):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_unparseable_crs_fails_before_writing(tmp_path):
    _rasterio()
    good = tmp_path / "keep.tif"
    good.write_bytes(b"precious bytes")
    g = HeightGrid(np.ones((4, 4)), attrs={"crs": "my favourite projection"})
    with pytest.raises(ValueError, match=r"grid.attrs\['crs'\] 'my favourite projection' is not a CRS rasterio can read"):
        save_dem(g, good)
    assert good.read_bytes() == b"precious bytes"
    with pytest.raises(ValueError, match="is not a CRS rasterio can read"):
        save_dem(g, tmp_path / "keep.asc")
    assert sorted(q.name for q in tmp_path.iterdir()) == ["keep.tif"]


def _green_mountains_odd():
    _rasterio()
    g = load_dem(shared_dem_path("green_mountains_vt", ".tif"))
    return g, g.crop(rows=(20, 121), cols=(30, 161))  # 101 x 131: odd sizes


def test_simplified_odd_grid_overlays_the_original_geotiff(tmp_path):
    rasterio = _rasterio()
    from simplifiers import simplify

    full, g = _green_mountains_odd()
    s = simplify(g, "lls", 1)
    assert s.shape == (51, 66) and s.is_uniform and s.attrs["crs"] == "EPSG:26918"
    p = save_dem(s, tmp_path / "s.tif")
    with rasterio.open(p) as src, rasterio.open(shared_dem_path("green_mountains_vt", ".tif")) as orig:
        assert src.crs == orig.crs
        t, o = src.transform, orig.transform
        assert (t.a, t.e) == (2 * o.a, 2 * o.e)  # exactly 180 m cells
        rows, cols = np.meshgrid(np.arange(src.height), np.arange(src.width), indexing="ij")
        xs, ys = rasterio.transform.xy(t, rows.ravel(), cols.ravel())
        xs, ys = np.asarray(xs).reshape(rows.shape), np.asarray(ys).reshape(rows.shape)
        np.testing.assert_allclose(xs[0], s.xs, rtol=0, atol=1e-6)
        np.testing.assert_allclose(ys[:, 0], s.ys[::-1], rtol=0, atol=1e-6)
        # Every coarse sample sits on a sample of the original raster: rows 20 + 2k (south-up) etc.
        orig_r, orig_c = rasterio.transform.rowcol(o, xs.ravel(), ys.ravel(), op=lambda v: v)
        orig_r = np.asarray(orig_r).reshape(rows.shape)
        orig_c = np.asarray(orig_c).reshape(rows.shape)
        np.testing.assert_allclose(orig_c - 0.5, 30 + 2 * cols, rtol=0, atol=1e-9)
        np.testing.assert_allclose(orig_r - 0.5, (orig.height - 1 - 20) - 2 * rows[::-1], rtol=0, atol=1e-9)
        np.testing.assert_array_equal(src.read(1), s.z[::-1])
    # "simple" keeps the original heights, so the rasters agree where they overlap.
    p2 = save_dem(simplify(g, "simple", 1), tmp_path / "simple.tif")
    with rasterio.open(p2) as src, rasterio.open(shared_dem_path("green_mountains_vt", ".tif")) as orig:
        window = orig.read(1)[orig.height - 1 - 120 : orig.height - 20 : 2, 30:161:2]
        np.testing.assert_array_equal(src.read(1), window.astype(np.float64))
    back = load_dem(p)
    assert_grid_equal(back, s, attrs=False)


def test_even_simplified_grid_is_resampled_with_a_warning(tmp_path):
    rasterio = _rasterio()
    from simplifiers import simplify

    full, _ = _green_mountains_odd()
    g = full.crop(rows=(0, 120), cols=(0, 120))
    s = simplify(g, "lls", 1)  # 60 x 60, last gap 3 fine cells (270 m) wide
    assert not s.is_uniform
    # Uniform spacing over the same extent is 10710 m / 59 = 181.525 m: sample 58 moves by 58 * 1.525 m.
    with pytest.warns(UserWarning, match=r"resampled .*moved 58 of 60 x positions by up to 88.4746 \(0.487 cell\)") as rec:
        p = save_dem(s, tmp_path / "even.tif")
    assert "y positions" in str(rec[0].message)
    with rasterio.open(p) as src:
        note = src.tags()["TERRAINVIS_RESAMPLED"]
        assert "moved" in note and src.crs.to_epsg() == 26918
        t = src.transform
        assert t.a == pytest.approx((s.xs[-1] - s.xs[0]) / 59, rel=1e-15)
        assert t.c + 0.5 * t.a == pytest.approx(s.xs[0], abs=1e-6)  # same sample extent
        assert t.c + (59 + 0.5) * t.a == pytest.approx(s.xs[-1], abs=1e-6)
        ux = np.linspace(s.xs[0], s.xs[-1], 60)
        uy = np.linspace(s.ys[0], s.ys[-1], 60)
        np.testing.assert_allclose(src.read(1)[::-1], s.height_on_grid(ux, uy), rtol=0, atol=1e-9)
    back = load_dem(p)
    assert back.attrs["resampled"] == note
    # The first sample and every one whose position did not move keep their height exactly.
    kept_x = np.abs(ux - s.xs) < 1e-6
    kept_y = np.abs(uy - s.ys) < 1e-6
    np.testing.assert_array_equal(back.z[np.ix_(kept_y, kept_x)], s.z[np.ix_(kept_y, kept_x)])
    with pytest.warns(UserWarning, match="resampled"):
        save_dem(s, tmp_path / "even.asc")


def test_georeferencing_survives_crop_subsample_fill_and_simplify():
    from simplifiers import simplify

    g = load_dem(shared_dem_path("mount_st_helens_wa"))
    keys = {k: g.attrs[k] for k in ("crs", "geographic", "xy_to_native")}
    rs, cs = g.valid_window()
    out = [g.crop(rows=(5, 60), cols=(7, 90)), g.subsample(3), g.fill_nodata()]
    filled = g.crop(rs, cs)
    out += [simplify(filled, m, 2) for m in ("simple", "gls", "lls", "feature")]
    for grid in out:
        assert {k: grid.attrs[k] for k in keys} == keys
        np.testing.assert_array_equal(native_coords(grid)[0], grid.xs)  # projected: native = own coordinates
    j = load_dem(shared_dem_path("jacksboro_fault_tn"))
    c = simplify(j.crop(rows=(1, 100), cols=(2, 101)), "lls", 1)
    lon_c, lat_c = native_coords(c)
    lon, lat = native_coords(j)
    np.testing.assert_allclose(lon_c, lon[2:101:2], rtol=0, atol=1e-11)
    np.testing.assert_allclose(lat_c, lat[1:100:2], rtol=0, atol=1e-11)


def test_native_coords_errors():
    g = HeightGrid(np.zeros((2, 2)), attrs={"geographic": True})
    with pytest.raises(ValueError, match="hold no 'xy_to_native'"):
        native_coords(g)
    with pytest.raises(ValueError, match=r"attrs\['xy_to_native'\] must be four numbers"):
        native_coords(HeightGrid(np.zeros((2, 2)), attrs={"xy_to_native": "x"}))
    with pytest.raises(ValueError, match="sx > 0 and sy > 0"):
        native_coords(HeightGrid(np.zeros((2, 2)), attrs={"xy_to_native": (1.0, 0.0, -1.0, 0.0)}))
    with pytest.raises(TypeError, match="grid must be a terrainvis.HeightGrid"):
        native_coords(np.zeros((2, 2)))


def test_geographic_grid_without_native_map_is_written_in_local_metres(tmp_path):
    _rasterio()
    g = HeightGrid(np.arange(9.0).reshape(3, 3), dx=30.0, dy=30.0, attrs={"geographic": True, "crs": "EPSG:4326"})
    with pytest.warns(UserWarning, match="hold no 'xy_to_native'.*local metres and no CRS"):
        p = save_dem(g, tmp_path / "g.tif")
    import rasterio

    with rasterio.open(p) as src:
        assert src.crs is None and src.transform.a == 30.0


# =================================================================== atomic writes
FORMATS = [".npz", ".npy", ".asc", ".tif", ".ply", ".obj", ".stl", ".glb"]


@pytest.mark.parametrize("suffix", FORMATS)
def test_failed_write_leaves_the_old_file(tmp_path, suffix, monkeypatch):
    if suffix in (".tif", ".asc"):
        _rasterio()
    import os

    p = tmp_path / f"old{suffix}"
    p.write_bytes(b"the old file")

    def boom(fd):
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(os, "fsync", boom)  # the flush of the new file fails
    g = HeightGrid(np.arange(12.0).reshape(3, 4))
    with warnings.catch_warnings(), pytest.raises(OSError, match="simulated"):
        warnings.simplefilter("ignore")
        save_terrain(g, p)
    assert p.read_bytes() == b"the old file"
    assert _leftovers(tmp_path) == []


def test_exception_mid_write_leaves_the_old_file(tmp_path, monkeypatch):
    p = tmp_path / "old.asc"
    p.write_text("the old file")
    real = np.savetxt

    def half(fh, rows, **kw):
        real(fh, rows[: len(rows) // 2], **kw)
        raise RuntimeError("interrupted (simulated)")

    monkeypatch.setattr(np, "savetxt", half)
    with pytest.raises(RuntimeError, match="interrupted"):
        save_dem(HeightGrid(np.arange(16.0).reshape(4, 4)), p)
    assert p.read_text() == "the old file" and _leftovers(tmp_path) == []


# =================================================================== meshes
def _tin_with_attrs():
    tin = synthetic_terrain("rough", size=7).to_tin()
    return TIN(tin.vertices + np.array([557805.123, 5107965.321, 0.0]), tin.faces, attrs={"name": "t", "k": (1, 2.5)})


@pytest.mark.parametrize("suffix", [".ply", ".obj"])
def test_exact_mesh_round_trip(tmp_path, suffix):
    tin = _tin_with_attrs()
    assert_tin_equal(load_terrain(save_terrain(tin, tmp_path / f"t{suffix}")), tin)
    # A grid is written through to_tin and read back as that TIN, with the grid's attrs.
    g = HeightGrid(np.random.default_rng(2).normal(size=(4, 5)), dx=0.1, origin=(1e-3, 7.0), attrs={"name": "g"})
    back = load_terrain(save_terrain(g, tmp_path / f"g{suffix}"))
    assert_tin_equal(back, g.to_tin(), attrs=False)
    assert_attrs_equal(back.attrs, {"name": "g"})
    # trimesh reads the files on its own too.
    import trimesh

    m = trimesh.load(tmp_path / f"t{suffix}", process=False)
    np.testing.assert_array_equal(m.vertices, tin.vertices)


def test_glb_keeps_a_float64_local_origin(tmp_path):
    import trimesh

    tin = _tin_with_attrs()
    p = save_terrain(tin, tmp_path / "t.glb")
    back = load_terrain(p)
    np.testing.assert_array_equal(back.faces, tin.faces)
    extent = np.ptp(tin.vertices, axis=0).max()
    # float32 about the local origin: errors of float32 of the extent, not of the UTM northing (0.5 m).
    np.testing.assert_allclose(back.vertices, tin.vertices, rtol=0, atol=2 * extent * 2.0**-24)
    assert_attrs_equal(back.attrs, tin.attrs)
    scene = trimesh.load(p)
    node_transform, _ = scene.graph["terrain"]
    np.testing.assert_array_equal(node_transform[:3, 3], tin.vertices.min(axis=0))
    # A grid goes through to_tin.
    g = HeightGrid(np.random.default_rng(5).normal(size=(3, 4)), dx=30.0, origin=(5e5, 4e6), attrs={"name": "g"})
    back = load_terrain(save_terrain(g, tmp_path / "g.glb"))
    np.testing.assert_array_equal(back.faces, g.to_tin().faces)
    np.testing.assert_allclose(back.vertices, g.to_tin().vertices, rtol=0, atol=1e-4)
    assert_attrs_equal(back.attrs, {"name": "g"})


def test_stl_is_float32_and_says_so(tmp_path):
    tin = _tin_with_attrs()
    with pytest.warns(UserWarning) as rec:
        p = save_terrain(tin, tmp_path / "t.stl")
    messages = " | ".join(str(w.message) for w in rec)
    assert "STL stores float32" in messages and "STL has no place for metadata" in messages
    back = load_terrain(p)
    assert back.n_vertices == tin.n_vertices and back.n_faces == tin.n_faces and back.attrs == {"path": str(p)}
    # The same triangles, vertices rounded to float32.
    f32 = tin.vertices.astype(np.float32).astype(np.float64)
    want = {tuple(sorted(map(tuple, f32[f]))) for f in tin.faces}
    got = {tuple(sorted(map(tuple, back.vertices[f]))) for f in back.faces}
    assert got == want
    assert back.is_height_field()
    # Local coordinates lose nothing worth a warning.
    local = TIN(tin.vertices - tin.vertices.min(axis=0), tin.faces)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        save_terrain(local, tmp_path / "local.stl")


# =================================================================== properties
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@st.composite
def _grids(draw):
    rows, cols = draw(st.integers(2, 7)), draw(st.integers(2, 7))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    z = rng.normal(0, 10.0 ** draw(st.integers(-3, 6)), (rows, cols))
    z[rng.random((rows, cols)) < draw(st.sampled_from([0.0, 0.2]))] = np.nan
    z[rng.random((rows, cols)) < 0.1] = -9999.0  # a real height, never nodata
    dx, dy = draw(st.floats(0.05, 5000.0)), draw(st.floats(0.05, 5000.0))
    origin = (draw(st.floats(-1e7, 1e7)), draw(st.floats(-1e7, 1e7)))
    return HeightGrid(z, dx=dx, dy=dy, origin=origin, attrs={"seed": draw(st.integers(0, 9))})


@settings(max_examples=25, deadline=None)
@given(g=_grids())
def test_round_trip_property(tmp_path_factory, g):
    folder = tmp_path_factory.mktemp("rt")
    suffixes = [".npz", ".asc"] + ([".tif"] if _has_rasterio() else [])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # coordinates near 0 with small cells may look like degrees
        for suffix in suffixes:
            back = load_dem(save_dem(g, folder / f"g{suffix}"))
            np.testing.assert_array_equal(back.z, g.z)  # NaN where NaN, -9999 where -9999, bits elsewhere
            if suffix == ".npz":
                assert_grid_equal(back, g)
            else:
                # A raster stores the corner and the spacing: the coordinates agree to rounding.
                scale = max(np.abs(g.xs).max(), np.abs(g.ys).max(), 1.0)
                np.testing.assert_allclose(back.xs, g.xs, rtol=0, atol=1e-12 * scale)
                np.testing.assert_allclose(back.ys, g.ys, rtol=0, atol=1e-12 * scale)
        tin = g.fill_nodata().to_tin()
        for suffix in (".npz", ".ply", ".obj"):
            assert_tin_equal(load_terrain(save_terrain(tin, folder / f"t{suffix}")), tin)


def _has_rasterio():
    try:
        import rasterio  # noqa: F401
    except ImportError:
        return False
    return True


def test_south_up_and_east_to_west_geotiffs(tmp_path):
    rasterio = _rasterio()
    from rasterio.transform import Affine

    z = np.arange(6.0).reshape(2, 3)  # file rows
    for name, t, want in (
        ("south_up.tif", Affine(10, 0, 1000, 0, 10, 2000), z),  # row 0 is south already
        ("west.tif", Affine(-10, 0, 1030, 0, -10, 2020), z[::-1, ::-1]),  # columns run east to west
    ):
        with rasterio.open(tmp_path / name, "w", driver="GTiff", height=2, width=3, count=1, dtype="float64",
                           transform=t, crs="EPSG:32633") as dst:
            dst.write(z, 1)
        g = load_dem(tmp_path / name)
        np.testing.assert_array_equal(g.z, want)
        np.testing.assert_array_equal(g.xs, [1005.0, 1015.0, 1025.0])
        np.testing.assert_array_equal(g.ys, [2005.0, 2015.0])


@pytest.mark.parametrize("dtype, nodata", [("float32", -9999.0), ("float32", -3.4028234663852886e38),
                                           ("int16", -32768), ("int16", -99999), ("uint8", None), ("float32", np.nan)])
@pytest.mark.parametrize("mask_band", [False, True])
def test_geotiff_nodata_and_masks_read_as_rasterio_masks_them(tmp_path, dtype, nodata, mask_band):
    # the reference: rasterio's own masked read, flipped to increasing y and x by hand
    rasterio = _rasterio()
    from rasterio.transform import Affine

    rng = np.random.default_rng(7)
    file_rows = rng.integers(1, 200, size=(5, 7)).astype(dtype)
    holds = nodata is not None and not (np.dtype(dtype).kind == "i" and not -32768 <= nodata <= 32767)
    if holds:
        file_rows[1, 2] = file_rows[3, 0] = np.asarray(nodata).astype(dtype)  # samples holding the nodata value
    path = tmp_path / "d.tif"
    profile = dict(driver="GTiff", height=5, width=7, count=1, dtype=dtype, crs="EPSG:32633",
                   transform=Affine(-10, 0, 1070, 0, -10, 2050))  # north-up, columns east to west
    if holds:  # (GDAL refuses a nodata value the band's type cannot hold)
        profile["nodata"] = nodata
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(file_rows, 1)
        if mask_band:  # an internal mask: samples valid by value but masked out
            valid = np.full((5, 7), 255, dtype=np.uint8)
            valid[0, :3] = 0
            dst.write_mask(valid)
    with rasterio.open(path) as src:
        ref = src.read(1, masked=True)
    want = np.where(np.ma.getmaskarray(ref), np.nan, np.ma.getdata(ref).astype(np.float64))[::-1, ::-1]
    if np.nanmax(np.abs(want)) > 1e15:
        # a mask band overrides the nodata value (GDAL's rule): -3.4e38 is then a height, and refused
        assert mask_band and nodata == -3.4028234663852886e38
        with pytest.raises(ValueError, match=r"holds a height of -3\.40282e\+38, beyond"):
            load_dem(path)
        return
    g = load_dem(path)
    np.testing.assert_array_equal(g.z, want)
    # nodata: the masked samples, and samples holding NaN (a NaN nodata value, or NaN under a mask band)
    assert np.isnan(g.z).sum() == (np.ma.getmaskarray(ref) | np.isnan(np.ma.getdata(ref))).sum()
    assert (np.isnan(g.z).sum() > 0) == (holds or mask_band)
    assert g.z.flags.c_contiguous and not g.z.flags.writeable


def test_asc_prj_is_written_and_a_stale_one_is_reported(tmp_path):
    _rasterio()
    g = _grid_with_nodata()
    save_dem(g, tmp_path / "a.asc")
    assert "UTM" in (tmp_path / "a.prj").read_text()
    bare = HeightGrid(g.z, dx=30.0, dy=25.0, origin=(560000.0, 5.1e6))
    with pytest.warns(UserWarning, match=r"a.prj beside 'a.asc' is left as it is, but the grid has no CRS"):
        save_dem(bare, tmp_path / "a.asc")
    assert load_dem(tmp_path / "a.asc").attrs["crs"] == "EPSG:32610"
    p = save_dem(HeightGrid(np.arange(4.0).reshape(2, 2)), tmp_path / "u.npy")
    assert load_dem(p, crs="EPSG:32633").attrs["crs"] == "EPSG:32633"


# ---------------------------------------------------------------------- rasters, figures and tables over a DEM
def test_write_geotiff_overlays_the_dem(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    from terrainvis.io import write_geotiff

    g = HeightGrid(np.arange(12.0).reshape(3, 4), dx=30.0, dy=20.0, origin=(500000.0, 4000000.0),
                   attrs={"crs": "EPSG:32617"})
    save_dem(g, tmp_path / "dem.tif")
    counts = np.arange(12, dtype=np.uint16).reshape(3, 4)
    write_geotiff(g, counts, tmp_path / "c.tif", nodata=65535, tags={"NOTE": "three rows"})
    with rasterio.open(tmp_path / "dem.tif") as dem, rasterio.open(tmp_path / "c.tif") as c:
        assert c.transform == dem.transform and c.crs == dem.crs
        assert c.dtypes[0] == "uint16" and c.nodata == 65535 and c.tags()["NOTE"] == "three rows"
        np.testing.assert_array_equal(c.read(1), counts[::-1])  # north up: the last row of z first
    with pytest.raises(ValueError, match=r"data must have the grid's shape \(3, 4\), got \(4, 3\)"):
        write_geotiff(g, counts.T, tmp_path / "x.tif")
    with pytest.raises(ValueError, match="path must end in .tif or .tiff, got 'x.png'"):
        write_geotiff(g, counts, tmp_path / "x.png")
    assert not (tmp_path / "x.tif").exists()


def test_save_figure_marks_the_png_and_write_csv_writes_atomically(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    from terrainvis.experiment._outdir import written_by_terrainvis
    from terrainvis.io import FIGURE_SOFTWARE, save_figure, write_csv

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    out = save_figure(fig, tmp_path / "accuracy_vs_size.png")
    plt.close(fig)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and written_by_terrainvis(out)
    assert FIGURE_SOFTWARE.encode() in out.read_bytes()[:400]
    fig, _ = plt.subplots()
    fig.savefig(tmp_path / "accuracy_vs_distance.png")  # the same kind of file, not terrainvis's
    plt.close(fig)
    assert not written_by_terrainvis(tmp_path / "accuracy_vs_distance.png")
    with pytest.raises(ValueError, match="path must end in .png"):
        save_figure(fig, tmp_path / "f.jpg")
    write_csv(pd.DataFrame({"x": [0.5, 1.25], "name": ["a", "b"]}), tmp_path / "t.csv", float_format="%.3f")
    assert (tmp_path / "t.csv").read_text() == "x,name\n0.500,a\n1.250,b\n"
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_a_nodata_value_the_band_cannot_hold_marks_no_sample():
    from terrainvis.io._geotiff import _as_stored

    assert _as_stored(-99999.0, np.int16) is None and _as_stored(1.5, np.int16) is None
    assert _as_stored(300.0, np.uint8) is None and _as_stored(-1.0, np.uint8) is None
    assert _as_stored(-32768.0, np.int16) == -32768.0
    assert _as_stored(1e39, np.float32) is None  # beyond float32: inf, no sample
    assert _as_stored(-3.4028234663852886e38, np.float32) == float(np.float32(-3.4028234663852886e38))
    assert _as_stored(0.1, np.float32) == float(np.float32(0.1)) != 0.1  # the band's own rounding


def test_a_geotiffs_nodata_is_counted_while_it_is_read(tmp_path):
    """The reader counts the NaN of each strip (no full-size mask afterwards): the count is the grid's."""
    from terrainvis import HeightGrid, load_dem, save_dem

    rng = np.random.default_rng(3)
    z = rng.normal(100.0, 10.0, (300, 257))
    z[rng.random(z.shape) < 0.07] = np.nan
    save_dem(HeightGrid(z, 30.0, 30.0, (500000.0, 4000000.0), attrs={"crs": "EPSG:32617"}), tmp_path / "d.tif")
    g = load_dem(tmp_path / "d.tif")
    assert g._cache["n_nodata"] == int(np.isnan(g.z).sum()) == int(np.isnan(z).sum()) > 0
    assert g.n_nodata == int(np.isnan(z).sum())
