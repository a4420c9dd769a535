"""What the command line writes: never an input, never the package, one run per output folder.

Issue 20: ``simplify X -o X`` overwrote the input (also through a symlink or another
spelling), ``-o .../data/hills.npz`` replaced a bundled terrain, two ``compare`` runs into
one ``--out`` both "succeeded", a second run with other settings left the first one's
files beside its own, and a local file named ``hills`` was silently shadowed by the
bundled terrain.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from terrainvis import bundled_terrain, save_dem
from terrainvis.core.fileio import OutputBusyError, RunLock, protected_folders
from terrainvis.cli import main
from conftest import one_line_error

SMALL = ["--terrain", "hills", "--levels", "1", "--methods", "simple", "lls", "--points", "8", "--sets", "1",
         "--workers", "1", "--repeats", "1", "--no-plots"]


_err = one_line_error  # the command must exit with the code and print one line, no traceback


@pytest.fixture
def dem(tmp_path):
    path = tmp_path / "dem.npz"
    save_dem(bundled_terrain("ridges").crop(rows=(0, 33), cols=(0, 33)), path)
    return path


# ---------------------------------------------------------------------- inputs are never overwritten
def test_simplify_and_viewshed_refuse_to_write_over_their_input(dem, tmp_path, capsys, monkeypatch):
    before = dem.read_bytes()
    link = tmp_path / "link.npz"
    link.symlink_to(dem)
    (tmp_path / "sub").mkdir()
    spellings = [str(dem), str(link), str(tmp_path / "sub" / ".." / "dem.npz")]
    monkeypatch.chdir(tmp_path)
    spellings.append("./dem.npz")
    for out in spellings:
        err = _err(capsys, 2, ["simplify", str(dem), "-m", "lls", "-l", "1", "-o", out])
        assert "is an input of this command" in err and "never overwrites its input" in err, err
        err = _err(capsys, 2, ["viewshed", str(dem), "--observer", "300", "300", "-o", out])
        assert "is an input of this command" in err, err
    # the input named through the link, the output the real file
    assert "is an input" in _err(capsys, 2, ["simplify", str(link), "-m", "lls", "-o", str(dem)])
    assert dem.read_bytes() == before and link.is_symlink()


def test_nothing_is_written_into_the_installed_package(tmp_path, capsys):
    from importlib import resources

    data = Path(str(resources.files("terrainvis.data")))
    bundled = data / "hills.npz"
    before = bundled.read_bytes()
    err = _err(capsys, 2, ["simplify", "ridges", "-m", "lls", "-l", "1", "-o", str(bundled)])
    assert "lies inside the installed terrainvis package" in err
    assert bundled.read_bytes() == before
    err = _err(capsys, 2, ["viewshed", "ridges", "--observer", "300", "300", "-o", str(data / "new.png")])
    assert "inside the installed terrainvis package" in err and not (data / "new.png").exists()
    import terrainvis

    inside = Path(terrainvis.__file__).parent / "results-here"
    err = _err(capsys, 2, ["compare", *SMALL, "--out", str(inside)])
    assert "--out" in err and "inside the installed terrainvis package" in err and not inside.exists()
    assert {Path(terrainvis.__file__).parent.resolve(), data.resolve()} <= set(protected_folders())


# ---------------------------------------------------------------------- one run per output
_HOLD = """
import sys, time
from terrainvis.core.fileio import RunLock
with RunLock(sys.argv[1], "--out 'x'", "terrainvis compare"):
    print("held", flush=True)
    time.sleep(60)
