"""The registry of methods, and the one entry point :func:`simplify`.

Every fact about a method lives in its :class:`Method` entry here: its name, kind, the
paper's row order (the order of :data:`METHODS`), where its code is, the halo it needs
on the block-wise path, how expensive it is (the runner schedules expensive units
first), how figures draw it, and the options it accepts. The rest of terrainvis reads
them through :data:`METHODS` and :func:`method_info`. A method from outside the package
is added with :func:`register` (a function), or by an installed plugin: a package that
declares an entry point in the group ``terrainvis.simplifiers`` whose value is a
:class:`Method` (:func:`load_plugins`, run when :mod:`simplifiers` is imported).

A *regular* method provides a curve operator ``op(f, axis=..., **options)`` that
reduces one axis of an array; :func:`simplify` applies it along rows, then columns,
``level`` times (:func:`simplifiers.reverse_faber.reduce_level`); a regular method
marked ``whole_grid`` instead provides ``op(grid, level, **options) -> HeightGrid`` at
the same coarse positions (it needs the whole terrain, as ``visopt`` does). An *irregular* method
provides ``build(grid, n_vertices, **options) -> TIN``; :func:`simplify` computes the
vertex budget, checks the result against the height-field rules
(:func:`check_height_field`) and records the metadata.
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import time
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from terrainvis.core.memory import check_memory
from terrainvis.core.registry import Registry
from terrainvis.core.validate import as_int, as_nonnegative_finite, describe, entry_name
from terrainvis.errors import SimplificationError
from terrainvis.core.terrain import TIN, HeightGrid

# repair, deviation and _target import numba (0.2 s): imported where a simplification runs,
# so that the methods' table and the levels (``terrainvis info``) come without it
from .levels import check_budget, check_level, coarse_coords, coarse_shape, vertex_budget

__all__ = [
    "Method", "METHODS", "KINDS", "register", "unregister", "load_plugins", "available", "default_methods",
    "method_info", "simplify", "check_height_field",
]

#: The kinds of method: ``"regular"`` returns a HeightGrid at the reverse Faber coarse
#: positions; ``"irregular"`` a TIN of the level's vertex budget; ``"semi-regular"`` a TIN
#: too, from a regular hierarchy of triangles (RTIN, as web-terrain tilers build).
KINDS = ("regular", "irregular", "semi-regular")
#: The entry-point group of plugin packages: each entry's value is a :class:`Method`.
PLUGIN_GROUP = "terrainvis.simplifiers"


@dataclass(frozen=True)
class Method:
    """One simplification method and everything the rest of terrainvis needs to know about it.

    Attributes
    ----------
    name : str
        The name passed to :func:`simplify` (and written in result tables).
    kind : {"regular", "irregular", "semi-regular"}
        Regular methods return a HeightGrid, irregular and semi-regular ones a TIN
        (:data:`KINDS`).
    module, attr : str
        Where the code is: a curve operator (regular), ``op(grid, level)`` (regular and
        ``whole_grid``) or ``build(grid, n_vertices)`` (irregular, semi-regular).
    description : str
        One line, with the reference.
    options : tuple of str
        The keyword options the method accepts (passed through :func:`simplify`).
    halo : int or None
        Fine samples each block needs from its neighbours on the block-wise path
        (:mod:`simplifiers.blockwise`); None when the method cannot run block-wise.
    cost_rank : int
        Scheduling order of the comparison runner: lower runs first (the most expensive
        methods), so that the pool stays busy to the end.
    style : (str, str)
        Matplotlib colour and marker of the method in figures.
    cascades : bool
        The method can continue from its own result at a finer level (``start=``), so a
        comparison may simplify level k+1 from level k instead of from the grid.
    default : bool
        The method is in a comparison's default method list (:mod:`terrainvis.experiment.options`).
    whole_grid : bool
        A regular method whose code is ``op(grid, level, **options) -> HeightGrid`` (the
        coarse grid at the reverse Faber positions) instead of a curve operator.
    memory : (int, int, int or None)
        Peak bytes the method adds per grid sample (for at most the third entry's samples;
        the rest cost :data:`_BYTES_PER_SAMPLE_BEYOND`) and per vertex of the result, the
        errors' evaluation included: the estimate :func:`simplify` checks against the
        memory available before it starts (:meth:`memory_need`).
    function : callable, optional
        The code itself, for a method registered with :func:`register` (``module`` and
        ``attr`` then name where it was defined, for messages and for worker processes,
        which import it from there).
    report_notes : str or callable, optional
        ``report_notes(rows) -> list of str``: lines that the report of
        :func:`terrainvis.compare` adds about this method's rows (a DataFrame of them) after
        its tables (:func:`terrainvis.experiment.report.method_notes`): a callable, or the
        name of a function of ``module``. None: none.
    """

    name: str
    kind: str
    module: str
    attr: str
    description: str
    options: tuple = ()
    halo: int | None = None
    cost_rank: int = 9
    style: tuple = ("k", "o")
    cascades: bool = False
    memory: tuple = (32, 0, None)
    default: bool = True
    whole_grid: bool = False
    function: Callable | None = None
    report_notes: str | Callable | None = None

    def memory_need(self, n_samples: int, n_vertices: int) -> int:
        """Estimated peak bytes of simplifying ``n_samples`` grid samples to ``n_vertices`` vertices."""
        per_sample, per_vertex, cap = self.memory
        heavy = n_samples if cap is None else min(n_samples, cap)
        return per_sample * heavy + _BYTES_PER_SAMPLE_BEYOND * (n_samples - heavy) + per_vertex * n_vertices

    def load(self):
        """The method's operator (regular) or build function (irregular, semi-regular)."""
        if self.function is not None:
            return self.function
        target = importlib.import_module(self.module)
        for part in self.attr.split("."):
            target = getattr(target, part)
        return target

    def notes(self, rows) -> list[str]:
        """The report's lines about ``rows``, this method's rows of a comparison (:attr:`report_notes`)."""
        if self.report_notes is None:
            return []
        notes = self.report_notes
        if isinstance(notes, str):
            notes = getattr(importlib.import_module(self.module), notes)
        return list(notes(rows))

    @property
    def regular(self) -> bool:
        return self.kind == "regular"


