"""What every terrainvis file format shares: the format identity, the error types, argument checks."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from ..core._georef import parse_crs
from ..core.validate import describe

#: The ``format`` entry of a terrainvis ``.npz`` file.
FORMAT = "terrainvis"
#: The ``format_version`` terrainvis writes (and the newest it reads).
FORMAT_VERSION = 1
#: The orientation of every TIN written (``.npz`` key ``orientation``, ``.glb`` metadata).
_TIN_ORIENTATION = "z_up_ccw"


class _Corrupt(ValueError):
    """A file that is not what its suffix says, or is damaged (turned into a ValueError naming it)."""


class _UserError(ValueError):
    """A problem with the caller's arguments found while reading (passed through unchanged)."""


# ---------------------------------------------------------------------- argument checks
_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")


def _check_path(path, suffixes, name: str = "path") -> tuple[Path, str]:
    if not isinstance(path, (str, Path)):
        raise TypeError(f"{name} must be a str or pathlib.Path, got {describe(path)}")
    if isinstance(path, str) and _URL.match(path):
        raise ValueError(
            f"{name} must be a local file; URLs are not supported, got {path!r}: download the file first"
        )
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


# ---------------------------------------------------------------------- memory before reading
#: Bytes a reader holds per sample besides the file's own values: the float64 heights and
#: the HeightGrid's own copy of them.
_READ_BYTES_PER_SAMPLE = 16


def _check_read_memory(name: str, shape, itemsize: int, extra_per_sample: int = 0) -> None:
    """Refuse to read ``shape`` samples of ``itemsize`` bytes when they cannot fit in memory."""
    from ..core.memory import check_memory

    n = math.prod(int(v) for v in shape)
    need = n * (int(itemsize) + _READ_BYTES_PER_SAMPLE + extra_per_sample)
    dims = "x".join(str(int(v)) for v in shape)
    check_memory(need, f"reading {name!r} ({dims} samples of {itemsize} bytes)")


def _npy_header(fh):
    """``(shape, dtype)`` from the header of a ``.npy`` stream, which is left after the header."""
    version = np.lib.format.read_magic(fh)
    if version == (1, 0):
        shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
    elif version == (2, 0):
        shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
    else:
        shape, _, dtype = np.lib.format._read_array_header(fh, version)
    return shape, dtype
