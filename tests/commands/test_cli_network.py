"""``terrainvis cumulative --network`` and ``--observers-out``: the files against the Python API.

The network (CSV with WKT lines, or a GeoPackage read back by our reader and by GDAL's
``ogrinfo`` where installed) is compared with :func:`terrainvis.intervisibility_network`
on the same DEM and observers, positions in the DEM's CRS; the observer sets with
:func:`terrainvis.observer_sets`, and their count with the counts GeoTIFF the same command
wrote.
"""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from conftest import shared_dem_path
from terrainvis import ObserverSets, intervisibility_network, load_dem, observer_sets
from terrainvis.cli import main
from terrainvis.io import read_geopackage_lines

GM_OBSERVERS = [(675000.0, 4887000.0), (680000.0, 4890000.0), (670000.0, 4880000.0), (683000.0, 4883000.0),
                (672000.0, 4891000.0)]


def _run(capsys, argv):
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def gm(tmp_path):
    dem = shared_dem_path("green_mountains_vt", ".tif")
    pd.DataFrame({"x": [p[0] for p in GM_OBSERVERS], "y": [p[1] for p in GM_OBSERVERS]}).to_csv(
        tmp_path / "obs.csv", index=False)
    return dem, tmp_path / "obs.csv"


def test_network_csv_and_observer_sets(tmp_path, capsys, gm):
    rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
    dem, obs = gm
    code, out, err = _run(capsys, ["cumulative", dem, "--observers", obs, "-o", tmp_path / "c.tif",
                                   "--observer-height", 15, "--curvature", 0.85714, "--network", tmp_path / "net.csv",
                                   "--observers-out", tmp_path / "sets.npz"])
    assert code == 0, err
    grid = load_dem(dem)
    xy = grid.from_native(GM_OBSERVERS)
    expected = intervisibility_network(grid, xy, observer_height=15.0, curvature=0.85714)
    got = pd.read_csv(tmp_path / "net.csv")
    assert got[["i", "j"]].values.tolist() == expected[["i", "j"]].values.tolist()
    np.testing.assert_allclose(got[["clearance", "distance", "z_i", "z_j"]],
                               expected[["clearance", "distance", "z_i", "z_j"]], rtol=1e-12)
    assert got["visible"].tolist() == expected["visible"].tolist()
    assert 0 < got["visible"].sum() < len(got)
    native = np.asarray(GM_OBSERVERS)
    np.testing.assert_allclose(got[["x_i", "y_i"]].to_numpy(), native[got["i"]], rtol=1e-12)
    first = got.iloc[0]
    x_i, y_i, x_j, y_j = (float(first[c]) for c in ("x_i", "y_i", "x_j", "y_j"))
    assert first["wkt"] == f"LINESTRING ({x_i!r} {y_i!r}, {x_j!r} {y_j!r})"
    sets = ObserverSets.load(tmp_path / "sets.npz")
    direct = observer_sets(grid, xy, observer_height=15.0, curvature=0.85714, workers=1)
    np.testing.assert_array_equal(sets.bits, direct.bits)
    with rasterio.open(tmp_path / "c.tif") as c:
        counts = c.read(1)[::-1]
    valid = np.isfinite(grid.z)
    np.testing.assert_array_equal(counts[valid], sets.count()[valid])
    assert f"network: {int(expected['visible'].sum())} of 10 pairs of observers see each other" in out
    assert out.strip().splitlines()[-1].endswith(f"c.tif, {tmp_path / 'sets.npz'} and {tmp_path / 'net.csv'}")


def test_network_geopackage_in_the_dems_crs(tmp_path, capsys, gm):
    rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
    dem, obs = gm
    code, out, err = _run(capsys, ["cumulative", dem, "--observers", obs, "-o", tmp_path / "c.tif",
                                   "--network", tmp_path / "net.gpkg"])
    assert code == 0, err
    grid = load_dem(dem)
    expected = intervisibility_network(grid, grid.from_native(GM_OBSERVERS))
    layer = read_geopackage_lines(tmp_path / "net.gpkg")
    with rasterio.open(dem) as src:
        epsg = src.crs.to_epsg()
    assert layer.attrs["srs_id"] == epsg and layer.attrs["organization_coordsys_id"] == epsg
    assert layer["visible"].tolist() == expected["visible"].astype(int).tolist()
    np.testing.assert_allclose(layer["clearance"], expected["clearance"], rtol=1e-12)
    native = np.asarray(GM_OBSERVERS)
    for row, geometry in zip(expected.itertuples(), layer["geometry"]):
        np.testing.assert_allclose(geometry, native[[row.i, row.j]], rtol=1e-12)
    if shutil.which("ogrinfo") is None:
        pytest.skip("GDAL's ogrinfo is not on PATH: the GeoPackage was checked by our reader only")
    run = subprocess.run(["ogrinfo", "-ro", "-so", "-al", str(tmp_path / "net.gpkg")], capture_output=True, text=True,
                         check=True)
    assert "ERROR" not in run.stderr, run.stderr
    assert "Feature Count: 10" in run.stdout and "Geometry: Line String" in run.stdout
    assert f'ID["EPSG",{epsg}]' in run.stdout or f'AUTHORITY["EPSG","{epsg}"]' in run.stdout


@pytest.mark.parametrize(("flag", "name", "message"), [
    ("--network", "net.shp", "--network must end in .csv or .gpkg, got 'net.shp'"),
    ("--observers-out", "sets.npy", "--observers-out must end in .npz, got 'sets.npy'"),
])
def test_bad_suffixes_are_one_line(tmp_path, capsys, flag, name, message):
    pd.DataFrame({"x": [100.0, 900.0], "y": [100.0, 900.0]}).to_csv(tmp_path / "o.csv", index=False)
    code, _, err = _run(capsys, ["cumulative", "hills", "--observers", tmp_path / "o.csv", "-o", tmp_path / "c.npz",
                                 flag, tmp_path / name])
    assert code == 2 and err.strip().count("\n") == 0 and message in err, err


def test_network_on_a_dem_with_nodata_asks_for_fill(tmp_path, capsys):
    from terrainvis import bundled_terrain, save_dem

    g = bundled_terrain("hills")
    z = g.z.copy()
    z[0, :5] = np.nan
    save_dem(g.copy_with(z), tmp_path / "holes.npz")
    pd.DataFrame({"x": [1000.0, 2000.0], "y": [1000.0, 2500.0]}).to_csv(tmp_path / "o.csv", index=False)
    argv = ["cumulative", tmp_path / "holes.npz", "--observers", tmp_path / "o.csv", "-o", tmp_path / "c.npz",
            "--network", tmp_path / "n.csv"]
    code, _, err = _run(capsys, argv)
    assert code == 2 and "add --fill nearest" in err and err.strip().count("\n") == 0, err
    code, out, err = _run(capsys, argv + ["--fill", "nearest"])
    assert code == 0, err
    assert len(pd.read_csv(tmp_path / "n.csv")) == 1
