"""Terrain-RGB tiles of a DEM, each simplified by a method: ``write_tileset(..., format="terrain-rgb")``.

Mapbox's terrain-RGB is a raster format: PNG tiles ``{z}/{x}/{y}.png`` in Web Mercator
(EPSG:3857) with XYZ rows (counted from the north), each pixel a height of
-10000 + (R * 65536 + G * 256 + B) * 0.1 m. Clients mesh the pixels themselves (deck.gl's
TerrainLayer with Martini or Delatin at a max error of its own).

The pixels of a tile
--------------------
Pixel (row r, column c) of a tile of W x W pixels (``lattice`` W, default
:data:`DEFAULT_PIXELS`) is the height at the fraction (c / W, r / W) of the tile from its
north-west corner, linear in Web Mercator, as deck.gl places it (and as
:func:`terrainvis.tiles.read.stitch_zoom` reads it). The tile's lattice holds those W x W
points and one more row and column (the southern and eastern neighbours' first ones, which
a client takes from them), each the DEM's exact surface at the point; a point outside the
tileset's lon/lat rectangle (the same rectangle as the quantized-mesh tilesets',
:func:`terrainvis.tiles.lonlat_rectangle`) takes the height at the nearest point of the
rectangle, so a tile partly outside it continues the rectangle's edge outwards.

From zoom ``zooms[0]`` on, the lattice (evenly spaced in local metres, as for
quantized-mesh tiles) is simplified by the method to the zoom's budget, and the tile's
pixels are the simplified surface at the lattice's points, rounded to the encoding's 0.1 m
step. Its error is measured on the pixels written: the largest difference between a
decoded pixel and the lattice's height there. A tile over its budget plus half the step
(0.05 m) is simplified again with the budget lowered by the excess, up to three times, and
is otherwise written as its whole lattice (a fallback, counted as for quantized-mesh
tiles). Below ``zooms[0]`` the pixels are the lattice's heights. The ``vertices`` of a
tile's row in ``terrainvis-tiles.csv`` are those of the simplified surface the pixels
were taken from (a client meshes the pixels again).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass

import numpy as np

from ..core.terrain import TIN, HeightGrid
from ..tolerances import TILE_BUDGET_REL
from . import quantized_mesh as qm
from ._common import Made, equirectangular, sample_lattice, within_budget

__all__ = ["DEFAULT_PIXELS", "RGB_STEP", "MERCATOR_HALF", "x_of_lon", "y_of_lat", "lon_of_x", "lat_of_y", "rgb_heights", "rgb_encode", "mercator_tile_bounds", "mercator_tiles_covering", "pixel_lattice",
           "encode_png", "decode_png"]

#: Pixels per tile side (Mapbox's terrain-RGB tiles are 256 x 256; 512 x 512 for "@2x").
DEFAULT_PIXELS = 256
#: The encoding's height step (m).
RGB_STEP = 0.1
#: Half the circumference of Web Mercator's sphere (m): x and y run over [-H, H].
MERCATOR_HALF = math.pi * qm.WGS84_A
#: Web Mercator's latitude limit (the square's edge).
MAX_LAT = 85.0511287798066
#: The PNG text chunk holding the vertices and triangles of the surface a tile's pixels were taken from.
_MESH_KEY = "terrainvis-mesh"


def rgb_heights(rgb: np.ndarray) -> np.ndarray:
    """Heights (float64, m) of terrain-RGB pixels: -10000 + (R * 65536 + G * 256 + B) * 0.1.

    >>> rgb_heights(np.array([[[1, 134, 160]]], dtype=np.uint8)).round(6).tolist()
    [[0.0]]
    """
    a = np.asarray(rgb).astype(np.int64)
    return -10000.0 + (a[..., 0] * 65536 + a[..., 1] * 256 + a[..., 2]) * 0.1


def rgb_encode(heights) -> np.ndarray:
    """(h, w, 3) uint8 terrain-RGB pixels of heights (m), each rounded to the encoding's 0.1 m step.

    >>> rgb_encode([[0.0, 1234.56]]).tolist()
    [[[1, 134, 160], [1, 182, 218]]]
    """
    v = np.rint((np.asarray(heights, dtype=np.float64) + 10000.0) * 10.0).astype(np.int64)
    if v.size and (v.min() < 0 or v.max() >= 1 << 24):
        raise ValueError("heights must lie in [-10000, 1667721.5] m for terrain-RGB")
    return np.stack([(v >> 16) & 255, (v >> 8) & 255, v & 255], axis=-1).astype(np.uint8)


def x_of_lon(lon) -> np.ndarray:
    """Web Mercator x (m) of longitudes (degrees)."""
    return np.radians(np.asarray(lon, dtype=np.float64)) * qm.WGS84_A


def y_of_lat(lat) -> np.ndarray:
    """Web Mercator y (m) of latitudes (degrees), clipped to the square's edge (:data:`MAX_LAT`)."""
    lat = np.clip(np.asarray(lat, dtype=np.float64), -MAX_LAT, MAX_LAT)
    return qm.WGS84_A * np.log(np.tan(np.pi / 4 + np.radians(lat) / 2))


