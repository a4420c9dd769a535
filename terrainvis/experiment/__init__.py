"""The experiment: :func:`compare` and its parts.

:mod:`~terrainvis.experiment.options` (every option, declared once),
:mod:`~terrainvis.experiment.plan` (terrains, settings, tasks),
:mod:`~terrainvis.experiment.units` (what one unit computes),
:mod:`~terrainvis.experiment.collect` (the rows), :mod:`~terrainvis.experiment.results`
(the CSV store), :mod:`~terrainvis.experiment.report` (the tables) and
:mod:`~terrainvis.experiment.plot` (the figures); :mod:`~terrainvis.experiment.comparison`
runs them.
"""

from .comparison import (
    COLUMNS,
    DEFAULT_TERRAINS,
    DEFAULTS,
    DISTANCE_UNITS,
    JACKSBORO_WINDOW,
    MEASURES,
    PREDICATES,
    Settings,
    compare,
    end_radius_for,
    point_sets,
    resolve_terrains,
    simplified_path,
)

__all__ = [
    "compare", "Settings", "DEFAULTS", "resolve_terrains", "point_sets", "DEFAULT_TERRAINS", "JACKSBORO_WINDOW",
    "COLUMNS", "PREDICATES", "DISTANCE_UNITS", "MEASURES", "simplified_path", "end_radius_for",
]