_RF = "simplifiers.reverse_faber"

#: Bytes per grid sample past a method's ``memory`` cap (QEC's tiles): the grid's mesh and the errors.
_BYTES_PER_SAMPLE_BEYOND = 72

#: Every method, in the paper's row order (irregular first, then regular).
METHODS: Registry = Registry("method", {
    m.name: m
    for m in (
        Method(
            "qec", "irregular", "simplifiers.quadric", "build",
            "quadric edge collapse (Garland & Heckbert 1997): pymeshlab, fast-simplification above 1.2 M samples",
            options=("backend", "start", "tile_samples"), cost_rank=1, style=("tab:red", "v"), cascades=True,
            # pymeshlab holds about 1 kB per sample of the mesh it decimates; tiles of 2^22 samples at most
            memory=(1000, 48, 2**22), report_notes="report_notes",
        ),
        Method(
            "greedy-cuts", "irregular", "simplifiers.greedy_cuts", "build",
            "greedy cuts (Silva, Mitchell & Kaufman 1995)",
            # heights, tolerances, occupancy, errors; front nodes, buckets, queue and triangles
            cost_rank=0, style=("tab:purple", "X"), memory=(56, 300, None),
        ),
        Method(
            "greedy-insertion", "irregular", "simplifiers.greedy_insertion", "build",
            "greedy insertion (Garland & Heckbert 1995, Algorithm III)",
            # heights and errors; 166 bytes of state per vertex, twice while an array grows, and the TIN
            cost_rank=3, style=("tab:orange", "P"), memory=(32, 400, None),
        ),
        Method("simple", "regular", _RF, "simple", "reverse Faber: keep the coarse samples",
               halo=2, cost_rank=6, style=("tab:gray", "o")),
        Method("gls", "regular", _RF, "gls", "reverse Faber: global least squares",
               halo=64, cost_rank=5, style=("tab:blue", "s")),
        Method("lls", "regular", _RF, "lls", "reverse Faber: local least squares",
               options=("weights",), halo=4, cost_rank=5, style=("tab:cyan", "D")),
        Method("feature", "regular", _RF, "feature", "reverse Faber: feature-aware least squares",
               options=("weight",), cost_rank=2, style=("tab:green", "^")),
        Method(
            "visopt", "regular", "simplifiers.visopt", "visopt",
            "visibility-optimized coarse heights for the calibrated relocation (docs/visopt.md)",
            options=("n_train", "rounds", "seed", "trust", "max_breakpoints"), cost_rank=1,
            style=("tab:olive", "*"), whole_grid=True, default=False,
            # GLS's solve and the error evaluation; the breakpoints (at most about 320 MB) do not grow with the grid
            memory=(48, 0, None),
        ),
    )
})


