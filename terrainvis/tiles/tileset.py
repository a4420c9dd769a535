"""``write_tileset``: a DEM as a Cesium quantized-mesh tileset, each tile simplified by a registered method.

What the tileset covers
-----------------------
The DEM's valid footprint (where its surface has a height) is mapped to lon/lat (WGS84,
EPSG:4326) with pyproj, and the tileset covers the largest lon/lat-aligned rectangle
inside it (:func:`lonlat_rectangle`): found on a 257 x 257 lattice over the footprint's
bounding box, then each side pushed outwards by bisection while the rectangle's boundary
stays on valid ground. A tile partly outside the rectangle holds its part inside as made
below, extended to the tile's edges at the heights of the rectangle's edge (:func:`_whole_tile`:
Cesium makes a tile the tileset lacks from its parent, and a parent with only its part of the
rectangle left those children empty, which stopped Cesium's renderer); beyond that the globe
has no terrain from this tileset.

How a tile is made
------------------
At zoom ``z`` every tile meeting the rectangle gets a lattice of at most (N + 1) x (N + 1)
points (N = 64 by default, as Cesium's 65 x 65 heightmap tiles) over the tile's part inside
the rectangle. The lattice points sit exactly on the tile's quantized positions (the
integer ``u``, ``v`` of the format, spread as evenly as they allow), so a mesh whose
vertices are lattice points is stored without horizontal rounding. Each point's height is
the DEM's exact piecewise-linear surface there (``HeightGrid.height_at`` at the point moved
to the grid's frame with pyproj). The lattice becomes a HeightGrid in a local metric frame,
equirectangular about the lattice's centre (lon0, lat0): ``x = R cos(lat0) (lon - lon0)
pi / 180``, ``y = R (lat - lat0) pi / 180`` with R = 6378137 m, so the simplifiers see
metres (for a tile inside the rectangle the lattice's centre is the tile's).

From zoom ``zooms[0]`` on, the lattice is simplified with ``method`` to the zoom's budget
``E_z = max_error0 / 2**z`` (default ``max_error0`` 77067 m, the common rule for
quantized-mesh tilesets); a regular method's grid is triangulated (``to_tin``). The tile is
then encoded, decoded again, and its error measured: the largest difference between the
decoded mesh and the lattice's heights at the lattice points. A tile over ``E_z`` plus half
the height quantization step (the method's own error measure, or the rounding of vertices
that are not lattice points, can put it there) is simplified again with the budget lowered
by the excess, up to three times; a tile still over it, or one the method cannot make, or
whose rounded positions would fold a triangle, is written as the whole lattice (counted
as a fallback in ``layer.json``). So every tile is within ``E_z`` of its lattice, plus half
the height quantization step (the header's height range / 32767), at the lattice points.

Below ``zooms[0]`` the tiles are written the way Cesium's heightmap tiles are: the whole
lattice, triangulated, not simplified. Cesium asks for the tiles of zoom 0 first and
descends, so every zoom from 0 to ``zooms[1]`` is written; a zoom-0 tile that does not
meet the rectangle (the other hemisphere) is written flat on the ellipsoid (two
triangles, height 0), because Cesium requests both root tiles.

Heights are written as the DEM holds them (taken as metres above the WGS84 ellipsoid, as
cesium-terrain-builder does; a DEM of orthometric heights is off by the geoid undulation).

Files and interruptions
-----------------------
Tiles go to ``out_dir/{z}/{x}/{y}.terrain`` (gzip-compressed by default, as
cesium-terrain-builder writes them; a web server must then send them with
``Content-Encoding: gzip``), each written atomically. The run's settings (method, zooms,
budget, lattice, compression, the DEM's fingerprint and CRS, the rectangle) go first into
``terrainvis-tiles.partial.json``; ``terrainvis-tiles.csv`` (one row per tile: vertices, triangles, the
zoom's budget, the method's own measure of its error, the error measured on the written
tile, whether it fell back to the whole lattice) and ``layer.json`` come last, and the
record is removed after them. An interrupted run thus leaves its finished tiles and the record but no
``layer.json``, so it never claims tiles it lacks, and ``resume=True`` continues it: with
the same settings, each tile already there is read and measured again, kept when it meets
its budget, and the others are made. A non-empty ``out_dir`` is refused otherwise unless
``overwrite=True``, which removes the files a tileset writes (``layer.json`` if terrainvis
wrote it, the record, the table, the ``{z}/{x}/{y}.terrain`` files and the leftover temporary files of
atomic writes) and nothing else.
"""

from __future__ import annotations

import gzip as _gzip
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.terrain import TIN, HeightGrid
from ..tolerances import QUANTIZED_SNAP, TILE_BUDGET_REL, TILE_RECTANGLE_SHRINK_REL
from . import quantized_mesh as qm
from ._common import EARTH_RADIUS
from ._common import Made as _Made
from ._common import equirectangular as _equirectangular
from ._common import sample_lattice, within_budget
from .keep_los import DEFAULT_LOS_HEIGHT, N_POINTS
from .terrain_rgb import DEFAULT_PIXELS as RGB_PIXELS
from .terrain_rgb import kept_rgb_tile, make_rgb_tile, mercator_tiles_covering, pixel_lattice
from .scheme import FORMATS, MAX_ZOOM, tile_bounds, tile_count, tile_ranges, tiles_covering

__all__ = ["DEFAULT_MAX_ERROR0", "DEFAULT_LATTICE", "EARTH_RADIUS", "LAYER", "PARTIAL", "TILES_CSV", "API_NAMES",
           "ZoomReport", "Tileset",
           "write_tileset", "lonlat_rectangle", "tile_lattice", "pyproj_module"]

