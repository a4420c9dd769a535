"""Issue 42's data-loss and escape defects, each reproduced first.

(a) a method name written into a file name led outside ``--out``; (b) ``evaluate --out
DIR --overwrite`` removed the earlier run before it checked anything, and removed its own
inputs when they sat in ``DIR/simplified/``; (c) ``evaluate --out`` replaced a user's own
simplified terrain at the name it writes; (d) two outputs of one command on one path
("wrote X.npz and X.npz", the first lost); (e) the GeoPackage writer replaced the old
file before it read the new one back, and left a sqlite journal behind on a full disk.
"""

from __future__ import annotations

import dataclasses
import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import simplifiers
from terrainvis import bundled_terrain, save_terrain
from terrainvis.cli import main
from terrainvis.core.terrain import HeightGrid
from terrainvis.errors import OutputError
from terrainvis.experiment import measures
from terrainvis.experiment.units import simplified_path
from terrainvis.relocation import registry as relocations
from terrainvis.visibility import engines
from conftest import one_line_error

BAD_NAMES = ["v2/../../../escaped", "../up", "a\\b", "new\nline", "pipe|name", " evil ", "--quick", "", ".hidden",
             "x" * 65, "tab\tname", "-", 7]


_err = one_line_error  # the command must exit with the code and print one line, no traceback


# ---------------------------------------------------------------------- (a) names
def _every_other(grid, level):
    from simplifiers.levels import coarse_coords

    xs, ys = coarse_coords(grid.xs, level), coarse_coords(grid.ys, level)
    return HeightGrid.from_coords(grid.height_on_grid(xs, ys), xs, ys)


def _relocation(name):
    return dataclasses.replace(relocations.RELOCATIONS["full"], name=name)


def _engine(name):
    return dataclasses.replace(engines.ENGINES["grid"], name=name)


def _measure(name):
    return dataclasses.replace(measures.MEASURES["pairs"], name=name)


@pytest.mark.parametrize("name", BAD_NAMES)
def test_every_registry_refuses_a_name_that_is_not_a_plain_word(name):
    with pytest.raises(ValueError, match="a method name must be 1-64 characters"):
        simplifiers.register(name, _every_other, kind="regular")
    with pytest.raises(ValueError, match="a relocation name must be 1-64 characters"):
        relocations.register(_relocation(name))
    with pytest.raises(ValueError, match="an? engine name must be 1-64 characters"):
        engines.register(_engine(name))
    with pytest.raises(ValueError, match="a measure name must be 1-64 characters"):
        measures.register(_measure(name))
    assert name not in simplifiers.METHODS and name not in relocations.RELOCATIONS
    assert name not in engines.ENGINES and name not in measures.MEASURES


def test_the_names_terrainvis_ships_and_plain_ones_pass():
    from terrainvis.core.validate import entry_name

    for name in [*simplifiers.METHODS, *relocations.RELOCATIONS, *engines.ENGINES, *measures.MEASURES,
                 "v2.1", "my_method+x", "A", "x" * 64]:
        assert entry_name(name, "method") == name


def test_a_plugin_with_such_a_name_is_skipped_with_a_warning(monkeypatch):
    from importlib import metadata

    from simplifiers import registry

    class EP:
        name, value, module = "escape", "evil:METHOD", "evil"

        def load(self):
            return registry.Method("v2/../../escaped", "regular", "evil", "op", "escapes")

    monkeypatch.setattr(metadata, "entry_points", lambda group: [EP()])
    monkeypatch.setattr(registry, "PLUGIN_FAILURES", {})
    with pytest.warns(UserWarning, match=r"plugin 'escape' .*a method name must be 1-64 characters"):
        assert registry.load_plugins() == []
    assert "v2/../../escaped" not in registry.METHODS


def test_a_file_name_that_would_leave_the_folder_is_refused(tmp_path):
    assert simplified_path(tmp_path, "hills", "lls", 2) == tmp_path / "hills__lls__level2.npz"
    for method in ("v2/../../../escaped", "../up"):
        with pytest.raises(ValueError, match="would be written outside the output folder"):
            simplified_path(tmp_path, "hills", method, 1)


