"""The registry of methods, and the one entry point :func:`simplify`.

Every fact about a method lives in its :class:`Method` entry here: its name, kind, the
paper's row order (the order of :data:`METHODS`), where its code is, the halo it needs
on the block-wise path, how expensive it is (the runner schedules expensive units
first), how figures draw it, and the options it accepts. The rest of terrainvis reads
them through :data:`METHODS` and :func:`method_info`; adding a method means adding an
entry here and writing its module.

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

import importlib
import time
from dataclasses import dataclass

import numpy as np

from terrainvis.core.memory import check_memory
from terrainvis.core.mesh import NotADiskError, boundary_loop, footprint_matches, signed_area2
from terrainvis.core.validate import as_int, as_nonnegative_finite, describe
from terrainvis.core.deviation import vertical_errors
from terrainvis.errors import SimplificationError
from terrainvis.core.terrain import TIN, HeightGrid

from ._target import qec_within, regular_within
from .levels import check_budget, check_level, check_vertex_count, coarse_coords, vertex_budget

__all__ = ["Method", "METHODS", "available", "default_methods", "method_info", "simplify", "check_height_field"]


@dataclass(frozen=True)
class Method:
    """One simplification method and everything the rest of terrainvis needs to know about it.

    Attributes
    ----------
    name : str
        The name passed to :func:`simplify` (and written in result tables).
    kind : {"regular", "irregular"}
        Regular methods return a HeightGrid, irregular ones a TIN.
    module, attr : str
        Where the code is: a curve operator (regular) or ``build`` (irregular).
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

    def memory_need(self, n_samples: int, n_vertices: int) -> int:
        """Estimated peak bytes of simplifying ``n_samples`` grid samples to ``n_vertices`` vertices."""
        per_sample, per_vertex, cap = self.memory
        heavy = n_samples if cap is None else min(n_samples, cap)
        return per_sample * heavy + _BYTES_PER_SAMPLE_BEYOND * (n_samples - heavy) + per_vertex * n_vertices

    def load(self):
        """The method's operator (regular) or build function (irregular)."""
        return getattr(importlib.import_module(self.module), self.attr)

    @property
    def regular(self) -> bool:
        return self.kind == "regular"


_RF = "simplifiers.reverse_faber"

#: Bytes per grid sample past a method's ``memory`` cap (QEC's tiles): the grid's mesh and the errors.
_BYTES_PER_SAMPLE_BEYOND = 72

#: Every method, in the paper's row order (irregular first, then regular).
METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method(
            "qec", "irregular", "simplifiers.quadric", "build",
            "quadric edge collapse (Garland & Heckbert 1997): pymeshlab, fast-simplification above 1.2 M samples",
            options=("backend", "start", "tile_samples"), cost_rank=1, style=("tab:red", "v"), cascades=True,
            # pymeshlab holds about 1 kB per sample of the mesh it decimates; tiles of 2^22 samples at most
            memory=(1000, 48, 2**22),
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
            "visibility-optimized coarse heights for the calibrated relocation (issue 18; docs/visopt.md)",
            options=("n_train", "rounds", "seed", "trust", "max_breakpoints"), cost_rank=1,
            style=("tab:olive", "*"), whole_grid=True, default=False,
            # GLS's solve and the error evaluation; the breakpoints (at most about 320 MB) do not grow with the grid
            memory=(48, 0, None),
        ),
    )
}


