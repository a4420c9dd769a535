"""The terrainvis command line: compare, simplify, los, info; one-line errors and exit codes."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pandas as pd
import pytest

from terrainvis.cli import main

from conftest import shared_dem_path

SMALL = ["--terrain", "hills", "--levels", "1", "--methods", "simple", "lls", "--points", "10", "--sets", "2",
         "--workers", "1", "--repeats", "1", "--relocations", "identity", "full", "half"]


def _one_line_error(capsys, code_expected, argv):
    capsys.readouterr()  # drop what earlier commands printed
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == code_expected, err
    assert "\n" not in err and "Traceback" not in err, err
    return err


def test_compare_writes_results(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["compare", *SMALL, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Table 1" in text and "identity is the best relocation overall" in text
    assert "The paper side by side" in text
    df = pd.read_csv(out / "results.csv")
    assert len(df) == 1 * 2 * 2 * 3
    assert (out / "tables.md").read_text().startswith("# terrainvis compare")
    for png in ("accuracy_vs_size.png", "tradeoff_full.png", "views_hills.png"):
        assert (out / png).stat().st_size > 1000
    assert sorted(p.name for p in (out / "simplified").iterdir()) == ["hills__lls__level1.npz", "hills__simple__level1.npz"]
    # --resume with everything done runs nothing and gives the same rows
    assert main(["compare", *SMALL, "--out", str(out), "--resume", "--no-plots"]) == 0
    again = pd.read_csv(out / "results.csv")
    pd.testing.assert_frame_equal(again[["accuracy", "method"]], df[["accuracy", "method"]])
    # ... and with other settings it refuses, naming them, in one line
    err = _one_line_error(capsys, 2, ["compare", *SMALL[:-2], "--repeats", "2", "--out", str(out), "--resume"])
    assert "repeats: 1 before, 2 now" in err and "another --out" in err


def test_compare_errors_are_one_line(tmp_path, capsys):
    err = _one_line_error(capsys, 2, ["compare", "--terrain", "atlantis", "--out", str(tmp_path)])
    assert "bundled terrain ['hills'" in err
    err = _one_line_error(capsys, 2, ["compare", "--terrain", "hills", "--methods", "nope", "--out", str(tmp_path)])
    assert "methods must be drawn from ['qec', 'greedy-cuts'" in err
    err = _one_line_error(capsys, 2, ["compare", "--terrain", "hills", "--relocations", "lift", "--out", str(tmp_path)])
    from terrainvis.relocation import available

    assert f"relocations must be drawn from {available()}" in err
    # zero is not silently replaced by the default
    assert "--points must be >= 2, got 0" in _one_line_error(capsys, 2, ["compare", "--points", "0", "--out", str(tmp_path)])
    assert "--sets must be >= 1, got 0" in _one_line_error(capsys, 2, ["compare", "--sets", "0", "--out", str(tmp_path)])
    assert "levels must be at most 6" in _one_line_error(capsys, 2, ["compare", "--levels", "7", "--out", str(tmp_path)])


def test_compare_output_path_problems(tmp_path, capsys):
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    assert "is an existing file" in _one_line_error(capsys, 2, ["compare", *SMALL, "--out", str(a_file)])
    assert "which is a file" in _one_line_error(capsys, 2, ["compare", *SMALL, "--out", str(a_file / "sub")])
    (tmp_path / "run" / "results.csv").mkdir(parents=True)
    assert "is a folder" in _one_line_error(capsys, 2, ["compare", *SMALL, "--out", str(tmp_path / "run")])
    assert a_file.read_text() == "x"


@pytest.mark.slow
def test_unreachable_scheduler_is_one_line(tmp_path, capsys):
    pytest.importorskip("distributed", reason="the dask extra is not installed")
    err = _one_line_error(capsys, 2, ["compare", *SMALL, "--scheduler", "tcp://127.0.0.1:9", "--out", str(tmp_path)])
    assert "could not be reached" in err


def test_no_counted_pair_says_why(tmp_path, capsys):
    code = main(["compare", *SMALL, "--max-distance", "0.001", "--no-plots", "--out", str(tmp_path)])
    assert code == 1
    assert "no pair was counted" in capsys.readouterr().err


def test_info(capsys):
    assert main(["info", "jacksboro"]) == 0
    out = capsys.readouterr().out
    assert "120 x 120" in out and "1:        3,600 vertices" in out


def test_info_and_nodata_options_on_a_dem_with_holes(tmp_path, capsys):
    path = shared_dem_path("mount_st_helens_wa")
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "4,151 cells (2.71 %)" in out and "EPSG:26710" in out
    err = _one_line_error(capsys, 2, ["simplify", str(path), "-m", "lls", "-l", "1", "-o", str(tmp_path / "x.npz")])
    assert "NaN" in err and "fill_nodata" in err
    assert main(["simplify", str(path), "-m", "lls", "-l", "1", "--fill", "nearest", "-o", str(tmp_path / "x.npz")]) == 0
    assert main(["simplify", str(path), "-m", "lls", "-l", "1", "--crop-valid", "-o", str(tmp_path / "y.npz")]) == 0


def test_simplify_writes_grids_and_meshes(tmp_path, capsys):
    from simplifiers import simplify

    from terrainvis import bundled_terrain, load_terrain

    T = bundled_terrain("ridges")
    assert main(["simplify", "ridges", "-m", "lls", "-l", "2", "-o", str(tmp_path / "r.npz"),
                 "--option", "weights=derived"]) == 0
    out = capsys.readouterr().out
    assert "900 vertices (30 x 30 grid)" in out and "max error" in out
    np.testing.assert_array_equal(load_terrain(tmp_path / "r.npz").z, simplify(T, "lls", 2, weights="derived").z)
    assert main(["simplify", "ridges", "-m", "greedy-insertion", "-l", "3", "-o", str(tmp_path / "r.ply")]) == 0
    import trimesh

    mesh = trimesh.load(tmp_path / "r.ply", process=False)
    assert len(mesh.vertices) == 225
    assert main(["simplify", "ridges", "-m", "greedy-insertion", "-l", "3", "-o", str(tmp_path / "r_tin.npz")]) == 0
    assert load_terrain(tmp_path / "r_tin.npz").n_vertices == 225
    err = _one_line_error(capsys, 2, ["simplify", "ridges", "-m", "qec", "-o", str(tmp_path / "q.xyz")])
    assert "-o must end in one of ['.tif', '.tiff', '.asc', '.npz', '.npy', '.ply'" in err and "q.xyz" in err
    err = _one_line_error(capsys, 2, ["simplify", "ridges", "-m", "lls", "-o", str(tmp_path / "q.npz"), "--option", "x"])
    assert "--option must be KEY=VALUE" in err
    err = _one_line_error(capsys, 2, ["simplify", "ridges", "-m", "lls", "-o", str(tmp_path / "q.npz"),
                                      "--option", "weights=bogus"])
    assert "weights must be one of" in err


def test_simplify_a_tin_to_a_raster_samples_it_at_the_dems_samples(tmp_path, capsys):
    """A TIN written as .tif / .asc is the TIN's surface at the DEM's own samples, with its transform."""
    from simplifiers import simplify

    from terrainvis import load_terrain, sample_dem, save_terrain

    dem = save_terrain(sample_dem("jacksboro").crop(rows=(0, 60), cols=(0, 80)), tmp_path / "dem.tif")
    T = load_terrain(dem)
    tin = simplify(T, "greedy-insertion", 3)
    for suffix in (".tif", ".asc"):
        out = tmp_path / f"gi{suffix}"
        assert main(["simplify", str(dem), "-m", "greedy-insertion", "-l", "3", "-o", str(out)]) == 0
        back = load_terrain(out)
        assert back.shape == T.shape
        np.testing.assert_allclose(back.xs, T.xs, rtol=0, atol=1e-6 * abs(T.dx))
        np.testing.assert_allclose(back.ys, T.ys, rtol=0, atol=1e-6 * abs(T.dy))
        X, Y = np.meshgrid(T.xs, T.ys)
        want = tin.height_at(np.column_stack([X.ravel(), Y.ravel()])).reshape(T.shape)  # the reference: the TIN itself
        tol = 1e-3 if suffix == ".asc" else 1e-4 * float(np.nanmax(np.abs(want)))  # .asc: text; .tif: float32
        np.testing.assert_allclose(back.z, want, rtol=0, atol=tol)
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize("method", ["lls", "greedy-insertion"])
def test_simplify_to_a_target_error(tmp_path, capsys, method):
    from terrainvis import bundled_terrain, load_terrain, vertical_errors

    T = bundled_terrain("hills")
    out = tmp_path / "s.npz"
    assert main(["simplify", "hills", "-m", method, "--max-error", "2.5", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    # a regular method lands on a level; an irregular one has none, only the target
    assert (f"{method} level " in printed) if method == "lls" else (f"{method} max error <= 2.5:" in printed), printed
    S = load_terrain(out)
    worst, _ = vertical_errors(T, S)  # measured again, independently of what simplify recorded
    assert worst <= 2.5 + 1e-9
    assert S.attrs["n_vertices"] < T.size
    # a finer limit than needed is kept: --max-error with -l stops at that level at the finest
    assert main(["simplify", "hills", "-m", method, "--max-error", "0", "-l", "2", "-o", str(tmp_path / "f.npz")]) == 0
    assert load_terrain(tmp_path / "f.npz").attrs["n_vertices"] <= (T.shape[0] // 4 + 1) * (T.shape[1] // 4 + 1)
    err = _one_line_error(capsys, 2, ["simplify", "hills", "-m", method, "--max-error", "-1", "-o", str(out)])
    assert "--max-error" in err and "-1" in err


def test_los_prints_the_verdict_and_where_it_is_decided(tmp_path, capsys):
    from terrainvis import bundled_terrain, line_of_sight
    from terrainvis.visibility.profile import lowest_point

    T = bundled_terrain("ridges")
    a, b = (100.0, 200.0), (3000.0, 3300.0)
    assert main(["los", "ridges", "--from", *map(str, a), "--to", *map(str, b)]) == 0
    out = capsys.readouterr().out
    pa = np.array([[*a, T.height_at([a])[0] + 1.7]])
    pb = np.array([[*b, T.height_at([b])[0]]])
    verdict = "visible" if line_of_sight(T, pa, pb)[0] else "blocked"
    low = lowest_point(T, pa[0], pb[0])
    assert f": {verdict}; lowest clearance" in out and f"at ({low['x']:.6g}, {low['y']:.6g})" in out
    pairs = tmp_path / "pairs.csv"
    pd.DataFrame({"x1": [100.0, 50.0], "y1": [200.0, 60.0], "x2": [3000.0, 70.0], "y2": [3300.0, 80.0]}).to_csv(pairs)
    assert main(["los", "ridges", "--pairs", str(pairs)]) == 0
    assert capsys.readouterr().out.count("lowest clearance") == 2
    err = _one_line_error(capsys, 2, ["los", "ridges", "--from", "0", "0", "--to", "1e7", "0"])
    assert "(10000000, 0) lies outside the DEM's footprint x [0, 3570], y [0, 3570] (or on nodata)" in err
    assert "give --from X Y and --to X Y" in _one_line_error(capsys, 2, ["los", "ridges", "--from", "0", "0"])


def test_missing_dem_file(capsys):
    assert "does not exist" in _one_line_error(capsys, 2, ["info", "no/such/dem.tif"])


def test_viewshed_writes_rasters_aligned_with_the_dem(tmp_path, capsys):
    rasterio = pytest.importorskip("rasterio", reason="the geo extra is not installed")
    from terrainvis import load_dem, load_terrain, viewshed

    dem = shared_dem_path("green_mountains_vt", ".tif")
    obs = ["675000", "4887000"]
    assert main(["viewshed", str(dem), "--observer", *obs, "-o", str(tmp_path / "v.tif")]) == 0
    assert "visible" in capsys.readouterr().out
    expected = viewshed(load_dem(dem), (675000.0, 4887000.0))
    with rasterio.open(tmp_path / "v.tif") as out, rasterio.open(dem) as src:
        assert out.crs == src.crs and out.transform == src.transform and out.shape == src.shape
        np.testing.assert_array_equal(out.read(1)[::-1], expected.astype(np.uint8))  # north-up rows
    assert main(["viewshed", str(dem), "--observer", *obs, "--height", "10", "-o", str(tmp_path / "v.npz")]) == 0
    saved = load_terrain(tmp_path / "v.npz")
    np.testing.assert_array_equal(saved.z, viewshed(load_dem(dem), (675000.0, 4887000.0), observer_height=10.0))
    assert saved.attrs["viewshed_observer_height"] == 10.0
    assert main(["viewshed", "hills", "--observer", "900", "900", "-o", str(tmp_path / "v.png")]) == 0
    assert (tmp_path / "v.png").stat().st_size > 1000
    err = _one_line_error(capsys, 2, ["viewshed", str(dem), "--observer", "0", "0", "-o", str(tmp_path / "w.tif")])
    assert "--observer (0, 0) lies outside the DEM's footprint x [664737, 685977], y [4878949, 4895779] (EPSG:26918)" in err
    assert "-o must end in .tif, .npz or .png" in _one_line_error(
        capsys, 2, ["viewshed", "hills", "--observer", "900", "900", "-o", str(tmp_path / "v.txt")])


def test_compare_viewsheds(tmp_path, capsys):
    assert main(["compare", "--terrain", "hills", "--levels", "1", "--methods", "lls", "--measure", "viewshed",
                 "--observers", "2", "--offset", "1.7", "--workers", "1", "--repeats", "1", "--no-plots",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "Viewsheds: cells whose verdict survives" in out and "The paper side by side" not in out
    assert len(pd.read_csv(tmp_path / "results.csv")) == 2 * 4  # 2 observers x the 4 default relocations


def test_warnings_are_one_line(tmp_path, capsys):
    """An even-sized grid's LLS result is rectilinear: writing it to .tif resamples, with one warning line."""
    from terrainvis import bundled_terrain, save_dem

    dem = tmp_path / "even.npz"
    save_dem(bundled_terrain("hills").crop(rows=(0, 40), cols=(0, 40)), dem)
    assert main(["simplify", str(dem), "-m", "lls", "-l", "1", "-o", str(tmp_path / "s.tif")]) == 0
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("terrainvis simplify: warning: .tif needs a uniform grid"), err
    # the errors of what was written are printed too, measured on the file against the DEM
    from terrainvis import load_terrain, vertical_errors

    worst, rms = vertical_errors(load_terrain(dem), load_terrain(tmp_path / "s.tif"))
    assert f"as written (resampled onto a uniform grid): max error {worst:.4g}, RMS error {rms:.4g}" in captured.out
