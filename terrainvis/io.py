"""Reading and writing terrains: one ``.npz`` format, DEM rasters and meshes.

Formats
-------
====================  ===========  =====================================================
suffix                kinds        notes
====================  ===========  =====================================================
``.npz``              grid, TIN    the terrainvis format (below); exact; attrs kept
``.tif``/``.tiff``    grid         GeoTIFF in the native CRS; attrs kept in a tag (needs
                                   the ``geo`` extra: ``pip install "terrainvis[geo]"``)
``.asc``              grid         ESRI ASCII grid in the native CRS, with a ``.prj``
                                   beside it for the CRS; no other metadata
``.npy``              grid         bare heights: unit spacing, origin (0, 0)
``.ply``, ``.obj``    grid, TIN    meshes with float64 coordinates (exact); attrs kept
                                   in a header comment; read back as a TIN
``.stl``              grid, TIN    float32 mesh (coordinates rounded, see below); no
                                   attrs
``.glb``              grid, TIN    float32 vertices about a float64 local origin; attrs
                                   kept
====================  ===========  =====================================================

:func:`load_terrain` and :func:`save_terrain` handle every row; :func:`load_dem` and
:func:`save_dem` are the same code restricted to grids and the raster suffixes. A grid
saved as a mesh goes through :meth:`HeightGrid.to_tin` and is read back as that TIN.

The terrainvis ``.npz`` format (version 1)
------------------------------------------
One writer and one reader for every ``.npz`` the project writes or ships (DEMs, the
bundled terrains, simplified grids and TINs). ``numpy.load(path)`` reads it with the
default ``allow_pickle=False``. Keys:

====================  ==========================  ================================================
key                   type                        meaning
====================  ==========================  ================================================
``format``            str                         ``"terrainvis"``
``format_version``    int64                       ``1``; a reader refuses a newer version
``kind``              str                         ``"grid"`` or ``"tin"``
``orientation``       str                         grid: ``"y_increasing"`` (``z[r, c]`` at
                                                  ``(xs[c], ys[r])``, row 0 at the smallest y,
                                                  i.e. south: the HeightGrid order) or
                                                  ``"y_decreasing"`` (row 0 at the largest y,
                                                  raster order; read, never written).
                                                  TIN: ``"z_up_ccw"`` (faces counter-clockwise
                                                  seen from +z)
``attrs``             str                         ``attrs`` of the terrain as JSON text
``z``                 float64 (rows, cols)        grid heights, NaN = nodata
``xs``, ``ys``        float64 (cols,), (rows,)    grid sample coordinates (rectilinear: exact)
``vertices``          float64 (n, 3)              TIN vertices x, y, z
``faces``             int32 or int64 (m, 3)       TIN vertex indices
====================  ==========================  ================================================

``attrs`` are JSON: str, bool, int, float (NaN and infinities as the JSON extensions
``NaN``/``Infinity``), None, lists and dicts with string keys are kept as they are; tuples
and numeric, bool or str numpy arrays are kept exactly through tagged objects
(``{"__tuple__": [...]}``, ``{"__ndarray__": [...], "dtype": "<f8", "shape": [...]}``);
numpy scalars become Python numbers. Any other value is dropped with a ``UserWarning``
naming its key. ``attrs["path"]`` is not written: the readers set it to the file read.

Older ``.npz`` dialects are read too, told apart by their keys (anything ambiguous is
refused with a message that says why): the shared-DEM dialect (north-up ``z``, ``dx``,
``dy`` in metres, ``geotransform``, ``crs``, ``geographic``), the bundled-terrain and
``experiment.save_simplified`` dialect (``z``, ``xs``, ``ys`` in HeightGrid order,
optionally ``kind``; or ``kind="tin"``, ``vertices``, ``faces``) and the former
``save_dem`` dialect (north-up ``z`` with ``dx``, ``dy``, ``xs``, ``ys``, ``geographic``).

Rows and north
--------------
Rasters are stored north-up: their first row is the northern edge. A
:class:`~terrainvis.HeightGrid` has increasing ``ys`` with ``z[r, c]`` at
``(xs[c], ys[r])``, so reading a north-up raster flips its rows (raster row ``i`` becomes
grid row ``rows - 1 - i``; x east, y north, heights up: a right-handed frame) and writing
one flips them back. A bare ``.npy`` array has no georeferencing and no orientation; it is
taken as grid rows unchanged, with unit spacing and the origin at (0, 0).

Coordinates and georeferencing
------------------------------
``xs`` and ``ys`` are sample (cell-centre) coordinates in metres. On a projected CRS they
are the CRS's own coordinates (e.g. UTM eastings and northings). On a geographic (lon/lat)
grid the spacing is converted to metres at the grid's centre latitude (WGS84 metres per
degree) and the origin is put at (0, 0), because line of sight needs x, y and z in one
unit. ``attrs`` keep the CRS and the map back to native coordinates (``crs``,
``geographic``, ``xy_to_native``; see :mod:`terrainvis._georef`), so a grid written to
GeoTIFF or ``.asc`` is in its native CRS again, with the transform derived from its own
coordinates (:func:`native_coords`). A file without a CRS whose coordinates look like
degrees gives a warning; ``load_dem(path, crs="EPSG:4326")`` converts it.

GeoTIFF and ``.asc`` need a uniform grid. A rectilinear grid (e.g. an even-sized regular
simplification, whose last gap is 3 fine cells wide) is resampled onto uniform
coordinates over the same sample extent with the same number of samples, its heights at
the moved samples read from its surface; a ``UserWarning`` names what moved and by how
much, and a GeoTIFF records it in its ``TERRAINVIS_RESAMPLED`` tag and ``attrs["resampled"]``.
Save to ``.npz`` to keep a rectilinear grid exactly.

Nodata is NaN in memory. Writers of ``.asc`` and ``.tif`` mark it with -9999 unless -9999
is a real height of the grid, in which case another value that does not occur is used; a
grid without NaN gets no nodata value at all. Readers turn the file's nodata value (e.g.
-9999) into NaN. Operations that cannot work with NaN raise
:class:`~terrainvis.errors.NodataError`.

Every file is written atomically (:func:`terrainvis._fileio.atomic_path`): a failure
never leaves a damaged file where a good one was.

Float precision of meshes
-------------------------
STL and glTF store float32 vertices (24-bit mantissa): UTM northings near 5,000 km are
0.5 m apart there. ``.glb`` is written about a local origin (the minimum corner) kept in
float64 in the node's transform, so it is exact to float32 of the terrain's own extent;
STL has no place for it and is written as it is, with a ``UserWarning`` when rounding
moves a vertex by more than 1e-6 of the terrain's extent. ``.ply`` and ``.obj`` are
written by terrainvis in float64 (``.ply``) or 17 significant digits (``.obj``): exact.
Meshes keep the terrain's own axes (x east, y north, z up); glTF's convention is +Y up,
so glTF viewers show a ``.glb`` terrain standing on its edge unless told that z is up.
"""

