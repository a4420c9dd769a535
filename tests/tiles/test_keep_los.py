"""``write_tileset(..., keep_los=P)`` / ``terrainvis tiles --keep-los P``: each zoom's budget chosen by line of sight.

The sight lines' plumbing is checked on tiles whose verdicts are known without the code under
test (a whole lattice decoded to the same surface keeps every pair; a flat tile makes every pair
visible, so it keeps exactly T's visible pairs). The search is checked on the bundled Cumberland
DEM against a measurement made here from the files written, read by the independent decoder
``quantized-mesh-tile``: the zoom's tiles keep the share the layer reports, at least P, and the
tiles written at the next larger rung (a plain halving run at that budget) keep less than P."""

from __future__ import annotations

import gzip
import json

import numpy as np
import pytest

from terrainvis import HeightGrid, visibility_matrix
from terrainvis.core.sampling import sample_points
from terrainvis.core.terrain import TIN
from terrainvis.tiles import decode_tile, encode_tile, tile_bounds, write_tileset
from terrainvis.tiles.keep_los import N_POINTS, choose_budget, kept_pairs, tile_sights
from tests.conftest import one_line_error

pyproj = pytest.importorskip("pyproj", reason="the tiles extra (pyproj) is not installed")

P = 0.99
ZOOMS = (9, 10)


class _Lattice:
    """A lattice as tile_lattice makes them, by hand: a tile's integer positions, their lon/lat, heights."""

    def __init__(self, z_, bounds, us, vs):
        from terrainvis.tiles.tileset import _equirectangular

        west, south, east, north = bounds
        self.bounds, self.us, self.vs, self.z = bounds, us, vs, z_
        self.lon = west + us / 32767 * (east - west)
        self.lat = south + vs / 32767 * (north - south)
        self.lon0, self.lat0 = 0.5 * (self.lon[0] + self.lon[-1]), 0.5 * (self.lat[0] + self.lat[-1])
        self._eq = _equirectangular

    def to_local(self, lon, lat):
        return self._eq(lon, lat, self.lon0, self.lat0)


def _terrace(n: int = 17):
    """A tile of zoom 12 whose lattice holds only two heights, 0 and 50 m: quantized without rounding."""
    bounds = tile_bounds(12, 1000, 700)
    us = np.rint(np.linspace(0, 32767, n)).astype(np.int64)
    z_ = np.where(np.add.outer(np.arange(n), np.arange(n)) % 7 < 3, 50.0, 0.0)
    return _Lattice(z_, bounds, us, us.copy())


def _whole(lat_):
    """The lattice's own triangulation, encoded and decoded."""
    U, V = np.meshgrid(lat_.us, lat_.vs)
    tin = HeightGrid.from_coords(lat_.z, np.arange(lat_.us.size, dtype=float),
                                 np.arange(lat_.vs.size, dtype=float)).to_tin()
    return decode_tile(encode_tile(U.ravel(), V.ravel(), lat_.z.ravel(), tin.faces, lat_.bounds), lat_.bounds)


def test_a_tile_that_is_its_lattice_keeps_every_pair():
    lat_ = _terrace()
    dec = _whole(lat_)
    U, V = np.meshgrid(lat_.us, lat_.vs)
    at = {(int(u), int(v)): h for u, v, h in zip(dec.u, dec.v, dec.height)}
    assert [at[(int(u), int(v))] for u, v in zip(U.ravel(), V.ravel())] == lat_.z.ravel().tolist()  # no rounding
    sights = tile_sights(lat_, 12, 1000, 700)
    assert sights.verdicts.size == N_POINTS * (N_POINTS - 1) // 2
    assert 0 < np.count_nonzero(sights.verdicts) < sights.verdicts.size  # the terrace blocks some, not all
    assert kept_pairs(lat_, sights, dec) == sights.verdicts.size


def test_a_flat_tile_keeps_exactly_the_visible_pairs():
    lat_ = _terrace()
    sights = tile_sights(lat_, 12, 1000, 700)
    M = 32767
    flat = decode_tile(encode_tile(np.array([0, M, M, 0]), np.array([0, 0, M, M]), np.full(4, 20.0),
                                   np.array([[0, 1, 2], [0, 2, 3]]), lat_.bounds), lat_.bounds)
    # T's verdicts computed again here, pair by pair, from the same points drawn with the documented seed
    xs, ys = lat_.to_local(lat_.lon, lat_.lat)
    grid = HeightGrid.from_coords(lat_.z, xs, ys)
    pts = sample_points(grid, N_POINTS, seed=np.random.default_rng([12, 1000, 700]), offset=2.0)
    i, j = np.triu_indices(N_POINTS, 1)
    from terrainvis import line_of_sight

    visible = int(np.count_nonzero(line_of_sight(grid, pts[i], pts[j])))
    assert kept_pairs(lat_, sights, flat) == visible  # 2 m above a plane, every pair is visible


