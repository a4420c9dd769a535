"""Frictions a newcomer met (issue 42), each reproduced first.

8. ``cumulative`` and ``site`` redrew their progress bars into log files (carriage
   returns and cursor escapes), where ``compare`` writes plain lines; and the first
   observer's compilation counted in the bar's rate ("22:42 left", "0.4 observers/s").
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from terrainvis import bundled_terrain, save_terrain


def _observers(path, n=12):
    rng = np.random.default_rng(0)
    xy = rng.uniform(200.0, 3300.0, (n, 2))
    path.write_text("x,y\n" + "".join(f"{x:.1f},{y:.1f}\n" for x, y in xy))
    return path


def test_progress_into_a_log_is_plain_lines(tmp_path, monkeypatch):
    from terrainvis.core import _progress

    dem = tmp_path / "hills.npz"
    save_terrain(bundled_terrain("hills"), dem)
    obs = _observers(tmp_path / "obs.csv")
    runs = {
        "cumulative viewshed": ["cumulative", str(dem), "--observers", str(obs), "--frame", "local", "-o",
                                str(tmp_path / "c.npz")],
        "candidate viewsheds": ["site", str(dem), "--grid", "20", "-k", "2", "--frame", "local"],
    }
    # a short run writes no progress line into a log
    for desc, argv in runs.items():
        with open(tmp_path / "log.txt", "w") as log:  # stderr is a file, as under nohup or a CI log
            out = subprocess.run([sys.executable, "-m", "terrainvis.cli", *argv], stderr=log, stdout=subprocess.PIPE,
                                 text=True, timeout=600)
        err = (tmp_path / "log.txt").read_text()
        assert out.returncode == 0, err
        assert "\r" not in err and "\x1b[" not in err and desc not in err, repr(err)
    # a long one (here: a line every 0 s) writes plain lines, the last one at the end
    from terrainvis import cumulative_viewshed

    monkeypatch.setattr(_progress.ProgressLines, "EVERY", 0.0)
    monkeypatch.setattr(_progress, "on_a_terminal", lambda: False)
    log = tmp_path / "api.txt"
    with open(log, "w") as fh, __import__("contextlib").redirect_stderr(fh):
        cumulative_viewshed(bundled_terrain("hills"), np.loadtxt(obs, delimiter=",", skiprows=1), progress=True)
    lines = log.read_text().splitlines()
    assert lines and all(ln.startswith("cumulative viewshed: ") for ln in lines), lines
    assert lines[-1].startswith("cumulative viewshed: 12/12 observers, ") and "\r" not in log.read_text()


# ---------------------------------------------------------------------- 4, 5, probe (e): the regression helper
def _utm_hills():
    from terrainvis import HeightGrid

    T = bundled_terrain("hills")
    return HeightGrid(T.z, 30.0, 30.0, (666000.0, 4893000.0), attrs={"crs": "EPSG:32618"})


def test_a_failing_regression_test_shows_its_message_not_the_helpers_source(tmp_path):
    test = tmp_path / "test_mine.py"
    test.write_text(
        "import simplifiers, terrainvis as tv\n"
        "from terrainvis.testing import assert_visibility_kept\n"
        "def test_coarse():\n"
        "    T = tv.bundled_terrain('hills')\n"
        "    assert_visibility_kept(T, simplifiers.simplify(T, 'simple', 4), min_accuracy=0.999, n=40)\n")
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(test)],
                         capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert out.returncode == 1, out.stdout
    assert "keeps" in out.stdout and "of the line-of-sight verdicts, below the required 99.90 %" in out.stdout
    # the helper's own lines (its checks and its call of the matrices) are not in the report
    assert "as_finite_scalar" not in out.stdout and "visibility_matrix(T, P" not in out.stdout, out.stdout


def test_positions_in_the_report_keep_their_digits():
    import pytest
    import simplifiers

    from terrainvis.testing import assert_visibility_kept

    T = _utm_hills()
    with pytest.raises(AssertionError) as info:
        assert_visibility_kept(T, simplifiers.simplify(T, "simple", 4), min_accuracy=0.999, n=40)
    text = str(info.value)
    assert "e+06" not in text and "(66" in text and ", 489" in text, text
    northing = text.split("(66", 1)[1].split(", ")[1]
    assert len(northing.replace(".", "")) >= 7, text  # to the metre at least (a tenth of a 30 m cell), not 10 m


def test_a_negative_offset_is_refused():
    import pytest
    import simplifiers

    from terrainvis.testing import assert_visibility_kept

    T = bundled_terrain("hills")
    with pytest.raises(ValueError, match=r"offset must be finite and >= 0 \(z units\), got -5.0"):
        assert_visibility_kept(T, simplifiers.simplify(T, "lls", 1), min_accuracy=0.5, n=20, offset=-5.0)


def test_evaluate_messages_keep_the_northings_digits(tmp_path):
    import pytest

    from terrainvis import HeightGrid, evaluate

    T = _utm_hills()
    short = HeightGrid.from_coords(T.z[:40], T.xs, T.ys[:40], attrs=dict(T.attrs))
    with pytest.raises(ValueError, match=r"covers y \[4893000, 4894170\], short of the DEM's \[4893000, 4896570\]"):
        evaluate(T, short, n_points=12, n_sets=1)


# ---------------------------------------------------------------------- 6: one's own method on the command line
def test_an_unknown_method_says_how_the_command_line_sees_ones_own(capsys):
    from terrainvis.cli import main

    hint = "the command line sees one through a plugin, an entry point of the group 'terrainvis.simplifiers'"
    for argv in (["simplify", "hills", "-m", "smoothed", "-l", "1", "-o", "x.npz"],
                 ["compare", "--methods", "smoothed", "--terrain", "hills"],
                 ["evaluate", "hills", "x.ply", "--against", "smoothed"]):
        capsys.readouterr()
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "'smoothed'" in err and hint in err and "examples/plugin/README.md" in err, err


def test_compare_help_lists_the_methods(capsys):
    import pytest

    import simplifiers
    from terrainvis.cli import main

    with pytest.raises(SystemExit):
        main(["compare", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    listed = text.split("one of: ", 1)[1]
    for name in simplifiers.METHODS:
        assert name in listed.replace("- ", "-"), name


# ---------------------------------------------------------------------- probe crashes: the report of any relocations
def test_the_report_works_for_every_subset_of_relocations(tmp_path, capsys):
    """``compare --relocations oracle`` alone ran every unit, then exited 2 ("attempt to get
    argmax of an empty sequence", the oracle's gap table); every subset of the relocations
    must give a report."""
    import argparse
    import itertools

    import terrainvis as tv
    from terrainvis.cli.compare import _compare_report
    from terrainvis.experiment.plan import settings_for

    from terrainvis.relocation import registry

    names = [n for n in registry.available() if n in registry.BUILTIN]  # every relocation terrainvis ships
    assert {*registry.PAPER_RELOCATIONS, registry.CALIBRATED, registry.EYE, registry.ORACLE} <= set(names)
    grids = {"hills": tv.synthetic_terrain("hills", size=33, seed=0)}
    df = tv.compare(grids, methods=["lls", "greedy-insertion"], levels=[1], n_points=8, n_sets=1, relocations=names,
                    workers=1, repeats=1)
    args = argparse.Namespace(no_plots=True)
    for k in range(1, len(names) + 1):
        for subset in itertools.combinations(names, k):
            part = df[df["relocation"].isin(subset)].reset_index(drop=True)
            settings = settings_for(grids, {"methods": ["lls", "greedy-insertion"], "levels": [1], "n_points": 8,
                                            "n_sets": 1, "relocations": list(subset)})
            out = tmp_path / "-".join(subset)
            out.mkdir()
            assert _compare_report(part, grids, settings, out, args, 0.0) == 0, subset
            assert (out / "tables.md").read_text().startswith("# terrainvis compare")
    capsys.readouterr()


# ---------------------------------------------------------------------- probe crashes: a plugin's failures
def _raising(grid, level):
    raise KeyError("no such thing")


def _exiting(grid, n_vertices):
    import sys as _sys

    _sys.exit(3)


def test_a_methods_own_failure_names_it_and_sys_exit_is_a_failure_of_its_unit():
    import pytest

    import simplifiers
    import terrainvis as tv
    from terrainvis.errors import SimplificationError

    T = tv.synthetic_terrain("hills", size=33, seed=0)
    simplifiers.register("raising", _raising, kind="regular")
    simplifiers.register("exiting", _exiting, kind="irregular")
    try:
        with pytest.raises(SimplificationError, match=r"raising failed on a \(33, 33\) grid: KeyError: 'no such thing'"):
            simplifiers.simplify(T, "raising", 1)
        with pytest.raises(SimplificationError, match=r"exiting called sys.exit\(3\) on a \(33, 33\) grid"):
            simplifiers.simplify(T, "exiting", 1)
        df = tv.compare({"hills": T}, methods=["exiting", "lls"], levels=[1], n_points=6, n_sets=1,
                        relocations=["full"], workers=1, repeats=1)
        failed = df[df["method"] == "exiting"]["error"]
        assert failed.notna().all() and failed.str.contains("sys.exit").all()
        assert df[df["method"] == "lls"]["error"].isna().all()
    finally:
        simplifiers.unregister("raising")
        simplifiers.unregister("exiting")


# ---------------------------------------------------------------------- probe wrong answers (a)
def test_evaluate_measures_the_surface_it_reads_not_the_errors_its_file_records(tmp_path):
    """A terrainvis PLY with every height raised 50 m still showed its stored max error (0.90 m)."""
    import simplifiers
    import terrainvis as tv
    from terrainvis import TIN, evaluate, load_terrain

    T = tv.synthetic_terrain("hills", size=33, seed=0)
    S = simplifiers.simplify(T, "greedy-insertion", 2)
    raised = TIN(S.vertices + [0.0, 0.0, 50.0], S.faces, attrs=dict(S.attrs))  # the stored errors kept
    tv.save_terrain(raised, tmp_path / "raised.ply")
    assert load_terrain(tmp_path / "raised.ply").attrs["max_error"] == S.attrs["max_error"]
    for given in (raised, tmp_path / "raised.ply"):
        df = evaluate({"hills": T}, given, name="raised", n_points=6, n_sets=1, relocations=["full"])
        assert df["max_error"].iloc[0] >= 50.0 - 1e-9 and df["rms_error"].iloc[0] > 49.0, df[["max_error", "rms_error"]]


# ---------------------------------------------------------------------- probe messages
def test_the_command_line_names_its_flags_not_python_keywords(capsys):
    from terrainvis.cli import main

    for argv, expected in ((["compare", "--terrain", "hills", "--points", "1"], "--points must be >= 2, got 1"),
                           (["compare", "--terrain", "hills", "--sets", "0"], "--sets must be >= 1, got 0"),
                           (["evaluate", "hills", __file__, "--points", "1"], "--points must be >= 2, got 1")):
        capsys.readouterr()
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.endswith(expected), err


def test_heights_no_float64_resolves_blame_the_terrain_not_the_height():
    """A DEM whose heights float64 cannot resolve against its scale said "--height must be
    within [2.42e+08, -2.42e+08]": a reversed interval, blaming the height."""
    import pytest

    from terrainvis import HeightGrid, viewshed

    z = np.full((20, 20), 1e12)
    z[5, 5] += 1e4
    g = HeightGrid(z, 1.0, 1.0)
    with pytest.raises(ValueError) as info:
        viewshed(g, (10.0, 10.0), observer_height=1.7)
    text = str(info.value)
    assert "the terrain's heights (up to |z| = 1e+12)" in text and "must be within" not in text, text


def test_a_crs_it_cannot_write_fails_before_the_viewshed_in_one_line(tmp_path):
    """A CRS the GeoTIFF writer cannot read failed only after the viewshed was computed (and
    PROJ printed its own two lines beside the message)."""
    import terrainvis as tv

    g = tv.bundled_terrain("hills")
    dem = tmp_path / "bad_crs.npz"
    tv.save_terrain(tv.HeightGrid(g.z, 30.0, 30.0, (500000.0, 4000000.0), attrs={"crs": "EPSG:99999999"}), dem)
    # the viewshed of the DEM (not the 3 x 3 one that loads the kernels) must not run
    guard = (
        "import sys\n"
        "from terrainvis.visibility.viewsheds import sweep\n"
        "real = sweep._viewshed\n"
        "def computed(t, *a, **k):\n"
        "    assert t.size <= 9, 'the viewshed was computed before the output was checked'\n"
        "    return real(t, *a, **k)\n"
        "sweep._viewshed = computed\n"
        "from terrainvis.cli import main\n"
        "sys.exit(main(sys.argv[1:]))\n"
    )
    for argv in (["viewshed", str(dem), "--observer", "501000", "4001000", "-o", str(tmp_path / "v.tif")],
                 ["cumulative", str(dem), "--observers", str(_observers(tmp_path / "o.csv")), "--frame", "local",
                  "-o", str(tmp_path / "c.tif")]):
        out = subprocess.run([sys.executable, "-c", guard, *argv], capture_output=True, text=True, timeout=300)
        assert out.returncode == 2, out.stderr
        lines = out.stderr.strip().splitlines()
        assert len(lines) == 1 and "names an EPSG code that rasterio does not know" in lines[0], out.stderr


def test_a_vertical_link_has_no_fresnel_zone_over_the_terrain():
    import warnings

    import pytest

    import terrainvis as tv

    g = tv.bundled_terrain("hills")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's "divide by zero" leaked from the command line
        with pytest.raises(ValueError, match="a and b must be apart horizontally, got a vertical link"):
            tv.fresnel_clearance(g, [500.0, 500.0, 330.0], [500.0, 500.0, 400.0], 900e6)


def test_compare_refuses_more_sited_observers_than_candidates(capsys):
    from terrainvis.cli import main

    assert main(["compare", "--terrain", "hills", "--measure", "viewshed", "--siting", "1000", "--out", "/nonexistent"
                 "/run"]) == 2
    err = capsys.readouterr().err.strip()
    assert "siting must be at most the siting candidates of terrain 'hills', 64" in err and "\n" not in err, err


def test_a_broken_plugins_warning_is_one_line_in_every_command(tmp_path):
    """simplify, evaluate and relocate build their parsers from the methods: a plugin that
    failed to load warned in Python's two-line format with its install path there."""
    info = tmp_path / "broken_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: broken-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[terrainvis.simplifiers]\nbroken = no_such_module_here:METHOD\n")
    env = dict(__import__("os").environ, PYTHONPATH=str(tmp_path))
    for argv in (["simplify", "hills", "-m", "lls", "-l", "1", "-o", str(tmp_path / "s.npz")],
                 ["info", "hills"]):
        out = subprocess.run([sys.executable, "-m", "terrainvis.cli", *argv], capture_output=True, text=True,
                             env=env, timeout=300)
        assert out.returncode == 0, out.stderr
        warned = [ln for ln in out.stderr.splitlines() if "broken" in ln]
        assert warned and all(ln.startswith(f"terrainvis {argv[0]}: warning: simplifier plugin 'broken'")
                              for ln in warned), out.stderr
        assert "warnings.warn" not in out.stderr and ".py:" not in out.stderr, out.stderr


