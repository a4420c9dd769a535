"""Collecting the rows of a :func:`terrainvis.compare` run into its table.

The columns (:data:`COLUMNS`; :func:`columns` with the registered measures' own), which of
them identify a unit (:data:`UNIT_KEY`, or :data:`BUDGET_KEY` in a run budgeted in vertical
error: :func:`unit_key`) or hold times (:data:`TIMING_COLUMNS`), how many rows a complete
unit has (:func:`rows_per_unit`), and the order of the final table (:func:`order`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .measures import MEASURES, builtin_columns, columns
from .options import Settings

__all__ = ["COLUMNS", "columns", "EVALUATE_COLUMNS", "BUDGET_COLUMNS", "UNIT_KEY", "BUDGET_KEY", "unit_key",
           "TIMING_COLUMNS", "rows_per_unit", "optional_columns", "table", "order"]

#: Columns of the result table with the measures terrainvis ships, in order (:func:`columns`
#: adds those of measures registered since).
COLUMNS = builtin_columns()
#: Columns only :func:`terrainvis.evaluate` fills: what it changed in a mesh to measure it (faces
#: reversed, a ``repair=True`` repair: :func:`terrainvis.core.repair.repair_summary`), the
#: farthest a vertex was snapped, and the zoom of a tileset's rows; empty in a comparison's rows,
#: and absent from older files.
EVALUATE_COLUMNS = ("repair", "repair_max_snap", "zoom")
#: Columns only a run budgeted in vertical error fills (``max_errors``): the budget E of the
#: row's unit and ``stopped_by``, ``"max_error"`` when the result is within E, else what stopped
#: the method first (:func:`terrainvis.experiment.units.stopped_by`); empty in a run by levels, and
#: absent from files written before budgets existed.
BUDGET_COLUMNS = ("max_error_budget", "stopped_by")
#: Columns that identify a unit of a run by levels.
UNIT_KEY = ("terrain", "method", "level")
#: Columns that identify a unit of a run budgeted in vertical error (its level is what the method reached).
BUDGET_KEY = ("terrain", "method", "max_error_budget")
#: Columns holding times (they differ between runs; everything else is deterministic).
TIMING_COLUMNS = ("simplify_seconds", "los_seconds", "los_seconds_original", "los_build_seconds")


def unit_key(settings: Settings) -> tuple:
    """The columns that identify a unit of a run with ``settings``: :data:`BUDGET_KEY` with
    ``max_errors``, else :data:`UNIT_KEY`."""
    from .options import budgeted

    return BUDGET_KEY if budgeted(settings) else UNIT_KEY


def rows_per_unit(settings: Settings) -> int:
    """The rows of a complete unit: sets (or observers) x relocations x distances."""
    from .measures import MEASURES

    return MEASURES[settings.measure].n_sets(settings) * len(settings.relocations) * len(settings.max_distance)


def optional_columns(measure: str) -> tuple:
    """The columns a results file of ``measure`` may lack and still resume: those only other
    measures fill (their :attr:`~terrainvis.experiment.measures.Measure.columns`),
    :data:`EVALUATE_COLUMNS` (read back as NaN, which is what a comparison's rows hold there)
    and :data:`BUDGET_COLUMNS` (empty in a run by levels; a run by budgets cannot resume a
    file written before them, whose settings have no budgets)."""
    return (tuple(c for m in MEASURES.values() if m.name != measure for c in m.columns) + EVALUATE_COLUMNS
            + BUDGET_COLUMNS)


def table(rows: list[dict]) -> pd.DataFrame:
    """Rows (dicts) as the frame a results CSV reads back as (see :func:`terrainvis.experiment.results.as_table`)."""
    from .results import as_table

    return as_table(rows, columns())


def order(df: pd.DataFrame, grids: dict) -> pd.DataFrame:
    """The table sorted: terrains as given, then set, methods in the registry's (the paper's) order,
    budget (in a run budgeted in vertical error), zoom (of a tileset's rows), level, relocation (identity, full, half, then
    the others), distance (unlimited last)."""
    from simplifiers import METHODS

    from ..relocation import registry as relocation

    rank_t = {t: i for i, t in enumerate(grids)}
    rank_m = {m: i for i, m in enumerate(METHODS)}
    rank_r = {r: i for i, r in enumerate(relocation.RELOCATIONS)}
    df = df[list(columns())]
    df = df.assign(
        _t=df["terrain"].map(rank_t), _m=df["method"].map(rank_m), _r=df["relocation"].map(rank_r),
        _d=df["max_distance"].fillna(np.inf),
    ).sort_values(["_t", "set", "_m", "max_error_budget", "zoom", "level", "_r", "_d"], kind="stable")
    return df.drop(columns=["_t", "_m", "_r", "_d"]).reset_index(drop=True)
