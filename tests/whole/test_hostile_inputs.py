"""What a new and a hostile user broke (issue 31): each case fails on the code before its fix.

The data-loss cases (a failed write, --overwrite) are in test_failed_writes.py and
test_outputs.py; these are the wrong answers, refused files and misleading tables.
"""

from __future__ import annotations

import pytest

import simplifiers
from terrainvis import bundled_terrain, compare, save_terrain
from terrainvis.cli import main
from terrainvis.experiment import report

from conftest import shared_dem_path


def _run(capsys, argv):
    capsys.readouterr()
    code = main([str(a) for a in argv])
    io = capsys.readouterr()
    return code, io.out, io.err


# ---------------------------------------------------------------------- 2: as-written check of a raster
@pytest.mark.parametrize("method", ["simple", "gls", "lls", "feature"])
@pytest.mark.parametrize("terrain, suffix", [("hills", ".tif"), ("mesas", ".asc"), ("jacksboro", ".tif")])
def test_a_simplified_raster_is_written_and_checked_without_a_false_error(tmp_path, capsys, method, terrain, suffix):
    pytest.importorskip("rasterio")
    code, out, err = _run(capsys, ["simplify", terrain, "-m", method, "-l", 2, "-o", tmp_path / f"s{suffix}"])
    assert code == 0, err
    assert "as written (resampled onto a uniform grid): max error" in out and "error:" not in err


def test_a_lon_lat_dem_simplified_to_asc_reads_back_within_millimetres(tmp_path, capsys):
    pytest.importorskip("rasterio")
    dem = shared_dem_path("jacksboro_fault_tn")
    code, out, err = _run(capsys, ["simplify", dem, "-m", "lls", "-l", 2, "--fill", "nearest", "-o",
                                   tmp_path / "j.asc"])
    assert code == 0, err
    assert "as written" in out


# ---------------------------------------------------------------------- 5: every format the toolkit writes is read
def test_commands_read_the_meshes_simplify_writes(tmp_path, capsys):
    for suffix in (".ply", ".obj", ".stl"):
        mesh = tmp_path / f"s{suffix}"
        assert _run(capsys, ["simplify", "hills", "-m", "greedy-insertion", "-l", 2, "-o", mesh])[0] == 0
        code, out, err = _run(capsys, ["info", mesh])
        assert code == 0 and out.startswith(f"s: TIN of 900 vertices"), err
        code, out, err = _run(capsys, ["los", mesh, "--from", 500, 500, "--to", 3000, 3000])
        assert code == 0 and ("visible" in out or "blocked" in out), err
        pts = tmp_path / "p.csv"
        pts.write_text("x,y\n600,600\n1800,2400\n")
        code, out, err = _run(capsys, ["relocate", "hills", "--simplified", mesh, "--points", pts, "--how", "full",
                                       "-o", tmp_path / f"r{suffix}.csv"])
        assert code == 0, err
    code, out, err = _run(capsys, ["info", tmp_path / "s.ply", "--fill", "nearest"])
    assert code == 2 and err.strip() == ("terrainvis info: error: --fill works on a grid DEM, and "
                                         f"'{tmp_path / 's.ply'}' is a mesh (a TIN)")


# ---------------------------------------------------------------------- 8: tables named by the paper's levels
def test_tables_are_numbered_by_level_as_the_paper_numbers_them():
    df = compare(["hills"], methods=["lls"], levels=[1, 3], n_points=10, n_sets=1, relocations=["full", "half"],
                 repeats=1, workers=1)
    tables = report.paper_tables(df)
    assert [k for k in tables if k.startswith(("Table", "Level"))] == ["Table 1", "Table 3", "Table 4"]
    assert tables["Table 3"].attrs["title"].startswith("Table 3: accuracy (%) at level 3 (1.5%)")
    deep = compare(["hills"], methods=["lls"], levels=[4], n_points=10, n_sets=1, relocations=["full"], repeats=1,
                   workers=1)
    assert "Level 4" in report.paper_tables(deep) and "Table 1" not in report.paper_tables(deep)


# ---------------------------------------------------------------------- 14: the calibrated relocation alone
def test_a_run_without_the_papers_relocations_reports_what_it_has(tmp_path, capsys):
    argv = ["compare", "--terrain", "hills", "--methods", "lls", "greedy-insertion", "--levels", 2, "--points", 15,
            "--sets", 1, "--relocations", "calibrated", "--partners", 128, "--workers", 1, "--no-plots",
            "--out", tmp_path / "c"]
    code, out, err = _run(capsys, argv)
    assert code == 0, err
    tables = (tmp_path / "c" / "tables.md").read_text()
    assert "| lls | 2 | 6.25 |" in tables  # the cost table is there
    assert "needs the paper's relocations (identity, full, half); this run has calibrated" in tables
    assert _run(capsys, argv[:-2] + ["--out", tmp_path / "c", "--resume"])[0] == 0


