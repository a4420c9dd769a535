"""Positions as a GIS user gives them: lon/lat degrees on a lon/lat DEM, projected x, y on a projected one.

The reference is rasterio's own transform of the file (``rasterio.transform.xy`` and
``rowcol``): a position given in degrees must land on the sample the file puts there,
through the API (``HeightGrid.from_native``) and through ``terrainvis los``,
``viewshed`` and ``relocate``. The local frame (``--frame local``) gives the same
answers; projected DEMs are unchanged, bit for bit.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import terrainvis as tv
from terrainvis.core._positions import PositionFrame
from terrainvis.cli import main
from terrainvis.visibility.profile import lowest_point

from conftest import shared_dem_path

rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
from rasterio.transform import Affine, rowcol  # noqa: E402
from rasterio.transform import xy as rio_xy  # noqa: E402

#: The window of jacksboro_fault_tn (north-up rows, columns) written as the test GeoTIFF.
ROWS, COLS = slice(100, 190), slice(120, 230)


@pytest.fixture(scope="module")
def lonlat_tif(tmp_path_factory):
    """A lon/lat GeoTIFF (EPSG:4326) cut from the shared Jacksboro DEM with its own geotransform."""
    with np.load(shared_dem_path("jacksboro_fault_tn"), allow_pickle=False) as d:
        z = np.asarray(d["z"], dtype=np.float32)[ROWS, COLS]
        gt = [float(v) for v in d["geotransform"]]
    transform = Affine(gt[1], 0.0, gt[0] + COLS.start * gt[1], 0.0, gt[5], gt[3] + ROWS.start * gt[5])
    path = tmp_path_factory.mktemp("lonlat") / "jacksboro_lonlat.tif"
    with rasterio.open(path, "w", driver="GTiff", height=z.shape[0], width=z.shape[1], count=1, dtype="float32",
                       crs="EPSG:4326", transform=transform) as dst:
        dst.write(z, 1)
    return path


@pytest.fixture(scope="module")
def raster(lonlat_tif):
    with rasterio.open(lonlat_tif) as src:
        return src.transform, src.read(1).astype(np.float64)


def _num(v) -> str:
    """A number as the command line takes it, every digit kept."""
    return repr(float(v))


def _run(capsys, argv):
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# ------------------------------------------------------------------ the API against rasterio's transform
@pytest.mark.parametrize("row, col", [(0, 0), (0, 109), (89, 0), (89, 109), (37, 58), (12, 91)])
def test_degrees_land_on_the_sample_rasterio_says(lonlat_tif, raster, row, col):
    t, band = raster
    g = tv.load_dem(lonlat_tif)
    rows = band.shape[0]
    lon, lat = rio_xy(t, row, col)  # the centre of raster sample (row, col)
    p = g.from_native([lon, lat])
    # raster row `row` (north-up) is grid row rows - 1 - row (y increasing)
    assert abs(p[0] - g.xs[col]) < 1e-6 and abs(p[1] - g.ys[rows - 1 - row]) < 1e-6
    assert g.height_at([p])[0] == pytest.approx(band[row, col], abs=1e-6)
    # and back: the grid's sample goes to the lon/lat whose raster cell rasterio names
    back = g.to_native([g.xs[col], g.ys[rows - 1 - row]])
    assert abs(back[0] - lon) < 1e-10 and abs(back[1] - lat) < 1e-10
    assert tuple(int(v) for v in rowcol(t, back[0], back[1])) == (row, col)


def test_positions_between_samples_follow_the_raster(lonlat_tif, raster):
    """A quarter of a cell east and north of a sample: the grid position moves by a quarter of its cell."""
    t, _ = raster
    g = tv.load_dem(lonlat_tif)
    lon, lat = rio_xy(t, 40, 50)
    p = g.from_native([lon + 0.25 * t.a, lat - 0.25 * t.e])  # t.e < 0: north is -e
    assert p[0] - g.xs[50] == pytest.approx(0.25 * g.dx, rel=1e-9)
    assert p[1] - g.ys[band_rows(raster) - 1 - 40] == pytest.approx(0.25 * g.dy, rel=1e-9)


def band_rows(raster) -> int:
    return raster[1].shape[0]


def test_shapes_heights_and_nan_pass_through(lonlat_tif):
    g = tv.load_dem(lonlat_tif)
    lon, lat = g.to_native([g.xs[3], g.ys[4]])
    one = g.from_native((lon, lat))
    many = g.from_native([[lon, lat], [np.nan, lat]])
    xyz = g.from_native(np.array([[lon, lat, 123.5]]))
    assert one.shape == (2,) and many.shape == (2, 2) and xyz.shape == (1, 3)
    np.testing.assert_array_equal(many[0], one)
    assert np.isnan(many[1, 0]) and xyz[0, 2] == 123.5 and xyz[0, :2].tolist() == one.tolist()
    with pytest.raises(ValueError, match="xy must hold positions along its last axis"):
        g.from_native([1.0])
    with pytest.raises(TypeError, match="xy must be numeric"):
        g.from_native("lon lat")
    broken = tv.HeightGrid(np.zeros((2, 2)), attrs={"geographic": True, "crs": "EPSG:4326"})
    with pytest.raises(ValueError, match="hold no 'xy_to_native'"):
        broken.from_native([0.0, 0.0])


def test_projected_and_plain_grids_are_unchanged_bit_for_bit():
    gm = tv.load_dem(shared_dem_path("green_mountains_vt", ".tif"))
    hills = tv.bundled_terrain("hills")
    rng = np.random.default_rng(1)
    for g in (gm, hills):
        xmin, xmax, ymin, ymax = g.extent
        p = np.column_stack([rng.uniform(xmin, xmax, 50), rng.uniform(ymin, ymax, 50), rng.uniform(0, 9, 50)])
        np.testing.assert_array_equal(g.from_native(p), p)
        np.testing.assert_array_equal(g.to_native(p), p)


@settings(max_examples=60, deadline=None)
@given(lat0=st.floats(-80.0, 79.0), lon0=st.floats(-180.0, 179.0), u=st.floats(0.0, 1.0), v=st.floats(0.0, 1.0),
       cell=st.sampled_from([1.0 / 3600.0, 3.0 / 3600.0, 30.0 / 3600.0]))
def test_round_trips_native_local(lat0, lon0, u, v, cell):
    """lon/lat -> local -> lon/lat and local -> lon/lat -> local, on grids read from lon/lat coordinates."""
    from terrainvis.core._georef import lonlat_to_local

    n = 50
    lon = lon0 + cell * np.arange(n)
    lat = lat0 + cell * np.arange(n)
    xs, ys, affine = lonlat_to_local(lon, lat, dlon=cell, dlat=cell)
    g = tv.HeightGrid.from_coords(np.zeros((n, n)), xs, ys,
                                  attrs={"crs": "EPSG:4326", "geographic": True, "xy_to_native": affine})
    p = np.array([lon[0] + u * (lon[-1] - lon[0]), lat[0] + v * (lat[-1] - lat[0])])
    back = g.to_native(g.from_native(p))
    assert np.abs(back - p).max() <= 1e-12 * (1 + np.abs(p).max())
    q = np.array([u * xs[-1], v * ys[-1]])
    again = g.from_native(g.to_native(q))
    assert np.abs(again - q).max() <= 1e-6  # micrometres: a float64 degree near 180 is 3e-14 deg ~ 3 nm


def test_crops_tins_and_the_bundled_sample_keep_the_map(lonlat_tif):
    g = tv.load_dem(lonlat_tif)
    lonlat = g.to_native(np.array([[g.xs[70], g.ys[50]], [g.xs[81], g.ys[61]]]))
    crop = g.crop(rows=(40, 80), cols=(60, 100))
    np.testing.assert_allclose(crop.height_at(crop.from_native(lonlat)), g.height_at(g.from_native(lonlat)), atol=1e-9)
    import simplifiers

    tin = simplifiers.simplify(g, "greedy-insertion", 2)
    np.testing.assert_array_equal(tin.from_native(lonlat), g.from_native(lonlat))
    # the shared .npz and matplotlib's copy of the same DEM put the same lon/lat on the same height
    shared, sample = tv.load_dem(shared_dem_path("jacksboro_fault_tn")), tv.sample_dem()
    np.testing.assert_allclose(shared.height_at(shared.from_native(lonlat)),
                               sample.height_at(sample.from_native(lonlat)), atol=1e-6)


# ------------------------------------------------------------------ the commands
def test_viewshed_in_degrees_is_the_viewshed_at_that_sample(lonlat_tif, raster, tmp_path, capsys):
    t, band = raster
    g = tv.load_dem(lonlat_tif)
    rows = band.shape[0]
    row, col = 30, 64
    lon, lat = rio_xy(t, row, col)
    code, out, err = _run(capsys, ["viewshed", lonlat_tif, "--observer", _num(lon), _num(lat), "--height", "10",
                                   "-o", tmp_path / "v.npz"])
    assert code == 0, err
    expected = tv.viewshed(g, (g.xs[col], g.ys[rows - 1 - row]), observer_height=10.0)
    saved = tv.load_terrain(tmp_path / "v.npz")
    np.testing.assert_array_equal(saved.z == 1.0, expected)
    assert np.allclose(saved.attrs["viewshed_observer_native"], [lon, lat], atol=1e-10)
    assert np.allclose(saved.attrs["viewshed_observer"], [g.xs[col], g.ys[rows - 1 - row]], atol=1e-6)
    assert f"observer ({lon:.7g}, {lat:.7g})" in out
    # the neighbouring samples see differently: a conversion one cell off would not pass
    for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        other = tv.viewshed(g, (g.xs[col + dc], g.ys[rows - 1 - row + dr]), observer_height=10.0)
        assert (other != expected).sum() > 10
    # the GeoTIFF is aligned with the input raster
    assert main(["viewshed", str(lonlat_tif), "--observer", _num(lon), _num(lat), "--height", "10",
                 "-o", str(tmp_path / "v.tif")]) == 0
    with rasterio.open(tmp_path / "v.tif") as v:
        assert v.crs == "EPSG:4326" and v.transform.almost_equals(t, precision=1e-12) and v.shape == band.shape
        np.testing.assert_array_equal(v.read(1)[::-1], expected.astype(np.uint8))
    # the same observer in the local frame gives the same viewshed
    x, y = g.xs[col], g.ys[rows - 1 - row]
    assert main(["viewshed", str(lonlat_tif), "--observer", _num(x), _num(y), "--height", "10", "--frame", "local",
                 "-o", str(tmp_path / "w.npz")]) == 0
    np.testing.assert_array_equal(tv.load_terrain(tmp_path / "w.npz").z, saved.z)


def test_los_in_degrees_and_in_the_local_frame(lonlat_tif, raster, tmp_path, capsys):
    t, band = raster
    g = tv.load_dem(lonlat_tif)
    rows = band.shape[0]
    (r1, c1), (r2, c2) = (10, 8), (80, 100)
    a_ll, b_ll = rio_xy(t, r1, c1), rio_xy(t, r2, c2)
    code, out, err = _run(capsys, ["los", lonlat_tif, "--from", *map(_num, a_ll), "--to", *map(_num, b_ll)])
    assert code == 0, err
    a = np.array([g.xs[c1], g.ys[rows - 1 - r1], band[r1, c1] + 1.7])
    b = np.array([g.xs[c2], g.ys[rows - 1 - r2], band[r2, c2]])
    visible = tv.line_of_sight(g, a[None], b[None])[0]
    clear = tv.min_clearance(g, a[None], b[None])[0]
    low = lowest_point(g, a, b)
    lon, lat = g.to_native([low["x"], low["y"]])
    line = out.strip().splitlines()[-1]
    assert f"({a_ll[0]:.7g}, {a_ll[1]:.7g}) -> ({b_ll[0]:.7g}, {b_ll[1]:.7g})" in line
    assert f": {'visible' if visible else 'blocked'}; lowest clearance {clear:.4g}" in line
    assert f" at ({lon:.7g}, {lat:.7g}), {low['distance']:.6g} from the observer" in line
    # the local frame: the same verdict, clearance and distance, positions in metres
    code, out_local, _ = _run(capsys, ["los", lonlat_tif, "--from", _num(a[0]), _num(a[1]), "--to", _num(b[0]),
                                       _num(b[1]), "--frame", "local"])
    assert code == 0
    local = out_local.strip().splitlines()[-1]
    assert local.split(": ", 1)[1].split(" at ")[0] == line.split(": ", 1)[1].split(" at ")[0]
    assert local.endswith(f"{low['distance']:.6g} from the observer")
    # many pairs in a CSV, in degrees
    pairs = tmp_path / "pairs.csv"
    pd.DataFrame({"x1": [a_ll[0], b_ll[0]], "y1": [a_ll[1], b_ll[1]], "x2": [b_ll[0], a_ll[0]],
                  "y2": [b_ll[1], a_ll[1]]}).to_csv(pairs, index=False)
    code, out_pairs, _ = _run(capsys, ["los", lonlat_tif, "--pairs", pairs])
    assert code == 0 and out_pairs.strip().splitlines()[1] == line


def test_relocate_writes_the_frame_it_reads(lonlat_tif, tmp_path, capsys):
    g = tv.load_dem(lonlat_tif)
    pts = tv.sample_points(g, 6, seed=3)
    lonlat = g.to_native(pts[:, :2])
    pd.DataFrame({"x": lonlat[:, 0], "y": lonlat[:, 1]}).to_csv(tmp_path / "p.csv", index=False)
    pd.DataFrame({"x": pts[:, 0], "y": pts[:, 1]}).to_csv(tmp_path / "q.csv", index=False)
    common = ["-m", "lls", "-l", "1", "--how", "full", "--offset", "2"]
    assert _run(capsys, ["relocate", lonlat_tif, "--points", tmp_path / "p.csv", "-o", tmp_path / "p_out.csv",
                         *common])[0] == 0
    assert _run(capsys, ["relocate", lonlat_tif, "--points", tmp_path / "q.csv", "-o", tmp_path / "q_out.csv",
                         "--frame", "local", *common])[0] == 0
    deg, met = pd.read_csv(tmp_path / "p_out.csv"), pd.read_csv(tmp_path / "q_out.csv")
    np.testing.assert_allclose(deg[["x", "y"]].to_numpy(), lonlat, atol=1e-9)  # written as read, to 1e-9 deg
    np.testing.assert_allclose(met[["x", "y"]].to_numpy(), pts[:, :2], atol=1e-6)
    for column in ("z", "z_original", "ground_simplified"):
        np.testing.assert_allclose(deg[column], met[column], atol=2e-6)
    import simplifiers

    S = simplifiers.simplify(g, "lls", 1)
    np.testing.assert_allclose(deg["z"], tv.relocate(np.column_stack([pts[:, :2], g.height_at(pts[:, :2]) + 2.0]),
                                                     S, "full", offset=2.0)[:, 2], atol=1e-6)


def _footprint_from_rasterio(raster) -> str:
    """The sample-centre footprint as rasterio's transform gives it, with the digits of a tenth of a 3" cell."""
    t, band = raster
    rows, cols = band.shape
    (w, n), (e, s) = rio_xy(t, 0, 0), rio_xy(t, rows - 1, cols - 1)
    return f"lon [{w:.7g}, {e:.7g}], lat [{s:.7g}, {n:.7g}]"