def test_the_search_takes_the_first_rung_that_keeps_the_share():
    lat_ = _terrace()
    shares = iter([0.5, 0.97, 0.995])
    made = []

    class Made:
        def __init__(self, b):
            self.decoded = _whole(lat_)
            self.budget = b

    def make(lat, b):
        made.append(b)
        return Made(b)

    from terrainvis.tiles import keep_los as module

    real = module.kept_pairs
    try:
        module.kept_pairs = lambda lat, s, d: int(round(next(shares) * s.verdicts.size))
        choice, tiles = choose_budget({(0, 0): lat_}, 12, P, 2.0, make)
    finally:
        module.kept_pairs = real
    top = float(np.ptp(lat_.z))
    assert made == [top, top * 2 ** -0.5, top / 2]
    assert choice.budget == top / 2 and choice.reached and tiles[(0, 0)].budget == top / 2
    assert [t[0] for t in choice.tried] == made


def _cumberland():
    from terrainvis.io import bundled_terrain

    return bundled_terrain("cumberland")


def _share_of_written(out, z, height=2.0):
    """The share of zoom z's sight lines kept by the tiles in ``out``: tiles read by quantized-mesh-tile,
    lattices and points made here as the module docstring says."""
    qmt = pytest.importorskip("quantized_mesh_tile", reason="quantized-mesh-tile (the tests' decoder) is absent")
    from quantized_mesh_tile.global_geodetic import GlobalGeodetic
    from terrainvis.tiles import tile_lattice
    from terrainvis.tiles.tileset import _rectangle, _Frame

    dem = _cumberland()
    frame = _Frame(dem, "dem")
    rect = _rectangle(dem, frame, "dem")
    kept = pairs = 0
    for f in sorted((out / str(z)).glob("*/*.terrain")):
        x, y = int(f.parent.name), int(f.stem)
        lat_ = tile_lattice(dem, z, x, y, rect, frame=frame)
        west, south, east, north = GlobalGeodetic(tmscompatible=True).TileBounds(x, y, z)
        tile = qmt.decode(str(f), [west, south, east, north], gzipped=True)
        lon, lat, h = np.array(tile.getVerticesCoordinates()).T
        tri = np.array(tile.indices, dtype=np.int64).reshape(-1, 3)
        xs, ys = lat_.to_local(lat_.lon, lat_.lat)
        grid = HeightGrid.from_coords(lat_.z, xs, ys)
        pts = sample_points(grid, N_POINTS, seed=np.random.default_rng([z, x, y]), offset=height)
        iu = np.triu_indices(N_POINTS, 1)
        on_t = visibility_matrix(grid, pts)[iu]
        tx, ty = lat_.to_local(lon, lat)
        tin = TIN(np.column_stack([tx, ty, h]), tri)
        moved = np.column_stack([pts[:, :2], tin.height_at(pts[:, :2]) + height])
        kept += int(np.count_nonzero(visibility_matrix(tin, moved)[iu] == on_t))
        pairs += iu[0].size
    return kept, pairs


@pytest.fixture(scope="module")
def kept_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("keep") / "t"
    ts = write_tileset(_cumberland(), out, method="greedy-insertion", zooms=ZOOMS, keep_los=P)
    return out, ts, json.loads((out / "layer.json").read_text(encoding="utf-8"))


def test_each_zoom_keeps_the_share_and_the_next_rung_up_does_not(kept_run, tmp_path):
    out, ts, layer = kept_run
    assert layer["terrainvis"]["keep_los"]["share"] == P and layer["terrainvis"]["max_error0"] is None
    for r in ts.zooms:
        if r.zoom < ZOOMS[0]:
            assert r.los is None and not r.simplified
            continue
        c = r.los
        kept, pairs = _share_of_written(out, r.zoom)
        assert (kept, pairs) == (c.kept, c.pairs) and c.reached and kept >= P * pairs
        assert layer["terrainvis"]["max_error"][str(r.zoom)] == r.max_error == c.budget > 0
        assert c.tried[-1][0] == c.budget and all(share < P for _, share in c.tried[:-1])
        if len(c.tried) > 1:  # the rung above, written by a plain halving run at its budget, keeps less
            above = tmp_path / f"above{r.zoom}"
            write_tileset(_cumberland(), above, method="greedy-insertion", zooms=(r.zoom, r.zoom),
                          max_error0=c.tried[-2][0] * 2 ** r.zoom)
            k2, p2 = _share_of_written(above, r.zoom)
            assert p2 == pairs and k2 < P * pairs and k2 / p2 == c.tried[-2][1]
    assert any(len(r.los.tried) > 1 for r in ts.zooms if r.los)  # the check above ran


