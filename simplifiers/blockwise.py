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

from terrainvis.core.validate import as_int, describe
from terrainvis.core.terrain import HeightGrid

from .levels import coarse_coords, coarse_length
from .registry import METHODS, method_info

__all__ = ["simplify_dask", "simplify_grid_blockwise", "simplify_dataarray", "blockwise_methods"]


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


def simplify_dataarray(da, method: str = "lls", level: int = 1, *, x=None, y=None, chunks=1024, **options):
    """:func:`simplify_dask` on an :class:`xarray.DataArray`: a lazy DataArray with the coarse coordinates.

    Parameters
    ----------
    da : xarray.DataArray, dims (y, x) in either order
        Heights, dask-backed (computed block by block, never loaded whole) or in memory
        (then split into ``chunks``). Dims are found as in
        :meth:`terrainvis.HeightGrid.from_xarray`; a descending coordinate (raster order)
        is handled by running the operator in the HeightGrid order (increasing
        coordinates), so the result equals :func:`simplifiers.simplify` on
        ``HeightGrid.from_xarray(da)``, returned in ``da``'s own order. Raw values with
        ``_FillValue``/``nodata`` and ``scale_factor``/``add_offset`` attributes are masked
        and scaled first. NaN is not checked (that would compute the array): it spreads
        to the coarse samples whose operator window holds it.
    method : {"simple", "lls", "gls"}
        See :func:`simplify_dask`.
    level : int
        Number of reduction steps.
    x, y : str, optional
        The names of the x and y dims.
    chunks : int or tuple, optional
        Chunks for an in-memory ``da`` (ignored for a dask-backed one).
    **options
        Passed to the operator (``weights=`` for ``"lls"``).

    Returns
    -------
    xarray.DataArray
        Lazy (dask-backed) coarse heights with the dims of ``da``, the coarse coordinates
        (:func:`simplifiers.levels.coarse_coords`: evenly spaced for odd lengths, the last
        gap 3 fine cells wide for even ones), ``da``'s scalar coordinates (a rioxarray
        ``spatial_ref`` without its now stale ``GeoTransform``) and ``attrs`` with
        ``method`` and ``level`` added.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> z = np.add.outer(np.arange(9.0), np.arange(9.0))
    >>> da = xr.DataArray(z, dims=("y", "x"), coords={"y": np.arange(9.0)[::-1], "x": np.arange(9.0)})
    >>> out = simplify_dataarray(da, "lls", 1, chunks=4)
    >>> out.shape, out.y.values.tolist()
    ((5, 5), [8.0, 6.0, 4.0, 2.0, 0.0])
    """
    import dask.array as dsa

    from terrainvis.core.dataarray import find_dims, raw_to_heights, xarray_module

    xr = xarray_module()
    if not isinstance(da, xr.DataArray):
        raise TypeError(f"da must be an xarray.DataArray, got {describe(da)}")
    level = as_int(level, "level", minimum=0)
    dims = da.dims
    xdim, ydim, flat = find_dims(da, x, y)
    flat = flat.transpose(ydim, xdim)
    xs = np.asarray(flat.coords[xdim].values, dtype=np.float64)
    ys = np.asarray(flat.coords[ydim].values, dtype=np.float64)
    data = flat.data if isinstance(flat.data, dsa.Array) else dsa.from_array(np.asarray(flat.data), chunks=chunks)
    attrs = flat.attrs
    nodata = next((attrs[k] for k in ("_FillValue", "nodata", "missing_value") if k in attrs), None)
    data = raw_to_heights(
        data, None if nodata is None else float(nodata), float(attrs.get("scale_factor", 1.0)),
        float(attrs.get("add_offset", 0.0)),
    )
    flip_y = ys.size >= 2 and ys[-1] < ys[0]
    flip_x = xs.size >= 2 and xs[-1] < xs[0]
    if flip_y:
        data, ys = data[::-1], ys[::-1]
    if flip_x:
        data, xs = data[:, ::-1], xs[::-1]
    out = simplify_dask(data, method, level, **options)
    cx, cy = coarse_coords(xs, level), coarse_coords(ys, level)
    if flip_y:
        out, cy = out[::-1], cy[::-1]
    if flip_x:
        out, cx = out[:, ::-1], cx[::-1]
    coords = {ydim: cy, xdim: cx}
    for key, coord in flat.coords.items():
        if coord.ndim == 0:
            kept = coord.copy()
            kept.attrs = {k: v for k, v in coord.attrs.items() if k != "GeoTransform"}
            coords[key] = kept
    new_attrs = {k: v for k, v in attrs.items() if k not in ("_FillValue", "nodata", "missing_value", "scale_factor", "add_offset")}
    new_attrs.update(method=method, level=level)
    result = xr.DataArray(out, dims=(ydim, xdim), coords=coords, attrs=new_attrs, name=da.name if da.name is not None else "z")
    return result.transpose(*[d for d in dims if d in (xdim, ydim)])