# ---------------------------------------------------------------------- probe wrong answers (d)
def test_a_ply_read_with_other_counts_than_its_header_declares_is_refused(tmp_path, monkeypatch):
    """A PLY whose header declares more vertices than it holds was read (trimesh took face lines
    for vertices) and scored with --repair. Here trimesh is made to read fewer vertices than the
    header of a good file declares, as it did."""
    import pytest
    import trimesh

    import simplifiers
    import terrainvis as tv

    S = simplifiers.simplify(tv.bundled_terrain("hills"), "greedy-insertion", 3)
    tv.save_terrain(S, tmp_path / "s.ply")
    assert tv.load_terrain(tmp_path / "s.ply").n_vertices == S.n_vertices  # a whole file reads
    real = trimesh.load

    def short(*a, **k):
        m = real(*a, **k)
        return trimesh.Trimesh(m.vertices[:-3], m.faces[(m.faces < len(m.vertices) - 3).all(axis=1)], process=False)

    monkeypatch.setattr(trimesh, "load", short)
    with pytest.raises(ValueError, match=rf"its header declares {S.n_vertices} vertices and {S.n_faces} faces, but "
                                         rf"{S.n_vertices - 3} vertices and \d+ faces were read"):
        tv.load_terrain(tmp_path / "s.ply")


