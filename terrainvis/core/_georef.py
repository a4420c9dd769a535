"""Georeferencing of a HeightGrid: its CRS and the map from its (x, y) to native coordinates.

A :class:`~terrainvis.HeightGrid` works in one length unit for x, y and z (metres), so
a grid read from a lon/lat raster is moved to local metres. Three ``attrs`` keys keep
what is needed to go back (they are plain values, so ``crop``, ``subsample``,
``fill_nodata`` and a regular simplification carry them over unchanged, and they stay
right because they describe a map of coordinates, not a raster):

``crs`` : str
    The CRS as the source states it: ``"EPSG:26918"``, a WKT string, or text with a
    remark such as ``"EPSG:4326 (assumed; lon/lat degrees)"`` (the EPSG code in it is
    used when the whole text is not a CRS).
``geographic`` : bool
    True when the native CRS is lon/lat; ``xs`` and ``ys`` are then local metres.
``xy_to_native`` : (sx, ox, sy, oy) tuple of float
    The per-axis affine map from the grid's coordinates to native ones:
    ``x_native = ox + sx * x`` and ``y_native = oy + sy * y`` (``sx``, ``sy`` > 0).
    ``(1.0, 0.0, 1.0, 0.0)`` on a projected grid, whose coordinates are native already.
    On a lon/lat grid ``sx = 1 / m_lon`` and ``sy = 1 / m_lat`` (WGS84 metres per degree
    at the centre latitude, :func:`metres_per_degree`), and ``(ox, oy)`` is the lon/lat
    of the sample at local (0, 0).
``source_crs`` : str, only on a grid resampled by :func:`terrainvis.io.to_metric`
    The lon/lat CRS the grid was resampled from. Its ``crs`` is then the metric CRS of
    its samples (a local transverse Mercator), and positions given in ``source_crs``
    are moved to the grid's frame through that projection.

Positions
---------
Every computation of terrainvis takes positions in the terrain's own frame, the frame of
``grid.xs`` and ``grid.ys``. A user gives them in the *native* CRS: the CRS of the DEM
file as read (``crs``), or the ``source_crs`` of a grid resampled onto a metric grid.
:func:`from_native` and :func:`to_native` convert between the two (``HeightGrid.from_native``
and ``HeightGrid.to_native`` call them); on a projected grid both are the identity, bit
for bit. The command line's ``--frame native`` (the default) goes through them
(:mod:`terrainvis.core._positions`); ``--frame local`` takes the terrain's own frame.
"""

from __future__ import annotations

import os

import math
import re
import warnings

import numpy as np

from ..tolerances import DEGREE_CELL_SLACK, EDGE_SNAP_REL, ROUNDING_ULPS, UNIFORM_STEP_REL

__all__ = [
    "GEOREF_KEYS", "IDENTITY", "metres_per_degree", "rasterio_module", "parse_crs", "crs_is_geographic",
    "xy_to_native", "native_axes", "lonlat_to_local", "looks_like_degrees", "warn_if_degrees",
    "position_crs", "from_native", "to_native", "transform_xy", "local_frame_error",
]

#: The ``attrs`` keys that hold a grid's georeferencing (see the module docstring).
GEOREF_KEYS = ("crs", "geographic", "xy_to_native", "source_crs", "native_lattice")
#: ``xy_to_native`` of a grid whose coordinates are already native.
IDENTITY = (1.0, 0.0, 1.0, 0.0)


def metres_per_degree(lat_deg: float) -> tuple[float, float]:
    """WGS84 metres per degree of longitude and of latitude at latitude ``lat_deg``.

    Examples
    --------
    >>> [round(v, 1) for v in metres_per_degree(45.0)]
    [78846.8, 111131.7]
    """
    phi = math.radians(lat_deg)
    lon = 111412.84 * math.cos(phi) - 93.5 * math.cos(3 * phi) + 0.118 * math.cos(5 * phi)
    lat = 111132.92 - 559.82 * math.cos(2 * phi) + 1.175 * math.cos(4 * phi) - 0.0023 * math.cos(6 * phi)
    return lon, lat


def rasterio_module(purpose: str = "reading and writing GeoTIFF"):
    """rasterio, or an ImportError with the install hint."""
    try:
        import rasterio
    except ImportError as exc:
        raise ImportError(f'{purpose} needs rasterio: pip install "terrainvis[geo]"') from exc
    return rasterio


_EPSG = re.compile(r"\bEPSG\s*:\s*(\d+)", re.IGNORECASE)


