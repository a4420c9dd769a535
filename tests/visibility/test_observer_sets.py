"""Tests of the observer sets and the intervisibility network (terrainvis.visibility.viewsheds.observers),
and of the GeoPackage layers the network is written to (terrainvis.io._gpkg).

References, independent of the packing and of the chunks:
* each observer's own :func:`terrainvis.viewshed` (bit for bit), and their sum,
  :func:`terrainvis.cumulative_viewshed` (bit for bit, also on two worker processes);
* for the network, the pair engine pair by pair (:func:`terrainvis.min_clearance`,
  :func:`terrainvis.line_of_sight`, both directions) and, for observers standing on
  samples, the viewshed sweep's verdict at the other observer's sample;
* a GeoPackage read back by our reader, by SQLite's own integrity checks, and by GDAL
  (``ogrinfo``) and fiona / pyogrio / osgeo where installed.
"""

from __future__ import annotations

import shutil
import sqlite3
import subprocess

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from terrainvis import (
    HeightGrid,
    ObserverSets,
    cumulative_viewshed,
    intervisibility_network,
    line_of_sight,
    min_clearance,
    observer_sets,
    synthetic_terrain,
    viewshed,
)
from terrainvis.errors import NodataError, NotEnoughMemoryError, OutsideFootprintError
from terrainvis.io import read_geopackage_lines, write_geopackage_lines
from terrainvis.visibility import clearance_tolerance


@pytest.fixture(scope="module")
def hills():
    return synthetic_terrain("hills", size=33, seed=4)


def _observers(grid, k, seed):
    rng = np.random.default_rng(seed)
    xmin, xmax, ymin, ymax = grid.extent
    obs = np.column_stack([rng.uniform(xmin, xmax, k), rng.uniform(ymin, ymax, k)])
    obs[0] = (grid.xs[3], grid.ys[5])  # on a sample
    obs[-1] = (xmax, ymax)  # a corner
    return obs


