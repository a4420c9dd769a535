"""The first run says what it compiles (issue 38): one line on stderr when a kernel of
``terrainvis.core.compiling.KERNELS`` starts compiling, once per process; ``terrainvis
compile`` compiles ahead and says which parts were cached already."""

from __future__ import annotations

import gc
import os
import subprocess
import sys

import numba
import numpy as np
import pytest

from terrainvis.cli import main
from terrainvis.core import compiling


def _toy(name: str):
    """A fresh kernel (not cached: it compiles on its first call) registered under ``name``."""

    @numba.njit(cache=False)
    def toy(x):
        s = 0.0
        for v in x:
            s += v * v
        return s

    toy.py_func.__qualname__ = name
    return toy, f"{toy.py_func.__module__}.{name}"


@pytest.fixture
def toy(monkeypatch):
    monkeypatch.delenv("TERRAINVIS_COMPILE_NOTICE", raising=False)
    compiling.install()
    kernel, key = _toy(f"toy_{os.getpid()}_{id(monkeypatch)}")
    monkeypatch.setitem(compiling.KERNELS, key, ("a toy kernel", 3.0))
    return kernel, key


def test_a_kernel_that_starts_compiling_says_so_once(toy, capsys):
    kernel, key = toy
    before = compiling.seconds()
    assert kernel(np.arange(3.0)) == 5.0
    err = capsys.readouterr().err
    assert err == ("terrainvis: compiling a toy kernel: about 3 s, on the first run only (numba compiles its kernels "
                   "once and keeps them in its cache)\n")
    assert key in compiling.announced() and compiling.seconds() > before
    kernel(np.arange(4.0))  # compiled: nothing more
    kernel(np.arange(4, dtype=np.int64))  # a new signature of a kernel announced already: nothing either
    assert capsys.readouterr().err == ""


def test_quiet_and_the_environment_silence_it(toy, capsys, monkeypatch):
    kernel, key = toy
    with compiling.quiet():
        kernel(np.arange(3.0))
    assert capsys.readouterr().err == "" and key not in compiling.announced()
    other, key2 = _toy(key.rsplit(".", 1)[1] + "_b")
    monkeypatch.setitem(compiling.KERNELS, key2, ("another toy", 1.0))
    monkeypatch.setenv("TERRAINVIS_COMPILE_NOTICE", "0")
    other(np.arange(3.0))
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("module, raised", [("terrainvis._probe", True), ("simplifiers._probe", True),
                                            ("someone_elses_module", False)])
def test_the_collectors_older_passes_are_rarer_while_our_kernels_compile(module, raised):
    from numba.core import event

    compiling.install()
    kernel, _ = _toy(f"gc_{abs(hash(module))}_{os.getpid()}")
    kernel.py_func.__module__ = module
    seen = []

    class After(event.Listener):  # registered after terrainvis's listener: sees what it set
        def on_start(self, ev):
            seen.append(gc.get_threshold())

        def on_end(self, ev):
            pass

    before = gc.get_threshold()
    with event.install_listener("numba:compile", After()):
        assert kernel(np.arange(3.0)) == 5.0
    young, middle, old = before
    want = (young, max(middle, compiling.COMPILE_GC_THRESHOLD), old) if raised else before
    assert seen[0] == want and gc.get_threshold() == before  # restored once the compilation ends


def test_kernels_not_listed_are_compiled_silently(capsys):
    compiling.install()
    kernel, key = _toy(f"unlisted_{os.getpid()}")
    kernel(np.arange(2.0))
    assert capsys.readouterr().err == "" and key not in compiling.announced()


def test_every_listed_kernel_exists():
    import importlib

    for key in compiling.KERNELS:
        module, name = key.rsplit(".", 1)
        assert hasattr(importlib.import_module(module), name), key


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_compile_ahead_then_cached(tmp_path, jobs):
    """Two parts, in this process or side by side in two workers: compiled into the cache the
    first time, each said once, and loaded from it the second."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    run = [sys.executable, "-m", "terrainvis.cli", "compile", "los", "output-modes", "--jobs", jobs]
    cold = subprocess.run(run, env=env, capture_output=True, text=True, timeout=600)
    assert cold.returncode == 0, cold.stderr
    assert "numba's cache is " + str(tmp_path / "cache") in cold.stderr
    if jobs == "2":  # the longer part first
        assert "terrainvis compile: output-modes, los, 2 processes side by side" in cold.stderr, cold.stderr
    else:  # in the order given
        assert "terrainvis compile: los, output-modes\n" in cold.stderr, cold.stderr
    assert "terrainvis: compiling" not in cold.stderr
    for part in ("los          ", "output-modes "):
        assert cold.stdout.count(f"  {part} compiled in") == 1, cold.stdout
    warm = subprocess.run(run, env=env, capture_output=True, text=True, timeout=600)
    assert warm.returncode == 0, warm.stderr
    for part in ("los          ", "output-modes "):
        assert f"  {part} cached already" in warm.stdout, warm.stdout


def test_jobs_must_be_a_whole_number_of_processes(capsys):
    assert main(["compile", "--jobs", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("terrainvis compile: error: argument --jobs/-j: expected a whole number of processes >= 1, got '0' "
                   "(see terrainvis compile --help)"), err


def test_an_unknown_part_is_one_line(capsys):
    assert main(["compile", "viewsheds"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("terrainvis compile: error: PART must be some of viewshed, output-modes, los, methods, compare, got "
                   "'viewsheds'"), err


# A kernel cached with a record type, then the record's module moved, as a new version of
# terrainvis moves a kernel module: the index numba kept names a module that is gone.
_PROBE_RUN = """
import importlib.util, sys
folder, records, mode, name = sys.argv[1:5]
sys.path.insert(0, folder)
if mode == "tolerant":
    from terrainvis.core import compiling
    compiling.install()