#: The methods terrainvis ships: :func:`register` refuses their names.
BUILTIN = METHODS.builtin


# ---------------------------------------------------------------------- methods from outside
def register(name: str, function: Callable, *, kind: str, description: str = "", options=(), cost_rank: int = 9,
             style=("k", "o"), memory=(32, 0, None), default: bool = False, report_notes: Callable | None = None,
             replace: bool = False) -> Method:
    """Register a simplification method from outside the package, and return its :class:`Method`.

    It is then a method like the built-in ones: :func:`simplify` runs it with the budget,
    height-field and memory checks, and :func:`terrainvis.compare` (serially, on worker
    processes and on dask, with resume), the tables and the figures take it by name. The
    registry is this Python process's: the command line (``terrainvis compare --methods``)
    sees a method of one's own through a plugin, an entry point of the group
    ``terrainvis.simplifiers`` (:func:`load_plugins`; ``examples/plugin/README.md``).

    Parameters
    ----------
    name : str
        Its name (not one of the built-in methods'; :data:`BUILTIN`): a letter or digit,
        then letters, digits and ``_ . + -``, at most 64 characters, since it becomes part
        of file names and table cells.
    function : callable
        ``kind="regular"``: ``function(grid, level, **options) -> HeightGrid`` with the
        coarse grid at the reverse Faber positions (:func:`simplifiers.levels.coarse_coords`
        of the grid's x and y at that level). ``kind="irregular"`` or ``"semi-regular"``:
        ``function(grid, n_vertices, **options) -> TIN``, a height field over the grid's
        extent with its four corners and ``n_vertices`` vertices (within
        :func:`~simplifiers.levels.budget_tolerance`). To run on worker processes it must
        be importable there: defined at the top level of a module (not a lambda, not in a
        notebook cell).
    kind : {"regular", "irregular", "semi-regular"}
    description : str
        One line for listings (default: the first line of the function's docstring).
    options : sequence of str
        The keyword options it accepts (through :func:`simplify`).
    cost_rank, style, memory, default, report_notes
        As in :class:`Method`: scheduling order (lower first), the figures' colour and
        marker, the memory estimate, whether a comparison runs it by default, and the lines
        a comparison's report adds about its rows.
    replace : bool
        Replace a method registered earlier under this name (never a built-in one).

    Returns
    -------
    Method

    Raises
    ------
    ValueError
        A name that is not a valid entry name (:data:`terrainvis.core.validate.ENTRY_NAME`:
        letters, digits and ``_ . + -``), built in or (without ``replace``) taken; an
        unknown kind.
    TypeError
        A function that is not callable or cannot take ``(grid, level_or_n_vertices,
        **options)``.

    Examples
    --------
    >>> from terrainvis import synthetic_terrain
    >>> from simplifiers.levels import coarse_coords
    >>> from terrainvis import HeightGrid
    >>> def every_other(grid, level):
    ...     step = 2 ** level
    ...     xs, ys = coarse_coords(grid.xs, level), coarse_coords(grid.ys, level)
    ...     return HeightGrid.from_coords(grid.height_on_grid(xs, ys), xs, ys)
    >>> m = register("every-other", every_other, kind="regular", description="samples at the coarse positions")
    >>> simplify(synthetic_terrain("hills", size=33), "every-other", 2).shape
    (9, 9)
    >>> _ = unregister("every-other")
    """
    METHODS.check_new(name, replace=replace)
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {list(KINDS)}, got {kind!r}")
    if not callable(function):
        raise TypeError(f"function must be callable, got {describe(function)}")
    if isinstance(options, str) or not all(isinstance(o, str) for o in options):
        raise TypeError(f"options must be a sequence of option names, got {options!r}")
    _check_signature(name, function, kind, tuple(options))
    if report_notes is not None and not callable(report_notes):
        raise TypeError(f"report_notes must be callable or None, got {describe(report_notes)}")
    if not description:
        doc = inspect.getdoc(function) or ""
        description = doc.splitlines()[0] if doc else f"{kind} method {name} (registered)"
    method = Method(
        name, kind, getattr(function, "__module__", None) or "", getattr(function, "__qualname__", name),
        description, options=tuple(options), cost_rank=as_int(cost_rank, "cost_rank"), style=tuple(style),
        memory=tuple(memory), default=bool(default), whole_grid=kind == "regular", function=function,
        report_notes=report_notes,
    )
    METHODS[name] = method
    return method


