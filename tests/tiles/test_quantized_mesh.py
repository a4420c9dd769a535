"""The quantized-mesh-1.0 encoder and decoder: hand-worked bytes, round trips (16- and 32-bit indices),
the horizon occlusion point, and an independent decoder (quantized-mesh-tile) reading our tiles."""

from __future__ import annotations

import gzip
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import Delaunay

from terrainvis.tiles import decode_tile, encode_tile
from terrainvis.tiles.quantized_mesh import (QUANTIZED_MAX, WGS84_A, WGS84_B, horizon_occlusion_point,
                                             lonlat_to_ecef)

BOUNDS = (-84.375, 36.5625, -84.0234375, 36.9140625)  # tile 9/271/360 of Cesium's geographic scheme


def _mesh(u, v):
    """A counter-clockwise Delaunay triangulation of distinct integer (u, v), without slivers of zero area."""
    tri = Delaunay(np.column_stack([u, v]).astype(float)).simplices.astype(np.int64)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    area = (u[b] - u[a]) * (v[c] - v[a]) - (u[c] - u[a]) * (v[b] - v[a])
    tri[area < 0] = tri[area < 0][:, [0, 2, 1]]
    return tri[area != 0]


def _check_round_trip(u, v, h, tri, bounds=BOUNDS):
    data = encode_tile(u, v, h, tri, bounds)
    t = decode_tile(data, bounds)
    assert decode_tile(gzip.compress(data), bounds).triangles.tolist() == t.triangles.tolist()
    used = np.unique(tri)
    assert t.u.size == used.size
    # each decoded vertex is one of ours (positions are distinct): map decoded -> ours by (u, v)
    ours = {(int(u[i]), int(v[i])): i for i in used}
    back = np.array([ours[(int(a), int(b))] for a, b in zip(t.u, t.v)])
    assert sorted(map(tuple, np.sort(back[t.triangles], axis=1).tolist())) == \
        sorted(map(tuple, np.sort(tri, axis=1).tolist()))
    # the same orientation: each decoded triangle is one of ours up to a rotation
    rotations = {tuple(np.roll(f, k)) for f in tri.tolist() for k in range(3)}
    assert all(tuple(f) in rotations for f in back[t.triangles].tolist())
    step = (t.max_height - t.min_height) / QUANTIZED_MAX
    assert t.min_height <= h[used].min() and t.max_height >= h[used].max()
    np.testing.assert_allclose(t.height, h[back], rtol=0, atol=0.5 * step + 1e-9 * max(1.0, abs(h).max()))
    west, south, east, north = bounds
    np.testing.assert_allclose(t.lon, west + u[back] / QUANTIZED_MAX * (east - west), rtol=0, atol=1e-12)
    np.testing.assert_allclose(t.lat, south + v[back] / QUANTIZED_MAX * (north - south), rtol=0, atol=1e-12)
    for edge, on in ((t.west, t.u == 0), (t.south, t.v == 0), (t.east, t.u == QUANTIZED_MAX),
                     (t.north, t.v == QUANTIZED_MAX)):
        assert sorted(edge.tolist()) == np.flatnonzero(on).tolist()
    return data, t


@st.composite
def meshes(draw):
    n = draw(st.integers(3, 60))
    corners = draw(st.booleans())
    pts = draw(st.sets(st.tuples(st.integers(0, QUANTIZED_MAX), st.integers(0, QUANTIZED_MAX)), min_size=n, max_size=n))
    pts = sorted(pts)
    if corners:  # vertices on every edge of the tile
        pts = sorted(set(pts) | {(0, 0), (QUANTIZED_MAX, 0), (0, QUANTIZED_MAX), (QUANTIZED_MAX, QUANTIZED_MAX)})
    u = np.array([p[0] for p in pts], dtype=np.int64)
    v = np.array([p[1] for p in pts], dtype=np.int64)
    h = np.array(draw(st.lists(st.floats(-500.0, 9000.0), min_size=u.size, max_size=u.size)))
    return u, v, h