def parse_crs(text, name: str = "crs"):
    """``text`` as a :class:`rasterio.crs.CRS`.

    The whole text is tried first (EPSG code, WKT, PROJ string); when that fails and the
    text names one ``EPSG:<code>`` (e.g. ``"EPSG:4326 (assumed; lon/lat degrees)"``),
    that code is used and the rest is taken as a remark.

    Raises
    ------
    ValueError
        When neither works; the message names ``name`` and the text.
    """
    rasterio = rasterio_module("parsing a CRS")
    from rasterio.crs import CRS

    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"{name} must be a non-empty CRS string such as 'EPSG:32633', got {text!r}")
    # PROJ's own "ERROR 1: ..." lines of a text it cannot read go to GDAL's log, not to stderr
    # beside the one-line message raised here
    with rasterio.Env(CPL_LOG=os.devnull):
        try:
            return CRS.from_user_input(text)
        except (rasterio.errors.CRSError, ValueError, TypeError):
            pass
        codes = set(_EPSG.findall(text))
        if len(codes) == 1:
            try:
                return CRS.from_epsg(int(codes.pop()))
            except (rasterio.errors.CRSError, ValueError) as exc:
                raise ValueError(f"{name} {text!r} names an EPSG code that rasterio does not know: {exc}") from None
    raise ValueError(
        f"{name} {text!r} is not a CRS rasterio can read (tried the whole text, then one EPSG:<code> in it); "
        "use e.g. 'EPSG:32633' or a WKT string"
    )


def crs_is_geographic(text: str) -> bool:
    """Whether a CRS string is lon/lat (with rasterio when installed, else from the text)."""
    try:
        return bool(parse_crs(text).is_geographic)
    except ImportError:
        pass
    except ValueError:
        return False
    head = text.strip().upper()
    if head.startswith(("GEOGCS", "GEOGCRS", "GEODCRS")):
        return True
    codes = _EPSG.findall(text)
    return bool(codes) and int(codes[0]) in (4326, 4269, 4267, 4258, 4283, 4617)


def xy_to_native(attrs: dict):
    """The validated ``(sx, ox, sy, oy)`` of ``attrs``, identity when absent, None when unknown.

    Unknown means a geographic grid without ``xy_to_native`` (its local metres cannot be
    mapped back to lon/lat).
    """
    value = attrs.get("xy_to_native")
    if value is None:
        return None if attrs.get("geographic") else IDENTITY
    try:
        sx, ox, sy, oy = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(
            f"attrs['xy_to_native'] must be four numbers (sx, ox, sy, oy), got {value!r}"
        ) from None
    if not all(math.isfinite(v) for v in (sx, ox, sy, oy)) or sx <= 0 or sy <= 0:
        raise ValueError(f"attrs['xy_to_native'] must be finite with sx > 0 and sy > 0, got {value!r}")
    return sx, ox, sy, oy


def native_axes(xs: np.ndarray, ys: np.ndarray, affine) -> tuple[np.ndarray, np.ndarray]:
    """The native coordinates of the sample columns and rows under ``(sx, ox, sy, oy)``."""
    sx, ox, sy, oy = affine
    if affine == IDENTITY:
        return xs.copy(), ys.copy()
    return ox + sx * xs, oy + sy * ys


def uniform_step(v: np.ndarray) -> float | None:
    """The step of an evenly spaced axis, or None (fewer than 2 values, or uneven).

    Evenly spaced means every step within :data:`~terrainvis.tolerances.UNIFORM_STEP_REL`
    of the mean step, or within the rounding of the coordinates themselves
    (:data:`~terrainvis.tolerances.ROUNDING_ULPS` of the largest): ``origin + step *
    arange(n)`` far from 0 is uneven by a few ulps of the largest coordinate (at 5e5
    with a 0.05 step that is 1e-10, above 1e-9 of the step), and is still the uniform
    grid it was built as. The one uniform-axis test (``HeightGrid.is_uniform`` uses it).
    """
    if v.size < 2:
        return None
    d = np.diff(v)
    step = (v[-1] - v[0]) / (v.size - 1)
    tol = UNIFORM_STEP_REL * abs(step) + ROUNDING_ULPS * np.finfo(np.float64).eps * float(np.abs(v).max())
    return float(step) if np.abs(d - step).max() <= tol else None