def _check_signature(name: str, function, kind: str, options: tuple) -> None:
    try:
        sig = inspect.signature(function)
    except (TypeError, ValueError):  # a builtin or an extension function: nothing to check
        return
    second = "level" if kind == "regular" else "n_vertices"
    try:
        sig.bind(None, 1, **{o: None for o in options})
    except TypeError as exc:
        raise TypeError(f"method {name!r}: its function must take (grid, {second}"
                        + "".join(f", {o}=..." for o in options) + f"); its signature is {sig} ({exc})") from None


def unregister(name: str) -> Method:
    """Remove a method added by :func:`register` (or a plugin) and return it; built-in methods stay."""
    return METHODS.remove(name)


#: The plugins that failed to load, by entry-point name (each reported once).
PLUGIN_FAILURES: dict[str, str] = {}


def load_plugins() -> list[str]:
    """Register the methods of installed plugins; return the names added.

    A plugin is a package that declares, in its ``pyproject.toml``,
    ``[project.entry-points."terrainvis.simplifiers"]`` ``my-method = "my_pkg.module:METHOD"``,
    where ``METHOD`` is a :class:`Method` (its ``name`` is the method's name). A plugin
    that fails to import, or whose entry is not a Method, or whose name is taken, is
    reported once (a :class:`UserWarning` naming it and the cause, recorded in
    :data:`PLUGIN_FAILURES`) and skipped; the other plugins load. Called when
    :mod:`simplifiers` is imported; calling it again loads only what is new.
    """
    from importlib.metadata import entry_points

    added = []
    for ep in entry_points(group=PLUGIN_GROUP):
        if ep.name in PLUGIN_FAILURES or any(m.module == ep.module and m.name == ep.name for m in METHODS.values()):
            continue
        try:
            method = ep.load()
            if not isinstance(method, Method):
                raise TypeError(f"its value {ep.value!r} is a {type(method).__name__}, not a simplifiers.Method")
            entry_name(method.name, "method")
            if method.kind not in KINDS:
                raise ValueError(f"its kind {method.kind!r} is not one of {list(KINDS)}")
            if method.name in METHODS:
                if METHODS[method.name] == method:
                    continue
                raise ValueError(f"its method name {method.name!r} is taken"
                                 + (" by a built-in method" if method.name in BUILTIN else ""))
        except Exception as exc:  # a broken plugin must not break terrainvis or the other plugins
            reason = f"{type(exc).__name__}: {exc}"
            PLUGIN_FAILURES[ep.name] = reason
            warnings.warn(f"simplifier plugin {ep.name!r} ({ep.value}) was not loaded: {reason}", UserWarning,
                          stacklevel=2)
            continue
        METHODS[method.name] = method
        added.append(method.name)
    return added


def available() -> list[str]:
    """Every registered method's name, in the paper's order (built-in, then registered ones);
    ``METHODS[name].kind`` is its kind. The other registries' ``available()`` answer alike.

    Examples
    --------
    >>> available()[:3], METHODS["lls"].kind
    (['qec', 'greedy-cuts', 'greedy-insertion'], 'regular')
    """
    return METHODS.names()


def default_methods() -> list[str]:
    """The methods a comparison runs unless told otherwise (``default=True``), in the paper's order.

    Examples
    --------
    >>> "visopt" in default_methods(), default_methods()[:2]
    (False, ['qec', 'greedy-cuts'])
    """
    return [name for name, m in METHODS.items() if m.default]


def method_info(method) -> Method:
    """The registry entry of ``method``, or ValueError naming the valid methods."""
    if isinstance(method, Method) and METHODS.get(method.name) == method:
        return method
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {list(METHODS)} (see simplifiers.available()), got {method!r}")
    return METHODS[method]


