"""A real client reads our tileset: CesiumJS (the ``cesium`` npm package) in headless Chromium.

``terrainvis.tiles.write_tileset`` writes the bundled projected GeoTIFF ``cumberland`` at zooms
8 to 11; a local ``http.server`` serves it beside tests/browser/tileset.html with a terrain
server's headers (gzip tiles with ``Content-Encoding: gzip``); the page asks
``Cesium.CesiumTerrainProvider.fromUrl`` for it and ``Cesium.sampleTerrainMostDetailed`` for the
heights at positions inside the tileset's rectangle, so Cesium's own code reads ``layer.json``,
fetches and decodes the tiles. Each height must be our decoder's surface there (the triangle of
the most detailed tile, linear in (u, v)) within the tile's height quantization step, and at two
interior lattice points of each most detailed tile within the zoom's budget of the DEM's own
surface. Three servers must fail it: one with a tile cut short, one with a tile missing, one
sending gzip tiles without ``Content-Encoding: gzip``. Then a Viewer draws the tileset with software WebGL (SwiftShader):
seen from inside its rectangle it renders down to the deepest zoom without an error, and so it
does seen whole, with the globe around it (which once stopped Cesium's renderer: tiles partly
outside the rectangle held only their part inside it).

Needs Debian's ``chromium`` (``apt-get install chromium``) and the ``cesium`` npm package
(``npm install --prefix tests/browser``); skips, naming them, where either is absent.
"""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

from tests.browser import cesium_page

pyproj = pytest.importorskip("pyproj", reason="the tiles extra (pyproj) is not installed")
_reason = cesium_page.missing()
if _reason:
    pytest.skip(_reason, allow_module_level=True)

from tests.tiles.test_tiles_command import _lattice  # noqa: E402 (the documented lattice, written once)
from terrainvis.tiles import decode_tile, tile_bounds  # noqa: E402

ZOOMS = (8, 11)
Q = 32767
#: Seconds before a Chromium that has not answered is killed and the test fails.
TIMEOUT = 120.0


@pytest.fixture(scope="module")
def dem():
    from terrainvis.io import bundled_terrain

    return bundled_terrain("cumberland")


@pytest.fixture(scope="module")
def tileset(tmp_path_factory, dem):
    from terrainvis.tiles import write_tileset

    out = tmp_path_factory.mktemp("browser") / "cumberland"
    write_tileset(dem, out, method="greedy-insertion", zooms=ZOOMS)
    return out, json.loads((out / "layer.json").read_text(encoding="utf-8"))


def _most_detailed(layer: dict, lon: float, lat: float) -> tuple[int, int, int]:
    """``(z, x, y)``: the tile of the deepest zoom whose ``available`` ranges hold the position."""
    for z in range(len(layer["available"]) - 1, -1, -1):
        size = 180.0 / 2 ** z
        x, y = math.floor((lon + 180.0) / size), math.floor((lat + 90.0) / size)
        if any(r["startX"] <= x <= r["endX"] and r["startY"] <= y <= r["endY"] for r in layer["available"][z]):
            return z, x, y
    raise AssertionError(f"no tile holds {lon}, {lat}")


def _surface(out, z: int, x: int, y: int, lon: float, lat: float) -> tuple[float, float]:
    """Our decoder's height at a position (the triangle holding it, linear in (u, v)) and the tile's height step."""
    w, s, e, n = tile_bounds(z, x, y)
    t = decode_tile((out / str(z) / str(x) / f"{y}.terrain").read_bytes(), (w, s, e, n))
    u, v = (lon - w) / (e - w) * Q, (lat - s) / (n - s) * Q
    a, b, c = t.triangles.T
    ua, va = t.u[a].astype(float), t.v[a].astype(float)
    d = (t.u[b] - ua) * (t.v[c] - va) - (t.u[c] - ua) * (t.v[b] - va)
    lb = ((u - ua) * (t.v[c] - va) - (t.u[c] - ua) * (v - va)) / d
    lc = ((t.u[b] - ua) * (v - va) - (u - ua) * (t.v[b] - va)) / d
    la = 1.0 - lb - lc
    inside = np.flatnonzero((la >= -1e-12) & (lb >= -1e-12) & (lc >= -1e-12))
    assert inside.size, f"{z}/{x}/{y}: no triangle holds {lon}, {lat}"
    i = inside[0]
    h = la[i] * t.height[a[i]] + lb[i] * t.height[b[i]] + lc[i] * t.height[c[i]]
    return float(h), (t.max_height - t.min_height) / Q


def _positions(out, layer, rng) -> tuple[np.ndarray, int]:
    """24 random positions inside the rectangle, then 2 interior lattice points of each most detailed tile.

    Returns the (n, 2) lon, lat and the count of random ones. Interior lattice points are not on a
    tile's edge, where Cesium could take the neighbouring tile."""
    w, s, e, n = layer["bounds"]
    random = np.column_stack([rng.uniform(w, e, 24), rng.uniform(s, n, 24)])
    z = len(layer["available"]) - 1
    points = []
    for r in layer["available"][z]:
        for x in range(r["startX"], r["endX"] + 1):
            for y in range(r["startY"], r["endY"] + 1):
                lon, lat = _lattice(z, x, y, layer["bounds"])
                points += [(lon[i], lat[j]) for i, j in zip(rng.integers(1, lon.size - 1, 2),
                                                            rng.integers(1, lat.size - 1, 2))]
    return np.vstack([random, points]), random.shape[0]