from __future__ import annotations

import json
import math
import warnings
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ._fileio import atomic_path
from ._georef import (
    IDENTITY, crs_is_geographic, lonlat_to_local, metres_per_degree, native_axes, parse_crs, rasterio_module,
    warn_if_degrees, xy_to_native,
)
from ._validate import describe
from .terrain import TIN, HeightGrid, _is_uniform, as_terrain

__all__ = [
    "load_terrain", "save_terrain", "load_dem", "save_dem", "sample_dem", "native_coords", "metres_per_degree",
    "SUFFIXES", "DEM_SUFFIXES", "MESH_SUFFIXES", "TERRAIN_SUFFIXES", "FORMAT", "FORMAT_VERSION",
]

#: Raster suffixes: read by :func:`load_dem`, written by :func:`save_dem`.
DEM_SUFFIXES = (".npz", ".npy", ".asc", ".tif", ".tiff")
#: The suffixes of :func:`load_dem` and :func:`save_dem` (the raster suffixes).
SUFFIXES = DEM_SUFFIXES
#: Mesh suffixes: any terrain is written as a mesh, read back as a TIN.
MESH_SUFFIXES = (".ply", ".obj", ".stl", ".glb")
#: Everything :func:`load_terrain` and :func:`save_terrain` handle.
TERRAIN_SUFFIXES = DEM_SUFFIXES + MESH_SUFFIXES
#: The ``format`` entry of a terrainvis ``.npz`` file.
FORMAT = "terrainvis"
#: The ``format_version`` this module writes (and the newest it reads).
FORMAT_VERSION = 1

_GRID_ORIENTATIONS = ("y_increasing", "y_decreasing")
_TIN_ORIENTATION = "z_up_ccw"
_ATTRS_TAG = "TERRAINVIS_ATTRS"
_RESAMPLED_TAG = "TERRAINVIS_RESAMPLED"
_PLY_ATTRS = "comment terrainvis-attrs "
_OBJ_ATTRS = "# terrainvis-attrs "


class _Corrupt(ValueError):
    """A file that is not what its suffix says, or is damaged (turned into a ValueError naming it)."""


# ---------------------------------------------------------------------- validation
def _check_path(path, suffixes, name: str = "path") -> tuple[Path, str]:
    if not isinstance(path, (str, Path)):
        raise TypeError(f"{name} must be a str or pathlib.Path, got {describe(path)}")
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in suffixes:
        raise ValueError(f"{name} must end in one of {list(suffixes)}, got {p.name!r} (suffix {p.suffix!r})")
    return p, suffix


def _check_nodata(nodata):
    if nodata is None:
        return None
    if isinstance(nodata, (bool, np.bool_)) or not isinstance(nodata, (int, float, np.integer, np.floating)):
        raise TypeError(f"nodata must be a real number (the height that marks missing samples), got {describe(nodata)}")
    value = float(nodata)
    if math.isnan(value):
        raise ValueError("nodata must not be NaN: NaN already marks nodata")
    return value


def _check_crs_arg(crs):
    if crs is None:
        return None
    if not isinstance(crs, str) or not crs.strip():
        raise TypeError(f"crs must be a CRS string such as 'EPSG:4326', got {describe(crs)}")
    try:
        parse_crs(crs, "crs")  # a clear ValueError now rather than a wrong grid later
    except ImportError:
        pass  # without rasterio the text is kept as given
    return crs


def _check_band(band, suffix: str):
    if band is None:
        return None
    if isinstance(band, (bool, np.bool_)) or not isinstance(band, (int, np.integer)):
        raise TypeError(f"band must be an integer (1 is the first band), got {describe(band)}")
    if band < 1:
        raise ValueError(f"band must be >= 1 (bands are numbered from 1, as in GDAL), got {band}")
    if suffix not in (".tif", ".tiff"):
        raise ValueError(f"band applies to GeoTIFF files (.tif, .tiff), got a {suffix} file")
    return int(band)


# ---------------------------------------------------------------------- attrs as JSON
_TUPLE = "__tuple__"
_ARRAY = "__ndarray__"


class _Unencodable(Exception):
    pass