def simplify(grid: HeightGrid, method: str, level: int | None = None, *, max_error=None, **options):
    """Simplify a height grid with one of the registered methods, to a size or to an error.

    Parameters
    ----------
    grid : HeightGrid
        The fine terrain; it must hold no nodata.
    method : str
        One of :func:`available`: ``"simple"``, ``"gls"``, ``"lls"``, ``"feature"``
        (regular: the result is a HeightGrid) or ``"qec"``, ``"greedy-insertion"``,
        ``"greedy-cuts"`` (irregular: the result is a TIN).
    level : int, optional
        Number of reverse-subdivision steps; each halves both axes (120 -> 60 -> 30 -> 15).
        For an irregular method, the vertex budget is the sample count of the regular
        result at this level. Default 1, or no limit (0) when ``max_error`` is given.
    max_error : float, optional
        A target error E (z units): the result is the smallest one whose max vertical
        error is <= E, no finer than ``level`` (or ``n_vertices``) when given. Regular
        methods return the coarsest level within E; greedy insertion inserts until the
        error is <= E; greedy cuts triangulates with ε = E; quadric edge collapse
        searches the vertex count (:func:`simplifiers._target.qec_within`). When even
        the size limit exceeds E, that result is returned with ``stopped_by ==
        "budget"``.
    **options
        The method's options (:attr:`Method.options`). Irregular methods also accept
        ``n_vertices=N`` to set the budget directly (``level`` is then only recorded).

    Returns
    -------
    HeightGrid or TIN
        ``attrs`` records ``method``, ``kind``, ``level`` (for an irregular method
        simplified to an error without a level: None), ``n_vertices``, ``nbytes``,
        ``max_error`` and ``rms_error`` against ``grid`` (:func:`terrainvis.vertical_errors`)
        and ``seconds`` (the simplification alone, a search included); irregular results
        also ``budget``. With ``max_error``: ``max_error_target``, ``stopped_by`` and
        ``notes`` (a line saying what was reached), and the search's record
        (``level_errors`` of a regular method, ``probes`` of QEC).

    Examples
    --------
    >>> from terrainvis import synthetic_terrain
    >>> S = simplify(synthetic_terrain("hills", size=33), "lls", 2)
    >>> S.shape, S.attrs["method"], S.attrs["n_vertices"]
    ((9, 9), 'lls', 81)
    >>> T = simplify(synthetic_terrain("hills", size=33), "lls", max_error=25.0)
    >>> T.attrs["level"], T.attrs["max_error"] <= 25.0, T.attrs["stopped_by"]
    (2, True, 'max_error')
    """
    from terrainvis.core.deviation import vertical_errors

    from ._target import regular_within

    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    info = method_info(method)
    method = info.name
    grid.require_finite(f"simplify(method={method!r})")
    unknown = sorted(set(options) - set(info.options) - ({"n_vertices"} if not info.regular else set()))
    if unknown:
        raise TypeError(f"{method} got unexpected option(s) {unknown}; it accepts {sorted(info.options)}")
    target = None if max_error is None else as_nonnegative_finite(max_error, "max_error", "z units")
    if level is None and target is None and "n_vertices" not in options:
        level = 1
    if info.regular:
        level = check_level(grid.shape, 0 if level is None else level)
        check_memory(info.memory_need(grid.size, 0), f"simplify({method!r}) of a {grid.shape[0]}x{grid.shape[1]} grid")
        t0 = time.perf_counter()
        with _calling(info, grid):
            if target is None:
                out, extra = _apply_regular(grid, info, level, options), {}
            elif info.whole_grid:
                out, extra = _whole_grid_within(grid, info, level, target, options)
                level = extra.pop("level")
            else:
                out, extra = regular_within(grid, info.load(), level, target, options)
                level = extra.pop("level")
        seconds = time.perf_counter() - t0
        _check_regular_result(out, grid, level, info)
    else:
        out, seconds, level, budget, extra = _run_irregular(grid, info, level, options, target)
        extra["budget"] = budget
    err_max, err_rms = vertical_errors(grid, out)
    n_vertices = out.size if info.regular else out.n_vertices
    if target is not None and err_max <= target and "max_error" not in (extra.get("stopped_by"),
                                                                         out.attrs.get("stopped_by")):
        # the budget stopped the method, but the result meets the target all the same (max_error 0 with
        # every vertex kept): say so, rather than "not met"
        extra["stopped_by"] = "max_error"
        extra["notes"] = [f"max_error {target:g}: met with {n_vertices:,} vertices (max error {err_max:.4g}), "
                          "the most the budget allows"]
    out.attrs.update(
        method=method, kind=info.kind, level=level, n_vertices=int(n_vertices), nbytes=int(out.nbytes),
        max_error=err_max, rms_error=err_rms, seconds=seconds, **extra,
    )
    return out


