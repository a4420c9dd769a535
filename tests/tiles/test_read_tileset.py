"""Reading tilesets back (terrainvis.tiles.read): stitching checked by hand and against independent references,
tilesets from another encoder (quantized-mesh-encoder) and of terrain-RGB, and the refusals of bad input."""

from __future__ import annotations

import gzip
import io
import json
from pathlib import Path

import numpy as np
import pytest

import terrainvis
from terrainvis.core.repair import height_field_problems
from terrainvis.core.terrain import HeightGrid
from terrainvis.tiles import decode_tile, write_tileset
from terrainvis.tiles.read import _lattice_mesh, _Piece, open_tileset, rgb_encode, rgb_heights, stitch_zoom

pyproj = pytest.importorskip("pyproj")

CUMBERLAND = Path(terrainvis.__file__).parent / "data" / "cumberland.tif"
R = 6378137.0


@pytest.fixture(scope="session")
def dem():
    return terrainvis.load_dem(CUMBERLAND)


def _plane_dem(like: HeightGrid) -> HeightGrid:
    """A plane over ``like``'s footprint, in its CRS: every straight-edged TIN with vertices on it is it."""
    X, Y = np.meshgrid(like.xs, like.ys)
    return HeightGrid.from_coords(_plane(X, Y, like), like.xs, like.ys, attrs={"crs": like.attrs["crs"]})


def _plane(x, y, like):
    return 200.0 + 0.01 * (x - like.xs[0]) + 0.02 * (y - like.ys[0])


def _to_utm(lon, lat, crs):
    t = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    return t.transform(lon, lat)


def _dem_heights(grid: HeightGrid, lon, lat, plane: bool):
    """Heights of ``grid`` at lon/lat, positions beyond its footprint taken at its nearest edge point."""
    x, y = _to_utm(np.ravel(lon), np.ravel(lat), grid.attrs["crs"])
    x0, x1, y0, y1 = grid.extent
    if plane:
        return _plane(np.asarray(x), np.asarray(y), grid).reshape(np.shape(lon))
    xy = np.column_stack([np.clip(x, x0, x1), np.clip(y, y0, y1)])
    return grid.height_at(xy).reshape(np.shape(lon))


# ---------------------------------------------------------------------- tilesets written here
def _mercator_lat(y):
    return np.degrees(np.arctan(np.sinh(y / R)))


def _tile_rect(projection: str, z: int, x: int, y_tms: int):
    if projection == "EPSG:4326":
        s = 180.0 / 2 ** z
        return -180.0 + x * s, -90.0 + y_tms * s, -180.0 + (x + 1) * s, -90.0 + (y_tms + 1) * s
    s = 2 * np.pi * R / 2 ** z
    return (-180.0 + x * 360.0 / 2 ** z, float(_mercator_lat(-np.pi * R + y_tms * s)),
            -180.0 + (x + 1) * 360.0 / 2 ** z, float(_mercator_lat(-np.pi * R + (y_tms + 1) * s)))


def _tiles_over(grid: HeightGrid, projection: str, z: int):
    """(x, TMS row) of every tile meeting the DEM's lon/lat bounding box."""
    t = pyproj.Transformer.from_crs(grid.attrs["crs"], "EPSG:4326", always_xy=True)
    x0, x1, y0, y1 = grid.extent
    lon, lat = t.transform([x0, x1, x0, x1], [y0, y0, y1, y1])
    if projection == "EPSG:4326":
        s = 180.0 / 2 ** z
        cx = (np.array(lon) + 180) / s
        cy = (np.array(lat) + 90) / s
    else:
        cx = (np.array(lon) + 180) / 360 * 2 ** z
        my = R * np.log(np.tan(np.pi / 4 + np.radians(lat) / 2))
        cy = (my + np.pi * R) / (2 * np.pi * R) * 2 ** z
    return [(x, y) for y in range(int(cy.min()), int(cy.max()) + 1) for x in range(int(cx.min()), int(cx.max()) + 1)]