# ---------------------------------------------------------------------- 2, 3: what evaluate changes in a mesh
def _meshes(tmp_path):
    import simplifiers
    import terrainvis as tv

    T = tv.bundled_terrain("hills")
    S = simplifiers.simplify(T, "greedy-insertion", 2)
    tv.save_terrain(S, tmp_path / "ccw.ply")
    tv.save_terrain(tv.TIN(S.vertices, S.faces[:, [0, 2, 1]]), tmp_path / "cw.ply")  # rows going down
    v = S.vertices.copy()
    border = np.flatnonzero((v[:, 0] == v[:, 0].max()) & (v[:, 1] > v[:, 1].min()) & (v[:, 1] < v[:, 1].max()))
    v[border[0], 0] -= 200.0  # a border vertex drifted inside
    tv.save_terrain(tv.TIN(v, S.faces), tmp_path / "drifted.ply")
    return T, S


def test_a_mesh_wound_clockwise_is_named_as_such_and_measured_as_its_counter_clockwise_twin(tmp_path):
    """pydelatin's TIN written with rows going down was "11398 of 11,398 faces fold over"."""
    from terrainvis import evaluate
    from terrainvis.core.repair import height_field_problems
    from terrainvis.io import load_terrain

    T, S = _meshes(tmp_path)
    problems = height_field_problems(load_terrain(tmp_path / "cw.ply"), T)
    assert problems[0].startswith(f"every face ({S.n_faces:,}) is wound clockwise") and "fold over" not in problems[0]
    kw = dict(n_points=12, n_sets=1, relocations=["full"])
    cw = evaluate({"hills": T}, tmp_path / "cw.ply", name="m", **kw)
    ccw = evaluate({"hills": T}, tmp_path / "ccw.ply", name="m", **kw)
    same = ["accuracy", "n_pairs", "agree_visible", "max_error", "rms_error", "n_vertices"]
    assert cw[same].equals(ccw[same])
    assert cw["repair"].iloc[0] == "faces reversed (the mesh was wound clockwise)" and ccw["repair"].isna().all()


