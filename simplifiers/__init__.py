"""Terrain simplifiers, all behind :func:`simplify` (``simplify(grid, method, level)``).

Regular methods keep a height grid (reverse Faber subdivision: ``"simple"``, ``"gls"``,
``"lls"``, ``"feature"``); irregular ones return a TIN with the same vertex budget
(``"qec"``, ``"greedy-insertion"``, ``"greedy-cuts"``). :data:`METHODS` holds every fact
about each method (kind, the paper's order, block-wise halo, cost, plot style, options);
:mod:`simplifiers.levels` maps levels to sizes and budgets. :func:`register` adds a method
from outside the package; installed plugins (entry points in the group
``terrainvis.simplifiers``) are registered when this package is imported
(:func:`load_plugins`).
"""

from __future__ import annotations

import importlib

from .levels import budget_tolerance, coarse_coords, coarse_length, coarse_shape, max_level, vertex_budget
from .registry import (
    KINDS,
    METHODS,
    Method,
    available,
    check_height_field,
    default_methods,
    load_plugins,
    method_info,
    register,
    simplify,
    unregister,
)

__all__ = [
    "simplify", "available", "default_methods", "METHODS", "Method", "KINDS", "register", "unregister",
    "load_plugins", "method_info", "check_height_field",
    "max_level", "vertex_budget", "budget_tolerance", "coarse_length", "coarse_shape", "coarse_coords",
    "faber_subdivide", "reverse_faber", "quadric", "greedy_insertion", "greedy_cuts", "blockwise", "levels",
]


def __getattr__(name):
    if name == "faber_subdivide":
        from .reverse_faber import faber_subdivide

        return faber_subdivide
    if name in ("reverse_faber", "quadric", "greedy_insertion", "greedy_cuts", "blockwise"):
        return importlib.import_module(f"simplifiers.{name}")
    raise AttributeError(f"module 'simplifiers' has no attribute {name!r}")


load_plugins()  # after every name above exists: a plugin may import them from this package