def _sample(out, positions, **server) -> dict:
    with cesium_page.serve(out, **server) as base:
        return cesium_page.run_page(cesium_page.page_url(base, positions=positions), timeout=TIMEOUT)


def test_cesium_reads_the_tileset_as_our_decoder_does(tileset, dem):
    out, layer = tileset
    positions, n_random = _positions(out, layer, np.random.default_rng(39))
    got = _sample(out, positions)
    assert got["exception"] is None, got["exception"]
    assert got["errors"] == []
    heights = got["heights"]
    assert heights is not None and len(heights) == len(positions) and None not in heights, heights
    to_dem = pyproj.Transformer.from_crs("EPSG:4326", dem.attrs["crs"], always_xy=True)
    budgets = layer["terrainvis"]["max_error"]
    for i, ((lon, lat), h) in enumerate(zip(positions, heights)):
        z, x, y = _most_detailed(layer, lon, lat)
        assert got["levels"][i] == z, (i, lon, lat)
        ours, step = _surface(out, z, x, y, lon, lat)
        # Cesium reads the same quantized values and interpolates them in the same triangle: equal to within the
        # height step (its mesh path keeps heights as float32)
        assert abs(h - ours) <= step + abs(ours) * 2.0 ** -23, (i, lon, lat, h, ours, step)
        if i >= n_random:  # a lattice point: within the zoom's budget of the DEM's own surface
            px, py = to_dem.transform(lon, lat)
            truth = float(dem.height_at(np.array([[px, py]]))[0])
            assert abs(h - truth) <= budgets[str(z)] + step + 1e-6, (i, lon, lat, h, truth, budgets[str(z)])


@pytest.mark.parametrize("damage", ["cut short", "missing"])
def test_a_damaged_tile_fails_the_sampling(tileset, tmp_path, damage):
    out, layer = tileset
    broken = tmp_path / "broken"
    shutil.copytree(out, broken)
    w, s, e, n = layer["bounds"]
    lon, lat = 0.5 * (w + e), 0.5 * (s + n)
    z, x, y = _most_detailed(layer, lon, lat)
    tile = broken / str(z) / str(x) / f"{y}.terrain"
    if damage == "missing":
        tile.unlink()
    else:
        import gzip

        tile.write_bytes(gzip.compress(gzip.decompress(tile.read_bytes())[:100], mtime=0))
    got = _sample(broken, [(lon, lat)])
    # sampleTerrainMostDetailed(..., rejectOnTileFail=true) rejects on a tile Cesium cannot fetch or decode
    assert got["exception"] is not None and got["heights"] is None, got
    if damage == "missing":
        assert "404" in got["exception"], got["exception"]
    good = _sample(out, [(lon, lat)])
    assert good["exception"] is None and good["heights"][0] is not None


def test_gzip_tiles_without_content_encoding_are_not_read(tileset):
    out, layer = tileset
    w, s, e, n = layer["bounds"]
    got = _sample(out, [(0.5 * (w + e), 0.5 * (s + n))], gzip_header=False)
    assert got["exception"] is not None and got["heights"] is None, got


def _view(out, frame: str) -> dict:
    with cesium_page.serve(out) as base:
        return cesium_page.run_page(cesium_page.page_url(base, view=frame), timeout=TIMEOUT)


def test_a_viewer_draws_the_tileset_seen_from_inside_its_rectangle(tileset):
    """Cesium's Viewer (software WebGL) draws the tileset down to its deepest zoom, every tile loaded, no error."""
    out, layer = tileset
    got = _view(out, "inside")
    assert got["exception"] is None, got["exception"]
    assert got["errors"] == [] and got["rendered"]["render_errors"] == [], got
    assert got["rendered"]["settled"], got
    # Cesium draws tiles of zoom 11 and, nearer the camera, tiles it upsamples from them (zooms 12 and more)
    assert max(int(z) for z in got["rendered"]["tiles_drawn"]) >= ZOOMS[1], got


def test_a_viewer_draws_the_tileset_and_the_globe_around_it(tileset):
    """As a user who flies to the tileset sees it: the whole rectangle and the globe beyond its edges.

    This failed while a tile partly outside the rectangle held only its part inside it: Cesium made
    that tile's missing children from it, meshes without vertices beyond the rectangle (NaN bounding
    volumes), and its renderer stopped ('Invalid array length' in View.createPotentiallyVisibleSet).
    Every tile now reaches its edges (terrainvis.tiles.tileset._whole_tile)."""
    out, layer = tileset
    got = _view(out, "whole")
    assert got["exception"] is None, got["exception"]
    assert got["errors"] == [] and got["rendered"]["render_errors"] == [], got
    assert got["rendered"]["settled"], got