# ---------------------------------------------------------------------- 1: heights float64 cannot resolve
def test_heights_beyond_what_float64_resolves_are_refused(tmp_path, capsys):
    import numpy as np

    from terrainvis import line_of_sight, viewshed, visibility_matrix

    g = bundled_terrain("hills")
    code, out, err = _run(capsys, ["los", "hills", "--from", 500, 500, "--to", 3000, 3000, "--height", "1e9"])
    assert code == 0 and "visible" in out  # high, still resolved: the answer is right
    for flag in ("--height", "--target-height"):
        for value in ("1e20", "1e300"):
            code, out, err = _run(capsys, ["los", "hills", "--from", 500, 500, "--to", 3000, 3000, flag, value])
            assert code == 2 and err.startswith(f"terrainvis los: error: {flag} must be within [0, 2.27e+10] for "
                                                "this terrain") and "\n" not in err.strip() and "overflow" not in err
    code, out, err = _run(capsys, ["viewshed", "hills", "--observer", 500, 500, "--height", "1e20", "-o",
                                   tmp_path / "v.tif"])
    assert code == 2 and "--height must be within" in err and not (tmp_path / "v.tif").exists()
    with pytest.raises(ValueError, match=r"a has 1 point\(s\) at heights float64 cannot resolve"):
        line_of_sight(g, [[500.0, 500.0, 1e20]], [[3000.0, 3000.0, 300.0]])
    with pytest.raises(ValueError, match="points has 1 point"):
        visibility_matrix(g, np.array([[500.0, 500.0, 300.0], [600.0, 600.0, -1e20]]))
    with pytest.raises(ValueError, match="observer_height must be within"):
        viewshed(g, (500.0, 500.0), observer_height=1e20)
    with pytest.raises(ValueError, match=r"offset must be within \[0, .*\(terrain 'hills'\)"):
        compare(["hills"], methods=["lls"], levels=[1], offset=1e20, workers=1)


# ---------------------------------------------------------------------- 21: one convention for "no error"
def test_no_error_is_missing_in_the_frame_and_in_the_csv(tmp_path):
    import pandas as pd

    df = compare(["hills"], methods=["lls"], levels=[1], n_points=8, n_sets=1, relocations=["full"], repeats=1,
                 workers=1, out_csv=tmp_path / "r.csv")
    back = pd.read_csv(tmp_path / "r.csv")
    assert df["error"].isna().all() and back["error"].isna().all()
    assert len(df[df.error.isna()]) == len(back[back.error.isna()]) == len(df)