source = f"import numba\\nfrom {records} import Rec\\n\\n@numba.njit(cache=True)\\ndef total(r):\\n    return r.a + r.b\\n"
path = f"{folder}/kernels/probe_kernel.py"
open(path, "w").write(source)
spec = importlib.util.spec_from_file_location(name, path)
module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(module)
print(module.total(module.Rec(1.0, 2.0)))
"""


def _probe(tmp_path, name: str, mode: str):
    """Cache a kernel (in a module called ``name``) of a record defined in ``probe_records``,
    move the record to ``probe_moved`` and call the kernel again on the same cache; the
    second run's result."""
    folder = tmp_path / mode / name
    (folder / "kernels").mkdir(parents=True)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / mode / "cache"))
    record = "from collections import namedtuple\nRec = namedtuple('Rec', ['a', 'b'])\n"
    (folder / "probe_records.py").write_text(record)
    first = subprocess.run([sys.executable, "-c", _PROBE_RUN, str(folder), "probe_records", mode, name],
                           env=env,
                           capture_output=True, text=True)
    assert first.returncode == 0 and first.stdout.strip() == "3.0", first.stderr
    (folder / "probe_records.py").unlink()
    (folder / "probe_moved.py").write_text(record)
    return subprocess.run([sys.executable, "-c", _PROBE_RUN, str(folder), "probe_moved", mode, name],
                          env=env,
                          capture_output=True, text=True)


def test_a_kept_cache_whose_index_names_a_moved_module_is_compiled_again(tmp_path):
    """numba raises ModuleNotFoundError on such an index (the first case); a kernel of
    terrainvis compiles again and answers (the second); other programs' kernels are left
    to numba (the third)."""
    plain = _probe(tmp_path, "terrainvis.probe_kernel", "plain")
    assert plain.returncode != 0 and "ModuleNotFoundError: No module named 'probe_records'" in plain.stderr
    ours = _probe(tmp_path, "terrainvis.probe_kernel", "tolerant")
    assert ours.returncode == 0 and ours.stdout.strip() == "3.0", ours.stderr
    theirs = _probe(tmp_path / "elsewhere", "probe_kernel", "tolerant")
    assert theirs.returncode != 0 and "ModuleNotFoundError: No module named 'probe_records'" in theirs.stderr


_MADE = '''
import math

import numba as nb
import numpy as np

from terrainvis.core.compiling import KERNEL_ONLY, kernel_of

GRID = 0
TIN = 1


# each leaf types on its own kind's surface only (an array here, a float there): a branch
# left in the other kind's kernel would not compile
@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def grid_leaf(s, x):
    return s.shape[0] * x


@nb.njit(cache=True, nogil=True, **KERNEL_ONLY)
def tin_leaf(s, x):
    return math.floor(s) + x


def _make(kind):
    @kernel_of(kind, "grid_total", "tin_total")
    def total(s, x):
        out = 0.0
        for i in range(3):
            if kind == GRID:
                out += grid_leaf(s, x + i)
            else:
                out += tin_leaf(s, x + i)
        return out

    return total


grid_total, tin_total = _make(GRID), _make(TIN)
'''

_MADE_RUN = r'''
import sys
import numpy as np
sys.path.insert(0, sys.argv[1])
import made_kernels as m
print(m.grid_total.__name__, m.tin_total.__name__, m.grid_total(np.zeros(4), 1.0), m.tin_total(10.0, 1.0))
for k in (m.grid_total, m.tin_total):
    print(sum(k.stats.cache_hits.values()), sum(k.stats.cache_misses.values()))
'''


def test_a_kernel_written_once_is_made_per_kind_and_each_is_cached(tmp_path):
    """``kernel_of``: each kind compiles its own branch alone (the other would not type), under
    its own name, and a second process loads both from numba's cache (the kind, a constant of
    the closure, keys the cache the same way in every process)."""
    (tmp_path / "made_kernels.py").write_text(_MADE)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    runs = [subprocess.run([sys.executable, "-c", _MADE_RUN, str(tmp_path)], env=env, capture_output=True, text=True)
            for _ in range(2)]
    for run in runs:
        assert run.returncode == 0, run.stderr
    first, second = (run.stdout.split("\n") for run in runs)
    assert first[0] == second[0] == "grid_total tin_total 24.0 36.0"
    assert first[1:3] == ["0 1", "0 1"]  # compiled, once each
    assert second[1:3] == ["1 0", "1 0"]  # loaded from the cache, each
    names = sorted(p.name.split("-")[0] for p in (tmp_path / "cache").rglob("*.nbi"))
    assert names == ["made_kernels.grid_leaf", "made_kernels.grid_total", "made_kernels.tin_leaf",
                     "made_kernels.tin_total"]