def test_an_interrupted_keep_los_run_resumes_without_searching_again(kept_run, tmp_path, monkeypatch):
    from terrainvis.tiles import keep_los

    out = tmp_path / "t"
    searched = []
    real_choose = keep_los.choose_budget

    def choose(lattices, z, *a, **k):
        searched.append(z)
        if z == ZOOMS[1] and len(searched) == 2:
            raise KeyboardInterrupt
        return real_choose(lattices, z, *a, **k)

    monkeypatch.setattr(keep_los, "choose_budget", choose)
    with pytest.raises(KeyboardInterrupt):
        write_tileset(_cumberland(), out, method="greedy-insertion", zooms=ZOOMS, keep_los=P)
    record = json.loads((out / "terrainvis-tiles.partial.json").read_text())
    assert list(record["chosen"]) == [str(ZOOMS[0])] and record["settings"]["keep_los"] == P
    assert not (out / "layer.json").exists()
    ts = write_tileset(_cumberland(), out, method="greedy-insertion", zooms=ZOOMS, keep_los=P, resume=True)
    assert searched == [ZOOMS[0], ZOOMS[1], ZOOMS[1]]  # zoom 9 was not searched again
    fresh, fresh_ts, fresh_layer = kept_run
    assert [r.as_json() for r in ts.zooms] == [r.as_json() for r in fresh_ts.zooms]
    for f in fresh.rglob("*.terrain"):
        assert gzip.decompress((out / f.relative_to(fresh)).read_bytes()) == gzip.decompress(f.read_bytes()), f


@pytest.mark.parametrize("kwargs, match", [
    ({"keep_los": 0.0}, r"keep_los must be a share of the verdicts in \(0, 1\], got 0.0"),
    ({"keep_los": 1.5}, r"keep_los must be a share"),
    ({"keep_los": True}, r"keep_los must be a share"),
    ({"keep_los": float("nan")}, r"keep_los must be a share"),
    ({"keep_los": 0.9, "los_height": -1.0}, r"los_height must be finite and >= 0 \(m\), got -1.0"),
    ({"keep_los": 0.9, "max_error0": 1000.0}, "max_error0 and keep_los exclude each other"),
])
def test_refusals_name_the_argument(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        write_tileset(_cumberland(), tmp_path / "t", method="simple", zooms=(9, 9), **kwargs)
    assert not (tmp_path / "t").exists()


@pytest.mark.parametrize("argv, expected", [
    (["--keep-los", "0"], "argument --keep-los: expected a share of the verdicts in (0, 1], such as 0.99, got '0'"),
    (["--keep-los", "0.9", "--max-error", "100"], "argument --max-error: not allowed with argument --keep-los"),
    (["--keep-los", "0.9", "--los-height", "-2"], "argument --los-height: expected a distance >= 0, got '-2'"),
])
def test_the_command_line_refuses_in_one_line(capsys, tmp_path, argv, expected):
    err = one_line_error(capsys, 2, ["tiles", "cumberland", str(tmp_path / "t"), "-m", "simple", "--zoom", "9", "9",
                                     *argv])
    assert expected in err


def test_the_command_prints_each_zooms_share(capsys, tmp_path):
    from terrainvis.cli import main

    assert main(["tiles", "cumberland", str(tmp_path / "t"), "-m", "greedy-insertion", "--zoom", "9", "9",
                 "--keep-los", "0.95", "--los-height", "10"]) == 0
    out = capsys.readouterr().out
    layer = json.loads((tmp_path / "t" / "layer.json").read_text())
    c = layer["terrainvis"]["keep_los"]
    assert c["share"] == 0.95 and c["height"] == 10.0
    z9 = c["zooms"]["9"]
    assert f"keeps {100 * z9['kept'] / z9['pairs']:.2f} % of {z9['pairs']:,} sight lines' verdicts" in out
    assert z9["kept"] >= 0.95 * z9["pairs"]


def test_no_rung_that_keeps_the_share_gives_whole_lattices():
    from terrainvis.tiles import keep_los as module

    lat_ = _terrace()
    made = []

    class Made:
        decoded = None

    def make(lat, b):
        made.append(b)
        return Made()

    real = module.kept_pairs
    try:
        module.kept_pairs = lambda lat, s, d: s.verdicts.size - 1  # one pair lost at every rung
        choice, tiles = choose_budget({(0, 0): lat_}, 12, 1.0, 2.0, make)
    finally:
        module.kept_pairs = real
    assert len(made) == module.MAX_RUNGS + 1 and made[-1] is None  # every rung, then the whole lattice
    assert made[-2] == float(np.ptp(lat_.z)) * 2.0 ** (-(module.MAX_RUNGS - 1) / 2)
    assert choice.budget == 0.0 and not choice.reached and choice.kept == choice.pairs - 1
