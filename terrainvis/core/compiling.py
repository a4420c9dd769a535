"""Saying so when numba compiles: one line on stderr when a call starts compiling a kernel.

numba compiles a kernel the first time it is called with an empty cache (a fresh install,
a new ``NUMBA_CACHE_DIR``, an edited source file) and keeps the machine code on disk
(``cache=True``); later runs load it in milliseconds. A first viewshed therefore takes
seconds of compilation before it computes anything, and without a word it looks hung.
This module listens to numba's compile events: when a kernel of :data:`KERNELS` (the
ones called from Python whose compilation takes a second or more) starts compiling, it
prints at once, on stderr, one line saying what, why, about how long, and that this
happens on the first run only::

    terrainvis: compiling the viewshed sweep: about 14 s, on the first run only (numba compiles its kernels once and keeps them in its cache)

Each kernel is announced once per process; a kernel that another one calls is compiled
inside its caller's announcement. The estimates are the compile times measured on this
project's 2-core machine (``python benchmarks/bench_cold_start.py``); they are no
promise. :func:`quiet` silences the lines (the workers of a comparison, whose main
process shows its own compile progress), and so does ``TERRAINVIS_COMPILE_NOTICE=0``.

:func:`seconds` is the wall time spent compiling in this process so far: progress
estimates leave it out.

While one of terrainvis's kernels compiles, Python's garbage collector passes over its
older objects more rarely (its middle threshold raised to :data:`COMPILE_GC_THRESHOLD`,
restored when the compilation ends). numba makes hundreds of thousands of objects while it
compiles, most of which live until it ends, and each pass of the older generations went
over all of them: the line-of-sight walk on grids compiled in 5.7–6.4 s with the
default thresholds and 4.0–4.3 s with this one, and a cold ``assert_visibility_kept``
peaked at 407 MB instead of 356 MB (docs/performance.md, "First run", gives the other
settings tried). Other programs' numba functions compile under the thresholds they set.

A cache that an older terrainvis left (a kept ``NUMBA_CACHE_DIR``, the ``__pycache__``
folders of an editable install) may index its kernels by record types of modules that a
newer version moved: the same installation reads such an index of terrainvis's kernels
as a cache miss instead of numba's ``ModuleNotFoundError`` (:func:`_tolerate_stale_indexes`).

``terrainvis compile`` compiles every kernel ahead (for CI images and containers):
:mod:`terrainvis.cli.compile_ahead`.
"""

from __future__ import annotations

import contextlib
import gc
import os
import pickle
import sys
import threading
import time

__all__ = ["KERNELS", "KERNEL_ONLY", "from_python", "COMPILE_GC_THRESHOLD", "install", "quiet", "seconds", "announced"]

#: The kernels announced when they start compiling: ``module.function`` -> (what, seconds),
#: the cold compile time of the kernel and every kernel it calls not compiled before it,
#: one process, measured on this project's 2-core machine (``python
#: benchmarks/bench_cold_start.py --kernels``, 29 November 2026, night). Kernels that take under
#: a second, or that follow one of these and share its callees (the best heights after
#: the calibration's sweeps), are not announced.
KERNELS: dict[str, tuple[str, float]] = {
    "terrainvis.visibility.viewsheds._sector_kernels.sweep": ("the viewshed sweep", 14.0),
    "terrainvis.visibility._kernels.grid_walks": ("the line-of-sight walk on grids", 4.0),
    "terrainvis.visibility._kernels.tin_pairs": ("the line-of-sight clipper on TINs", 1.0),
    "terrainvis.visibility._threshold_kernels.grid_sweep": ("the calibrated relocation's walks on grids", 8.0),
    "terrainvis.visibility._threshold_kernels.tin_sweep": ("the calibrated relocation's walks on TINs", 4.0),
    "terrainvis.visibility._threshold_kernels.grid_eye_thresholds": ("a viewshed's heights and angles", 4.0),
    "terrainvis.visibility._threshold_kernels.tin_eye_thresholds": ("a viewshed's heights and angles on TINs", 2.0),
    "terrainvis.core._volume_kernels.volume_between": ("the volume between two surfaces", 3.0),
    "simplifiers._gc_kernels.greedy_cuts_front": ("greedy cuts", 6.0),
    "simplifiers._gi_kernels.init_state": ("greedy insertion", 2.0),
    "simplifiers._faber_kernels.feature_apply": ("feature-aware least squares", 2.0),
    "simplifiers._visopt_kernels.track_counts": ("visopt", 1.0),
}

