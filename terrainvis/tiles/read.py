"""Reading terrain tilesets back: one zoom's tiles over a DEM stitched into one TIN in the DEM's frame.

:func:`open_tileset` says what a folder holds, :func:`stitch_zoom` makes the TIN that
:func:`terrainvis.evaluate` measures as it measures any simplification.

Formats
-------
* **Cesium quantized-mesh-1.0**: ``layer.json`` (``"format": "quantized-mesh-1.0"``) and
  the tiles its ``tiles`` template names (``{z}/{x}/{y}.terrain``, gzip-compressed or
  not). ``layer.json``'s ``projection`` is ``EPSG:4326`` (Cesium's geographic tiling: two
  tiles at zoom 0) or ``EPSG:3857`` (Web Mercator: one tile at zoom 0), its ``scheme``
  ``tms`` (rows from the south, the default) or ``xyz`` / ``slippyMap`` (rows from the
  north). As Cesium does, a vertex's longitude and latitude are linear in its ``u`` and
  ``v`` across the tile's longitude/latitude rectangle, in either projection. Extensions
  (normals, water mask, metadata) are not read.
* **terrain-RGB**: PNG (or WebP) tiles ``{z}/{x}/{y}.png`` in Web Mercator XYZ rows,
  height = -10000 + (R * 65536 + G * 256 + B) * 0.1 m (Mapbox's encoding). A tile of
  W x W pixels is meshed as deck.gl's TerrainLayer meshes it: pixel (row r, column c) is
  the point at the fraction (c / W, r / W) of the tile from its north-west corner, the
  (W + 1)-th row and column are the southern and eastern neighbours' first ones (deck.gl
  repeats the tile's last ones instead, which we do only where the neighbour is absent:
  its step along every seam is one a single surface cannot hold), and the mesh is
  Martini's (``pymartini``, W a power of two) or Delatin's (``pydelatin``) at the zoom's
  ``max_error``, or the whole grid of pixels (each cell split along the diagonal from
  (r, c) to (r + 1, c + 1)).

Stitching
---------
Every tile's vertices are put on one integer lattice of the zoom (a tile's quantized
``u``, ``v`` or its pixel column and row, offset by the tile's column and row times the
tile's width in steps), so the vertices neighbouring tiles share on their common edge have
exactly equal positions:

1. each tile's triangles of zero area (skirts, whose vertices repeat the edge's at a lower
   height) and the vertices no triangle then uses are dropped;
2. vertices at one position are merged into one, at the mean of their heights (two tiles
   quantize one edge vertex's height each in its own range);
3. a vertex of one tile inside an edge of its neighbour's (each tile is simplified on its
   own, so their edges need not share every vertex) splits the neighbour's triangle there:
   the seams are closed at the heights the tiles give their own edge vertices;
4. the vertices go to longitude and latitude, through pyproj to the DEM's CRS, and to the
   DEM's own frame (its ``xy_to_native``); positions within rounding of the footprint's edges
   are put on them;
5. the TIN is clipped to the DEM's footprint: a triangle across its edge keeps its part
   inside, triangulated, its new vertices on the edge at the heights of the triangle's plane
   (a new vertex on a shared edge is made once, for both triangles).

The edges of a tile are straight in the DEM's frame between its projected vertices (as any
renderer draws them after projecting its vertices), so the stitched surface is the tiles'
up to the curvature of the projection within one triangle.

Heights are taken as in the DEM's vertical datum. Tiles in another datum (quantized-mesh
tiles from cesium-terrain-builder hold the source DEM's heights, usually orthometric;
Cesium World Terrain holds ellipsoidal heights) are brought to the DEM's with
``offset``, the height added to every tile's heights: for a DEM of orthometric heights
and tiles of ellipsoidal ones, ``offset`` is minus the geoid undulation N of the area (N is
about -30 m around Cumberland, Tennessee: ``offset`` +30 m). A constant is exact over an area where the
undulation varies by less than the error that matters.
"""

from __future__ import annotations

import gzip
import json
import math
import re
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.terrain import TIN, HeightGrid
from . import quantized_mesh as qm
from .terrain_rgb import MERCATOR_HALF, lat_of_y, lon_of_x, rgb_encode, rgb_heights, x_of_lon, y_of_lat

__all__ = ["Tiles", "open_tileset", "stitch_zoom", "MESHERS", "FORMATS", "PROJECTIONS", "SCHEMES",
           "rgb_heights", "rgb_encode"]