def test_every_problem_is_named_and_a_repair_is_said_and_recorded(tmp_path, capsys):
    import pandas as pd

    from terrainvis.cli import main

    _meshes(tmp_path)
    argv = ["evaluate", "hills", str(tmp_path / "drifted.ply"), "--points", "8", "--sets", "1", "--relocations",
            "full"]
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "more problem" not in err and err.count(";") >= 2 and "boundary edges lie off" in err, err
    assert main(argv + ["--repair", "--out", str(tmp_path / "o"), "--no-plots"]) == 0
    err = capsys.readouterr().err
    line = "hills: drifted: changed to be measured: 1 boundary vertices snapped onto the sides (by up to 200)"
    assert line in err, err
    rows = pd.read_csv(tmp_path / "o" / "results.csv")
    assert rows["repair"].iloc[0] == line.split("measured: ")[1] and rows["repair_max_snap"].iloc[0] == 200.0
    assert "### Meshes changed to be measured" in (tmp_path / "o" / "tables.md").read_text()


# ---------------------------------------------------------------------- 10: smaller
def test_float32_heights_stored_exactly_say_so_not_rounded_by_up_to_0(tmp_path, capsys):
    import terrainvis as tv
    from terrainvis.cli import main

    g = tv.bundled_terrain("hills")
    dem = tmp_path / "d32.npz"
    tv.save_terrain(tv.HeightGrid(g.z.round(), 30.0, 30.0), dem)  # whole metres: every simplify-by-simple height is exact
    capsys.readouterr()
    assert main(["simplify", str(dem), "-m", "simple", "-l", "1", "-o", str(tmp_path / "s.tif")]) == 0
    out = capsys.readouterr().out
    assert "rounded by up to 0" not in out and "heights stored as float32, exactly" in out, out


