"""The one entry point, :func:`simplify`, and the registry of methods behind it.

Each method lives in its own module. A *regular* method provides a curve operator
``op(f, axis=...)`` that reduces one axis of an array; :func:`simplify` applies it along
rows then columns, ``level`` times (through ``reverse_faber.reduce_level``). An *irregular* method provides
``build(grid, n_vertices, **options) -> TIN``; :func:`simplify` computes the vertex
budget, checks the result against the height-field rules and records the metadata.
"""

from __future__ import annotations

import importlib
import time
from dataclasses import dataclass

import numpy as np

from terrainvis._validate import as_int, describe
from terrainvis.errors import SimplificationError
from terrainvis.metrics import errors_from_heights, vertical_errors
from terrainvis.terrain import TIN, HeightGrid

__all__ = ["simplify", "available", "coarse_length", "max_level", "vertex_budget", "check_height_field"]


@dataclass(frozen=True)
class Method:
    name: str
    kind: str  # "regular" or "irregular"
    module: str
    attr: str
    description: str

    def load(self):
        return getattr(importlib.import_module(self.module), self.attr)


_METHODS = {
    m.name: m
    for m in [
        Method("simple", "regular", "simplifiers.reverse_faber", "simple", "reverse Faber: keep the coarse samples"),
        Method("gls", "regular", "simplifiers.reverse_faber", "gls", "reverse Faber: global least squares"),
        Method("lls", "regular", "simplifiers.reverse_faber", "lls", "reverse Faber: local least squares"),
        Method("feature", "regular", "simplifiers.reverse_faber", "feature", "reverse Faber: feature-aware least squares"),
        Method("qec", "irregular", "simplifiers.quadric", "build", "quadric edge collapse (Garland & Heckbert 1997)"),
        Method(
            "greedy-insertion", "irregular", "simplifiers.greedy_insertion", "build",
            "greedy insertion (Garland & Heckbert 1995, Algorithm III)",
        ),
        Method(
            "greedy-cuts", "irregular", "simplifiers.greedy_cuts", "build",
            "greedy cuts (Silva, Mitchell & Kaufman 1995)",
        ),
    ]
}

#: The paper's order of methods (regular first, then irregular).
METHOD_ORDER = tuple(_METHODS)


def available() -> dict[str, str]:
    """Every registered method and its kind, ``{"simple": "regular", ..., "qec": "irregular", ...}``."""
    return {name: m.kind for name, m in _METHODS.items()}


def method_info(method: str) -> Method:
    if not isinstance(method, str) or method not in _METHODS:
        raise ValueError(
            f"method must be one of {list(_METHODS)} (see simplifiers.available()), got {method!r}"
        )
    return _METHODS[method]


def coarse_length(m: int) -> int:
    """Samples left after one reverse-subdivision step of a curve of ``m`` samples."""
    return (m + 1) // 2


def max_level(shape) -> int:
    """The deepest level for a grid of this shape: each step needs at least 3 samples per axis."""
    level = 0
    rows, cols = shape
    while rows >= 3 and cols >= 3:
        rows, cols = coarse_length(rows), coarse_length(cols)
        level += 1
    return level


def _coarse_shape(shape, level: int) -> tuple[int, int]:
    rows, cols = shape
    for _ in range(level):
        rows, cols = coarse_length(rows), coarse_length(cols)
    return rows, cols


def vertex_budget(shape, level: int) -> int:
    """The number of samples of the ``"simple"`` result at ``level``: the irregular budget."""
    rows, cols = _coarse_shape(shape, level)
    return rows * cols


def _check_level(grid: HeightGrid, level) -> int:
    level = as_int(level, "level", minimum=0)
    top = max_level(grid.shape)
    if level > top:
        raise ValueError(
            f"level must be in [0, {top}] for a {grid.shape[0]}x{grid.shape[1]} grid "
            f"(each step needs at least 3 samples along both axes), got {level}"
        )
    return level


def simplify(grid: HeightGrid, method: str, level: int = 1, **options):
    """Simplify a height grid with one of the registered methods.

    Parameters
    ----------
    grid : HeightGrid
        The fine terrain; it must hold no nodata.
    method : str
        One of :func:`available`: ``"simple"``, ``"gls"``, ``"lls"``, ``"feature"``
        (regular: the result is a HeightGrid) or ``"qec"``, ``"greedy-insertion"``,
        ``"greedy-cuts"`` (irregular: the result is a TIN).
    level : int
        Number of reverse-subdivision steps; each halves both axes (120 -> 60 -> 30 -> 15).
        For an irregular method, the vertex budget is the sample count of the regular
        result at this level.
    **options
        Method options. Irregular methods accept ``vertices=N`` to override the budget.

    Returns
    -------
    HeightGrid or TIN
        A regular result carries its metadata in ``.attrs``, an irregular one in ``.meta``:
        method, level, vertex count, bytes, max and RMS vertical error against ``grid``,
        and the seconds taken.
    """
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    info = method_info(method)
    grid.require_finite(f"simplify(method={method!r})")
    if info.kind == "regular":
        level = _check_level(grid, level)
        t0 = time.perf_counter()
        out = _apply_regular(grid, method, level, options)
        seconds = time.perf_counter() - t0
        meta = out.attrs
    else:
        out, seconds, approx = _run_irregular(grid, info, level, options)
        meta = out.meta
    if info.kind == "regular":
        err_max, err_rms = vertical_errors(grid, out)
    else:
        err_max, err_rms = errors_from_heights(grid, approx)
    n_vertices = out.size if isinstance(out, HeightGrid) else out.n_vertices
    meta.update(
        method=method, kind=info.kind, level=level, n_vertices=int(n_vertices), nbytes=int(out.nbytes),
        max_error=err_max, rms_error=err_rms, seconds=seconds,
    )
    return out


