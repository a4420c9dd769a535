"""What a new user and a hostile one trip over (issue 20): messages, exit codes, progress, memory.

Each test failed before its fix: nodata errors pointed command-line users at a Python
method, ``info`` refused ``--fill``, ``--height nan`` was "outside the DEM", output errors
named a hidden temporary file after the computation, a full disk exited 2 without a file
name, an all-NaN DEM printed numpy's "All-NaN slice" warning, extents printed 6
significant digits (10 m at UTM northings), ``| head`` printed "error: Broken pipe",
negative eye heights were accepted by ``los`` and ``compare`` but not ``viewshed``,
SIGTERM's message ended in ";", a bad ``--pairs`` cell named nothing, ``seed=-1`` gave
numpy's "expected non-negative integer", "1 terrains", ``n_points=10**7`` allocated until
it failed, and tqdm warned "IProgress not found" in a Jupyter kernel without ipywidgets.
"""

from __future__ import annotations

import errno
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pandas as pd
import pytest

from terrainvis import HeightGrid, bundled_terrain, compare, save_dem
from terrainvis.cli import main

from conftest import one_line_error, shared_dem_path


_err = one_line_error  # the command must exit with the code and print one line, no traceback


@pytest.fixture
def holes(tmp_path):
    z = bundled_terrain("hills").z[:33, :33].copy()
    z[5, 7] = np.nan
    path = tmp_path / "holes.npz"
    save_dem(HeightGrid(z, dx=30.0, dy=30.0), path)
    return path


# ---------------------------------------------------------------------- nodata
def test_nodata_errors_name_the_command_line_options(holes, tmp_path, capsys):
    err = _err(capsys, 2, ["simplify", str(holes), "-m", "lls", "-o", str(tmp_path / "s.npz")])
    assert "--fill nearest" in err and "--crop-valid" in err and "1 NaN cell(s) out of 33x33" in err
    err = _err(capsys, 2, ["compare", "--terrain", str(holes), "--out", str(tmp_path / "r")])
    assert "--fill" in err and "--crop-valid" in err


def test_info_takes_fill_and_crop_valid(holes, capsys):
    capsys.readouterr()
    assert main(["info", str(holes)]) == 0
    assert "1 cell (0.09 %)" in capsys.readouterr().out
    assert main(["info", str(holes), "--fill", "nearest"]) == 0
    assert "nodata    0 cells" in capsys.readouterr().out
    assert main(["info", str(holes), "--crop-valid"]) == 0
    assert "nodata    0 cells" in capsys.readouterr().out


def test_an_all_nodata_dem_is_refused_clearly(tmp_path, capsys):
    path = tmp_path / "empty.npz"
    save_dem(HeightGrid(np.full((9, 9), np.nan)), path)
    for argv in (["info", str(path)], ["los", str(path), "--from", "1", "1", "--to", "5", "5"],
                 ["simplify", str(path), "-m", "lls", "-o", str(tmp_path / "s.npz")]):
        err = _err(capsys, 2, argv)
        # refused where the file is read, naming it and saying why
        assert "'empty.npz' holds no height: all 9x9 samples are nodata" in err and "All-NaN" not in err


# ---------------------------------------------------------------------- numbers and heights
@pytest.mark.parametrize("argv, flag", [
    (["los", "hills", "--from", "100", "100", "--to", "900", "900", "--height", "nan"], "--height"),
    (["los", "hills", "--from", "100", "100", "--to", "900", "900", "--target-height", "inf"], "--target-height"),
    (["los", "hills", "--from", "nan", "100", "--to", "900", "900"], "--from"),
    (["viewshed", "hills", "--observer", "100", "100", "--height", "nan", "-o", "v.npz"], "--height"),
])
def test_non_finite_numbers_have_their_own_message(argv, flag, capsys):
    err = _err(capsys, 2, argv)
    assert f"argument {flag}: expected a finite number" in err and "outside" not in err



def test_a_negative_max_distance_is_refused_by_its_option(tmp_path, capsys):
    """viewshed and cumulative check --max-distance alike, naming the option (not the API's max_distance)."""
    obs = tmp_path / "obs.csv"
    obs.write_text("x,y\n100,100\n")
    for argv in (["viewshed", "hills", "--observer", "100", "100", "-o", str(tmp_path / "v.npz")],
                 ["cumulative", "hills", "--observers", str(obs), "-o", str(tmp_path / "c.npz")]):
        err = _err(capsys, 2, argv + ["--max-distance", "-5"])
        assert "argument --max-distance: expected a distance >= 0, got '-5'" in err, err

