"""compare(): determinism, workers, dask, localized tests, failures, validation up front, the CSV and resume."""

from __future__ import annotations

import re

import json

import numpy as np
import pandas as pd
import pytest

from terrainvis.visibility import engine_names

from terrainvis import HeightGrid, compare, synthetic_terrain
from terrainvis.experiment import COLUMNS, DEFAULT_TERRAINS, JACKSBORO_WINDOW, resolve_terrains
from terrainvis.experiment.collect import TIMING_COLUMNS
from terrainvis.experiment.results import settings_path
from terrainvis.relocation.registry import PAPER_RELOCATIONS, available

MEASURED = ["accuracy", "visible_kept", "blocked_kept", "agree_visible", "agree_blocked", "false_visible",
            "false_blocked", "n_vertices", "nbytes", "max_error", "rms_error", "volume_error"]
KEYS = ["terrain", "method", "level", "relocation", "set"]
STABLE = [c for c in COLUMNS if c not in TIMING_COLUMNS]


@pytest.fixture(scope="module")
def small():
    return {"a": synthetic_terrain("mountains", size=33, seed=1), "b": synthetic_terrain("mesas", size=33, seed=2)}


def _kw(**extra):
    # the runner's tests use the paper's three relocations; the calibrated one is tested in
    # test_calibration.py and, through compare, in test_calibrated_in_a_comparison
    kw = dict(methods=["simple", "lls", "greedy-insertion"], levels=[1, 2], n_points=12, n_sets=2, seed=3, repeats=1,
              relocations=list(PAPER_RELOCATIONS))
    kw.update(extra)
    return kw


@pytest.fixture(scope="module")
def serial(small):
    return compare(small, workers=1, **_kw())


