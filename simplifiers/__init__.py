"""Terrain simplifiers, all behind :func:`simplify` (``simplify(grid, method, level)``).

Regular methods keep a height grid (reverse Faber subdivision: ``"simple"``, ``"gls"``,
``"lls"``, ``"feature"``); irregular ones return a TIN with the same vertex budget
(``"qec"``, ``"greedy-insertion"``, ``"greedy-cuts"``). :func:`available` lists them.
"""

from __future__ import annotations

import importlib

from ._registry import available, check_height_field, max_level, simplify, vertex_budget

__all__ = [
    "simplify", "available", "max_level", "vertex_budget", "check_height_field",
    "reconstruction_error", "faber_subdivide", "reverse_faber",
]


def reconstruction_error(fine, coarse) -> tuple[float, float]:
    """Maximum and RMS vertical error of a simplified surface (grid or TIN) against ``fine``.

    See :func:`terrainvis.metrics.vertical_errors`.
    """
    from terrainvis.metrics import vertical_errors

    return vertical_errors(fine, coarse)


def __getattr__(name):
    if name == "faber_subdivide":
        from .reverse_faber import faber_subdivide

        return faber_subdivide
    if name in ("reverse_faber", "quadric", "greedy_insertion", "greedy_cuts"):
        return importlib.import_module(f"simplifiers.{name}")
    raise AttributeError(f"module 'simplifiers' has no attribute {name!r}")