"""


def _holder(lock: Path):
    p = subprocess.Popen([sys.executable, "-c", _HOLD, str(lock)], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "held"
    return p


def test_a_second_run_into_the_same_folder_is_refused_naming_the_first(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    holder = _holder(out / "results.lock")
    try:
        err = _err(capsys, 2, ["compare", *SMALL, "--out", str(out)])
        assert f"pid {holder.pid}" in err and "started 20" in err and "terrainvis compare" in err, err
        assert "is in use by another run" in err
        with pytest.raises(OutputBusyError, match=f"pid {holder.pid}"):  # and so is the API, on that CSV
            from terrainvis import compare

            compare(["hills"], methods=["lls"], levels=[1], n_points=6, n_sets=1, workers=1,
                    out_csv=out / "results.csv")
        assert sorted(p.name for p in out.iterdir()) == ["results.lock"]  # the refused runs wrote nothing
    finally:
        holder.kill()
        holder.wait()
    # the holder died without releasing it (SIGKILL): the next run takes over, with a note
    capsys.readouterr()
    assert main(["compare", *SMALL, "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"took over the lock left by terrainvis compare, pid {holder.pid}" in err and "no longer running" in err
    assert not (out / "results.lock").exists()  # released at the end


def test_two_real_runs_into_one_folder(tmp_path):
    """The first of two concurrent ``terrainvis compare`` processes runs; the second is refused at once.

    The first run releases its lock before its process exits: on a loaded machine the second
    can start after that and find a finished run instead (refused too, for another reason).
    Such an attempt proves nothing, and the next one gives the first run four times the points."""
    for attempt, points in enumerate((30, 120, 480)):
        out = tmp_path / f"run{attempt}"
        cmd = [sys.executable, "-m", "terrainvis.cli", "compare", "--terrain", "hills", "ridges", "--levels", "1", "2",
               "--methods", "lls", "greedy-insertion", "--points", str(points), "--sets", "3", "--workers", "1",
               "--no-plots", "--relocations", "identity", "full", "half", "--out", str(out)]
        first = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 120
            while not (out / "results.lock").exists() and first.poll() is None and time.monotonic() < deadline:
                time.sleep(0.02)
            assert (out / "results.lock").exists(), "the first run never took the folder"
            second = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
            held = (out / "results.lock").exists() and first.poll() is None
        finally:
            code = first.wait(timeout=600)
        assert code == 0, first.stderr.read()
        if held:
            break
    assert held, "the first run ended before the second was refused three times; the test proved nothing"
    assert second.returncode == 2, second.stderr
    assert f"pid {first.pid}" in second.stderr and "wrote" not in second.stdout
    assert len(pd.read_csv(out / "results.csv")) == 2 * 3 * 2 * 2 * 3


def test_run_lock_is_reentrant_in_one_process_and_released(tmp_path):
    lock = tmp_path / "results.lock"
    with RunLock(lock, "x") as a:
        assert json.loads(lock.read_text())["pid"] == os.getpid()
        with RunLock(lock, "x"):
            pass
        assert lock.exists()  # the inner exit does not release the outer hold
        assert a is not None
    assert not lock.exists()


def test_a_folder_with_an_earlier_run_needs_resume_or_overwrite(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["compare", *SMALL[:-1], "--out", str(out)]) == 0  # with figures
    first = sorted(p.relative_to(out).as_posix() for p in out.rglob("*"))
    assert "simplified/hills__simple__level1.npz" in first and "views_hills.png" in first
    # files terrainvis did not write stay, whatever their names
    mine = ["notes.txt", "simplified/mine.npz", "views_holiday.png", "simplified/other__lls__level1.npz"]
    for name in mine:
        (out / name).write_text("mine")
    err = _err(capsys, 2, ["compare", *SMALL, "--out", str(out)])
    assert "holds the results of an earlier run (results.csv, tables.md" in err and "--resume" in err
    assert "--overwrite" in err
    # another run (other methods and relocations) replaces the earlier one
    capsys.readouterr()
    argv = ["compare", "--terrain", "hills", "--levels", "1", "--methods", "lls", "--relocations", "full",
            "--points", "8", "--sets", "1", "--workers", "1", "--repeats", "1", "--out", str(out), "--overwrite"]
    assert main(argv) == 0
    assert "removed the earlier run's results.csv, tables.md" in capsys.readouterr().err
    now = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    expected = sorted(["results.csv", "results.settings.json", "tables.md", "accuracy_vs_size.png",
                       "tradeoff_full.png", "views_hills.png", "simplified/hills__lls__level1.npz"] + mine)
    assert now == expected
    assert set(pd.read_csv(out / "results.csv")["method"]) == {"lls"}
    # --resume continues it without asking
    assert main(argv[:-1] + ["--resume", "--no-plots"]) == 0


def test_overwrite_never_removes_files_terrainvis_did_not_write(tmp_path, capsys):
    """A results.csv, tables.md, figure or lock file of the user's own, at the names a run
    writes, is neither removed by --overwrite nor replaced by the run (issue 31 B)."""
    out = tmp_path / "run"
    out.mkdir()
    mine = {"results.csv": "id,value\n1,2\n", "tables.md": "# my own tables\n"}
    for name, text in mine.items():
        (out / name).write_text(text)
    for flags in ([], ["--overwrite"], ["--resume"]):
        err = _err(capsys, 2, ["compare", *SMALL, "--out", str(out), *flags])
        assert "holds results.csv and tables.md, which terrainvis did not write" in err
        assert "never replaces a file it did not write" in err
    assert {p.name: p.read_text() for p in out.iterdir()} == mine
    # beside an earlier run of terrainvis: its own files go, the user's tables.md stays and is refused
    (out / "results.csv").unlink()
    assert main(["compare", *SMALL[:-1], "--out", str(tmp_path / "other")]) == 0  # with figures
    for name in ("results.csv", "results.settings.json"):
        (out / name).write_bytes((tmp_path / "other" / name).read_bytes())
    err = _err(capsys, 2, ["compare", *SMALL, "--out", str(out), "--overwrite"])
    assert "holds tables.md, which terrainvis did not write" in err
    assert (out / "results.csv").exists() and (out / "tables.md").read_text() == mine["tables.md"]
    # a figure of the user's at a figure's name, and a lock file that is not terrainvis's
    (out / "tables.md").unlink()
    (out / "accuracy_vs_size.png").write_bytes((tmp_path / "other" / "accuracy_vs_size.png").read_bytes()[:8] + b"x")
    err = _err(capsys, 2, ["compare", *SMALL, "--out", str(out), "--overwrite"])
    assert "holds accuracy_vs_size.png, which terrainvis did not write" in err
    (out / "accuracy_vs_size.png").unlink()
    (out / "results.lock").write_text("my lock notes\n")
    err = _err(capsys, 2, ["compare", *SMALL, "--out", str(out), "--overwrite"])
    assert "holds results.lock, which terrainvis did not write" in err
    assert (out / "results.lock").read_text() == "my lock notes\n"
    (out / "results.lock").unlink()
    # what terrainvis wrote is recognised and removed
    assert main(["compare", *SMALL[:-1], "--out", str(out), "--overwrite"]) == 0
    assert "removed the earlier run's results.csv" in capsys.readouterr().err


def test_compare_refuses_an_out_csv_terrainvis_did_not_write(tmp_path):
    from terrainvis import compare

    csv = tmp_path / "mine.csv"
    csv.write_text("id,value\n1,2\n")
    with pytest.raises(ValueError, match="exists and was not written by terrainvis"):
        compare(["hills"], methods=["simple"], levels=[1], n_points=8, n_sets=1, relocations=["full"], out_csv=csv)
    assert csv.read_text() == "id,value\n1,2\n"
    # a results file of an earlier run is replaced, as before
    compare(["hills"], methods=["simple"], levels=[1], n_points=8, n_sets=1, relocations=["full"],
            out_csv=tmp_path / "r.csv")
    df = compare(["hills"], methods=["lls"], levels=[1], n_points=8, n_sets=1, relocations=["full"],
                 out_csv=tmp_path / "r.csv")
    assert set(pd.read_csv(tmp_path / "r.csv")["method"]) == {"lls"} == set(df["method"])


def test_overwrite_never_removes_an_input(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["compare", *SMALL, "--out", str(out)]) == 0
    dem = out / "simplified" / "hills__lls__level1.npz"
    err = _err(capsys, 2, ["compare", "--terrain", str(dem), "--levels", "1", "--methods", "simple", "--points", "6",
                           "--sets", "1", "--workers", "1", "--no-plots", "--out", str(out), "--overwrite"])
    assert "would remove" in err and "input" in err and dem.exists()


# ---------------------------------------------------------------------- a local file wins
def test_a_local_file_named_like_a_bundled_terrain_wins_with_a_note(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    ridges = bundled_terrain("ridges")
    save_dem(ridges, tmp_path / "r.npz")
    os.rename(tmp_path / "r.npz", tmp_path / "hills")  # a DEM file named like the bundled terrain, no suffix
    capsys.readouterr()
    assert main(["info", "hills"]) == 0
    io = capsys.readouterr()
    assert f"z [{np.nanmin(ridges.z):.6g}, {np.nanmax(ridges.z):.6g}]" in io.out  # the local file's heights
    assert "read the local file" in io.err and "not the bundled terrain" in io.err and len(io.err.splitlines()) == 1
    # a suffix-less DEM that is no bundled name is read too; a file that is no DEM is refused clearly
    os.rename(tmp_path / "hills", tmp_path / "mydem")
    assert main(["info", "mydem"]) == 0
    (tmp_path / "hills").write_text("not a DEM")
    err = _err(capsys, 2, ["info", "hills"])
    assert "file without a suffix" in err and "not a DEM" in err and "wins over the bundled terrain" in err
    # a folder of that name does not shadow anything
    os.remove(tmp_path / "hills")
    (tmp_path / "hills").mkdir()
    assert main(["info", "hills"]) == 0 and "z [220" in capsys.readouterr().out


def test_a_local_asc_without_suffix_keeps_its_projection(tmp_path, monkeypatch):
    pytest.importorskip("rasterio", reason="the geo extra is not installed")
    from terrainvis import HeightGrid
    from terrainvis.experiment.plan import resolve_terrains

    g = HeightGrid(np.arange(20.0).reshape(4, 5), dx=30.0, dy=30.0, origin=(500000.0, 4000000.0),
                   attrs={"crs": "EPSG:32617"})
    save_dem(g, tmp_path / "d.asc")
    os.rename(tmp_path / "d.asc", tmp_path / "plain")
    os.rename(tmp_path / "d.prj", tmp_path / "plain.prj")
    back = resolve_terrains([str(tmp_path / "plain")])["plain"]
    np.testing.assert_array_equal(back.z, g.z)
    assert "32617" in str(back.attrs.get("crs")) and back.attrs["path"] == str(tmp_path / "plain")
