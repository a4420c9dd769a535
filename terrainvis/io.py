"""Reading and writing DEMs: ``.npz``, ``.npy``, ESRI ASCII grids and GeoTIFF.

Rows and north
--------------
Rasters are stored north-up: their first row is the northern edge. A
:class:`~terrainvis.HeightGrid` has increasing ``ys`` with ``z[r, c]`` at
``(xs[c], ys[r])``, so :func:`load_dem` flips the rows of a north-up raster: raster row
``i`` becomes grid row ``rows - 1 - i``, and ``ys`` grows northwards (x east, y north,
heights up: a right-handed frame). :func:`save_dem` flips them back. A bare ``.npy``
array has no georeferencing and no orientation; it is taken as grid rows unchanged, with
unit spacing and the origin at (0, 0).

Coordinates
-----------
``xs`` and ``ys`` are cell centres in metres. On a projected CRS they are the CRS's own
coordinates (e.g. UTM eastings and northings). On a geographic (lon/lat) grid the
spacing is converted to metres at the grid's centre latitude (WGS84 metres per degree)
and the origin is put at (0, 0), because line of sight needs x, y and z in one unit; the
native georeferencing is kept in ``grid.attrs``.

Nodata becomes NaN. Operations that cannot work with NaN raise
:class:`~terrainvis.errors.NodataError`, which points to :meth:`HeightGrid.fill_nodata`
and :meth:`HeightGrid.crop`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ._validate import describe
from .terrain import HeightGrid

__all__ = ["load_dem", "save_dem", "sample_dem", "metres_per_degree", "SUFFIXES"]

#: File suffixes understood by :func:`load_dem` and :func:`save_dem`.
SUFFIXES = (".npz", ".npy", ".asc", ".tif", ".tiff")


def metres_per_degree(lat_deg: float) -> tuple[float, float]:
    """WGS84 metres per degree of longitude and of latitude at latitude ``lat_deg``."""
    phi = math.radians(lat_deg)
    lon = 111412.84 * math.cos(phi) - 93.5 * math.cos(3 * phi) + 0.118 * math.cos(5 * phi)
    lat = 111132.92 - 559.82 * math.cos(2 * phi) + 1.175 * math.cos(4 * phi) - 0.0023 * math.cos(6 * phi)
    return lon, lat


def _path(path, name: str = "path") -> Path:
    if not isinstance(path, (str, Path)):
        raise TypeError(f"{name} must be a str or pathlib.Path, got {describe(path)}")
    return Path(path)


def _suffix(p: Path) -> str:
    suffix = p.suffix.lower()
    if suffix not in SUFFIXES:
        raise ValueError(f"path must end in one of {list(SUFFIXES)}, got {p.name!r} (suffix {p.suffix!r})")
    return suffix


class _Corrupt(ValueError):
    pass


def load_dem(path, *, nodata: float | None = None) -> HeightGrid:
    """Read a DEM into a :class:`~terrainvis.HeightGrid`.

    Parameters
    ----------
    path : str or Path
        ``.npz`` (keys ``z``, ``dx``, ``dy``; optionally ``xs``/``ys``, ``geotransform``,
        ``crs``, ``geographic`` — the format of ``shared/data/dem``), ``.npy`` (a bare
        array, unit spacing), ``.asc`` (ESRI ASCII grid) or ``.tif``/``.tiff`` (GeoTIFF,
        needs the ``geo`` extra: ``pip install "terrainvis[geo]"``).
    nodata : float, optional
        An extra value to treat as nodata (besides the file's own nodata value).

    Returns
    -------
    HeightGrid
        Rows flipped so that y grows northwards (see the module docstring); nodata as NaN;
        ``attrs`` holds the source path, CRS and native georeferencing when known.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        Unknown suffix, or a corrupt or inconsistent file.
    """
    p = _path(path)
    suffix = _suffix(p)
    if not p.exists():
        raise FileNotFoundError(f"path {str(p)!r} does not exist")
    try:
        if suffix == ".npz":
            grid = _load_npz(p)
        elif suffix == ".npy":
            grid = _load_npy(p)
        elif suffix == ".asc":
            grid = _load_asc(p)
        else:
            grid = _load_tif(p)
    except _Corrupt as exc:
        raise ValueError(f"could not read {p.name!r} as a {suffix} DEM: {exc}") from None
    except (OSError, EOFError, KeyError, IndexError, TypeError, ValueError) as exc:
        if isinstance(exc, (FileNotFoundError, ImportError)):
            raise
        raise ValueError(f"could not read {p.name!r} as a {suffix} DEM: {type(exc).__name__}: {exc}") from exc
    if nodata is not None:
        z = grid.z.copy()
        z[z == float(nodata)] = np.nan
        grid = grid.copy_with(z)
    grid.attrs.setdefault("path", str(p))
    return grid


def _scalar(data, key):
    if key not in data:
        raise _Corrupt(f"missing key {key!r} (found {sorted(data.keys())})")
    arr = np.asarray(data[key])
    if arr.size != 1:
        raise _Corrupt(f"key {key!r} must be a scalar, got shape {arr.shape}")
    return arr.reshape(()).item()


def _load_npz(p: Path) -> HeightGrid:
    with np.load(p, allow_pickle=False) as data:
        if "z" not in data:
            raise _Corrupt(f"missing key 'z' (found {sorted(data.keys())})")
        z = np.asarray(data["z"], dtype=np.float64)
        if z.ndim != 2:
            raise _Corrupt(f"z must be 2-D, got shape {z.shape}")
        attrs = {}
        for key in ("crs", "source", "license", "description", "z_units"):
            if key in data:
                attrs[key] = str(data[key])
        geographic = bool(_scalar(data, "geographic")) if "geographic" in data else False
        attrs["geographic"] = geographic
        if "geotransform" in data:
            attrs["geotransform"] = tuple(float(v) for v in np.asarray(data["geotransform"]).ravel())
        z = z[::-1]  # north-up raster rows -> increasing y
        if "xs" in data and "ys" in data:
            xs = np.asarray(data["xs"], dtype=np.float64)
            ys = np.asarray(data["ys"], dtype=np.float64)
            return HeightGrid.from_coords(z, xs, ys, attrs=attrs)
        dx = float(_scalar(data, "dx"))
        dy = float(_scalar(data, "dy"))
        origin = (0.0, 0.0)
        gt = attrs.get("geotransform")
        if gt is not None and not geographic and len(gt) == 6:
            # Cell centres in the projected CRS; the south-west centre is the origin.
            origin = (gt[0] + 0.5 * gt[1], gt[3] + gt[5] * (z.shape[0] - 0.5))
    return HeightGrid(z, dx=dx, dy=dy, origin=origin, attrs=attrs)


def _load_npy(p: Path) -> HeightGrid:
    z = np.load(p, allow_pickle=False)
    if z.dtype.kind not in "iuf":
        raise _Corrupt(f"expected a numeric array, got dtype {z.dtype}")
    return HeightGrid(z.astype(np.float64))


_ASC_KEYS = {"ncols", "nrows", "xllcorner", "yllcorner", "xllcenter", "yllcenter", "cellsize", "dx", "dy", "nodata_value"}


def _load_asc(p: Path) -> HeightGrid:
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
            break
        if len(parts) != 2:
            raise _Corrupt(f"header line {i + 1} must be 'key value', got {lines[i]!r}")
        header[key] = float(parts[1])
        i += 1
    for key in ("ncols", "nrows"):
        if key not in header:
            raise _Corrupt(f"header has no {key!r}")
    ncols, nrows = int(header["ncols"]), int(header["nrows"])
    if "cellsize" in header:
        dx = dy = header["cellsize"]
    elif "dx" in header and "dy" in header:
        dx, dy = header["dx"], header["dy"]
    else:
        raise _Corrupt("header has neither 'cellsize' nor 'dx' and 'dy'")
    values = np.array(" ".join(lines[i:]).split(), dtype=np.float64)
    if values.size != ncols * nrows:
        raise _Corrupt(f"expected {nrows}x{ncols} = {nrows * ncols} values, found {values.size}")
    z = values.reshape(nrows, ncols)
    if "nodata_value" in header:
        z[z == header["nodata_value"]] = np.nan
    return HeightGrid(z[::-1], dx=dx, dy=dy, origin=(_asc_centre(header, "x", dx), _asc_centre(header, "y", dy)))


def _asc_centre(header: dict, axis: str, spacing: float) -> float:
    """The lower-left cell centre along ``axis`` ("x" or "y") from an ESRI ASCII header."""
    if f"{axis}llcenter" in header:
        return header[f"{axis}llcenter"]
    if f"{axis}llcorner" in header:
        return header[f"{axis}llcorner"] + 0.5 * spacing
    raise _Corrupt(f"header has neither '{axis}llcorner' nor '{axis}llcenter'")


def _rasterio():
    try:
        import rasterio
    except ImportError as exc:
        raise ImportError(
            'reading and writing GeoTIFF needs rasterio: pip install "terrainvis[geo]"'
        ) from exc
    return rasterio


def _load_tif(p: Path) -> HeightGrid:
    rasterio = _rasterio()
    try:
        with rasterio.open(p) as src:
            band = src.read(1, masked=True)
            t = src.transform
            crs = src.crs
    except rasterio.errors.RasterioError as exc:
        raise _Corrupt(str(exc)) from exc
    if t.b != 0 or t.d != 0:
        raise _Corrupt(f"rotated rasters are not supported (transform {tuple(t)[:6]})")
    z = np.ma.filled(band.astype(np.float64), np.nan)
    dx, dy = abs(t.a), abs(t.e)
    rows, cols = z.shape
    attrs = {"crs": str(crs) if crs else "", "geotransform": (t.c, t.a, t.b, t.f, t.d, t.e)}
    north_up = t.e < 0
    if north_up:
        z = z[::-1]
    geographic = bool(crs is not None and crs.is_geographic)
    attrs["geographic"] = geographic
    if geographic:
        lat_c = t.f + t.e * rows / 2.0
        m_lon, m_lat = metres_per_degree(lat_c)
        return HeightGrid(z, dx=dx * m_lon, dy=dy * m_lat, attrs=attrs)
    x0 = t.c + 0.5 * t.a
    y0 = (t.f + t.e * (rows - 0.5)) if north_up else (t.f + 0.5 * t.e)
    return HeightGrid(z, dx=dx, dy=dy, origin=(x0, y0), attrs=attrs)


def save_dem(grid: HeightGrid, path) -> Path:
    """Write a grid so that :func:`load_dem` reads it back unchanged.

    Parameters
    ----------
    grid : HeightGrid
    path : str or Path
        ``.npz`` (any rectilinear grid, exact coordinates kept), ``.asc`` and
        ``.tif``/``.tiff`` (uniform grids; nodata written as -9999 and read back as
        NaN) or ``.npy`` (only z; the grid must have unit spacing and origin (0, 0)).
        Rows are written north-up (flipped back, see the module docstring).

    Returns
    -------
    Path
        The path written.
    """
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    p = _path(path)
    suffix = _suffix(p)
    north_up = grid.z[::-1]
    if suffix == ".npz":
        extra = {}
        for key in ("crs", "source", "license", "description"):
            if key in grid.attrs:
                extra[key] = np.asarray(str(grid.attrs[key]))
        np.savez_compressed(
            p, z=north_up, dx=np.float64(grid.dx), dy=np.float64(grid.dy), xs=grid.xs, ys=grid.ys,
            geographic=np.bool_(grid.attrs.get("geographic", False)), **extra,
        )
        return p
    if suffix == ".npy":
        unit = grid.is_uniform and grid.dx == 1.0 and grid.dy == 1.0 and grid.xs[0] == 0.0 and grid.ys[0] == 0.0
        if not unit:
            raise ValueError(
                "a .npy file keeps only z, so grid must have unit spacing and origin (0, 0); "
                f"got {grid!r}; save to .npz to keep the coordinates"
            )
        np.save(p, grid.z)
        return p
    if not grid.is_uniform:
        raise ValueError(f"{suffix} files need a uniform grid, got a rectilinear one ({grid!r}); save to .npz instead")
    dx, dy = grid.dx, grid.dy
    if suffix == ".asc":
        z = np.where(np.isnan(north_up), -9999.0, north_up)
        size_lines = f"cellsize {dx!r}\n" if dx == dy else f"dx {dx!r}\ndy {dy!r}\n"
        with open(p, "w", encoding="ascii") as fh:
            fh.write(f"ncols {grid.shape[1]}\nnrows {grid.shape[0]}\n")
            fh.write(f"xllcenter {float(grid.xs[0])!r}\nyllcenter {float(grid.ys[0])!r}\n{size_lines}NODATA_value -9999\n")
            np.savetxt(fh, z, fmt="%.17g")
        return p
    rasterio = _rasterio()
    from rasterio.transform import from_origin

    transform = from_origin(grid.xs[0] - dx / 2, grid.ys[-1] + dy / 2, dx, dy)
    crs = grid.attrs.get("crs") or None
    if grid.attrs.get("geographic"):
        crs = None  # the coordinates were converted to local metres; they are no longer lon/lat
    with rasterio.open(
        p, "w", driver="GTiff", height=grid.shape[0], width=grid.shape[1], count=1, dtype="float64",
        transform=transform, crs=crs, nodata=-9999.0,
    ) as dst:
        dst.write(np.where(np.isnan(north_up), -9999.0, north_up), 1)
    return p


_SAMPLES = {"jacksboro": "jacksboro_fault_dem.npz"}


def _matplotlib_sample(filename: str) -> Path:
    """Path of a file in matplotlib's sample data, found without importing matplotlib."""
    import importlib.util

    spec = importlib.util.find_spec("matplotlib")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("sample_dem needs matplotlib (a core dependency of terrainvis): pip install matplotlib")
    for root in spec.submodule_search_locations:
        path = Path(root) / "mpl-data" / "sample_data" / filename
        if path.exists():
            return path
    raise FileNotFoundError(f"matplotlib's sample data has no {filename!r} (looked in {list(spec.submodule_search_locations)})")


def sample_dem(name: str = "jacksboro") -> HeightGrid:
    """A real DEM that ships with matplotlib, so it needs no download.

    Parameters
    ----------
    name : {"jacksboro"}
        ``"jacksboro"``: the USGS 3-arc-second DEM of the Jacksboro fault, Tennessee
        (344 x 403 samples, 236-1076 m), from matplotlib's sample data. Its lon/lat cells
        are converted to metres at the centre latitude: 74.57 m (east-west) x 92.47 m
        (north-south).

    Returns
    -------
    HeightGrid
        Rows flipped so that y grows northwards, origin (0, 0) in local metres.
    """
    if name not in _SAMPLES:
        raise ValueError(f"name must be one of {list(_SAMPLES)}, got {name!r}")
    with np.load(_matplotlib_sample(_SAMPLES[name]), allow_pickle=False) as data:
        z = np.asarray(data["elevation"], dtype=np.float64)
        dx_deg = float(data["dx"])
        dy_deg = float(data["dy"])
        # In this file 'ymin' holds the northern edge and 'ymax' the southern one.
        lat_c = 0.5 * (float(data["ymin"]) + float(data["ymax"]))
        lon_w = float(data["xmin"])
        lat_n = max(float(data["ymin"]), float(data["ymax"]))
    m_lon, m_lat = metres_per_degree(lat_c)
    attrs = {
        "name": name,
        "source": "matplotlib sample data jacksboro_fault_dem.npz (USGS 3-arc-second DEM)",
        "geographic": True,
        "crs": "lon/lat (assumed WGS84/NAD83)",
        "geotransform": (lon_w, dx_deg, 0.0, lat_n, 0.0, -dy_deg),
    }
    return HeightGrid(z[::-1], dx=dx_deg * m_lon, dy=dy_deg * m_lat, attrs=attrs)
