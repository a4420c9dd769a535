"""A command imports what it uses and nothing else (issue 28: commands that start as quickly as GIS tools).

Each case runs the command in a fresh interpreter and lists the heavy modules it imported.
``benchmarks/bench_startup.py`` times the same commands beside GDAL's.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

HEAVY = ("numpy", "numba", "pandas", "simplifiers", "terrainvis.experiment", "terrainvis.relocation", "matplotlib",
         "trimesh", "embreex", "pymeshlab", "rasterio", "dask")


def _imported(argv) -> set[str]:
    code = (
        "import sys\n"
        "from terrainvis.cli import main\n"
        f"try:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
        f"print('imported:' + ','.join(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    line = out.stdout.splitlines()[-1]
    assert line.startswith("imported:"), out.stdout
    return set(filter(None, line.removeprefix("imported:").split(",")))


def test_help_imports_nothing_heavy():
    # the command list needs each command's one help line, not its flags
    assert _imported(["--help"]) == set()


def test_a_command_s_help_builds_only_its_own_flags():
    # compare's flags come from the experiment's options (pandas, the simplifiers); los's do not
    assert not _imported(["los", "--help"]) & {"pandas", "simplifiers", "terrainvis.experiment", "numba"}
    assert "terrainvis.experiment" in _imported(["compare", "--help"])


@pytest.mark.parametrize("argv", [
    ["los", "hills", "--from", "300", "400", "--to", "2000", "2000"],
    ["viewshed", "hills", "--observer", "300", "400", "-o", "{tmp}/v.npz"],
])
def test_the_visibility_commands_import_no_experiment(argv, tmp_path):
    got = _imported([a.format(tmp=tmp_path) for a in argv])
    assert "numba" in got  # they run the kernels ...
    # ... and need nothing of the experiment, the simplifiers, the meshes or the figures
    assert not got & {"pandas", "simplifiers", "terrainvis.experiment", "terrainvis.relocation", "matplotlib",
                      "trimesh", "embreex", "pymeshlab", "dask"}, got


def test_info_reads_and_describes_without_numba(tmp_path):
    """``info`` reads the DEM and prints its levels and methods: numpy, no kernels, no simplifier runs."""
    got = _imported(["info", "hills"])
    assert "numpy" in got and "simplifiers" in got  # the methods' table and the levels
    assert not got & {"numba", "pandas", "terrainvis.experiment", "matplotlib", "trimesh", "embreex", "pymeshlab",
                      "dask"}, got


def test_the_visibility_package_imports_its_parts_on_first_use():
    code = ("import sys\nimport terrainvis.visibility as v\nprint('numba' in sys.modules)\n"
            "v.viewshed\nprint('numba' in sys.modules, 'terrainvis.visibility.viewsheds.siting' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "True", "False"], out.stdout


def test_kernels_load_beside_the_read_and_their_error_is_raised():
    import threading
    import time

    from terrainvis.cli._common import loading_kernels

    seen = {}

    def load():
        seen["thread"] = threading.current_thread() is not threading.main_thread()
        time.sleep(0.3)
        seen["loaded"] = True

    t0 = time.monotonic()
    with loading_kernels(load, "test"):
        time.sleep(0.3)  # the read
    assert seen == {"thread": True, "loaded": True}
    assert time.monotonic() - t0 < 0.55  # side by side, not one after the other

    def broken():
        raise ImportError("no kernels")

    with pytest.raises(ImportError, match="no kernels"):
        with loading_kernels(broken, "test"):
            pass


def test_an_error_while_reading_waits_for_the_kernels_to_load():
    import time

    from terrainvis.cli._common import UsageError, loading_kernels

    seen = {}

    def load():
        time.sleep(0.3)
        seen["loaded"] = True

    with pytest.raises(UsageError, match="no such DEM"):
        with loading_kernels(load, "test"):
            raise UsageError("no such DEM")
    assert seen == {"loaded": True}  # no LLVM left running in another thread as the process exits


def test_the_collector_pauses_while_kernels_load_and_freezes_only_in_a_process_of_its_own(monkeypatch):
    import gc
    from types import SimpleNamespace

    from terrainvis.cli import _common

    calls, states = [], {}
    monkeypatch.setattr(gc, "freeze", lambda: calls.append("freeze"))
    monkeypatch.setattr(gc, "collect", lambda *a: calls.append("collect") or 0)
    monkeypatch.setitem(sys.modules, "terrainvis.core.compiling", SimpleNamespace(seconds=lambda: 0.0))
    assert gc.isenabled()

    def load():
        states["load"] = gc.isenabled()

    with _common.loading_kernels(load, "test"):
        states["block"] = gc.isenabled()
    assert states == {"load": False, "block": False} and gc.isenabled()
    assert calls == []  # main() inside a program's process: nothing frozen, and nothing compiled to collect
    # the command's own process, after a compile (its garbage collected before the rest is frozen), and an error

    def broken():
        raise ImportError("no kernels")

    monkeypatch.setattr(_common, "_OWN_PROCESS", [True])
    clock = SimpleNamespace(spent=2.5)  # compiled before the block (an earlier command of the process): no pass
    monkeypatch.setitem(sys.modules, "terrainvis.core.compiling", SimpleNamespace(seconds=lambda: clock.spent))
    with _common.loading_kernels(load, "test"):
        pass
    assert calls == ["freeze"]

    def compiles_then_breaks():
        clock.spent += 1.0
        raise ImportError("no kernels")

    calls.clear()
    with pytest.raises(ImportError, match="no kernels"):
        with _common.loading_kernels(compiles_then_breaks, "test"):
            pass
    assert calls == ["collect", "freeze"] and gc.isenabled()


@pytest.mark.parametrize("preset, want", [(None, "1"), ("3", "3")])
def test_the_script_runs_openblas_on_one_thread_unless_told_and_freezes_its_kernels(preset, want):
    import os

    code = ("import atexit, gc, os, sys\n"
            "atexit.register(lambda: print(f'OPENBLAS={os.environ.get(\"OPENBLAS_NUM_THREADS\")} "
            "frozen={gc.get_freeze_count() > 0}'))\n"
            "sys.argv = ['terrainvis', 'los', 'hills', '--from', '100', '100', '--to', '3000', '3000', "
            "'--frame', 'local']\n"
            "from terrainvis.cli import console\n"
            "console()\n")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if preset is not None:
        env["OPENBLAS_NUM_THREADS"] = preset
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[-1] == f"OPENBLAS={want} frozen=True", out.stdout