def lon_of_x(x) -> np.ndarray:
    """Longitudes (degrees) of Web Mercator x (m)."""
    return np.degrees(np.asarray(x, dtype=np.float64) / qm.WGS84_A)


def lat_of_y(y) -> np.ndarray:
    """Latitudes (degrees) of Web Mercator y (m)."""
    return np.degrees(np.arctan(np.sinh(np.asarray(y, dtype=np.float64) / qm.WGS84_A)))


def mercator_tile_bounds(z: int, x: int, y: int) -> tuple[float, float, float, float]:
    """(west, south, east, north) in degrees of the Web Mercator tile (z, x, y), rows from the north."""
    size = 2 * MERCATOR_HALF / 2 ** z
    west, east = -MERCATOR_HALF + x * size, -MERCATOR_HALF + (x + 1) * size
    north, south = MERCATOR_HALF - y * size, MERCATOR_HALF - (y + 1) * size
    return (float(lon_of_x(west)), float(lat_of_y(south)), float(lon_of_x(east)), float(lat_of_y(north)))


def mercator_tiles_covering(z: int, bounds) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)``, inclusive: the Web Mercator tiles of zoom z (rows from the north) that meet the
    lon/lat rectangle ``bounds`` = (west, south, east, north) in a part of positive area."""
    west, south, east, north = bounds
    n = 2 ** z
    size = 2 * MERCATOR_HALF / n
    fx0, fx1 = (x_of_lon(west) + MERCATOR_HALF) / size, (x_of_lon(east) + MERCATOR_HALF) / size
    fy0, fy1 = (MERCATOR_HALF - y_of_lat(north)) / size, (MERCATOR_HALF - y_of_lat(south)) / size

    def first(f):
        return min(n - 1, max(0, int(math.floor(f))))

    def last(f):  # a rectangle ending on a tile's edge does not meet the next tile
        return min(n - 1, max(0, int(math.ceil(f)) - 1))

    return first(fx0), first(fy0), last(fx1), last(fy1)


@dataclass(frozen=True)
class PixelLattice:
    """A terrain-RGB tile's lattice: (W + 1) x (W + 1) points, ``lon`` west to east, ``lat`` south to north,
    ``z`` their heights (rows south to north), ``grid`` the same heights evenly spaced in local metres (the
    simplifiers'), ``pixels`` W."""

    bounds: tuple
    lon: np.ndarray
    lat: np.ndarray
    lon0: float
    lat0: float
    z: np.ndarray
    grid: HeightGrid
    pixels: int

    def to_local(self, lon, lat) -> tuple[np.ndarray, np.ndarray]:
        return equirectangular(lon, lat, self.lon0, self.lat0)

    def tile_heights(self, heights: np.ndarray) -> np.ndarray:
        """The W x W pixels (rows from the north) of lattice heights (rows from the south)."""
        w = self.pixels
        return heights[::-1][:w, :w]


def pixel_lattice(grid: HeightGrid, z: int, x: int, y: int, rectangle, frame, pixels: int = DEFAULT_PIXELS,
                  name: str = "grid") -> PixelLattice:
    """The lattice of terrain-RGB tile ``(z, x, y)`` (the module docstring)."""
    size = 2 * MERCATOR_HALF / 2 ** z
    steps = np.arange(pixels + 1) / pixels
    lon = lon_of_x(-MERCATOR_HALF + (x + steps) * size)
    lat = lat_of_y(MERCATOR_HALF - (y + steps) * size)[::-1]  # south to north
    rw, rs, re_, rn = rectangle
    heights, lon0, lat0, even = sample_lattice(grid, frame, lon, lat, name, np.clip(lon, rw, re_),
                                               np.clip(lat, rs, rn))
    return PixelLattice(mercator_tile_bounds(z, x, y), lon, lat, lon0, lat0, heights, even, int(pixels))


def encode_png(heights: np.ndarray, mesh: tuple[int, int] | None = None) -> bytes:
    """A terrain-RGB PNG of (rows from the north) heights in metres, rounded to 0.1 m. ``mesh``: the vertices
    and triangles of the surface they were taken from, kept in a text chunk (``terrainvis-mesh``) that a
    resumed run reads back; no other metadata, so the same heights give the same bytes."""
    from PIL import Image, PngImagePlugin

    info = None
    if mesh is not None:
        info = PngImagePlugin.PngInfo()
        info.add_text(_MESH_KEY, f"{int(mesh[0])} {int(mesh[1])}")
    buf = io.BytesIO()
    Image.fromarray(rgb_encode(heights), mode="RGB").save(buf, format="PNG", compress_level=6, pnginfo=info)
    return buf.getvalue()


def decode_png(data: bytes) -> np.ndarray:
    """The heights (m, rows from the north) of a terrain-RGB PNG's bytes."""
    return _decoded(data)[0]


def _decoded(data: bytes) -> tuple[np.ndarray, tuple[int, int] | None]:
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        im.load()
        text = getattr(im, "text", {}).get(_MESH_KEY)
        heights = rgb_heights(np.asarray(im.convert("RGB")))
    try:
        mesh = tuple(int(v) for v in text.split()) if text else None
    except ValueError:
        mesh = None
    return heights, mesh if mesh is not None and len(mesh) == 2 else None


def _surface(lat_: PixelLattice, tin: TIN) -> np.ndarray:
    """A simplified surface (the even grid's frame) at the lattice's points, rows from the south."""
    g = lat_.grid
    X, Y = np.meshgrid(g.xs, g.ys)
    return tin.height_at(np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape)


def make_rgb_tile(lat_: PixelLattice, method: str | None, budget: float | None):
    """Simplify (or not), rasterize, encode, measure; retries and the whole lattice as the fallback."""
    want = lat_.tile_heights(lat_.z)

    def encode(tin):
        surface = _surface(lat_, tin)
        if not np.isfinite(surface).all():
            return f"{method}'s mesh does not cover the lattice"
        data = encode_png(lat_.tile_heights(surface), (tin.n_vertices, tin.n_faces))
        return Made(data, float(np.abs(decode_png(data) - want).max()), tin.n_vertices, tin.n_faces), RGB_STEP

    fallback = None
    if method is not None:
        made, fallback = within_budget(lat_.grid, method, budget, encode)
        if made is not None:
            return made
    n = lat_.pixels + 1
    mesh = (n * n, 2 * (n - 1) * (n - 1))
    data = encode_png(want, mesh)
    return Made(data, float(np.abs(decode_png(data) - want).max()), *mesh, fallback)


def kept_rgb_tile(data: bytes, lat_: PixelLattice, budget: float | None):
    """An unfinished run's tile, read and measured again: kept when it decodes and meets its budget."""
    try:
        got, mesh = _decoded(data)
    except (OSError, ValueError, SyntaxError):
        return None
    want = lat_.tile_heights(lat_.z)
    if got.shape != want.shape or mesh is None:
        return None
    err = float(np.abs(got - want).max())
    if not err <= ((0.0 if budget is None else budget) + 0.5 * RGB_STEP) * (1 + TILE_BUDGET_REL):
        return None
    n = lat_.pixels + 1
    whole = budget is not None and mesh[0] == n * n
    return Made(b"", err, *mesh, "the whole lattice (kept from the unfinished run)" if whole else None)