#: numba options of a kernel that only other kernels call: no entry from Python (neither
#: the CPython wrapper nor the C one is made), which numba otherwise builds, optimises,
#: emits and caches for every compiled function. A cold first viewshed compiled in 14.8 s
#: of CPU instead of 18.0 (docs/performance.md, "Kernels without an entry from Python"). Such a kernel
#: must never be called from Python, where it would crash the interpreter (there is no
#: code behind its entry): ``tests/whole/test_kernel_only.py`` checks that no Python code of
#: terrainvis, its tests or its benchmarks names one but through :func:`from_python`.
KERNEL_ONLY = {"no_cpython_wrapper": True, "no_cfunc_wrapper": True}


def from_python(kernel):
    """A Python entry to a :data:`KERNEL_ONLY` kernel (or one numba inlines into its callers),
    for tests and benchmarks that call one from Python: a kernel (not cached) that calls it
    with the same positional arguments and returns what it returns.
    ``tests/whole/test_kernel_only.py`` allows Python code to name a kernel-only kernel only
    as this function's argument."""
    import inspect

    import numba as nb

    # the kernel's own positional parameters, not *args: numba inlines an ``inline="always"``
    # kernel only into a call with plain arguments
    names = ", ".join(f"a{i}" for i in range(len(inspect.signature(kernel.py_func).parameters)))
    scope = {"kernel": kernel}
    exec(f"def call({names}):\n    return kernel({names})\n", scope)
    return nb.njit(nogil=True)(scope["call"])


def kernel_of(kind: int, *names: str, **options):
    """Decorate a kernel written once for several kinds of input (a grid, a TIN) and made
    for one of them: ``kind`` (0, 1, ...) is a constant of the function's closure, and its
    body branches on it (``if kind == GRID: ...``), so numba drops the other branches before
    it types the function, and each made kernel is typed and compiled as a copy written for
    its kind alone would be (the closure's constant also keys numba's cache). The kernel takes the
    name ``names[kind]`` (its cache files, the compile notices of :data:`KERNELS`);
    ``options`` are numba's, beside ``cache=True, nogil=True`` (``**KERNEL_ONLY`` for a
    kernel only kernels call). A factory makes each kind::

        def _threshold(kind):
            @kernel_of(kind, "grid_threshold", "tin_threshold", **KERNEL_ONLY)
            def threshold(s, st, p, q, rules):
                ...
            return threshold

        grid_threshold, tin_threshold = _threshold(GRID), _threshold(TIN)

    ``tests/whole/test_kernel_only.py`` reads the names from the decorator; the layout and
    code-shape tests count a function it decorates as a kernel."""
    import numba as nb

    name = names[kind]

    def made(function):
        function.__name__ = name
        function.__qualname__ = name
        return nb.njit(cache=True, nogil=True, **options)(function)

    return made


#: The garbage collector's middle threshold (collections of the youngest generation between
#: two of the middle one; Python's default is 10) while a kernel of terrainvis compiles.
COMPILE_GC_THRESHOLD = 1000
#: The modules whose kernels compile under :data:`COMPILE_GC_THRESHOLD`.
_OURS = ("terrainvis.", "simplifiers.")

_lock = threading.Lock()
_gc_before: tuple | None = None  # the thresholds to restore when the compilation ends
_depth = 0  # compile events open (numba compiles one kernel at a time, holding its lock)
_started = 0.0
_total = 0.0
_announced: set = set()
_quiet = 0
_installed = False


def install() -> None:
    """Listen to numba's compile events and read stale cache indexes of terrainvis's kernels
    as empty (:func:`_tolerate_stale_indexes`); once per process, called when a kernel
    module is imported."""
    global _installed
    with _lock:
        if _installed:
            return
        from numba.core import event

        _tolerate_stale_indexes()

        class Listener(event.Listener):
            def on_start(self, ev):
                _on_start(ev)

            def on_end(self, ev):
                _on_end(ev)

        event.register("numba:compile", Listener())
        _installed = True