# ---------------------------------------------------------------------- 16: workers that die, from the command line
def test_dead_workers_are_one_line_on_the_command_line(tmp_path):
    import os
    import subprocess
    import sys
    import textwrap

    info = tmp_path / "dying-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: dying\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[terrainvis.simplifiers]\ndying = dying_method:METHOD\n")
    (tmp_path / "dying_method.py").write_text(textwrap.dedent('''
        import os
        from simplifiers import Method

        def build(grid, n_vertices):
            os._exit(3)  # a worker killed mid-unit (out of memory, a segfault in a library)

        METHOD = Method("dying", "irregular", __name__, "build", "a method whose worker dies", default=False)
    '''))
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    r = subprocess.run([sys.executable, "-m", "terrainvis", "compare", "--terrain", "hills", "ridges", "--methods",
                        "dying", "lls", "--levels", "1", "--points", "8", "--sets", "1", "--relocations", "full",
                        "--workers", "2", "--no-plots", "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 1, r.stderr
    lines = [line for line in r.stderr.strip().splitlines() if "%|" not in line]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith("terrainvis compare: failed: the worker processes died (")
    assert "--workers 1" in lines[0] and "__main__" not in lines[0]


# ---------------------------------------------------------------------- 18, 20: refusals before numpy's own errors
def test_sizes_and_values_that_cannot_work_are_refused_by_name():
    import numpy as np

    from terrainvis import HeightGrid, TIN, sample_points, synthetic_terrain, visibility_matrix
    from terrainvis.errors import NotEnoughMemoryError

    g = bundled_terrain("hills")
    with pytest.raises(NotEnoughMemoryError, match=r"sample_points of 1,000,000,000 points needs about"):
        sample_points(g, 10**9)
    with pytest.raises(NotEnoughMemoryError, match=r"visibility_matrix of 200,000 points \(a 200,000 x 200,000"):
        visibility_matrix(g, np.tile([[100.0, 100.0, 300.0]], (200_000, 1)))
    with pytest.raises(ValueError, match="seed must be >= 0, got -1"):
        synthetic_terrain("hills", seed=-1)
    with pytest.raises(TypeError, match=r"attrs must be a dict \(name -> value\) or None, got list"):
        HeightGrid(np.zeros((2, 2)), attrs=[1])
    with pytest.raises(ValueError, match=r"z holds a height of 1e\+308, beyond \+-1e\+15"):
        HeightGrid(np.full((2, 2), 1e308))
    with pytest.raises(ValueError, match=r"vertices holds a height of -1e\+300"):
        TIN([[0.0, 0.0, -1e300], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [[0, 1, 2]])


# ---------------------------------------------------------------------- 3: partners that cannot fit
def test_partners_that_cannot_fit_are_refused_before_anything_is_allocated(tmp_path, capsys):
    pts = tmp_path / "p.csv"
    pts.write_text("x,y\n600,600\n1800,2400\n")
    code, out, err = _run(capsys, ["relocate", "hills", "-m", "lls", "-l", 1, "--points", pts, "--partners",
                                   1_000_000_000, "-o", tmp_path / "r.csv"])
    assert code == 2 and "the calibrated relocation of 2 points against 1,000,000,000 partners needs about" in err
    assert not (tmp_path / "r.csv").exists()
    code, out, err = _run(capsys, ["compare", "--terrain", "hills", "--methods", "lls", "--levels", 1, "--partners",
                                   100_000_000, "--out", tmp_path / "c"])
    assert code == 2 and "n_partners=100,000,000 (the calibrated relocation's partners) needs at least" in err
    assert not (tmp_path / "c" / "results.csv").exists()


# ---------------------------------------------------------------------- 6, 7: progress where someone watches, lines in a log
def test_progress_is_shown_on_a_terminal_and_written_as_lines_into_a_log(tmp_path, capsys):
    import subprocess
    import sys

    from terrainvis.core._progress import show_by_default

    capsys.readouterr()
    compare(["hills"], methods=["lls"], levels=[1], n_points=8, n_sets=1, relocations=["full"], repeats=1, workers=1)
    assert capsys.readouterr().err == "" and not show_by_default()  # not a terminal: tqdm's convention, nothing
    compare(["hills"], methods=["lls"], levels=[1, 2], n_points=8, n_sets=1, relocations=["full"], repeats=1,
            workers=1, progress=True)
    err = capsys.readouterr().err
    assert err.splitlines()[-1].startswith("compare: 2/2 units, ") and "\r" not in err and "\x1b" not in err
    r = subprocess.run([sys.executable, "-m", "terrainvis", "compare", "--terrain", "hills", "ridges", "--methods",
                        "lls", "simple", "--levels", "1", "--points", "8", "--sets", "1", "--relocations", "full",
                        "--workers", "2", "--no-plots", "--out", str(tmp_path / "o")], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    assert "\x1b" not in r.stderr and "\r" not in r.stderr  # a log file gets lines, not bars redrawn in place
    assert r.stderr.strip().splitlines()[-1].startswith("compare: 4/4 units, ")


def test_long_commands_say_what_they_do_on_a_terminal(tmp_path):
    import os
    import pty
    import subprocess
    import sys

    main_fd, tty = pty.openpty()  # stderr a terminal, as a user's
    try:
        r = subprocess.run([sys.executable, "-m", "terrainvis", "simplify", "hills", "-m", "qec", "-l", "2", "-o",
                            str(tmp_path / "q.ply")], stdout=subprocess.PIPE, stderr=tty, timeout=600)
        os.close(tty)
        said = b""
        while True:
            try:
                chunk = os.read(main_fd, 4096)
            except OSError:
                break
            if not chunk:
                break
            said += chunk
    finally:
        os.close(main_fd)
    assert r.returncode == 0
    assert b"terrainvis simplify: simplifying 120x120 samples with qec to level 2 ..." in said


# ---------------------------------------------------------------------- 13: the nearest sample under curvature
def test_the_nearest_sample_takes_the_pair_engines_verdict_under_curvature():
    import numpy as np

    from terrainvis import line_of_sight, viewshed

    g = bundled_terrain("hills")
    rng = np.random.default_rng(0)
    blocked = 0
    for _ in range(40):
        x, y = rng.uniform(0, 3570, 2)
        seen = viewshed(g, (x, y), observer_height=0.0, curvature=0.85714)
        c, r = int(np.argmin(np.abs(g.xs - x))), int(np.argmin(np.abs(g.ys - y)))
        eye = [[x, y, float(g.height_at([[x, y]])[0])]]
        exact = line_of_sight(g, eye, [[g.xs[c], g.ys[r], g.z[r, c]]], curvature=0.85714)[0]
        assert seen[r, c] == exact
        blocked += not exact
    assert blocked > 0  # an eye on the ground under curvature misses some of its nearest samples


# ---------------------------------------------------------------------- 15: outputs on the DEM's own lattice
def test_outputs_of_a_lon_lat_dem_carry_its_own_transform(tmp_path):
    import warnings

    import numpy as np

    rasterio = pytest.importorskip("rasterio")
    from terrainvis import load_dem, save_dem, viewshed
    from terrainvis.io import write_mask_geotiff

    dem = shared_dem_path("jacksboro_fault_tn")
    source = tuple(np.load(dem)["geotransform"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = load_dem(dem).fill_nodata("nearest")
    write_mask_geotiff(g, viewshed(g, (g.xs[200], g.ys[170])), tmp_path / "v.tif")
    with rasterio.open(tmp_path / "v.tif") as src:
        t = src.transform
    assert (t.c, t.a, t.f, t.e) == (source[0], source[1], source[3], source[5])  # bit for bit, no rounding noise
    save_dem(g, tmp_path / "d.asc")
    header = (tmp_path / "d.asc").read_text().splitlines()[:5]
    assert f"cellsize {float(source[1])!r}" in header  # square cells: cellsize, not dx and dy lines
    crop = g.crop(rows=(10, 60), cols=(20, 90))  # a window of the lattice: the cells still lie on it
    save_dem(crop, tmp_path / "c.tif")
    with rasterio.open(tmp_path / "c.tif") as src:
        assert src.transform.a == source[1] and src.transform.c == source[0] + 20 * source[1]


# ---------------------------------------------------------------------- 12: heights as GIS tools write them
def test_simplified_geotiffs_store_float32_heights_unless_asked(tmp_path, capsys):
    import numpy as np

    rasterio = pytest.importorskip("rasterio")
    from terrainvis import HeightGrid, load_dem, save_dem

    code, out, err = _run(capsys, ["simplify", "hills", "-m", "lls", "-l", 1, "-o", tmp_path / "a.tif"])
    assert code == 0 and "heights stored as float32, rounded by up to" in out
    code, out, err = _run(capsys, ["simplify", "hills", "-m", "lls", "-l", 1, "-o", tmp_path / "b.tif", "--dtype",
                                   "float64"])
    assert code == 0 and "float32" not in out
    with rasterio.open(tmp_path / "a.tif") as a, rasterio.open(tmp_path / "b.tif") as b:
        assert a.dtypes == ("float32",) and b.dtypes == ("float64",)
    g = HeightGrid(np.array([[0.1, 1000.123456789], [2.0, 3.0]]))
    exact = load_dem(save_dem(g, tmp_path / "exact.tif"))  # default: whatever keeps every height
    np.testing.assert_array_equal(exact.z, g.z)
    rounded = load_dem(save_dem(g, tmp_path / "f32.tif", dtype="float32"))
    np.testing.assert_array_equal(rounded.z, g.z.astype(np.float32).astype(np.float64))
    with pytest.raises(ValueError, match="dtype chooses how a GeoTIFF stores heights; 'x.asc' is not one"):
        save_dem(g, tmp_path / "x.asc", dtype="float32")
    with pytest.raises(ValueError, match=r"dtype must be one of \['float32', 'float64'\] or None, got 'float16'"):
        save_dem(g, tmp_path / "x.tif", dtype="float16")


# ---------------------------------------------------------------------- 20: the rest of the probe's list
def test_the_probes_small_cases_get_clear_answers(tmp_path, capsys):
    import numpy as np

    from terrainvis import HeightGrid, save_dem

    code, out, err = _run(capsys, ["los", "hills", "--from", "1e300", 500, "--to", 3000, 3000])
    assert code == 2 and "(1e+300, 500) lies outside the DEM's footprint" in err  # not 301 digits
    (tmp_path / "folder.tif").mkdir()
    code, out, err = _run(capsys, ["info", tmp_path / "folder.tif"])
    assert code == 2 and err.strip().endswith(f"DEM '{tmp_path / 'folder.tif'}' is a folder, not a DEM file")
    save_dem(HeightGrid(np.arange(4.0).reshape(2, 2)), tmp_path / "two.npz")
    code, out, err = _run(capsys, ["compare", "--terrain", tmp_path / "two.npz", "--out", tmp_path / "c"])
    assert code == 2 and "terrain 'two' (2x2) is too small to simplify: each level needs at least 3 samples" in err
    pairs = tmp_path / "p.csv"
    pairs.write_text("x1,y1,x2,y2\n")
    code, out, err = _run(capsys, ["los", "hills", "--pairs", pairs])
    assert code == 2 and out == "" and "holds no row after its header" in err
    with pytest.raises(ValueError, match="resume=True continues the run stored in out_csv; give out_csv"):
        compare(["hills"], methods=["lls"], levels=[1], resume=True, workers=1)


def test_npy_is_refused_before_simplifying_and_a_met_target_is_said_met(tmp_path, capsys):
    import time

    t0 = time.perf_counter()
    code, out, err = _run(capsys, ["simplify", "hills", "-m", "qec", "-l", 1, "-o", tmp_path / "t.npy"])
    assert code == 2 and out == "" and "a .npy file keeps only the heights" in err  # nothing was simplified
    assert time.perf_counter() - t0 < 30
    tin = simplifiers.simplify(bundled_terrain("hills"), "greedy-insertion", max_error=0.0)
    assert tin.attrs["max_error"] == 0.0 and tin.attrs["stopped_by"] == "max_error"
    assert tin.attrs["notes"] == ["max_error 0: met with 14,400 vertices (max error 0), the most the budget allows"]


def test_a_simplified_terrain_never_finished_leaves_no_temporary_file(tmp_path):
    # item 20: a worker stopped mid-write (full disk, kill) left '.NAME.XXXXXXXX.npz' in OUT/simplified
    save = tmp_path / "simplified"
    save.mkdir()
    stale = save / ".hills__lls__level1.npz.k2j4x9q1.npz"
    stale.write_bytes(b"PK\x03\x04 half a file")
    mine = [save / ".hills__lls__level1.npz.keep", save / ".notes.npz.abcdefgh.npz", save / "hills__lls__level1.npz.bak"]
    for p in mine:  # the user's own files, named alike but not a save's temporary file
        p.write_text("mine")
    df = compare(["hills"], methods=["lls"], levels=[1], n_points=8, n_sets=1, workers=1, repeats=1,
                 relocations=["identity"], save_dir=save)
    assert df["error"].isna().all()
    assert not stale.exists()
    assert all(p.read_text() == "mine" for p in mine)
    assert sorted(p.name for p in save.iterdir() if not p.name.startswith(".")) == ["hills__lls__level1.npz",
                                                                                   "hills__lls__level1.npz.bak"]


def test_file_names_that_are_not_utf8(tmp_path):
    # item 19: every command takes, reports and writes them, on a strict UTF-8 output too
    import os
    import subprocess
    import sys

    import pandas as pd

    from terrainvis import load_dem, save_dem

    if sys.platform == "win32" or os.fsencode(os.fsdecode(b"\xff")) != b"\xff":
        pytest.skip("this file system takes only Unicode names")
    raw = os.fsencode(tmp_path)
    dem = raw + b"/dem_\xff.npz"
    save_dem(bundled_terrain("hills"), os.fsdecode(dem))
    env = dict(os.environ, PYTHONIOENCODING="utf-8:strict")
    code = "import sys; from terrainvis.cli import main; sys.exit(main([a for a in sys.argv[1:]]))"

    def run(*args):
        out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, env=env, cwd=tmp_path,
                             timeout=300)
        assert out.returncode == 0, out.stderr.decode(errors="replace")
        return out.stdout

    assert b"dem_\\xff: 120x120 uniform grid" in run("info", dem)  # the label: the byte as an escape
    assert b"blocked" in run("los", dem, "--from", "300", "400", "--to", "2000", "2000")
    png, tif = raw + b"/v_\xfe.png", raw + b"/v_\xfe.tif"
    out = run("viewshed", dem, "--observer", "300", "400", "-o", tif)
    assert b"wrote " + tif in out  # the path as the user's own bytes
    run("viewshed", dem, "--observer", "300", "400", "-o", png)
    assert os.path.getsize(png) > 1000 and load_dem(os.fsdecode(tif)).shape == (120, 120)
    folder = raw + b"/out_\xfe"
    run("compare", "--terrain", dem, "--methods", "lls", "--levels", "1", "--points", "8", "--sets", "1",
        "--relocations", "identity", "--out", folder)
    df = pd.read_csv(os.fsdecode(folder + b"/results.csv"))
    assert set(df["terrain"]) == {"dem_\\xff"} and df["error"].isna().all()
