"""Cesium's quantized-mesh-1.0 terrain tiles: an encoder and a decoder, written from the format's specification.

A tile is little-endian binary (https://github.com/CesiumGS/quantized-mesh):

1. the header, 88 bytes: the tile's centre in Earth-centred, Earth-fixed (ECEF) WGS84
   coordinates (3 doubles), its lowest and highest height (2 floats), its bounding sphere
   (centre, radius: 4 doubles) and its horizon occlusion point (3 doubles, in the
   ellipsoid-scaled frame, see :func:`horizon_occlusion_point`);
2. the vertices: their count (uint32), then the ``u``, ``v`` and ``height`` arrays, each
   ``count`` uint16 values in [0, 32767] (``u`` west to east, ``v`` south to north across
   the tile, ``height`` from the lowest to the highest), each stored as zig-zag encoded
   deltas from the value before it (the first from 0);
3. the triangles: their count (uint32), then 3 indices each, counter-clockwise seen from
   above, high-water-mark encoded (the vertices are numbered in the order the triangles
   first use them, and each index is stored as ``highest - index``, where ``highest`` starts
   at 0 and grows by one each time a code is 0). The indices are uint16 when the tile has
   at most 65,536 vertices and uint32 otherwise; uint32 indices start on a 4-byte
   boundary (2 bytes of padding before the triangle count when needed);
4. the edge vertices, west, south, east, north: each a count (uint32) and the indices
   (the width of the triangles'), not encoded: the vertices with ``u == 0``, ``v == 0``,
   ``u == 32767`` and ``v == 32767``.

No extension follows (no normals, no water mask). Tiles are usually served gzip-compressed
(as cesium-terrain-builder writes them); :func:`decode_tile` reads both.
"""

from __future__ import annotations

import gzip
import math
import struct
from dataclasses import dataclass

import numpy as np

from ..tolerances import HORIZON_DENOMINATOR_MIN

__all__ = ["QUANTIZED_MAX", "WGS84_A", "WGS84_B", "lonlat_to_ecef", "to_uv", "horizon_occlusion_point",
           "encode_tile", "decode_tile", "DecodedTile", "height_step"]

#: The largest quantized u, v and height (the format's range is [0, 32767]).
QUANTIZED_MAX = 32767
#: WGS84's semi-major axis (m).
WGS84_A = 6378137.0
#: WGS84's semi-minor axis (m).
WGS84_B = WGS84_A * (1.0 - 1.0 / 298.257223563)
_E2 = 1.0 - (WGS84_B / WGS84_A) ** 2
_HEADER = struct.Struct("<3d2f4d3d")
#: Vertex counts above this take 32-bit indices.
_MAX_16BIT_VERTICES = 65536


def lonlat_to_ecef(lon, lat, height) -> np.ndarray:
    """(n, 3) WGS84 ECEF coordinates (m) of longitudes, latitudes (degrees) and ellipsoidal heights (m).

    >>> lonlat_to_ecef([0.0, 90.0], [0.0, 0.0], [0.0, 10.0]).round(3).tolist()
    [[6378137.0, 0.0, 0.0], [0.0, 6378147.0, 0.0]]
    """
    lam = np.radians(np.asarray(lon, dtype=np.float64))
    phi = np.radians(np.asarray(lat, dtype=np.float64))
    h = np.asarray(height, dtype=np.float64)
    n = WGS84_A / np.sqrt(1.0 - _E2 * np.sin(phi) ** 2)
    x = (n + h) * np.cos(phi) * np.cos(lam)
    y = (n + h) * np.cos(phi) * np.sin(lam)
    z = (n * (1.0 - _E2) + h) * np.sin(phi)
    return np.column_stack([np.atleast_1d(x), np.atleast_1d(y), np.atleast_1d(z)])


def to_uv(lon, lat, bounds) -> tuple[np.ndarray, np.ndarray]:
    """Quantized ``u``, ``v`` (int64 in [0, 32767]) of positions in a tile's ``bounds`` (west, south, east, north).

    Rounded to the nearest step; a position rounding puts a little outside the tile is put on its edge.

    >>> [a.tolist() for a in to_uv([0.0, 45.0, 90.0], [-90.0, 0.0, 90.0], (0.0, -90.0, 90.0, 90.0))]
    [[0, 16384, 32767], [0, 16384, 32767]]
    """
    west, south, east, north = (float(b) for b in bounds)
    u = np.rint((np.asarray(lon, dtype=np.float64) - west) / (east - west) * QUANTIZED_MAX)
    v = np.rint((np.asarray(lat, dtype=np.float64) - south) / (north - south) * QUANTIZED_MAX)
    return (np.clip(u, 0, QUANTIZED_MAX).astype(np.int64), np.clip(v, 0, QUANTIZED_MAX).astype(np.int64))


