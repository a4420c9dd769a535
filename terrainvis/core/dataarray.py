"""HeightGrid <-> xarray.DataArray (the optional xarray extra; rioxarray carries the CRS when installed).

xarray is not a dependency of terrainvis: it is imported inside the functions, which say
how to install it when it is missing. The usual raster layout (dims ``(y, x)`` with ``y``
descending, or ``(band, y, x)`` with one band as ``rioxarray.open_rasterio`` gives it) is
turned into the HeightGrid order (increasing ``x`` and ``y``); raw values with
``scale_factor``/``add_offset`` and ``_FillValue``/``nodata`` attributes are scaled and
masked as a GeoTIFF reader would.
"""

from __future__ import annotations

import numpy as np

from ._georef import IDENTITY, crs_is_geographic, lonlat_to_local, parse_crs, warn_if_degrees
from .validate import describe

__all__ = ["xarray_module", "find_dims", "dataarray_parts", "grid_to_dataarray", "raw_to_heights"]

_X_NAMES = ("x", "lon", "longitude", "easting")
_Y_NAMES = ("y", "lat", "latitude", "northing")
_NODATA_ATTRS = ("_FillValue", "nodata", "missing_value")
_SCALE_ATTRS = ("scale_factor", "add_offset")


def xarray_module():
    """xarray, or an ImportError with the install hint."""
    try:
        import xarray
    except ImportError as exc:
        raise ImportError(
            "HeightGrid.from_xarray/to_xarray and simplify_dataarray need xarray: pip install xarray "
            "(and rioxarray to carry the CRS)"
        ) from exc
    return xarray


def _rioxarray():
    try:
        import rioxarray  # noqa: F401  (registers the .rio accessor)
    except ImportError:
        return None
    return rioxarray


def find_dims(da, x, y, name: str = "da") -> tuple[str, str, object]:
    """The names of the x and y dims of ``da`` and ``da`` without a length-1 ``band`` dim."""
    if da.ndim == 3 and "band" in da.dims:
        if da.sizes["band"] != 1:
            raise ValueError(
                f"{name} has {da.sizes['band']} bands; a DEM has one: pick it first, e.g. {name}.sel(band=1)"
            )
        da = da.squeeze("band", drop=True)
    if da.ndim != 2:
        raise ValueError(f"{name} must be a 2-D DataArray (y, x), got {da.ndim}-D with dims {da.dims}")

    def pick(given, names, axis):
        if given is not None:
            if given not in da.dims:
                raise ValueError(f"{axis} must name a dim of {name} {list(da.dims)}, got {given!r}")
            return given
        found = [d for d in da.dims if str(d).lower() in names]
        if len(found) != 1:
            raise ValueError(
                f"cannot tell which dim of {name} {list(da.dims)} is {axis} (looked for {list(names)}); "
                f"pass {axis}=<dim name>"
            )
        return found[0]

    xdim = pick(x, _X_NAMES, "x")
    ydim = pick(y, _Y_NAMES, "y")
    if xdim == ydim:
        raise ValueError(f"x and y must be different dims of {name}, got {xdim!r} for both")
    for d in (xdim, ydim):
        if d not in da.coords:
            raise ValueError(f"{name} has no coordinate for its dim {d!r}; assign one with {name}.assign_coords({d}=...)")
    return xdim, ydim, da


def _nodata_and_scale(da):
    attrs = da.attrs
    nodata = next((attrs[k] for k in _NODATA_ATTRS if k in attrs), None)
    scale = float(attrs.get("scale_factor", 1.0))
    offset = float(attrs.get("add_offset", 0.0))
    return (None if nodata is None else float(nodata)), scale, offset


def raw_to_heights(data, nodata, scale, offset):
    """Heights from raw values: ``nodata`` masked to NaN, then ``data * scale + offset`` (numpy or dask)."""
    out = data.astype(np.float64)
    if nodata is not None and not np.isnan(nodata):
        if isinstance(out, np.ndarray):
            out = np.where(out == nodata, np.nan, out)
        else:
            import dask.array as dsa

            out = dsa.where(out == nodata, np.nan, out)
    if scale != 1.0 or offset != 0.0:
        out = out * scale + offset
    return out