def lonlat_to_local(lon: np.ndarray, lat: np.ndarray, *, dlon: float | None = None, dlat: float | None = None):
    """Local metres for increasing lon/lat sample coordinates.

    The spacing is converted with WGS84 metres per degree at the centre latitude and
    the first sample becomes (0, 0). A uniform axis (or one given its step ``dlon`` /
    ``dlat``) gets ``index * step * metres_per_degree`` exactly, as the uniform
    :class:`~terrainvis.HeightGrid` constructor would.

    Returns
    -------
    xs : (cols,) float64
    ys : (rows,) float64
    affine : (sx, ox, sy, oy)
        The ``xy_to_native`` map back to lon/lat.
    """
    lat_c = 0.5 * (float(lat[0]) + float(lat[-1]))
    m_lon, m_lat = metres_per_degree(lat_c)

    def axis(v, step, m):
        step = uniform_step(v) if step is None else step
        if step is not None:
            return np.arange(v.size, dtype=np.float64) * (step * m)
        return (v - v[0]) * m

    xs = axis(np.asarray(lon, dtype=np.float64), dlon, m_lon)
    ys = axis(np.asarray(lat, dtype=np.float64), dlat, m_lat)
    return xs, ys, (1.0 / m_lon, float(lon[0]), 1.0 / m_lat, float(lat[0]))


def looks_like_degrees(xs: np.ndarray, ys: np.ndarray) -> bool:
    """True when coordinates fit lon/lat ranges with cells of at most one arc-minute.

    Projected coordinates of real DEMs are metres or feet with cells of at least a few
    centimetres and usually large offsets; lon/lat DEMs have cells of 1 to 30 arc-seconds.
    """
    if xs.size < 2 or ys.size < 2:
        return False
    in_range = xs[0] >= -180.0 and xs[-1] <= 360.0 and ys[0] >= -90.0 and ys[-1] <= 90.0
    cell = max(float(np.diff(xs).max()), float(np.diff(ys).max()))
    return bool(in_range and cell <= 1.0 / 60.0 + DEGREE_CELL_SLACK)


def warn_if_degrees(xs: np.ndarray, ys: np.ndarray, source: str, stacklevel: int = 4, *,
                    named: bool = False, fix: str = "load_dem") -> None:
    """A UserWarning when coordinates without a CRS look like lon/lat degrees.

    ``named`` says that the coordinates are *called* lon/lat (xarray dims ``lon``/``lat``):
    then any coordinates within lon/lat ranges warn, whatever their cell size. ``fix``
    names the function whose ``crs=`` converts them.
    """
    if xs.size < 2 or ys.size < 2:
        return
    in_range = xs[0] >= -180.0 and xs[-1] <= 360.0 and ys[0] >= -90.0 and ys[-1] <= 90.0
    if looks_like_degrees(xs, ys) or (named and in_range):
        cell = max(float(np.diff(xs).max()), float(np.diff(ys).max()))
        why = "are named lon/lat" if named else "look like lon/lat degrees"
        warnings.warn(
            f"{source} records no CRS, but its coordinates {why} (x in "
            f"[{xs[0]:.6g}, {xs[-1]:.6g}], y in [{ys[0]:.6g}, {ys[-1]:.6g}], cells of {cell:.3g}); they are "
            f"read as metres, which makes slopes and line of sight wrong. Pass crs='EPSG:4326' to {fix} "
            "to convert them to metres.",
            UserWarning,
            stacklevel=stacklevel,
        )


# ---------------------------------------------------------------------- positions
def position_crs(attrs: dict) -> str | None:
    """The CRS positions are given in by default: ``source_crs`` when present, else ``crs`` (None: not recorded)."""
    text = attrs.get("source_crs") or attrs.get("crs") or None
    return text if isinstance(text, str) else None


