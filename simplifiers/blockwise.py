"""Reverse Faber subdivision block by block on a dask array, for rasters larger than memory.

Each pass reduces one axis. The array is rechunked so that every chunk but the last has
an even length along that axis (so each chunk starts at a coarse position), each chunk
is padded with ``halo`` samples from its neighbours (``dask.array.overlap``, no padding at
the array's edges), the in-memory curve operator runs on the padded block, and the
outputs that belong to the chunk's own coarse positions are kept.

Why this is exact
-----------------
* **simple** and **lls** are local: a coarse sample depends on the fine samples within 2
  of its position, and the operators treat only the two curve ends specially. A halo of
  4 keeps every kept output away from the padded block's artificial ends, and the last
  block keeps the real end (and, for even lengths, the real 3-wide last gap: the padded
  block starts at an even offset, so its length has the parity of the whole curve). The
  result equals the in-memory one bit for bit.
* **gls** solves a tridiagonal system per curve, which is global. But the inverse of
  the normal matrix decays geometrically, by a factor of 3 - 2*sqrt(2) ~ 0.17 per coarse
  sample, so the influence of samples more than ``halo`` = 64 fine samples (32 coarse)
  away is below 0.17**32 ~ 3e-25 of their size: far below float64 rounding. The result
  equals the in-memory one to rounding (about 1e-15 relative), not bit for bit.
* **feature** couples consecutive critical points, which may be arbitrarily far apart;
  it has no finite halo and is not offered here.
"""

from __future__ import annotations

import numpy as np

from terrainvis._validate import as_int, describe
from terrainvis.terrain import HeightGrid

from .levels import coarse_coords, coarse_length
from .registry import METHODS, method_info

__all__ = ["simplify_dask", "simplify_grid_blockwise", "blockwise_methods"]


def blockwise_methods() -> list[str]:
    """The methods that can run block-wise: those with a finite halo in the registry."""
    return [name for name, m in METHODS.items() if m.halo is not None]


def _reduce_axis(x, method: str, axis: int, options: dict):
    import dask.array as da

    m = x.shape[axis]
    if m < 3:
        raise ValueError(f"axis {axis} has {m} samples; a curve needs at least 3 to reduce")
    info = method_info(method)
    halo = info.halo
    op = info.load()
    # Even chunk lengths along the axis (at least the halo), except possibly the last.
    target = max(int(np.median(x.chunks[axis])), 2 * halo, 8)
    target += target % 2
    sizes = [target] * (m // target)
    rest = m - sum(sizes)
    if rest:
        if sizes and rest < halo + 3:
            sizes[-1] += rest  # keep the last block long enough to hold its real end
        else:
            sizes.append(rest)
    if len(sizes) == 1:
        # One block along this axis: no halo needed.
        one = x.rechunk({axis: m})
        out_chunks = tuple(c if i != axis else (coarse_length(m),) for i, c in enumerate(one.chunks))
        return one.map_blocks(lambda b: op(b, axis=axis, **options), chunks=out_chunks, dtype=np.float64)
    x = x.rechunk({axis: tuple(sizes)})
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    n_blocks = len(sizes)
    out_sizes = []
    for i, (s, L) in enumerate(zip(starts, sizes)):
        if i < n_blocks - 1:
            out_sizes.append(L // 2)
        else:
            out_sizes.append(coarse_length(m) - sum(out_sizes))
    depth = {d: 0 for d in range(x.ndim)}
    depth[axis] = halo
    padded = da.overlap.overlap(x, depth=depth, boundary={d: "none" for d in range(x.ndim)})

    def block(b, block_id=None):
        i = block_id[axis]
        left = 0 if i == 0 else halo
        c = op(b, axis=axis, **options)  # the padded block starts at an even offset
        first = left // 2
        return np.take(c, np.arange(first, first + out_sizes[i]), axis=axis)

    out_chunks = tuple(c if d != axis else tuple(out_sizes) for d, c in enumerate(x.chunks))
    return padded.map_blocks(block, chunks=out_chunks, dtype=np.float64)


def simplify_dask(z, method: str = "lls", level: int = 1, **options):
    """Reverse Faber subdivision of a (possibly larger than memory) dask array.

    Parameters
    ----------
    z : (rows, cols) dask.array.Array or array_like
        Heights in :class:`~terrainvis.HeightGrid` row order, without NaN.
    method : {"simple", "lls", "gls"}
        The operator (see the module docstring for why "feature" is not offered).
    level : int
        Number of steps; each reduces the rows (axis 1) and then the columns (axis 0),
        as :func:`simplifiers.simplify` does.
    **options
        Passed to the operator (``weights=`` for ``"lls"``).

    Returns
    -------
    dask.array.Array
        The coarse heights; equal to ``simplify(grid, method, level).z`` (bit for bit for
        simple and lls, to rounding for gls). Nothing is computed until you ask.
    """
    import dask.array as da

    if method not in blockwise_methods():
        raise ValueError(f"method must be one of {blockwise_methods()} for block-wise reduction, got {method!r}")
    level = as_int(level, "level", minimum=0)
    x = z if isinstance(z, da.Array) else da.asarray(np.asarray(z, dtype=np.float64))
    if x.ndim != 2:
        raise ValueError(f"z must be a 2-D array (rows, cols), got {x.ndim}-D with shape {x.shape}")
    x = x.astype(np.float64)
    for _ in range(level):
        if x.shape[0] < 3 or x.shape[1] < 3:
            raise ValueError(f"level {level} is too deep for a {z.shape[0]}x{z.shape[1]} grid")
        x = _reduce_axis(x, method, 1, options)
        x = _reduce_axis(x, method, 0, options)
    return x


def simplify_grid_blockwise(grid: HeightGrid, method: str = "lls", level: int = 1, *, chunks=1024, **options) -> HeightGrid:
    """:func:`simplify_dask` on a HeightGrid, computed, with the coarse coordinates.

    Useful to check the block-wise path against :func:`simplifiers.simplify`, and to
    bound peak memory on a large grid that fits on disk but not comfortably in memory.
    """
    import dask.array as da

    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    grid.require_finite("simplify_grid_blockwise")
    zc = simplify_dask(da.from_array(grid.z, chunks=chunks), method, level, **options).compute()
    level = as_int(level, "level", minimum=0)
    return HeightGrid.from_coords(zc, coarse_coords(grid.xs, level), coarse_coords(grid.ys, level), attrs=grid.attrs)
