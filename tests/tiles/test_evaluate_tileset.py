"""terrainvis.evaluate(DEM, TILESET_DIR, zoom=[...]) and terrainvis evaluate DEM TILESET_DIR --zoom Z: tilesets
measured as any simplification, and their one-line refusals."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest
from test_read_tileset import CUMBERLAND, _qm_encoder_tileset, _rgb_tileset

import terrainvis
from terrainvis.cli import main
from terrainvis.core.terrain import HeightGrid
from terrainvis.experiment.collect import TIMING_COLUMNS
from terrainvis.tiles import write_tileset
from terrainvis.tiles.read import stitch_zoom

pytest.importorskip("pyproj")

QUICK = dict(relocations=["identity", "full"], n_points=30, n_sets=2)


@pytest.fixture(scope="module")
def dem():
    return terrainvis.load_dem(CUMBERLAND)


@pytest.fixture(scope="module")
def ours(dem, tmp_path_factory):
    """A tileset terrainvis tiles wrote over Cumberland: zoom 9 as whole lattices, 10 simplified (greedy insertion)."""
    out = tmp_path_factory.mktemp("ours")
    write_tileset(dem, out, method="greedy-insertion", zooms=(10, 10), lattice=16)
    return out


def test_a_tileset_is_measured_as_its_stitched_tin_to_the_last_pair(dem, ours):
    got = terrainvis.evaluate({"cumberland": dem}, {"ts": ours}, zoom=[9, 10], **QUICK)
    assert got["error"].isna().all()
    assert sorted(set(zip(got["method"], got["zoom"]))) == [("ts-z10", 10), ("ts-z9", 9)]
    tins = {f"ts-z{z}": stitch_zoom(dem, ours, z) for z in (9, 10)}
    want = terrainvis.evaluate({"cumberland": dem}, tins, **QUICK)  # a stitched TIN keeps its zoom
    drop = list(TIMING_COLUMNS)
    pd.testing.assert_frame_equal(got.drop(columns=drop), want.drop(columns=drop))
    # every pair's verdict: the agreement counts of every point set and relocation
    assert (got["agree_visible"] + got["agree_blocked"] + got["false_visible"] + got["false_blocked"]
            == got["n_pairs"]).all()


def test_a_tileset_of_another_encoder_is_read_and_measured(dem, tmp_path):
    ts = _qm_encoder_tileset(tmp_path / "qme", dem, 10, max_error=5.0)
    df = terrainvis.evaluate({"cumberland": dem}, ts, zoom=10, **QUICK)
    assert df["error"].isna().all() and (df["zoom"] == 10).all()
    row = df.iloc[0]
    # tiles within 5 m (20 m every other tile) of a 65 x 65 lattice of each tile, ~270 m apart: the DEM's
    # 90 m samples between lattice points add to it, as the tiles' own error does not see them
    assert 20.0 < row["max_error"] < 150.0 and row["rms_error"] < 15.0
    assert 1000 < row["n_vertices"] < dem.size
    assert df["accuracy"].mean() > 0.9


@pytest.mark.parametrize("mesh,err", [("grid", None), ("delatin", [10.0]), ("martini", 10.0)])
def test_a_terrain_rgb_tileset_is_read_and_measured(dem, tmp_path, mesh, err):
    if mesh == "martini":
        pytest.importorskip("pymartini")
    ts = _rgb_tileset(tmp_path / "rgb", dem, 11, width=128)  # pixels of ~123 m at 36.6 degrees north
    df = terrainvis.evaluate({"cumberland": dem}, ts, zoom=[11], tile_mesh=mesh, tile_max_error=err, **QUICK)
    assert df["error"].isna().all()
    row = df.iloc[0]
    # 123 m pixels of a 90 m DEM (measured: max 23-31 m, rms 4.4-5.6 m); a tile read upside down or shifted by
    # a pixel row is off by far more
    assert row["rms_error"] < 8.0 and row["max_error"] < 50.0
    if mesh == "grid":  # every pixel over the DEM's 28.8 x 30.2 km: about 235 x 247
        assert 50_000 < row["n_vertices"] < 70_000
    else:  # Martini's right triangles need more vertices than Delatin's for one error
        assert row["n_vertices"] < (20_000 if mesh == "delatin" else 35_000)
    assert df["accuracy"].mean() > 0.9


def test_the_offset_moves_the_tiles(dem, ours):
    a = terrainvis.evaluate({"cumberland": dem}, ours, zoom=10, **QUICK)
    b = terrainvis.evaluate({"cumberland": dem}, ours, zoom=10, tile_offset=-50.0, **QUICK)
    assert b["rms_error"].iloc[0] > a["rms_error"].iloc[0] + 20


# ---------------------------------------------------------------------- refusals, from Python
def test_zoom_is_required_with_a_tileset_and_lists_the_present_ones(dem, ours):
    with pytest.raises(ValueError, match=r"^zoom must name the zooms of tileset '.*' to measure; it holds zooms 0-10$"):
        terrainvis.evaluate({"cumberland": dem}, ours, **QUICK)
    with pytest.raises(ValueError, match=r"^zoom 12, 13 not in tileset '.*', which holds zooms 0-10$"):
        terrainvis.evaluate({"cumberland": dem}, ours, zoom=[10, 12, 13], **QUICK)


def test_zoom_without_a_tileset_and_bad_tile_options(dem, tmp_path):
    with pytest.raises(ValueError, match="zoom chooses the zooms of a tileset, and no simplified terrain is a tileset"):
        terrainvis.evaluate({"cumberland": dem}, dem.to_tin(), zoom=3, **QUICK)
    with pytest.raises(ValueError, match=r"tile_mesh 'martini' meshes at a maximum error per zoom; give "
                                         r"tile_max_error \(none for zoom 3\)"):
        terrainvis.evaluate({"cumberland": dem}, dem.to_tin(), zoom=3, tile_mesh="martini", **QUICK)
    with pytest.raises(ValueError, match=r"tile_max_error must be one error or one per zoom of zoom \(2\), got 3"):
        terrainvis.evaluate({"cumberland": dem}, dem.to_tin(), zoom=[3, 4], tile_max_error=[1, 2, 3], **QUICK)


# ---------------------------------------------------------------------- refusals, from the command line
def _one_line(capsys, argv) -> str:
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("terrainvis evaluate: error: "), err
    assert "Traceback" not in err
    return lines[0]


def test_cli_refusals_are_one_line(dem, ours, tmp_path, capsys):
    base = ["evaluate", str(CUMBERLAND)]
    line = _one_line(capsys, base + [str(ours)])
    assert "--zoom must name the zooms of tileset" in line and "holds zooms 0-10" in line
    line = _one_line(capsys, base + [str(ours), "--zoom", "14"])
    assert line.endswith(f"--zoom 14 not in tileset {str(ours)!r}, which holds zooms 0-10")

    missing = shutil.copytree(ours, tmp_path / "missing")
    victim = sorted((missing / "10").glob("*/*.terrain"))[-1]
    victim.unlink()
    line = _one_line(capsys, base + [str(missing), "--zoom", "10"])
    assert f"missing ({victim.parent.parent.name}/{victim.parent.name}/{victim.stem})" in line
    assert "does not cover the DEM at zoom 10" in line

    corrupt = shutil.copytree(ours, tmp_path / "corrupt")
    victim = sorted((corrupt / "10").glob("*/*.terrain"))[0]
    victim.write_bytes(b"garbage")
    line = _one_line(capsys, base + [str(corrupt), "--zoom", "10"])
    assert f"tile {str(victim)!r} is not a readable quantized-mesh-1.0 tile" in line

    for field, value, said in (("scheme", "quadkey", "declares scheme 'quadkey'; expected tms, xyz or slippyMap"),
                               ("projection", "EPSG:2056", "declares projection 'EPSG:2056'; expected EPSG:4326 or "
                                                           "EPSG:3857")):
        bad = shutil.copytree(ours, tmp_path / field)
        layer = json.loads((bad / "layer.json").read_text())
        layer[field] = value
        (bad / "layer.json").write_text(json.dumps(layer))
        assert said in _one_line(capsys, base + [str(bad), "--zoom", "10"])

    bare = tmp_path / "bare.npz"
    terrainvis.save_terrain(HeightGrid.from_coords(dem.z, dem.xs, dem.ys), bare)
    line = _one_line(capsys, ["evaluate", str(bare), str(ours), "--zoom", "10"])
    assert "original has no CRS (attrs['crs'])" in line


def test_cli_measures_a_tileset_and_draws_the_zoom_figure(ours, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["evaluate", str(CUMBERLAND), str(ours), "--zoom", "9", "10", "--relocations", "identity",
                 "--points", "20", "--sets", "1", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    df = pd.read_csv(out / "results.csv")
    assert sorted(df["zoom"].unique().tolist()) == [9, 10]
    assert (out / "accuracy_vs_zoom.png").is_file()
    assert "zoom" in text.splitlines()[1]
    assert np.isfinite(df["accuracy"]).all()
