"""What the raster formats share: georeferencing a grid read, native coordinates, nodata, uniform layout."""

from __future__ import annotations

import warnings

import numpy as np

from ..core._georef import IDENTITY, crs_is_geographic, lonlat_to_local, native_axes, warn_if_degrees, xy_to_native
from ..core.validate import describe
from ..core.terrain import HeightGrid, _is_uniform
from ..tolerances import DIVISOR_FLOOR, RESAMPLE_SHIFT_REL
from ._common import _UserError


def _georeference(z, xs, ys, attrs: dict, file_crs, crs_arg, source: str, *, dlon=None, dlat=None,
                  lattice=None, owned: bool = False) -> HeightGrid:
    """A HeightGrid from native sample coordinates (increasing), with its georeferencing attrs.

    ``dlon`` / ``dlat`` are the file's own steps (native units); ``lattice`` its cells as
    stored, ``(left, dx, top, dy)`` (the west and north edges, the positive steps), which
    is recorded in ``attrs["native_lattice"]`` so that a grid written back on that lattice
    gets the file's numbers, not their rounding through the terrain's frame
    (:func:`native_lattice`). ``owned``: ``z`` is the reader's own fresh float64 buffer, which
    the grid adopts instead of copying.
    """
    if lattice is not None:
        attrs["native_lattice"] = tuple(float(v) for v in lattice)
    if file_crs and crs_arg:
        raise _UserError(f"crs: {source} records the CRS {file_crs!r}; crs= is only for files that record none, got {crs_arg!r}")
    text = file_crs or crs_arg
    if not text:
        warn_if_degrees(xs, ys, source, stacklevel=6)
        return HeightGrid._from_coords(z, xs, ys, attrs, owned=owned)
    geographic = crs_is_geographic(text)
    if geographic:
        xs, ys, affine = lonlat_to_local(xs, ys, dlon=dlon, dlat=dlat)
    else:
        affine = IDENTITY
    attrs.update(crs=text, geographic=geographic, xy_to_native=affine)
    return HeightGrid._from_coords(z, xs, ys, attrs, owned=owned)


def native_lattice(attrs: dict, nx: np.ndarray, ny: np.ndarray) -> tuple[float, float, float, float]:
    """``(left, dx, top, dy)`` of a north-up raster whose sample centres are the native axes ``nx``, ``ny``.

    Native axes computed from the terrain's frame carry rounding (a lon/lat step of 0.01
    comes back as 0.009999999999999995). When the axes lie on the cells of the raster the
    grid was read from (``attrs["native_lattice"]``): the same steps and their samples on
    its cell centres, within :data:`~terrainvis.tolerances.UNIFORM_STEP_REL`, that
    raster's own numbers are used: a viewshed of a DEM carries the DEM's transform, and
    an ``.asc`` of square cells its ``cellsize``.
    """
    from ..tolerances import UNIFORM_STEP_REL

    nx, ny = np.asarray(nx, dtype=np.float64), np.asarray(ny, dtype=np.float64)
    dx = float((nx[-1] - nx[0]) / (nx.size - 1)) if nx.size > 1 else None
    dy = float((ny[-1] - ny[0]) / (ny.size - 1)) if ny.size > 1 else None
    lattice = attrs.get("native_lattice")
    if isinstance(lattice, (tuple, list)) and len(lattice) == 4:
        left, sdx, top, sdy = (float(v) for v in lattice)

        def whole(v):
            return abs(v - round(v)) <= UNIFORM_STEP_REL * max(1.0, abs(v))

        same = all(d is None or abs(d / s - 1.0) <= UNIFORM_STEP_REL for d, s in ((dx, sdx), (dy, sdy)))
        k = (float(nx[0]) - (left + 0.5 * sdx)) / sdx
        j = ((top - 0.5 * sdy) - float(ny[-1])) / sdy
        if same and whole(k) and whole(j):
            return left + round(k) * sdx, sdx, top - round(j) * sdy, sdy
    dx = 1.0 if dx is None else dx
    dy = 1.0 if dy is None else dy
    return float(nx[0]) - 0.5 * dx, dx, float(ny[-1]) + 0.5 * dy, dy


