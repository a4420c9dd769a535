"""The two terrain models everything else works on: :class:`HeightGrid` and :class:`TIN`.

The surface of a grid
---------------------
A :class:`HeightGrid` stands for one piecewise-linear surface. Each cell, between
rows r, r+1 and columns c, c+1, is split along the diagonal from vertex (r, c) to
vertex (r+1, c+1) into two triangles:

* the *lower* triangle (r, c), (r, c+1), (r+1, c+1), where u >= v, and
* the *upper* triangle (r, c), (r+1, c+1), (r+1, c), where v > u,

with u = (x - xs[c]) / (xs[c+1] - xs[c]) and v = (y - ys[r]) / (ys[r+1] - ys[r]) the
local coordinates in the cell. :meth:`HeightGrid.height_at`, :meth:`HeightGrid.to_tin`,
the grid line-of-sight engine and every simplifier use this one surface, so a grid and
its TIN are the same surface and line of sight on them agrees.

Rows and north
--------------
``z[r, c]`` sits at ``(xs[c], ys[r])`` and both coordinate vectors increase, so row 0 is
the *smallest* y. A north-up raster (row 0 is north) is therefore flipped by
:func:`terrainvis.load_dem` (and :meth:`HeightGrid.from_xarray` flips a descending ``y``):
raster row ``i`` becomes grid row ``rows - 1 - i`` and y grows northwards. The
:class:`HeightGrid` constructors themselves never flip anything, and the terrainvis
``.npz`` format stores this order and says so (``orientation = "y_increasing"``; see
:mod:`terrainvis.io`).

Metadata
--------
``attrs`` is a plain dict carried over by :meth:`HeightGrid.crop`,
:meth:`HeightGrid.subsample`, :meth:`HeightGrid.fill_nodata` and the regular
simplifiers. Georeferencing lives there (``crs``, ``geographic``, ``xy_to_native``: see
:mod:`terrainvis.core._georef`), and it stays valid through all of these because it maps
coordinates rather than describing one raster.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np

from ._georef import uniform_step
from .interrupt import call
from .validate import as_float_array, as_int, as_points, as_positive_finite, describe
from ..errors import NodataError
from ..tolerances import BARYCENTRIC_SLACK, DIVISOR_FLOOR, FOOTPRINT_REL

__all__ = ["HeightGrid", "TIN", "as_terrain"]


def _kn():
    """This module's numba kernels (:mod:`terrainvis.core._kernels`), imported on first use:
    numba takes about 0.2 s to import, and reading, describing or writing a terrain needs none of it."""
    from . import _kernels

    return _kernels


def _surface():
    """:mod:`terrainvis.core.surface` (numba's records of a surface), imported on first use, as :func:`_kn`."""
    from . import surface

    return surface


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.flags.writeable = False
    return arr


def _check_coords(values, name: str, length: int) -> np.ndarray:
    arr = as_float_array(values, name)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array of length {length}, got {arr.ndim}-D with shape {arr.shape}")
    if arr.shape[0] != length:
        raise ValueError(f"{name} must have length {length} to match z, got length {arr.shape[0]}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite, got {int((~np.isfinite(arr)).sum())} non-finite value(s)")
    steps = np.diff(arr)
    if (steps <= 0).any():
        i = int(np.flatnonzero(steps <= 0)[0])
        raise ValueError(
            f"{name} must be strictly increasing, but {name}[{i + 1}] = {arr[i + 1]!r} "
            f"is not greater than {name}[{i}] = {arr[i]!r}"
        )
    return np.array(arr, dtype=np.float64, copy=True)


def _check_z(z, owned: bool = False) -> np.ndarray:
    """``z`` checked, as a fresh C-contiguous float64 array (``owned``: a reader's own fresh
    float64 or float32 buffer, which nobody else holds, is kept instead of copied; a float32
    one stays float32, :attr:`HeightGrid.heights`)."""
    if owned and isinstance(z, np.ndarray) and z.dtype in (np.float64, np.float32) and z.ndim == 2 \
            and z.flags.c_contiguous and z.flags.writeable and z.flags.owndata:
        if z.shape[0] < 2 or z.shape[1] < 2:
            raise ValueError(f"z must have at least 2x2 samples, got shape {z.shape}")
        return z  # an infinite height shows in its range (_check_heights): no pass and no mask of its own
    if np.ma.isMaskedArray(z):
        # Masked samples are nodata, so NaN (np.asarray would expose the values under the mask).
        arr = as_float_array(np.ma.getdata(z), "z")
        mask = np.ma.getmaskarray(z)
        if mask.any():
            arr = np.where(mask, np.nan, arr)
    else:
        arr = as_float_array(z, "z")
    if arr.ndim != 2:
        raise ValueError(f"z must be a 2-D array (rows, cols), got {arr.ndim}-D with shape {arr.shape}")
    if arr.shape[0] < 2 or arr.shape[1] < 2:
        raise ValueError(f"z must have at least 2x2 samples, got shape {arr.shape}")
    if np.isinf(arr).any():
        raise ValueError(
            f"z must hold finite heights or NaN for nodata, got {int(np.isinf(arr).sum())} infinite value(s)"
        )
    return np.array(arr, dtype=np.float64, order="C", copy=True)


#: The largest |height| a terrain may hold (z units). Beyond it a value is no elevation in
#: any unit a DEM uses (1e15 mm is a billion kilometres), and float64 arithmetic on it
#: (the squares of least squares, areas, thresholds) overflows or loses every digit of
#: the relief.
MAX_HEIGHT = 1e15


def _height_range(z: np.ndarray) -> tuple[float, float] | None:
    """``(lowest, highest)`` height of ``z`` (NaN ignored), None when none is finite.

    One pass each of ``fmin``/``fmax``, which skip NaN without copying ``z`` (masking the
    finite values first would copy the grid).
    """
    flat = z.reshape(-1)
    if flat.size == 0:
        return None
    lo, hi = float(np.fmin.reduce(flat)), float(np.fmax.reduce(flat))
    return None if np.isnan(lo) else (lo, hi)


def _check_heights(z: np.ndarray, name: str) -> tuple[float, float] | None:
    """``z``'s height range (:func:`_height_range`), or ValueError when a height is infinite or
    beyond ``MAX_HEIGHT``."""
    zr = _height_range(z)
    if zr is not None and not (np.isfinite(zr[0]) and np.isfinite(zr[1])):
        raise ValueError(f"{name} must hold finite heights or NaN for nodata, got {int(np.isinf(z).sum())} infinite "
                         "value(s)")
    if zr is not None and max(-zr[0], zr[1]) > MAX_HEIGHT:
        worst = zr[0] if -zr[0] > zr[1] else zr[1]
        raise ValueError(f"{name} holds a height of {worst:.6g}, beyond +-{MAX_HEIGHT:g} (z units): no DEM's elevation, "
                         "and float64 arithmetic on it loses the relief; check the file's scale and nodata value")
    return zr


def height_range(terrain) -> tuple[float, float] | None:
    """``(lowest, highest)`` height of a HeightGrid (NaN ignored) or of a TIN's vertices; None when
    the grid holds no finite height. Computed when the terrain is made (it checks every height
    then), so asking costs nothing."""
    if "z_range" not in terrain._cache:
        z = terrain.z if isinstance(terrain, HeightGrid) else terrain.vertices[:, 2]
        terrain._cache["z_range"] = _height_range(z)
    return terrain._cache["z_range"]


def fingerprint(grid) -> str:
    """A content hash of a HeightGrid: 16 hex digits of the SHA-256 of its heights and
    coordinates, computed once per grid (its arrays are read-only). A results file records
    it so that a resume notices a changed terrain; the caches of work on T kept across the
    units of a comparison are keyed by it."""
    fp = grid._cache.get("fingerprint")
    if fp is None:
        h = hashlib.sha256()
        for a in (grid.z, grid.xs, grid.ys):
            h.update(np.ascontiguousarray(a).tobytes())
        fp = grid._cache["fingerprint"] = h.hexdigest()[:16]
    return fp


def _as_attrs(attrs) -> dict:
    if attrs is None:
        return {}
    if not isinstance(attrs, dict):
        raise TypeError(f"attrs must be a dict (name -> value) or None, got {describe(attrs)}")
    return dict(attrs)


class HeightGrid:
    """A rectilinear height grid and the piecewise-linear surface over it.

    ``z[r, c]`` is the height at ``(xs[c], ys[r])``. Each cell is split along the
    diagonal from vertex (r, c) to vertex (r+1, c+1); this is the surface used by every
    part of terrainvis (see the module docstring). NaN marks nodata.

    Parameters
    ----------
    z : (rows, cols) array_like
        Heights, copied to a read-only float64 array. Never flipped. NaN marks nodata,
        and so does the mask of a :class:`numpy.ma.MaskedArray`.
    dx, dy : float
        Uniform sample spacing along x (columns) and y (rows).
    origin : (float, float)
        Coordinates ``(xs[0], ys[0])`` of sample ``z[0, 0]``.

    Examples
    --------
    >>> g = HeightGrid([[0.0, 1.0], [2.0, 3.0]], dx=10.0, dy=10.0)
    >>> g.shape, g.extent
    ((2, 2), (0.0, 10.0, 0.0, 10.0))
    >>> float(g.height_at([[10.0, 0.0]])[0])
    1.0
    """

    __slots__ = ("_z", "xs", "ys", "attrs", "_cache", "__weakref__")

    def __init__(self, z, dx: float = 1.0, dy: float = 1.0, origin=(0.0, 0.0), *, attrs=None):
        zz = _check_z(z)
        dx = as_positive_finite(dx, "dx")
        dy = as_positive_finite(dy, "dy")
        try:
            ox, oy = (float(v) for v in origin)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"origin must be a pair of numbers (x0, y0), got {describe(origin)}") from exc
        if not (math.isfinite(ox) and math.isfinite(oy)):
            raise ValueError(f"origin must be finite, got {origin!r}")
        rows, cols = zz.shape
        with np.errstate(over="ignore"):  # an overflow is refused just below, with its own message
            xs = ox + dx * np.arange(cols, dtype=np.float64)
            ys = oy + dy * np.arange(rows, dtype=np.float64)
        for name, v, o, d in (("x", xs, ox, dx), ("y", ys, oy, dy)):
            if not np.isfinite(v[-1]):
                raise ValueError(f"origin {name}0 = {o!r} plus d{name} = {d!r} times {v.size - 1} overflows float64")
            if (np.diff(v) <= 0).any():
                raise ValueError(
                    f"d{name} = {d!r} is too small for origin {name}0 = {o!r}: float64 numbers near "
                    f"{abs(v[-1]):.3g} are {np.spacing(abs(v[-1])):.3g} apart, so the {name} coordinates would not "
                    "be strictly increasing; use a larger spacing or an origin nearer 0"
                )
        self._init(zz, xs, ys, attrs)

    @classmethod
    def from_coords(cls, z, xs, ys, *, attrs=None) -> "HeightGrid":
        """A rectilinear grid: ``z[r, c]`` at ``(xs[c], ys[r])``, xs and ys strictly increasing."""
        return cls._from_coords(z, xs, ys, attrs, owned=False)

    @classmethod
    def _from_coords(cls, z, xs, ys, attrs, *, owned: bool) -> "HeightGrid":
        """:meth:`from_coords`; ``owned``: ``z`` is a reader's fresh float64 buffer, adopted without a copy
        (a 3601² DEM: 100 MB less to copy, and as much less memory at the peak)."""
        zz = _check_z(z, owned)
        rows, cols = zz.shape
        xx = _check_coords(xs, "xs", cols)
        yy = _check_coords(ys, "ys", rows)
        obj = cls.__new__(cls)
        obj._init(zz, xx, yy, attrs)
        return obj

    @classmethod
    def from_xarray(cls, da, *, x=None, y=None, crs=None) -> "HeightGrid":
        """A grid from a 2-D :class:`xarray.DataArray` (needs xarray; rioxarray is used when installed).

        Parameters
        ----------
        da : xarray.DataArray, dims (y, x) in either order
            Heights with 1-D coordinates on both dims. The dims are found by name
            (``x``/``lon``/``longitude``/``easting`` and ``y``/``lat``/``latitude``/
            ``northing``) unless ``x`` and ``y`` name them. A descending coordinate (the
            usual raster order, y from north to south) is flipped into the HeightGrid
            order. A length-1 ``band`` dim (``rioxarray.open_rasterio``) is dropped. A
            dask-backed array is computed.
        x, y : str, optional
            The names of the x and y dims.
        crs : str, optional
            The CRS when ``da`` records none (``da.rio.crs``, ``da.attrs["crs"]`` or a
            ``spatial_ref`` coordinate). A lon/lat CRS converts the coordinates to local
            metres, as :func:`terrainvis.load_dem` does.

        Returns
        -------
        HeightGrid
            ``attrs`` are ``da.attrs`` (without ``_FillValue``/``nodata``/``missing_value``,
            which mark nodata, and ``scale_factor``/``add_offset``, which are applied) plus
            the georeferencing (``crs``, ``geographic``, ``xy_to_native``) when the CRS is
            known.

        Examples
        --------
        >>> import xarray as xr
        >>> da = xr.DataArray([[3.0, 4.0], [1.0, 2.0]], dims=("y", "x"), coords={"y": [10.0, 0.0], "x": [0.0, 10.0]})
        >>> HeightGrid.from_xarray(da).z.tolist()  # y ascending now: row 0 is y = 0
        [[1.0, 2.0], [3.0, 4.0]]
        """
        from .dataarray import dataarray_parts

        z, xs, ys, attrs = dataarray_parts(da, x=x, y=y, crs=crs)
        return cls.from_coords(z, xs, ys, attrs=attrs)

    def to_xarray(self, *, name: str = "z"):
        """This grid as an :class:`xarray.DataArray` with dims ``("y", "x")`` (needs xarray).

        The coordinates are ``xs`` and ``ys`` (increasing: row 0 is the smallest y),
        ``attrs`` a copy of :attr:`attrs`. When rioxarray is installed and the grid is
        projected (its coordinates are in its CRS), the CRS is also written with
        ``da.rio.write_crs``; a lon/lat grid's coordinates are local metres, so its CRS
        stays in ``attrs`` only (with ``xy_to_native``). ``HeightGrid.from_xarray`` reads
        the result back unchanged.

        Examples
        --------
        >>> g = HeightGrid([[1.0, 2.0], [3.0, 4.0]], dx=10.0, dy=10.0)
        >>> da = g.to_xarray()
        >>> da.dims, da.y.values.tolist()
        (('y', 'x'), [0.0, 10.0])
        """
        from .dataarray import grid_to_dataarray

        return grid_to_dataarray(self, name=name)

    def _init(self, z, xs, ys, attrs):
        zr = _check_heights(z, "z")
        self._z = _frozen(z)
        self.xs = _frozen(xs)
        self.ys = _frozen(ys)
        self.attrs = _as_attrs(attrs)
        self._cache = {"z_range": zr}

    def __reduce__(self):
        # Pickle the data only: cached acceleration structures (pyramid, Embree scene,
        # TIN) are rebuilt on demand in the receiving process. Heights kept as float32
        # travel as float32.
        return (_rebuild_grid, (self._z, self.xs, self.ys, self.attrs))

    # ------------------------------------------------------------------ basics
    @property
    def z(self) -> np.ndarray:
        """(rows, cols) read-only float64 heights; NaN marks nodata.

        A grid read from a float32 raster keeps the file's float32 samples
        (:attr:`heights`) until something asks for ``z``: the float64 array is then made
        once (every float32 value is a float64 value, so nothing changes) and replaces
        them.
        """
        z = self._z
        if z.dtype != np.float64:
            from .memory import fresh_array

            # a raster-sized buffer without numpy's huge-page advice, as the reader's (its first touch
            # stalled in the kernel's compaction now and then: a 3601² simplify command 0.2 s slower)
            wide = fresh_array(z.shape, np.float64)
            np.copyto(wide, z)
            z = self._z = _frozen(wide)
        return z

    @property
    def heights(self) -> np.ndarray:
        """The heights as the grid holds them: :attr:`z`, or a float32 raster's own samples
        (read-only float32, equal to ``z`` value for value) until ``z`` is first asked for.

        The viewshed reads these (its kernels convert each height to float64 as they read
        it, so its verdicts are those of ``z``): a float32 DEM's viewshed holds 4 bytes a
        sample of heights instead of 8.
        """
        return self._z

    @property
    def shape(self) -> tuple[int, int]:
        return self._z.shape

    @property
    def size(self) -> int:
        """Number of samples."""
        return int(self._z.size)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` of the footprint."""
        return (float(self.xs[0]), float(self.xs[-1]), float(self.ys[0]), float(self.ys[-1]))

    @property
    def nbytes(self) -> int:
        """Bytes held by the heights (:attr:`heights`) and the two coordinate vectors."""
        return int(self._z.nbytes + self.xs.nbytes + self.ys.nbytes)

    @property
    def is_uniform(self) -> bool:
        """True when both coordinate vectors are evenly spaced (to 1e-9 relative)."""
        return _is_uniform(self.xs) and _is_uniform(self.ys)

    @property
    def dx(self) -> float:
        """Mean spacing along x (the spacing itself on a uniform grid)."""
        return float((self.xs[-1] - self.xs[0]) / (self.xs.size - 1))

    @property
    def dy(self) -> float:
        """Mean spacing along y (the spacing itself on a uniform grid)."""
        return float((self.ys[-1] - self.ys[0]) / (self.ys.size - 1))

    @property
    def n_nodata(self) -> int:
        """Number of NaN (nodata) samples."""
        if "n_nodata" not in self._cache:
            self._cache["n_nodata"] = int(np.isnan(self._z).sum())
        return self._cache["n_nodata"]

    def require_finite(self, operation: str) -> None:
        """Raise :class:`~terrainvis.errors.NodataError` when z holds NaN."""
        if self.n_nodata:
            raise NodataError(operation, self.n_nodata, self.shape)

    def __repr__(self) -> str:
        xmin, xmax, ymin, ymax = self.extent
        kind = "uniform" if self.is_uniform else "rectilinear"
        return (
            f"HeightGrid({self.shape[0]}x{self.shape[1]} {kind}, x [{xmin:g}, {xmax:g}], "
            f"y [{ymin:g}, {ymax:g}], z [{np.nanmin(self._z):g}, {np.nanmax(self._z):g}]"
            + (f", {self.n_nodata} nodata" if self.n_nodata else "")
            + ")"
        )

    def copy_with(self, z=None, *, xs=None, ys=None) -> "HeightGrid":
        """A new grid with some arrays replaced (the attrs are carried over)."""
        return HeightGrid.from_coords(
            self.z if z is None else z,
            self.xs if xs is None else xs,
            self.ys if ys is None else ys,
            attrs=self.attrs,
        )

    # ------------------------------------------------------------- positions
    def from_native(self, xy) -> np.ndarray:
        """Positions in the DEM's native CRS, moved to this grid's own frame (that of ``xs``, ``ys``).

        Every function of terrainvis takes positions in the grid's own frame. On a
        projected DEM (UTM, ...) that is its CRS already and this is a copy. On a lon/lat
        DEM the frame is local metres: this takes lon, lat in degrees, as GDAL and GRASS
        do. On a grid resampled by :func:`terrainvis.io.to_metric` it takes positions in
        the lon/lat CRS it was resampled from. See :mod:`terrainvis.core._georef`. A position
        that the conversion's rounding puts just outside the grid (by at most ``1e-9`` of
        its extent) is put on its edge: the lon/lat of an edge sample lands on it.

        Parameters
        ----------
        xy : array_like, shape (2,), (n, 2) or (n, k >= 2)
            x, y (lon, lat) first along the last axis; further columns (a height z) are
            copied unchanged, so ``grid.from_native(points_xyz)`` works too. NaN stays NaN.

        Returns
        -------
        ndarray, float64, the shape of ``xy``

        Raises
        ------
        ValueError
            When the attrs say the grid is geographic but hold no map back to lon/lat.

        Examples
        --------
        >>> g = HeightGrid(np.zeros((3, 3)), dx=500.0, dy=1000.0,
        ...                attrs={"crs": "EPSG:4326", "geographic": True, "xy_to_native": (0.001, -72.8, 0.001, 44.1)})
        >>> g.from_native([-72.3, 45.1]).round(6).tolist()
        [500.0, 1000.0]
        >>> g.to_native([[500.0, 1000.0, 7.0]]).round(6).tolist()
        [[-72.3, 45.1, 7.0]]
        """
        from ._georef import from_native

        return from_native(self.attrs, xy, extent=self.extent)

    def to_native(self, xy) -> np.ndarray:
        """Positions in this grid's own frame, moved to the native CRS: the inverse of :meth:`from_native`."""
        from ._georef import to_native

        return to_native(self.attrs, xy)

    # ---------------------------------------------------------------- surface
    def height_at(self, xy) -> np.ndarray:
        """Height of the surface at each point.

        Parameters
        ----------
        xy : (m, 2) array_like
            World coordinates.

        Returns
        -------
        (m,) float64
            The piecewise-linear surface (cells split along the (r, c)-(r+1, c+1)
            diagonal), NaN outside the extent or where a vertex of the triangle under
            the point is nodata (the same triangles that :meth:`to_tin` leaves out).
        """
        pts = as_points(xy, "xy", 2)
        out = np.full(pts.shape[0], np.nan)
        if pts.shape[0] == 0:
            return out
        call(_surface().heights_at, self._z, self.xs, self.ys,
             np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), out, work=out.size)
        return out

    def height_on_grid(self, xs, ys) -> np.ndarray:
        """Heights at every node of another rectilinear grid, shape (len(ys), len(xs)).

        The same surface as :meth:`height_at` (NaN outside the extent), evaluated without
        building the (len(ys) * len(xs), 2) array of query points.
        """
        qx = np.ascontiguousarray(as_float_array(xs, "xs").ravel())
        qy = np.ascontiguousarray(as_float_array(ys, "ys").ravel())
        out = np.full((qy.size, qx.size), np.nan)
        call(_kn().grid_on_grid, self.xs, self.ys, self._z, qx, qy, out, work=out.size)
        return out

    def sample_xy(self) -> np.ndarray:
        """(rows*cols, 2) coordinates of every sample in row-major order."""
        X, Y = np.meshgrid(self.xs, self.ys)
        return np.column_stack([X.ravel(), Y.ravel()])

    def to_tin(self) -> "TIN":
        """The TIN of exactly this surface.

        One vertex per sample (index ``r * cols + c``), two triangles per cell split
        along the (r, c)-(r+1, c+1) diagonal, counter-clockwise so normals point up.
        On a grid with nodata, the nodata vertices and the triangles touching them are
        left out (and the remaining vertices keep their row-major order). The result is
        cached on the grid.
        """
        tin = self._cache.get("tin")
        if tin is not None:
            return tin
        rows, cols = self.shape
        X, Y = np.meshgrid(self.xs, self.ys)
        vertices = np.column_stack([X.ravel(), Y.ravel(), self.z.ravel()])
        idx = np.arange(rows * cols, dtype=np.int64).reshape(rows, cols)
        a = idx[:-1, :-1]
        b = idx[:-1, 1:]
        c = idx[1:, 1:]
        d = idx[1:, :-1]
        lower = np.stack([a, b, c], axis=-1).reshape(-1, 3)
        upper = np.stack([a, c, d], axis=-1).reshape(-1, 3)
        faces = np.stack([lower, upper], axis=1).reshape(-1, 3)
        if self.n_nodata:
            # Drop the triangles touching nodata, then the nodata vertices (re-indexed).
            finite = np.isfinite(vertices[:, 2])
            faces = faces[finite[faces].all(axis=1)]
            new_index = np.cumsum(finite) - 1
            vertices = vertices[finite]
            faces = new_index[faces]
        dtype = np.int32 if vertices.shape[0] < 2**31 - 1 else np.int64
        tin = TIN(vertices, faces.astype(dtype), attrs={"source": "HeightGrid.to_tin", "grid_shape": self.shape})
        self._cache["tin"] = tin
        return tin

    # ---------------------------------------------------------------- nodata
    def valid_window(self, size=None) -> tuple[slice, slice]:
        """``(rows, cols)`` slices of the largest axis-aligned window without nodata.

        Parameters
        ----------
        size : int or (int, int), optional
            At most this many rows and columns (one int: both; each >= 2): the window of
            that size at the middle of the largest one (the whole of it along an axis
            where it is smaller; an odd remainder leaves the extra sample at the end).
            None: the largest window itself.

        Examples
        --------
        >>> z = np.zeros((6, 7))
        >>> z[0, 0] = np.nan
        >>> HeightGrid(z).valid_window()
        (slice(0, 6, None), slice(1, 7, None))
        >>> HeightGrid(z).valid_window(size=(2, 4))
        (slice(2, 4, None), slice(2, 6, None))
        """
        limit = None if size is None else _window_size(size)
        if not self.n_nodata:
            r0, r1, c0, c1 = 0, self.shape[0], 0, self.shape[1]
        else:
            r0, r1, c0, c1 = call(_kn().largest_valid_rectangle, np.isfinite(self.z), work=self.size)
            if r1 - r0 < 2 or c1 - c0 < 2:
                raise ValueError(f"z has no NaN-free window of at least 2x2 samples ({self.n_nodata} NaN cells)")
        if limit is not None:
            r0, r1 = _middle(int(r0), int(r1), limit[0])
            c0, c1 = _middle(int(c0), int(c1), limit[1])
        return slice(int(r0), int(r1)), slice(int(c0), int(c1))

    def crop(self, rows=None, cols=None, *, bbox=None) -> "HeightGrid":
        """A sub-grid.

        Parameters
        ----------
        rows, cols : slice or (start, stop), optional
            Index ranges to keep (step 1), with Python's rules: ``None`` for an open
            end, negative indices count from the end (``rows=(-10, None)`` keeps the last
            10 rows). ``None`` keeps everything.
        bbox : (xmin, xmax, ymin, ymax), optional
            Keep the samples inside this box instead (inclusive).

        Examples
        --------
        >>> g = HeightGrid(np.arange(16.0).reshape(4, 4))
        >>> g.crop(rows=(1, 3), cols=slice(0, 2)).shape
        (2, 2)
        """
        if bbox is not None:
            if rows is not None or cols is not None:
                raise TypeError("crop takes either rows/cols or bbox, not both")
            try:
                xmin, xmax, ymin, ymax = (float(v) for v in bbox)
            except (TypeError, ValueError) as exc:
                raise TypeError(f"bbox must be (xmin, xmax, ymin, ymax), got {describe(bbox)}") from exc
            cmask = np.flatnonzero((self.xs >= xmin) & (self.xs <= xmax))
            rmask = np.flatnonzero((self.ys >= ymin) & (self.ys <= ymax))
            rs = slice(int(rmask[0]), int(rmask[-1]) + 1) if rmask.size else slice(0, 0)
            cs = slice(int(cmask[0]), int(cmask[-1]) + 1) if cmask.size else slice(0, 0)
        else:
            rs = _as_slice(rows, "rows", self.shape[0])
            cs = _as_slice(cols, "cols", self.shape[1])
        z = self.z[rs, cs]
        if z.shape[0] < 2 or z.shape[1] < 2:
            raise ValueError(
                f"crop must keep at least 2x2 samples of the {self.shape[0]}x{self.shape[1]} grid, got "
                f"{z.shape[0]}x{z.shape[1]} (rows {rs.start}:{rs.stop}, cols {cs.start}:{cs.stop})"
            )
        return HeightGrid.from_coords(z, self.xs[cs], self.ys[rs], attrs=self.attrs)

    def subsample(self, step: int) -> "HeightGrid":
        """Every ``step``-th sample along both axes (a cheap way to shrink a large DEM)."""
        step = as_int(step, "step", minimum=1)
        if (self.shape[0] - 1) // step < 1 or (self.shape[1] - 1) // step < 1:
            raise ValueError(f"step must leave at least 2x2 samples of the {self.shape} grid, got {step}")
        return HeightGrid.from_coords(self.z[::step, ::step], self.xs[::step], self.ys[::step], attrs=self.attrs)

    def fill_nodata(self, method: str = "nearest") -> "HeightGrid":
        """A copy with every NaN sample filled.

        Parameters
        ----------
        method : {"nearest", "linear"}
            ``"nearest"`` copies the nearest valid sample (in index space).
            ``"linear"`` interpolates linearly inside the convex hull of the valid samples
            (Delaunay, scipy) and falls back to nearest outside it.
        """
        if method not in ("nearest", "linear"):
            raise ValueError(f"method must be one of ['nearest', 'linear'], got {method!r}")
        if not self.n_nodata:
            return self
        from scipy import ndimage

        nan = np.isnan(self.z)
        if nan.all():
            raise ValueError("z is entirely nodata; there is nothing to fill from")
        z = self.z.copy()
        if method == "linear":
            from scipy.interpolate import griddata

            X, Y = np.meshgrid(self.xs, self.ys)
            z[nan] = griddata((X[~nan], Y[~nan]), self.z[~nan], (X[nan], Y[nan]), method="linear")
        still = np.isnan(z)
        if still.any():
            _, (ri, ci) = ndimage.distance_transform_edt(nan, return_indices=True)
            z[still] = self.z[ri[still], ci[still]]
        return self.copy_with(z)


def _as_slice(value, name: str, length: int) -> slice:
    """``rows``/``cols`` of :meth:`HeightGrid.crop` as a step-1 slice within ``length`` (Python's rules)."""
    if value is None:
        return slice(0, length)
    if isinstance(value, slice):
        if value.step not in (None, 1):
            raise ValueError(f"{name} must have step 1, got step {value.step}; use subsample() to thin a grid")
        start, stop = value.start, value.stop
    else:
        try:
            start, stop = value
        except (TypeError, ValueError):
            raise TypeError(
                f"{name} must be a slice or a (start, stop) pair of integers or None, got {describe(value)}"
            ) from None
    for bound in (start, stop):
        if bound is not None and (isinstance(bound, (bool, np.bool_)) or not isinstance(bound, (int, np.integer))):
            raise TypeError(
                f"{name} bounds must be integers or None (negative counts from the end), got {describe(bound)} "
                f"in {name}={value!r}"
            )
    start, stop, _ = slice(start, stop).indices(length)
    return slice(start, max(start, stop))


def _is_uniform(v: np.ndarray) -> bool:
    """Evenly spaced (:func:`terrainvis.core._georef.uniform_step`); fewer than 3 values always are."""
    return v.size < 3 or uniform_step(v) is not None


@dataclass(frozen=True)
class _Buckets:
    starts: np.ndarray
    items: np.ndarray
    x0: float
    y0: float
    bw: float
    bh: float
    nbx: int
    nby: int


class TIN:
    """A triangulated irregular network: a terrain surface made of triangles.

    Parameters
    ----------
    vertices : (n, 3) array_like
        x, y, z of each vertex (copied to read-only float64).
    faces : (m, 3) array_like of int
        Vertex indices of each triangle, counter-clockwise seen from above.
    attrs : dict, optional
        Free-form metadata, as in ``HeightGrid.attrs``. The simplifiers record the
        method, level, vertex count, bytes, errors and timing here.
    """

    __slots__ = ("vertices", "faces", "attrs", "_cache", "__weakref__")

    def __init__(self, vertices, faces, *, attrs=None):
        v = as_float_array(vertices, "vertices")
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"vertices must have shape (n, 3), got {v.shape}")
        if v.shape[0] < 3:
            raise ValueError(f"vertices must hold at least 3 vertices, got {v.shape[0]}")
        if not np.isfinite(v).all():
            raise ValueError(f"vertices must be finite, got {int((~np.isfinite(v)).any(axis=1).sum())} non-finite row(s)")
        zr = _check_heights(v[:, 2], "vertices")
        f = np.asarray(faces)
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"faces must have shape (m, 3), got {f.shape}")
        if f.shape[0] < 1:
            raise ValueError("faces must hold at least one triangle, got 0")
        if not np.issubdtype(f.dtype, np.integer):
            raise TypeError(f"faces must be an integer array, got dtype {f.dtype}")
        if f.min() < 0 or f.max() >= v.shape[0]:
            raise ValueError(f"faces must index vertices in [0, {v.shape[0] - 1}], got range [{f.min()}, {f.max()}]")
        self.vertices = _frozen(np.array(v, dtype=np.float64, order="C", copy=True))
        dtype = np.int32 if v.shape[0] < 2**31 - 1 else np.int64
        self.faces = _frozen(np.array(f, dtype=dtype, order="C", copy=True))
        self.attrs = _as_attrs(attrs)
        self._cache = {"z_range": zr}

    def __reduce__(self):
        return (_rebuild_tin, (self.vertices, self.faces, self.attrs))

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def nbytes(self) -> int:
        """Bytes held by the vertex and face arrays."""
        return int(self.vertices.nbytes + self.faces.nbytes)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` of the vertices."""
        lo = self.vertices[:, :2].min(axis=0)
        hi = self.vertices[:, :2].max(axis=0)
        return (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))

    @property
    def mesh(self):
        """The :class:`trimesh.Trimesh` of this TIN (built once, not processed)."""
        mesh = self._cache.get("mesh")
        if mesh is None:
            import trimesh

            mesh = trimesh.Trimesh(vertices=self.vertices, faces=self.faces, process=False, validate=False)
            self._cache["mesh"] = mesh
        return mesh

    def __repr__(self) -> str:
        xmin, xmax, ymin, ymax = self.extent
        return (
            f"TIN({self.n_vertices} vertices, {self.n_faces} faces, x [{xmin:g}, {xmax:g}], "
            f"y [{ymin:g}, {ymax:g}])"
        )

    # ---------------------------------------------------------------- geometry
    def face_areas(self) -> np.ndarray:
        """(m,) signed projected (x, y) area of each face: > 0 for counter-clockwise faces."""
        from .mesh import signed_area2

        return 0.5 * signed_area2(self.vertices, self.faces)

    def footprint_area(self) -> float:
        """Sum of the signed projected areas of the faces."""
        return float(self.face_areas().sum())

    def is_height_field(self, rtol: float = FOOTPRINT_REL) -> bool:
        """True when every face is counter-clockwise in projection and the footprint area equals
        the extent's (to ``rtol`` of it: :func:`terrainvis.core.mesh.footprint_matches`)."""
        areas = self.face_areas()
        if not (areas > 0).all():
            return False
        xmin, xmax, ymin, ymax = self.extent
        area = (xmax - xmin) * (ymax - ymin)
        from .mesh import footprint_matches

        return footprint_matches(areas.sum(), area, rtol)

    def _buckets(self) -> _Buckets:
        bk = self._cache.get("buckets")
        if bk is None:
            xmin, xmax, ymin, ymax = self.extent
            nf = self.n_faces
            side = max(1, int(math.sqrt(nf / 2.0)))
            w = max(xmax - xmin, DIVISOR_FLOOR)
            h = max(ymax - ymin, DIVISOR_FLOOR)
            nbx = max(1, int(round(side * math.sqrt(w / h))))
            nby = max(1, int(round(side * math.sqrt(h / w))))
            bw = w / nbx
            bh = h / nby
            v = self.vertices
            starts, items = _kn().build_buckets(
                np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1]), self.faces, xmin, ymin, bw, bh, nbx, nby
            )
            bk = _Buckets(starts, items, xmin, ymin, bw, bh, nbx, nby)
            self._cache["buckets"] = bk
        return bk

    def height_at(self, xy) -> np.ndarray:
        """Height of the TIN at each point, NaN outside the footprint.

        Parameters
        ----------
        xy : (m, 2) array_like

        Returns
        -------
        (m,) float64
        """
        pts = as_points(xy, "xy", 2)
        out = np.full(pts.shape[0], np.nan)
        if pts.shape[0] == 0:
            return out
        bk = self._buckets()
        v = self.vertices
        tin = _surface().SurfaceTin(
            np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1]), np.ascontiguousarray(v[:, 2]), self.faces,
            _surface().no_neighbours(), bk.starts, bk.items, bk.x0, bk.y0, bk.bw, bk.bh, bk.nbx, bk.nby,
        )
        call(_kn().locate_heights, tin, np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), out,
             BARYCENTRIC_SLACK, work=pts.shape[0])
        return out

    def from_native(self, xy) -> np.ndarray:
        """Positions in the native CRS of the DEM this TIN came from, moved to its own frame.

        A simplified TIN carries its grid's georeferencing in ``attrs``; this is
        :meth:`HeightGrid.from_native` on them (a copy when there is none).
        """
        from ._georef import from_native

        return from_native(self.attrs, xy, extent=self.extent)

    def to_native(self, xy) -> np.ndarray:
        """Positions in this TIN's own frame, moved to the native CRS: the inverse of :meth:`from_native`."""
        from ._georef import to_native

        return to_native(self.attrs, xy)

    def to_grid(self, like: "HeightGrid") -> "HeightGrid":
        """This TIN's surface sampled at every sample of ``like``: a raster of it (NaN outside the TIN).

        Parameters
        ----------
        like : HeightGrid
            The grid whose coordinates (and georeferencing: ``crs``, ``geographic``,
            ``xy_to_native``) the raster takes, usually the DEM the TIN was simplified
            from. Samples outside the TIN's faces are nodata (NaN).

        Returns
        -------
        HeightGrid
            ``attrs`` are this TIN's, with ``like``'s georeferencing and
            ``sampled_from_tin`` (the TIN's vertex count).

        Examples
        --------
        >>> g = HeightGrid([[0.0, 1.0, 2.0], [1.0, 2.0, 3.0], [2.0, 3.0, 4.0]])
        >>> coarse = TIN([[0, 0, 0], [2, 0, 2], [2, 2, 4], [0, 2, 2]], [[0, 1, 2], [0, 2, 3]])
        >>> coarse.to_grid(g).z.tolist() == g.z.tolist()  # a plane is sampled exactly
        True
        """
        if not isinstance(like, HeightGrid):
            raise TypeError(f"like must be a terrainvis.HeightGrid (the grid to sample on), got {describe(like)}")
        from ._georef import GEOREF_KEYS

        z = self.height_on_grid(like.xs, like.ys)
        attrs = {k: v for k, v in self.attrs.items() if k not in GEOREF_KEYS}
        attrs.update({k: like.attrs[k] for k in GEOREF_KEYS if k in like.attrs}, sampled_from_tin=self.n_vertices)
        return HeightGrid.from_coords(z, like.xs, like.ys, attrs=attrs)

    def height_on_grid(self, xs, ys) -> np.ndarray:
        """Heights at every node of a rectilinear grid, shape (len(ys), len(xs)); NaN outside."""
        xs = np.ascontiguousarray(as_float_array(xs, "xs").ravel())
        ys = np.ascontiguousarray(as_float_array(ys, "ys").ravel())
        out = np.full((ys.size, xs.size), np.nan)
        v = self.vertices
        call(
            _kn().rasterize_tin,
            np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1]), np.ascontiguousarray(v[:, 2]),
            self.faces, xs, ys, out, BARYCENTRIC_SLACK, work=out.size + self.n_faces,
        )
        return out



