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
``geographic``, ``xy_to_native``; see :mod:`terrainvis.core._georef`), so a grid written to
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

Every file is written atomically (:func:`terrainvis.core.fileio.atomic_path`): a failure
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

import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..core._georef import metres_per_degree
from ..core.validate import describe
from ..errors import NotEnoughMemoryError
from ..core.terrain import TIN, HeightGrid, as_terrain
from ._asc import _read_asc, _write_asc
from ._common import (
    FORMAT,
    FORMAT_VERSION,
    _check_band,
    _check_crs_arg,
    _check_nodata,
    _check_path,
    _Corrupt,
    _UserError,
)
from ._geotiff import _read_tif, _write_tif, check_geotiff_target, write_geotiff, write_mask_geotiff
from ._gpkg import read_lines as read_geopackage_lines
from ._gpkg import write_lines as write_geopackage_lines
from ._outputs import FIGURE_SOFTWARE, figure_metadata, save_figure, write_csv
from ._meshfile import _read_mesh, _write_mesh
from ._metric import to_metric
from ._npy import _read_npy, _write_npy
from ._npz import _read_npz, _write_npz
from ._raster import native_coords
from ._sample import bundled_terrain, sample_dem

# One module per concern (all private; this module is the API and the dispatch by suffix):
#   _common    FORMAT, FORMAT_VERSION, the error types, argument checks shared by every format
#   _attrs     attrs as JSON text (tagged tuples and arrays)
#   _raster    what the raster formats share: georeferencing a grid read, native_coords, the
#              nodata value written, the uniform layout (resampling a rectilinear grid)
#   _npz       the terrainvis .npz format (version 1) and the older .npz dialects
#   _npy       bare .npy arrays
#   _asc       ESRI ASCII grids and their .prj
#   _geotiff   GeoTIFF through rasterio
#   _meshfile  .ply, .obj, .stl, .glb
#   _outputs   figures (.png, marked as terrainvis's) and CSV tables, written atomically
#   _gpkg      GeoPackage line layers through sqlite3 (write_geopackage_lines, read_geopackage_lines)
#   _sample    sample_dem, bundled_terrain
#   _metric    to_metric: a lon/lat grid resampled onto a local transverse Mercator grid

__all__ = [
    "load_terrain", "HEIGHT_DTYPES", "write_geotiff", "write_mask_geotiff", "check_geotiff_target", "save_figure", "write_csv", "figure_metadata",
    "FIGURE_SOFTWARE", "save_terrain", "load_dem", "save_dem", "sample_dem", "bundled_terrain", "native_coords",
    "metres_per_degree", "to_metric", "write_geopackage_lines", "read_geopackage_lines",
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
    if isinstance(terrain, HeightGrid) and terrain.n_nodata == terrain.size:
        raise ValueError(
            f"{p.name!r} holds no height: all {terrain.shape[0]}x{terrain.shape[1]} samples are nodata"
            + (f" (the file's nodata value or nodata={nodata!r})" if nodata is not None else "")
        )
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
    except (FileNotFoundError, ImportError, _UserError, NotEnoughMemoryError):
        raise
    except (OSError, EOFError, KeyError, IndexError, TypeError, ValueError, zipfile.BadZipFile, zlib.error) as exc:
        raise ValueError(f"could not read {p.name!r} as a {suffix} file: {type(exc).__name__}: {exc}") from exc
    return terrain



# ---------------------------------------------------------------------- public: save
def save_terrain(terrain, path, *, like: HeightGrid | None = None, dtype: str | None = None) -> Path:
    """Write a HeightGrid or a TIN so that :func:`load_terrain` reads it back.

    Parameters
    ----------
    terrain : HeightGrid or TIN
    like : HeightGrid, optional
        For a TIN written to a raster (``.tif``, ``.tiff``, ``.asc``, ``.npy``): the grid
        whose samples the TIN's surface is sampled at (:meth:`TIN.to_grid`; nodata
        outside the TIN), with its CRS and transform, usually the DEM the TIN was
        simplified from. Not used otherwise.
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
    if like is not None and not isinstance(like, HeightGrid):
        raise TypeError(f"like must be a terrainvis.HeightGrid (the grid to sample a TIN on), got {describe(like)}")
    if dtype is not None:
        if dtype not in HEIGHT_DTYPES:
            raise ValueError(f"dtype must be one of {list(HEIGHT_DTYPES)} or None, got {dtype!r}")
        if suffix not in (".tif", ".tiff"):
            raise ValueError(f"dtype chooses how a GeoTIFF stores heights; {p.name!r} is not one (other formats "
                             "keep float64)")
    if isinstance(terrain, TIN) and suffix not in (".npz",) + MESH_SUFFIXES:
        if like is None:
            raise ValueError(
                f"a TIN is written to a raster ({suffix}) by sampling its surface on a grid: pass like=<the grid> "
                f"(e.g. the DEM it was simplified from), or write .npz or a mesh ({', '.join(MESH_SUFFIXES)}); "
                f"got {p.name!r}"
            )
        terrain = terrain.to_grid(like)
    if suffix == ".npz":
        _write_npz(terrain, p)
    elif suffix in MESH_SUFFIXES:
        _write_mesh(terrain, p, suffix)
    elif suffix == ".npy":
        _write_npy(terrain, p)
    elif suffix == ".asc":
        _write_asc(terrain, p)
    else:
        _write_tif(terrain, p, dtype=dtype)
    return p


#: How a GeoTIFF may store heights (``dtype=`` of :func:`save_terrain` and :func:`save_dem`).
HEIGHT_DTYPES = ("float32", "float64")


def save_dem(grid: HeightGrid, path, *, dtype: str | None = None) -> Path:
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
    dtype : {"float32", "float64"}, optional
        How a GeoTIFF stores the heights. None (the default): float32 when every height
        survives it exactly, else float64, so the file reads back as written; "float32"
        as GIS tools write elevation (rounding each height by at most 2^-24 of its size:
        under 0.1 mm below 1,000 m); "float64" always.

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
    return save_terrain(grid, p, dtype=dtype)
