"""Placing test points on a simplified terrain: the paper's relocations, the calibrated one, the oracle bound.

:func:`relocate` dispatches by name on the registry :data:`RELOCATIONS`
(:mod:`~terrainvis.relocation.registry`); :func:`register` adds a relocation of your own, with
its own options of a run if it has some (:class:`Option`, :class:`Flag`, :class:`Switch`:
``Relocation(run_options=...)``).
The relocations themselves: :mod:`~terrainvis.relocation.paper` (identity, full, half),
:mod:`~terrainvis.relocation.calibrated`, :mod:`~terrainvis.relocation.eye` (the calibrated
relocation shipped with S(T), without T) and :mod:`~terrainvis.relocation.oracle`.
"""

from ..core.option import Flag, Option, Switch
from .registry import (
    CALIBRATED,
    EYE,
    ORACLE,
    PAPER_RELOCATIONS,
    RELOCATIONS,
    Relocation,
    available,
    default_relocations,
    practical_relocations,
    register,
    relocate,
    run_options,
    unregister,
)

__all__ = [
    "relocate", "Relocation", "RELOCATIONS", "register", "unregister", "available", "default_relocations",
    "practical_relocations", "run_options", "Option", "Flag", "Switch", "PAPER_RELOCATIONS", "CALIBRATED", "EYE",
    "ORACLE", "EyeSurface", "eye_surface",
]


def __getattr__(name):
    # the eye surface's module imports the calibrated relocation's walks: only when asked for
    if name in ("EyeSurface", "eye_surface"):
        from . import eye

        return getattr(eye, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