#: What unpickling a cache index raises when the index names a module, class or function
#: that is gone (a kernel module moved, a record renamed) or when the file is damaged.
_STALE_INDEX_ERRORS = (ImportError, AttributeError, EOFError, pickle.UnpicklingError)


def _ours(cache) -> bool:
    """Whether a numba ``Cache`` holds one of terrainvis's kernels (by its module's name)."""
    return getattr(getattr(cache, "_py_func", None), "__module__", "").startswith(_OURS)


def _drop_index(cache) -> None:
    """Remove a cache's index file (its compiled files stay until numba reuses their names)."""
    with contextlib.suppress(FileNotFoundError):
        os.remove(cache._cache_file._index_path)


def _tolerate_stale_indexes() -> None:
    """Treat a cache index of terrainvis's kernels that cannot be unpickled as a cache miss.

    numba keeps, per kernel, an index of the signatures it compiled, pickled with the types
    in them: a record type (a named tuple) is pickled by its module and name. When a new
    version of terrainvis moves a kernel module or renames a record, the indexes an older
    version left in a kept cache (``__pycache__`` folders of an editable install, a CI
    cache kept between runs, ``NUMBA_CACHE_DIR``) name a module that is gone, and numba
    0.68 raises ``ModuleNotFoundError`` from the first call of any kernel that had been
    compiled with that record, before it checks whether the index is stale (numba issue
    6018). Here the index of such a kernel is removed and the kernel compiles again, as
    for any stale index; numba writes a new one. Other programs' kernels are left to
    numba.
    """
    from numba.core import caching

    load, save = caching.Cache.load_overload, caching.Cache.save_overload
    if getattr(load, "terrainvis_tolerant", False):
        return

    def load_overload(self, sig, target_context):
        try:
            return load(self, sig, target_context)
        except _STALE_INDEX_ERRORS:
            if not _ours(self):
                raise
            _drop_index(self)
            return None

    def save_overload(self, sig, data):
        try:
            return save(self, sig, data)
        except _STALE_INDEX_ERRORS:
            if not _ours(self):
                raise
            _drop_index(self)
            return save(self, sig, data)

    load_overload.terrainvis_tolerant = True
    caching.Cache.load_overload = load_overload
    caching.Cache.save_overload = save_overload


def seconds() -> float:
    """Wall seconds this process has spent compiling numba kernels so far (the ones running included)."""
    with _lock:
        return _total + (time.perf_counter() - _started if _depth else 0.0)


def announced() -> list[str]:
    """The kernels announced so far in this process (``module.function``)."""
    with _lock:
        return sorted(_announced)


@contextlib.contextmanager
def quiet():
    """No compile lines while the block runs (in any thread)."""
    global _quiet
    with _lock:
        _quiet += 1
    try:
        yield
    finally:
        with _lock:
            _quiet -= 1


def _enabled() -> bool:
    return _quiet == 0 and os.environ.get("TERRAINVIS_COMPILE_NOTICE", "1") not in ("0", "no", "off", "false")


def _line(name: str) -> str | None:
    known = KERNELS.get(name)
    if known is None:
        return None
    what, estimate = known
    return (f"terrainvis: compiling {what}: about {estimate:.0f} s, on the first run only (numba compiles its "
            "kernels once and keeps them in its cache)")


def _on_start(ev) -> None:
    global _depth, _started, _gc_before
    line = None
    with _lock:
        if _depth == 0:
            _started = time.perf_counter()
            name = _name(ev)
            if name.startswith(_OURS):
                _gc_before = gc.get_threshold()
                young, middle, old = _gc_before
                gc.set_threshold(young, max(middle, COMPILE_GC_THRESHOLD), old)
            if name not in _announced and _enabled():
                line = _line(name)
                if line is not None:
                    _announced.add(name)
        _depth += 1
    if line is not None:
        print(line, file=sys.stderr, flush=True)


def _on_end(ev) -> None:
    global _depth, _total, _gc_before
    with _lock:
        _depth -= 1
        if _depth == 0:
            _total += time.perf_counter() - _started
            if _gc_before is not None:
                gc.set_threshold(*_gc_before)
                _gc_before = None


def _name(ev) -> str:
    try:
        fn = ev.data["dispatcher"].py_func
        return f"{fn.__module__}.{fn.__qualname__}"
    except Exception:  # numba internals: a best-effort label
        return ""