def native_coords(grid: HeightGrid) -> tuple[np.ndarray, np.ndarray]:
    """The sample coordinates of ``grid`` in its native CRS.

    Parameters
    ----------
    grid : HeightGrid

    Returns
    -------
    x : (cols,) float64
    y : (rows,) float64
        ``ox + sx * grid.xs`` and ``oy + sy * grid.ys`` with ``attrs["xy_to_native"]``
        (the grid's own coordinates when it is not geographic).

    Raises
    ------
    ValueError
        When the grid is geographic but its map back to lon/lat is unknown.

    Examples
    --------
    >>> from terrainvis import HeightGrid
    >>> g = HeightGrid([[0.0, 0.0], [0.0, 0.0]], dx=2.0, attrs={"geographic": True, "xy_to_native": (0.5, 10.0, 1.0, 40.0)})
    >>> [v.tolist() for v in native_coords(g)]
    [[10.0, 11.0], [40.0, 41.0]]
    """
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    affine = xy_to_native(grid.attrs)
    if affine is None:
        raise ValueError("grid.attrs say the grid is geographic but hold no 'xy_to_native'; its lon/lat are unknown")
    return native_axes(grid.xs, grid.ys, affine)


def _nodata_value(z: np.ndarray, *, always: bool = False) -> float | None:
    """None without NaN (unless ``always``); else -9999 unless it is a real height, else another value that does not occur.

    The last candidate, float32's lowest value, is never a height (a terrain holds no
    |height| above :data:`terrainvis.core.terrain.MAX_HEIGHT`), so one always remains.
    """
    nan = np.isnan(z)
    if not nan.any() and not always:
        return None
    finite = z[~nan]
    for candidate in (-9999.0, -32768.0, -99999.0):
        if not (finite == candidate).any():
            return candidate
    return -3.4028234663852886e38


def _uniform_layout(grid: HeightGrid, suffix: str, *, values: bool = True):
    """What a uniform raster of ``grid`` holds: heights, native sample axes, CRS text, resampling note
    (``values`` False: the heights are None, and none is read or resampled)."""
    affine = xy_to_native(grid.attrs)
    crs_text = grid.attrs.get("crs") or None
    if crs_text is not None and not isinstance(crs_text, str):
        raise ValueError(f"grid.attrs['crs'] must be a CRS string, got {describe(crs_text)}")
    if affine is None:
        warnings.warn(
            f"grid.attrs say the grid is geographic (lon/lat) but hold no 'xy_to_native', so its local metres "
            f"cannot be mapped back to lon/lat; the {suffix} file gets the local metres and no CRS",
            UserWarning, stacklevel=4,
        )
        affine, crs_text = IDENTITY, None
    xs, ys = grid.xs, grid.ys
    z = grid.z if values else None
    note = None
    if not grid.is_uniform:
        ux = xs if _is_uniform(xs) else np.linspace(xs[0], xs[-1], xs.size)
        uy = ys if _is_uniform(ys) else np.linspace(ys[0], ys[-1], ys.size)
        moved = []
        for axis, old, new in (("x", xs, ux), ("y", ys, uy)):
            shift = np.abs(new - old)
            cell = (old[-1] - old[0]) / (old.size - 1)
            n = int((shift > RESAMPLE_SHIFT_REL * max(abs(cell), DIVISOR_FLOOR)).sum())
            if n:
                moved.append(f"{n} of {old.size} {axis} positions by up to {shift.max():.6g} ({shift.max() / cell:.3g} cell)")
        note = (
            f"{suffix} needs a uniform grid: the rectilinear {grid.shape[0]}x{grid.shape[1]} grid was resampled onto "
            f"uniform coordinates over the same sample extent with the same number of samples; moved "
            f"{' and '.join(moved)}; heights there are read from the grid's surface. Save to .npz to keep it exactly (a "
            "reverse-subdivision level L is uniform, on the DEM's own samples, when the DEM has 2^L k + 1 samples a "
            "side: cut it to n - (n - 1) mod 2^L)."
        )
        warnings.warn(note, UserWarning, stacklevel=4)
        if values:
            z = grid.height_on_grid(ux, uy)
        xs, ys = ux, uy
    nx, ny = native_axes(xs, ys, affine)
    return z, nx, ny, crs_text, note