def _encode(value, where: str):
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, tuple):
        return {_TUPLE: [_encode(v, f"{where}[{i}]") for i, v in enumerate(value)]}
    if isinstance(value, list):
        return [_encode(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, dict):
        for k in value:
            if not isinstance(k, str):
                raise _Unencodable(f"{where} has a non-string key {k!r}")
        if _TUPLE in value or _ARRAY in value:
            raise _Unencodable(f"{where} uses a reserved key ({_TUPLE!r} or {_ARRAY!r})")
        return {k: _encode(v, f"{where}[{k!r}]") for k, v in value.items()}
    if isinstance(value, np.ndarray) and value.dtype.kind in "biufU":
        return {_ARRAY: value.tolist(), "dtype": value.dtype.str, "shape": list(value.shape)}
    raise _Unencodable(f"{where} is a {type(value).__name__}, which JSON cannot hold")


def _decode_object(obj: dict):
    if set(obj) == {_TUPLE}:
        return tuple(obj[_TUPLE])
    if set(obj) == {_ARRAY, "dtype", "shape"}:
        return np.array(obj[_ARRAY], dtype=np.dtype(obj["dtype"])).reshape(obj["shape"])
    return obj


def _attrs_to_json(attrs: dict) -> str:
    """``attrs`` (without ``path``) as JSON text; values JSON cannot hold are dropped with a warning."""
    out = {}
    for key, value in attrs.items():
        if key == "path":
            continue
        try:
            if not isinstance(key, str):
                raise _Unencodable(f"attrs key {key!r} is not a string")
            out[key] = _encode(value, f"attrs[{key!r}]")
        except _Unencodable as exc:
            warnings.warn(f"{exc}; it is not written to the file", UserWarning, stacklevel=4)
    return json.dumps(out, allow_nan=True)


def _attrs_from_json(text: str) -> dict:
    try:
        attrs = json.loads(text, object_hook=_decode_object)
    except (ValueError, TypeError) as exc:
        raise _Corrupt(f"its attrs are not valid JSON ({exc})") from None
    if not isinstance(attrs, dict):
        raise _Corrupt(f"its attrs must be a JSON object, got {type(attrs).__name__}")
    return attrs


# ---------------------------------------------------------------------- public: load
def load_terrain(path, *, nodata: float | None = None, crs: str | None = None, band: int | None = None):
    """Read a terrain: a HeightGrid from a raster or grid file, a TIN from a mesh or TIN file.

    Parameters
    ----------
    path : str or Path
        Any suffix of :data:`TERRAIN_SUFFIXES` (see the module docstring): ``.npz`` (the
        terrainvis format, either kind, and the older dialects), ``.npy``, ``.asc``,
        ``.tif``/``.tiff``, or a mesh (``.ply``, ``.obj``, ``.stl``, ``.glb``; read with
        trimesh as a TIN).
    nodata : float, optional
        A height to treat as nodata (besides the file's own nodata value), compared
        with the heights as read (after a GeoTIFF's scale and offset). Grids only.
    crs : str, optional
        The CRS of a file that records none (``.asc`` without ``.prj``, ``.tif`` without
        CRS, ``.npy``, an older ``.npz``), e.g. ``"EPSG:4326"``: a lon/lat CRS converts
        the coordinates to local metres. A file that records a CRS refuses it.
    band : int, optional
        The GeoTIFF band to read (1 is the first). A multi-band GeoTIFF needs it; other
        formats refuse it.

    Returns
    -------
    HeightGrid or TIN
        ``attrs`` as stored, plus the georeferencing (``crs``, ``geographic``,
        ``xy_to_native``) when known and ``path``, the file read.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        Unknown suffix, or a corrupt, truncated, ambiguous or inconsistent file; the
        message names the file and the reason.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from terrainvis import synthetic_terrain
    >>> g = synthetic_terrain("hills", size=9)
    >>> p = save_terrain(g, pathlib.Path(tempfile.mkdtemp()) / "hills.npz")
    >>> back = load_terrain(p)
    >>> bool((back.z == g.z).all()), back.attrs["name"]
    (True, 'hills')
    """
    p, suffix = _check_path(path, TERRAIN_SUFFIXES)
    nodata = _check_nodata(nodata)
    crs = _check_crs_arg(crs)
    band = _check_band(band, suffix)
    if not p.exists():
        raise FileNotFoundError(f"path {str(p)!r} does not exist")
    if p.is_dir():
        raise ValueError(f"path {str(p)!r} is a folder, not a {suffix} file")
    terrain = _read(p, suffix, crs=crs, band=band)
    if isinstance(terrain, TIN):
        if nodata is not None or crs is not None:
            raise ValueError(f"{p.name!r} holds a TIN; nodata and crs apply to grids only")
    elif nodata is not None:
        z = terrain.z.copy()
        z[z == nodata] = np.nan
        terrain = terrain.copy_with(z)
    terrain.attrs["path"] = str(p)
    return terrain


def load_dem(path, *, nodata: float | None = None, crs: str | None = None, band: int | None = None) -> HeightGrid:
    """Read a DEM into a :class:`~terrainvis.HeightGrid` (:func:`load_terrain` for grids).

    Parameters
    ----------
    path : str or Path
        ``.npz`` (the terrainvis format or an older dialect, e.g. ``shared/data/dem``),
        ``.npy`` (a bare array, unit spacing), ``.asc`` (ESRI ASCII grid, with its ``.prj``
        when present) or ``.tif``/``.tiff`` (GeoTIFF, needs the ``geo`` extra:
        ``pip install "terrainvis[geo]"``).
    nodata, crs, band
        As in :func:`load_terrain`.

    Returns
    -------
    HeightGrid
        Rows flipped so that y grows northwards (see the module docstring); nodata as NaN;
        ``attrs`` hold the file's path, the CRS and the map to native coordinates when known.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        Unknown suffix, a file holding a TIN, or a corrupt or inconsistent file.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from terrainvis import HeightGrid
    >>> g = HeightGrid([[1.0, 2.0], [3.0, 4.0]], dx=30.0, dy=30.0, origin=(500000.0, 4000000.0))
    >>> p = save_dem(g, pathlib.Path(tempfile.mkdtemp()) / "g.asc")
    >>> load_dem(p).xs.tolist()
    [500000.0, 500030.0]
    """
    p, _ = _check_path(path, DEM_SUFFIXES)
    terrain = load_terrain(p, nodata=nodata, crs=crs, band=band)
    if not isinstance(terrain, HeightGrid):
        raise ValueError(f"{p.name!r} holds a TIN, not a grid; read it with terrainvis.io.load_terrain")
    return terrain


def _read(p: Path, suffix: str, *, crs, band):
    readers = {
        ".npz": _read_npz, ".npy": _read_npy, ".asc": _read_asc, ".tif": _read_tif, ".tiff": _read_tif,
    }
    try:
        if suffix in MESH_SUFFIXES:
            return _read_mesh(p, suffix)
        terrain = readers[suffix](p, crs=crs, band=band)
    except _Corrupt as exc:
        raise ValueError(f"could not read {p.name!r} as a {suffix} file: {exc}") from None
    except (FileNotFoundError, ImportError, _UserError):
        raise
    except (OSError, EOFError, KeyError, IndexError, TypeError, ValueError, zipfile.BadZipFile, zlib.error) as exc:
        raise ValueError(f"could not read {p.name!r} as a {suffix} file: {type(exc).__name__}: {exc}") from exc
    return terrain


class _UserError(ValueError):
    """A problem with the caller's arguments found while reading (passed through unchanged)."""


def _georeference(z, xs, ys, attrs: dict, file_crs, crs_arg, source: str, *, dlon=None, dlat=None) -> HeightGrid:
    """A HeightGrid from native sample coordinates (increasing), with its georeferencing attrs."""
    if file_crs and crs_arg:
        raise _UserError(f"crs: {source} records the CRS {file_crs!r}; crs= is only for files that record none, got {crs_arg!r}")
    text = file_crs or crs_arg
    if not text:
        warn_if_degrees(xs, ys, source, stacklevel=6)
        return HeightGrid.from_coords(z, xs, ys, attrs=attrs)
    geographic = crs_is_geographic(text)
    if geographic:
        xs, ys, affine = lonlat_to_local(xs, ys, dlon=dlon, dlat=dlat)
    else:
        affine = IDENTITY
    attrs.update(crs=text, geographic=geographic, xy_to_native=affine)
    return HeightGrid.from_coords(z, xs, ys, attrs=attrs)


# ---------------------------------------------------------------------- .npz
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


def _read_npz(p: Path, *, crs=None, band=None):
    with open(p, "rb") as fh:
        head = fh.read(8)
    if head.startswith(b"\x93NUMPY"):
        raise _Corrupt("it is a .npy file (one bare array), not a .npz archive; give it the suffix .npy")
    if not head.startswith(_ZIP_MAGIC):
        raise _Corrupt(f"it is not a .npz file (a zip archive of .npy arrays): it starts with {head!r}")
    try:
        with np.load(p, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except ValueError as exc:
        if "pickle" in str(exc):
            raise _Corrupt(
                "it holds an object array, which only pickle can read; terrainvis never writes one and does not "
                "unpickle files"
            ) from None
        raise _Corrupt(f"it is truncated or corrupt (ValueError: {exc})") from None
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as exc:
        raise _Corrupt(f"it is truncated or corrupt ({type(exc).__name__}: {exc})") from None
    terrain = _terrain_from_arrays(arrays)
    if crs is not None and isinstance(terrain, HeightGrid):
        if terrain.attrs.get("crs"):
            raise _UserError(
                f"crs: {p.name!r} records the CRS {terrain.attrs['crs']!r}; crs= is only for files that record none, "
                f"got {crs!r}"
            )
        if terrain.attrs.get("geographic"):
            raise _UserError(f"crs: {p.name!r} is a lon/lat grid already converted to metres; crs= cannot apply")
        terrain = _georeference(terrain.z, terrain.xs, terrain.ys, dict(terrain.attrs), None, crs, p.name)
    return terrain


def _text(a: dict, key: str) -> str:
    v = a[key]
    if v.ndim != 0 or v.dtype.kind not in "US":
        raise _Corrupt(f"key {key!r} must be a text scalar, got an array of shape {v.shape} and dtype {v.dtype}")
    return str(v)


def _scalar(a: dict, key: str) -> float:
    v = a[key]
    if v.size != 1 or v.dtype.kind not in "biuf":
        raise _Corrupt(f"key {key!r} must be a numeric scalar, got an array of shape {v.shape} and dtype {v.dtype}")
    return float(v.reshape(()))


def _need(a: dict, keys, what: str):
    missing = [k for k in keys if k not in a]
    if missing:
        raise _Corrupt(f"{what} needs the keys {list(keys)}, but {missing} are missing (found {sorted(a)})")


def _terrain_from_arrays(a: dict):
    keys = set(a)
    if "format" in keys:
        return _from_v1(a)
    if "vertices" in keys or "faces" in keys:
        if "z" in keys:
            raise _Corrupt(f"it holds both a grid ('z') and a TIN ('vertices', 'faces') and no 'format' key; keys {sorted(a)}")
        if "kind" in keys and _text(a, "kind") != "tin":
            raise _Corrupt(f"its key 'kind' is {_text(a, 'kind')!r}, but it holds 'vertices'/'faces' (a TIN)")
        _need(a, ("vertices", "faces"), "a TIN")
        return TIN(a["vertices"], a["faces"])
    if "z" not in keys:
        raise _Corrupt(f"it holds neither a grid (key 'z') nor a TIN (keys 'vertices', 'faces'); keys {sorted(a)}")
    if "kind" in keys and _text(a, "kind") != "grid":
        raise _Corrupt(f"its key 'kind' is {_text(a, 'kind')!r}, but it holds 'z' (a grid)")
    z = np.asarray(a["z"], dtype=np.float64)
    if z.ndim != 2:
        raise _Corrupt(f"z must be 2-D, got shape {z.shape}")
    has_spacing = "dx" in keys or "dy" in keys
    has_coords = "xs" in keys or "ys" in keys
    if has_spacing:
        _need(a, ("dx", "dy"), "a north-up raster .npz (the shared-DEM dialect)")
        return _from_north_up(a, z)
    if has_coords:
        _need(a, ("xs", "ys"), "a grid .npz with coordinates")
        xs = np.asarray(a["xs"], dtype=np.float64)
        ys = np.asarray(a["ys"], dtype=np.float64)
        # z[r, c] at (xs[c], ys[r]): unambiguous whichever way the coordinates run.
        if ys.ndim == 1 and ys.size >= 2 and ys[-1] < ys[0]:
            z, ys = z[::-1], ys[::-1]
        if xs.ndim == 1 and xs.size >= 2 and xs[-1] < xs[0]:
            z, xs = z[:, ::-1], xs[::-1]
        return HeightGrid.from_coords(z, xs, ys)
    raise _Corrupt(
        "it has 'z' but no coordinates: neither 'dx'/'dy' (a north-up raster, as in shared/data/dem) nor "
        "'xs'/'ys' (grid rows with their coordinates), so its spacing and row order are unknown"
    )


def _from_north_up(a: dict, z_north_up: np.ndarray) -> HeightGrid:
    """The shared-DEM dialect and the former save_dem dialect: raster rows, dx/dy in metres."""
    z = z_north_up[::-1]
    rows, cols = z.shape
    attrs = {}
    for key in ("crs", "source", "license", "description", "z_units"):
        if key in a:
            attrs[key] = _text(a, key)
    geographic = bool(_scalar(a, "geographic")) if "geographic" in a else False
    attrs["geographic"] = geographic
    dx, dy = _scalar(a, "dx"), _scalar(a, "dy")
    if "xs" in a or "ys" in a:
        # The former save_dem dialect: exact coordinates beside the mean spacing.
        _need(a, ("xs", "ys"), "a north-up .npz with coordinates (the former save_dem dialect)")
        xs = np.asarray(a["xs"], dtype=np.float64)
        ys = np.asarray(a["ys"], dtype=np.float64)
        for axis, v, d in (("x", xs, dx), ("y", ys, dy)):
            if v.ndim == 1 and v.size >= 2:
                mean = float((v[-1] - v[0]) / (v.size - 1))
                if not abs(mean - d) <= 1e-9 * max(abs(d), abs(mean)):
                    raise _Corrupt(
                        f"its d{axis} = {d!r} disagrees with the mean spacing {mean!r} of {axis}s, so it is not a "
                        "file of a known dialect (z, dx, dy, xs, ys as the former save_dem wrote)"
                    )
        if not geographic:
            attrs["xy_to_native"] = IDENTITY
        return HeightGrid.from_coords(z, xs, ys, attrs=attrs)
    origin = (0.0, 0.0)
    if "geotransform" in a:
        gt = np.asarray(a["geotransform"], dtype=np.float64).ravel()
        if gt.size != 6 or gt[2] != 0 or gt[4] != 0:
            raise _Corrupt(f"geotransform must be 6 numbers of a north-up raster (no rotation), got {gt.tolist()}")
        x0 = gt[0] + 0.5 * gt[1]  # the south-west sample centre in native coordinates
        y0 = gt[3] + gt[5] * (rows - 0.5)
        if geographic:
            dx_native = _scalar(a, "dx_native") if "dx_native" in a else abs(gt[1])
            dy_native = _scalar(a, "dy_native") if "dy_native" in a else abs(gt[5])
            attrs["xy_to_native"] = (dx_native / dx, float(x0), dy_native / dy, float(y0))
        else:
            origin = (float(x0), float(y0))
            attrs["xy_to_native"] = IDENTITY
    elif not geographic:
        attrs["xy_to_native"] = IDENTITY
    return HeightGrid(z, dx=dx, dy=dy, origin=origin, attrs=attrs)


def _from_v1(a: dict):
    fmt = _text(a, "format")
    if fmt != FORMAT:
        raise _Corrupt(f"its key 'format' is {fmt!r}, not {FORMAT!r}")
    _need(a, ("format_version", "kind", "orientation", "attrs"), f"a {FORMAT} .npz")
    version = _scalar(a, "format_version")
    if version != int(version) or version < 1:
        raise _Corrupt(f"its format_version must be a positive integer, got {version!r}")
    if version > FORMAT_VERSION:
        raise _Corrupt(
            f"it was written by a newer terrainvis (format version {int(version)}; this one reads up to "
            f"{FORMAT_VERSION}); upgrade terrainvis to read it"
        )
    kind = _text(a, "kind")
    orientation = _text(a, "orientation")
    attrs = _attrs_from_json(_text(a, "attrs"))
    if kind == "grid":
        _need(a, ("z", "xs", "ys"), "a grid")
        z, xs, ys = a["z"], a["xs"], a["ys"]
        if orientation == "y_decreasing":
            if z.ndim != 2 or ys.ndim != 1:
                raise _Corrupt(f"z must be 2-D and ys 1-D, got shapes {z.shape} and {ys.shape}")
            z, ys = z[::-1], ys[::-1]
        elif orientation != "y_increasing":
            raise _Corrupt(f"a grid's orientation must be one of {list(_GRID_ORIENTATIONS)}, got {orientation!r}")
        return HeightGrid.from_coords(z, xs, ys, attrs=attrs)
    if kind == "tin":
        if orientation != _TIN_ORIENTATION:
            raise _Corrupt(f"a TIN's orientation must be {_TIN_ORIENTATION!r}, got {orientation!r}")
        _need(a, ("vertices", "faces"), "a TIN")
        return TIN(a["vertices"], a["faces"], attrs=attrs)
    raise _Corrupt(f"its kind must be 'grid' or 'tin', got {kind!r}")


def _npz_arrays(terrain) -> dict:
    common = {
        "format": np.asarray(FORMAT), "format_version": np.int64(FORMAT_VERSION),
        "attrs": np.asarray(_attrs_to_json(terrain.attrs)),
    }
    if isinstance(terrain, HeightGrid):
        return dict(common, kind=np.asarray("grid"), orientation=np.asarray("y_increasing"), z=terrain.z,
                    xs=terrain.xs, ys=terrain.ys)
    return dict(common, kind=np.asarray("tin"), orientation=np.asarray(_TIN_ORIENTATION), vertices=terrain.vertices,
                faces=terrain.faces)


def _write_npz(terrain, p: Path) -> None:
    arrays = _npz_arrays(terrain)
    with atomic_path(p) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)  # a file object: numpy appends no suffix


# ---------------------------------------------------------------------- .npy
def _read_npy(p: Path, *, crs=None, band=None) -> HeightGrid:
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


# ---------------------------------------------------------------------- .asc
_ASC_KEYS = {"ncols", "nrows", "xllcorner", "yllcorner", "xllcenter", "yllcenter", "cellsize", "dx", "dy", "nodata_value"}


def _prj_path(p: Path) -> Path | None:
    for suffix in (".prj", ".PRJ"):
        q = p.with_suffix(suffix)
        if q.exists():
            return q
    return None


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
    return _georeference(z[::-1], xs, ys, {}, file_crs, crs, source, dlon=dx, dlat=dy)


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


def _nodata_value(z: np.ndarray) -> float | None:
    """None without NaN; else -9999 unless it is a real height, else another value that does not occur."""
    nan = np.isnan(z)
    if not nan.any():
        return None
    finite = z[~nan]
    for candidate in (-9999.0, -32768.0, -99999.0, -3.4028234663852886e38):
        if not (finite == candidate).any():
            return candidate
    below = float(np.nextafter(finite.min(), -np.inf))  # below every height, so not one of them
    return below if math.isfinite(below) else float(np.nextafter(finite.max(), np.inf))


def _uniform_layout(grid: HeightGrid, suffix: str):
    """What a uniform raster of ``grid`` holds: heights, native sample axes, CRS text, resampling note."""
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
    xs, ys, z = grid.xs, grid.ys, grid.z
    note = None
    if not grid.is_uniform:
        ux = xs if _is_uniform(xs) else np.linspace(xs[0], xs[-1], xs.size)
        uy = ys if _is_uniform(ys) else np.linspace(ys[0], ys[-1], ys.size)
        moved = []
        for axis, old, new in (("x", xs, ux), ("y", ys, uy)):
            shift = np.abs(new - old)
            cell = (old[-1] - old[0]) / (old.size - 1)
            n = int((shift > 1e-9 * max(abs(cell), 1e-300)).sum())
            if n:
                moved.append(f"{n} of {old.size} {axis} positions by up to {shift.max():.6g} ({shift.max() / cell:.3g} cell)")
        note = (
            f"{suffix} needs a uniform grid: the rectilinear {grid.shape[0]}x{grid.shape[1]} grid was resampled onto "
            f"uniform coordinates over the same sample extent with the same number of samples; moved "
            f"{' and '.join(moved)}; heights there are read from the grid's surface. Save to .npz to keep it exactly."
        )
        warnings.warn(note, UserWarning, stacklevel=4)
        z = grid.height_on_grid(ux, uy)
        xs, ys = ux, uy
    nx, ny = native_axes(xs, ys, affine)
    return z, nx, ny, crs_text, note


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
    dx = float((nx[-1] - nx[0]) / (cols - 1))
    dy = float((ny[-1] - ny[0]) / (rows - 1))
    nodata = _nodata_value(z)
    body = (z if nodata is None else np.where(np.isnan(z), nodata, z))[::-1]
    size_lines = f"cellsize {dx!r}\n" if dx == dy else f"dx {dx!r}\ndy {dy!r}\n"
    header = (
        f"ncols {cols}\nnrows {rows}\nxllcenter {float(nx[0])!r}\nyllcenter {float(ny[0])!r}\n{size_lines}"
        + ("" if nodata is None else f"NODATA_value {nodata!r}\n")
    )
    if prj_text is not None:
        prj = p.with_suffix(".prj")
        with atomic_path(prj) as tmp:
            tmp.write_text(prj_text, encoding="ascii")
    with atomic_path(p) as tmp, open(tmp, "w", encoding="ascii") as fh:
        fh.write(header)
        np.savetxt(fh, body, fmt="%.17g")


# ---------------------------------------------------------------------- GeoTIFF
def _read_tif(p: Path, *, crs=None, band=None) -> HeightGrid:
    rasterio = rasterio_module()
    try:
        with rasterio.open(p) as src:
            if band is None and src.count != 1:
                raise _UserError(
                    f"{p.name!r} has {src.count} bands; a DEM has one: pass band=k (1..{src.count}) to choose one"
                )
            b = 1 if band is None else band
            if b > src.count:
                raise _UserError(f"band must be in [1, {src.count}] for {p.name!r}, got {b}")
            data = src.read(b, masked=True)
            scale, offset = src.scales[b - 1], src.offsets[b - 1]
            t = src.transform
            file_crs = src.crs
            tags = src.tags()
    except rasterio.errors.RasterioError as exc:
        raise _Corrupt(str(exc)) from exc
    if t.b != 0 or t.d != 0:
        raise _Corrupt(f"rotated rasters are not supported (transform {tuple(t)[:6]})")
    # Plain arrays, not masked arithmetic (several times slower on large rasters).
    z = np.asarray(np.ma.getdata(data), dtype=np.float64)  # a fresh buffer from rasterio: changed in place
    scale = 1.0 if scale is None else float(scale)
    offset = 0.0 if offset is None else float(offset)
    if scale != 1.0:
        z *= scale
    if offset != 0.0:
        z += offset
    mask = np.ma.getmaskarray(data)
    if mask.any():
        z[mask] = np.nan
    rows, cols = z.shape
    # Sample centres in native coordinates, made increasing (x east, y north).
    dx, dy = abs(t.a), abs(t.e)
    x0 = t.c + 0.5 * t.a if t.a > 0 else t.c + t.a * (cols - 0.5)
    y0 = t.f + t.e * (rows - 0.5) if t.e < 0 else t.f + 0.5 * t.e
    if t.e < 0:
        z = z[::-1]  # north-up raster rows -> increasing y
    if t.a < 0:
        z = z[:, ::-1]
    xs = x0 + dx * np.arange(cols, dtype=np.float64)
    ys = y0 + dy * np.arange(rows, dtype=np.float64)
    attrs = {}
    if _ATTRS_TAG in tags:
        attrs = _attrs_from_json(tags[_ATTRS_TAG])
    crs_text = None
    if file_crs:
        crs_text = file_crs.to_string()
        stored = attrs.get("crs")
        if isinstance(stored, str) and stored != crs_text:
            # Keep the stored text (e.g. with a remark) when it names the same CRS.
            try:
                if parse_crs(stored) == file_crs:
                    crs_text = stored
            except ValueError:
                pass
    for key in ("crs", "geographic", "xy_to_native"):
        attrs.pop(key, None)  # the file's own georeferencing decides
    return _georeference(z, xs, ys, attrs, crs_text, crs, p.name, dlon=dx, dlat=dy)


def _write_tif(grid: HeightGrid, p: Path) -> None:
    rasterio = rasterio_module()
    from rasterio.transform import Affine

    z, nx, ny, crs_text, note = _uniform_layout(grid, p.suffix)
    crs = parse_crs(crs_text, "grid.attrs['crs']") if crs_text else None  # before any file is touched
    rows, cols = z.shape
    dx = float((nx[-1] - nx[0]) / (cols - 1))
    dy = float((ny[-1] - ny[0]) / (rows - 1))
    transform = Affine(dx, 0.0, float(nx[0]) - 0.5 * dx, 0.0, -dy, float(ny[-1]) + 0.5 * dy)
    nodata = _nodata_value(z)
    north_up = z[::-1] if nodata is None else np.where(np.isnan(z), nodata, z)[::-1]
    attrs = dict(grid.attrs)
    tags = {}
    if note is not None:
        attrs["resampled"] = note
        tags[_RESAMPLED_TAG] = note
    tags[_ATTRS_TAG] = _attrs_to_json(attrs)
    with atomic_path(p) as tmp:
        with rasterio.open(
            tmp, "w", driver="GTiff", height=rows, width=cols, count=1, dtype="float64", transform=transform,
            crs=crs, nodata=nodata,
        ) as dst:
            dst.write(north_up, 1)
            dst.update_tags(**tags)


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


# ---------------------------------------------------------------------- meshes
def _mesh_of(terrain) -> TIN:
    return terrain.to_tin() if isinstance(terrain, HeightGrid) else terrain


def _ply_bytes(tin: TIN, attrs_json: str) -> bytes:
    faces = tin.faces
    index_type, index_dtype = ("int", "<i4") if tin.n_vertices < 2**31 else ("uint", "<u4")
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"{_PLY_ATTRS}{attrs_json}\n"
        f"element vertex {tin.n_vertices}\nproperty double x\nproperty double y\nproperty double z\n"
        f"element face {tin.n_faces}\nproperty list uchar {index_type} vertex_indices\nend_header\n"
    )
    packed = np.empty(tin.n_faces, dtype=[("n", "u1"), ("i", index_dtype, (3,))])
    packed["n"] = 3
    packed["i"] = faces
    return header.encode("ascii") + tin.vertices.astype("<f8").tobytes() + packed.tobytes()