def test_shape_and_columns(serial):
    assert list(serial.columns) == list(COLUMNS)
    # terrains x sets x methods x levels x relocations
    assert len(serial) == 2 * 2 * 3 * 2 * 3
    assert serial["error"].isna().all() and (serial["predicate"] == "exact").all()
    assert serial["n_pairs"].eq(12 * 11 // 2).all()
    assert serial["accuracy"].between(0, 1).all() and serial["end_radius"].eq(0).all()
    lv1 = serial[serial["level"] == 1]
    assert lv1["n_vertices"].eq(17 * 17).all() and lv1["size_fraction"].eq(17 * 17 / 33**2).all()
    # sorted: terrains as given, then set, methods in the paper's order, level, relocation
    first = serial[(serial.terrain == "a") & (serial.set == 0)]
    assert list(dict.fromkeys(first["method"])) == ["greedy-insertion", "simple", "lls"]


def test_agreement_is_the_one_of_the_matrices(small, serial):
    """Recompute one row by hand from the public pieces."""
    from simplifiers import simplify

    from terrainvis import agreement, relocate, visibility_matrix, volume_error
    from terrainvis.experiment import point_sets

    row = serial[(serial.terrain == "b") & (serial.method == "lls") & (serial.level == 2)
                 & (serial.relocation == "half") & (serial.set == 1)].iloc[0]
    T = small["b"]
    P = point_sets(T, "b", 12, 2, 3, 0.0)[1]
    S = simplify(T, "lls", 2)
    a = agreement(visibility_matrix(T, P), visibility_matrix(S, relocate(P, S, "half")))
    assert row["accuracy"] == a["accuracy"] and row["false_blocked"] == a["false_blocked"]
    assert row["volume_error"] == volume_error(T, S)


def test_deterministic_and_pool_equals_serial(small, serial):
    again = compare(small, workers=2, **_kw())
    pd.testing.assert_frame_equal(again[MEASURED + KEYS], serial[MEASURED + KEYS])


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


def test_failure_is_recorded_and_the_run_goes_on(small, monkeypatch):
    import simplifiers
    from terrainvis.errors import SimplificationError

    real = simplifiers.simplify

    def failing(grid, method, level=1, **options):
        if method == "lls" and level == 2:
            raise SimplificationError("lls: injected failure")
        return real(grid, method, level, **options)

    monkeypatch.setattr(simplifiers, "simplify", failing)
    df = compare({"a": small["a"]}, workers=1, **_kw(methods=["lls"], levels=[1, 2]))
    bad = df[df["level"] == 2]
    assert len(bad) == 6 and bad["error"].eq("SimplificationError: lls: injected failure").all()
    assert bad["accuracy"].isna().all() and (df[df["level"] == 1]["error"].isna()).all()


def test_everything_is_validated_before_any_unit_runs(small):
    from terrainvis import TIN  # noqa: F401 (the message names the irregular methods)

    tiny = HeightGrid(np.random.default_rng(0).normal(size=(5, 5)))
    cases = [
        (dict(levels=[3]), ValueError, r"levels must be at most 2 for terrain 'tiny' \(5x5"),
        (dict(levels=[1, 1]), ValueError, "levels must not repeat a level, got 1 twice"),
        (dict(levels=1.0), TypeError, "levels must be an integer or a list of integers, got float 1.0"),
        (dict(levels=[0]), ValueError, "levels must be >= 1, got 0"),
        (dict(methods=["lls", "lls"]), ValueError, "methods must not repeat a name, got 'lls' twice"),
        (dict(methods=["decimate"]), ValueError, r"methods must be drawn from \['qec', 'greedy-cuts'"),
        (dict(relocations=["full", "full"]), ValueError, "relocations must not repeat a name"),
        (dict(relocations=["lift"]), ValueError, re.escape(f"relocations must be drawn from {available()}, got 'lift'")),
        (dict(engine="gird"), ValueError, re.escape(f"engine must be one of {engine_names()}, got 'gird'")),
        (dict(engine="grid", methods=["lls", "qec"]), ValueError, r"engine 'grid' works on grids only.*\['qec'\]"),
        (dict(predicate="loose"), ValueError, r"predicate must be one of \['exact', 'paper'\]"),
        (dict(seed=-1), ValueError, "seed must be >= 0, got -1"),
        (dict(n_points=1), ValueError, "n_points must be >= 2, got 1"),
        (dict(n_sets=0), ValueError, "n_sets must be >= 1, got 0"),
        (dict(max_distance=0.0), ValueError, r"max_distance must be > 0 \(or None / inf for every pair\), got 0.0"),
        (dict(client="x"), TypeError, "client must be a dask.distributed.Client, got str 'x'"),
        (dict(workers=0), ValueError, "workers must be >= 1, got 0"),
        (dict(volume="auto"), TypeError, "volume must be True or False"),
    ]
    for kw, exc, match in cases:
        with pytest.raises(exc, match=match):
            compare({"tiny": tiny}, **{**_kw(levels=[1], methods=["lls"]), **kw})
    with pytest.raises(TypeError, match="terrains must be a terrain, a list of terrains or a dict of them, got None"):
        compare(None)


def _interrupt_after(n_finished: int):
    """An ``on_unit`` that raises KeyboardInterrupt once ``n_finished`` units have finished, as a Ctrl-C would."""
    calls = []

    def on_unit(key, rows):
        calls.append(key)
        assert len(rows) and (rows[["terrain", "method"]].to_numpy() == key[:2]).all()
        if len(calls) == n_finished:
            raise KeyboardInterrupt

    return on_unit, calls


def _recording():
    """An ``on_unit`` that records the keys of the units that ran."""
    ran = []
    return (lambda key, rows: ran.append(key)), ran


def test_incremental_csv_and_resume(small, tmp_path, serial):
    out = tmp_path / "results.csv"
    stop, calls = _interrupt_after(2)
    with pytest.raises(KeyboardInterrupt):
        compare(small, workers=1, out_csv=out, on_unit=stop, **_kw())
    assert len(calls) == 2
    on_disk = pd.read_csv(out)
    assert len(on_disk) == 2 * 6  # the two finished units (2 sets x 3 relocations each) are on disk
    finished = {(t, m, (lv,)) for t, m, lv in on_disk[["terrain", "method", "level"]].drop_duplicates().to_numpy().tolist()}
    assert finished == {tuple(k) for k in calls}
    record, rerun = _recording()
    df = compare(small, workers=1, out_csv=out, resume=True, on_unit=record, **_kw())
    assert len(rerun) == 12 - 2 and not finished & {tuple(u) for u in rerun}
    assert len(df) == 72 and len(pd.read_csv(out)) == 72
    assert not df.duplicated(KEYS).any()
    pd.testing.assert_frame_equal(df[STABLE], serial[STABLE], check_dtype=False)
    pd.testing.assert_frame_equal(pd.read_csv(out, dtype={"error": str})[STABLE],
                                  serial[STABLE], check_dtype=False)


def test_resume_after_an_interrupt_before_the_first_unit(small, tmp_path):
    """A Ctrl-C inside the first unit (here: raised by a user's method, registered as users do)."""
    import simplifiers

    state = {"interrupt": True}

    def flaky(grid, level, **options):
        if state.pop("interrupt", False):
            raise KeyboardInterrupt
        return simplifiers.simplify(grid, "lls", level)

    simplifiers.register("flaky-lls", flaky, kind="regular")
    try:
        out = tmp_path / "results.csv"
        kw = _kw(methods=["flaky-lls"])
        with pytest.raises(KeyboardInterrupt):
            compare(small, workers=1, out_csv=out, **kw)
        assert out.read_text().count("\n") == 1  # the header only
        df = compare(small, workers=1, out_csv=out, resume=True, **kw)
        whole = compare(small, workers=1, **kw)  # uninterrupted
    finally:
        simplifiers.unregister("flaky-lls")
    pd.testing.assert_frame_equal(df[STABLE], whole[STABLE], check_dtype=False)
    assert set(df["method"]) == {"flaky-lls"} and len(df) == 2 * 2 * 2 * 3  # terrains x sets x levels x relocations


def test_min_height_error():
    """The error of S(T)'s minimum-visible-height raster: RMS and 95th percentile of |S - T|, on the counted
    cells where both are finite; none when S(T) is T."""
    from terrainvis import viewshed
    from terrainvis.experiment.measures import min_height_error

    t = np.array([[0.0, 1.0, np.nan], [2.0, 0.0, 5.0]])
    s = np.array([[0.0, 3.0, 1.0], [np.nan, -1.0, 5.0]])
    # counted and finite on both: (0,0) error 0, (0,1) error 2, (1,1) error -1, (1,2) error 0
    e = min_height_error(t, s)
    assert e["min_height_rms"] == pytest.approx(np.sqrt(5 / 4))
    assert e["min_height_p95"] == pytest.approx(np.percentile([0.0, 2.0, 1.0, 0.0], 95))  # 1.85
    e = min_height_error(t, s, np.array([[False, True, True], [True, False, False]]))
    assert e == {"min_height_rms": 2.0, "min_height_p95": 2.0}
    assert all(np.isnan(v) for v in min_height_error(t, s, np.zeros(t.shape, bool)).values())
    T = synthetic_terrain("hills", size=33, seed=4)
    eye = np.array([T.xs[10], T.ys[20], T.z[20, 10] + 1.7])
    h = viewshed(T, eye, output="min_height")
    assert (h > 0).any()
    assert min_height_error(h, viewshed(T, eye, at=T, output="min_height")) == {"min_height_rms": 0.0,
                                                                                  "min_height_p95": 0.0}


def test_the_pairs_measure_leaves_the_min_height_columns_empty(small):
    df = compare({"a": small["a"]}, workers=1, **_kw(methods=["lls"], levels=[1]))
    assert df["min_height_rms"].isna().all() and df["min_height_p95"].isna().all() and df["accuracy"].notna().all()
    # and so does the viewshed measure with min_height=False, its other columns the same
    kw = dict(methods=["lls"], levels=[1], seed=3, repeats=1, measure="viewshed", n_observers=2)
    on, off = compare({"a": small["a"]}, workers=1, **kw), compare({"a": small["a"]}, workers=1, min_height=False, **kw)
    assert on["min_height_rms"].notna().all() and off["min_height_rms"].isna().all() and off["min_height_p95"].isna().all()
    rest = [c for c in STABLE if not c.startswith("min_height")]
    pd.testing.assert_frame_equal(on[rest], off[rest])


def test_resume_of_a_file_written_before_the_min_height_columns(small, tmp_path):
    """A results file without the viewshed measure's columns (an older terrainvis) resumes in the pair
    measure, which leaves them empty, and is refused, clearly, in the viewshed measure."""
    out = tmp_path / "results.csv"
    kw = _kw(methods=["simple", "lls"], levels=[1])
    full = compare({"a": small["a"]}, workers=1, out_csv=out, **kw)
    old = pd.read_csv(out, dtype=str, keep_default_na=False)
    old = old[old["method"] == "simple"].drop(columns=["min_height_rms", "min_height_p95"])
    old.to_csv(out, index=False)  # an older file, with the first unit only
    record, rerun = _recording()
    df = compare({"a": small["a"]}, workers=1, out_csv=out, resume=True, on_unit=record, **kw)
    assert rerun == [("a", "lls", (1,))]
    pd.testing.assert_frame_equal(df[STABLE], full[STABLE], check_dtype=False)
    assert pd.read_csv(out).columns.tolist() == list(COLUMNS)  # written back with every column
    vkw = dict(methods=["lls"], levels=[1], seed=3, repeats=1, measure="viewshed", n_observers=1)
    out.unlink()
    compare({"a": small["a"]}, workers=1, out_csv=out, **vkw)
    pd.read_csv(out, dtype=str, keep_default_na=False).drop(columns=["min_height_p95"]).to_csv(out, index=False)
    with pytest.raises(ValueError, match=r"missing columns \['min_height_p95'\].*older terrainvis.*new output"):
        compare({"a": small["a"]}, workers=1, out_csv=out, resume=True, **vkw)


SITING = ["siting_share", "siting_share_original", "siting_ratio"]


def _sited_share(T, S, candidates, k, offset):
    """Independently of siting_coverage: k observers chosen on S, built on T, their union's share of T's samples."""
    from terrainvis import site_observers, viewshed

    chosen = site_observers(S, candidates, k, observer_height=offset, at=T, workers=1).chosen
    seen = np.zeros(T.shape, dtype=bool)
    for x, y in candidates[chosen]:
        seen |= viewshed(T, (x, y), observer_height=offset)
    return seen.sum() / T.size  # a uniform grid without nodata: every sample the same area


def test_siting_in_the_viewshed_measure(small):
    """siting_share: the share of T that k observers chosen on S(T) see on T; siting_share_original: those chosen
    on T; both from the same candidate lattice (8 per side at most); every row of a unit carries the unit's values."""
    from simplifiers import simplify

    from terrainvis import candidate_grid
    from terrainvis.experiment.measures import SITING_LATTICE, siting_coverage

    T = small["a"]
    df = compare({"a": T}, workers=1, methods=["lls", "greedy-insertion"], levels=[1, 3], seed=3, repeats=1,
                 measure="viewshed", n_observers=2, offset=1.7, siting=3, min_height=False,
                 relocations=["identity", "full"])
    candidates = candidate_grid(T, 5)  # ceil(33 / 8)
    assert len(candidates) == 7 * 7 and SITING_LATTICE == 8
    share_t = _sited_share(T, T, candidates, 3, 1.7)
    assert df.groupby(["method", "level"])[SITING].nunique().eq(1).all().all()  # one value per unit
    ratios = []
    for method, level in [("lls", 1), ("lls", 3), ("greedy-insertion", 1), ("greedy-insertion", 3)]:
        S = simplify(T, method, level)
        share = _sited_share(T, S, candidates, 3, 1.7)
        row = df[(df.method == method) & (df.level == level)].iloc[0]
        assert row["siting_share"] == pytest.approx(share, rel=1e-12)
        assert row["siting_share_original"] == pytest.approx(share_t, rel=1e-12)
        assert row["siting_ratio"] == pytest.approx(share / share_t, rel=1e-12)
        ratios.append(row["siting_ratio"])
    assert siting_coverage(T, S, 3, offset=1.7) == {c: row[c] for c in SITING}  # the function compare calls
    assert min(ratios) < 0.99  # the coarsest grid moves the sites (else the test above would check little)
    # k larger than the lattice: every candidate, on S(T) and on T alike
    assert siting_coverage(T, simplify(T, "lls", 3), 100, offset=1.7)["siting_ratio"] == 1.0


def test_siting_of_the_terrain_itself_is_exact():
    """S(T) = T (evaluate with the original as the simplification) chooses T's observers: the ratio is exactly 1."""
    from terrainvis import evaluate

    T = synthetic_terrain("rough", size=33, seed=7)
    df = evaluate({"t": T}, T, name="itself", measure="viewshed", n_observers=1, repeats=1, offset=1.7,
                  relocations=["full"], min_height=False)
    assert (df["siting_ratio"] == 1.0).all() and (df["siting_share"] == df["siting_share_original"]).all()
    assert 0 < df["siting_share"].iloc[0] < 1


def test_the_siting_columns_are_empty_in_the_pairs_measure_and_with_siting_0(small):
    df = compare({"a": small["a"]}, workers=1, **_kw(methods=["lls"], levels=[1]))
    assert df[SITING].isna().all().all() and df["accuracy"].notna().all()
    kw = dict(methods=["lls"], levels=[1], seed=3, repeats=1, measure="viewshed", n_observers=2, min_height=False)
    on, off = compare({"a": small["a"]}, workers=1, **kw), compare({"a": small["a"]}, workers=1, siting=0, **kw)
    assert on[SITING].notna().all().all() and off[SITING].isna().all().all()
    rest = [c for c in STABLE if c not in SITING]
    pd.testing.assert_frame_equal(on[rest], off[rest])
    with pytest.raises(ValueError, match="siting must be >= 0, got -1"):
        compare({"a": small["a"]}, workers=1, siting=-1, **kw)


def test_resume_of_a_file_written_before_the_siting_columns(small, tmp_path):
    """A viewshed results file with the min-height columns but not the siting ones (the version before them) is
    refused naming the three; a pairs file without them resumes."""
    out = tmp_path / "results.csv"
    vkw = dict(methods=["lls"], levels=[1], seed=3, repeats=1, measure="viewshed", n_observers=1, min_height=False)
    compare({"a": small["a"]}, workers=1, out_csv=out, **vkw)
    pd.read_csv(out, dtype=str, keep_default_na=False).drop(columns=SITING).to_csv(out, index=False)
    with pytest.raises(ValueError, match=re.escape(f"missing columns {SITING}") + ".*older terrainvis.*new output"):
        compare({"a": small["a"]}, workers=1, out_csv=out, resume=True, **vkw)
    out.unlink()
    kw = _kw(methods=["simple", "lls"], levels=[1])
    full = compare({"a": small["a"]}, workers=1, out_csv=out, **kw)
    old = pd.read_csv(out, dtype=str, keep_default_na=False)
    old[old["method"] == "simple"].drop(columns=SITING).to_csv(out, index=False)
    record, rerun = _recording()
    df = compare({"a": small["a"]}, workers=1, out_csv=out, resume=True, on_unit=record, **kw)
    assert rerun == [("a", "lls", (1,))]
    pd.testing.assert_frame_equal(df[STABLE], full[STABLE], check_dtype=False)
    assert pd.read_csv(out).columns.tolist() == list(COLUMNS)


def test_resume_is_strict_about_settings(small, tmp_path):
    out = tmp_path / "results.csv"
    compare({"a": small["a"]}, workers=1, out_csv=out, **_kw(methods=["lls"], levels=[1]))
    stored = json.loads(settings_path(out).read_text())
    assert stored["n_points"] == 12 and list(stored["terrains"]) == ["a"]
    with pytest.raises(ValueError, match=r"other settings \(seed: 3 before, 4 now\).*new output.*same settings"):
        compare({"a": small["a"]}, workers=1, out_csv=out, resume=True, **_kw(methods=["lls"], levels=[1], seed=4))
    with pytest.raises(ValueError, match=r"methods: \[\"lls\"\] before, \[\"simple\", \"lls\"\] now"):
        compare({"a": small["a"]}, workers=1, out_csv=out, resume=True, **_kw(methods=["simple", "lls"], levels=[1]))
    with pytest.raises(ValueError, match="terrains: "):
        compare({"b": small["b"]}, workers=1, out_csv=out, resume=True, **_kw(methods=["lls"], levels=[1]))
    # the same name with other heights is another terrain
    changed = small["a"].copy_with(small["a"].z + 1.0)
    with pytest.raises(ValueError, match="terrains: "):
        compare({"a": changed}, workers=1, out_csv=out, resume=True, **_kw(methods=["lls"], levels=[1]))
    settings_path(out).unlink()
    with pytest.raises(ValueError, match="settings file 'results.settings.json' is missing"):
        compare({"a": small["a"]}, workers=1, out_csv=out, resume=True, **_kw(methods=["lls"], levels=[1]))


def test_a_cut_off_last_row_is_dropped_with_a_warning(small, tmp_path):
    out = tmp_path / "results.csv"
    kw = _kw(methods=["simple", "lls"], levels=[1])
    full = compare({"a": small["a"]}, workers=1, out_csv=out, **kw)
    text = out.read_text()
    out.write_text(text[: len(text) - 40])  # a write cut off in the last row (a full disk, a power loss)
    record, rerun = _recording()
    with pytest.warns(RuntimeWarning, match="dropped a cut-off last row"):
        df = compare({"a": small["a"]}, workers=1, out_csv=out, resume=True, on_unit=record, **kw)
    assert rerun == [("a", "lls", (1,))]  # only the unit of the damaged row runs again
    pd.testing.assert_frame_equal(df[STABLE], full[STABLE], check_dtype=False)


def test_out_csv_problems_are_clear(small, tmp_path):
    (tmp_path / "results.csv").mkdir()
    with pytest.raises(ValueError, match="is a folder"):
        compare({"a": small["a"]}, workers=1, out_csv=tmp_path / "results.csv", **_kw(methods=["lls"], levels=[1]))


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


def test_bad_terrains_list_the_valid_ones():
    with pytest.raises(ValueError, match=r"bundled terrain \['hills'.*'jacksboro'\]"):
        compare(["everest"], workers=1)
    z = np.zeros((5, 5))
    z[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        compare({"holes": HeightGrid(z)}, workers=1)


def test_save_dir_keeps_every_simplified_terrain(small, tmp_path):
    from simplifiers import simplify

    from terrainvis import TIN, load_terrain
    from terrainvis.experiment import simplified_path

    compare({"a": small["a"]}, workers=1, save_dir=tmp_path, **_kw(n_sets=1))
    for method in ("simple", "lls", "greedy-insertion"):
        for level in (1, 2):
            saved = load_terrain(simplified_path(tmp_path, "a", method, level))
            fresh = simplify(small["a"], method, level)
            if isinstance(fresh, TIN):
                np.testing.assert_array_equal(saved.vertices, fresh.vertices)
                np.testing.assert_array_equal(saved.faces, fresh.faces)
            else:
                np.testing.assert_array_equal(saved.z, fresh.z)
                np.testing.assert_array_equal(saved.xs, fresh.xs)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        simplified_path(tmp_path, "a", m, lv).name for m in ("simple", "lls", "greedy-insertion") for lv in (1, 2)
    )  # no temporary files left behind


def test_paper_predicate_uses_one_cell_of_the_surface_under_test(small):
    df = compare({"a": small["a"]}, workers=1, predicate="paper", **_kw(levels=[1, 2]))
    assert (df["predicate"] == "paper").all()
    # 33 -> 17 -> 9 samples over 960 m: coarse cells of 60 m and 120 m, for the grids and
    # for the TINs with the same vertex budget
    for (method, level), r in df.groupby(["method", "level"])["end_radius"]:
        assert r.eq(30.0 * 2**level).all(), (method, level)
    exact = compare({"a": small["a"]}, workers=1, **_kw(levels=[1, 2]))
    # T's verdicts are exact in both runs: only the S(T) side changes, and it is never stricter
    assert (df["n_pairs"].to_numpy() == exact["n_pairs"].to_numpy()).all()
    vis_paper = df["agree_visible"] + df["false_visible"]
    vis_exact = exact["agree_visible"] + exact["false_visible"]
    assert (vis_paper.to_numpy() >= vis_exact.to_numpy()).all()


def test_a_distance_sweep_equals_separate_runs(small):
    kw = _kw(methods=["lls"], levels=[2])
    sweep = compare({"a": small["a"]}, workers=1, max_distance=[300.0, None], **kw)
    assert len(sweep) == 2 * 3 * 2
    for d in (300.0, None):
        one = compare({"a": small["a"]}, workers=1, max_distance=d, **kw)
        part = sweep[sweep["max_distance"].isna()] if d is None else sweep[sweep["max_distance"] == d]
        pd.testing.assert_frame_equal(part[MEASURED + ["n_pairs"]].reset_index(drop=True),
                                      one[MEASURED + ["n_pairs"]].reset_index(drop=True))
    cells = compare({"a": small["a"]}, workers=1, max_distance=10, distance_unit="cells", **kw)
    metres = compare({"a": small["a"]}, workers=1, max_distance=300.0, **kw)  # 10 cells of 30 m
    assert (cells["n_pairs"].to_numpy() == metres["n_pairs"].to_numpy()).all()
    assert (cells["distance_unit"] == "cells").all() and (cells["max_distance"] == 10).all()
    with pytest.raises(ValueError, match="max_distance must not repeat a distance"):
        compare({"a": small["a"]}, max_distance=[5.0, 5.0], **kw)
    with pytest.raises(ValueError, match=r"distance_unit must be one of \['world', 'cells'\]"):
        compare({"a": small["a"]}, distance_unit="km", **kw)


def test_oracle_rows_bound_the_practical_ones(small):
    df = compare({"a": small["a"]}, workers=1,
                 **_kw(methods=["lls"], levels=[3], n_sets=1, relocations=["identity", "full", "half", "oracle"]))
    acc = df.set_index("relocation")["accuracy"]
    assert acc["oracle"] >= acc[["identity", "full", "half"]].max()
    # with the calibrated relocation in the run, the oracle starts from it too: never below it
    df = compare({"a": small["a"]}, workers=1, n_partners=64,
                 **_kw(methods=["lls", "greedy-insertion"], levels=[3], n_sets=2,
                       relocations=["oracle", "calibrated", "full"]))
    for _, cell in df.groupby(["method", "set"]):
        acc = cell.set_index("relocation")["accuracy"]
        assert acc["oracle"] >= acc[["calibrated", "full"]].max()


def test_cascade_continues_each_qec_level_from_the_previous(small, tmp_path, monkeypatch):
    from simplifiers import simplify

    from terrainvis.experiment import comparison as experiment

    kw = _kw(methods=["qec", "lls"], levels=[1, 2], n_sets=1)
    g = {"a": small["a"]}
    independent = compare(g, workers=1, cascade=False, **kw)
    cascaded = compare(g, workers=1, cascade=True, **kw)
    assert list(cascaded.groupby(["method", "level"])["cascaded"].all()) == [False, False, False, True]
    assert not independent["cascaded"].any()
    # "auto" (the default) cascades above a grid size only
    pd.testing.assert_frame_equal(compare(g, workers=1, **kw)[STABLE], independent[STABLE])
    monkeypatch.setattr(experiment, "CASCADE_AUTO_MIN_SAMPLES", small["a"].size - 1)
    pd.testing.assert_frame_equal(compare(g, workers=1, **kw)[STABLE], cascaded[STABLE])
    monkeypatch.undo()
    s1 = simplify(small["a"], "qec", 1)
    s2 = simplify(small["a"], "qec", 2, start=s1)
    row = cascaded[(cascaded.method == "qec") & (cascaded.level == 2)].iloc[0]
    assert (row["n_vertices"], row["max_error"]) == (s2.n_vertices, s2.attrs["max_error"])
    same = ["lls"]  # methods that cannot cascade are unchanged, and so is QEC's first level
    pd.testing.assert_frame_equal(cascaded[cascaded.method.isin(same)][MEASURED].reset_index(drop=True),
                                  independent[independent.method.isin(same)][MEASURED].reset_index(drop=True))
    assert cascaded[(cascaded.method == "qec") & (cascaded.level == 1)]["max_error"].iloc[0] == s1.attrs["max_error"]
    # resume after the cascade's first level: the task runs both levels again, rows are not doubled
    out = tmp_path / "results.csv"
    full = compare(g, workers=1, cascade=True, out_csv=out, **kw)
    lines = out.read_text().splitlines()
    level2 = [i for i, line in enumerate(lines) if ",qec,irregular,2," in line]
    assert len(level2) == 3  # 1 set x 3 relocations: drop them as if the run had stopped there
    out.write_text("\n".join(line for i, line in enumerate(lines) if i not in level2) + "\n")
    record, rerun = _recording()
    again = compare(g, workers=1, cascade=True, out_csv=out, resume=True, on_unit=record, **kw)
    assert rerun == [("a", "qec", (1, 2))]
    assert not again.duplicated(KEYS).any() and len(again) == len(full)
    pd.testing.assert_frame_equal(again[STABLE], full[STABLE], check_dtype=False)


def test_calibrated_in_a_comparison(small):
    """compare relocates with the calibrated relocation as relocate does (T, the run's seed, the
    predicate's end radius), and it keeps at least as many verdicts as full projection here."""
    from simplifiers import simplify

    from terrainvis import agreement, relocate, visibility_matrix
    from terrainvis.experiment import point_sets

    T = small["a"]
    df = compare({"a": T}, workers=1, methods=["lls"], levels=[2], n_points=20, n_sets=1, seed=3, repeats=1,
                 relocations=["full", "calibrated"], predicate="paper")
    S = simplify(T, "lls", 2)
    P = point_sets(T, "a", 20, 1, 3, 0.0)[0]
    radius = float(df["end_radius"].iloc[0])
    moved = relocate(P, S, "calibrated", original=T, seed=3, end_radius=radius)
    expected = agreement(visibility_matrix(T, P), visibility_matrix(S, moved, end_radius=radius))["accuracy"]
    acc = df.set_index("relocation")["accuracy"]
    assert acc["calibrated"] == expected
    assert acc["calibrated"] >= acc["full"]


def test_viewshed_measure(small):
    from simplifiers import simplify

    from terrainvis import relocate, viewshed
    from terrainvis.experiment import Settings
    from terrainvis.experiment.measures import observers as _observers

    g = {"a": small["a"]}
    kw = dict(methods=["lls", "greedy-insertion"], levels=[2], seed=3, repeats=1, measure="viewshed", n_observers=3,
              offset=1.7)
    df = compare(g, workers=1, **kw)
    # 2 methods x 3 observers x the 4 default relocations
    assert len(df) == 2 * 3 * 4 and (df["measure"] == "viewshed").all() and df["error"].isna().all()
    assert df["n_pairs"].eq(33 * 33).all()  # every sample of T is a target
    # one row by hand: observer 1 relocated by half onto the TIN, its viewshed of T's samples there
    T = small["a"]
    eye = _observers(T, "a", Settings(n_observers=3, seed=3, offset=1.7))[1]
    S = simplify(T, "greedy-insertion", 2)
    v_t = viewshed(T, eye)
    v_s = viewshed(S, relocate(eye[None], S, "half", offset=1.7)[0], at=T)
    row = df[(df.method == "greedy-insertion") & (df.set == 1) & (df.relocation == "half")].iloc[0]
    assert row["accuracy"] == (v_t == v_s).mean()
    assert row["false_blocked"] == int((v_t & ~v_s).sum())
    assert row["visible_area_ratio"] == pytest.approx(v_s.sum() / v_t.sum())
    # the calibrated observer: placed against targets on the surfaces (target_height), partners from the run's seed
    moved = relocate(eye[None], S, "calibrated", original=T, offset=1.7, target_height=0.0, seed=3)[0]
    v_c = viewshed(S, moved, at=T)
    row = df[(df.method == "greedy-insertion") & (df.set == 1) & (df.relocation == "calibrated")].iloc[0]
    assert row["accuracy"] == (v_t == v_c).mean()
    # the minimum visible height: S(T)'s raster for the half-relocated eye minus T's, where both are finite
    h_t = viewshed(T, eye, output="min_height")
    h_s = viewshed(S, relocate(eye[None], S, "half", offset=1.7)[0], at=T, output="min_height")
    err = (h_s - h_t)[np.isfinite(h_s) & np.isfinite(h_t)]
    assert err.size == 33 * 33 and np.abs(err).max() > 0  # no nodata here; the TIN moves some heights
    row = df[(df.method == "greedy-insertion") & (df.set == 1) & (df.relocation == "half")].iloc[0]
    assert row["min_height_rms"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-12)
    assert row["min_height_p95"] == pytest.approx(np.percentile(np.abs(err), 95), rel=1e-12)
    assert df["min_height_rms"].notna().all() and (df["min_height_p95"] >= 0).all()
    with pytest.raises(ValueError, match="measure 'viewshed' supports predicate 'exact' only"):
        compare(g, predicate="paper", **kw)
    with pytest.raises(ValueError, match=r"measure must be one of \['pairs', 'viewshed'\]"):
        compare(g, **{**kw, "measure": "rays"})



_WARM_UP_SCRIPT = """
import sys
from numba.core import event
import terrainvis as tv
from terrainvis.experiment import plan, units

measure, predicate = sys.argv[1:]
grids = plan.resolve_terrains(["hills"])
settings = plan.settings_for(grids, dict(
    methods=None, levels=[1], relocations=["identity", "full", "half"] + (["oracle"] if measure == "pairs" else []), n_points=8, n_sets=1,
    seed=0, max_distance=[None, 500.0], distance_unit="world", offset=1.0, engine="auto", predicate=predicate,
    volume=True, repeats=1, cascade=False, measure=measure, n_observers=1, target_height=0.0))
tasks = plan.tasks(grids, settings)
for part in plan.warm_up_parts(tasks, grids):
    units.warm_up_part(part, settings)  # not warm_up: a failure must show here
with event.install_recorder("numba:compile") as rec:
    for t, m, levels in tasks:
        rows = units.run_unit(grids[t], t, m, levels, settings, None)
        assert not any(r["error"] for r in rows), rows[0]["error"]
compiled = sorted({ev.data["dispatcher"].py_func.__qualname__ for _, ev in rec.buffer if "dispatcher" in ev.data})
print(compiled)
"""


@pytest.mark.parametrize("measure, predicate", [("pairs", "paper"), ("pairs", "exact"), ("viewshed", "exact")])
def test_the_warm_up_compiles_everything_the_units_need(measure, predicate, tmp_path):
    """A cold run compiles in warm-up parts spread over the workers: the units must then compile nothing."""
    import subprocess
    import sys

    script = tmp_path / "warm.py"
    script.write_text(_WARM_UP_SCRIPT)
    out = subprocess.run([sys.executable, str(script), measure, predicate], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", f"compiled after the warm-up: {out.stdout}"


def test_a_cascade_level_that_fails_is_simplified_from_the_grid(small, monkeypatch):
    import simplifiers
    from terrainvis.errors import SimplificationError

    kw = _kw(methods=["qec"], levels=[1, 2], n_sets=1)
    g = {"a": small["a"]}
    independent = compare(g, workers=1, cascade=False, **kw)
    real = simplifiers.simplify

    def no_cascade(grid, method, level=1, **options):
        if "start" in options:
            raise SimplificationError("qec (fast-simplification backend) produced a mesh that is not a disk")
        return real(grid, method, level, **options)

    monkeypatch.setattr(simplifiers, "simplify", no_cascade)
    fallback = compare(g, workers=1, cascade=True, **kw)
    assert fallback["error"].isna().all() and not fallback["cascaded"].any()
    pd.testing.assert_frame_equal(fallback[STABLE], independent[STABLE])


def test_on_unit_sees_every_unit_once_with_its_rows(small, serial):
    seen = {}

    def on_unit(key, rows):
        assert key not in seen
        assert list(rows.columns) == list(COLUMNS)
        seen[key] = rows

    compare(small, workers=1, on_unit=on_unit, **_kw())
    assert len(seen) == 2 * 3 * 2  # terrains x methods x levels, one level per unit
    rows = pd.concat(seen.values())
    got = rows.set_index(KEYS).sort_index()[MEASURED]
    np.testing.assert_array_equal(got.to_numpy(), serial.set_index(KEYS).sort_index()[MEASURED].to_numpy())
    with pytest.raises(TypeError, match=r"on_unit must be a function of \(key, rows\) or None, got int 5"):
        compare(small, workers=1, on_unit=5, **_kw())