# ---------------------------------------------------------------------- (b), (c) evaluate --out
@pytest.fixture
def meshes(tmp_path):
    T = bundled_terrain("hills").crop(rows=(0, 33), cols=(0, 33))
    dem = tmp_path / "dem.npz"
    save_terrain(T, dem)
    good = tmp_path / "good.ply"
    save_terrain(simplifiers.simplify(T, "greedy-insertion", 2), good)
    return dem, good


ARGS = ["--points", "8", "--sets", "1", "--relocations", "full", "--repeats", "1", "--no-plots"]


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_evaluate_overwrite_keeps_the_earlier_run_until_the_new_one_exists(meshes, tmp_path, capsys, monkeypatch):
    dem, good = meshes
    out = tmp_path / "o"
    assert main(["evaluate", str(dem), str(good), "--out", str(out), *ARGS]) == 0
    before = _snapshot(out)
    assert "results.csv" in before and "tables.md" in before
    # a mistyped mesh name, a bad seed, a refused mesh: each refused, the earlier run whole
    _err(capsys, 2, ["evaluate", str(dem), str(tmp_path / "typo.ply"), "--out", str(out), "--overwrite", *ARGS])
    assert _snapshot(out) == before
    _err(capsys, 2, ["evaluate", str(dem), str(good), "--out", str(out), "--overwrite", "--seed", "-1", *ARGS])
    assert _snapshot(out) == before
    far = tmp_path / "far.ply"
    import trimesh

    m = trimesh.load(good, process=False)
    m.vertices[:, 0] += 1e6
    m.export(far)
    _err(capsys, 2, ["evaluate", str(dem), str(far), "--out", str(out), "--overwrite", *ARGS])
    assert _snapshot(out) == before
    # Ctrl-C while it measures: the earlier run whole

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr("terrainvis.experiment.evaluate._rows", interrupted)
    assert main(["evaluate", str(dem), str(good), "--out", str(out), "--overwrite", *ARGS]) == 130
    after = _snapshot(out)  # beside the earlier run, whole, the new run's rows so far (none): --resume goes on
    assert {k: v for k, v in after.items() if k in before} == before
    assert sorted(set(after) - set(before)) == ["results.partial.csv", "results.partial.settings.json"]
    monkeypatch.undo()
    # a real replacement: the new run's files, and the earlier run's files it did not write again are gone
    other = tmp_path / "other.ply"
    other.write_bytes(good.read_bytes())
    assert main(["evaluate", str(dem), str(other), "--out", str(out), "--overwrite", *ARGS]) == 0
    assert "removed the earlier run's" not in capsys.readouterr().err  # the same files, rewritten
    assert set(pd.read_csv(out / "results.csv")["method"]) == {"other"}


def _counting(monkeypatch, stop_at=None):
    """Count the terrains measured (``units.measured_rows`` calls); Ctrl-C at call ``stop_at``."""
    from terrainvis.experiment import units

    calls, real = [], units.measured_rows

    def measured(grid, simplified, base, *a, **k):
        calls.append(base["method"])
        if len(calls) == stop_at:
            raise KeyboardInterrupt
        return real(grid, simplified, base, *a, **k)

    monkeypatch.setattr(units, "measured_rows", measured)
    return calls