@settings(max_examples=80, deadline=None)
@given(meshes())
def test_round_trip_16_bit(mesh):
    u, v, h = mesh
    try:
        tri = _mesh(u, v)
    except Exception:  # scipy refuses collinear points: no mesh to test
        tri = np.zeros((0, 3), dtype=np.int64)
    if tri.shape[0] == 0:
        with pytest.raises(ValueError):
            encode_tile(u, v, h, np.zeros((0, 3), dtype=np.int64), BOUNDS)
        return
    _, t = _check_round_trip(u, v, h, tri)
    assert t.index_bytes == 2


def test_round_trip_32_bit_with_padding():
    # 257 x 257 = 66,049 vertices (> 65,536: 32-bit indices); an odd count, so the indices need 2 bytes of padding
    k = np.rint(np.linspace(0, QUANTIZED_MAX, 257)).astype(np.int64)
    U, V = np.meshgrid(k, k)
    u, v = U.ravel(), V.ravel()
    rng = np.random.default_rng(3)
    h = rng.uniform(100.0, 1500.0, u.size)
    r, c = np.divmod(np.arange(256 * 256), 256)
    a = r * 257 + c
    tri = np.concatenate([np.column_stack([a, a + 1, a + 258]), np.column_stack([a, a + 258, a + 257])])
    data, t = _check_round_trip(u, v, h, tri)
    assert t.index_bytes == 4
    end_vertices = 88 + 4 + 6 * u.size
    assert end_vertices % 4 == 2
    assert data[end_vertices:end_vertices + 2] == b"\0\0"
    assert struct.unpack_from("<I", data, end_vertices + 2)[0] == tri.shape[0]


def test_exactly_65536_vertices_keep_16_bit_indices():
    k = np.rint(np.linspace(0, QUANTIZED_MAX, 256)).astype(np.int64)
    U, V = np.meshgrid(k, k)
    r, c = np.divmod(np.arange(255 * 255), 255)
    a = r * 256 + c
    tri = np.concatenate([np.column_stack([a, a + 1, a + 257]), np.column_stack([a, a + 257, a + 256])])
    _, t = _check_round_trip(U.ravel(), V.ravel(), np.zeros(U.size), tri)
    assert t.u.size == 65536 and t.index_bytes == 2


def test_bytes_by_hand():
    data = encode_tile([0, 32767, 0, 32767], [0, 0, 32767, 32767], [10.0, 20.0, 30.0, 40.0],
                       [[0, 1, 3], [0, 3, 2]], (0.0, 0.0, 1.0, 1.0))
    head = struct.unpack_from("<3d2f4d3d", data)
    assert head[3:5] == (10.0, 40.0)
    at = 88
    assert struct.unpack_from("<I", data, at)[0] == 4
    # vertices in order of first use: 0, 1, 3, 2 -> u = 0, 32767, 32767, 0: deltas 0, 32767, 0, -32767,
    # zig-zag 0, 65534, 0, 65533
    assert struct.unpack_from("<4H", data, at + 4) == (0, 65534, 0, 65533)
    # heights 10, 20, 40, 30 over [10, 40]: 0, 10922 (rounded), 32767, 21845 -> deltas zig-zagged
    hq = [0, 10922, 32767, 21845]
    d = np.diff(hq, prepend=0)
    assert struct.unpack_from("<4H", data, at + 4 + 16) == tuple(int((x << 1) ^ (x >> 63)) for x in d)
    # triangles (0, 1, 2), (0, 2, 3) after renumbering: high-water-mark codes 0, 0, 0, 3, 1, 0
    at += 4 + 24
    assert struct.unpack_from("<I", data, at)[0] == 2
    assert struct.unpack_from("<6H", data, at + 4) == (0, 0, 0, 3, 1, 0)
    at += 4 + 12
    edges = []
    for _ in range(4):
        n = struct.unpack_from("<I", data, at)[0]
        edges.append(list(struct.unpack_from(f"<{n}H", data, at + 4)))
        at += 4 + 2 * n
    assert edges == [[0, 3], [0, 1], [1, 2], [3, 2]]  # west, south, east, north, each along its edge
    assert at == len(data)


def test_refuses_clockwise_and_out_of_range():
    with pytest.raises(ValueError, match="counter-clockwise"):
        encode_tile([0, 0, 10], [0, 10, 0], [0.0, 0.0, 0.0], [[0, 1, 2]], BOUNDS)
    with pytest.raises(ValueError, match="u must hold integers"):
        encode_tile([0, 40000, 0], [0, 0, 10], [0.0, 0.0, 0.0], [[0, 1, 2]], BOUNDS)
    with pytest.raises(ValueError, match="ends at byte"):
        decode_tile(encode_tile([0, 10, 0], [0, 0, 10], [0.0, 1.0, 2.0], [[0, 1, 2]], BOUNDS)[:-3], BOUNDS)