def _positions(xy, name: str) -> np.ndarray:
    """``xy`` as a new float64 array whose last axis holds x, y (and anything after them, e.g. z)."""
    try:
        arr = np.array(xy, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be numeric array-like positions (x, y), got {type(xy).__name__} {xy!r:.60}") from None
    if arr.ndim == 0 or arr.shape[-1] < 2:
        raise ValueError(
            f"{name} must hold positions along its last axis: shape (2,), (n, 2) or (n, 3) with x, y first, "
            f"got shape {arr.shape}"
        )
    return arr


def transform_xy(src: str, dst: str, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` from the CRS ``src`` to ``dst`` with rasterio (PROJ); non-finite values stay NaN."""
    rasterio_module("moving positions between CRSs")
    from rasterio.warp import transform

    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    ox = np.full(x.shape, np.nan)
    oy = np.full(y.shape, np.nan)
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.any():
        a = parse_crs(src, "source CRS")
        b = parse_crs(dst, "destination CRS")
        try:
            tx, ty = transform(a, b, x[ok], y[ok])
        except Exception as exc:  # PROJ: a point outside the projection's domain (e.g. latitude 95)
            raise ValueError(f"positions could not be moved from {src!r} to {dst!r}: {exc}") from None
        ox[ok] = tx
        oy[ok] = ty
    return ox, oy


def _affine_or_raise(attrs: dict):
    affine = xy_to_native(attrs)
    if affine is None:
        raise ValueError("the terrain's attrs say it is geographic but hold no 'xy_to_native': its lon/lat are unknown")
    return affine


def from_native(attrs: dict, xy, name: str = "xy", extent=None) -> np.ndarray:
    """Positions in the native CRS (:func:`position_crs`) moved to the terrain's own frame.

    Parameters
    ----------
    attrs : dict
        The terrain's ``attrs`` (its georeferencing; none: the identity).
    xy : array_like, shape (2,), (n, 2) or (n, k >= 2)
        x, y first along the last axis (lon, lat in degrees on a geographic terrain);
        further columns (a height z) are copied unchanged. NaN stays NaN.
    extent : (xmin, xmax, ymin, ymax), optional
        The terrain's footprint in its own frame. A position the conversion's rounding
        puts just outside it (by at most ``EDGE_SNAP_REL`` of its span plus a few float64 steps)
        is put on its edge, so that the lon/lat of an edge sample lands on that sample.

    Returns
    -------
    ndarray, float64, the shape of ``xy``
        A new array; on a projected terrain (or one without a CRS) a copy of ``xy``.
    """
    arr = _positions(xy, name)
    out = arr.copy()
    x, y = arr[..., 0], arr[..., 1]
    source = attrs.get("source_crs")
    if source:
        x, y = transform_xy(source, attrs["crs"], x, y)
    affine = _affine_or_raise(attrs)
    if affine != IDENTITY:
        sx, ox, sy, oy = affine
        x = (x - ox) / sx
        y = (y - oy) / sy
    if extent is not None:
        xmin, xmax, ymin, ymax = (float(v) for v in extent)
        x = _onto_edges(x, xmin, xmax)
        y = _onto_edges(y, ymin, ymax)
    out[..., 0] = x
    out[..., 1] = y
    return out


def _onto_edges(v: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``v`` with the values within rounding outside ``[lo, hi]`` put on ``lo`` or ``hi``."""
    tol = EDGE_SNAP_REL * (hi - lo) + ROUNDING_ULPS * np.spacing(max(abs(lo), abs(hi)))
    v = np.array(v, dtype=np.float64, copy=True)
    v[(v < lo) & (v >= lo - tol)] = lo
    v[(v > hi) & (v <= hi + tol)] = hi
    return v


def to_native(attrs: dict, xy, name: str = "xy") -> np.ndarray:
    """Positions in the terrain's own frame moved to the native CRS: the inverse of :func:`from_native`."""
    arr = _positions(xy, name)
    out = arr.copy()
    x, y = arr[..., 0], arr[..., 1]
    affine = _affine_or_raise(attrs)
    if affine != IDENTITY:
        sx, ox, sy, oy = affine
        x = ox + sx * x
        y = oy + sy * y
    source = attrs.get("source_crs")
    if source:
        x, y = transform_xy(attrs["crs"], source, x, y)
    out[..., 0] = x
    out[..., 1] = y
    return out


def local_frame_error(attrs: dict, ys: np.ndarray) -> tuple[float, float] | None:
    """How far east-west lengths of a lon/lat grid's local frame are off at its southern and northern rows.

    The local frame uses one east-west scale (WGS84 metres per degree of longitude at
    the centre latitude of the grid as read, ``1 / sx``) for every row; the true scale at
    latitude phi is ``metres_per_degree(phi)[0]``. Returns the relative errors
    ``scale / true - 1`` at the first and last row (negative: too short), or None when
    the grid is not geographic (or its map to lon/lat is unknown).

    Examples
    --------
    >>> from terrainvis.core._georef import lonlat_to_local
    >>> xs, ys, affine = lonlat_to_local(np.linspace(0, 1, 11), np.linspace(44.5, 45.5, 11))
    >>> [round(100 * e, 3) for e in local_frame_error({"geographic": True, "xy_to_native": affine}, ys)]
    [-0.858, 0.881]
    """
    if not attrs.get("geographic") or attrs.get("source_crs"):
        return None
    affine = xy_to_native(attrs)
    if affine is None or len(ys) == 0:
        return None
    sx, _, sy, oy = affine
    errors = []
    for y in (float(ys[0]), float(ys[-1])):
        true = metres_per_degree(oy + sy * y)[0]
        errors.append((1.0 / sx) / true - 1.0)
    return errors[0], errors[1]