# ----------------------------------------------------------------- observer sets
@pytest.mark.parametrize("k", [1, 8, 13])
@pytest.mark.parametrize("kw", [
    {},
    {"target_height": 2.0, "max_distance": 400.0},
    {"curvature": 1.0, "earth_radius": 3000.0},
    {"azimuth": (300.0, 60.0), "vertical": (-10.0, 5.0), "min_distance": 100.0, "max_distance": 900.0},
])
def test_sets_are_the_viewsheds_bit_for_bit(hills, k, kw):
    obs = _observers(hills, k, seed=k)
    heights = np.linspace(1.0, 12.0, k)
    sets = observer_sets(hills, obs, observer_height=heights, workers=1, **kw)
    views = [viewshed(hills, o, observer_height=h, **kw) for o, h in zip(obs, heights)]
    for i, v in enumerate(views):
        np.testing.assert_array_equal(sets.seen_by(i), v, err_msg=f"observer {i}")
    total = cumulative_viewshed(hills, obs, observer_height=heights, workers=1, **kw)
    count = sets.count()
    assert count.dtype == total.dtype
    np.testing.assert_array_equal(count, total)
    assert sets.nbytes == hills.size * -(-k // 8)
    assert sets.bits.shape == hills.shape + (-(-k // 8),)
    if k % 8:
        assert not (sets.bits[:, :, -1] & np.uint8((1 << (8 - k % 8)) - 1)).any()  # the unused bits are 0
    stack = np.stack(views, axis=-1)
    for r, c in [(0, 0), (5, 3), (16, 20), (32, 32), (10, 31)]:
        assert sets.observers_at_sample(r, c).tolist() == np.flatnonzero(stack[r, c]).tolist()
    np.testing.assert_array_equal(sets.frequency(), stack.sum(axis=-1) / k)


def test_count_on_two_workers_is_cumulative_viewsheds(hills):
    obs = _observers(hills, 21, seed=3)
    sets = observer_sets(hills, obs, workers=2)
    np.testing.assert_array_equal(sets.count(), cumulative_viewshed(hills, obs, workers=1))
    for i in (0, 7, 8, 20):
        np.testing.assert_array_equal(sets.seen_by(i), viewshed(hills, obs[i]))


def test_nodata_eyes_and_targets_on_another_grid():
    g = synthetic_terrain("ridges", size=25, seed=1)
    z = g.z.copy()
    z[:4, :6] = np.nan
    g = g.copy_with(z)
    obs = _observers(g, 9, seed=2)
    eyes = np.column_stack([obs, g.height_at(obs) + 3.0])
    sets = observer_sets(g, eyes, workers=1)
    for i in range(9):
        np.testing.assert_array_equal(sets.seen_by(i), viewshed(g, eyes[i]))
    assert not sets.valid[:4, :6].any() and np.isnan(sets.frequency()[:4, :6]).all()
    coarse = g.subsample(2)
    on = observer_sets(g, obs, at=coarse, workers=1)
    assert on.shape == coarse.shape
    np.testing.assert_array_equal(on.count(), cumulative_viewshed(g, obs, at=coarse, workers=1))


def test_observers_at_a_position_is_the_nearest_sample(hills):
    obs = _observers(hills, 10, seed=6)
    sets = observer_sets(hills, obs, workers=1)
    dx = hills.dx
    # 0.4 of a cell east and north of sample (r=7, c=11), and 0.6 (nearer (8, 12))
    for (x, y), (r, c) in [((hills.xs[11] + 0.4 * dx, hills.ys[7] + 0.4 * dx), (7, 11)),
                           ((hills.xs[11] + 0.6 * dx, hills.ys[7] + 0.6 * dx), (8, 12)),
                           ((hills.xs[-1], hills.ys[0]), (0, 32))]:
        assert sets.sample_at(x, y) == (r, c)
        assert sets.observers_at(x, y).tolist() == sets.observers_at_sample(r, c).tolist()
    with pytest.raises(OutsideFootprintError, match=r"\(x, y\) must lie inside the grid's footprint"):
        sets.observers_at(-1.0, 10.0)
    with pytest.raises(ValueError, match=r"row must be <= 32, got 33"):
        sets.observers_at_sample(33, 0)


def test_save_and_load(hills, tmp_path):
    obs = _observers(hills, 11, seed=8)
    sets = observer_sets(hills, obs, observer_height=4.0, curvature=0.85714, workers=1)
    sets.save(tmp_path / "s.npz")
    back = ObserverSets.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(back.bits, sets.bits)
    np.testing.assert_array_equal(back.observers, obs)
    assert back.n_observers == 11 and back.settings["curvature"] == 0.85714
    assert back.settings["observer_height"] == 4.0
    np.testing.assert_array_equal(back.count(), sets.count())
    np.savez(tmp_path / "other.npz", z=np.zeros(3))
    with pytest.raises(ValueError, match="is not an observer-sets file"):
        ObserverSets.load(tmp_path / "other.npz")
    with pytest.raises(ValueError, match=r"path must end in .npz"):
        sets.save(tmp_path / "s.bin")


def test_memory_is_checked_first(hills, monkeypatch):
    import terrainvis.core.memory as memory

    monkeypatch.setattr(memory, "available_memory", lambda: 1000)
    with pytest.raises(NotEnoughMemoryError, match=r"observer sets of 20 observers on 33x33 samples"):
        observer_sets(hills, _observers(hills, 20, 0), workers=1)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10_000), k=st.integers(1, 19))
def test_membership_is_the_viewsheds_on_random_terrains(seed, k):
    g = synthetic_terrain(["hills", "ridges", "mesas"][seed % 3], size=13, seed=seed)
    obs = _observers(g, k, seed)
    sets = observer_sets(g, obs, observer_height=2.0, workers=1)
    stack = np.stack([viewshed(g, o, observer_height=2.0) for o in obs], axis=-1)
    np.testing.assert_array_equal(np.unpackbits(sets.bits, axis=-1, count=k).view(bool), stack)


# ----------------------------------------------------------------- the network
@pytest.mark.parametrize("curvature", [0.0, 1.0])
def test_network_against_the_pair_engine(hills, curvature):
    obs = _observers(hills, 9, seed=11)
    heights = np.linspace(0.0, 25.0, 9)
    radius = 3000.0  # a tiny earth, so that curvature matters at 1 km
    net = intervisibility_network(hills, obs, observer_height=heights, curvature=curvature, earth_radius=radius)
    assert len(net) == 9 * 8 // 2
    assert list(zip(net["i"], net["j"])) == [(i, j) for i in range(9) for j in range(i + 1, 9)]
    eyes = np.column_stack([obs, hills.height_at(obs) + heights])
    a, b = eyes[net["i"]], eyes[net["j"]]
    np.testing.assert_allclose(net[["x_i", "y_i", "z_i"]].to_numpy(), a, rtol=1e-12)
    np.testing.assert_allclose(net[["x_j", "y_j", "z_j"]].to_numpy(), b, rtol=1e-12)
    np.testing.assert_allclose(net["distance"], np.hypot(*(b - a)[:, :2].T), rtol=1e-12)
    kw = {"curvature": curvature, "earth_radius": radius}
    forward = min_clearance(hills, a, b, **kw)
    backward = min_clearance(hills, b, a, **kw)
    np.testing.assert_allclose(net["clearance"], forward, rtol=1e-12)
    np.testing.assert_allclose(net["clearance"], backward, rtol=0, atol=1e-9 * 1000)
    assert net["visible"].tolist() == line_of_sight(hills, a, b, engine="grid", **kw).tolist()
    assert net["visible"].tolist() == line_of_sight(hills, b, a, engine="grid", **kw).tolist()
    assert 0 < net["visible"].sum() < len(net)  # the case holds both verdicts
    if curvature:
        flat = intervisibility_network(hills, obs, observer_height=heights)
        assert (net["clearance"] <= flat["clearance"] + 1e-9).all()
        assert (net["clearance"] < flat["clearance"] - 1.0).any()  # the bulge lowers some sight lines by metres


def test_network_agrees_with_the_viewshed_sweep_on_samples(hills):
    rng = np.random.default_rng(5)
    r = rng.integers(0, 33, 10)
    c = rng.integers(0, 33, 10)
    obs = np.column_stack([hills.xs[c], hills.ys[r]])
    net = intervisibility_network(hills, obs, observer_height=6.0)
    for row in net.itertuples():
        seen = viewshed(hills, obs[row.i], observer_height=6.0, target_height=6.0)[r[row.j], c[row.j]]
        assert seen == row.visible, (row.i, row.j, row.clearance, clearance_tolerance(hills))


def test_network_refuses_nodata_and_names_observers_outside(hills):
    z = hills.z.copy()
    z[0, 0] = np.nan
    with pytest.raises(NodataError):
        intervisibility_network(hills.copy_with(z), [[300.0, 300.0], [600.0, 600.0]])
    with pytest.raises(OutsideFootprintError, match=r"observers\[1\] = \(5000.0, 10.0\)"):
        intervisibility_network(hills, [[300.0, 300.0], [5000.0, 10.0]])
    one = intervisibility_network(hills, [[300.0, 300.0]])
    assert len(one) == 0 and "clearance" in one.columns


# ----------------------------------------------------------------- GeoPackage
def _layer(tmp_path, crs="EPSG:26918"):
    lines = np.array([[[500000.0, 4600000.0], [501000.5, 4601000.25]],
                      [[500100.0, 4600050.0], [499000.0, 4602000.0]],
                      [[500000.0, 4600000.0], [500000.0, 4600000.0]]])
    attrs = pd.DataFrame({"i": [0, 0, 1], "j": [1, 2, 2], "clearance": [1.5, -3.25, np.inf],
                          "visible": [True, False, True], "note": ["a", "b", "c"]})
    path = write_geopackage_lines(tmp_path / "net.gpkg", lines, attrs, table="links", crs=crs)
    return path, lines, attrs


def test_geopackage_reads_back_with_our_reader_and_sqlite(tmp_path):
    path, lines, attrs = _layer(tmp_path)
    back = read_geopackage_lines(path)
    np.testing.assert_array_equal(np.stack(back["geometry"].to_list()), lines)
    assert back["i"].tolist() == [0, 0, 1] and back["note"].tolist() == ["a", "b", "c"]
    assert back["visible"].tolist() == [1, 0, 1]  # SQLite's BOOLEAN is an integer
    assert back["clearance"].tolist() == [1.5, -3.25, np.inf]
    assert back.attrs["srs_id"] == 26918 and back.attrs["organization"] == "EPSG"
    con = sqlite3.connect(path)
    try:
        assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert con.execute("PRAGMA foreign_key_check").fetchall() == []
        assert con.execute("PRAGMA application_id").fetchone()[0] == 0x47504B47
        box = con.execute("SELECT min_x, min_y, max_x, max_y FROM gpkg_contents").fetchone()
    finally:
        con.close()
    xy = lines.reshape(-1, 2)
    assert box == (xy[:, 0].min(), xy[:, 1].min(), xy[:, 0].max(), xy[:, 1].max())
    with pytest.raises(ValueError, match="is not a GeoPackage"):
        bad = tmp_path / "plain.gpkg"
        sqlite3.connect(bad).execute("CREATE TABLE t (a)").connection.close()
        read_geopackage_lines(bad)


def test_geopackage_without_a_crs_uses_the_undefined_cartesian_system(tmp_path):
    path, lines, _ = _layer(tmp_path, crs=None)
    assert read_geopackage_lines(path).attrs["srs_id"] == -1


@pytest.mark.skipif(shutil.which("ogrinfo") is None, reason="GDAL's ogrinfo is not on PATH (Debian package gdal-bin)")
def test_gdal_reads_the_geopackage(tmp_path):
    path, lines, attrs = _layer(tmp_path)
    run = subprocess.run(["ogrinfo", "-ro", "-al", str(path)], capture_output=True, text=True, check=True)
    assert "ERROR" not in run.stderr and "Warning" not in run.stderr, run.stderr
    out = run.stdout
    assert "Layer name: links" in out and "Geometry: Line String" in out and "Feature Count: 3" in out
    assert 'ID["EPSG",26918]' in out or 'AUTHORITY["EPSG","26918"]' in out
    assert "LINESTRING (500000 4600000,501000.5 4601000.25)" in out
    assert "visible (Integer(Boolean))" in out and "clearance (Real)" in out
    assert "clearance (Real) = -3.25" in out


@pytest.mark.parametrize("module", ["pyogrio", "fiona", "osgeo.ogr"])
def test_other_readers_read_the_geopackage(tmp_path, module):
    lib = pytest.importorskip(module, reason=f"{module} is not installed (GDAL's ogrinfo is tested above)")
    path, lines, attrs = _layer(tmp_path)
    if module == "pyogrio":
        meta = lib.read_info(path)
        assert meta["features"] == 3 and meta["geometry_type"] == "LineString"
    elif module == "fiona":
        with lib.open(path) as src:
            assert len(src) == 3 and src.schema["geometry"] == "LineString"
    else:
        ds = lib.Open(str(path))
        assert ds.GetLayer(0).GetFeatureCount() == 3


def test_network_figure_draws_the_visible_pairs(hills):
    from terrainvis.experiment import plot

    obs = _observers(hills, 7, seed=11)
    net = intervisibility_network(hills, obs, observer_height=10.0)
    sets = observer_sets(hills, obs, observer_height=10.0, workers=1)
    fig = plot.observer_network(hills, net, frequency=sets.frequency())
    ax = fig.axes[0]
    segments = ax.collections[0].get_segments()
    assert len(segments) == int(net["visible"].sum())
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert legend == [f"see each other ({int(net['visible'].sum())} of 21 pairs)", "7 observers"]
    with pytest.raises(TypeError, match="network must be the DataFrame"):
        plot.observer_network(hills, net[["i", "j"]])