#: The formats read.
FORMATS = ("quantized-mesh-1.0", "terrain-rgb")
#: The tilings' projections (``layer.json``'s ``projection``).
PROJECTIONS = ("EPSG:4326", "EPSG:3857")
#: The row orders (``layer.json``'s ``scheme``): TMS rows from the south, XYZ rows from the north.
SCHEMES = {"tms": "tms", "xyz": "xyz", "slippymap": "xyz"}
#: How a terrain-RGB tile is meshed (deck.gl's TerrainLayer's tesselators, and the whole grid).
MESHERS = ("martini", "delatin", "grid")
#: Web Mercator's half-width (m): pi times WGS84's semi-major axis.
_RGB_SUFFIXES = (".png", ".webp")
_NUMBER = re.compile(r"^\d+$")


@dataclass(frozen=True)
class Tiles:
    """A tileset folder as :func:`open_tileset` read it.

    Attributes
    ----------
    path : Path
    format : str
        One of :data:`FORMATS`.
    projection : str
        ``"EPSG:4326"`` or ``"EPSG:3857"``.
    scheme : str
        ``"tms"`` or ``"xyz"``.
    template : str
        The tiles' path under ``path``, with ``{z}``, ``{x}`` and ``{y}``.
    zooms : tuple of int
        The zooms it holds tiles of (``layer.json``'s ``available``, else the folders).
    """

    path: Path
    format: str
    projection: str
    scheme: str
    template: str
    zooms: tuple

    def tile_path(self, z: int, x: int, y: int) -> Path:
        """The file of tile (z, x, y), its row ``y`` counted as the scheme counts it."""
        return self.path / self.template.format(z=z, x=x, y=y)

    def count(self, z: int) -> tuple[int, int]:
        """``(columns, rows)`` of zoom ``z``."""
        return (2 ** (z + 1), 2 ** z) if self.projection == "EPSG:4326" else (2 ** z, 2 ** z)


def _zooms_text(zooms) -> str:
    return ", ".join(str(z) for z in zooms) if zooms else "none"