def test_outside_names_the_footprint_in_the_users_frame(lonlat_tif, raster, tmp_path, capsys):
    g = tv.load_dem(lonlat_tif)
    native = PositionFrame(g).footprint()
    assert native == _footprint_from_rasterio(raster) + " (EPSG:4326, degrees)"
    assert native == "lon [-84.31333, -84.2225], lat [36.575, 36.64917] (EPSG:4326, degrees)"
    code, _, err = _run(capsys, ["viewshed", lonlat_tif, "--observer", "-72.8", "44.12", "-o", tmp_path / "v.tif"])
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"--observer (-72.8, 44.12) lies outside the DEM's footprint {native} (or on nodata)" in err
    # local metres given as degrees, and degrees given as local metres: the message says which frame fits
    code, _, err = _run(capsys, ["viewshed", lonlat_tif, "--observer", "1000", "1000", "-o", tmp_path / "v.tif"])
    assert code == 2 and "it is on the DEM as the terrain's own x, y (local metres): add --frame local" in err
    code, _, err = _run(capsys, ["los", lonlat_tif, "--from", "-84.3", "36.6", "--to", "-84.25", "36.62",
                                 "--frame", "local"])
    local = f"x [0, {g.extent[1]:.6g}], y [0, {g.extent[3]:.6g}] (local metres)"
    assert code == 2 and f"lies outside the DEM's footprint {local}" in err
    assert "it is on the DEM as lon, lat in degrees (EPSG:4326): add --frame native" in err
    (tmp_path / "far.csv").write_text("x,y\n-84.3,36.6\n-80,30\n")
    code, _, err = _run(capsys, ["relocate", lonlat_tif, "--points", tmp_path / "far.csv", "-o", tmp_path / "o.csv",
                                 "-m", "lls"])
    assert code == 2 and "row 2 (-80, 30) lies outside the DEM's footprint lon [" in err
    # a projected DEM: its own coordinates, no hint (both frames are the same)
    gm = shared_dem_path("green_mountains_vt", ".tif")
    code, _, err = _run(capsys, ["los", gm, "--from", "0", "0", "--to", "1", "1"])
    assert code == 2 and err.strip().endswith("(EPSG:26918) (or on nodata)")