#: What ``layer.json``'s ``format`` says of each.
_LAYER_FORMAT = {"quantized-mesh": "quantized-mesh-1.0", "terrain-rgb": "terrain-rgb"}
#: The budget of zoom 0 (m); zoom z gets ``DEFAULT_MAX_ERROR0 / 2**z``.
DEFAULT_MAX_ERROR0 = 77067.0
#: Lattice cells per tile side (65 x 65 points, as Cesium's heightmap tiles).
DEFAULT_LATTICE = 64
#: The tileset's description, written last.
LAYER = "layer.json"
#: One row per tile: its size, budget, the method's own error measure and the error measured on the tile.
TILES_CSV = "terrainvis-tiles.csv"
#: The settings of a run that has not finished (written first, removed once layer.json is written): what
#: ``resume=True`` checks before it keeps the tiles already written.
PARTIAL = "terrainvis-tiles.partial.json"
#: How messages name the arguments (the command line passes its flags instead).
API_NAMES = {"out_dir": "out_dir", "overwrite": "overwrite=True", "resume": "resume=True", "zooms": "zooms", "method": "method",
             "max_error0": "max_error0", "lattice": "lattice", "grid": "grid", "keep_los": "keep_los",
             "los_height": "los_height", "format": "format", "gzip": "gzip=True"}
#: The lattice the footprint's rectangle is searched on (points per side).
_SEARCH = 257
_TILE_FILE = re.compile(r"^\d+$")
#: The header of :data:`TILES_CSV` (``method_error`` empty for a tile not simplified here, or kept by a resume).
_CSV_HEADER = "z,x,y,vertices,triangles,max_error,method_error,measured_error,whole_lattice_fallback"


def pyproj_module():
    """pyproj, or an ImportError with the install hint."""
    try:
        import pyproj
    except ImportError as exc:
        raise ImportError('writing terrain tiles needs pyproj: pip install "terrainvis[tiles]"') from exc
    return pyproj


# ---------------------------------------------------------------------- the DEM in lon/lat
class _Frame:
    """Lon/lat (EPSG:4326) to a grid's own frame and back, through its CRS and ``xy_to_native``."""

    def __init__(self, grid: HeightGrid, name: str):
        from ..core._georef import _EPSG, xy_to_native

        pyproj = pyproj_module()
        text = grid.attrs.get("crs")
        if not isinstance(text, str) or not text.strip():
            raise ValueError(f"{name} has no CRS (attrs['crs']): a tileset places the DEM on the globe, so it needs a "
                             "georeferenced DEM (a GeoTIFF or an .asc with its .prj, or load_dem(..., crs=...))")
        try:
            crs = pyproj.CRS.from_user_input(text)
        except pyproj.exceptions.CRSError:
            codes = set(_EPSG.findall(text))
            if len(codes) != 1:
                raise ValueError(f"{name}'s CRS {text!r} is not one pyproj can read") from None
            crs = pyproj.CRS.from_epsg(int(codes.pop()))
        affine = xy_to_native(grid.attrs)
        if affine is None:
            raise ValueError(f"{name} is geographic but holds no attrs['xy_to_native']: its lon/lat are unknown")
        self.affine = affine
        self.crs_text = text
        self.forward = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
        self.back = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)

    def to_grid(self, lon, lat) -> np.ndarray:
        """(n, 2) positions in the grid's frame (non-finite where the projection has none)."""
        x, y = self.forward.transform(np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64))
        sx, ox, sy, oy = self.affine
        xy = np.column_stack([(np.asarray(x, dtype=np.float64) - ox) / sx, (np.asarray(y, dtype=np.float64) - oy) / sy])
        return np.where(np.isfinite(xy), xy, np.nan)

    def to_lonlat(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        sx, ox, sy, oy = self.affine
        lon, lat = self.back.transform(ox + sx * np.asarray(x, dtype=np.float64), oy + sy * np.asarray(y, dtype=np.float64))
        return np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)


def _valid(grid: HeightGrid, frame: _Frame, lon, lat) -> np.ndarray:
    xy = frame.to_grid(np.ravel(lon), np.ravel(lat))
    ok = np.isfinite(xy).all(axis=1)
    out = np.zeros(ok.shape, dtype=bool)
    if ok.any():
        out[ok] = np.isfinite(grid.height_at(xy[ok]))
    return out.reshape(np.shape(lon))


