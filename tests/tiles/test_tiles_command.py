"""``terrainvis tiles`` on the bundled projected GeoTIFF ``cumberland``: layer.json, the files, every tile read by
our decoder and by quantized-mesh-tile, and each tile within its zoom's error of its lattice, all computed here
from the documented rules (pyproj, matplotlib's linear interpolation), not from the writer's own helpers."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import one_line_error
from terrainvis.tiles import decode_tile

pyproj = pytest.importorskip("pyproj", reason="the tiles extra (pyproj) is not installed")

ZOOMS = (9, 11)
E0 = 77067.0
Q = 32767


@pytest.fixture(scope="session")
def dem():
    from terrainvis.io import bundled_terrain

    return bundled_terrain("cumberland")


@pytest.fixture(scope="session")
def tileset(tmp_path_factory):
    from terrainvis.cli import main

    out = tmp_path_factory.mktemp("tiles") / "cumberland"
    assert main(["tiles", "cumberland", str(out), "--method", "greedy-insertion", "--zoom", *map(str, ZOOMS)]) == 0
    return out, json.loads((out / "layer.json").read_text(encoding="utf-8"))


def _bounds(z, x, y):
    size = 180.0 / 2 ** z
    return -180.0 + x * size, -90.0 + y * size, -180.0 + (x + 1) * size, -90.0 + (y + 1) * size


def _files(out: Path) -> dict:
    found = {}
    for f in out.glob("*/*/*.terrain"):
        z, x = int(f.parent.parent.name), int(f.parent.name)
        found.setdefault(z, set()).add((x, int(f.stem)))
    return found


def test_layer_json_describes_the_files(tileset):
    out, layer = tileset
    assert layer["tilejson"] == "2.1.0"
    assert layer["format"] == "quantized-mesh-1.0"
    assert layer["scheme"] == "tms" and layer["projection"] == "EPSG:4326"
    assert layer["tiles"] == ["{z}/{x}/{y}.terrain"]
    assert layer["minzoom"] == 0 and layer["maxzoom"] == ZOOMS[1]
    assert len(layer["available"]) == ZOOMS[1] + 1
    files = _files(out)
    assert sorted(files) == list(range(ZOOMS[1] + 1))
    for z, ranges in enumerate(layer["available"]):
        claimed = [(x, y) for r in ranges for x in range(r["startX"], r["endX"] + 1)
                   for y in range(r["startY"], r["endY"] + 1)]
        assert len(claimed) == len(set(claimed))
        assert set(claimed) == files[z], z
    tv = layer["terrainvis"]
    assert tv["method"] == "greedy-insertion" and tv["zooms"] == list(ZOOMS)
    for z in range(ZOOMS[1] + 1):
        want = E0 / 2 ** z if z >= ZOOMS[0] else None
        assert tv["max_error"][str(z)] == want


def test_the_table_has_a_row_per_tile(tileset):
    import pandas as pd

    out, layer = tileset
    table = pd.read_csv(out / "terrainvis-tiles.csv")
    files = {(z, x, y) for z, tiles in _files(out).items() for x, y in tiles}
    assert set(zip(table.z, table.x, table.y)) == files - {(0, 1, 0)}  # all but the flat root tile
    simplified = table.z >= ZOOMS[0]
    assert table.method_error[simplified].notna().all() and table.method_error[~simplified].isna().all()
    np.testing.assert_array_equal(table.max_error[simplified], E0 / 2.0 ** table.z[simplified])
    for r in layer["terrainvis"]["zooms_written"]:
        rows = table[table.z == r["zoom"]]
        assert rows.measured_error.max() == r["largest_error"]
        assert rows.vertices.sum() == r["vertices"]


def test_the_tiles_are_those_meeting_the_rectangle(tileset, dem):
    out, layer = tileset
    w, s, e, n = layer["bounds"]
    files = _files(out)
    for z in range(ZOOMS[1] + 1):
        want = set()
        nx, ny = 2 ** (z + 1), 2 ** z
        for x in range(nx):
            for y in range(ny):
                tw, ts, te, tn = _bounds(z, x, y)
                if min(te, e) > max(tw, w) and min(tn, n) > max(ts, s):
                    want.add((x, y))
        if z == 0:
            want |= {(0, 0), (1, 0)}  # Cesium asks for both root tiles
        assert files[z] == want, z


def test_the_rectangle_lies_inside_the_dem_and_touches_its_edge_on_every_side(tileset, dem):
    _, layer = tileset
    w, s, e, n = layer["bounds"]
    to_utm = pyproj.Transformer.from_crs("EPSG:4326", dem.attrs["crs"], always_xy=True)

    def inside(lon, lat):
        x, y = to_utm.transform(np.asarray(lon), np.asarray(lat))
        return np.isfinite(dem.height_at(np.column_stack([x, y])))

    t = np.linspace(0, 1, 2001)
    edges = [(np.full(t.size, w), s + t * (n - s)), (w + t * (e - w), np.full(t.size, s)),
             (np.full(t.size, e), s + t * (n - s)), (w + t * (e - w), np.full(t.size, n))]
    for lon, lat in edges:
        assert inside(lon, lat).all()
    # the largest: each side pushed out by 1/1000 of the rectangle leaves the DEM somewhere along it
    dx, dy = 1e-3 * (e - w), 1e-3 * (n - s)
    for side, (lon, lat) in enumerate(edges):
        moved = (lon - dx, lat) if side == 0 else (lon, lat - dy) if side == 1 else (lon + dx, lat) if side == 2 \
            else (lon, lat + dy)
        assert not inside(*moved).all(), side


def _lattice(z, x, y, rect, n=64):
    """The documented lattice: integer quantized positions inside the rectangle, as even as they allow."""
    tw, ts, te, tn = _bounds(z, x, y)
    w, s, e, nn = rect

    def axis(lo, hi, a0, a1):
        a = max(0, math.ceil((max(lo, a0) - a0) * Q / (a1 - a0) - 1e-9))
        b = min(Q, math.floor((min(hi, a1) - a0) * Q / (a1 - a0) + 1e-9))
        k = min(n, b - a)
        return a0 + np.rint(a + np.arange(k + 1) * ((b - a) / k)) / Q * (a1 - a0)

    return axis(w, e, tw, te), axis(s, nn, ts, tn)


def test_every_tile_is_within_its_zooms_error_of_its_lattice(tileset, dem):
    from matplotlib.tri import LinearTriInterpolator, Triangulation

    out, layer = tileset
    rect = layer["bounds"]
    to_utm = pyproj.Transformer.from_crs("EPSG:4326", dem.attrs["crs"], always_xy=True)
    checked = 0
    for f in sorted(out.glob("*/*/*.terrain")):
        z, x, y = int(f.parent.parent.name), int(f.parent.name), int(f.stem)
        tw, ts, te, tn = _bounds(z, x, y)
        if not (min(te, rect[2]) > max(tw, rect[0]) and min(tn, rect[3]) > max(ts, rect[1])):
            continue  # the root tile outside the rectangle: flat, checked below
        data = f.read_bytes()
        assert data[:2] == b"\x1f\x8b"  # gzip by default
        t = decode_tile(data, (tw, ts, te, tn))
        a, b, c = t.triangles.T
        area = (t.u[b] - t.u[a]) * (t.v[c] - t.v[a]) - (t.u[c] - t.u[a]) * (t.v[b] - t.v[a])
        assert (area > 0).all()  # counter-clockwise in (u, v)
        lon, lat = _lattice(z, x, y, rect)
        LON, LAT = np.meshgrid(lon, lat)
        ux, uy = to_utm.transform(LON.ravel(), LAT.ravel())
        truth = dem.height_at(np.column_stack([ux, uy]))
        assert np.isfinite(truth).all()
        k = 1e4  # degrees to about metres-sized numbers for the interpolation's planes
        mesh = LinearTriInterpolator(Triangulation((t.lon - tw) * k, (t.lat - ts) * k, t.triangles), t.height)
        got = np.ma.filled(mesh((LON.ravel() - tw) * k, (LAT.ravel() - ts) * k), np.nan)
        assert np.isfinite(got).all(), f"{z}/{x}/{y}: the mesh misses lattice points"
        step = (t.max_height - t.min_height) / Q
        budget = E0 / 2 ** z if z >= ZOOMS[0] else 0.0
        err = float(np.abs(got - truth).max())
        assert err <= budget + step + 1e-6, (z, x, y, err, budget, step)
        if z >= ZOOMS[0]:
            assert t.u.size < LON.size  # simplified
        checked += 1
    assert checked >= 30


def test_the_root_tile_outside_is_flat_and_whole(tileset):
    out, layer = tileset
    t = decode_tile((out / "0" / "1" / "0.terrain").read_bytes(), _bounds(0, 1, 0))
    assert t.triangles.shape == (2, 3)
    assert sorted(zip(t.u.tolist(), t.v.tolist())) == [(0, 0), (0, Q), (Q, 0), (Q, Q)]
    assert np.all(t.height == 0.0)


def test_an_independent_decoder_reads_every_tile(tileset):
    try:
        from quantized_mesh_tile.terrain import TerrainTile
    except ImportError:
        pytest.skip("quantized-mesh-tile is not installed (pip install quantized-mesh-tile; it is in the test extra)")
    out, _ = tileset
    for f in sorted(out.glob("*/*/*.terrain")):
        z, x, y = int(f.parent.parent.name), int(f.parent.name), int(f.stem)
        bounds = _bounds(z, x, y)
        ours = decode_tile(f.read_bytes(), bounds)
        theirs = TerrainTile(west=bounds[0], south=bounds[1], east=bounds[2], north=bounds[3])
        theirs.fromFile(str(f), gzipped=True)
        got = np.array(theirs.getVerticesCoordinates())
        np.testing.assert_allclose(got[:, 0], ours.lon, rtol=0, atol=1e-9)
        np.testing.assert_allclose(got[:, 1], ours.lat, rtol=0, atol=1e-9)
        np.testing.assert_allclose(got[:, 2], ours.height, rtol=0, atol=1e-6 + 1e-6 * abs(ours.max_height))
        assert np.array(theirs.indices).reshape(-1, 3).tolist() == ours.triangles.tolist()


# ---------------------------------------------------------------------- mistakes, one line each
def test_a_dem_without_a_crs(capsys, tmp_path):
    err = one_line_error(capsys, 2, ["tiles", "hills", str(tmp_path / "o"), "--method", "simple", "--zoom", "0", "1"])
    assert "DEM 'hills' has no CRS" in err
    assert not (tmp_path / "o").exists()


def test_an_unknown_method(capsys, tmp_path):
    err = one_line_error(capsys, 2, ["tiles", "cumberland", str(tmp_path / "o"), "--method", "nope", "--zoom", "0", "1"])
    assert "unknown method 'nope'" in err and "--method" in err


def test_an_inverted_zoom_range(capsys, tmp_path):
    err = one_line_error(capsys, 2, ["tiles", "cumberland", str(tmp_path / "o"), "--method", "simple", "--zoom", "3", "1"])
    assert "--zoom" in err and "3 1" in err


def test_a_zoom_out_of_range(capsys, tmp_path):
    err = one_line_error(capsys, 2, ["tiles", "cumberland", str(tmp_path / "o"), "--method", "simple", "--zoom", "0", "25"])
    assert "--zoom" in err and "25" in err


def test_an_existing_out_dir_needs_overwrite(capsys, tmp_path):
    from terrainvis.cli import main

    out = tmp_path / "o"
    args = ["tiles", "cumberland", str(out), "--method", "simple", "--zoom", "0", "1", "--no-gzip"]
    assert main(args) == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert not (out / "0" / "0" / "0.terrain").read_bytes().startswith(b"\x1f\x8b")  # --no-gzip: raw
    (out / "notes.txt").write_text("mine")
    err = one_line_error(capsys, 2, args)
    assert "OUT_DIR" in err and "--overwrite" in err and "a tileset terrainvis wrote" in err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file() and p.name != "notes.txt"} == before
    assert main(args + ["--overwrite"]) == 0
    assert "removed the earlier tileset's" in capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "mine"  # not a tileset's file: kept
    assert json.loads((out / "layer.json").read_text())["terrainvis"]["method"] == "simple"


def test_overwrite_never_replaces_a_layer_json_terrainvis_did_not_write(capsys, tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "layer.json").write_text('{"tilejson": "2.1.0"}')
    err = one_line_error(capsys, 2, ["tiles", "cumberland", str(out), "--method", "simple", "--zoom", "0", "0",
                                     "--overwrite"])
    assert "layer.json that terrainvis did not write" in err
    assert (out / "layer.json").read_text() == '{"tilejson": "2.1.0"}'


def test_overwrite_never_removes_tiles_terrainvis_did_not_write(capsys, tmp_path):
    """Tiles with neither a layer.json nor a run record of terrainvis (another tiler's output kept
    without its layer.json) are refused, not removed."""
    out = tmp_path / "o"
    (out / "5" / "17").mkdir(parents=True)
    (out / "5" / "17" / "9.terrain").write_bytes(b"another tiler's tile")
    err = one_line_error(capsys, 2, ["tiles", "cumberland", str(out), "--method", "simple", "--zoom", "0", "0",
                                     "--overwrite"])
    assert "1 {z}/{x}/{y} tile file(s)" in err and "did not write" in err
    assert (out / "5" / "17" / "9.terrain").read_bytes() == b"another tiler's tile"


def test_without_pyproj_one_line_names_the_extra(capsys, tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "pyproj", None)
    err = one_line_error(capsys, 2, ["tiles", "cumberland", str(tmp_path / "o"), "--method", "simple", "--zoom", "0", "0"])
    assert 'pip install "terrainvis[tiles]"' in err


def test_an_interrupted_run_is_continued_with_resume(capsys, tmp_path, monkeypatch):
    from terrainvis.cli import main
    from terrainvis.tiles import tileset as module

    real, calls = module._make_tile, []

    def stopping(*a, **k):
        calls.append(1)
        if len(calls) == 5:
            raise KeyboardInterrupt
        return real(*a, **k)

    out = tmp_path / "o"
    args = ["tiles", "cumberland", str(out), "--method", "simple", "--zoom", "2", "5"]  # 7 tiles, 6 made
    monkeypatch.setattr(module, "_make_tile", stopping)
    assert main(args) == 130
    assert "--resume continues" in capsys.readouterr().err
    monkeypatch.setattr(module, "_make_tile", real)
    assert not (out / "layer.json").exists()
    err = one_line_error(capsys, 2, args)
    assert "an unfinished run's" in err and "--resume continues it" in err
    err = one_line_error(capsys, 2, args[:-2] + ["1", "5", "--resume"])
    assert "other settings (zooms: [2, 5] then, [1, 5] now)" in err
    calls.clear()
    monkeypatch.setattr(module, "_make_tile", stopping)  # counts again: only the missing tiles are made
    assert main(args + ["--resume"]) == 0
    assert len(calls) == 3  # the tile of zoom 4 (whose making was interrupted) and the two of zoom 5
    assert json.loads((out / "layer.json").read_text())["maxzoom"] == 5