def _occluded(eye, point) -> bool:
    """Whether the unit sphere hides ``point`` from ``eye`` (both in the ellipsoid-scaled frame): the segment meets it."""
    d = point - eye
    t = np.clip(-eye @ d / (d @ d), 0.0, 1.0)
    return float(np.linalg.norm(eye + t * d)) < 1.0


@settings(max_examples=60, deadline=None)
@given(st.floats(-170, 170), st.floats(-80, 80), st.floats(0.01, 5.0), st.integers(0, 2**31))
def test_horizon_point_hides_only_what_hides_the_tile(lon0, lat0, size, seed):
    """A viewer who cannot see the occlusion point cannot see any vertex of the tile (Cesium's promise)."""
    rng = np.random.default_rng(seed)
    lon = lon0 + rng.uniform(0, size, 40)
    lat = np.clip(lat0 + rng.uniform(0, size, 40), -89.9, 89.9)
    ecef = lonlat_to_ecef(lon, lat, rng.uniform(0.0, 8000.0, 40))
    centre = 0.5 * (ecef.min(axis=0) + ecef.max(axis=0))
    p = horizon_occlusion_point(ecef, centre)
    radii = np.array([WGS84_A, WGS84_A, WGS84_B])
    scaled = ecef / radii
    for _ in range(200):
        eye = rng.normal(size=3)
        eye *= rng.uniform(1.0001, 4.0) / np.linalg.norm(eye)
        if _occluded(eye, p):
            assert all(_occluded(eye, q) for q in scaled)


# ---------------------------------------------------------------------- an independent decoder
def _independent():
    try:
        from quantized_mesh_tile.terrain import TerrainTile
    except ImportError:
        pytest.skip("quantized-mesh-tile is not installed (pip install quantized-mesh-tile; it is in the test extra)")
    return TerrainTile


@pytest.mark.parametrize("compressed", [True, False])
def test_independent_decoder_reads_our_tiles(tmp_path, compressed):
    TerrainTile = _independent()
    rng = np.random.default_rng(7)
    pts = {(0, 0), (QUANTIZED_MAX, 0), (0, QUANTIZED_MAX), (QUANTIZED_MAX, QUANTIZED_MAX)}
    while len(pts) < 300:
        pts.add((int(rng.integers(0, QUANTIZED_MAX + 1)), int(rng.integers(0, QUANTIZED_MAX + 1))))
    pts = sorted(pts)
    u = np.array([p[0] for p in pts])
    v = np.array([p[1] for p in pts])
    h = rng.uniform(200.0, 900.0, u.size)
    tri = _mesh(u, v)
    data = encode_tile(u, v, h, tri, BOUNDS)
    path = tmp_path / "t.terrain"
    path.write_bytes(gzip.compress(data) if compressed else data)
    ours = decode_tile(path.read_bytes(), BOUNDS)
    west, south, east, north = BOUNDS
    theirs = TerrainTile(west=west, south=south, east=east, north=north)
    theirs.fromFile(str(path), gzipped=compressed)
    got = np.array(theirs.getVerticesCoordinates())
    step = (ours.max_height - ours.min_height) / QUANTIZED_MAX
    np.testing.assert_allclose(got[:, 0], ours.lon, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[:, 1], ours.lat, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[:, 2], ours.height, rtol=0, atol=1e-6 * step + 1e-9)
    # and within quantization of the heights we gave
    used_h = {(int(a), int(b)): x for a, b, x in zip(u, v, h)}
    want = np.array([used_h[(int(a), int(b))] for a, b in zip(ours.u, ours.v)])
    assert np.abs(got[:, 2] - want).max() <= 0.5 * step + 1e-6
    assert np.array(theirs.indices).reshape(-1, 3).tolist() == ours.triangles.tolist()
    assert sorted(theirs.westI) == sorted(ours.west.tolist())
    assert sorted(theirs.northI) == sorted(ours.north.tolist())
