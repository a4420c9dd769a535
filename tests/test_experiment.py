"""compare(): determinism, workers, dask, localized tests, failures, incremental CSV and resume."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from terrainvis import HeightGrid, compare, synthetic_terrain
from terrainvis.experiment import COLUMNS, DEFAULT_TERRAINS, JACKSBORO_WINDOW, resolve_terrains

MEASURED = ["accuracy", "visible_kept", "blocked_kept", "agree_visible", "agree_blocked", "false_visible",
            "false_blocked", "n_vertices", "nbytes", "max_error", "rms_error", "volume_error"]


@pytest.fixture(scope="module")
def small():
    return {"a": synthetic_terrain("mountains", size=33, seed=1), "b": synthetic_terrain("mesas", size=33, seed=2)}


def _kw(**extra):
    kw = dict(methods=["simple", "lls", "greedy-insertion"], levels=[1, 2], n_points=12, n_sets=2, seed=3, repeats=1)
    kw.update(extra)
    return kw


@pytest.fixture(scope="module")
def serial(small):
    return compare(small, workers=1, **_kw())


def test_shape_and_columns(serial):
    assert list(serial.columns) == list(COLUMNS)
    # terrains x sets x methods x levels x relocations
    assert len(serial) == 2 * 2 * 3 * 2 * 3
    assert (serial["error"] == "").all()
    assert serial["n_pairs"].eq(12 * 11 // 2).all()
    assert serial["accuracy"].between(0, 1).all()
    lv1 = serial[serial["level"] == 1]
    assert lv1["n_vertices"].eq(17 * 17).all() and lv1["size_fraction"].eq(17 * 17 / 33**2).all()


def test_agreement_is_the_one_of_the_matrices(small, serial):
    """Recompute one row by hand from the public pieces."""
    from simplifiers import simplify

    from terrainvis import agreement, relocate, visibility_matrix
    from terrainvis.experiment import point_sets

    row = serial[(serial.terrain == "b") & (serial.method == "lls") & (serial.level == 2)
                 & (serial.relocation == "half") & (serial.set == 1)].iloc[0]
    T = small["b"]
    P = point_sets(T, "b", 12, 2, 3, 0.0)[1]
    S = simplify(T, "lls", 2)
    a = agreement(visibility_matrix(T, P), visibility_matrix(S, relocate(P, S, "half")))
    assert row["accuracy"] == a["accuracy"] and row["false_blocked"] == a["false_blocked"]


def test_deterministic_and_pool_equals_serial(small, serial):
    again = compare(small, workers=2, **_kw())
    pd.testing.assert_frame_equal(again[MEASURED + ["terrain", "method", "level", "relocation", "set"]],
                                  serial[MEASURED + ["terrain", "method", "level", "relocation", "set"]])


def test_point_sets_depend_on_seed_and_name_only(small):
    from terrainvis.experiment import point_sets

    a = point_sets(small["a"], "a", 5, 2, 0, 0.0)
    b = point_sets(small["a"], "a", 5, 2, 0, 0.0)
    c = point_sets(small["a"], "a", 5, 2, 1, 0.0)
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0], a[1]) and not np.array_equal(a[0], c[0])


def test_max_distance_restricts_pairs(small):
    df = compare({"a": small["a"]}, workers=1, **_kw(max_distance=300.0, methods=["lls"], levels=[1]))
    assert (df["n_pairs"] < 66).all() and (df["n_pairs"] > 0).all()
    from terrainvis.experiment import point_sets

    P = point_sets(small["a"], "a", 12, 2, 3, 0.0)[0]
    d = np.hypot(*(P[:, None, :2] - P[None, :, :2]).transpose(2, 0, 1))
    expected = int(np.count_nonzero(np.triu(d <= 300.0, 1)))
    assert df[df["set"] == 0]["n_pairs"].eq(expected).all()


def test_failure_is_recorded_and_the_run_goes_on(small):
    tiny = HeightGrid(np.random.default_rng(0).normal(size=(5, 5)))
    df = compare({"tiny": tiny, "a": small["a"]}, workers=1, **_kw(methods=["lls"], levels=[3]))
    bad = df[df["terrain"] == "tiny"]
    assert len(bad) == 6 and bad["error"].str.contains("level must be in \\[0, 2\\]").all()
    assert bad["accuracy"].isna().all()
    assert (df[df["terrain"] == "a"]["error"] == "").all()


def test_incremental_csv_and_resume(small, tmp_path, monkeypatch):
    from terrainvis import experiment

    out = tmp_path / "results.csv"
    calls = []
    real = experiment._run_unit

    def counting(grid, terrain, method, level, settings):
        calls.append((terrain, method, level))
        if len(calls) == 3:
            raise KeyboardInterrupt  # interrupted after two finished units
        return real(grid, terrain, method, level, settings)

    monkeypatch.setattr(experiment, "_run_unit", counting)
    with pytest.raises(KeyboardInterrupt):
        compare(small, workers=1, out_csv=out, **_kw())
    on_disk = pd.read_csv(out)
    assert len(on_disk) == 2 * 6  # two finished units of 2 sets x 3 relocations are kept
    finished = set(map(tuple, on_disk[["terrain", "method", "level"]].drop_duplicates().to_numpy().tolist()))
    calls.clear()
    monkeypatch.setattr(experiment, "_run_unit", real)
    df = compare(small, workers=1, out_csv=out, resume=True, **_kw())
    assert len(df) == 72 and len(pd.read_csv(out)) == 72
    assert not df.duplicated(["terrain", "method", "level", "set", "relocation"]).any()
    # the resumed result equals an uninterrupted run
    full = compare(small, workers=1, **_kw())
    pd.testing.assert_frame_equal(df[MEASURED], full[MEASURED], check_dtype=False)
    with pytest.raises(ValueError, match="other settings"):
        compare(small, workers=1, out_csv=out, resume=True, **_kw(seed=4))
    assert finished  # the two finished units were not recomputed: checked by row count above


def test_dask_local_cluster_matches_serial(small, serial):
    distributed = pytest.importorskip("distributed", reason="the dask extra is not installed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            df = compare(small, client=client, **_kw())
    pd.testing.assert_frame_equal(df[MEASURED], serial[MEASURED])


def test_resolve_terrains():
    grids = resolve_terrains(["hills", "jacksboro"])
    assert list(grids) == ["hills", "jacksboro"] and grids["jacksboro"].shape == (120, 120)
    (r0, r1), (c0, c1) = JACKSBORO_WINDOW
    from terrainvis import sample_dem

    np.testing.assert_array_equal(grids["jacksboro"].z, sample_dem().z[r0:r1, c0:c1])
    assert set(DEFAULT_TERRAINS) == {"hills", "mesas", "rough", "mountains", "ridges", "jacksboro"}


def test_bad_names_list_the_valid_ones(small):
    with pytest.raises(ValueError, match=r"bundled terrain \['hills'.*'jacksboro'\]"):
        compare(["everest"], workers=1)
    with pytest.raises(ValueError, match=r"method must be one of \['simple'"):
        compare(small, methods=["decimate"], workers=1)
    with pytest.raises(ValueError, match=r"relocations must be drawn from \['identity', 'full', 'half'\]"):
        compare(small, relocations=["lift"], workers=1)
    z = np.zeros((5, 5))
    z[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        compare({"holes": HeightGrid(z)}, workers=1)


def test_save_dir_keeps_every_simplified_terrain(small, tmp_path):
    from simplifiers import simplify

    from terrainvis import TIN
    from terrainvis.experiment import load_simplified, simplified_path

    compare({"a": small["a"]}, workers=1, save_dir=tmp_path, **_kw(n_sets=1))
    for method in ("simple", "lls", "greedy-insertion"):
        for level in (1, 2):
            saved = load_simplified(simplified_path(tmp_path, "a", method, level))
            fresh = simplify(small["a"], method, level)
            if isinstance(fresh, TIN):
                np.testing.assert_array_equal(saved.vertices, fresh.vertices)
                np.testing.assert_array_equal(saved.faces, fresh.faces)
            else:
                np.testing.assert_array_equal(saved.z, fresh.z)
                np.testing.assert_array_equal(saved.xs, fresh.xs)
    assert not list(tmp_path.glob("*.part.npz"))
