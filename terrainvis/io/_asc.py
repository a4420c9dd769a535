"""ESRI ASCII grids (``.asc``) with the CRS in a ``.prj`` beside them."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from ..core.fileio import atomic_path
from ..core._georef import parse_crs
from ..core.terrain import HeightGrid
from ._common import _check_read_memory, _Corrupt
from ._raster import _georeference, _nodata_value, _uniform_layout, native_lattice

_ASC_KEYS = {"ncols", "nrows", "xllcorner", "yllcorner", "xllcenter", "yllcenter", "cellsize", "dx", "dy", "nodata_value"}


def _prj_path(p: Path) -> Path | None:
    for suffix in (".prj", ".PRJ"):
        q = p.with_suffix(suffix)
        if q.exists():
            return q
    return None


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_asc(p: Path, *, crs=None, band=None) -> HeightGrid:
    header = {}
    with open(p, "r", encoding="ascii", errors="strict") as fh:
        lines = fh.read().splitlines()
    i = 0
    while i < len(lines):
        parts = lines[i].split()
        if not parts:
            i += 1
            continue
        key = parts[0].lower()
        if key not in _ASC_KEYS:
            if not _is_number(parts[0]):
                raise _Corrupt(
                    f"header line {i + 1} has the unknown key {parts[0]!r}; an ESRI ASCII grid header holds "
                    f"{', '.join(sorted(_ASC_KEYS))}"
                )
            break
        if len(parts) != 2:
            raise _Corrupt(f"header line {i + 1} must be 'key value', got {lines[i]!r}")
        try:
            header[key] = float(parts[1])
        except ValueError:
            raise _Corrupt(f"header line {i + 1}: {parts[0]} must be a number, got {parts[1]!r}") from None
        i += 1
    for key in ("ncols", "nrows"):
        if key not in header:
            raise _Corrupt(f"header has no {key!r}")
        v = header[key]
        if not (math.isfinite(v) and v == int(v) and v >= 2):
            raise _Corrupt(f"{key} must be a whole number >= 2, got {v!r}")
    ncols, nrows = int(header["ncols"]), int(header["nrows"])
    size = p.stat().st_size
    if 2 * ncols * nrows > size:  # every value takes a digit and a separator at least
        raise _Corrupt(f"the header claims {nrows}x{ncols} values, but the file of {size:,} bytes holds at most {size // 2:,}")
    # the text, its tokens (Python strings, about 60 bytes each) and the float64 arrays
    _check_read_memory(p.name, (nrows, ncols), 8, extra_per_sample=64)
    if "cellsize" in header:
        dx = dy = header["cellsize"]
    elif "dx" in header and "dy" in header:
        dx, dy = header["dx"], header["dy"]
    else:
        raise _Corrupt("header has neither 'cellsize' nor 'dx' and 'dy'")
    if not (dx > 0 and dy > 0 and math.isfinite(dx) and math.isfinite(dy)):
        raise _Corrupt(f"the cell size must be finite and > 0, got dx={dx!r}, dy={dy!r}")
    try:
        values = np.array(" ".join(lines[i:]).split(), dtype=np.float64)
    except ValueError as exc:
        raise _Corrupt(f"the heights after the header are not all numbers ({exc})") from None
    if values.size != ncols * nrows:
        raise _Corrupt(f"expected {nrows}x{ncols} = {nrows * ncols} values, found {values.size}")
    z = values.reshape(nrows, ncols)
    if "nodata_value" in header:
        z[z == header["nodata_value"]] = np.nan
    x0, y0 = _asc_centre(header, "x", dx), _asc_centre(header, "y", dy)
    xs = x0 + dx * np.arange(ncols, dtype=np.float64)
    ys = y0 + dy * np.arange(nrows, dtype=np.float64)
    prj = _prj_path(p)
    file_crs = None
    if prj is not None:
        file_crs = _crs_from_prj(prj)
    source = p.name if prj is None else f"{p.name} (with {prj.name})"
    lattice = (x0 - 0.5 * dx, dx, y0 + (nrows - 0.5) * dy, dy)  # the cells' west and north edges
    return _georeference(z[::-1], xs, ys, {}, file_crs, crs, source, dlon=dx, dlat=dy, lattice=lattice)


def _crs_from_prj(prj: Path) -> str:
    text = prj.read_text(encoding="utf-8", errors="replace").strip()
    if not text:
        raise _Corrupt(f"{prj.name} beside it is empty")
    try:
        crs = parse_crs(text, prj.name)
    except ImportError:
        return text  # kept as WKT; rasterio is needed only to name it
    except ValueError as exc:
        raise _Corrupt(str(exc)) from None
    epsg = crs.to_epsg()
    return f"EPSG:{epsg}" if epsg else crs.to_wkt()


def _asc_centre(header: dict, axis: str, spacing: float) -> float:
    """The lower-left cell centre along ``axis`` ("x" or "y") from an ESRI ASCII header."""
    if f"{axis}llcenter" in header:
        return header[f"{axis}llcenter"]
    if f"{axis}llcorner" in header:
        return header[f"{axis}llcorner"] + 0.5 * spacing
    raise _Corrupt(f"header has neither '{axis}llcorner' nor '{axis}llcenter'")


def _write_asc(grid: HeightGrid, p: Path) -> None:
    z, nx, ny, crs_text, note = _uniform_layout(grid, ".asc")
    prj_text = None
    if crs_text:
        try:
            prj_text = parse_crs(crs_text, "grid.attrs['crs']").to_wkt(version="WKT1_ESRI")
        except ImportError:
            warnings.warn(
                f"writing the .prj beside {p.name!r} needs rasterio (pip install \"terrainvis[geo]\"); the CRS "
                f"{crs_text!r} is not written", UserWarning, stacklevel=3,
            )
    elif _prj_path(p) is not None:
        warnings.warn(
            f"{_prj_path(p).name} beside {p.name!r} is left as it is, but the grid has no CRS: load_dem will read "
            "that .prj as the CRS of the new file; delete it if it does not apply",
            UserWarning, stacklevel=3,
        )
    rows, cols = z.shape
    left, dx, top, dy = native_lattice(grid.attrs, nx, ny)
    x0, y0 = left + 0.5 * dx, top - (rows - 0.5) * dy
    nodata = _nodata_value(z)
    body = (z if nodata is None else np.where(np.isnan(z), nodata, z))[::-1]
    size_lines = f"cellsize {dx!r}\n" if dx == dy else f"dx {dx!r}\ndy {dy!r}\n"
    header = (
        f"ncols {cols}\nnrows {rows}\nxllcenter {x0!r}\nyllcenter {y0!r}\n{size_lines}"
        + ("" if nodata is None else f"NODATA_value {nodata!r}\n")
    )
    if prj_text is not None:
        prj = p.with_suffix(".prj")
        with atomic_path(prj) as tmp:
            tmp.write_text(prj_text, encoding="ascii")
    with atomic_path(p) as tmp, open(tmp, "w", encoding="ascii") as fh:
        fh.write(header)
        np.savetxt(fh, body, fmt="%.17g")