def _apply_regular(grid: HeightGrid, method: str, level: int, options) -> HeightGrid:
    if level == 0:
        return grid.copy_with()
    # Coordinates: every operator reproduces linear functions, so on a uniform axis
    # applying it to the coordinates gives exactly the coordinates at the coarse
    # positions. After one level the last gap is wider (even lengths), the axis is no
    # longer linear in the index, and the operators act in index space; we then keep the
    # coordinates at the coarse positions, which is what the operator gives on the
    # uniform first level, so every level covers the same extent with the same rule.
    # One level is the operator along every row (axis 1), then along every column
    # (axis 0); reduce_level does exactly that (fused into one pass for LLS).
    from simplifiers.reverse_faber import reduce_level
    from simplifiers.reverse_faber import simple as take_coarse

    z, xs, ys = grid.z, grid.xs, grid.ys
    for _ in range(level):
        z = reduce_level(z, method, **options)
        xs = take_coarse(xs, axis=0)
        ys = take_coarse(ys, axis=0)
    return HeightGrid.from_coords(z, xs, ys, attrs=grid.attrs)


def _run_irregular(grid: HeightGrid, info: Method, level, options):
    options = dict(options)
    n_override = options.pop("vertices", None)
    if n_override is None:
        level = _check_level(grid, level)
        budget = vertex_budget(grid.shape, level)
    else:
        if level is not None:
            level = as_int(level, "level", minimum=0)
        budget = as_int(n_override, "vertices")
    if budget < 4 or budget > grid.size:
        raise ValueError(
            f"the vertex budget must be in [4, {grid.size}] for a {grid.shape[0]}x{grid.shape[1]} grid, got {budget}"
        )
    t0 = time.perf_counter()
    if grid.shape == (2, 2) or budget == grid.size:
        own = grid.to_tin()
        tin = TIN(own.vertices, own.faces)  # a fresh object: its meta must not touch the grid's cached TIN
    else:
        build = info.load()
        try:
            tin = build(grid, budget, **options)
        except (SimplificationError, TypeError, ValueError):
            raise
        except Exception as exc:  # a library failed: name the method and the cause
            raise SimplificationError(f"{info.name} failed on a {grid.shape} grid: {type(exc).__name__}: {exc}") from exc
    seconds = time.perf_counter() - t0
    if tin.meta.get("stopped_by") == "max_error":
        # An error threshold stopped the method before the budget: fewer vertices are
        # expected, every other rule still holds.
        approx = check_height_field(tin, grid, method=info.name, budget=None)
        if tin.n_vertices > budget:
            raise SimplificationError(f"{info.name} stopped by max_error with {tin.n_vertices} vertices, over the budget of {budget}")
    else:
        approx = check_height_field(tin, grid, method=info.name, budget=budget)
    tin.meta["budget"] = budget
    return tin, seconds, approx


def budget_tolerance(budget: int) -> int:
    """Allowed |vertex count - budget|: 1 % of the budget, and at least one vertex."""
    return max(1, int(0.01 * budget))


def check_height_field(tin: TIN, grid: HeightGrid, *, method: str, budget: int | None = None) -> np.ndarray:
    """Raise :class:`SimplificationError` unless ``tin`` is a valid height field over ``grid``'s extent.

    The rules: the four corners are vertices, every boundary vertex lies on a boundary
    line, every face normal has z > 0, the projected area equals the extent's, every grid
    sample lies inside the footprint, and the vertex count is within
    :func:`budget_tolerance` of the budget.

    Returns
    -------
    (rows, cols) float64
        The TIN's heights at the grid's samples (computed for the footprint check).
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
    # Undirected edges as one int64 key each (lo * n + hi): a 1-D unique is far cheaper
    # than a row-wise one.
    n = np.int64(tin.n_vertices)
    e = tin.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)
    keys, counts = np.unique(np.minimum(e[:, 0], e[:, 1]) * n + np.maximum(e[:, 0], e[:, 1]), return_counts=True)
    single = keys[counts == 1]
    bverts = np.unique(np.concatenate([single // n, single % n]))
    on_line = (v[bverts, 0] == xmin) | (v[bverts, 0] == xmax) | (v[bverts, 1] == ymin) | (v[bverts, 1] == ymax)
    if not on_line.all():
        problems.append(f"{int((~on_line).sum())} boundary vertices lie off the boundary lines")
    if (counts > 2).any():
        problems.append(f"{int((counts > 2).sum())} edges are shared by more than two faces")
    nz = tin.face_normals_z()
    if not (nz > 0).all():
        problems.append(f"{int((nz <= 0).sum())} of {nz.size} faces fold over (normal z <= 0)")
    area = (xmax - xmin) * (ymax - ymin)
    fp = tin.footprint_area()
    if abs(fp - area) > 1e-9 * area:
        problems.append(f"the projected area is {fp / area:.6%} of the extent's")
    approx = None
    if not problems:
        approx = tin.height_on_grid(grid.xs, grid.ys)
        missing = np.isnan(approx)
        if missing.any():
            problems.append(f"{int(missing.sum())} grid samples lie outside the footprint")
    if budget is not None and abs(tin.n_vertices - budget) > budget_tolerance(budget):
        problems.append(f"it has {tin.n_vertices} vertices for a budget of {budget}")
    if problems:
        raise SimplificationError(f"{method} returned an invalid height field: " + "; ".join(problems))
    return approx