def _largest_true_rectangle(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """``(r0, c0, r1, c1)`` inclusive: the all-True rectangle of ``mask`` with the most cells (None: no True)."""
    rows, cols = mask.shape
    heights = np.zeros(cols, dtype=np.int64)
    best, found = 0, None
    for r in range(rows):
        heights = np.where(mask[r], heights + 1, 0)
        stack: list[int] = []
        for c in range(cols + 1):
            h = int(heights[c]) if c < cols else 0
            while stack and int(heights[stack[-1]]) >= h:
                top = stack.pop()
                height = int(heights[top])
                left = stack[-1] + 1 if stack else 0
                area = height * (c - left)
                if height and area > best:
                    best, found = area, (r - height + 1, left, r, c - 1)
            stack.append(c)
    return found


def lonlat_rectangle(grid: HeightGrid, *, name: str = "grid") -> tuple[float, float, float, float]:
    """``(west, south, east, north)``: the largest lon/lat-aligned rectangle inside the DEM's valid footprint.

    The footprint (where ``grid.height_at`` is finite) is mapped to lon/lat with pyproj. The
    rectangle with the most cells of a 257 x 257 lattice over the footprint's bounding box is
    taken, then each side is pushed outwards by bisection while the rectangle's boundary (1025
    points a side) stays on valid ground, and the result is shrunk by ``TILE_RECTANGLE_SHRINK_REL`` of its size
    against rounding. Largest means in square degrees on that lattice.

    Raises
    ------
    ValueError
        Without a CRS, when the footprint crosses the antimeridian, or when no rectangle of
        two lattice steps a side fits.
    """
    frame = _Frame(grid, name)
    return _rectangle(grid, frame, name)


def _rectangle(grid: HeightGrid, frame: _Frame, name: str) -> tuple[float, float, float, float]:
    x0, x1, y0, y1 = grid.xs[0], grid.xs[-1], grid.ys[0], grid.ys[-1]
    t = np.linspace(0.0, 1.0, 513)
    bx = np.concatenate([x0 + t * (x1 - x0), np.full(t.size, x1), x1 - t * (x1 - x0), np.full(t.size, x0)])
    by = np.concatenate([np.full(t.size, y0), y0 + t * (y1 - y0), np.full(t.size, y1), y1 - t * (y1 - y0)])
    lon, lat = frame.to_lonlat(bx, by)
    ok = np.isfinite(lon) & np.isfinite(lat)
    if not ok.any():
        raise ValueError(f"{name}'s footprint has no lon/lat in its CRS {frame.crs_text!r}")
    lon, lat = lon[ok], lat[ok]
    if lon.max() - lon.min() > 180.0 or np.abs(np.diff(lon)).max() > 90.0:
        raise ValueError(f"{name}'s footprint crosses the antimeridian (longitudes {lon.min():.4f} to {lon.max():.4f}): "
                         "a tileset of it is not supported; cut the DEM at 180 degrees first")
    w, e = float(lon.min()), float(lon.max())
    s, n = max(float(lat.min()), -90.0), min(float(lat.max()), 90.0)
    glon = np.linspace(w, e, _SEARCH)
    glat = np.linspace(s, n, _SEARCH)
    mask = _valid(grid, frame, *np.meshgrid(glon, glat))
    found = _largest_true_rectangle(mask)
    if found is None or found[2] == found[0] or found[3] == found[1]:
        raise ValueError(f"{name}'s valid footprint holds no lon/lat rectangle of two steps of a {_SEARCH}-point "
                         "lattice a side: it is too thin, or mostly nodata")
    r0, c0, r1, c1 = found
    rect = [glon[c0], glat[r0], glon[c1], glat[r1]]
    # each side outwards, up to the next lattice line (the first beyond, which was not all valid)
    outward = [glon[c0 - 1] if c0 > 0 else w, glat[r0 - 1] if r0 > 0 else s,
               glon[c1 + 1] if c1 + 1 < _SEARCH else e, glat[r1 + 1] if r1 + 1 < _SEARCH else n]
    for side in range(4):
        good, far = rect[side], outward[side]
        for _ in range(40):
            if good == far:
                break
            trial = list(rect)
            trial[side] = far
            if _boundary_valid(grid, frame, trial):
                good = far
                break
            mid = 0.5 * (good + far)
            trial[side] = mid
            if _boundary_valid(grid, frame, trial):
                good = mid
            else:
                far = mid
        rect[side] = good
    w, s, e, n = (float(v) for v in rect)
    dw, dh = TILE_RECTANGLE_SHRINK_REL * (e - w), TILE_RECTANGLE_SHRINK_REL * (n - s)
    return w + dw, s + dh, e - dw, n - dh


def _boundary_valid(grid, frame, rect) -> bool:
    w, s, e, n = rect
    t = np.linspace(0.0, 1.0, 1025)
    lon = np.concatenate([w + t * (e - w), np.full(t.size, e), w + t * (e - w), np.full(t.size, w)])
    lat = np.concatenate([np.full(t.size, s), s + t * (n - s), np.full(t.size, n), s + t * (n - s)])
    return bool(_valid(grid, frame, lon, lat).all())


# ---------------------------------------------------------------------- one tile
@dataclass(frozen=True)
class _Lattice:
    """A tile's lattice: its quantized columns and rows, their lon/lat, its heights, and ``grid``, the
    HeightGrid the simplifiers get: the lattice in the local metric frame, spaced evenly at its mean step."""

    bounds: tuple
    us: np.ndarray
    vs: np.ndarray
    lon: np.ndarray
    lat: np.ndarray
    lon0: float
    lat0: float
    z: np.ndarray
    grid: HeightGrid

    def to_local(self, lon, lat) -> tuple[np.ndarray, np.ndarray]:
        """The true local frame (equirectangular about lon0, lat0), where errors are measured."""
        return _equirectangular(lon, lat, self.lon0, self.lat0)

    def grid_to_lonlat(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Positions of ``grid`` (evenly spaced) to lon/lat: lattice column i to ``lon[i]``, linear between."""
        g = self.grid
        c = (np.asarray(x, dtype=np.float64) - g.xs[0]) / (g.xs[-1] - g.xs[0]) * (g.xs.size - 1)
        r = (np.asarray(y, dtype=np.float64) - g.ys[0]) / (g.ys[-1] - g.ys[0]) * (g.ys.size - 1)
        return (np.interp(c, np.arange(self.lon.size), self.lon), np.interp(r, np.arange(self.lat.size), self.lat))


def _steps(lo: float, hi: float, n: int) -> np.ndarray | None:
    """The integer quantized positions of a lattice over [lo, hi] (in units of the tile): at most n + 1, even."""
    a = max(0, math.ceil(lo - QUANTIZED_SNAP))
    b = min(qm.QUANTIZED_MAX, math.floor(hi + QUANTIZED_SNAP))
    if b - a < 1:
        return None
    k = min(n, b - a)
    return np.rint(a + np.arange(k + 1) * ((b - a) / k)).astype(np.int64)


def tile_lattice(grid: HeightGrid, z: int, x: int, y: int, rectangle, *, lattice: int = DEFAULT_LATTICE,
                 frame=None, name: str = "grid"):
    """The lattice of tile ``(z, x, y)`` over its part inside ``rectangle``: an object with ``grid``
    (the HeightGrid in the local metric frame), ``lon``, ``lat`` (its columns and rows in degrees),
    ``us``, ``vs`` (their quantized positions) and ``to_local`` / ``to_lonlat``; None when the part is
    thinner than one quantization step.

    Raises
    ------
    ValueError
        When a lattice point lies on nodata (a hole smaller than the rectangle search's lattice).
    """
    frame = _Frame(grid, name) if frame is None else frame
    bounds = tile_bounds(z, x, y)
    west, south, east, north = bounds
    rw, rs, re_, rn = rectangle
    scale_x = qm.QUANTIZED_MAX / (east - west)
    scale_y = qm.QUANTIZED_MAX / (north - south)
    us = _steps((max(rw, west) - west) * scale_x, (min(re_, east) - west) * scale_x, lattice)
    vs = _steps((max(rs, south) - south) * scale_y, (min(rn, north) - south) * scale_y, lattice)
    if us is None or vs is None:
        return None
    lon = west + us / qm.QUANTIZED_MAX * (east - west)
    lat = south + vs / qm.QUANTIZED_MAX * (north - south)
    z_, lon0, lat0, even = sample_lattice(grid, frame, lon, lat, name)
    return _Lattice(bounds, us, vs, lon, lat, lon0, lat0, z_, even)


def _encode(lat_: _Lattice, tin: TIN) -> tuple[bytes, qm.DecodedTile] | None:
    """The tile of ``tin`` (local frame), reaching the whole tile (:func:`_whole_tile`), and its decoding;
    None when rounding would fold a triangle."""
    v = tin.vertices
    lon, lat = lat_.grid_to_lonlat(v[:, 0], v[:, 1])
    u, vv = qm.to_uv(lon, lat, lat_.bounds)
    faces = np.asarray(tin.faces, dtype=np.int64)
    from ..core.mesh import signed_area2  # core.mesh imports numba: not at import time

    if (signed_area2(np.column_stack([u, vv]), faces) <= 0).any():
        return None
    u, vv, h, faces = _whole_tile(u, vv, v[:, 2], faces, (int(lat_.us[0]), int(lat_.us[-1])),
                                  (int(lat_.vs[0]), int(lat_.vs[-1])))
    data = qm.encode_tile(u, vv, h, faces, lat_.bounds)
    return data, qm.decode_tile(data, lat_.bounds)


def _whole_tile(u, v, h, faces, u_span, v_span):
    """A mesh over the part ``u_span`` x ``v_span`` of a tile (quantized positions), extended to the
    whole tile.

    Cesium makes a tile the tileset lacks from its parent: a parent that held only its part of the
    tileset's rectangle left the others empty, and Cesium's renderer stopped on them. Each side of
    the part inside the tile gets a strip out to the tile's edge: every vertex of the mesh on that
    side is repeated on the edge at the same height, and each corner a quad at the part's corner
    height. Outside the rectangle the terrain is thus the rectangle's edge, extended outwards; the
    part inside is the mesh as it was.
    """
    M = qm.QUANTIZED_MAX
    (ua, ub), (va, vb) = u_span, v_span  # the mesh's vertices on a side of the part are sorted along it
    index = {(int(a), int(b)): i for i, (a, b) in enumerate(zip(u, v))}
    us, vs, hs = list(map(int, u)), list(map(int, v)), list(map(float, h))
    at = {k: hs[i] for k, i in index.items()}
    tris = [tuple(f) for f in np.asarray(faces, dtype=np.int64)]

    def vertex(a, b, height):
        key = (a, b)
        if key not in index:
            index[key] = len(us)
            us.append(a)
            vs.append(b)
            hs.append(height)
        return index[key]

    def quad(p, q, r, s):  # counter-clockwise corners of a quad: two triangles
        tris.extend([(p, q, r), (p, r, s)])

    # strips: west (u == ua, out to 0), east (u == ub, to M), south (v == va, to 0), north (v == vb, to M)
    if ua > 0:
        col = sorted(b for (a, b) in at if a == ua)
        for b0, b1 in zip(col, col[1:]):
            quad(vertex(0, b0, at[(ua, b0)]), index[(ua, b0)], index[(ua, b1)], vertex(0, b1, at[(ua, b1)]))
    if ub < M:
        col = sorted(b for (a, b) in at if a == ub)
        for b0, b1 in zip(col, col[1:]):
            quad(index[(ub, b0)], vertex(M, b0, at[(ub, b0)]), vertex(M, b1, at[(ub, b1)]), index[(ub, b1)])
    if va > 0:
        row = sorted(a for (a, b) in at if b == va)
        for a0, a1 in zip(row, row[1:]):
            quad(vertex(a0, 0, at[(a0, va)]), vertex(a1, 0, at[(a1, va)]), index[(a1, va)], index[(a0, va)])
    if vb < M:
        row = sorted(a for (a, b) in at if b == vb)
        for a0, a1 in zip(row, row[1:]):
            quad(index[(a0, vb)], index[(a1, vb)], vertex(a1, M, at[(a1, vb)]), vertex(a0, M, at[(a0, vb)]))
    # corners: the part's corner height out to the tile's corner
    for cu, eu in ((ua, 0), (ub, M)):
        for cv, ev in ((va, 0), (vb, M)):
            if cu == eu or cv == ev:
                continue
            c = at[(cu, cv)]
            ring = [index[(cu, cv)], vertex(eu, cv, c), vertex(eu, ev, c), vertex(cu, ev, c)]
            if (eu > cu) != (ev > cv):  # keep the quad counter-clockwise
                ring = ring[::-1]
            quad(*ring)
    return np.array(us), np.array(vs), np.array(hs), np.array(tris, dtype=np.int64)


def _error(lat_: _Lattice, dec: qm.DecodedTile) -> float:
    """The largest |decoded mesh - lattice height| at the lattice points (inf where the mesh misses one)."""
    x, y = lat_.to_local(dec.lon, dec.lat)
    tin = TIN(np.column_stack([x, y, dec.height]), dec.triangles)
    X, Y = np.meshgrid(*lat_.to_local(lat_.lon, lat_.lat))
    got = tin.height_at(np.column_stack([X.ravel(), Y.ravel()]))
    diff = np.abs(got - lat_.z.ravel())
    return float(diff.max()) if np.isfinite(diff).all() else math.inf


def _make_tile(lat_: _Lattice, method: str | None, budget: float | None) -> _Made:
    """Simplify (or not), encode, measure; retries and the whole lattice as the fallback (module docstring)."""

    def encode(tin):
        made = _encode(lat_, tin)
        if made is None:
            return "the rounding of the vertices to the tile's positions would fold a triangle"
        data, dec = made
        return (_Made(data, _error(lat_, dec), dec.u.size, dec.triangles.shape[0], decoded=dec),
                qm.height_step(dec.min_height, dec.max_height))

    fallback = None
    if method is not None:
        made, fallback = within_budget(lat_.grid, method, budget, encode)
        if made is not None:
            return made
    data, dec = _encode(lat_, lat_.grid.to_tin())
    return _Made(data, _error(lat_, dec), dec.u.size, dec.triangles.shape[0], fallback, decoded=dec)


def _flat_tile(bounds) -> bytes:
    """A whole tile flat on the ellipsoid (height 0): two triangles."""
    m = qm.QUANTIZED_MAX
    return qm.encode_tile(np.array([0, m, m, 0]), np.array([0, 0, m, m]), np.zeros(4), [[0, 1, 2], [0, 2, 3]], bounds)


# ---------------------------------------------------------------------- the output folder
def _ours(layer: Path) -> bool:
    try:
        meta = json.loads(layer.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and "terrainvis" in meta and meta.get("format") in _LAYER_FORMAT.values()


def _tile_files(out: Path) -> list[Path]:
    """The ``{z}/{x}/{y}.terrain`` and ``.png`` files under ``out`` and the leftovers of their atomic writes."""
    found = []
    for zd in out.iterdir():
        if not (zd.is_dir() and _TILE_FILE.match(zd.name)):
            continue
        for xd in zd.iterdir():
            if not (xd.is_dir() and _TILE_FILE.match(xd.name)):
                continue
            for f in xd.iterdir():
                if f.is_file() and re.fullmatch(r"\d+\.(terrain|png)|\.\d+\.(terrain\.[a-z0-9_]{8}\.terrain|png\.[a-z0-9_]{8}\.png)",
                                                f.name):
                    found.append(f)
    return found


def _partial(out: Path) -> dict | None:
    """The settings an unfinished run recorded in ``out`` (None: no record terrainvis wrote)."""
    try:
        rec = json.loads((out / PARTIAL).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return rec if isinstance(rec, dict) and rec.get("format") in _LAYER_FORMAT.values() and "settings" in rec else None


def _prepare(out_dir, overwrite: bool, resume: bool, settings: dict, names: dict) -> tuple[Path, int]:
    """``out_dir`` checked and made; with ``overwrite`` an earlier tileset's files removed (how many); with
    ``resume`` an unfinished run's settings checked against ``settings``."""
    from ..core.fileio import check_writable_dir, refuse_protected

    refuse_protected(out_dir, names["out_dir"])
    out = check_writable_dir(out_dir, names["out_dir"])
    entries = sorted(p.name for p in out.iterdir())
    if not entries:
        return out, 0
    where = f"{names['out_dir']} {str(out)!r}"
    layer = out / LAYER
    earlier = _partial(out)
    if resume:
        if earlier is None:
            done = " (a finished tileset: nothing to resume)" if _ours(layer) else ""
            raise ValueError(f"{names['resume']}: {where} holds no unfinished run of terrainvis tiles{done}; "
                             f"{names['overwrite']} replaces what is there")
        differ = sorted(k for k in set(settings) | set(earlier["settings"])
                        if settings.get(k) != earlier["settings"].get(k))
        if differ:
            shown = "; ".join(f"{k}: {earlier['settings'].get(k)!r} then, {settings.get(k)!r} now" for k in differ)
            raise ValueError(f"{names['resume']}: the unfinished run in {where} had other settings ({shown}); "
                             f"{names['overwrite']} starts again with these")
        return out, 0
    if not overwrite:
        n = len(_tile_files(out))
        tiles = f"{n:,} tile{'s' if n != 1 else ''}"
        if _ours(layer):
            shown = f"a tileset terrainvis wrote: {LAYER} and {tiles}"
        elif earlier is not None:
            raise ValueError(f"{where} holds an unfinished run's {tiles}; {names['resume']} continues it (same "
                             f"settings), {names['overwrite']} replaces it, or choose another folder")
        elif n:
            shown = f"{tiles} without {LAYER}"
        else:
            shown = ", ".join(entries[:3]) + (f" and {len(entries) - 3} more" if len(entries) > 3 else "")
        raise ValueError(f"{where} is not empty (it holds {shown}); {names['overwrite']} replaces the tileset in it "
                         "(the files a tileset writes, nothing else), or choose another folder")
    if layer.exists() and not _ours(layer):
        raise ValueError(f"{where} holds a {LAYER} that terrainvis did not write; terrainvis never replaces a file it "
                         "did not write: move it away or choose another folder")
    files = _tile_files(out)
    if files and not (_ours(layer) or earlier is not None):
        # every run of terrainvis tiles writes its record before its first tile: tiles without
        # either record are another program's (a tiler's output kept without its layer.json)
        raise ValueError(f"{where} holds {len(files):,} {{z}}/{{x}}/{{y}} tile file(s) without a {LAYER} or a record "
                         f"that terrainvis wrote; terrainvis never replaces files it did not write: move them away "
                         "or choose another folder")
    leftovers = [p for p in out.iterdir() if p.is_file() and re.fullmatch(
        r"\.(layer\.json|terrainvis-tiles\.partial\.json)\.[a-z0-9_]{8}\.json|\.terrainvis-tiles\.csv\.[a-z0-9_]{8}\.csv",
        p.name)]
    csv = out / TILES_CSV
    ours_csv = csv.is_file() and csv.read_text(encoding="utf-8", errors="replace").startswith(_CSV_HEADER)
    if csv.exists() and not ours_csv:
        raise ValueError(f"{where} holds a {TILES_CSV} that terrainvis did not write; terrainvis never replaces a "
                         "file it did not write: move it away or choose another folder")
    mine = [f for f in (layer, out / PARTIAL, csv) if f.exists() and (f.name != PARTIAL or earlier is not None)]
    removed = 0
    for f in mine + files + leftovers:
        f.unlink()
        removed += 1
    for zd in out.iterdir():
        if zd.is_dir() and _TILE_FILE.match(zd.name):
            for xd in zd.iterdir():
                if xd.is_dir() and _TILE_FILE.match(xd.name) and not any(xd.iterdir()):
                    xd.rmdir()
            if not any(zd.iterdir()):
                zd.rmdir()
    return out, removed


def _kept(path: Path, lat_: _Lattice, budget: float | None) -> _Made | None:
    """An unfinished run's tile, read and measured again: kept when it decodes and meets its budget."""
    try:
        data = path.read_bytes()
        dec = qm.decode_tile(data, lat_.bounds)
    except (OSError, ValueError, EOFError, _gzip.BadGzipFile):
        return None
    err = _error(lat_, dec)
    allowed = (0.0 if budget is None else budget) + 0.5 * qm.height_step(dec.min_height, dec.max_height)
    if not err <= allowed * (1 + TILE_BUDGET_REL):
        return None
    # a simplified tile holding every lattice point is one written as the whole lattice (a fallback)
    U, V = np.meshgrid(lat_.us, lat_.vs)
    present = set(zip(dec.u.tolist(), dec.v.tolist()))
    whole = budget is not None and all(p in present for p in zip(U.ravel().tolist(), V.ravel().tolist()))
    return _Made(b"", err, dec.u.size, dec.triangles.shape[0], "the whole lattice (kept from the unfinished run)"
                 if whole else None)


# ---------------------------------------------------------------------- the tileset
@dataclass(frozen=True)
class ZoomReport:
    """One zoom of a tileset: its tiles, their size, the budget and the largest error measured."""

    zoom: int
    simplified: bool
    max_error: float | None
    n_tiles: int
    n_vertices: int
    n_triangles: int
    largest_error: float
    fallbacks: int
    fallback_reasons: tuple = ()
    los: object = None  # with keep_los: the zoom's terrainvis.tiles.keep_los.ZoomChoice

    @property
    def los_kept(self) -> float | None:
        """With ``keep_los``: the share of the zoom's sight lines whose verdict its tiles keep."""
        return None if self.los is None else self.los.share

    def as_json(self) -> dict:
        out = {"zoom": self.zoom, "simplified": self.simplified, "max_error": self.max_error, "tiles": self.n_tiles,
               "vertices": self.n_vertices, "triangles": self.n_triangles, "largest_error": self.largest_error,
               "fallbacks": self.fallbacks}
        if self.los is not None:
            out.update(los_kept=self.los.share, los_pairs=self.los.pairs)
        return out


@dataclass(frozen=True)
class Tileset:
    """What :func:`write_tileset` wrote: the folder, the rectangle covered, each zoom's report, ``layer.json``'s content."""

    out_dir: Path
    bounds: tuple
    method: str
    zooms: list = field(default_factory=list)
    layer: dict = field(default_factory=dict)
    removed: int = 0

    @property
    def largest_error(self) -> float:
        return max((z.largest_error for z in self.zooms if z.simplified), default=0.0)


def _check(grid, method, zooms, max_error0, gzip, lattice, names) -> tuple:
    from simplifiers import METHODS

    if not isinstance(grid, HeightGrid):
        raise TypeError(f"{names['grid']} must be a HeightGrid, got {type(grid).__name__}")
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"{names['method']} must be one of {', '.join(METHODS)}, got {method!r}")
    try:
        lo, hi = zooms
    except (TypeError, ValueError):
        raise ValueError(f"{names['zooms']} must be two zooms (min, max), got {zooms!r}") from None
    for v in (lo, hi):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or not 0 <= v <= MAX_ZOOM:
            raise ValueError(f"{names['zooms']} must be integers in [0, {MAX_ZOOM}], got {lo!r} {hi!r}")
    if lo > hi:
        raise ValueError(f"{names['zooms']} must run from the lower zoom to the higher (min <= max), got {lo} {hi}")
    e0 = DEFAULT_MAX_ERROR0 if max_error0 is None else max_error0
    if isinstance(e0, bool) or not isinstance(e0, (int, float, np.floating, np.integer)) or not math.isfinite(e0) or e0 < 0:
        raise ValueError(f"{names['max_error0']} must be a finite number >= 0 (m), got {max_error0!r}")
    if not isinstance(gzip, (bool, np.bool_)):
        raise TypeError(f"gzip must be True or False, got {gzip!r}")
    if isinstance(lattice, bool) or not isinstance(lattice, (int, np.integer)) or not 1 <= lattice <= 1024:
        raise ValueError(f"{names['lattice']} must be an integer in [1, 1024], got {lattice!r}")
    return int(lo), int(hi), float(e0), int(lattice)


def _check_format(format, gzip, keep_los, names) -> bool:
    """``format`` one of :data:`FORMATS` and the options it allows; True for terrain-RGB."""
    if format not in FORMATS:
        raise ValueError(f"{names['format']} must be one of {', '.join(FORMATS)}, got {format!r}")
    if format == "terrain-rgb":
        if gzip:
            raise ValueError(f"{names['gzip']} is for quantized-mesh tiles: terrain-RGB tiles are PNGs, compressed "
                             "already")
        if keep_los is not None:
            raise ValueError(f"{names['keep_los']} chooses the budgets of quantized-mesh tiles only: a client meshes "
                             "terrain-RGB pixels at a max error of its own")
    return format == "terrain-rgb"


def write_tileset(grid: HeightGrid, out_dir, *, method: str, zooms, max_error0: float | None = None,
                  gzip: bool | None = None, lattice: int | None = None, overwrite: bool = False, resume: bool = False,
                  name: str | None = None, names: dict | None = None, keep_los: float | None = None,
                  los_height: float = DEFAULT_LOS_HEIGHT, format: str = "quantized-mesh") -> Tileset:
    """Write ``grid`` as a Cesium quantized-mesh-1.0 tileset (or terrain-RGB tiles) in ``out_dir``, each tile
    simplified by ``method``.

    The module docstring describes what the tileset covers, how each tile is made and the
    files; :func:`terrainvis.tiles.decode_tile` reads a tile back. With
    ``format="terrain-rgb"`` the tiles are Mapbox's terrain-RGB PNGs in Web Mercator
    (:mod:`terrainvis.tiles.terrain_rgb`).

    Parameters
    ----------
    grid : HeightGrid
        A georeferenced DEM (``attrs["crs"]``), heights in metres; nodata only outside
        the rectangle the tileset covers.
    out_dir : str or Path
        An empty folder (created when missing), or any folder with ``overwrite=True``.
    method : str
        A registered method (``simplifiers.available()``), used from ``zooms[0]`` on.
    zooms : (int, int)
        ``(min, max)`` with ``0 <= min <= max <= 24``; zooms 0 to ``max`` are written,
        below ``min`` as whole lattices.
    max_error0 : float, optional
        The budget at zoom 0 in metres (default 77067); zoom z gets ``max_error0 / 2**z``.
        Not with ``keep_los``.
    gzip : bool, optional
        Compress quantized-mesh tiles with gzip (the default), as cesium-terrain-builder does.
        Terrain-RGB tiles are PNGs, never gzipped (True is refused).
    lattice : int, optional
        Lattice cells per tile side (default 64: 65 x 65 points); for terrain-RGB the
        pixels per tile side (default 256).
    overwrite : bool
        Replace the tileset files in a non-empty ``out_dir``.
    resume : bool
        Continue the unfinished run in ``out_dir`` (one with the same settings and DEM): its
        tiles are read and measured again, kept when they meet their budget, and the rest
        are made.
    name : str, optional
        The tileset's name in ``layer.json`` (default ``grid.attrs["name"]`` or ``"terrain"``).
    names : dict, optional
        How messages name the arguments (:data:`API_NAMES`; the command line passes its flags).
    keep_los : float, optional
        Instead of halving budgets, each zoom's budget is the largest vertical error at which
        its tiles keep at least this share (in (0, 1]) of the line-of-sight verdicts of
        their sight lines: :mod:`terrainvis.tiles.keep_los`. Each zoom's share is in the
        report (:attr:`ZoomReport.los_kept`) and in ``layer.json``.
    los_height : float
        With ``keep_los``: the sight lines' ends above the ground (m, default 2).
    format : {"quantized-mesh", "terrain-rgb"}
        The tiles' format. ``keep_los`` is for quantized-mesh tiles (a client meshes
        terrain-RGB pixels with a max error of its own).

    Returns
    -------
    Tileset

    Examples
    --------
    >>> import tempfile
    >>> from terrainvis.io import bundled_terrain
    >>> dem = bundled_terrain("cumberland")
    >>> ts = write_tileset(dem, tempfile.mkdtemp(), method="greedy-insertion", zooms=(9, 9))  # doctest: +SKIP
    >>> ts.zooms[-1].largest_error <= 77067.0 / 2**9 + 1.0  # doctest: +SKIP
    True
    """
    from .keep_los import check_keep_los

    names = {**API_NAMES, **(names or {})}
    rgb = _check_format(format, gzip, keep_los, names)
    gzip = not rgb if gzip is None else gzip
    lattice = (RGB_PIXELS if rgb else DEFAULT_LATTICE) if lattice is None else lattice
    lo, hi, e0, lattice = _check(grid, method, zooms, max_error0, gzip, lattice, names)
    keep, los_height = check_keep_los(keep_los, los_height, names)
    if keep is not None and max_error0 is not None:
        raise ValueError(f"{names['max_error0']} and {names['keep_los']} exclude each other: the budgets halve from "
                         "zoom 0's, or line of sight chooses them")
    frame = _Frame(grid, names["grid"])
    rect = _rectangle(grid, frame, names["grid"])
    if overwrite and resume:
        raise ValueError(f"{names['overwrite']} and {names['resume']} exclude each other: replace the run, or continue it")
    from ..core.fileio import atomic_write_text
    from ..core.terrain import fingerprint

    settings = {"format": format, "method": method, "zooms": [lo, hi], "max_error0": None if keep is not None else e0,
                "lattice": lattice, "gzip": bool(gzip), "dem": fingerprint(grid), "crs": frame.crs_text,
                "bounds": [float(v) for v in rect]}
    if keep is not None:
        settings.update(keep_los=keep, los_height=los_height)
    out, removed = _prepare(out_dir, bool(overwrite), bool(resume), settings, names)
    # the budgets line of sight chose for each zoom, kept in the record so that a resume does not search again
    chosen = dict(((_partial(out) or {}).get("chosen") or {}) if resume else {})
    record = {"format": _LAYER_FORMAT[format], "settings": settings, "chosen": chosen}
    atomic_write_text(out / PARTIAL, json.dumps(record, indent=1) + "\n")
    run = _Run(grid, frame, rect, out, method, lattice, bool(gzip), bool(resume), keep, los_height, names["grid"],
               record, rgb)
    reports, available, rows = [], [], []
    for z in range(hi + 1):
        report, written = _write_zoom(run, z, z >= lo, e0 / 2 ** z if z >= lo and keep is None else None, rows)
        reports.append(report)
        available.append(tile_ranges(written))
    layer = _layer(run, name or grid.attrs.get("name") or "terrain", (lo, hi), settings, reports, available)
    atomic_write_text(out / TILES_CSV, _CSV_HEADER + "\n" + "".join(r + "\n" for r in rows))
    atomic_write_text(out / LAYER, json.dumps(layer, indent=1) + "\n")
    (out / PARTIAL).unlink()
    return Tileset(out, rect, method, reports, layer, removed)


@dataclass(frozen=True)
class _Run:
    """What every zoom of one :func:`write_tileset` run shares."""

    grid: HeightGrid
    frame: _Frame
    rect: tuple
    out: Path
    method: str
    lattice: int
    gzip: bool
    resume: bool
    keep: float | None
    los_height: float
    name: str
    record: dict  # the partial record; its "chosen" holds the budgets line of sight chose
    rgb: bool = False  # terrain-RGB tiles (Web Mercator, XYZ rows, PNG)

    def covering(self, z: int) -> tuple[list, tuple]:
        """The tiles of zoom z to write, and the range of those meeting the rectangle."""
        if self.rgb:
            x0, y0, x1, y1 = mercator_tiles_covering(z, self.rect)
        else:
            x0, y0, x1, y1 = tiles_covering(z, self.rect)
        todo = [(x, y) for y in range(y0, y1 + 1) for x in range(x0, x1 + 1)]
        if z == 0 and not self.rgb:  # Cesium asks for both root tiles
            todo += [(x, 0) for x in range(tile_count(0)[0]) if (x, 0) not in todo]
        return todo, (x0, y0, x1, y1)

    def lattice_of(self, z: int, x: int, y: int):
        if self.rgb:
            return pixel_lattice(self.grid, z, x, y, self.rect, self.frame, self.lattice, self.name)
        return tile_lattice(self.grid, z, x, y, self.rect, lattice=self.lattice, frame=self.frame, name=self.name)

    def make(self, lat_, method, budget):
        return (make_rgb_tile if self.rgb else _make_tile)(lat_, method, budget)

    def kept(self, path: Path, lat_, budget):
        if self.rgb:
            try:
                data = path.read_bytes()
            except OSError:
                return None
            return kept_rgb_tile(data, lat_, budget)
        return _kept(path, lat_, budget)


def _zoom_budget(run: _Run, z: int, lattices: dict) -> tuple:
    """With ``keep_los``: zoom z's budget (recorded by an earlier run, or searched now and recorded), the
    method its tiles take (None: whole lattices), the tiles the search made, and its choice."""
    from ..core.fileio import atomic_write_text
    from .keep_los import ZoomChoice, choose_budget

    chosen = run.record["chosen"]
    made_at = {}
    if str(z) in chosen:
        choice = ZoomChoice.from_json(chosen[str(z)])
    else:
        choice, made_at = choose_budget(
            {k: v for k, v in lattices.items() if v is not None}, z, run.keep, run.los_height,
            lambda lat_, b: _make_tile(lat_, run.method if b is not None else None, b))
        chosen[str(z)] = choice.as_json()
        atomic_write_text(run.out / PARTIAL, json.dumps(run.record, indent=1) + "\n")
    whole = not choice.tried or choice.budget == 0.0  # no rung kept the share: whole lattices
    return choice.budget, None if whole else run.method, made_at, choice


def _write_zoom(run: _Run, z: int, simplified: bool, budget: float | None, rows: list) -> tuple:
    """Zoom z's tiles made (or kept by a resume) and written; its report and the tiles written. Each
    tile's row of the table is appended to ``rows``."""
    from ..core.fileio import atomic_path

    tile_method = run.method if simplified else None
    todo, (x0, y0, x1, y1) = run.covering(z)
    lattices = {(x, y): run.lattice_of(z, x, y) if x0 <= x <= x1 and y0 <= y <= y1 else None for x, y in todo}
    choice, made_at = None, {}
    if simplified and run.keep is not None:
        budget, tile_method, made_at, choice = _zoom_budget(run, z, lattices)
    written, errors, n_v, n_t, reasons = [], [], 0, 0, []
    for x, y in todo:
        lat_ = lattices[(x, y)]
        if lat_ is None and z > 0:
            continue  # a part thinner than one quantization step
        path = run.out / str(z) / str(x) / f"{y}.{'png' if run.rgb else 'terrain'}"
        made = made_at.get((x, y))
        if made is None and run.resume and lat_ is not None and path.is_file():
            made = run.kept(path, lat_, budget)
            data = None  # kept as it is
        if lat_ is None:
            data = _flat_tile(tile_bounds(0, x, 0))
        elif made is None or made.data:  # made now (or by the search), not kept by a resume
            made = made or run.make(lat_, tile_method, budget if tile_method else None)
            data = made.data
        if made is not None:
            fell_back = bool(made.fallback) and tile_method is not None
            rows.append(f"{z},{x},{y},{made.n_vertices},{made.n_triangles},{'' if budget is None else repr(budget)},"
                        f"{'' if made.simplify_error is None else repr(made.simplify_error)},{made.error!r},"
                        f"{'yes' if fell_back else 'no'}")
            errors.append(made.error)
            n_v += made.n_vertices
            n_t += made.n_triangles
            if fell_back:
                reasons.append(f"{z}/{x}/{y}: {made.fallback}")
        if data is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(path) as tmp:
                tmp.write_bytes(_gzip.compress(data, mtime=0) if run.gzip and not run.rgb else data)
        written.append((x, y))
    return ZoomReport(z, simplified, budget, len(written), n_v, n_t, max(errors, default=0.0), len(reasons),
                      tuple(reasons), choice), written


def _layer(run: _Run, label, zooms, settings: dict, reports: list, available: list) -> dict:
    """``layer.json``'s content."""
    lo, hi = zooms
    layer = {
        "tilejson": "2.1.0", "name": str(label),
        "description": f"{label} simplified with {run.method} from zoom {lo}" + (
            f", each zoom to the largest vertical error keeping {run.keep:.4g} of its tiles' line-of-sight verdicts"
            if run.keep is not None else "") + " (terrainvis)",
        "version": "1.0.0", "format": "terrain-rgb" if run.rgb else "quantized-mesh-1.0", "attribution": "",
        "scheme": "xyz" if run.rgb else "tms", "tiles": ["{z}/{x}/{y}.png" if run.rgb else "{z}/{x}/{y}.terrain"],
        "projection": "EPSG:3857" if run.rgb else "EPSG:4326", "bounds": list(run.rect),
        "minzoom": 0, "maxzoom": hi, "available": available,
        "terrainvis": {
            "method": run.method, "zooms": [lo, hi], "max_error0": settings["max_error0"], "lattice": run.lattice,
            "gzip": run.gzip,
            "source_crs": run.frame.crs_text,
            "max_error": {str(r.zoom): r.max_error for r in reports},
            "largest_error": max((r.largest_error for r in reports if r.simplified), default=0.0),
            "zooms_written": [r.as_json() for r in reports],
        },
    }
    if run.rgb:  # TileJSON's raster-dem fields, as Mapbox's terrain-RGB sources carry them
        layer.update(encoding="mapbox", tileSize=run.lattice)
    if run.keep is not None:
        layer["terrainvis"]["keep_los"] = {"share": run.keep, "height": run.los_height, "points_per_tile": N_POINTS,
                                           "zooms": {str(r.zoom): r.los.as_json() for r in reports if r.los}}
    return layer