def test_heights_above_the_surface_are_never_negative(tmp_path, capsys):
    base = ["--from", "100", "100", "--to", "900", "900"]
    for argv in (["los", "hills", *base, "--height", "-100"], ["los", "hills", *base, "--target-height", "-1"],
                 ["viewshed", "hills", "--observer", "100", "100", "--height", "-50", "-o", str(tmp_path / "v.npz")]):
        assert "expected a height >= 0 above the surface" in _err(capsys, 2, argv)
    err = _err(capsys, 2, ["compare", "--terrain", "hills", "--offset", "-5", "--out", str(tmp_path / "r")])
    assert "offset must be >= 0 (a height above the surface), got -5.0" in err
    with pytest.raises(ValueError, match=r"target_height must be >= 0"):
        compare(["hills"], methods=["lls"], levels=[1], target_height=-1.0, workers=1)
    assert main(["los", "hills", *base, "--height", "0"]) == 0


def test_seed_minus_one_names_the_seed():
    from terrainvis import sample_points

    with pytest.raises(ValueError, match=r"seed must be >= 0 \(or a numpy Generator\), got -1"):
        sample_points(bundled_terrain("hills"), 5, seed=-1)
    with pytest.raises(TypeError, match="seed must be an integer >= 0, None or a numpy Generator, got str 'a'"):
        sample_points(bundled_terrain("hills"), 5, seed="a")
    assert sample_points(bundled_terrain("hills"), 3, seed=np.random.default_rng(1)).shape == (3, 3)


# ---------------------------------------------------------------------- outputs
def test_an_unwritable_output_is_refused_before_computing(tmp_path, capsys, monkeypatch):
    import simplifiers
    import terrainvis.core.fileio as fileio

    def no_probe(*a, **k):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(fileio.tempfile, "mkstemp", no_probe)
    monkeypatch.setattr(simplifiers, "simplify", lambda *a, **k: pytest.fail("simplified before checking -o"))
    err = _err(capsys, 2, ["simplify", "hills", "-m", "lls", "-o", str(tmp_path / "s.npz")])
    assert f"-o '{tmp_path / 's.npz'}' cannot be written" in err and "is not writable" in err


def test_a_full_disk_exits_1_naming_the_real_file(tmp_path, capsys, monkeypatch):
    import os

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)  # the file system reports the full disk when the data is flushed
    out = tmp_path / "s.npz"
    for argv in (["simplify", "hills", "-m", "lls", "-o", str(out)],
                 ["viewshed", "hills", "--observer", "900", "900", "-o", str(out)]):
        err = _err(capsys, 1, argv)
        assert err.endswith(f"could not write {out}: No space left on device"), err
        assert ".s.npz." not in err  # not the temporary file
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    err = _err(capsys, 1, ["compare", "--terrain", "hills", "--levels", "1", "--methods", "lls", "--points", "5",
                           "--sets", "1", "--workers", "1", "--out", str(tmp_path / "run")])
    assert "could not write" in err and "results" in err and "No space left on device" in err


