"""Placing test points on a simplified terrain: the paper's relocations, the calibrated one and the oracle.

:func:`relocate` dispatches by name (:mod:`~terrainvis.relocation.registry`);
:mod:`~terrainvis.relocation.calibrated` is the calibrated relocation.
"""

from .registry import CALIBRATED, ORACLE, PAPER_RELOCATIONS, RELOCATIONS, relocate

__all__ = ["relocate", "RELOCATIONS", "PAPER_RELOCATIONS", "CALIBRATED", "ORACLE"]
