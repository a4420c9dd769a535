"""An example terrainvis plugin: ``box-average``, a regular simplifier (a box filter)."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter

from simplifiers import Method
from simplifiers.reverse_faber import coarse_positions
from terrainvis import HeightGrid

__all__ = ["box_average", "METHOD"]


def box_average(grid: HeightGrid, level: int, *, width: int | None = None) -> HeightGrid:
    """The mean of the fine samples within half a coarse cell of each reverse Faber coarse position.

    Parameters
    ----------
    grid : HeightGrid
        The fine terrain (no nodata).
    level : int
        Reverse-subdivision steps; the coarse grid keeps the samples at the positions
        every step keeps.
    width : int, optional
        The box's side in fine samples (odd); default ``2**level + 1``, one coarse cell.
    """
    rows = np.arange(grid.shape[0])
    cols = np.arange(grid.shape[1])
    for _ in range(level):
        rows, cols = rows[coarse_positions(rows.size)], cols[coarse_positions(cols.size)]
    size = 2**level + 1 if width is None else int(width)
    smooth = uniform_filter(np.asarray(grid.z, dtype=np.float64), size=size, mode="nearest")
    return HeightGrid.from_coords(smooth[np.ix_(rows, cols)], grid.xs[cols], grid.ys[rows], attrs=grid.attrs)


#: The plugin's entry: a regular method whose code takes (grid, level) (``whole_grid``).
METHOD = Method(
    "box-average", "regular", __name__, "box_average",
    "box filter: the mean of the fine samples around each coarse position (example plugin)",
    options=("width",), cost_rank=6, style=("tab:pink", "h"), whole_grid=True, default=False,
)