def _qm_encoder_tileset(out: Path, grid: HeightGrid, z: int, *, projection="EPSG:4326", scheme="tms", plane=False,
                        max_error=5.0, extensions=True):
    """A quantized-mesh tileset made with quantized-mesh-encoder from pydelatin meshes of 65 x 65 lattices."""
    qme = pytest.importorskip("quantized_mesh_encoder")
    pydelatin = pytest.importorskip("pydelatin")
    from quantized_mesh_encoder.extensions import VertexNormalsExtension, WaterMaskExtension

    n = 64
    tiles = _tiles_over(grid, projection, z)
    for k, (x, y) in enumerate(tiles):
        w, s, e, nn = _tile_rect(projection, z, x, y)
        lon = np.linspace(w, e, n + 1)
        lat = np.linspace(nn, s, n + 1)  # rows from the north, as an image
        lon[-1], lat[0], lat[-1] = e, nn, s
        LON, LAT = np.meshgrid(lon, lat)
        Z = _dem_heights(grid, LON, LAT, plane)
        # every other tile at 4 times the error: neighbours then differ along their seam (T-junctions)
        d = pydelatin.Delatin(Z, max_error=max_error * (4 if (x + y) % 2 else 1))
        v = np.asarray(d.vertices, dtype=np.float64)
        col, up = np.rint(v[:, 0]).astype(int), np.rint(v[:, 1]).astype(int)
        positions = np.column_stack([lon[col], lat[n - up], Z[n - up, col]])
        # the format's high-water-mark coding needs the vertices in the order the triangles first use them,
        # which the encoder leaves to its caller
        flat = np.asarray(d.triangles, dtype=np.int64).ravel()
        used, first = np.unique(flat, return_index=True)
        order = used[np.argsort(first)]
        renumber = np.empty(v.shape[0], dtype=np.int64)
        renumber[order] = np.arange(order.size)
        positions, triangles = positions[order], renumber[flat].reshape(-1, 3)
        f = io.BytesIO()
        exts = [VertexNormalsExtension(positions=positions.astype(np.float32), indices=triangles.astype(np.uint32)),
                WaterMaskExtension(data=0)] if extensions else []
        qme.encode(f, positions, triangles.astype(np.uint32), bounds=tuple(np.float32([w, s, e, nn])),
                   extensions=exts)
        row = y if scheme == "tms" else 2 ** z - 1 - y
        path = out / str(z) / str(x) / f"{row}.terrain"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(gzip.compress(f.getvalue()) if k % 2 else f.getvalue())  # some gzipped, some not
    layer = {"tilejson": "2.1.0", "format": "quantized-mesh-1.0", "version": "1.0.0", "scheme": scheme,
             "tiles": ["{z}/{x}/{y}.terrain?v={version}"], "projection": projection,
             "available": [[] for _ in range(z)] + [[{"startX": min(t[0] for t in tiles), "endX": max(t[0] for t in tiles),
                                                     "startY": 0, "endY": 2 ** z}]]}
    (out / "layer.json").write_text(json.dumps(layer))
    return out


def _rgb_tileset(out: Path, grid: HeightGrid, z: int, *, plane=False, width=256):
    """Terrain-RGB PNG tiles (Web Mercator, XYZ rows): pixel (r, c) is the DEM at the fraction (c, r) / width."""
    from PIL import Image

    over = _tiles_over(grid, "EPSG:3857", z)
    xs, ys = [t[0] for t in over], [t[1] for t in over]
    # a tile more all round: the outer tiles' backfilled edges (which no neighbour corrects) stay off the DEM
    for x, y_tms in [(x, y) for y in range(min(ys) - 1, max(ys) + 2) for x in range(min(xs) - 1, max(xs) + 2)]:
        y = 2 ** z - 1 - y_tms
        s = 2 * np.pi * R / 2 ** z
        mx = -np.pi * R + (x + np.arange(width) / width) * s
        my = np.pi * R - (y + np.arange(width) / width) * s
        MX, MY = np.meshgrid(mx, my)
        Z = _dem_heights(grid, np.degrees(MX / R), _mercator_lat(MY), plane)
        path = out / str(z) / str(x) / f"{y}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(rgb_encode(Z)).save(path)
    return out


@pytest.fixture(scope="session")
def ours(dem, tmp_path_factory):
    """A tileset terrainvis tiles wrote over Cumberland: zoom 9 as whole lattices, 10 simplified (greedy insertion)."""
    out = tmp_path_factory.mktemp("ours")
    write_tileset(dem, out, method="greedy-insertion", zooms=(10, 10), lattice=16)
    return out