@contextlib.contextmanager
def _calling(info: Method, grid: HeightGrid):
    """A method's own code runs in this block: its failure is a SimplificationError naming it.

    The errors of arguments and memory (TypeError, ValueError, MemoryError) and
    SimplificationError pass as they are; any other exception of a library or a plugin is
    wrapped with the method's name and the grid's shape (a plugin's KeyError was a
    traceback of 20 lines from the command line). ``sys.exit()`` in a plugin ended a
    whole comparison silently with its status: it is a failure of that method, recorded
    in its unit's rows like any other. Ctrl-C passes.
    """
    try:
        yield
    except (SimplificationError, TypeError, ValueError, MemoryError):
        raise
    except SystemExit as exc:
        raise SimplificationError(f"{info.name} called sys.exit({exc.code!r}) on a {grid.shape} grid: a method "
                                  "returns its result or raises") from None
    except Exception as exc:  # a library or a plugin failed: name the method and the cause
        raise SimplificationError(f"{info.name} failed on a {grid.shape} grid: {type(exc).__name__}: {exc}") from exc


def _check_regular_result(out, grid: HeightGrid, level: int, info: Method) -> None:
    """A regular method's result is a HeightGrid at the reverse Faber coarse positions of ``level``."""
    if not isinstance(out, HeightGrid):
        raise SimplificationError(f"{info.name} returned {describe(out)}, not a terrainvis.HeightGrid (a regular "
                                  "method returns the coarse grid)")
    shape = coarse_shape(grid.shape, level)
    if out.shape != shape:
        raise SimplificationError(f"{info.name} returned a {out.shape[0]}x{out.shape[1]} grid at level {level}, "
                                  f"not the {shape[0]}x{shape[1]} of the reverse Faber coarse positions")
    if not (np.array_equal(out.xs, coarse_coords(grid.xs, level)) and np.array_equal(out.ys, coarse_coords(grid.ys,
                                                                                                             level))):
        raise SimplificationError(f"{info.name} returned a grid whose coordinates are not the reverse Faber coarse "
                                  f"positions of level {level} (simplifiers.levels.coarse_coords)")
    if not np.isfinite(out.z).all():
        raise SimplificationError(f"{info.name} returned a grid with {int((~np.isfinite(out.z)).sum())} non-finite "
                                  "heights")


def _apply_regular(grid: HeightGrid, info: Method, level: int, options) -> HeightGrid:
    if level == 0:
        return grid.copy_with()
    if info.whole_grid:
        return info.load()(grid, level, **options)
    from .reverse_faber import reduce_level

    op = info.load()
    z = grid.z
    for _ in range(level):
        z = reduce_level(z, op, **options)
    return HeightGrid.from_coords(z, coarse_coords(grid.xs, level), coarse_coords(grid.ys, level), attrs=grid.attrs)


def _whole_grid_within(grid: HeightGrid, info: Method, cap: int, target: float, options):
    """:func:`simplifiers._target.regular_within` for a ``whole_grid`` method: each level
    from ``cap`` to the deepest computed from the grid, the coarsest within ``target`` kept."""
    from terrainvis.core.deviation import vertical_errors

    from .levels import max_level

    levels = [(lv, out, vertical_errors(grid, out)[0])
              for lv in range(cap, max_level(grid.shape) + 1)
              for out in [_apply_regular(grid, info, lv, options)]]
    within = [item for item in levels if item[2] <= target]
    level, out, err = within[-1] if within else levels[0]
    if within:
        note = f"max_error {target:g}: level {level} is the coarsest within it (max error {err:.4g})"
    else:
        note = f"max_error {target:g} is not met even at level {level}, the finest allowed (max error {err:.4g})"
    return out, {"level": level, "max_error_target": target, "stopped_by": "max_error" if within else "budget",
                 "level_errors": [[lv, e] for lv, _, e in levels], "notes": [note]}