def available() -> dict[str, str]:
    """Every registered method and its kind, in the paper's order.

    Examples
    --------
    >>> available()["lls"], available()["qec"]
    ('regular', 'irregular')
    """
    return {name: m.kind for name, m in METHODS.items()}


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
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    info = method_info(method)
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
        if target is None:
            out, extra = _apply_regular(grid, info, level, options), {}
        elif info.whole_grid:
            out, extra = _whole_grid_within(grid, info, level, target, options)
            level = extra.pop("level")
        else:
            out, extra = regular_within(grid, info.load(), level, target, options)
            level = extra.pop("level")
        seconds = time.perf_counter() - t0
    else:
        out, seconds, level, budget, extra = _run_irregular(grid, info, level, options, target)
        extra["budget"] = budget
    err_max, err_rms = vertical_errors(grid, out)
    n_vertices = out.size if info.regular else out.n_vertices
    out.attrs.update(
        method=method, kind=info.kind, level=level, n_vertices=int(n_vertices), nbytes=int(out.nbytes),
        max_error=err_max, rms_error=err_rms, seconds=seconds, **extra,
    )
    return out


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
        try:
            if target is None:
                tin = build(grid, budget, **options)
            elif info.name == "qec":
                tin, extra = qec_within(grid, build, budget, target, options)
            else:  # greedy insertion and greedy cuts stop at the error themselves
                tin = build(grid, budget, max_error=target, **options)
                extra = _error_note(tin, target, budget)
        except (SimplificationError, TypeError, ValueError, MemoryError):
            raise
        except Exception as exc:  # a library failed: name the method and the cause
            raise SimplificationError(f"{info.name} failed on a {grid.shape} grid: {type(exc).__name__}: {exc}") from exc
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
    if tin.attrs.get("stopped_by") == "max_error":
        note = f"max_error {target:g}: {tin.n_vertices:,} vertices, the first count within it"
    else:
        note = f"max_error {target:g} is not met within the budget of {budget:,} vertices"
    return {"max_error_target": target, "notes": [note]}


def check_height_field(tin: TIN, grid: HeightGrid, *, method: str, budget: int | None = None) -> None:
    """Raise :class:`SimplificationError` unless ``tin`` is a valid height field over ``grid``'s extent.

    The rules: the four corners are vertices and no vertex lies outside the extent; the
    mesh is one triangulated disk (every edge shared by at most two faces, consistently
    oriented, one boundary loop, Euler characteristic 1) whose boundary edges all lie
    on the four boundary lines; every face is counter-clockwise in projection; the
    projected area equals the extent's; and the vertex count is within
    :func:`~simplifiers.levels.budget_tolerance` of ``budget`` (when given).

    Together these mean the TIN covers the extent exactly once: with every face
    counter-clockwise, the number of faces over a point equals the winding number of the
    boundary loop around it. A loop running along the rectangle's sides has one winding
    number k everywhere inside, and the area rule makes k = 1. So no grid sample needs to
    be located to check coverage.
    """
    xmin, xmax, ymin, ymax = grid.extent
    v = tin.vertices
    problems = []
    for cx, cy in ((xmin, ymin), (xmax, ymin), (xmin, ymax), (xmax, ymax)):
        if not ((v[:, 0] == cx) & (v[:, 1] == cy)).any():
            problems.append(f"corner ({cx:g}, {cy:g}) is missing")
    outside = (v[:, 0] < xmin) | (v[:, 0] > xmax) | (v[:, 1] < ymin) | (v[:, 1] > ymax)
    if outside.any():
        problems.append(f"{int(outside.sum())} vertices lie outside the extent")
    area2 = signed_area2(v, tin.faces)
    if not (area2 > 0).all():
        problems.append(f"{int((area2 <= 0).sum())} of {area2.size} faces fold over (not counter-clockwise)")
    area = (xmax - xmin) * (ymax - ymin)
    if not footprint_matches(0.5 * area2.sum(), area):
        problems.append(f"the projected area is {0.5 * area2.sum() / area:.6%} of the extent's")
    used = np.zeros(tin.n_vertices, dtype=bool)
    used[tin.faces.ravel()] = True
    if not used.all():
        problems.append(f"{int((~used).sum())} vertices belong to no face")
    else:
        try:
            loop = boundary_loop(tin.faces, tin.n_vertices)
        except NotADiskError as exc:
            problems.append(str(exc))
        else:
            p, q = v[loop], v[np.roll(loop, -1)]
            on_line = (
                ((p[:, 0] == xmin) & (q[:, 0] == xmin)) | ((p[:, 0] == xmax) & (q[:, 0] == xmax))
                | ((p[:, 1] == ymin) & (q[:, 1] == ymin)) | ((p[:, 1] == ymax) & (q[:, 1] == ymax))
            )
            if not on_line.all():
                problems.append(f"{int((~on_line).sum())} boundary edges lie off the boundary lines")
    if budget is not None:
        count = check_vertex_count(tin.n_vertices, budget)
        if count:
            problems.append(count)
    if problems:
        raise SimplificationError(f"{method} returned an invalid height field: " + "; ".join(problems))
