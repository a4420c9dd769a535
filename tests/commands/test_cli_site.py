"""``terrainvis site``: the command's outputs against the Python API, and its one-line errors.

Every output is checked against :func:`terrainvis.site_observers` on the same terrain and
candidates (itself tested against the plain greedy and brute force in test_siting.py), and
the GeoTIFF against the DEM it came from (rasterio's CRS, transform and shape).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import shared_dem_path
from terrainvis import bundled_terrain, candidate_grid, load_dem, site_observers
from terrainvis.cli import main

GM_CANDIDATES = [(675000.0, 4887000.0), (680000.0, 4890000.0), (670000.0, 4880000.0), (683000.0, 4883000.0),
                 (672000.0, 4891000.0), (678000.0, 4879000.0)]


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


def test_grid_candidates_outputs_equal_the_api(tmp_path, capsys):
    code, out, err = _run(capsys, ["site", "hills", "--grid", 15, "-k", 3, "-o", tmp_path / "chosen.csv",
                                   "--coverage", tmp_path / "cov.npz", "--plot", tmp_path / "curve.png",
                                   "--height", 5, "--target-height", 1])
    assert code == 0, err
    grid = bundled_terrain("hills")
    expected = site_observers(grid, candidate_grid(grid, 15), 3, observer_height=5.0, target_height=1.0, workers=1)
    got = pd.read_csv(tmp_path / "chosen.csv")
    assert got["candidate"].tolist() == expected.chosen.tolist()
    for column in ("x", "y", "gain_cells", "covered_cells", "covered_area", "covered_share"):
        np.testing.assert_allclose(got[column], expected.table[column], rtol=1e-12, err_msg=column)
    cov = load_dem(tmp_path / "cov.npz")
    np.testing.assert_array_equal(cov.z.astype(bool), expected.covered)
    assert (tmp_path / "curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    lines = out.strip().splitlines()
    assert lines[0] == "hills: choosing 3 of 64 candidates (--grid 15), eyes 5 above the surface, target 1"
    rows = [ln.split() for ln in lines[4:7]]
    assert [int(r[1]) for r in rows] == expected.chosen.tolist()
    assert [r[-2] for r in rows] == [f"{100 * s:.2f}" for s in expected.table["covered_share"]]
    assert "this choice reaches at least" in lines[7]


def test_csv_candidates_on_a_georeferenced_dem(tmp_path, capsys):
    rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
    dem = shared_dem_path("green_mountains_vt", ".tif")
    heights = [5.0, 8.0, 12.0, 8.0, 3.0, 8.0]
    pd.DataFrame({"x": [p[0] for p in GM_CANDIDATES], "y": [p[1] for p in GM_CANDIDATES],
                  "height": heights}).to_csv(tmp_path / "cands.csv", index=False)
    code, out, err = _run(capsys, ["site", dem, "--candidates", tmp_path / "cands.csv", "-k", 2, "--height", 99,
                                   "--curvature", 0.85714, "-o", tmp_path / "c.csv", "--coverage", tmp_path / "c.tif"])
    assert code == 0, err
    grid = load_dem(dem)
    h = np.array([5.0, 8.0, 12.0, 8.0, 3.0, 8.0])
    expected = site_observers(grid, grid.from_native(GM_CANDIDATES), 2, observer_height=h, curvature=0.85714,
                              workers=1)
    got = pd.read_csv(tmp_path / "c.csv")
    assert got["candidate"].tolist() == expected.chosen.tolist()
    np.testing.assert_allclose(got[["x", "y"]].to_numpy(), np.asarray(GM_CANDIDATES)[expected.chosen], rtol=1e-12)
    with rasterio.open(tmp_path / "c.tif") as c, rasterio.open(dem) as src:
        assert c.crs == src.crs and c.transform == src.transform and c.shape == src.shape
        data = c.read(1)[::-1]  # north-up rows
    valid = np.isfinite(grid.z)
    np.testing.assert_array_equal(data[valid] == 1, expected.covered[valid])
    assert (data[~valid] == 255).all()
    assert "earth: curved, coefficient 0.85714" in out


@pytest.mark.parametrize(("argv", "pieces"), [
    (["-k", "0", "--grid", "10"], ["argument -k", "expected a whole number >= 1, got '0'"]),
    (["-k", "2", "--grid", "0"], ["argument --grid", "expected a whole number >= 1, got '0'"]),
    (["-k", "2", "--grid", "1.5"], ["argument --grid", "got '1.5'"]),
    (["-k", "101", "--grid", "12"], ["-k must be at most the number of candidates, 100 (--grid 12), got 101"]),
    (["-k", "2"], ["one of the arguments --candidates --grid is required"]),
    (["-k", "2", "--grid", "12", "--candidates", "x.csv"], ["--candidates: not allowed with argument --grid"]),
    (["-k", "2", "--grid", "12", "-o", "chosen.txt"], ["-o must end in .csv, got 'chosen.txt'"]),
    (["-k", "2", "--grid", "12", "--plot", "curve.pdf"], ["--plot must end in .png, got 'curve.pdf'"]),
    (["-k", "2", "--grid", "12", "--azimuth", "10", "400"], ["--azimuth", "400"]),
    (["-k", "2", "--grid", "12", "--vertical", "5", "-5"], ["--vertical"]),
])
def test_one_line_errors(tmp_path, capsys, monkeypatch, argv, pieces):
    monkeypatch.chdir(tmp_path)
    err = _err(capsys, ["site", "hills", *argv])
    for piece in pieces:
        assert piece in err, err


def test_a_candidate_outside_the_dem_is_named(tmp_path, capsys):
    pd.DataFrame({"x": [100.0, 5000.0, 7000.0], "y": [100.0, 100.0, 100.0]}).to_csv(tmp_path / "c.csv", index=False)
    err = _err(capsys, ["site", "hills", "--candidates", tmp_path / "c.csv", "-k", 1])
    assert "--candidates" in err and "row 2 (5000, 100) lies outside the DEM's footprint" in err
    assert "2 candidates of 3 do" in err
    pd.DataFrame({"x": [100.0], "y": [100.0], "height": [-1.0]}).to_csv(tmp_path / "h.csv", index=False)
    err = _err(capsys, ["site", "hills", "--candidates", tmp_path / "h.csv", "-k", 1])
    assert "row 1, column height is -1; heights above the surface must be >= 0" in err


def test_a_field_of_view_is_the_apis(tmp_path, capsys):
    code, out, err = _run(capsys, ["site", "hills", "--grid", 15, "-k", 3, "-o", tmp_path / "chosen.csv",
                                   "--height", 5, "--azimuth", 300, 60, "--min-distance", 100])
    assert code == 0, err
    grid = bundled_terrain("hills")
    expected = site_observers(grid, candidate_grid(grid, 15), 3, observer_height=5.0, azimuth=(300.0, 60.0),
                              min_distance=100.0, workers=1)
    whole = site_observers(grid, candidate_grid(grid, 15), 3, observer_height=5.0, workers=1)
    assert expected.table["covered_cells"].iloc[-1] < whole.table["covered_cells"].iloc[-1]
    got = pd.read_csv(tmp_path / "chosen.csv")
    assert got["candidate"].tolist() == expected.chosen.tolist()
    np.testing.assert_array_equal(got["covered_cells"], expected.table["covered_cells"])
    assert "azimuth 300 to 60 degrees clockwise (through north)" in out