def _run_irregular(grid: HeightGrid, info: Method, level, options, target):
    """``(tin, seconds, level, budget, extra attrs)`` of an irregular method (``target``: max_error or None)."""
    from ._target import qec_within

    options = dict(options)
    n_override = options.pop("n_vertices", None)
    if n_override is not None:
        if level is not None:
            level = as_int(level, "level", minimum=0)
        budget = check_budget(grid.shape, n_override, "n_vertices")
    elif level is None:  # an error target without a size limit
        budget = grid.size
    else:
        level = check_level(grid.shape, level)
        budget = vertex_budget(grid.shape, level)
    # an error target's count is unknown: the per-sample part alone is checked then
    need = info.memory_need(grid.size, budget if target is None else 0)
    check_memory(need, f"simplify({info.name!r}) of a {grid.shape[0]}x{grid.shape[1]} grid to {budget:,} vertices")
    t0 = time.perf_counter()
    extra = {}
    if grid.shape == (2, 2) or (budget == grid.size and target is None):
        own = grid.to_tin()
        tin = TIN(own.vertices, own.faces)  # a fresh object: its attrs must not touch the grid's cached TIN
    else:
        build = info.load()
        with _calling(info, grid):
            if target is None:
                tin = build(grid, budget, **options)
            elif info.name == "qec":
                tin, extra = qec_within(grid, build, budget, target, options)
            else:  # greedy insertion, greedy cuts and the peers (simplifiers/peers) stop at the error themselves
                tin = build(grid, budget, max_error=target, **options)
                extra = _error_note(tin, target, budget)
        if not isinstance(tin, TIN):
            raise SimplificationError(f"{info.name} returned {describe(tin)}, not a terrainvis.TIN (an {info.kind} "
                                      "method returns a TIN)")
    seconds = time.perf_counter() - t0
    early = "max_error" in (tin.attrs.get("stopped_by"), extra.get("stopped_by"))
    if early and tin.n_vertices > budget:
        raise SimplificationError(
            f"{info.name} stopped by max_error with {tin.n_vertices} vertices, over the budget of {budget}"
        )
    # An error threshold may stop a method before the budget: fewer vertices are
    # expected then, and every other rule still holds.
    check_height_field(tin, grid, method=info.name, budget=None if early else budget)
    # the result carries the grid's attrs (name, CRS, georeferencing) as a regular one does
    tin.attrs = {**grid.attrs, **tin.attrs}
    return tin, seconds, level, budget, extra


def _error_note(tin: TIN, target: float, budget: int) -> dict:
    """The attrs of a greedy result simplified to an error (its own ``stopped_by`` says which limit held)."""
    search = tin.attrs.get("search")
    if tin.attrs.get("stopped_by") == "max_error" and isinstance(search, dict) and "errors" in search:
        # a peer's bisection over its library's parameter (simplifiers/peers/_common.py)
        note = (f"max_error {target:g}: {tin.n_vertices:,} vertices, the fewest found within it "
                f"(a search over {search.get('parameter', 'a parameter')})")
    elif tin.attrs.get("stopped_by") == "max_error":
        note = f"max_error {target:g}: {tin.n_vertices:,} vertices, the first count within it"
    else:
        note = f"max_error {target:g} is not met within the budget of {budget:,} vertices"
    return {"max_error_target": target, "notes": [note]}


def check_height_field(tin: TIN, grid: HeightGrid, *, method: str, budget: int | None = None) -> None:
    """Raise :class:`SimplificationError` unless ``tin`` is a valid height field over ``grid``'s extent.

    The rules and what the message says are :func:`terrainvis.core.repair.height_field_problems`'s
    (with ``budget``: the vertex count within :func:`~simplifiers.levels.budget_tolerance` of it).
    """
    from terrainvis.core.repair import height_field_problems

    problems = height_field_problems(tin, grid, budget=budget)
    if problems:
        raise SimplificationError(f"{method} returned an invalid height field: " + "; ".join(problems))