def _obj_bytes(tin: TIN, attrs_json: str) -> bytes:
    import io

    buf = io.StringIO()
    buf.write(f"# terrainvis {FORMAT_VERSION}: a TIN, x y z as written (z up), faces counter-clockwise from above\n")
    buf.write(f"{_OBJ_ATTRS}{attrs_json}\n")
    np.savetxt(buf, tin.vertices, fmt="v %.17g %.17g %.17g")
    np.savetxt(buf, tin.faces.astype(np.int64) + 1, fmt="f %d %d %d")
    return buf.getvalue().encode("ascii")


def _stl_bytes(tin: TIN) -> bytes:
    import trimesh

    v = tin.vertices
    err = float(np.abs(v.astype(np.float32).astype(np.float64) - v).max())
    lo, hi = v.min(axis=0), v.max(axis=0)
    span = float((hi - lo).max())
    if err > 1e-6 * max(span, 1e-300):
        warnings.warn(
            f"STL stores float32: coordinates up to {np.abs(v).max():.6g} are rounded by up to {err:.3g} "
            f"({err / max(span, 1e-300):.2g} of the terrain's extent); save to .ply, .obj or .npz for exact coordinates",
            UserWarning, stacklevel=4,
        )
    mesh = trimesh.Trimesh(vertices=v, faces=tin.faces, process=False, validate=False)
    return mesh.export(file_type="stl")