def _rebuild_grid(z, xs, ys, attrs):
    # the unpickled arrays are this call's own: a float32 one stays float32
    z = np.require(z, requirements=["C", "W", "O"])
    return HeightGrid._from_coords(z, xs, ys, attrs, owned=True)


def _rebuild_tin(vertices, faces, attrs):
    return TIN(vertices, faces, attrs=attrs)


def as_terrain(terrain, name: str = "terrain"):
    """Check that ``terrain`` is a HeightGrid or a TIN."""
    if not isinstance(terrain, (HeightGrid, TIN)):
        raise TypeError(f"{name} must be a terrainvis.HeightGrid or terrainvis.TIN, got {describe(terrain)}")
    return terrain


def _window_size(size) -> tuple[int, int]:
    """``size`` of :meth:`HeightGrid.valid_window` as (rows, cols), checked."""
    pair = (size, size) if np.ndim(size) == 0 else tuple(size)
    if len(pair) != 2:
        raise TypeError(f"size must be an int or (rows, cols), got {describe(size)}")
    return as_int(pair[0], "size", minimum=2), as_int(pair[1], "size", minimum=2)


def _middle(start: int, stop: int, n: int) -> tuple[int, int]:
    """The ``n`` indices (at most) in the middle of ``start:stop``."""
    n = min(n, stop - start)
    first = start + (stop - start - n) // 2
    return first, first + n