# ---------------------------------------------------------------------- probe wrong answers (c)
def test_a_raster_terrainvis_wrote_is_not_padded_for_its_rounding_noise(tmp_path, capsys):
    """evaluate padded a 30 x 30 .tif by a whole row (930 vertices) for 4.5e-13 of noise in its
    transform; the size columns and --against's budgets were off by 1.7-3.3 %."""
    import terrainvis as tv
    from terrainvis.cli import main

    capsys.readouterr()
    assert main(["simplify", "hills", "-m", "lls", "-l", "2", "-o", str(tmp_path / "s.tif")]) == 0
    s = tv.load_dem(tmp_path / "s.tif")
    assert s.shape == (30, 30) and (s.ys[0] != 0.0 or s.ys[-1] != 3570.0 or s.xs[-1] != 3570.0)  # the noise is there
    df = tv.evaluate("hills", tmp_path / "s.tif", name="s", n_points=8, n_sets=1, relocations=["full"])
    assert int(df["n_vertices"].iloc[0]) == 900, df["n_vertices"]


# ---------------------------------------------------------------------- probe messages: repeated and split vertices
def test_a_mesh_written_face_by_face_is_merged_and_split_vertices_are_named(tmp_path):
    """Meshes with duplicated or split vertices were refused, even with --repair, as "not a
    disk" without saying why (STL's reader merges duplicates, PLY and OBJ do not)."""
    import pytest

    import simplifiers
    import terrainvis as tv

    T = tv.bundled_terrain("hills")
    S = simplifiers.simplify(T, "greedy-insertion", 3)
    v = S.vertices[S.faces.reshape(-1)]
    f = np.arange(v.shape[0]).reshape(-1, 3)  # every face its own three vertices
    for suffix in (".ply", ".obj"):
        tv.save_terrain(tv.TIN(v, f), tmp_path / f"faces{suffix}")
        kw = dict(n_points=10, n_sets=1, relocations=["full"])
        loose = tv.evaluate({"hills": T}, tmp_path / f"faces{suffix}", name="m", **kw)
        whole = tv.evaluate({"hills": T}, S, name="m", **kw)
        assert loose["n_vertices"].iloc[0] == S.n_vertices and loose["accuracy"].equals(whole["accuracy"])
        assert loose["repair"].iloc[0].startswith(f"{v.shape[0] - S.n_vertices} repeated vertices merged")
    split = v.copy()
    split[::3, 2] += 1e-3 * (np.arange(v.shape[0] // 3) % 2)  # same x, y, another height
    with pytest.raises(ValueError, match=r"vertices share their x, y with another vertex \(the first at .*split "
                                         r"vertices \(one per face\) must be merged"):
        tv.evaluate({"hills": T}, tv.TIN(split, f), name="s", n_points=8, n_sets=1, relocations=["full"])


# ---------------------------------------------------------------------- probe crashes: --network's memory
def test_network_memory_is_checked_before_the_viewsheds_with_what_the_format_takes(tmp_path, capsys, monkeypatch):
    """--network's check assumed 128 bytes a pair where a GeoPackage takes about 1.3 kB: the run
    failed after all its viewsheds."""
    from terrainvis.cli import main
    from terrainvis.core import memory

    obs = _observers(tmp_path / "obs.csv", n=1000)
    monkeypatch.setattr(memory, "available_memory", lambda: 200 << 20)
    capsys.readouterr()
    code = main(["cumulative", "hills", "--observers", str(obs), "--frame", "local", "-o", str(tmp_path / "c.npz"),
                 "--network", str(tmp_path / "n.gpkg")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "--network 'n.gpkg': the intervisibility network of 1,000 observers (499,500 pairs) needs" in err
    assert not (tmp_path / "c.npz").exists()  # refused before the viewsheds and their counts