def test_evaluate_keeps_each_measured_terrain_and_resumes(meshes, tmp_path, capsys, monkeypatch):
    dem, good = meshes
    other = tmp_path / "other.ply"
    save_terrain(simplifiers.simplify(bundled_terrain("hills").crop(rows=(0, 33), cols=(0, 33)), "qec", 2), other)
    argv = ["evaluate", str(dem), str(good), str(other), "--against", "lls", *ARGS]
    clean = tmp_path / "clean"
    assert main([*argv, "--out", str(clean)]) == 0
    out = tmp_path / "o"
    # Ctrl-C while the second terrain is measured: the first one's rows are kept, and said where
    calls = _counting(monkeypatch, stop_at=2)
    capsys.readouterr()
    assert main([*argv, "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert f"interrupted; the terrains measured so far are in {out / 'results.partial.csv'} (--resume continues)" in err
    assert calls == ["good", "other"] and not (out / "results.csv").exists()
    assert set(pd.read_csv(out / "results.partial.csv")["method"]) == {"good"}
    # without a flag the unfinished run is named and kept
    err = _err(capsys, 2, [*argv, "--out", str(out)])
    assert "the unfinished run's results.partial.csv" in err and "--resume" in err, err
    # --resume measures only the rest, and gives the clean run's table
    monkeypatch.undo()
    calls = _counting(monkeypatch)
    assert main([*argv, "--out", str(out), "--resume"]) == 0
    assert calls == ["other", "lls"]
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in clean.iterdir())
    got, want = pd.read_csv(out / "results.csv"), pd.read_csv(clean / "results.csv")
    from terrainvis.experiment.collect import TIMING_COLUMNS

    timing = list(TIMING_COLUMNS)
    pd.testing.assert_frame_equal(got.drop(columns=timing), want.drop(columns=timing))
    # --resume of the finished run measures nothing and rewrites the same table
    calls.clear()
    assert main([*argv, "--out", str(out), "--resume"]) == 0
    assert calls == [] and not (out / "results.partial.csv").exists()
    pd.testing.assert_frame_equal(pd.read_csv(out / "results.csv"), got)


def test_evaluate_resume_refuses_a_changed_terrain_or_setting(meshes, tmp_path, capsys, monkeypatch):
    dem, good = meshes
    out = tmp_path / "o"
    argv = ["evaluate", str(dem), str(good), "--against", "lls", *ARGS, "--out", str(out)]
    _counting(monkeypatch, stop_at=2)
    assert main(argv) == 130
    monkeypatch.undo()
    before = _snapshot(out)
    err = _err(capsys, 2, [*argv, "--resume", "--seed", "3"])
    assert "cannot resume" in err and "seed: " in err, err
    import trimesh

    m = trimesh.load(good, process=False)
    m.vertices[:, 2] += 1.0  # the same name, other heights
    m.export(good)
    err = _err(capsys, 2, [*argv, "--resume"])
    assert "cannot resume" in err and "evaluated: " in err, err
    assert _snapshot(out) == before
    # --overwrite starts again; the unfinished run's files are replaced, none is left over
    assert main([*argv, "--overwrite"]) == 0
    assert not (out / "results.partial.csv").exists() and not (out / "results.partial.settings.json").exists()
    assert set(pd.read_csv(out / "results.csv")["method"]) == {"good", "lls"}
    _err(capsys, 2, argv[:-2] + ["--resume"])  # --resume without --out


def test_evaluate_overwrite_never_removes_its_inputs(meshes, tmp_path, capsys):
    dem, good = meshes
    out = tmp_path / "o"
    assert main(["evaluate", str(dem), str(good), "--out", str(out), *ARGS[:-1]]) == 0  # with the simplified terrain
    saved = sorted((out / "simplified").glob("*.npz"))
    assert len(saved) == 1
    before = _snapshot(out)
    err = _err(capsys, 2, ["evaluate", str(dem), str(saved[0]), "--out", str(out), "--overwrite", *ARGS])
    assert "an input of this run" in err and str(saved[0]) in err, err
    assert _snapshot(out) == before


def test_evaluate_never_replaces_a_users_own_simplified_terrain(meshes, tmp_path, capsys):
    dem, good = meshes
    out = tmp_path / "o"
    (out / "simplified").mkdir(parents=True)
    mine = out / "simplified" / "dem__good__level2.npz"
    save_terrain(bundled_terrain("hills").crop(rows=(0, 9), cols=(0, 9)), mine)  # terrainvis's format, not a run's
    before = mine.read_bytes()
    for extra in ([], ["--overwrite"]):
        err = _err(capsys, 2, ["evaluate", str(dem), str(good), "--out", str(out), *ARGS[:-1], *extra])
        assert "simplified/dem__good__level2.npz, which this run would write" in err, err
        assert mine.read_bytes() == before


# ---------------------------------------------------------------------- (d) outputs on one path
def _observers(tmp_path) -> Path:
    path = tmp_path / "obs.csv"
    path.write_text("x,y\n300,300\n900,1200\n")
    return path


def test_cumulative_refuses_two_outputs_on_one_path(tmp_path, capsys):
    dem = tmp_path / "dem.npz"
    save_terrain(bundled_terrain("hills").crop(rows=(0, 33), cols=(0, 33)), dem)
    obs = _observers(tmp_path)
    x = tmp_path / "x.npz"
    link = tmp_path / "link.npz"
    link.symlink_to(x)  # dangling: x does not exist yet
    (tmp_path / "sub").mkdir()
    base = ["cumulative", str(dem), "--observers", str(obs), "--frame", "local"]
    for other in (x, link, tmp_path / "sub" / ".." / "x.npz"):
        err = _err(capsys, 2, base + ["-o", str(x), "--observers-out", str(other)])
        assert f"--observers-out {str(other)!r} is also this command's -o" in err, err
        assert not x.exists()
    png_link = tmp_path / "p.png"
    png_link.symlink_to(tmp_path / "c.tif")
    err = _err(capsys, 2, base + ["-o", str(tmp_path / "c.tif"), "--png", str(png_link)])
    assert "--png" in err and "is also this command's -o (the same file as" in err, err


def test_site_refuses_two_outputs_on_one_path(tmp_path, capsys):
    csv = tmp_path / "s.csv"
    plot = tmp_path / "p.png"
    plot.symlink_to(csv)  # a link that leads --plot onto -o
    err = _err(capsys, 2, ["site", "hills", "-k", "2", "--grid", "4", "-o", str(csv), "--plot", str(plot)])
    assert f"--plot {str(plot)!r} is also this command's -o" in err, err
    assert not csv.exists()


def test_one_path_check_names_both_flags(tmp_path):
    from terrainvis.core.fileio import check_output_file

    a = tmp_path / "a.npz"
    (tmp_path / "sub").mkdir()
    with pytest.raises(ValueError, match=r"--observers-out '.*a\.npz' is also this command's -o \(the same file as "
                                         r"'.*a\.npz'\): one would overwrite the other"):
        check_output_file(tmp_path / "sub" / ".." / "a.npz", "--observers-out", outputs={"-o": a})
    assert check_output_file(tmp_path / "b.npz", "--observers-out", outputs={"-o": a}) == tmp_path / "b.npz"


# ---------------------------------------------------------------------- (e) the GeoPackage writer
def _lines(n=3):
    xy = np.stack([np.c_[np.arange(n), np.zeros(n)], np.c_[np.arange(n), np.ones(n)]], axis=1).astype(float)
    return xy, pd.DataFrame({"k": np.arange(n)})


def test_a_failed_read_back_keeps_the_old_geopackage(tmp_path, monkeypatch):
    from terrainvis.io import _gpkg

    path = tmp_path / "net.gpkg"
    xy, attrs = _lines()
    _gpkg.write_lines(path, xy, attrs)
    before = path.read_bytes()

    def no_memory(*a, **k):
        raise MemoryError("no memory left for the read-back")

    monkeypatch.setattr(_gpkg, "read_lines", no_memory)
    with pytest.raises(MemoryError):
        _gpkg.write_lines(path, *_lines(5))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["net.gpkg"]


def test_a_full_disk_in_sqlite_is_an_output_error_and_leaves_nothing(tmp_path, monkeypatch):
    from terrainvis.io import _gpkg

    path = tmp_path / "net.gpkg"
    xy, attrs = _lines()
    _gpkg.write_lines(path, xy, attrs)
    before = path.read_bytes()
    real = _gpkg._write

    def full(con, *a):
        real(con, *a)
        con.execute("BEGIN")
        con.execute("CREATE TABLE more (x)")  # a journal exists now
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(_gpkg, "_write", full)
    with pytest.raises(OutputError, match=r"could not write .*net\.gpkg: SQLite: database or disk is full"):
        _gpkg.write_lines(path, xy, attrs)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["net.gpkg"]


def test_evaluate_says_on_a_terminal_as_each_terrain_is_measured(meshes, tmp_path, capsys, monkeypatch):
    dem, good = meshes
    argv = ["evaluate", str(dem), str(good), "--against", "lls", *ARGS]
    capsys.readouterr()
    assert main(argv) == 0
    assert capsys.readouterr().err == ""  # a log gets the results only
    monkeypatch.setattr("terrainvis.core._progress.on_a_terminal", lambda: True)
    assert main(argv) == 0
    lines = capsys.readouterr().err.splitlines()
    assert [line.split(" (")[0] for line in lines] == ["terrainvis evaluate: measured good",
                                                       "terrainvis evaluate: measured lls"], lines
    T = bundled_terrain("hills").crop(rows=(0, 33), cols=(0, 33))
    n = simplifiers.simplify(T, "greedy-insertion", 2).n_vertices
    assert lines[0].startswith(f"terrainvis evaluate: measured good ({n:,} vertices, ") and lines[0].endswith(" s)")