def _glb_bytes(tin: TIN, attrs_json: str) -> bytes:
    import trimesh

    origin = tin.vertices.min(axis=0)
    mesh = trimesh.Trimesh(vertices=tin.vertices - origin, faces=tin.faces, process=False, validate=False)
    scene = trimesh.Scene()
    transform = np.eye(4)
    transform[:3, 3] = origin
    scene.add_geometry(mesh, node_name="terrain", geom_name="terrain", transform=transform)
    scene.metadata["terrainvis"] = {
        "format": FORMAT, "format_version": FORMAT_VERSION, "kind": "tin", "orientation": _TIN_ORIENTATION,
        "origin": [float(v) for v in origin], "attrs": attrs_json,
    }
    return scene.export(file_type="glb")


def _write_mesh(terrain, p: Path, suffix: str) -> None:
    tin = _mesh_of(terrain)
    if suffix == ".stl":
        if terrain.attrs:
            keys = sorted(k for k in terrain.attrs if k != "path")
            if keys:
                warnings.warn(
                    f"STL has no place for metadata: attrs {keys} are not written", UserWarning, stacklevel=3,
                )
        data = _stl_bytes(tin)
    else:
        attrs_json = _attrs_to_json(terrain.attrs)
        data = {".ply": _ply_bytes, ".obj": _obj_bytes, ".glb": _glb_bytes}[suffix](tin, attrs_json)
    with atomic_path(p) as tmp:
        tmp.write_bytes(data)