# ---------------------------------------------------------------------- stitching by hand
def _square_piece(col, row, q, h, extra_east=False):
    """A tile of ``q`` steps: its corners and centre (4 triangles); with ``extra_east`` a vertex mid-east."""
    U = [0, q, q, 0, q // 2] + ([q] if extra_east else [])
    V = [0, 0, q, q, q // 2] + ([q // 2] if extra_east else [])
    if extra_east:
        tri = [(0, 1, 4), (1, 5, 4), (5, 2, 4), (2, 3, 4), (3, 0, 4)]
    else:
        tri = [(0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)]
    U, V = np.array(U) + col * q, np.array(V) + row * q
    return _Piece(U, V, np.full(U.size, float(h)), np.array(tri))


def _is_tiling(U, V, tri, lo, hi):
    """Counter-clockwise faces of positive area covering the square [lo, hi]^2 once, without T-junctions."""
    a, b, c = tri.T
    area = (U[b] - U[a]) * (V[c] - V[a]) - (U[c] - U[a]) * (V[b] - V[a])
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    lone = np.unique(edges, axis=0)[counts == 1]
    on_side = ((U[lone[:, 0]] == U[lone[:, 1]]) & np.isin(U[lone[:, 0]], [lo, hi])) | \
              ((V[lone[:, 0]] == V[lone[:, 1]]) & np.isin(V[lone[:, 0]], [lo, hi]))
    return bool((area > 0).all() and area.sum() == 2 * (hi - lo) ** 2 and counts.max() <= 2 and on_side.all())


def test_two_by_two_tiles_merge_to_the_hand_count():
    q = 8
    pieces = [_square_piece(c, r, q, 10 * (2 * r + c)) for r in (0, 1) for c in (0, 1)]
    U, V, h, tri = _lattice_mesh(pieces)
    # 20 vertices given; the 3 x 3 corners are shared (9) and the 4 centres are not: 13
    assert U.size == 13 and tri.shape[0] == 16
    assert _is_tiling(U, V, tri, 0, 2 * q)
    # the centre of the block is in all four tiles: the mean of their heights
    k = int(np.flatnonzero((U == q) & (V == q))[0])
    assert h[k] == pytest.approx((0 + 10 + 20 + 30) / 4)


def test_a_t_junction_on_a_seam_splits_the_neighbours_triangle():
    q = 8
    pieces = [_square_piece(0, 0, q, 0.0, extra_east=True), _square_piece(1, 0, q, 4.0)]
    U, V, h, tri = _lattice_mesh(pieces)
    # 6 + 5 vertices, 2 corners shared: 9; the west triangle of the second tile is split in two: 5 + 5 faces
    assert U.size == 9 and tri.shape[0] == 10
    assert _is_tiling(U, V, tri, 0, q) is False  # the block is 2 x 1 tiles
    a, b, c = tri.T
    area = (U[b] - U[a]) * (V[c] - V[a]) - (U[c] - U[a]) * (V[b] - V[a])
    assert (area > 0).all() and area.sum() == 2 * 2 * q * q
    mid = int(np.flatnonzero((U == q) & (V == q // 2))[0])
    assert (tri == mid).any(axis=1).sum() == 4  # two faces of each tile meet at the seam's vertex


def test_skirts_and_degenerate_triangles_are_dropped():
    q = 8
    p = _square_piece(0, 0, q, 5.0)
    # a skirt along the south edge: two vertices under the corners, two vertical triangles
    U = np.concatenate([p.U, [0, q]])
    V = np.concatenate([p.V, [0, 0]])
    h = np.concatenate([p.h, [-100.0, -100.0]])
    tri = np.concatenate([p.tri, [[0, 1, 5], [1, 6, 5]]])
    U2, V2, h2, tri2 = _lattice_mesh([_Piece(U, V, h, tri)])
    assert U2.size == 5 and tri2.shape[0] == 4 and (h2 == 5.0).all()


# ---------------------------------------------------------------------- our own tilesets, against each tile alone
def _alone(dem, tiles, z, xy):
    """Heights at ``xy`` (the DEM's frame) from each tile decoded alone, its vertices projected with pyproj
    (straight edges in the DEM's frame, as the stitched TIN has them), and each point's tile's height step."""
    from terrainvis.core.terrain import TIN
    from terrainvis.tiles.tileset import _Frame

    frame = _Frame(dem, "dem")  # lon/lat to the DEM's frame: its CRS, then its xy_to_native
    out = np.full(xy.shape[0], np.nan)
    steps = np.zeros(xy.shape[0])
    for path in sorted((tiles.path / str(z)).glob("*/*.terrain")):
        c, r = int(path.parent.name), int(path.stem)
        from terrainvis.tiles.scheme import tile_bounds

        d = decode_tile(path.read_bytes(), tile_bounds(z, c, r))
        tin = TIN(np.column_stack([frame.to_grid(d.lon, d.lat), d.height]), d.triangles)
        got = tin.height_at(xy)
        m = np.isfinite(got) & np.isnan(out)
        out[m] = got[m]
        steps[m] = (d.max_height - d.min_height) / 32767
    return out, steps


@pytest.mark.parametrize("which,z", [("ours", 9), ("ours", 10), ("encoder", 10)])
def test_stitched_heights_match_each_tile_decoded_alone(dem, ours, tmp_path, which, z):
    ts = ours if which == "ours" else _qm_encoder_tileset(tmp_path / "enc", dem, z, max_error=5.0)
    tiles = open_tileset(ts)
    tin = stitch_zoom(dem, tiles, z)
    assert height_field_problems(tin, dem) == []
    X, Y = np.meshgrid(dem.xs[::2], dem.ys[::2])
    xy = np.column_stack([X.ravel(), Y.ravel()])
    want, steps = _alone(dem, tiles, z, xy)
    assert np.isfinite(want).all()
    diff = np.abs(tin.height_at(xy) - want)
    if which == "ours":
        # terrainvis's tiles keep every lattice point of their edges: neighbours share every edge vertex, up to
        # each tile's height quantization
        assert diff.max() <= steps.max() + 1e-6
    else:
        # pydelatin simplifies each tile alone: T-junctions on the seams, closed at the neighbour's heights, move
        # the triangles along them by at most the cracks (within the two tiles' errors, 5 and 20 m); elsewhere
        # nothing moves
        assert steps.max() < diff.max() <= 5.0 + 20.0 + 2 * steps.max()
        assert np.median(diff) <= 1e-6


def test_xyz_rows_and_web_mercator_read_the_same_surface(dem, tmp_path):
    plane = _plane_dem(dem)
    for projection in ("EPSG:4326", "EPSG:3857"):
        a = stitch_zoom(plane, _qm_encoder_tileset(tmp_path / f"tms{projection[-4:]}", plane, 10, plane=True,
                                                   projection=projection), 10)
        b = stitch_zoom(plane, _qm_encoder_tileset(tmp_path / f"xyz{projection[-4:]}", plane, 10, plane=True,
                                                   projection=projection, scheme="xyz"), 10)
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.faces, b.faces)
        # on a plane a straight-edged TIN is the plane up to its vertices' rounding (float32 positions of the
        # encoder: 0.7 m at most, times the slope; heights quantized to range / 32767)
        assert height_field_problems(a, plane) == []
        x, y = a.vertices[:, 0], a.vertices[:, 1]
        assert np.abs(a.vertices[:, 2] - _plane(x, y, plane)).max() < 0.05


def test_terrain_rgb_tiles_reproduce_a_plane(dem, tmp_path):
    plane = _plane_dem(dem)
    ts = _rgb_tileset(tmp_path / "rgb", plane, 11, plane=True, width=64)
    for mesh, err in (("grid", None), ("martini", 0.5), ("delatin", 0.5)):
        if mesh == "martini":
            pytest.importorskip("pymartini")
        tin = stitch_zoom(plane, ts, 11, mesh=mesh, max_error=err)
        assert height_field_problems(tin, plane) == []
        x, y = tin.vertices[:, 0], tin.vertices[:, 1]
        assert np.abs(tin.vertices[:, 2] - _plane(x, y, plane)).max() <= 0.05 + 1e-6  # the encoding's 0.1 m step
        if mesh == "grid":
            n_grid = tin.n_vertices
        else:
            assert tin.n_vertices < n_grid / 4  # a plane needs few vertices


def test_a_terrain_rgb_tilejson_is_read_as_its_folder(dem, tmp_path):
    """A layer.json (TileJSON) beside terrain-RGB tiles, without a format: its .png template says terrain-RGB, in
    TileJSON's default XYZ rows; with "scheme": "tms" the rows count from the south."""
    plane = _plane_dem(dem)
    ts = _rgb_tileset(tmp_path / "rgb", plane, 11, plane=True, width=32)
    bare = stitch_zoom(plane, ts, 11)
    (ts / "layer.json").write_text(json.dumps({"tilejson": "2.2.0", "tiles": ["{z}/{x}/{y}.png"]}))
    tiles = open_tileset(ts)
    assert (tiles.format, tiles.projection, tiles.scheme) == ("terrain-rgb", "EPSG:3857", "xyz")
    np.testing.assert_array_equal(stitch_zoom(plane, tiles, 11).vertices, bare.vertices)
    (ts / "layer.json").write_text(json.dumps({"tilejson": "2.2.0", "tiles": ["{z}/{x}/{y}.png"], "scheme": "tms"}))
    with pytest.raises(ValueError, match="does not cover the DEM at zoom 11"):  # the rows then name other tiles
        stitch_zoom(plane, ts, 11)


def test_rgb_encoding_round_trips():
    h = np.array([[-10000.0, 0.0, 1234.5, 8848.8]])
    np.testing.assert_allclose(rgb_heights(rgb_encode(h)), h, atol=1e-6)


def test_offset_is_added_to_every_height(dem, ours):
    a = stitch_zoom(dem, ours, 10)
    b = stitch_zoom(dem, ours, 10, offset=-30.0)
    np.testing.assert_array_equal(a.vertices[:, :2], b.vertices[:, :2])
    np.testing.assert_allclose(b.vertices[:, 2], a.vertices[:, 2] - 30.0)


# ---------------------------------------------------------------------- bad input
def _copy(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


def test_missing_tiles_are_named(dem, ours, tmp_path):
    ts = _copy(ours, tmp_path / "ts")
    tiles = open_tileset(ts)
    victim = sorted((ts / "10").glob("*/*.terrain"))[0]
    victim.unlink()
    name = f"10/{victim.parent.name}/{victim.stem}"
    with pytest.raises(ValueError, match=rf"does not cover the DEM at zoom 10: 1 tile\(s\) over its footprint are "
                                         rf"missing \({name}\)"):
        stitch_zoom(dem, tiles, 10)


def test_a_corrupt_tile_is_named_by_its_path(dem, ours, tmp_path):
    ts = _copy(ours, tmp_path / "ts")
    victim = sorted((ts / "10").glob("*/*.terrain"))[0]
    victim.write_bytes(b"\x1f\x8b not gzip at all")
    with pytest.raises(ValueError, match=rf"tile '{victim}' is not a readable quantized-mesh-1.0 tile"):
        stitch_zoom(dem, ts, 10)
    victim.write_bytes(b"\0" * 100)  # cut short
    with pytest.raises(ValueError, match=rf"tile '{victim}' is not a readable quantized-mesh-1.0 tile: the tile ends"):
        stitch_zoom(dem, ts, 10)


def test_an_absent_zoom_lists_the_present_ones(dem, ours):
    with pytest.raises(ValueError, match=r"zoom 13 is not in tileset .*: its zooms are 0, 1, .*, 10$"):
        stitch_zoom(dem, ours, 13)


@pytest.mark.parametrize("field,value,expected", [
    ("scheme", "quadkey", "declares scheme 'quadkey'; expected tms, xyz or slippyMap"),
    ("projection", "EPSG:3395", "declares projection 'EPSG:3395'; expected EPSG:4326 or EPSG:3857"),
    ("format", "heightmap-1.0", "declares format 'heightmap-1.0' with tiles '{z}/{x}/{y}.terrain'; expected "
                                "quantized-mesh-1.0 with .terrain tiles"),
])
def test_unknown_scheme_projection_or_format(ours, tmp_path, field, value, expected):
    ts = _copy(ours, tmp_path / "ts")
    layer = json.loads((ts / "layer.json").read_text())
    layer[field] = value
    (ts / "layer.json").write_text(json.dumps(layer))
    with pytest.raises(ValueError, match=expected):
        open_tileset(ts)


def test_a_dem_without_crs_is_refused(dem, ours):
    bare = HeightGrid.from_coords(dem.z, dem.xs, dem.ys)
    with pytest.raises(ValueError, match=r"original has no CRS \(attrs\['crs'\]\)"):
        stitch_zoom(bare, ours, 10)


def test_not_a_tileset(tmp_path):
    with pytest.raises(ValueError, match="holds neither"):
        open_tileset(tmp_path)
    (tmp_path / "3" / "1").mkdir(parents=True)
    (tmp_path / "3" / "1" / "2.terrain").write_bytes(b"")
    with pytest.raises(ValueError, match="holds .terrain tiles but no layer.json"):
        open_tileset(tmp_path)


def test_two_by_two_tiles_through_the_whole_reader(tmp_path):
    """Four hand-made quantized-mesh tiles (corners and centre each) over a geographic DEM that is exactly
    their union: nothing is clipped, and the stitched TIN has the hand count, 9 corners + 4 centres."""
    from terrainvis.tiles import encode_tile
    from terrainvis.tiles.scheme import tile_bounds

    z, q = 3, 32767
    for x in (2, 3):
        for y in (5, 6):
            h = [100.0 * x + y] * 4 + [500.0]
            data = encode_tile([0, q, q, 0, q // 2], [0, 0, q, q, q // 2], h,
                               [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]], tile_bounds(z, x, y))
            path = tmp_path / str(z) / str(x) / f"{y}.terrain"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(gzip.compress(data) if x == 2 else data)
    (tmp_path / "layer.json").write_text(json.dumps({"format": "quantized-mesh-1.0", "tiles": ["{z}/{x}/{y}.terrain"],
                                                     "available": [[]] * 3 + [[{"startX": 2, "startY": 5, "endX": 3,
                                                                                "endY": 6}]]}))
    w, s, _, _ = tile_bounds(z, 2, 5)
    _, _, e, n = tile_bounds(z, 3, 6)
    lon, lat = np.linspace(w, e, 9), np.linspace(s, n, 9)
    grid = HeightGrid.from_coords(np.zeros((9, 9)), lon, lat, attrs={"crs": "EPSG:4326"})
    tin = stitch_zoom(grid, tmp_path, z)
    assert tin.n_vertices == 13 and tin.faces.shape[0] == 16
    assert height_field_problems(tin, grid) == []
    # the shared corner of the four tiles: the mean of their corner heights
    k = int(np.flatnonzero((tin.vertices[:, 0] == lon[4]) & (tin.vertices[:, 1] == lat[4]))[0])
    assert tin.vertices[k, 2] == pytest.approx(np.mean([205.0, 305.0, 206.0, 306.0]), abs=0.01)
    assert tin.attrs["n_tiles"] == 4


def test_a_geographic_dem_reads_its_tileset(tmp_path):
    """Jacksboro (3 arc-second lon/lat, its frame local metres): a tileset of it read back is a height field over
    it, equal to each tile decoded alone up to the tiles' height quantization."""
    from conftest import shared_dem_path

    dem = terrainvis.load_dem(shared_dem_path("jacksboro_fault_tn"))
    write_tileset(dem, tmp_path, method="greedy-insertion", zooms=(11, 11), lattice=16)
    tiles = open_tileset(tmp_path)
    tin = stitch_zoom(dem, tiles, 11)
    assert height_field_problems(tin, dem) == []
    X, Y = np.meshgrid(dem.xs[::3], dem.ys[::3])
    xy = np.column_stack([X.ravel(), Y.ravel()])
    want, steps = _alone(dem, tiles, 11, xy)
    assert np.isfinite(want).all()
    assert np.abs(tin.height_at(xy) - want).max() <= steps.max() + 1e-6


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clipping_keeps_the_surface_inside_and_covers_the_rectangle(seed):
    """A random grid's TIN (a few vertices moved off the lattice) clipped to an inner rectangle: one cover of the
    rectangle, and the same heights inside as the TIN it was cut from."""
    from terrainvis.core.terrain import TIN
    from terrainvis.tiles.read import _clip

    rng = np.random.default_rng(seed)
    g = HeightGrid.from_coords(rng.normal(0, 10, (8, 8)), np.arange(8.0), np.arange(8.0))
    tin = g.to_tin()
    v = tin.vertices.copy()
    inner = (np.abs(v[:, 0] - 3.5) < 3) & (np.abs(v[:, 1] - 3.5) < 3)
    v[inner, :2] += rng.uniform(-0.15, 0.15, (int(inner.sum()), 2))
    v[9, 0] = 1.0  # a vertex exactly on the clip line x = 1
    tin = TIN(v, tin.faces)
    a, b, c = tin.faces.T
    assert (((v[b, 0] - v[a, 0]) * (v[c, 1] - v[a, 1]) - (v[c, 0] - v[a, 0]) * (v[b, 1] - v[a, 1])) > 0).all()
    extent = (1.0, 5.7, 0.4, 6.3)
    xy, h, tri = _clip(v[:, :2], v[:, 2], tin.faces, extent)
    cut = TIN(np.column_stack([xy, h]), tri)
    box = HeightGrid.from_coords(np.zeros((2, 2)), np.array(extent[:2]), np.array(extent[2:]))
    assert height_field_problems(cut, box) == []
    pts = np.column_stack([rng.uniform(extent[0], extent[1], 500), rng.uniform(extent[2], extent[3], 500)])
    np.testing.assert_allclose(cut.height_at(pts), tin.height_at(pts), atol=1e-9)
