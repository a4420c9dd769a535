"""``terrainvis cumulative`` and the earth model of ``los`` and ``viewshed`` on the command line.

Every output is checked against the Python API on the same terrain (``cumulative_viewshed``,
``viewshed``, ``line_of_sight``), and the files against the DEM they came from (rasterio's
CRS, transform and shape); every mistake ends in one line on stderr with exit status 2.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import shared_dem_path
from terrainvis import HeightGrid, bundled_terrain, cumulative_viewshed, line_of_sight, save_dem, viewshed
from terrainvis.cli import main

GM_OBSERVERS = [(675000.0, 4887000.0), (680000.0, 4890000.0), (670000.0, 4880000.0), (683000.0, 4883000.0)]


def _run(capsys, argv):
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _err(capsys, argv, code=2):
    got, _, err = _run(capsys, argv)
    err = err.strip()
    assert got == code, err
    assert "\n" not in err and "Traceback" not in err, err
    return err


def _csv(path, xy, **columns):
    xy = np.asarray(xy, dtype=float)
    pd.DataFrame({"x": xy[:, 0], "y": xy[:, 1], **columns}).to_csv(path, index=False)
    return path


# ------------------------------------------------------------------ cumulative
def test_counts_geotiff_is_aligned_with_the_dem_and_equals_the_api(tmp_path, capsys):
    rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
    from terrainvis import load_dem

    dem = shared_dem_path("green_mountains_vt", ".tif")
    obs = _csv(tmp_path / "obs.csv", GM_OBSERVERS)
    code, out, err = _run(capsys, ["cumulative", dem, "--observers", obs, "-o", tmp_path / "c.tif",
                                   "--png", tmp_path / "c.png", "--workers", "1", "--observer-height", "5"])
    assert code == 0, err
    expected = cumulative_viewshed(load_dem(dem), GM_OBSERVERS, observer_height=5.0, workers=1)
    assert expected.max() >= 2  # some samples are seen by more than one observer
    with rasterio.open(tmp_path / "c.tif") as c, rasterio.open(dem) as src:
        assert c.crs == src.crs and c.transform == src.transform and c.shape == src.shape
        assert c.dtypes[0] == "uint16" and c.nodata == 65535
        np.testing.assert_array_equal(c.read(1)[::-1], expected)  # north-up rows
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    lines = out.strip().splitlines()
    assert lines[0] == "green_mountains_vt: 4 observers, eyes 5 above the surface, target 0"
    assert lines[1].startswith("  earth: flat (curvature 0; --curvature 0.85714")
    seen = 100 * (expected > 0).mean()
    assert f"seen by any {int((expected > 0).sum()):,} of 44,556 samples ({seen:.2f} %)" in lines[2]
    assert f"most observers on one sample {int(expected.max())}" in lines[2]
    assert " s in this process (" in lines[2]
    assert lines[3] == f"  wrote {tmp_path / 'c.tif'} and {tmp_path / 'c.png'}"


def test_options_reach_the_api(tmp_path, capsys):
    """Per-observer heights from the CSV, target height, max distance and curvature, to .npz."""
    from terrainvis import load_terrain

    grid = bundled_terrain("ridges")
    xy = [(300.0, 400.0), (2000.0, 2500.0), (3300.0, 900.0)]
    obs = _csv(tmp_path / "obs.csv", xy, height=[2.0, 30.0, 0.0])
    argv = ["cumulative", "ridges", "--observers", obs, "-o", tmp_path / "c.npz", "--workers", "1",
            "--target-height", "1.5", "--max-distance", "2500", "--curvature", "1", "--earth-radius", "4000"]
    code, out, err = _run(capsys, argv)
    assert code == 0, err
    expected = cumulative_viewshed(grid, xy, observer_height=[2.0, 30.0, 0.0], target_height=1.5,
                                   max_distance=2500.0, curvature=1.0, earth_radius=4000.0, workers=1)
    saved = load_terrain(tmp_path / "c.npz")
    np.testing.assert_array_equal(saved.z, expected)
    assert saved.attrs["cumulative_observers"] == 3 and saved.attrs["cumulative_curvature"] == 1.0
    assert "eyes 0 to 30 above the surface, target 1.5, within 2500" in out
    assert "earth: curved, coefficient 1 (geometric), radius 4,000" in out
    # the curvature changed the answer (so the check above is not the flat one by accident)
    flat = cumulative_viewshed(grid, xy, observer_height=[2.0, 30.0, 0.0], target_height=1.5, max_distance=2500.0,
                               workers=1)
    assert (flat != expected).any()


def test_nodata_is_the_largest_value_and_two_workers_agree(tmp_path, capsys):
    rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
    z = bundled_terrain("hills").z[:60, :70].copy()
    z[10:13, 40:50] = np.nan
    dem = tmp_path / "holes.tif"
    save_dem(HeightGrid(z, dx=30.0, dy=30.0, attrs={"crs": "EPSG:32618"}), dem)
    xy = [(100.0, 100.0), (1500.0, 900.0), (600.0, 1700.0), (2000.0, 200.0), (1000.0, 1000.0)]
    obs = _csv(tmp_path / "obs.csv", xy)
    for workers in ("1", "2"):
        assert _run(capsys, ["cumulative", dem, "--observers", obs, "-o", tmp_path / f"c{workers}.tif",
                             "--workers", workers])[0] == 0
    from terrainvis import load_dem

    expected = cumulative_viewshed(load_dem(dem), xy, workers=1)
    for workers in ("1", "2"):
        with rasterio.open(tmp_path / f"c{workers}.tif") as c:
            data = c.read(1)[::-1]
            assert c.nodata == 65535 and c.crs == "EPSG:32618"
        assert (data[np.isnan(z)] == 65535).all()
        np.testing.assert_array_equal(data[~np.isnan(z)], expected[~np.isnan(z)])


def test_observers_in_degrees_on_a_lonlat_dem(tmp_path, capsys):
    """The bundled Jacksboro window is lon/lat: the CSV takes degrees (native), or metres with --frame local."""
    rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
    from terrainvis.experiment.plan import resolve_one

    grid = resolve_one(None, "jacksboro", 0)[1]  # as the commands load it
    local = np.array([[grid.xs[20], grid.ys[30]], [grid.xs[90], grid.ys[70]], [grid.xs[60], grid.ys[100]]])
    degrees = grid.to_native(local)
    assert (degrees[:, 0] < -84).all() and (degrees[:, 1] > 36).all()
    obs = _csv(tmp_path / "deg.csv", degrees)
    code, out, err = _run(capsys, ["cumulative", "jacksboro", "--observers", obs, "-o", tmp_path / "c.tif",
                                   "--workers", "1"])
    assert code == 0, err
    expected = cumulative_viewshed(grid, local, workers=1)
    with rasterio.open(tmp_path / "c.tif") as c:
        assert c.crs == "EPSG:4326"
        np.testing.assert_array_equal(c.read(1)[::-1], expected)
    metres = _csv(tmp_path / "m.csv", local)
    assert _run(capsys, ["cumulative", "jacksboro", "--observers", metres, "--frame", "local", "-o",
                         tmp_path / "d.tif", "--workers", "1"])[0] == 0
    with rasterio.open(tmp_path / "d.tif") as d:
        np.testing.assert_array_equal(d.read(1)[::-1], expected)
    # metres given as degrees: refused, with the hint
    err = _err(capsys, ["cumulative", "jacksboro", "--observers", metres, "-o", tmp_path / "e.tif"])
    assert "row 1" in err and "lies outside the DEM's footprint lon [" in err and "--frame local" in err


def test_mistakes_end_in_one_line(tmp_path, capsys):
    dem = "ridges"
    good = _csv(tmp_path / "obs.csv", [(300.0, 400.0), (2000.0, 2500.0)])
    out = tmp_path / "c.tif"
    err = _err(capsys, ["cumulative", dem, "--observers", _csv(tmp_path / "far.csv", [(300.0, 400.0), (1e6, 0.0),
                                                                                     (-5.0, 0.0)]), "-o", out])
    assert "--observers" in err and "row 2 (1000000, 0) lies outside the DEM's footprint" in err and "2 observers of 3 do" in err
    pd.DataFrame({"x": [1.0], "z": [2.0]}).to_csv(tmp_path / "noy.csv", index=False)
    assert "--observers needs the columns x, y" in _err(capsys, ["cumulative", dem, "--observers", tmp_path / "noy.csv",
                                                                 "-o", out])
    pd.DataFrame({"x": ["300", "abc"], "y": ["400", "500"]}).to_csv(tmp_path / "bad.csv", index=False)
    assert "row 2 (line 3), column x holds 'abc'" in _err(capsys, ["cumulative", dem, "--observers",
                                                                   tmp_path / "bad.csv", "-o", out])
    (tmp_path / "empty.csv").write_text("x,y\n")
    assert "holds no row after its header" in _err(capsys, ["cumulative", dem, "--observers", tmp_path / "empty.csv",
                                                           "-o", out])
    neg = _csv(tmp_path / "neg.csv", [(300.0, 400.0), (900.0, 900.0)], height=[1.0, -3.0])
    assert "row 2, column height is -3" in _err(capsys, ["cumulative", dem, "--observers", neg, "-o", out])
    err = _err(capsys, ["cumulative", dem, "--observers", tmp_path / "missing.csv", "-o", out])
    assert "--observers" in err and "could not be read as CSV" in err and "No such file or directory" in err
    assert "-o must end in .tif or .npz" in _err(capsys, ["cumulative", dem, "--observers", good, "-o",
                                                          tmp_path / "c.png"])
    assert "--png must end in .png" in _err(capsys, ["cumulative", dem, "--observers", good, "-o", out, "--png",
                                                     tmp_path / "c.jpg"])
    assert "--workers" in _err(capsys, ["cumulative", dem, "--observers", good, "-o", out, "--workers", "0"])
    assert "--curvature" in _err(capsys, ["cumulative", dem, "--observers", good, "-o", out, "--curvature", "-0.5"])
    assert "--earth-radius" in _err(capsys, ["cumulative", dem, "--observers", good, "-o", out, "--earth-radius", "0"])
    assert "--observers" in _err(capsys, ["cumulative", dem, "-o", out])
    assert "--observer-height" in _err(capsys, ["cumulative", dem, "--observers", good, "-o", out,
                                                "--observer-height", "-1"])
    # the observers' CSV is never written over
    err = _err(capsys, ["cumulative", dem, "--observers", good, "-o", tmp_path / "x.npz", "--png", good])
    assert "--png" in err
    assert good.read_text().startswith("x,y")
    assert not out.exists()


# ------------------------------------------------------------------ los and viewshed: the earth model
def test_viewshed_takes_the_earth_model(tmp_path, capsys):
    from terrainvis import load_terrain

    grid = bundled_terrain("mountains")
    code, out, _ = _run(capsys, ["viewshed", "mountains", "--observer", "1800", "1800", "--height", "10", "-o",
                                 tmp_path / "flat.npz"])
    assert code == 0
    assert "  earth: flat (curvature 0; --curvature 0.85714 for gdal_viewshed's default, standard refraction)" in out
    np.testing.assert_array_equal(load_terrain(tmp_path / "flat.npz").z,
                                  viewshed(grid, (1800.0, 1800.0), observer_height=10.0))
    code, out, _ = _run(capsys, ["viewshed", "mountains", "--observer", "1800", "1800", "--height", "10",
                                 "--curvature", "0.85714", "--earth-radius", "3000", "-o", tmp_path / "curved.npz"])
    assert code == 0
    assert "  earth: curved, coefficient 0.85714 (standard refraction), radius 3,000" in out
    expected = viewshed(grid, (1800.0, 1800.0), observer_height=10.0, curvature=0.85714, earth_radius=3000.0)
    saved = load_terrain(tmp_path / "curved.npz")
    np.testing.assert_array_equal(saved.z, expected)
    assert saved.attrs["viewshed_curvature"] == 0.85714 and saved.attrs["viewshed_earth_radius"] == 3000.0
    assert (expected != load_terrain(tmp_path / "flat.npz").z.astype(bool)).any()


def test_los_takes_the_earth_model(capsys):
    grid = bundled_terrain("hills")
    a, b = (200.0, 300.0), (3300.0, 3000.0)
    pa = np.array([[*a, grid.height_at([a])[0] + 20.0]])
    pb = np.array([[*b, grid.height_at([b])[0] + 20.0]])
    flat = line_of_sight(grid, pa, pb)[0]
    curved = line_of_sight(grid, pa, pb, curvature=1.0, earth_radius=2000.0)[0]
    assert flat != curved  # the small earth changes this pair's verdict
    base = ["los", "hills", "--from", *a, "--to", *b, "--height", "20", "--target-height", "20"]
    code, out, _ = _run(capsys, base)
    assert code == 0
    header, line = out.strip().splitlines()
    assert header.endswith("; earth: flat (curvature 0; --curvature 0.85714 for gdal_viewshed's default, standard "
                           "refraction)")
    assert f": {'visible' if flat else 'blocked'};" in line
    code, out, _ = _run(capsys, base + ["--curvature", "1", "--earth-radius", "2000"])
    assert code == 0
    header, line = out.strip().splitlines()
    assert header.endswith("; earth: curved, coefficient 1 (geometric), radius 2,000")
    assert f": {'visible' if curved else 'blocked'};" in line
    assert "--curvature" in _err(capsys, base + ["--curvature", "nan"])


def test_on_a_dask_scheduler(tmp_path, capsys):
    distributed = pytest.importorskip("distributed", reason="the dask extra is not installed (pip install terrainvis[dask])")
    from terrainvis import load_terrain

    xy = [(300.0, 400.0), (2000.0, 2500.0), (3300.0, 900.0), (1200.0, 3000.0)]
    obs = _csv(tmp_path / "obs.csv", xy)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        code, out, err = _run(capsys, ["cumulative", "ridges", "--observers", obs, "-o", tmp_path / "c.npz",
                                       "--scheduler", cluster.scheduler_address])
    assert code == 0, err
    assert "on the dask cluster" in out
    np.testing.assert_array_equal(load_terrain(tmp_path / "c.npz").z,
                                  cumulative_viewshed(bundled_terrain("ridges"), xy, workers=1))