def _crs_of(da, crs) -> str | None:
    if crs is not None:
        return crs
    if _rioxarray() is not None:
        rio_crs = da.rio.crs
        if rio_crs is not None:
            epsg = rio_crs.to_epsg()
            return f"EPSG:{epsg}" if epsg else rio_crs.to_wkt()
    text = da.attrs.get("crs")
    if isinstance(text, str) and text.strip():
        return text
    if "spatial_ref" in da.coords:
        for key in ("crs_wkt", "spatial_ref"):
            text = da.coords["spatial_ref"].attrs.get(key)
            if isinstance(text, str) and text.strip():
                return text
    return None


def dataarray_parts(da, *, x=None, y=None, crs=None):
    """``(z, xs, ys, attrs)`` of the HeightGrid that :meth:`terrainvis.HeightGrid.from_xarray` builds.

    This module knows nothing of HeightGrid (``terrain`` imports it, not the other way).
    """
    xr = xarray_module()

    if not isinstance(da, xr.DataArray):
        raise TypeError(f"da must be an xarray.DataArray, got {describe(da)}")
    if crs is not None and (not isinstance(crs, str) or not crs.strip()):
        raise TypeError(f"crs must be a CRS string such as 'EPSG:4326', got {describe(crs)}")
    xdim, ydim, da = find_dims(da, x, y)
    da = da.transpose(ydim, xdim)
    nodata, scale, offset = _nodata_and_scale(da)
    z = raw_to_heights(np.asarray(da.values), nodata, scale, offset)
    xs = np.asarray(da.coords[xdim].values, dtype=np.float64)
    ys = np.asarray(da.coords[ydim].values, dtype=np.float64)
    if ys.size >= 2 and ys[-1] < ys[0]:
        z, ys = z[::-1], ys[::-1]  # raster order (y descending) -> HeightGrid order
    if xs.size >= 2 and xs[-1] < xs[0]:
        z, xs = z[:, ::-1], xs[::-1]
    attrs = {k: v for k, v in da.attrs.items() if k not in _NODATA_ATTRS + _SCALE_ATTRS}
    if "xy_to_native" in attrs:
        # Written by to_xarray: the coordinates are terrainvis coordinates already.
        if crs is not None:
            raise ValueError("crs: da.attrs already hold terrainvis georeferencing (xy_to_native); crs= cannot apply")
        return z, xs, ys, attrs
    text = _crs_of(da, crs)
    if text is None:
        named = str(xdim).lower() in ("lon", "longitude") and str(ydim).lower() in ("lat", "latitude")
        warn_if_degrees(xs, ys, "the DataArray", stacklevel=4, named=named, fix="HeightGrid.from_xarray")
        return z, xs, ys, attrs
    geographic = crs_is_geographic(text)
    affine = IDENTITY
    if geographic:
        xs, ys, affine = lonlat_to_local(xs, ys)
    attrs.update(crs=text, geographic=geographic, xy_to_native=affine)
    return z, xs, ys, attrs


def grid_to_dataarray(grid, *, name: str = "z"):
    """See :meth:`terrainvis.HeightGrid.to_xarray` (``grid`` is any object with ``z``, ``xs``, ``ys``, ``attrs``)."""
    xr = xarray_module()
    da = xr.DataArray(
        np.array(grid.z), dims=("y", "x"), coords={"y": np.array(grid.ys), "x": np.array(grid.xs)},
        attrs=dict(grid.attrs), name=name,
    )
    text = grid.attrs.get("crs")
    if isinstance(text, str) and text and not grid.attrs.get("geographic") and _rioxarray() is not None:
        try:
            wkt = parse_crs(text, "grid.attrs['crs']").to_wkt()
        except (ValueError, ImportError):
            return da  # kept in attrs only
        da = da.rio.write_crs(wkt)
        da.attrs["crs"] = text  # write_crs moves it to the spatial_ref coordinate; keep the text (and any remark)
    return da