def open_tileset(path, *, name: str = "tileset") -> Tiles:
    """What the tileset folder ``path`` holds: its format, projection, row scheme, tile paths and zooms.

    A folder with a ``layer.json`` is what that file declares (``format``, ``projection``,
    ``scheme``, ``tiles``; without a ``format``, ``.png`` or ``.webp`` tiles are terrain-RGB,
    in Web Mercator XYZ rows unless it says otherwise, and others quantized-mesh-1.0, in
    Cesium's geographic TMS tiling unless it says otherwise); one without it that holds
    ``{z}/{x}/{y}.png`` (or ``.webp``) tiles is terrain-RGB in Web Mercator XYZ rows.

    Raises
    ------
    ValueError
        A folder that does not exist or holds no tileset, a ``layer.json`` that cannot be
        read, an unknown format, scheme or projection: one line naming ``name``.
    """
    p = Path(path)
    if not p.is_dir():
        raise ValueError(f"{name} must be a tileset folder, got {str(p)!r}, which is not a folder")
    layer = p / "layer.json"
    if layer.is_file():
        try:
            meta = json.loads(layer.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise ValueError(f"{name}: {str(layer)!r} is not a readable JSON file ({exc})") from None
        if not isinstance(meta, dict):
            raise ValueError(f"{name}: {str(layer)!r} must hold a JSON object, got {type(meta).__name__}")
        templates = meta.get("tiles") or ["{z}/{x}/{y}.terrain"]
        if not (isinstance(templates, list) and templates and isinstance(templates[0], str)):
            raise ValueError(f"{name}: {str(layer)!r}'s tiles must be a list of path templates, got {templates!r}")
        template = templates[0].split("?")[0].replace("{version}", str(meta.get("version", "")))
        if not all(k in template for k in ("{z}", "{x}", "{y}")) or re.search(r"\{(?!z\}|x\}|y\})", template):
            raise ValueError(f"{name}: {str(layer)!r}'s tiles template must name {{z}}, {{x}} and {{y}} only, got "
                             f"{templates[0]!r}")
        image = template.lower().endswith(_RGB_SUFFIXES)
        fmt = str(meta.get("format", "terrain-rgb" if image else "quantized-mesh-1.0"))
        if fmt == "quantized-mesh-1.0" and not image:
            default_projection, default_scheme = "EPSG:4326", "tms"  # Cesium's defaults
        elif fmt.lower() in ("terrain-rgb", "png", "pngraw", "webp") and image:
            fmt, default_projection, default_scheme = "terrain-rgb", "EPSG:3857", "xyz"  # TileJSON's defaults
        else:
            raise ValueError(f"{name}: {str(layer)!r} declares format {fmt!r} with tiles {template!r}; expected "
                             "quantized-mesh-1.0 with .terrain tiles, or terrain-rgb (png, pngraw, webp) with .png or "
                             ".webp tiles")
        projection = str(meta.get("projection", default_projection)).upper()
        if projection not in PROJECTIONS:
            raise ValueError(f"{name}: {str(layer)!r} declares projection {meta.get('projection')!r}; expected "
                             f"{' or '.join(PROJECTIONS)}")
        scheme = SCHEMES.get(str(meta.get("scheme", default_scheme)).lower())
        if scheme is None:
            raise ValueError(f"{name}: {str(layer)!r} declares scheme {meta.get('scheme')!r}; expected tms, xyz "
                             "or slippyMap")
        available = meta.get("available")
        zooms = _available_zooms(available) if isinstance(available, list) else None
        if zooms is None:
            zooms = _folder_zooms(p)
        return Tiles(p, fmt, projection, scheme, template, zooms)
    zooms = _folder_zooms(p, _RGB_SUFFIXES)
    if zooms:
        suffix = _rgb_suffix(p, zooms[0])
        return Tiles(p, "terrain-rgb", "EPSG:3857", "xyz", "{z}/{x}/{y}" + suffix, zooms)
    if _folder_zooms(p, (".terrain",)):
        raise ValueError(f"{name}: {str(p)!r} holds .terrain tiles but no layer.json, which says their scheme and "
                         "projection; add the layer.json the tiler wrote")
    raise ValueError(f"{name} must be a tileset folder (a layer.json with {{z}}/{{x}}/{{y}}.terrain tiles, or "
                     f"{{z}}/{{x}}/{{y}}.png terrain-RGB tiles), got {str(p)!r}, which holds neither")


def _available_zooms(available: list) -> tuple:
    return tuple(z for z, ranges in enumerate(available) if isinstance(ranges, list) and ranges)


def _folder_zooms(p: Path, suffixes=None) -> tuple:
    out = []
    for zd in p.iterdir():
        if not (zd.is_dir() and _NUMBER.match(zd.name)):
            continue
        for xd in zd.iterdir():
            if xd.is_dir() and _NUMBER.match(xd.name) and any(
                    f.is_file() and (suffixes is None or f.suffix.lower() in suffixes) for f in xd.iterdir()):
                out.append(int(zd.name))
                break
    return tuple(sorted(out))


def _rgb_suffix(p: Path, z: int) -> str:
    for xd in sorted((p / str(z)).iterdir()):
        for f in sorted(xd.iterdir()) if xd.is_dir() else ():
            if f.suffix.lower() in _RGB_SUFFIXES:
                return f.suffix
    return ".png"


# ---------------------------------------------------------------------- the tiling's geometry
def _tile_float(tiles: Tiles, z: int, lon: np.ndarray, lat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fractional tile column and TMS row (from the south) of positions at zoom ``z``."""
    if tiles.projection == "EPSG:4326":
        size = 180.0 / 2 ** z
        return (lon + 180.0) / size, (lat + 90.0) / size
    x, y = x_of_lon(lon), y_of_lat(lat)
    size = 2 * MERCATOR_HALF / 2 ** z
    return (x + MERCATOR_HALF) / size, (y + MERCATOR_HALF) / size


def _to_lonlat(tiles: Tiles, z: int, U: np.ndarray, V: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Longitude and latitude of positions on the zoom's integer lattice (``steps`` per tile, V from the south)."""
    n = steps * 2 ** z
    if tiles.projection == "EPSG:4326":
        return -180.0 + U / n * 180.0, -90.0 + V / n * 180.0
    if tiles.format == "terrain-rgb":  # linear in Web Mercator across the tile
        x = -MERCATOR_HALF + U / n * 2 * MERCATOR_HALF
        y = -MERCATOR_HALF + V / n * 2 * MERCATOR_HALF
        return lon_of_x(x), lat_of_y(y)
    # quantized-mesh in Web Mercator tiles: linear in latitude across each tile's latitude range (as Cesium)
    lon = -180.0 + U / n * 360.0
    row = np.minimum(V // steps, 2 ** z - 1)
    size = 2 * MERCATOR_HALF / 2 ** z
    south = lat_of_y(-MERCATOR_HALF + row * size)
    north = lat_of_y(-MERCATOR_HALF + (row + 1) * size)
    return lon, south + (V - row * steps) / steps * (north - south)


def _footprint_lonlat(grid: HeightGrid, frame, n: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """The DEM footprint's boundary (``n`` points a side, counter-clockwise in the grid's frame) in lon/lat."""
    x0, x1, y0, y1 = grid.extent
    t = np.linspace(0.0, 1.0, n, endpoint=False)
    bx = np.concatenate([x0 + t * (x1 - x0), np.full(n, x1), x1 - t * (x1 - x0), np.full(n, x0)])
    by = np.concatenate([np.full(n, y0), y0 + t * (y1 - y0), np.full(n, y1), y1 - t * (y1 - y0)])
    return frame.to_lonlat(bx, by)


def _needed_tiles(tiles: Tiles, z: int, grid: HeightGrid, frame) -> tuple[set, tuple]:
    """The tiles of zoom ``z`` (column, TMS row) over the DEM's footprint, and the bounding range of them.

    A tile is needed when the footprint covers part of it: its boundary passes through the
    tile (sampled at 1/64 of a tile, a little inside the footprint so that a footprint whose
    edge runs along a tile edge does not claim the neighbour) or the tile's centre lies inside it.
    """
    lon, lat = _footprint_lonlat(grid, frame)
    if not (np.isfinite(lon).all() and np.isfinite(lat).all()):
        raise ValueError(f"the DEM's footprint has no longitude and latitude everywhere in its CRS {frame.crs_text!r}")
    if lon.max() - lon.min() > 180.0:
        raise ValueError("the DEM's footprint crosses the antimeridian: reading a tileset over it is not supported")
    tx, ty = _tile_float(tiles, z, lon, lat)
    # densify to 1/64 of a tile, and pull the ring a little inside towards its centre
    ring = np.column_stack([tx, ty])
    nxt = np.roll(ring, -1, axis=0)
    k = np.maximum(1, np.ceil(np.abs(nxt - ring).max(axis=1) * 64)).astype(np.int64)
    idx = np.repeat(np.arange(ring.shape[0]), k)
    frac = (np.arange(idx.size) - np.repeat(np.cumsum(k) - k, k)) / np.repeat(k, k)
    pts = ring[idx] + (nxt[idx] - ring[idx]) * frac[:, None]
    from ..tolerances import TILE_RING_INSET_REL

    pts = pts + (ring.mean(axis=0) - pts) * TILE_RING_INSET_REL
    nx, ny = tiles.count(z)
    cols = np.clip(np.floor(pts[:, 0]).astype(np.int64), 0, nx - 1)
    rows = np.clip(np.floor(pts[:, 1]).astype(np.int64), 0, ny - 1)
    needed = set(zip(cols.tolist(), rows.tolist()))
    c0, c1, r0, r1 = int(cols.min()), int(cols.max()), int(rows.min()), int(rows.max())
    cx, cy = np.meshgrid(np.arange(c0, c1 + 1) + 0.5, np.arange(r0, r1 + 1) + 0.5)
    inside = _inside(ring, cx.ravel(), cy.ravel())
    needed |= set(zip(cx.ravel()[inside].astype(np.int64).tolist(), cy.ravel()[inside].astype(np.int64).tolist()))
    return needed, (c0, r0, c1, r1)


def _inside(ring: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Points inside the closed polygon ``ring`` (crossing number), in blocks."""
    out = np.zeros(px.size, dtype=bool)
    a, b = ring, np.roll(ring, -1, axis=0)
    for s in range(0, px.size, 256):
        x, y = px[s:s + 256, None], py[s:s + 256, None]
        cross = (a[None, :, 1] > y) != (b[None, :, 1] > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xi = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
        out[s:s + 256] = ((cross & (x < xi)).sum(axis=1) % 2) == 1
    return out


# ---------------------------------------------------------------------- reading tiles
@dataclass
class _Piece:
    """One tile's mesh on the zoom's integer lattice: positions U, V (int64), heights, triangles."""

    U: np.ndarray
    V: np.ndarray
    h: np.ndarray
    tri: np.ndarray


def _read_qm(path: Path, col: int, row: int) -> _Piece:
    try:
        data = path.read_bytes()
        dec = qm.decode_tile(data, (0.0, 0.0, 1.0, 1.0))
    except (ValueError, EOFError, struct.error, zlib.error, gzip.BadGzipFile, OSError) as exc:
        raise ValueError(f"tile {str(path)!r} is not a readable quantized-mesh-1.0 tile: {exc}") from None
    if not dec.triangles.shape[0]:
        raise ValueError(f"tile {str(path)!r} is not a readable quantized-mesh-1.0 tile: it has no triangles")
    if not (np.isfinite(dec.min_height) and np.isfinite(dec.max_height)):
        raise ValueError(f"tile {str(path)!r} is not a readable quantized-mesh-1.0 tile: its height range "
                         f"[{dec.min_height}, {dec.max_height}] is not finite")
    Q = qm.QUANTIZED_MAX
    return _Piece(col * Q + dec.u, row * Q + dec.v, dec.height.astype(np.float64), dec.triangles)


def _rgb_pixels(path: Path, width: list) -> np.ndarray:
    """A terrain-RGB tile's heights (w x w, rows from the north); ``width`` holds the zoom's tile width."""
    try:
        from PIL import Image
    except ImportError as exc:
        raise ImportError('reading terrain-RGB tiles needs Pillow: pip install "terrainvis[tiles]"') from exc
    try:
        with Image.open(path) as im:
            im.load()
            rgb = np.asarray(im.convert("RGB"))
    except (OSError, ValueError, SyntaxError) as exc:
        raise ValueError(f"tile {str(path)!r} is not a readable terrain-RGB image: {exc}") from None
    h, w = rgb.shape[:2]
    if h != w or w < 2:
        raise ValueError(f"tile {str(path)!r} must be a square image of at least 2 x 2 pixels, got {w} x {h}")
    if width[0] is None:
        width[0] = w
    elif w != width[0]:
        raise ValueError(f"tile {str(path)!r} is {w} x {w} pixels, and the zoom's other tiles {width[0]} x {width[0]}")
    return rgb_heights(rgb)


def _rgb_pieces(pixels: dict, mesher: str, max_error: float | None, paths: dict) -> list:
    """Each terrain-RGB tile ((col, TMS row) -> heights) meshed over its (w + 1) x (w + 1) points.

    The extra column and row are the eastern and southern neighbours' first column and row
    (and the south-eastern neighbour's first pixel) when those tiles are there; otherwise the
    tile's own last ones are repeated, as deck.gl does for every tile (which leaves a step
    along every seam, one a single surface cannot hold).
    """
    out = []
    for (col, row), own in pixels.items():
        w = own.shape[0]
        z = np.empty((w + 1, w + 1))
        z[:w, :w] = own
        east, south, corner = pixels.get((col + 1, row)), pixels.get((col, row - 1)), pixels.get((col + 1, row - 1))
        z[:w, w] = east[:, 0] if east is not None else own[:, -1]
        z[w, :w] = south[0, :] if south is not None else z[w - 1, :w]
        z[w, w] = corner[0, 0] if corner is not None else (south[0, -1] if south is not None else z[w - 1, w])
        rows, cols, tri = _mesh_rgb(z, mesher, max_error, paths[(col, row)])
        # pixel row r is the fraction r / w of the tile from its north edge: v = w - r from the south
        out.append(_Piece(col * w + cols, row * w + (w - rows), z[rows, cols], tri))
    return out


def _mesh_rgb(z: np.ndarray, mesher: str, max_error: float | None, path: Path):
    """Rows, columns (int64) and triangles of a tile's heights ``z`` ((w+1) x (w+1)) meshed by ``mesher``."""
    n = z.shape[0]
    if mesher == "grid":
        r, c = np.divmod(np.arange(n * n), n)
        a = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
        tri = np.concatenate([np.column_stack([a, a + n + 1, a + 1]), np.column_stack([a, a + n, a + n + 1])])
        return r.astype(np.int64), c.astype(np.int64), tri
    if mesher == "martini":
        if (n - 1) & (n - 2):
            raise ValueError(f"tile {str(path)!r} is {n - 1} pixels wide; Martini meshes tiles of a power of two "
                             "(use mesh='delatin' or 'grid')")
        try:
            from pymartini import Martini
        except ImportError as exc:
            raise ImportError('meshing with Martini needs pymartini: pip install "terrainvis[peers]"') from exc
        tile = Martini(n).create_tile(z.astype(np.float32).ravel())
        vertices, triangles = tile.get_mesh(float(max_error))
        v = np.asarray(vertices, dtype=np.int64).reshape(-1, 2)
        return v[:, 1], v[:, 0], np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    try:
        from pydelatin import Delatin
    except ImportError as exc:
        raise ImportError('meshing with Delatin needs pydelatin: pip install "terrainvis[peers]"') from exc
    d = Delatin(z, max_error=float(max_error))
    v = np.rint(np.asarray(d.vertices, dtype=np.float64)[:, :2]).astype(np.int64)
    return n - 1 - v[:, 1], v[:, 0], np.asarray(d.triangles, dtype=np.int64).reshape(-1, 3)  # its y counts up


# ---------------------------------------------------------------------- stitching
def _clean(piece: _Piece) -> _Piece:
    """Counter-clockwise triangles of positive area on the lattice (skirts and degenerate ones dropped), and
    only the vertices they use."""
    from ..core.mesh import signed_area2  # core.mesh imports numba: not at import time

    U, V, tri = piece.U, piece.V, piece.tri
    area = signed_area2(np.column_stack([U, V]), tri)
    tri = np.where((area < 0)[:, None], tri[:, [0, 2, 1]], tri)[area != 0]
    used = np.unique(tri)
    new = np.full(U.size, -1, dtype=np.int64)
    new[used] = np.arange(used.size)
    return _Piece(U[used], V[used], piece.h[used], new[tri])


def _merge(pieces: list) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pieces as one mesh: U, V, h (the mean at a shared position), triangles."""
    U = np.concatenate([p.U for p in pieces])
    V = np.concatenate([p.V for p in pieces])
    h = np.concatenate([p.h for p in pieces])
    starts = np.cumsum([0] + [p.U.size for p in pieces])[:-1]
    tri = np.concatenate([p.tri + s for p, s in zip(pieces, starts)])
    keys, inverse = np.unique(np.column_stack([U, V]), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    k = keys.shape[0]
    height = np.bincount(inverse, weights=h, minlength=k) / np.bincount(inverse, minlength=k)
    tri = inverse[tri]
    keep = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
    return keys[:, 0].copy(), keys[:, 1].copy(), height, tri[keep]


def _close_seams(U: np.ndarray, V: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Triangles with every vertex that lies inside one of their boundary edges (a T-junction on a seam) made
    a vertex of theirs: such a triangle's ring, with those vertices, is triangulated again."""
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    owner = np.tile(np.arange(tri.shape[0]), 3)
    _, inv, counts = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True, return_counts=True)
    lone = np.flatnonzero(counts[inv.reshape(-1)] == 1)
    if not lone.size:
        return tri
    on_edge = np.unique(edges[lone])  # vertices on some boundary edge: the only candidates
    # each vertex keyed by (line, position along it), sorted: vertical lines by (U, V), horizontal by (V, U)
    lines = {}
    for name, line, along in (("u", U, V), ("v", V, U)):
        key = line[on_edge] * (1 << 32) + along[on_edge]
        order = np.argsort(key, kind="stable")
        lines[name] = (key[order], on_edge[order])
    inserts: dict[int, dict] = {}
    for e in lone.tolist():
        a, b = int(edges[e, 0]), int(edges[e, 1])
        if U[a] == U[b]:
            keys, ids = lines["u"]
            line, lo, hi = U[a], V[a], V[b]
        elif V[a] == V[b]:
            keys, ids = lines["v"]
            line, lo, hi = V[a], U[a], U[b]
        else:
            continue
        first = np.searchsorted(keys, line * (1 << 32) + min(lo, hi), side="right")
        last = np.searchsorted(keys, line * (1 << 32) + max(lo, hi), side="left")
        if last > first:
            inner = ids[first:last].tolist()
            inserts.setdefault(int(owner[e]), {})[(a, b)] = inner if lo < hi else inner[::-1]
    if not inserts:
        return tri
    pos = np.column_stack([U, V])
    keep = np.ones(tri.shape[0], dtype=bool)
    extra = []
    for t, edge_inserts in inserts.items():
        keep[t] = False
        ring = []
        for a, b in ((tri[t, 0], tri[t, 1]), (tri[t, 1], tri[t, 2]), (tri[t, 2], tri[t, 0])):
            ring.append(int(a))
            ring += edge_inserts.get((int(a), int(b)), [])
        extra += _triangulate_convex(ring, pos)
    return np.concatenate([tri[keep], np.array(extra, dtype=np.int64).reshape(-1, 3)])


def _area2(pos: np.ndarray, a: int, b: int, c: int):
    return (pos[b, 0] - pos[a, 0]) * (pos[c, 1] - pos[a, 1]) - (pos[c, 0] - pos[a, 0]) * (pos[b, 1] - pos[a, 1])


def _triangulate_convex(ring: list, pos: np.ndarray) -> list | None:
    """Triangles (counter-clockwise, each of positive area) of a convex counter-clockwise ring of vertex indices
    that may hold collinear runs, every vertex of the ring used; None when the ring has no area.

    Ears are cut at vertices whose triangle has positive area and whose removal leaves a ring
    of positive area (or the last triangle): in a convex ring of positive area one always
    exists (a vertex at the end of a collinear run, next to a vertex off it).
    """
    ring = list(ring)
    out = []
    while len(ring) > 3:
        n = len(ring)
        for k in range(n):
            p, c, q = ring[k - 1], ring[k], ring[(k + 1) % n]
            if _area2(pos, p, c, q) <= 0:
                continue
            rest = ring[:k] + ring[k + 1:]
            if any(_area2(pos, rest[0], rest[i], rest[i + 1]) > 0 for i in range(1, len(rest) - 1)):
                out.append((p, c, q))
                ring = rest
                break
        else:
            return None
    if _area2(pos, *ring) <= 0:
        return None
    return out + [tuple(ring)]


def _lattice_mesh(pieces: list) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The zoom's pieces as one mesh on the integer lattice, seams closed (steps 1 to 3 of the module docstring)."""
    U, V, h, tri = _merge([_clean(p) for p in pieces])
    return U, V, h, _close_seams(U, V, tri)


# ---------------------------------------------------------------------- into the DEM's frame, clipped
def _clip(xy: np.ndarray, h: np.ndarray, tri: np.ndarray, extent) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The TIN (counter-clockwise in ``xy``) clipped to the rectangle ``extent`` (xmin, xmax, ymin, ymax).

    Triangles inside are kept, triangles beyond one side dropped, the others clipped side by
    side (Sutherland-Hodgman) and triangulated. A point where an edge crosses a side is made
    once per (edge, side), from the edge's endpoints in one order, so the triangles on both
    sides of the edge share it; its coordinate across the side is the side's exactly.
    """
    xmin, xmax, ymin, ymax = extent
    x, y = xy[:, 0], xy[:, 1]
    tx, ty = x[tri], y[tri]
    inside = (tx >= xmin).all(1) & (tx <= xmax).all(1) & (ty >= ymin).all(1) & (ty <= ymax).all(1)
    outside = (tx <= xmin).all(1) | (tx >= xmax).all(1) | (ty <= ymin).all(1) | (ty >= ymax).all(1)
    cut = np.flatnonzero(~inside & ~outside)
    pts = [list(p) for p in np.column_stack([xy, h])]
    made: dict = {}
    # each side as (axis, value, sign): inside where sign * (coordinate - value) >= 0
    sides = ((0, xmin, 1.0), (0, xmax, -1.0), (1, ymin, 1.0), (1, ymax, -1.0))

    def crossing(a: int, b: int, s: int) -> int:
        key = (min(a, b), max(a, b), s)
        k = made.get(key)
        if k is None:
            p, q = (pts[a], pts[b]) if a < b else (pts[b], pts[a])
            axis, value, _ = sides[s]
            t = (value - p[axis]) / (q[axis] - p[axis])
            point = [p[i] + t * (q[i] - p[i]) for i in range(3)]
            point[axis] = value
            other = 1 - axis
            lo, hi = sorted((p[other], q[other]))
            point[other] = min(max(point[other], lo), hi)
            k = made[key] = len(pts)
            pts.append(point)
        return k

    new_tri = []
    for t in cut.tolist():
        ring = [int(v) for v in tri[t]]
        for s, (axis, value, sign) in enumerate(sides):
            if not ring:
                break
            out = []
            for i in range(len(ring)):
                a, b = ring[i - 1], ring[i]
                da, db = sign * (pts[a][axis] - value), sign * (pts[b][axis] - value)
                if db >= 0:
                    if da < 0 and db > 0:
                        out.append(crossing(a, b, s))
                    out.append(b)
                elif da > 0:
                    out.append(crossing(a, b, s))
            ring = out
        if len(ring) < 3:
            continue
        P = np.array([pts[v] for v in ring])
        local = _triangulate_convex(list(range(len(ring))), P)
        if local is None:  # no area left inside
            continue
        new_tri += [(ring[a], ring[b], ring[c]) for a, b, c in local]
    P = np.array(pts, dtype=np.float64).reshape(-1, 3)
    faces = np.concatenate([tri[inside], np.array(new_tri, dtype=np.int64).reshape(-1, 3)])
    used = np.unique(faces)
    new = np.full(P.shape[0], -1, dtype=np.int64)
    new[used] = np.arange(used.size)
    return P[used, :2], P[used, 2], new[faces]


def _onto_edges(v: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Coordinates within rounding of ``lo`` or ``hi`` (either side) put exactly on it."""
    from ..tolerances import EDGE_SNAP_REL, ROUNDING_ULPS

    tol = EDGE_SNAP_REL * (hi - lo) + ROUNDING_ULPS * np.spacing(max(abs(lo), abs(hi)))
    v = v.copy()
    v[np.abs(v - lo) <= tol] = lo
    v[np.abs(v - hi) <= tol] = hi
    return v


def _merge_positions(xy: np.ndarray, h: np.ndarray, tri: np.ndarray):
    """Vertices at exactly one position made one (the mean height): a clipped corner made by two triangles."""
    keys, inverse = np.unique(xy, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    if keys.shape[0] == xy.shape[0]:
        return xy, h, tri
    h = np.bincount(inverse, weights=h) / np.bincount(inverse)
    tri = inverse[tri]
    keep = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
    return keys, h, tri[keep]


def _with_path(name: str, tiles) -> str:
    """``name`` and the tileset's path, unless the name already quotes it (evaluate names a folder by itself)."""
    path = str(tiles.path)
    return name if repr(path) in name else f"{name} {path!r}"


def stitch_zoom(grid: HeightGrid, tiles, zoom, *, mesh: str = "grid", max_error: float | None = None,
                offset: float = 0.0, name: str = "tileset", frame=None) -> TIN:
    """One zoom of a tileset over ``grid``: its tiles stitched into one TIN in the grid's frame, clipped to its footprint.

    See the module docstring for the formats, the stitching and ``offset``.

    Parameters
    ----------
    grid : HeightGrid
        The DEM: georeferenced (``attrs["crs"]``).
    tiles : Tiles, str or Path
        A tileset (:func:`open_tileset`) or its folder.
    zoom : int
        One of ``tiles.zooms``.
    mesh : {"grid", "martini", "delatin"}
        How terrain-RGB tiles are meshed (unused for quantized-mesh).
    max_error : float, optional
        Martini's and Delatin's maximum error (m); required with them.
    offset : float
        Height (m) added to every tile's heights.
    name : str
        How messages name the tileset.
    frame : optional
        The grid's lon/lat frame (:class:`terrainvis.tiles.tileset._Frame`), when already made.

    Returns
    -------
    TIN
        Counter-clockwise, in ``grid``'s frame, covering its footprint; ``attrs`` records the
        tileset (``tileset``, ``zoom``, ``n_tiles``, ``format``).

    Raises
    ------
    ValueError
        A DEM without a CRS, an absent zoom (the present ones listed), tiles missing over the
        DEM (named), a corrupt tile (named by path), a mesh the stitching cannot make a height
        field of.
    """
    from .tileset import _Frame

    if not isinstance(tiles, Tiles):
        tiles = open_tileset(tiles, name=name)
    if isinstance(zoom, bool) or not isinstance(zoom, (int, np.integer)):
        raise ValueError(f"zoom must be an integer, got {zoom!r}")
    zoom = int(zoom)
    if zoom not in tiles.zooms:
        raise ValueError(f"zoom {zoom} is not in {_with_path(name, tiles)}: its zooms are {_zooms_text(tiles.zooms)}")
    if mesh not in MESHERS:
        raise ValueError(f"mesh must be one of {', '.join(MESHERS)}, got {mesh!r}")
    if tiles.format == "terrain-rgb" and mesh != "grid" and max_error is None:
        raise ValueError(f"mesh={mesh!r} needs the zoom's max_error (m), got none for zoom {zoom}")
    if not (isinstance(offset, (int, float, np.integer, np.floating)) and math.isfinite(offset)):
        raise ValueError(f"offset must be a finite height (m), got {offset!r}")
    frame = _Frame(grid, "original") if frame is None else frame
    needed, (c0, r0, c1, r1) = _needed_tiles(tiles, zoom, grid, frame)
    nx, ny = tiles.count(zoom)
    if tiles.format == "terrain-rgb":  # the neighbours around, when there: their pixels correct the backfilled edges
        c0, r0, c1, r1 = max(c0 - 1, 0), max(r0 - 1, 0), min(c1 + 1, nx - 1), min(r1 + 1, ny - 1)
    pieces, missing, width, pixels, paths = [], [], [None], {}, {}
    for row in range(r0, r1 + 1):
        for col in range(c0, c1 + 1):
            file_row = row if tiles.scheme == "tms" else ny - 1 - row
            path = tiles.tile_path(zoom, col, file_row)
            if not path.is_file():
                if (col, row) in needed:
                    missing.append(f"{zoom}/{col}/{file_row}")
                continue
            if tiles.format == "quantized-mesh-1.0":
                pieces.append(_read_qm(path, col, row))
            else:
                pixels[(col, row)] = _rgb_pixels(path, width)
                paths[(col, row)] = path
    if missing:
        shown = ", ".join(missing[:8]) + (f" and {len(missing) - 8} more" if len(missing) > 8 else "")
        raise ValueError(f"{_with_path(name, tiles)} does not cover the DEM at zoom {zoom}: {len(missing)} tile(s) "
                         f"over its footprint are missing ({shown})")
    if pixels:
        pieces = _rgb_pieces(pixels, mesh, max_error, paths)
    steps = qm.QUANTIZED_MAX if tiles.format == "quantized-mesh-1.0" else width[0]
    U, V, h, tri = _lattice_mesh(pieces)
    lon, lat = _to_lonlat(tiles, zoom, U.astype(np.float64), V.astype(np.float64), steps)
    xy = frame.to_grid(lon, lat)
    if not np.isfinite(xy).all():
        raise ValueError(f"{name}: {int((~np.isfinite(xy).all(axis=1)).sum())} vertices of zoom {zoom} have no "
                         f"position in the DEM's CRS {frame.crs_text!r}")
    xmin, xmax, ymin, ymax = grid.extent
    xy = np.column_stack([_onto_edges(xy[:, 0], xmin, xmax), _onto_edges(xy[:, 1], ymin, ymax)])
    from ..core.mesh import signed_area2  # core.mesh imports numba: not at import time

    area = signed_area2(xy, tri)
    if (area < 0).sum() > (area > 0).sum():  # the grid's y runs south: the same mesh, the other winding
        tri = tri[:, [0, 2, 1]]
    xy, h, tri = _clip(xy, h + float(offset), tri, grid.extent)
    xy, h, tri = _merge_positions(xy, h, tri)
    if not tri.shape[0]:
        raise ValueError(f"{_with_path(name, tiles)} has no triangle over the DEM at zoom {zoom}")
    attrs = {"tileset": str(tiles.path), "zoom": zoom, "n_tiles": len(pieces), "format": tiles.format,
             "method": f"{tiles.path.name}-z{zoom}", "kind": "irregular"}
    return TIN(np.column_stack([xy, h]), tri, attrs=attrs)