def horizon_occlusion_point(ecef: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """The horizon occlusion point of points ``ecef`` (n, 3), in the ellipsoid-scaled frame.

    Cesium's ``EllipsoidalOccluder.computeHorizonCullingPoint``: in the frame where the
    WGS84 ellipsoid is the unit sphere (x / a, y / a, z / b), the point lies on the ray
    from the centre of the earth along ``direction`` (the bounding sphere's centre), as
    close as it can while every point of the tile (a point below the ellipsoid taken on
    it) stays behind the horizon of a viewer who cannot see the occlusion point. When a
    point is 90 degrees or more from ``direction`` (a tile of a hemisphere) no such point
    exists; the ray's point at 10**6 earth radii is returned, which no viewer near the
    earth sees behind the horizon, so the tile is never culled that way (Cesium leaves the
    point undefined in that case, with the same effect).

    Parameters
    ----------
    ecef : (n, 3) float64
    direction : (3,) float64
        ECEF, not scaled (the bounding sphere's centre).

    Returns
    -------
    (3,) float64
    """
    radii = np.array([WGS84_A, WGS84_A, WGS84_B])
    d = np.asarray(direction, dtype=np.float64) / radii
    norm = float(np.linalg.norm(d))
    if norm == 0.0:
        d = np.array([1.0, 0.0, 0.0])
    else:
        d = d / norm
    p = np.asarray(ecef, dtype=np.float64) / radii
    mag2 = np.einsum("ij,ij->i", p, p)
    mag = np.sqrt(mag2)
    unit = p / np.where(mag > 0, mag, 1.0)[:, None]
    mag2 = np.maximum(1.0, mag2)
    mag = np.maximum(1.0, mag)
    cos_a = unit @ d
    sin_a = np.linalg.norm(np.cross(unit, d), axis=1)
    cos_b = 1.0 / mag
    sin_b = np.sqrt(mag2 - 1.0) * cos_b
    denom = cos_a * cos_b - sin_a * sin_b
    if not (denom > HORIZON_DENOMINATOR_MIN).all():
        return d * 1e6
    return d * float((1.0 / denom).max())


def _zigzag_deltas(values: np.ndarray) -> np.ndarray:
    d = np.diff(values.astype(np.int64), prepend=0)
    return ((d << 1) ^ (d >> 63)).astype(np.uint16)


def _unzigzag_sum(codes: np.ndarray) -> np.ndarray:
    c = codes.astype(np.int64)
    return np.cumsum((c >> 1) ^ -(c & 1))


def _high_water_mark(indices: np.ndarray) -> np.ndarray:
    """Codes of indices numbered in order of first use (``highest - index``)."""
    highest = np.concatenate([[0], np.maximum.accumulate(indices)[:-1] + 1]) if indices.size else indices
    return highest - indices


def _from_high_water_mark(codes: np.ndarray) -> np.ndarray:
    codes = codes.astype(np.int64)
    highest = np.concatenate([[0], np.cumsum(codes == 0)[:-1]]) if codes.size else codes
    return highest - codes


def encode_tile(u, v, heights, triangles, bounds) -> bytes:
    """One quantized-mesh-1.0 tile (uncompressed bytes).

    Parameters
    ----------
    u, v : (n,) int
        Quantized positions in [0, 32767] across the tile (:func:`to_uv`).
    heights : (n,) float64
        Ellipsoidal heights (m), quantized here between their lowest and highest.
    triangles : (m, 3) int
        Vertex indices, counter-clockwise in (u, v), each of positive area there.
    bounds : (west, south, east, north)
        The tile's rectangle in degrees (:func:`~terrainvis.tiles.scheme.tile_bounds`).

    Returns
    -------
    bytes
        Vertices unused by every triangle are left out; the others are numbered in the
        order the triangles first use them (the high-water-mark order).

    Examples
    --------
    >>> data = encode_tile([0, 32767, 0], [0, 0, 32767], [1.0, 3.0, 1.0], [[0, 1, 2]], (0.0, 0.0, 1.0, 1.0))
    >>> t = decode_tile(data, (0.0, 0.0, 1.0, 1.0))
    >>> t.triangles.tolist(), t.west.tolist(), t.south.tolist(), t.height.tolist()
    ([[0, 1, 2]], [0, 2], [0, 1], [1.0, 3.0, 1.0])
    """
    u = np.asarray(u)
    v = np.asarray(v)
    h = np.asarray(heights, dtype=np.float64)
    tri = np.asarray(triangles)
    if u.ndim != 1 or v.shape != u.shape or h.shape != u.shape:
        raise ValueError(f"u, v and heights must be 1-d arrays of one length, got shapes {u.shape}, {v.shape}, {h.shape}")
    if tri.ndim != 2 or tri.shape[1] != 3 or tri.shape[0] == 0:
        raise ValueError(f"triangles must have shape (m, 3) with m >= 1, got {tri.shape}")
    if not (np.issubdtype(tri.dtype, np.integer) and tri.min() >= 0 and tri.max() < u.size):
        raise ValueError(f"triangles must hold integer indices in [0, {u.size - 1}]")
    for name, a in (("u", u), ("v", v)):
        if not np.issubdtype(a.dtype, np.integer) or (a.size and (a.min() < 0 or a.max() > QUANTIZED_MAX)):
            raise ValueError(f"{name} must hold integers in [0, {QUANTIZED_MAX}]")
    if not np.isfinite(h).all():
        raise ValueError("heights must be finite")
    from ..core.mesh import signed_area2  # core.mesh imports numba: not at import time

    area = signed_area2(np.column_stack([u.astype(np.int64), v.astype(np.int64)]), tri)  # exact in int64
    if (area <= 0).any():
        raise ValueError(f"triangles must be counter-clockwise with positive area in (u, v): "
                         f"{int((area <= 0).sum())} of {tri.shape[0]} are not")
    west, south, east, north = (float(b) for b in bounds)
    # vertices in the order of their first use
    flat = tri.ravel().astype(np.int64)
    used, first = np.unique(flat, return_index=True)
    order = used[np.argsort(first, kind="stable")]
    new = np.empty(u.size, dtype=np.int64)
    new[order] = np.arange(order.size)
    u, v, h = u[order].astype(np.int64), v[order].astype(np.int64), h[order]
    indices = new[flat]
    n = order.size

    lo, hi = _float32_range(h)
    hq = np.zeros(n, dtype=np.int64) if hi == lo else np.clip(
        np.rint((h - lo) / (hi - lo) * QUANTIZED_MAX), 0, QUANTIZED_MAX).astype(np.int64)
    lon = west + u / QUANTIZED_MAX * (east - west)
    lat = south + v / QUANTIZED_MAX * (north - south)
    height = lo + hq / QUANTIZED_MAX * (hi - lo)
    ecef = lonlat_to_ecef(lon, lat, height)
    centre = 0.5 * (ecef.min(axis=0) + ecef.max(axis=0))
    radius = float(np.linalg.norm(ecef - centre, axis=1).max())
    horizon = horizon_occlusion_point(ecef, centre)

    wide = n > _MAX_16BIT_VERTICES
    itype = np.dtype("<u4" if wide else "<u2")
    parts = [_HEADER.pack(*centre, lo, hi, *centre, radius, *horizon), struct.pack("<I", n),
             _zigzag_deltas(u).astype("<u2").tobytes(), _zigzag_deltas(v).astype("<u2").tobytes(),
             _zigzag_deltas(hq).astype("<u2").tobytes()]
    if wide:
        size = sum(len(p) for p in parts)
        parts.append(b"\0" * (-size % 4))
    parts += [struct.pack("<I", tri.shape[0]), _high_water_mark(indices).astype(itype).tobytes()]
    for edge in _edges(u, v):
        parts += [struct.pack("<I", edge.size), edge.astype(itype).tobytes()]
    return b"".join(parts)


def _float32_range(h: np.ndarray) -> tuple[float, float]:
    """The header's lowest and highest height: float32 values at or below, at or above, the heights."""
    lo = np.float32(h.min())
    if float(lo) > h.min():
        lo = np.nextafter(lo, np.float32(-np.inf))
    hi = np.float32(h.max())
    if float(hi) < h.max():
        hi = np.nextafter(hi, np.float32(np.inf))
    return float(lo), float(hi)


def _edges(u: np.ndarray, v: np.ndarray) -> list[np.ndarray]:
    """West, south, east and north edge vertices, each ordered along its edge."""
    out = []
    for on, along in ((u == 0, v), (v == 0, u), (u == QUANTIZED_MAX, v), (v == QUANTIZED_MAX, u)):
        idx = np.flatnonzero(on)
        out.append(idx[np.argsort(along[idx], kind="stable")])
    return out


@dataclass(frozen=True)
class DecodedTile:
    """A quantized-mesh tile read back (:func:`decode_tile`).

    Attributes
    ----------
    lon, lat, height : (n,) float64
        Each vertex in degrees and metres (dequantized over the tile's bounds and the
        header's height range).
    u, v, h : (n,) int64
        The quantized values as stored.
    triangles : (m, 3) int64
        Counter-clockwise vertex indices.
    west, south, east, north : (k,) int64
        The edge vertices as stored.
    centre, bounding_sphere, horizon_occlusion_point : float64 arrays of 3, 4 and 3
    min_height, max_height : float
    index_bytes : int
        2 or 4.
    """

    lon: np.ndarray
    lat: np.ndarray
    height: np.ndarray
    u: np.ndarray
    v: np.ndarray
    h: np.ndarray
    triangles: np.ndarray
    west: np.ndarray
    south: np.ndarray
    east: np.ndarray
    north: np.ndarray
    centre: np.ndarray
    bounding_sphere: np.ndarray
    horizon_occlusion_point: np.ndarray
    min_height: float
    max_height: float
    index_bytes: int


class _Reader:
    def __init__(self, data: bytes):
        self.data, self.at = data, 0

    def take(self, n: int) -> bytes:
        if self.at + n > len(self.data):
            raise ValueError(f"the tile ends at byte {len(self.data)}, before the {n} bytes expected at byte {self.at}")
        out = self.data[self.at:self.at + n]
        self.at += n
        return out

    def count(self) -> int:
        return struct.unpack("<I", self.take(4))[0]

    def array(self, n: int, dtype: str) -> np.ndarray:
        size = np.dtype(dtype).itemsize
        return np.frombuffer(self.take(n * size), dtype=dtype).astype(np.int64)


def decode_tile(data: bytes, bounds) -> DecodedTile:
    """Read a quantized-mesh-1.0 tile (gzip-compressed or not) whose rectangle is ``bounds``.

    Parameters
    ----------
    data : bytes
        The file's content.
    bounds : (west, south, east, north)
        The tile's rectangle in degrees (a tile does not record it).

    Returns
    -------
    DecodedTile

    Raises
    ------
    ValueError
        On a tile that is cut short, holds an index beyond its vertices, or a quantized
        value above 32767. Extensions after the edges are not read.
    """
    data = bytes(data)
    if data[:2] == b"\x1f\x8b":
        data = gzip.decompress(data)
    r = _Reader(data)
    head = _HEADER.unpack(r.take(_HEADER.size))
    n = r.count()
    u = _unzigzag_sum(r.array(n, "<u2"))
    v = _unzigzag_sum(r.array(n, "<u2"))
    h = _unzigzag_sum(r.array(n, "<u2"))
    for name, a in (("u", u), ("v", v), ("height", h)):
        if a.size and (a.min() < 0 or a.max() > QUANTIZED_MAX):
            raise ValueError(f"the tile's {name} values leave [0, {QUANTIZED_MAX}]: it is not a quantized-mesh tile")
    wide = n > _MAX_16BIT_VERTICES
    itype = "<u4" if wide else "<u2"
    if wide:
        r.take(-r.at % 4)
    m = r.count()
    tri = _from_high_water_mark(r.array(3 * m, itype)).reshape(m, 3)
    if tri.size and (tri.min() < 0 or tri.max() >= n):
        raise ValueError(f"the tile's triangles use vertex {int(tri.max())}, and it has {n}")
    edges = [r.array(r.count(), itype) for _ in range(4)]
    west, south, east, north = (float(b) for b in bounds)
    lo, hi = float(head[3]), float(head[4])
    return DecodedTile(
        lon=west + u / QUANTIZED_MAX * (east - west), lat=south + v / QUANTIZED_MAX * (north - south),
        height=lo + h / QUANTIZED_MAX * (hi - lo), u=u, v=v, h=h, triangles=tri,
        west=edges[0], south=edges[1], east=edges[2], north=edges[3],
        centre=np.array(head[0:3]), bounding_sphere=np.array(head[5:9]), horizon_occlusion_point=np.array(head[9:12]),
        min_height=lo, max_height=hi, index_bytes=4 if wide else 2)


def height_step(min_height: float, max_height: float) -> float:
    """The quantization step of heights in a tile: ``(max - min) / 32767``."""
    return (float(max_height) - float(min_height)) / QUANTIZED_MAX if math.isfinite(max_height - min_height) else 0.0
