"""Bare ``.npy`` height arrays: grid rows as they are, unit spacing, origin (0, 0)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.fileio import atomic_path
from ..core.validate import describe
from ..core.terrain import HeightGrid
from ._common import _check_read_memory, _Corrupt, _npy_header
from ._raster import _georeference


def _read_npy(p: Path, *, crs=None, band=None) -> HeightGrid:
    with open(p, "rb") as fh:
        try:
            shape, dtype = _npy_header(fh)
        except ValueError as exc:
            raise _Corrupt(f"it is not a .npy array file ({exc})") from None
    if dtype.kind in "iuf" and len(shape) == 2:
        _check_read_memory(p.name, shape, dtype.itemsize)
    try:
        z = np.load(p, allow_pickle=False)
    except ValueError as exc:
        if "pickle" in str(exc):
            raise _Corrupt("it is not a .npy array file (numpy would need pickle to read it)") from None
        raise _Corrupt(str(exc)) from None
    if not isinstance(z, np.ndarray) or z.dtype.kind not in "iuf":
        raise _Corrupt(f"expected a numeric array, got {describe(z)}")
    z = z.astype(np.float64)
    if z.ndim != 2:
        raise _Corrupt(f"expected a 2-D array of heights, got shape {z.shape}")
    rows, cols = z.shape
    xs, ys = np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64)
    return _georeference(z, xs, ys, {}, None, crs, p.name) if crs else HeightGrid(z)


def _write_npy(grid: HeightGrid, p: Path) -> None:
    unit = grid.is_uniform and grid.dx == 1.0 and grid.dy == 1.0 and grid.xs[0] == 0.0 and grid.ys[0] == 0.0
    if not unit:
        raise ValueError(
            "a .npy file keeps only z, so grid must have unit spacing and origin (0, 0); "
            f"got {grid!r}; save to .npz to keep the coordinates"
        )
    with atomic_path(p) as tmp, open(tmp, "wb") as fh:
        np.save(fh, grid.z)
