"""GeoTIFF (``.tif``, ``.tiff``) through rasterio, with ``attrs`` kept in a tag."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..core.fileio import atomic_path
from ..core.memory import fresh_array
from ..core._georef import GEOREF_KEYS, parse_crs, rasterio_module
from ..core.terrain import HeightGrid
from ._attrs import _attrs_from_json, _attrs_to_json
from ._common import _check_read_memory, _Corrupt, _UserError
from ._raster import _georeference, _nodata_value, _uniform_layout, native_lattice

_ATTRS_TAG = "TERRAINVIS_ATTRS"
_RESAMPLED_TAG = "TERRAINVIS_RESAMPLED"


def _read_tif(p: Path, *, crs=None, band=None) -> HeightGrid:
    rasterio = rasterio_module()

    try:
        with contextlib.ExitStack() as stack:
            if _gdal_path(p):
                src = stack.enter_context(rasterio.open(p, **_decoding_threads(p)))
            else:  # a name GDAL cannot take: read the bytes through memory
                from rasterio.io import MemoryFile

                src = stack.enter_context(stack.enter_context(MemoryFile(p.read_bytes())).open())
            if band is None and src.count != 1:
                raise _UserError(
                    f"{p.name!r} has {src.count} bands; a DEM has one: pass band=k (1..{src.count}) to choose one"
                )
            b = 1 if band is None else band
            if b > src.count:
                raise _UserError(f"band must be in [1, {src.count}] for {p.name!r}, got {b}")
            # the band, its mask (1 byte) and the float64 heights
            _check_read_memory(p.name, (src.height, src.width), np.dtype(src.dtypes[b - 1]).itemsize, extra_per_sample=1)
            plain, (scale, offset) = _plain(src, b), _scale_offset(src, b)
            t = src.transform
            if t.b != 0 or t.d != 0:
                raise _Corrupt(f"rotated rasters are not supported (transform {tuple(t)[:6]})")
            n_nan = None
            if plain:
                # each strip is read once, whole blocks at a time: GDAL's block cache (5 % of the
                # memory by default) would keep every block read, the size of the band again
                # (8192² float32: 871 MB at the end of the reading instead of 599 MB)
                with rasterio.Env(GDAL_CACHEMAX=_strip_cache_bytes(src, b)):
                    z, n_nan = _read_strips(src, b, t, (scale, offset), _held_dtype(src, b))
            else:
                z = _to_heights(_masked(src.read(b, masked=True), t), (scale, offset))
            file_crs = src.crs
            tags = src.tags()
    except rasterio.errors.RasterioError as exc:
        raise _Corrupt(str(exc)) from exc
    rows, cols = z.shape
    # Sample centres in native coordinates, made increasing (x east, y north).
    dx, dy = abs(t.a), abs(t.e)
    x0 = t.c + 0.5 * t.a if t.a > 0 else t.c + t.a * (cols - 0.5)
    y0 = t.f + t.e * (rows - 0.5) if t.e < 0 else t.f + 0.5 * t.e
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
    for key in GEOREF_KEYS:
        attrs.pop(key, None)  # the file's own georeferencing decides
    lattice = (t.c if t.a > 0 else t.c + t.a * cols, dx, t.f if t.e < 0 else t.f + t.e * rows, dy)
    grid = _georeference(z, xs, ys, attrs, crs_text, crs, p.name, dlon=dx, dlat=dy, lattice=lattice, owned=True)
    if n_nan is not None and grid.heights is z:  # the grid adopted the buffer the strips counted
        grid._cache["n_nodata"] = n_nan
    return grid


#: Samples read at once: a strip of whole rows of about this many (rounded to the file's
#: blocks), so that an interrupt is answered between strips (a 20000² band read in one
#: call held Ctrl-C for seconds) and the file's own type is never held whole beside the heights.
_STRIP_SAMPLES = 1 << 22


#: Samples from which a GeoTIFF is decoded on every core (GDAL's ``NUM_THREADS``): on 8192² and
#: 20000² float32 DEFLATE tiles the reading took 0.6 and 2.0 s instead of 1.3 and 3.5 s; on
#: 3601² the second core loads numba's kernels beside the reading, and the command was
#: slower with it (A/B 1.065, 27 November).
THREADED_DECODING_SAMPLES = 1 << 24


def _decoding_threads(p: Path) -> dict:
    """``num_threads="ALL_CPUS"`` for a raster of at least :data:`THREADED_DECODING_SAMPLES` samples."""
    rasterio = rasterio_module()
    with contextlib.suppress(Exception):  # what cannot be opened is reported by the read itself
        with rasterio.open(p) as probe:
            if probe.width * probe.height >= THREADED_DECODING_SAMPLES:
                return {"num_threads": "ALL_CPUS"}
    return {}


def _strip_cache_bytes(src, b: int) -> int:
    """GDAL's block cache while :func:`_read_strips` reads: two strips of blocks (at least 16 MiB)."""
    block_rows = max(1, src.block_shapes[b - 1][0])
    step = max(block_rows, _STRIP_SAMPLES // max(src.width, 1) // block_rows * block_rows)
    return max(16 << 20, 2 * step * src.width * np.dtype(src.dtypes[b - 1]).itemsize)


def _plain(src, b: int) -> bool:
    """Whether band ``b``'s nodata is its nodata value alone (found in the pass that converts and flips
    the band); a mask beyond it (a mask band, alpha) needs rasterio's masked read."""
    from rasterio.enums import MaskFlags

    return all(f in (MaskFlags.all_valid, MaskFlags.nodata) for f in src.mask_flag_enums[b - 1])


def _scale_offset(src, b: int) -> tuple[float, float]:
    scale, offset = src.scales[b - 1], src.offsets[b - 1]
    return (1.0 if scale is None else float(scale)), (0.0 if offset is None else float(offset))


def _held_dtype(src, b: int) -> np.dtype:
    """The dtype the grid read from band ``b`` holds its heights in (:attr:`~terrainvis.HeightGrid.heights`):
    float32 for a float32 band read plainly (:func:`_plain`) without scale or offset (its samples are
    the heights), float64 otherwise."""
    keep32 = np.dtype(src.dtypes[b - 1]) == np.float32 and _plain(src, b) and _scale_offset(src, b) == (1.0, 0.0)
    return np.dtype(np.float32 if keep32 else np.float64)


def held_dtype(p: Path) -> np.dtype:
    """:func:`_held_dtype` of the GeoTIFF ``p``'s first band, from its header (float64 when it
    cannot be opened: the read itself reports why)."""
    rasterio = rasterio_module()
    with contextlib.suppress(Exception):
        with rasterio.open(p) as src:
            return _held_dtype(src, 1)
    return np.dtype(np.float64)


def _read_strips(src, b: int, t, scale_offset, dtype) -> np.ndarray:
    """Band ``b`` of an open raster as heights: rows in increasing y (and x), its nodata
    value NaN, ``(scale, offset)`` applied, read in strips of rows (:data:`_STRIP_SAMPLES`)
    into a fresh buffer the grid adopts; and the number of NaN (counted strip by strip: a
    grid's ``n_nodata`` without a pass and a mask of its own).

    The buffer's ``dtype`` is :func:`_held_dtype`'s: float32 for a float32 band that has no
    scale or offset (the samples are the heights: the grid keeps them,
    :attr:`~terrainvis.HeightGrid.heights`, half the memory of a float64 copy)."""
    from rasterio.windows import Window

    rows, cols = src.height, src.width
    z = fresh_array((rows, cols), dtype)
    nodata = src.nodatavals[b - 1]
    stored = None
    if nodata is not None and not np.isnan(nodata):
        stored = _as_stored(nodata, np.dtype(src.dtypes[b - 1]))
    block = max(1, src.block_shapes[b - 1][0])
    step = max(block, _STRIP_SAMPLES // max(cols, 1) // block * block)
    flip_rows, flip_cols = t.e < 0, t.a < 0
    n_nan = 0
    for r0 in range(0, rows, step):
        r1 = min(rows, r0 + step)
        part = src.read(b, window=Window(0, r0, cols, r1 - r0))
        dst = z[rows - r1: rows - r0] if flip_rows else z[r0:r1]
        dst[...] = part[::-1 if flip_rows else 1, ::-1 if flip_cols else 1]
        if stored is not None:
            dst[dst == stored] = np.nan
        _to_heights(dst, scale_offset)
        n_nan += int(np.count_nonzero(np.isnan(dst)))
    return z, n_nan


def _to_heights(z: np.ndarray, scale_offset) -> np.ndarray:
    """``z * scale + offset`` in place (the band's stored values to heights), as two steps."""
    scale, offset = scale_offset
    if scale != 1.0:
        z *= scale
    if offset != 0.0:
        z += offset
    return z


def _masked(data, t) -> np.ndarray:
    """A masked band read whole (a mask band or alpha beyond the nodata value) as float64, flipped as
    :func:`_read_strips` does, its masked samples NaN."""
    band = np.ma.getdata(data)
    z = np.empty(band.shape, dtype=np.float64)
    z[...] = band[::-1 if t.e < 0 else 1, ::-1 if t.a < 0 else 1]
    mask = np.ma.getmaskarray(data)[::-1 if t.e < 0 else 1, ::-1 if t.a < 0 else 1]
    if mask.any():
        z[mask] = np.nan
    return z


def _as_stored(nodata: float, dtype) -> float | None:
    """The nodata value as the band's type holds it (None when that type cannot hold it: no sample is nodata).

    GDAL reports it as a double; a float32 band compares its own rounding of it, as a
    masked read does."""
    dtype = np.dtype(dtype)
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        if nodata != int(nodata) or not info.min <= nodata <= info.max:
            return None
    with np.errstate(over="ignore"):
        value = np.asarray(nodata).astype(dtype)
    return float(value) if np.isfinite(value) else None


#: Rasters with at least this many rows and columns are written in tiles (GDAL's usual 256 x 256).
_TILE_FROM = 512
_BLOCK = 256


def _creation_options(rows: int, cols: int, dtype: str) -> dict:
    """What GDAL writes for a DEM: DEFLATE (with the floating-point or integer predictor), tiles when large."""
    opts = {"compress": "deflate", "bigtiff": "if_safer"}
    if dtype.startswith("float"):
        opts["predictor"] = 3
    if rows >= _TILE_FROM and cols >= _TILE_FROM:
        opts.update(tiled=True, blockxsize=_BLOCK, blockysize=_BLOCK)
    return opts


def _height_dtype(rows_of: "_Rows") -> str:
    """float32 when every value (nodata included) survives the round trip exactly, else
    float64; strip by strip (two full-size copies of an 8192² grid were 768 MB)."""
    for r0, r1 in rows_of.strips():
        values = rows_of(r0, r1)
        with np.errstate(over="ignore", invalid="ignore"):
            z32 = values.astype(np.float32)
        if not np.array_equal(z32.astype(np.float64), values):
            return "float64"
    return "float32"


class _Rows:
    """The rows of a raster to write, north-up, made strip by strip from the grid's own
    south-up array: ``rows(r0, r1)`` (row 0 the northernmost) in ``dtype`` (None: as they
    are), NaN replaced by ``nodata`` when given, ``nodata_mask`` (south-up, bool) samples
    set to ``nodata``. A full north-up copy of the raster is never made: writing an 8192²
    viewshed held a uint8 copy and its flipped copy (128 MB), a DEM two float copies."""

    def __init__(self, south_up: np.ndarray, dtype, nodata=None, nodata_mask=None):
        self.a = south_up
        self.dtype = None if dtype is None else np.dtype(dtype)
        self.nodata = nodata
        self.mask = nodata_mask
        self.shape = south_up.shape

    def strips(self):
        """``(r0, r1)`` of the strips, about :data:`_STRIP_SAMPLES` samples each."""
        rows, cols = self.shape
        step = max(1, _STRIP_SAMPLES // max(cols, 1))
        return [(r0, min(rows, r0 + step)) for r0 in range(0, rows, step)]

    def __call__(self, r0: int, r1: int) -> np.ndarray:
        n = self.shape[0]
        part = self.a[n - r1: n - r0][::-1]
        if self.nodata is not None and part.dtype.kind == "f":
            part = np.where(np.isnan(part), self.nodata, part)
        out = np.array(part, dtype=self.dtype or part.dtype, order="C")  # a copy: the masked samples are set in it
        if self.mask is not None:
            out[self.mask[n - r1: n - r0][::-1]] = self.nodata
        return out

    @property
    def out_dtype(self) -> np.dtype:
        return self.dtype if self.dtype is not None else self.a.dtype


def _write_tif(grid: HeightGrid, p: Path, *, dtype: str | None = None) -> None:
    rasterio_module()  # the geo extra's one-line error before any work

    z, nx, ny, crs_text, note = _uniform_layout(grid, p.suffix)
    crs = parse_crs(crs_text, "grid.attrs['crs']") if crs_text else None  # before any file is touched
    rows, cols = z.shape
    transform = _north_up_transform(nx, ny, grid.attrs)
    nodata = _nodata_value(z, always=True)  # GIS tools expect the tag even when no sample uses it
    rows_of = _Rows(z, None, nodata)
    dtype = _height_dtype(rows_of) if dtype is None else dtype
    attrs = dict(grid.attrs)
    tags = {}
    if note is not None:
        attrs["resampled"] = note
        tags[_RESAMPLED_TAG] = note
    tags[_ATTRS_TAG] = _attrs_to_json(attrs)
    profile = dict(height=rows, width=cols, count=1, dtype=dtype, transform=transform, crs=crs, nodata=nodata)
    with atomic_path(p) as tmp:
        _write_gtiff(tmp, _Rows(z, dtype, nodata), profile, tags)


def _gdal_path(path: Path) -> bool:
    """Whether GDAL can be handed ``path``: rasterio passes paths on as UTF-8, so a name
    that is not valid UTF-8 (bytes kept as surrogates by Python) cannot be."""
    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _write_gtiff(path: Path, data: "_Rows", profile: dict, tags: dict | None = None) -> None:
    """One band as GDAL writes a GeoTIFF (:func:`_creation_options`), strip by strip from
    ``data``; through memory when GDAL cannot take the name.

    GDAL reports some failed writes (a full disk while it flushes its tiles on closing
    the file) only as lines that libtiff prints on stderr, and closes the file as if it
    were complete. So those lines are captured while GDAL writes, and the file is read
    back and compared with ``data`` before it is handed on: a damaged file raises
    :class:`OSError` with the first line GDAL printed, which
    :func:`~terrainvis.core.fileio.atomic_path` turns into an
    :class:`~terrainvis.core.fileio.OutputError` without renaming the file over the
    destination. After a good write the captured lines (warnings) are printed as GDAL
    would have printed them.
    """
    rasterio = rasterio_module()
    profile = dict(profile, driver="GTiff", **_creation_options(data.shape[0], data.shape[1], str(data.out_dtype)))
    tags = {k: str(v) for k, v in (tags or {}).items()}
    if not _gdal_path(path):
        from rasterio.io import MemoryFile

        with MemoryFile() as mem:
            with mem.open(**profile) as dst:
                _write_strips(dst, data)
                dst.update_tags(**tags)
            path.write_bytes(mem.read())  # a failed Python write raises
        return
    with _stderr_lines() as printed:
        try:
            with rasterio.open(path, "w", **profile) as dst:
                _write_strips(dst, data)
                dst.update_tags(**tags)
            failed = None if _reads_back(path, data, tags) else "the file does not read back as written"
        except rasterio.errors.RasterioError as exc:
            failed = str(exc)
    if failed is not None:
        reason = next((line.strip().rstrip(".") for line in printed if line.strip()), failed)
        raise OSError(f"GDAL could not write the GeoTIFF: {reason}")
    if printed:
        sys.stderr.write("".join(line + "\n" for line in printed))


def _write_strips(dst, data: "_Rows") -> None:
    from rasterio.windows import Window

    cols = data.shape[1]
    for r0, r1 in data.strips():
        dst.write(data(r0, r1), 1, window=Window(0, r0, cols, r1 - r0))


def _reads_back(path: Path, data: "_Rows", tags: dict) -> bool:
    """Whether the GeoTIFF ``path`` reads back as ``data`` with ``tags`` (strip by strip)."""
    from rasterio.windows import Window

    rasterio = rasterio_module()
    with rasterio.open(path) as src:
        if (src.height, src.width) != data.shape or np.dtype(src.dtypes[0]) != data.out_dtype:
            return False
        for r0, r1 in data.strips():
            if not _same_values(src.read(1, window=Window(0, r0, data.shape[1], r1 - r0)), data(r0, r1)):
                return False
        stored = src.tags()
    return all(stored.get(k) == v for k, v in tags.items())


#: Unsigned integer types by size in bytes, for comparing arrays bit for bit.
_BITS = {1: np.uint8, 2: np.uint16, 4: np.uint32, 8: np.uint64}


def _same_values(a: np.ndarray, b: np.ndarray) -> bool:
    """``np.array_equal(a, b, equal_nan=True)`` for two arrays of one shape and dtype, bit for
    bit first: on a 3601² raster the bits take 0.01 s, ``equal_nan`` 0.3 s (float32) or
    0.07 s (uint8). Only arrays whose bits differ (a NaN's payload, -0.0 against 0.0, or
    other values) take the slow comparison."""
    bits = _BITS.get(a.dtype.itemsize)
    if bits is not None and a.dtype.kind in "biuf" and a.flags.c_contiguous and b.flags.c_contiguous \
            and np.array_equal(a.view(bits), b.view(bits)):
        return True
    return bool(np.array_equal(a, b, equal_nan=True))


@contextlib.contextmanager
def _stderr_lines():
    """Capture what C code prints on file descriptor 2 while the block runs; yield the list of its lines.

    The list is filled when the block ends. The capture is held in memory (a memfd where
    the platform has one), so a full disk does not lose it; where no capture can be set
    up, nothing is captured and the list stays empty.
    """
    lines: list[str] = []
    try:
        sys.stderr.flush()
        sink = os.fdopen(os.memfd_create("terrainvis-gdal"), "w+b") if hasattr(os, "memfd_create") else \
            tempfile.TemporaryFile()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no fd 2 (an embedded interpreter), no memory
        yield lines
        return
    os.dup2(sink.fileno(), 2)
    try:
        yield lines
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        sink.seek(0)
        lines.extend(sink.read().decode("utf-8", "replace").splitlines())
        sink.close()


def _north_up_transform(nx: np.ndarray, ny: np.ndarray, attrs: dict | None = None):
    """The GDAL transform of a north-up raster whose sample centres are the native axes nx, ny
    (on the lattice of the raster ``attrs`` were read from, that raster's numbers: :func:`native_lattice`)."""
    from rasterio.transform import Affine

    left, dx, top, dy = native_lattice(attrs or {}, nx, ny)
    return Affine(dx, 0.0, left, 0.0, -dy, top)


def write_geotiff(grid: HeightGrid, data: np.ndarray, path, *, nodata=None, tags: dict | None = None) -> Path:
    """Write one value per sample of ``grid`` as a single-band GeoTIFF aligned with it.

    The grid's CRS and the transform of its own coordinates, as :func:`~terrainvis.save_dem`
    writes them, so the file overlays the grid's GeoTIFF in a GIS; compressed and tiled as
    GDAL writes a DEM. The file is written atomically and read back before it replaces
    an existing one (a full disk raises :class:`~terrainvis.errors.OutputError` and leaves
    the old file). Viewsheds, observer counts and other rasters over a DEM are the
    intended use.

    Parameters
    ----------
    grid : HeightGrid
        A uniform grid (a rectilinear one cannot be one raster; save an ``.npz`` then).
    data : (rows, cols) array
        The values, row 0 at the grid's smallest y (the grid's own order); written with
        their dtype (bool as uint8).
    path : str or Path
        A ``.tif`` or ``.tiff`` file.
    nodata : number, optional
        The value that marks samples without data (recorded in the file).
    tags : dict, optional
        GDAL metadata items (text) stored in the file.

    Returns
    -------
    Path
    """
    p = Path(path)
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {type(grid).__name__}")
    values = np.asarray(data)
    if values.shape != grid.shape:
        raise ValueError(f"data must have the grid's shape {grid.shape}, got {values.shape}")
    return _write_raster(grid, _Rows(values, np.uint8 if values.dtype == bool else None), p, nodata=nodata,
                         tags=tags)


def check_geotiff_target(grid: HeightGrid, path) -> tuple:
    """What a GeoTIFF over ``grid``'s samples at ``path`` needs, checked before anything is computed:
    ``(path, native x, native y, CRS)``. A command calls it before its work, so that a grid
    without a uniform layout or with a CRS that cannot be written fails at once, not after
    a viewshed of minutes.

    Raises
    ------
    ValueError
        A suffix other than ``.tif``/``.tiff``, a rectilinear grid, or a CRS that cannot be read.
    """
    p = Path(path)
    if p.suffix.lower() not in (".tif", ".tiff"):
        raise ValueError(f"path must end in .tif or .tiff, got {p.name!r}")
    if not grid.is_uniform:
        raise ValueError("a GeoTIFF needs a uniform grid, and this one is rectilinear: write the raster as .npz")
    _, nx, ny, crs_text, _ = _uniform_layout(grid, p.suffix, values=False)
    crs = parse_crs(crs_text, "grid.attrs['crs']") if crs_text else None
    return p, nx, ny, crs


def _write_raster(grid: HeightGrid, rows_of: "_Rows", path, *, nodata=None, tags=None) -> Path:
    """The checks and the write of :func:`write_geotiff` for rows made strip by strip."""
    p, nx, ny, crs = check_geotiff_target(grid, path)
    rows, cols = rows_of.shape
    profile = dict(height=rows, width=cols, count=1, dtype=rows_of.out_dtype.name,
                   transform=_north_up_transform(nx, ny, grid.attrs), crs=crs, nodata=nodata)
    with atomic_path(p) as tmp:
        _write_gtiff(tmp, rows_of, profile, tags)
    return p


def write_mask_geotiff(grid: HeightGrid, mask: np.ndarray, path, *, nodata_mask=None) -> Path:
    """Write a boolean raster over ``grid``'s samples as a uint8 GeoTIFF aligned with it.

    1 where ``mask`` is True, 0 where False, 255 (the nodata value) where ``nodata_mask``
    is True (:func:`write_geotiff`). A viewshed is the intended use.

    Parameters
    ----------
    grid : HeightGrid
        A uniform grid (a rectilinear one cannot be one raster; save an ``.npz`` then).
    mask : (rows, cols) bool
    path : str or Path
        A ``.tif`` or ``.tiff`` file, written atomically.
    nodata_mask : (rows, cols) bool, optional
    """
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {type(grid).__name__}")
    m = np.asarray(mask, dtype=bool)
    if m.shape != grid.shape:
        raise ValueError(f"mask must have the grid's shape {grid.shape}, got {m.shape}")
    holes = None if nodata_mask is None else np.asarray(nodata_mask, dtype=bool)
    if holes is not None and holes.shape != grid.shape:
        raise ValueError(f"nodata_mask must have the grid's shape {grid.shape}, got {holes.shape}")
    return _write_raster(grid, _Rows(m, np.uint8, 255, holes), path, nodata=255)
