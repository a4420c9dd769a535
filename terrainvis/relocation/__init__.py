"""Placing test points on a simplified terrain: the paper's relocations, the calibrated one, the oracle bound.

:func:`relocate` dispatches by name on the registry :data:`RELOCATIONS`
(:mod:`~terrainvis.relocation.registry`); :func:`register` adds a relocation of your own.
The relocations themselves: :mod:`~terrainvis.relocation.paper` (identity, full, half),
:mod:`~terrainvis.relocation.calibrated` and :mod:`~terrainvis.relocation.oracle`.
"""

from .registry import (
    CALIBRATED,
    ORACLE,
    PAPER_RELOCATIONS,
    RELOCATIONS,
    Relocation,
    available,
    default_relocations,
    practical_relocations,
    register,
    relocate,
    unregister,
)

__all__ = [
    "relocate", "Relocation", "RELOCATIONS", "register", "unregister", "available", "default_relocations",
    "practical_relocations", "PAPER_RELOCATIONS", "CALIBRATED", "ORACLE",
]