def test_projected_dems_give_the_same_output_in_both_frames(capsys):
    gm = shared_dem_path("green_mountains_vt", ".tif")
    argv = ["los", gm, "--from", "667000", "4881000", "--to", "683000", "4893000"]
    code, native, _ = _run(capsys, argv)
    code2, local, _ = _run(capsys, argv + ["--frame", "local"])
    assert code == code2 == 0 and native == local
    assert "(667000, 4881000) -> (683000, 4893000): blocked; lowest clearance -254.7 at (677607, 4888955)" in native


def test_info_says_which_frame_the_commands_take(lonlat_tif, raster, capsys):
    code, out, _ = _run(capsys, ["info", lonlat_tif])
    assert code == 0
    assert (f"positions lon, lat in degrees (EPSG:4326), the commands' default: {_footprint_from_rasterio(raster)}; "
            "--frame local takes the x, y above (local metres)") in out
    # the local frame's east-west error at the edge rows, against geodesic cell widths on WGS84
    pyproj = pytest.importorskip("pyproj")
    t, band = raster
    g = tv.load_dem(lonlat_tif)
    geod = pyproj.Geod(ellps="WGS84")
    (lon, north), (_, south) = rio_xy(t, 0, 0), rio_xy(t, band.shape[0] - 1, 0)
    err = [100 * (g.dx / geod.inv(lon, lat, lon + t.a, lat)[2] - 1) for lat in (south, north)]
    assert f"east-west lengths {err[0]:+.2f} % off at the southern edge, {err[1]:+.2f} % at the northern edge" in out
    assert err[0] < -0.01 and err[1] > 0.01
    code, out, _ = _run(capsys, ["info", shared_dem_path("green_mountains_vt", ".tif")])
    assert "positions x, y in EPSG:26918, in the commands (--from, --to, --observer, CSVs; --frame local is the same" \
           in out and "distances" not in out
