"""How simplification levels map to sizes: coarse lengths, vertex budgets and their checks.

A level is a number of reverse-subdivision steps. Each step keeps ``(m + 1) // 2`` of the
``m`` samples along both axes (120 -> 60 -> 30 -> 15), at the coarse positions of
:func:`simplifiers.reverse_faber.coarse_positions`. An irregular method gets the same
vertex budget as the regular result at that level, within :func:`budget_tolerance`.

Every method and the registry take their level and budget rules from here.
"""

from __future__ import annotations

import numpy as np

from terrainvis.core.validate import as_int
from terrainvis.tolerances import BUDGET_WINDOW_REL

__all__ = [
    "coarse_length", "coarse_shape", "coarse_coords", "max_level", "vertex_budget", "budget_tolerance",
    "check_level", "check_budget", "check_vertex_count",
]


def coarse_length(m: int) -> int:
    """Samples left after one reverse-subdivision step of a curve of ``m`` samples."""
    return (m + 1) // 2


def coarse_shape(shape, level: int) -> tuple[int, int]:
    """The grid shape after ``level`` steps.

    Examples
    --------
    >>> coarse_shape((120, 120), 3)
    (15, 15)
    """
    rows, cols = shape
    for _ in range(level):
        rows, cols = coarse_length(rows), coarse_length(cols)
    return rows, cols


def coarse_coords(v: np.ndarray, level: int) -> np.ndarray:
    """A coordinate vector after ``level`` steps: its values at the coarse positions.

    Every reverse Faber operator reproduces linear functions, so on a uniform axis this
    is exactly what applying the operator to the coordinates gives; after the first step
    the last gap of an even length is wider and the axis is no longer linear in the
    index, so every level takes the coordinates at the coarse positions, the same rule.

    Examples
    --------
    >>> coarse_coords(np.arange(8.0), 1).tolist()
    [0.0, 2.0, 4.0, 7.0]
    """
    from .reverse_faber import coarse_positions

    for _ in range(level):
        v = v[coarse_positions(v.shape[0])]
    return v


def max_level(shape) -> int:
    """The deepest level for a grid of this shape: each step needs at least 3 samples per axis.

    Examples
    --------
    >>> max_level((120, 120)), max_level((3, 200)), max_level((2, 9))
    (6, 1, 0)
    """
    level = 0
    rows, cols = shape
    while rows >= 3 and cols >= 3:
        rows, cols = coarse_length(rows), coarse_length(cols)
        level += 1
    return level


def vertex_budget(shape, level: int) -> int:
    """The sample count of a regular result at ``level``: the irregular methods' budget.

    Examples
    --------
    >>> vertex_budget((120, 120), 1), vertex_budget((120, 120), 3)
    (3600, 225)
    """
    rows, cols = coarse_shape(shape, level)
    return rows * cols


def budget_tolerance(budget: int) -> int:
    """Allowed |vertex count - budget|: :data:`~terrainvis.tolerances.BUDGET_WINDOW_REL` (1 %)
    of the budget, and at least one vertex."""
    return max(1, int(BUDGET_WINDOW_REL * budget))


def check_level(shape, level) -> int:
    """``level`` as an int, or ValueError naming the valid range for this grid shape."""
    level = as_int(level, "level", minimum=0)
    top = max_level(shape)
    if level > top:
        raise ValueError(
            f"level must be in [0, {top}] for a {shape[0]}x{shape[1]} grid "
            f"(each step needs at least 3 samples along both axes), got {level}"
        )
    return level


def check_budget(shape, n_vertices, name: str = "n_vertices") -> int:
    """A vertex budget as an int in [4, rows * cols], or an error naming ``name``."""
    n = as_int(n_vertices, name)
    size = shape[0] * shape[1]
    if n < 4 or n > size:
        raise ValueError(f"{name} must be in [4, {size}] for a {shape[0]}x{shape[1]} grid, got {n}")
    return n


def check_vertex_count(n_vertices: int, budget: int) -> str | None:
    """None when ``n_vertices`` is within :func:`budget_tolerance` of ``budget``, else the problem."""
    if abs(n_vertices - budget) <= budget_tolerance(budget):
        return None
    return f"it has {n_vertices} vertices for a budget of {budget} +- {budget_tolerance(budget)}"
