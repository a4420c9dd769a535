"""terrainvis.evaluate and terrainvis evaluate: simplifications made elsewhere, measured as compare measures.

The reference is compare itself: a built-in method's TIN written to a mesh file and
evaluated under the same terrain name and seed gives compare's rows for that method, to
the last pair. Then the frame (the DEM's CRS or the terrain's), the height-field checks
and the repair, a raster resampled elsewhere, the command line and the regression helper
``terrainvis.testing.assert_visibility_kept``.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

import simplifiers
from terrainvis import TIN, HeightGrid, bundled_terrain, compare, evaluate, sample_dem, save_terrain, synthetic_terrain
from terrainvis.cli import main
from terrainvis.core._positions import PositionFrame
from terrainvis.testing import assert_visibility_kept

KW = dict(n_points=16, n_sets=2, seed=7, relocations=["identity", "full", "half"], repeats=1)
SAME = ["terrain", "set", "method", "kind", "level", "relocation", "accuracy", "n_pairs", "agree_visible",
        "agree_blocked", "false_visible", "false_blocked", "n_vertices", "max_error", "rms_error"]


@pytest.fixture(scope="module")
def run():
    """compare on hills, irregular and regular methods at levels 2 and 3 (their simplified terrains saved)."""
    import tempfile
    from pathlib import Path

    folder = Path(tempfile.mkdtemp())
    df = compare(["hills"], methods=["qec", "greedy-insertion", "lls"], levels=[2, 3], workers=1,
                 save_dir=folder, **KW)
    return df, folder


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".off", ".stl", ".glb"])
def test_a_mesh_file_of_a_method_gives_compares_rows(run, tmp_path, suffix):
    import trimesh

    df, folder = run
    from terrainvis import load_terrain

    for method in ("qec", "greedy-insertion"):
        for level in (2, 3):
            tin = load_terrain(folder / f"hills__{method}__level{level}.npz")
            path = tmp_path / f"{method}{suffix}"
            if suffix in (".ply", ".obj"):
                save_terrain(tin, path)  # terrainvis's own writer: the terrain's frame, recorded
            else:  # another tool's file: no terrainvis record, coordinates as they are (a projected DEM: native)
                trimesh.Trimesh(tin.vertices, tin.faces, process=False).export(path)
            ev = evaluate("hills", path, name=method, **KW)
            ours = df[(df["method"] == method) & (df["level"] == level)].reset_index(drop=True)
            cols = SAME if suffix in (".ply", ".obj", ".off") else [c for c in SAME if c not in ("max_error",
                                                                                               "rms_error", "kind")]
            if suffix in (".stl", ".glb"):  # float32 vertices: the same surface within float32, not the same bits
                assert (ev["accuracy"] - ours["accuracy"]).abs().max() <= 0.02
                continue
            pd.testing.assert_frame_equal(ev[cols], ours[cols])


def test_a_grid_and_a_trimesh_object_give_compares_rows(run):
    import trimesh

    df, folder = run
    from terrainvis import load_terrain

    grid = load_terrain(folder / "hills__lls__level3.npz")
    ev = evaluate({"hills": bundled_terrain("hills")}, {"lls": grid}, **KW)
    pd.testing.assert_frame_equal(ev[SAME], df[(df.method == "lls") & (df.level == 3)].reset_index(drop=True)[SAME])
    tin = load_terrain(folder / "hills__qec__level3.npz")
    ev = evaluate("hills", trimesh.Trimesh(tin.vertices, tin.faces, process=False), name="qec", **KW)
    cols = [c for c in SAME if c != "kind"]
    pd.testing.assert_frame_equal(ev[cols], df[(df.method == "qec") & (df.level == 3)].reset_index(drop=True)[cols])


def test_against_measures_built_in_methods_at_the_same_size(run):
    df, folder = run
    from terrainvis import load_terrain

    tin = load_terrain(folder / "hills__greedy-insertion__level2.npz")
    ev = evaluate("hills", tin, name="mine", against=["qec", "lls"], **KW)
    assert list(dict.fromkeys(ev["method"])) == ["qec", "lls", "mine"]
    qec = ev[ev.method == "qec"]["n_vertices"].iloc[0]  # QEC asked for the same vertex count, reached within the window
    assert abs(qec - tin.n_vertices) <= simplifiers.budget_tolerance(tin.n_vertices)
    assert set(ev[ev.method == "lls"]["level"]) == {2}  # a regular method at the nearest level
    # a label that clashes with a method measured beside it is told apart
    ev = evaluate("hills", {"qec": tin}, against=["qec"], **KW)
    assert set(ev["method"]) == {"qec", "qec-evaluated"}


def _write_obj(path, vertices, faces):
    """An OBJ as another tool writes one: full precision, no terrainvis record."""
    with open(path, "w") as fh:
        fh.writelines(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in vertices)
        fh.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)


def test_a_mesh_in_the_dems_crs_is_moved_to_the_terrains_frame(tmp_path):
    import trimesh

    T = sample_dem("jacksboro").crop(rows=(0, 60), cols=(0, 60))  # lon/lat: native is degrees
    S = simplifiers.simplify(T, "greedy-insertion", 2)
    native = S.vertices.copy()
    native[:, :2] = PositionFrame(T, "native").from_grid(native[:, :2])
    _write_obj(tmp_path / "deg.obj", native, S.faces)
    kw = dict(n_points=12, n_sets=2, relocations=["full", "half"], repeats=1)
    a = evaluate({"j": T}, tmp_path / "deg.obj", name="gi", **kw)  # another tool's file: native by default
    b = evaluate({"j": T}, S, name="gi", **kw)
    pd.testing.assert_frame_equal(a[["accuracy", "agree_visible", "n_vertices"]],
                                  b[["accuracy", "agree_visible", "n_vertices"]])
    # trimesh writes PLY vertices as float32: 0.4 m of rounding in degrees here; the edges are still found
    trimesh.Trimesh(native, S.faces, process=False).export(tmp_path / "deg32.ply")
    c = evaluate({"j": T}, tmp_path / "deg32.ply", name="gi", **kw)
    assert c["error"].isna().all() and (c["accuracy"] - b["accuracy"]).abs().max() <= 2 / c["n_pairs"].min()
    with pytest.raises(ValueError, match=r"simplified terrain 'deg' covers x \[-8[\d.]+, -8[\d.]+\].*does not overlap "
                                         r"the DEM's footprint.*pass frame='native'"):
        evaluate({"j": T}, tmp_path / "deg.obj", frame="local", **kw)
    # a mesh in local metres said to be in degrees
    _write_obj(tmp_path / "metres.obj", S.vertices, S.faces)
    with pytest.raises(ValueError, match=r"does not overlap the DEM's footprint lon \[.*pass frame='local'"):
        evaluate({"j": T}, tmp_path / "metres.obj", frame="native", **kw)


def test_a_mesh_that_is_not_a_height_field_is_refused_or_repaired():
    T = bundled_terrain("hills")
    S = simplifiers.simplify(T, "greedy-insertion", 3)
    v = S.vertices.copy()
    inner = np.flatnonzero((v[:, 0] > 500) & (v[:, 0] < 3000) & (v[:, 1] > 500) & (v[:, 1] < 3000))[0]
    v[inner, :2] += [400.0, 350.0]  # drags a vertex over its neighbours: faces fold
    folded = TIN(v, S.faces)
    kw = dict(n_points=12, n_sets=1, relocations=["full"], repeats=1)
    with pytest.raises(ValueError, match=r"simplified terrain 'simplified' is not a height field over the DEM's "
                                         r"footprint: \d+ of [\d,]+ faces fold over \(not counter-clockwise; the first "
                                         r"around \([\d.]+, [\d.]+\)\).*repair=True"):
        evaluate("hills", folded, **kw)
    fixed = evaluate("hills", folded, repair=True, **kw)
    assert fixed["error"].isna().all() and fixed["accuracy"].notna().all()
    from terrainvis import repair_tin

    repaired = repair_tin(folded, T)
    assert repaired.attrs["repair"]["repairs"] + repaired.attrs["repair"]["collapses"] >= 1
    # a corner missing and a vertex outside: named, with where
    v = S.vertices.copy()
    corner = int(np.flatnonzero((v[:, 0] == T.xs[-1]) & (v[:, 1] == T.ys[-1]))[0])
    v[corner, :2] -= [45.0, 0.0]
    with pytest.raises(ValueError, match=r"corner \(3570, 3570\) is missing"):
        evaluate("hills", TIN(v, S.faces), **kw)
    v[corner, :2] += [100.0, 0.0]
    from terrainvis.core.repair import height_field_problems

    assert "1 vertices lie outside the extent (the first at (3625, 3570))" in height_field_problems(TIN(v, S.faces), T)
    with pytest.raises(ValueError, match=r"corner \(3570, 3570\) is missing; 1 vertices lie outside the extent .*; "
                                         r"the projected area is .*; 1 boundary edges lie off"):  # every problem named
        evaluate("hills", TIN(v, S.faces), **kw)
    assert (evaluate("hills", TIN(v, S.faces), repair=True, **kw)["error"].isna()).all()


def test_a_raster_resampled_elsewhere_is_extended_to_the_footprint():
    T = bundled_terrain("hills")
    # a 2x coarser raster as gdalwarp -r average writes it: cell centres half a coarse cell inside T's
    z = T.z[:120, :120].reshape(60, 2, 60, 2).mean(axis=(1, 3))
    xs, ys = T.xs[0] + 15.0 + 60.0 * np.arange(60), T.ys[0] + 15.0 + 60.0 * np.arange(60)
    coarse = HeightGrid.from_coords(z, xs, ys)
    ev = evaluate("hills", coarse, name="average", n_points=12, n_sets=1, relocations=["full"], repeats=1)
    assert ev["error"].isna().all() and ev["accuracy"].between(0.5, 1.0).all()
    short = HeightGrid.from_coords(z[:40], xs, ys[:40])
    with pytest.raises(ValueError, match=r"covers y \[15, 2355\], short of the DEM's \[0, 3570\] by more than one "
                                         r"of its cells"):
        evaluate("hills", short, n_points=12, n_sets=1)


def test_the_command_line(run, tmp_path, capsys):
    df, folder = run
    from terrainvis import load_terrain

    save_terrain(load_terrain(folder / "hills__qec__level2.npz"), tmp_path / "q.ply")
    argv = ["evaluate", "hills", str(tmp_path / "q.ply"), "--points", "16", "--sets", "2", "--seed", "7",
            "--relocations", "identity", "full", "half", "--repeats", "1"]
    capsys.readouterr()
    assert main(argv + ["--min-accuracy", "0.5"]) == 0
    out = capsys.readouterr().out
    mean_full = 100 * df[(df.method == "qec") & (df.level == 2) & (df.relocation == "full")]["accuracy"].mean()
    assert re.search(rf"full\s+\d+\s+2\s+{mean_full:.2f}", out), out
    assert main(argv + ["--min-accuracy", "0.9999"]) == 1
    err = capsys.readouterr().err.strip()
    assert re.fullmatch(r"terrainvis evaluate: q keeps [\d.]+ % of the verdicts under '\w+', below --min-accuracy "
                        r"99.99 %( \(and \d more\))?", err), err
    assert main(argv + ["--min-accuracy", "95"]) == 2
    assert "--min-accuracy must be a share in [0, 1] (0.95 for 95 %), got 95" in capsys.readouterr().err
    # --out: results.csv and tables.md, and a second run needs --overwrite
    assert main(argv + ["--against", "lls", "--out", str(tmp_path / "o"), "--no-plots"]) == 0
    written = pd.read_csv(tmp_path / "o" / "results.csv")
    assert set(written["method"]) == {"q", "lls"} and (tmp_path / "o" / "tables.md").exists()
    capsys.readouterr()
    assert main(argv + ["--out", str(tmp_path / "o"), "--no-plots"]) == 2
    assert "holds the results of an earlier run" in capsys.readouterr().err
    # bad input: one line each
    v = load_terrain(folder / "hills__qec__level2.npz")
    verts = v.vertices.copy()
    verts[:, 0] += 1e6
    save_terrain(TIN(verts, v.faces), tmp_path / "far.ply")
    assert main(["evaluate", "hills", str(tmp_path / "far.ply")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "does not overlap the DEM's footprint" in err
    assert main(["evaluate", "hills", str(tmp_path / "nothing.ply")]) == 2
    assert "SIMPLIFIED" in capsys.readouterr().err


def test_out_csv_keeps_each_terrain_and_resume_measures_only_the_rest(run, tmp_path):
    from terrainvis import load_terrain
    from terrainvis.experiment.collect import TIMING_COLUMNS

    df, folder = run
    meshes = {m: load_terrain(folder / f"hills__{m}__level2.npz") for m in ("qec", "greedy-insertion")}
    meshes = {f"my-{m}": t for m, t in meshes.items()}
    kw = dict(against=["lls", "greedy-insertion"], **KW)
    want = evaluate({"hills": bundled_terrain("hills")}, meshes, **kw)
    keys = []

    def stop_after_two(key, rows):
        keys.append(key)
        assert list(rows["method"].unique()) == [key[1]] and len(rows) == 2 * 3  # sets x relocations
        if len(keys) == 2:
            raise RuntimeError("stop")

    out = tmp_path / "r.csv"
    with pytest.raises(RuntimeError, match="stop"):
        evaluate({"hills": bundled_terrain("hills")}, meshes, out_csv=out, on_unit=stop_after_two, **kw)
    assert keys == [("hills", "my-qec", 2), ("hills", "my-greedy-insertion", 2)]
    assert list(pd.read_csv(out)["method"].unique()) == ["my-qec", "my-greedy-insertion"]
    keys.clear()
    got = evaluate({"hills": bundled_terrain("hills")}, meshes, out_csv=out, resume=True,
                   on_unit=lambda key, rows: keys.append(key), **kw)
    # only the rest; greedy-insertion at the two meshes' sizes, both nearest level 2: two units under one key
    assert keys == [("hills", "lls", 2), ("hills", "greedy-insertion", 2), ("hills", "greedy-insertion", 2)]
    assert len(want) == 5 * 2 * 3 and sorted(want["n_vertices"][want["method"] == "greedy-insertion"].unique()) == \
        sorted(t.n_vertices for t in meshes.values())
    pd.testing.assert_frame_equal(got.drop(columns=list(TIMING_COLUMNS)), want.drop(columns=list(TIMING_COLUMNS)))
    from terrainvis.experiment.collect import COLUMNS
    from terrainvis.experiment.results import read_results

    pd.testing.assert_frame_equal(read_results(out, COLUMNS), got)  # the file holds the final table
    # another simplified terrain under the same name is another run
    changed = {**meshes, "my-qec": TIN(meshes["my-qec"].vertices + [0, 0, 1], meshes["my-qec"].faces)}
    with pytest.raises(ValueError, match=r"cannot resume .*evaluated: "):
        evaluate({"hills": bundled_terrain("hills")}, changed, out_csv=out, resume=True, **kw)
    with pytest.raises(ValueError, match="resume=True continues the run stored in out_csv"):
        evaluate("hills", meshes["my-qec"], resume=True)


def test_assert_visibility_kept_passes_and_reports():
    T = bundled_terrain("ridges")
    fine = simplifiers.simplify(T, "lls", 1)
    got = assert_visibility_kept(T, fine, min_accuracy=0.8, n=40, seed=2)
    assert got["n_pairs"] == 40 * 39 // 2 and got["accuracy"] >= 0.8
    assert got["false_visible"] + got["false_blocked"] == round((1 - got["accuracy"]) * got["n_pairs"])
    coarse = simplifiers.simplify(T, "simple", 4)
    with pytest.raises(AssertionError) as info:
        assert_visibility_kept(T, coarse, min_accuracy=0.999, n=40, seed=2, relocation="identity", worst=3)
    text = str(info.value)
    assert re.match(r"the simplification keeps [\d.]+ % of the line-of-sight verdicts, below the required 99.90 %",
                    text)
    assert "blocked pairs became visible" in text and "relocated onto it by 'identity'" in text
    worst = [line for line in text.splitlines() if line.startswith("    (")]
    assert 1 <= len(worst) <= 3 and all("clearance" in line for line in worst)
    with pytest.raises(ValueError, match=r"min_accuracy must be a share in \[0, 1\] \(0.95 for 95 %\), got 95"):
        assert_visibility_kept(T, fine, min_accuracy=95)


def test_the_terrains_own_tin_keeps_every_verdict_with_the_exact_engine(tmp_path, capsys):
    """Issue 42, wrong answer (b): the DEM's own TIN measured by evaluate kept 99.84 % of the
    verdicts, because 'auto' answers on TINs with Embree's float32 rays. engine='exact'
    (refused before: 'tin' does not run on T's grid) keeps every verdict, and the summary
    says which engine decided the TIN's verdicts."""
    T = synthetic_terrain("rough", size=48, seed=5)
    own = T.to_tin()
    kw = dict(n_points=40, n_sets=2, seed=3, relocations=["identity"], repeats=1, volume=False)
    ev = evaluate({"r": T}, {"own": own}, engine="exact", **kw)
    assert len(ev) == 2 and (ev["accuracy"] == 1.0).all() and (ev["false_visible"] == 0).all()
    save_terrain(T, tmp_path / "r.npz")
    save_terrain(own, tmp_path / "own.npz")
    base = ["evaluate", str(tmp_path / "r.npz"), str(tmp_path / "own.npz"), "--points", "40", "--sets", "2",
            "--relocations", "identity", "--no-plots", "--no-volume"]
    assert main([*base, "--out", str(tmp_path / "auto")]) == 0
    assert "verdicts on TINs by engine 'embree', not exact (--engine exact: the exact TIN clipper)" in \
        capsys.readouterr().out
    assert main([*base, "--out", str(tmp_path / "exact"), "--engine", "exact"]) == 0
    assert "predicate exact, verdicts exact," in capsys.readouterr().out
    assert "verdicts exact" in (tmp_path / "exact" / "tables.md").read_text()


@pytest.mark.parametrize("option, value, instead", [
    ("max_errors", [5.0], "terrainvis.compare(max_errors=...) budgets them"),
    ("levels", [1, 2], "at the level whose grid is closest"),
    ("methods", ["lls"], "against= measures built-in methods beside them"),
    ("cascade", True, "it simplifies nothing"),
])
def test_the_options_that_choose_what_compare_simplifies_are_refused(option, value, instead):
    # evaluate measures the terrains it is given: these options would be ignored silently
    T = bundled_terrain("hills")
    with pytest.raises(TypeError, match=rf"evaluate\(\) takes no {option}=: it measures the simplified terrains "
                                        rf"it is given; .*{re.escape(instead)}"):
        evaluate(T, T.to_tin(), **{option: value})