def test_a_closed_pipe_ends_quietly(tmp_path):
    rng = np.random.default_rng(0)
    pairs = tmp_path / "pairs.csv"
    xy = rng.uniform(100, 3400, size=(3000, 4))
    pd.DataFrame(xy, columns=["x1", "y1", "x2", "y2"]).to_csv(pairs, index=False)
    p = subprocess.Popen([sys.executable, "-m", "terrainvis.cli", "los", "hills", "--pairs", str(pairs)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert p.stdout.readline().startswith(b"hills: observer")  # then the reader goes away, as head does
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 128 + signal.SIGPIPE
    assert err == "", err


# ---------------------------------------------------------------------- digits
def test_coordinates_print_to_the_grid_s_resolution(capsys):
    from terrainvis import load_dem

    path = shared_dem_path("green_mountains_vt")
    grid = load_dem(path)
    xmin, xmax, ymin, ymax = grid.extent
    capsys.readouterr()
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"y [{ymin:.0f}, {ymax:.0f}]" in out and "e+06" not in out  # 90 m cells: to the metre
    x0, y0 = grid.xs[10], grid.ys[10]
    x1, y1 = grid.xs[150], grid.ys[120]
    assert main(["los", str(path), "--from", str(x0), str(y0), "--to", str(x1), str(y1)]) == 0
    out = capsys.readouterr().out
    assert f"({x0:.0f}, {y0:.0f}) -> ({x1:.0f}, {y1:.0f})" in out and "e+06" not in out


# ---------------------------------------------------------------------- words
def test_sigterm_message_ends_cleanly(capsys, monkeypatch, tmp_path):
    from terrainvis import cli
    from terrainvis.core.runner import Interrupted

    def stopped(*args):
        raise Interrupted(signal.SIGTERM)

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(cli.COMMANDS["info"], "run", stopped)
    capsys.readouterr()
    assert main(["info", "hills"]) == 143
    assert capsys.readouterr().err.strip() == "terrainvis info: interrupted (interrupted by SIGTERM)"
    monkeypatch.setattr(cli.compare, "_compare_in", stopped)  # compare's folder is held: it says what it keeps
    assert main(["compare"]) == 143
    assert capsys.readouterr().err.strip().endswith("(interrupted by SIGTERM); finished units are in results.csv "
                                                    "(use --resume)")


def test_a_bad_pairs_cell_is_named_by_file_row_and_column(tmp_path, capsys):
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("x1,y1,x2,y2\n100,200,900,900\n100,abc,900,900\n")
    err = _err(capsys, 2, ["los", "hills", "--pairs", str(pairs)])
    assert f"--pairs '{pairs}': row 2 (line 3), column y1 holds 'abc', not a finite number" in err
    pairs.write_text("x1,y1,x2,y2\n100,200,,900\n")
    assert "row 1 (line 2), column x2 is empty" in _err(capsys, 2, ["los", "hills", "--pairs", str(pairs)])


def test_counts_are_singular_when_one(tmp_path, capsys):
    capsys.readouterr()
    assert main(["compare", "--terrain", "hills", "--levels", "1", "--methods", "lls", "--relocations", "full",
                 "--points", "5", "--sets", "1", "--workers", "1", "--repeats", "1", "--no-plots",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "1 unit, 1 row, 1 terrain, predicate exact" in out and "terrains" not in out.splitlines()[-1]


# ---------------------------------------------------------------------- memory
def test_a_run_that_cannot_fit_in_memory_is_refused_before_it_starts(tmp_path, capsys):
    from terrainvis.core.memory import available_memory, format_bytes

    have = available_memory()
    assert have is None or have > 0
    if have is None:
        pytest.skip("this platform does not say how much memory is available")
    from terrainvis.errors import NotEnoughMemoryError

    with pytest.raises(NotEnoughMemoryError, match=r"n_points=10,000,000 .* needs at least 1.6 PiB of memory, but "
                                                   r"this machine has .* available; use fewer points"):
        compare(["hills"], methods=["lls"], levels=[1], n_points=10**7, workers=1)
    # refused before anything runs: a usage mistake (exit 2), one line
    err = _err(capsys, 2, ["compare", "--terrain", "hills", "--points", "10000000", "--out", str(tmp_path / "r")])
    assert err.startswith("terrainvis compare: error: n_points=10,000,000") and "PiB" in err
    assert not (tmp_path / "r" / "results.csv").exists()
    assert format_bytes(1.8e15) == "1.6 PiB" and format_bytes(999) == "999 bytes"
    assert format_bytes(12_345_678) == "11.8 MiB"


def test_the_cli_turns_a_memory_error_into_one_line(capsys, monkeypatch):
    from terrainvis import cli

    def hungry(args):
        raise MemoryError("Unable to allocate 7.28 TiB for an array with shape (1000000, 1000000)")

    monkeypatch.setattr(cli.COMMANDS["info"], "run", hungry)
    err = _err(capsys, 1, ["info", "hills"])
    assert err == "terrainvis info: error: out of memory: Unable to allocate 7.28 TiB for an array with shape " \
                  "(1000000, 1000000)"


# ---------------------------------------------------------------------- progress
def test_a_cold_cache_shows_what_compiles_and_how_far(capsys, monkeypatch):
    from terrainvis.experiment import plan

    monkeypatch.setattr(plan, "kernels_cached", lambda: False)  # as on a fresh install
    capsys.readouterr()
    compare(["hills"], methods=["lls", "qec"], levels=[1], n_points=5, n_sets=1, repeats=1, workers=1,
            progress=True)
    err = capsys.readouterr().err
    # lls, qec, the measures on a grid and on a TIN, the volume
    assert "first run: compiling the numba kernels this run needs (5 parts, about" in err
    # stderr is no terminal here: plain lines, as a log file gets them, not bars redrawn in place
    assert "terrainvis: compiled the kernels (5 parts) in " in err and "compare: 2/2 units, " in err
    assert "\r" not in err and "\x1b" not in err


def test_the_compile_estimate_packs_parts_on_the_workers():
    from terrainvis.experiment.plan import COMPILE_SECONDS, compile_seconds

    parts = [("method", "greedy-cuts", 33), ("method", "lls", 33), ("measure", "grid", 33)]
    assert compile_seconds(parts, 1) == pytest.approx(sum(COMPILE_SECONDS[p[1]] for p in parts))
    # two workers: the grid measure (the longest) on one, greedy cuts and LLS on the other
    assert COMPILE_SECONDS["greedy-cuts"] + COMPILE_SECONDS["lls"] < COMPILE_SECONDS["grid"]
    assert compile_seconds(parts, 2) == COMPILE_SECONDS["grid"]
    assert compile_seconds(parts, 3) == COMPILE_SECONDS["grid"]
    # the TIN measure waits for the grid one (it would compile the grid's kernels again)
    tin = parts + [("measure", "tin", 33)]
    assert compile_seconds(tin, 3) == pytest.approx(COMPILE_SECONDS["grid"] + COMPILE_SECONDS["tin"])


def test_the_work_order_starts_nothing_before_what_it_compiles_is_there():
    from terrainvis.experiment import plan
    from terrainvis.experiment.plan import compile_weight, part_needs, unit_needs, warm_up_parts, work_order

    grids = plan.resolve_terrains(["hills", "ridges"])
    settings = plan.settings_for(grids, {"levels": [1, 3], "n_points": 20, "n_sets": 2})
    tasks = plan.tasks(grids, settings)
    parts = warm_up_parts(tasks, grids, settings)
    assert ("measure", "volume", 33) in parts and ("measure", "tin", 33) in parts
    assert ("measure", "volume", 33) not in warm_up_parts(tasks, grids, settings.replace(volume=False))
    everything = sorted([("part", p) for p in parts] + [("task", t) for t in tasks], key=repr)
    assert sorted(work_order(parts, tasks, 3), key=repr) == everything
    for at_once in (1, 2):  # this machine's two cores: a worker never has to wait
        order = work_order(parts, tasks, at_once)
        assert sorted(order, key=repr) == everything
        free, finish = [0.0] * at_once, {}  # replay it as a first-in, first-out pool with the estimates
        for kind, x in order:
            w = free.index(min(free))
            needs = part_needs(x, parts) if kind == "part" else unit_needs(x, parts)
            assert all(finish[d] <= free[w] for d in needs), (at_once, kind, x)
            finish[x] = free[w] = free[w] + (compile_weight(x) if kind == "part" else 1.0)


_KERNEL = """
import sys, types, warnings
warnings.simplefilter("always")
sys.modules["ipywidgets"] = None  # not installed
ipython = types.ModuleType("IPython")
ipython.get_ipython = lambda: types.SimpleNamespace(config={"IPKernelApp": {}})  # inside a Jupyter kernel
sys.modules["IPython"] = ipython
sys.modules["ipykernel.zmqshell"] = types.ModuleType("ipykernel.zmqshell")  # how tqdm.auto recognises a kernel
import terrainvis as tv
from terrainvis.core._progress import progress_bar_class
print(progress_bar_class().__module__)
tv.compare(["hills"], methods=["lls"], levels=[1], n_points=5, n_sets=1, repeats=1, workers=1, progress=True)
"""


def test_no_ipywidgets_warning_in_a_kernel_without_ipywidgets(tmp_path):
    script = tmp_path / "kernel.py"
    script.write_text(textwrap.dedent(_KERNEL))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "tqdm.std"
    assert "IProgress" not in out.stderr and "compare: 100%" in out.stderr, out.stderr


_WIDGETS = """
import sys, types
widgets = types.ModuleType("ipywidgets")  # a stand-in: the three names tqdm.notebook imports
for name in ("IntProgress", "HBox", "HTML", "FloatProgress"):
    setattr(widgets, name, type(name, (), {"__init__": lambda self, *a, **k: None}))
widgets.__version__ = "8.1.0"
sys.modules["ipywidgets"] = widgets
sys.modules["ipykernel.zmqshell"] = types.ModuleType("ipykernel.zmqshell")
from terrainvis.core._progress import progress_bar_class
print(progress_bar_class().__module__)
"""


def test_a_kernel_with_ipywidgets_gets_the_notebook_bar(tmp_path):
    script = tmp_path / "widgets.py"
    script.write_text(textwrap.dedent(_WIDGETS))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "tqdm.notebook" and "IProgress" not in out.stderr