def _mesh_attrs(p: Path, suffix: str, loaded) -> dict:
    if suffix == ".ply":
        with open(p, "rb") as fh:
            head = b""
            while b"end_header" not in head:
                chunk = fh.read(1 << 16)
                if not chunk:
                    break
                head += chunk
        for line in head.split(b"end_header")[0].decode("ascii", errors="replace").splitlines():
            if line.startswith(_PLY_ATTRS):
                return _attrs_from_json(line[len(_PLY_ATTRS):])
    elif suffix == ".obj":
        with open(p, "r", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if not line.startswith("#"):
                    break
                if line.startswith(_OBJ_ATTRS):
                    return _attrs_from_json(line[len(_OBJ_ATTRS):].strip())
    elif suffix == ".glb":
        meta = getattr(loaded, "metadata", {}) or {}
        info = meta.get("terrainvis")
        if isinstance(info, dict) and isinstance(info.get("attrs"), str):
            return _attrs_from_json(info["attrs"])
    return {}


def _read_mesh(p: Path, suffix: str) -> TIN:
    import trimesh

    try:
        loaded = trimesh.load(str(p), file_type=suffix[1:], process=False)
        mesh = loaded.to_geometry() if isinstance(loaded, trimesh.Scene) else loaded
    except Exception as exc:  # a third-party parser: any failure means the file cannot be read
        raise _Corrupt(f"trimesh could not read it ({type(exc).__name__}: {exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise _Corrupt(f"it holds no triangle mesh (trimesh read {type(mesh).__name__})")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if suffix == ".stl":
        # STL repeats each vertex for every face: merge exact duplicates.
        vertices, inverse = np.unique(vertices, axis=0, return_inverse=True)
        faces = inverse.reshape(-1)[faces]
    attrs = _mesh_attrs(p, suffix, loaded)
    return TIN(vertices, faces, attrs=attrs)


# ---------------------------------------------------------------------- public: save
def save_terrain(terrain, path) -> Path:
    """Write a HeightGrid or a TIN so that :func:`load_terrain` reads it back.

    Parameters
    ----------
    terrain : HeightGrid or TIN
    path : str or Path
        The suffix picks the format (see the module docstring):

        * ``.npz``: either kind, exact (z, xs, ys or vertices, faces; attrs as JSON);
        * ``.tif``/``.tiff``, ``.asc``: grids, in the native CRS (GeoTIFF CRS and
          transform from the grid's own coordinates; ``.asc`` with a ``.prj`` beside it);
          a rectilinear grid is resampled onto a uniform one with a warning; nodata
          written as -9999 (another value when -9999 is a real height; none without NaN);
        * ``.npy``: grids with unit spacing and origin (0, 0) (only z is kept);
        * ``.ply``, ``.obj``, ``.stl``, ``.glb``: any terrain as a mesh (a grid through
          :meth:`HeightGrid.to_tin`). ``.ply`` (float64) and ``.obj`` (17 digits) are
          exact; ``.stl`` and ``.glb`` hold float32 vertices: UTM coordinates near
          5,000 km are 0.5 m apart in float32, so ``.glb`` is written about a float64
          local origin (the node's translation) and ``.stl`` warns when it rounds.

    Returns
    -------
    Path
        The path written (exactly ``path``; the suffix's case is kept).

    Raises
    ------
    ValueError
        An unknown suffix, a TIN to a grid-only format, a CRS in ``attrs`` that rasterio
        cannot read (raised before anything is written). The destination is replaced
        atomically: on any failure the file that was there is left unchanged.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from terrainvis import synthetic_terrain
    >>> tin = synthetic_terrain("hills", size=5).to_tin()
    >>> p = save_terrain(tin, pathlib.Path(tempfile.mkdtemp()) / "hills.ply")
    >>> back = load_terrain(p)
    >>> bool((back.vertices == tin.vertices).all() and (back.faces == tin.faces).all())
    True
    """
    as_terrain(terrain)
    p, suffix = _check_path(path, TERRAIN_SUFFIXES)
    if p.is_dir():
        raise ValueError(f"path {str(p)!r} is a folder; give a file name ending in {suffix}")
    if isinstance(terrain, TIN) and suffix not in (".npz",) + MESH_SUFFIXES:
        raise ValueError(
            f"a TIN can be written as .npz or a mesh ({', '.join(MESH_SUFFIXES)}), not {suffix} (a raster format); "
            f"got {p.name!r}"
        )
    if suffix == ".npz":
        _write_npz(terrain, p)
    elif suffix in MESH_SUFFIXES:
        _write_mesh(terrain, p, suffix)
    elif suffix == ".npy":
        _write_npy(terrain, p)
    elif suffix == ".asc":
        _write_asc(terrain, p)
    else:
        _write_tif(terrain, p)
    return p


def save_dem(grid: HeightGrid, path) -> Path:
    """Write a grid so that :func:`load_dem` reads it back (:func:`save_terrain` for grids).

    Parameters
    ----------
    grid : HeightGrid
    path : str or Path
        ``.npz`` (any rectilinear grid, exact coordinates and attrs kept), ``.asc`` and
        ``.tif``/``.tiff`` (in the native CRS; a rectilinear grid is resampled onto a
        uniform one with a warning; nodata written as -9999, another value when -9999
        is a real height, none without NaN) or ``.npy`` (only z; the grid must have
        unit spacing and origin (0, 0)). Rows are written north-up (flipped back, see
        the module docstring).

    Returns
    -------
    Path
        The path written.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from terrainvis import HeightGrid
    >>> g = HeightGrid([[1.0, 2.0], [3.0, 4.0]])
    >>> save_dem(g, pathlib.Path(tempfile.mkdtemp()) / "G.NPZ").name
    'G.NPZ'
    """
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    p, suffix = _check_path(path, DEM_SUFFIXES)
    return save_terrain(grid, p)


# ---------------------------------------------------------------------- sample data
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
        Rows flipped so that y grows northwards, origin (0, 0) in local metres; ``attrs``
        hold the CRS (``"EPSG:4326 (assumed; lon/lat degrees)"``) and ``xy_to_native``,
        the map back to lon/lat.

    Examples
    --------
    >>> g = sample_dem()
    >>> g.shape, round(g.dx, 2), round(g.dy, 2)
    ((344, 403), 74.57, 92.47)
    """
    if name not in _SAMPLES:
        raise ValueError(f"name must be one of {list(_SAMPLES)}, got {name!r}")
    with np.load(_matplotlib_sample(_SAMPLES[name]), allow_pickle=False) as data:
        z = np.asarray(data["elevation"], dtype=np.float64)
        dx_deg = float(data["dx"])
        dy_deg = float(data["dy"])
        # In this file 'ymin' holds the northern edge and 'ymax' the southern one.
        lon_w = float(data["xmin"])
        lat_n = max(float(data["ymin"]), float(data["ymax"]))
        lat_c = 0.5 * (float(data["ymin"]) + float(data["ymax"]))
    rows = z.shape[0]
    m_lon, m_lat = metres_per_degree(lat_c)
    # local x = (lon - lon of the western sample centres) * m_lon, likewise y from the southern ones
    affine = (1.0 / m_lon, lon_w + 0.5 * dx_deg, 1.0 / m_lat, lat_n - dy_deg * (rows - 0.5))
    attrs = {
        "name": name,
        "source": "matplotlib sample data jacksboro_fault_dem.npz (USGS 3-arc-second DEM)",
        "crs": "EPSG:4326 (assumed; lon/lat degrees)",
        "geographic": True,
        "xy_to_native": affine,
    }
    return HeightGrid(z[::-1], dx=dx_deg * m_lon, dy=dy_deg * m_lat, attrs=attrs)
