"""Adding a measure touches the registry and the measure's own module only.

A toy measure, *stars* (each point set's first point against every other point: n - 1
pairs instead of the matrix's n (n - 1) / 2), is written as a module of its own (in a
temporary folder) and given one :func:`terrainvis.experiment.measures.register` call.
``compare`` runs it in this process and on worker processes, the plan's memory check and
the rows of a complete unit read it, the results table holds the column of its own
(``star_seen``), the report's tables say what it counts, and the command line's
``--measure`` offers it.
"""

from __future__ import annotations

import textwrap

import numpy as np
import pandas as pd
import pytest

from terrainvis import agreement, compare, relocate, synthetic_terrain, visibility_matrix
from terrainvis.cli import main
from terrainvis.experiment import measures, point_sets, report

_MODULE = '''
"""A toy measure: each set's first point against every other one."""
import dataclasses
import time

import numpy as np

from terrainvis import agreement, relocate, visibility_matrix
from terrainvis.experiment.measures import point_sets


def sets(grid, name, settings):
    return point_sets(grid, name, settings.n_points, settings.n_sets, settings.seed, settings.offset)


def rows(grid, simplified, base, settings, sets, sight):
    out = []
    for s, pts in enumerate(sets):
        star = np.zeros((len(pts), len(pts)), dtype=bool)
        star[0, 1:] = True
        t0 = time.perf_counter()
        v_true = visibility_matrix(grid, pts, sight=sight)
        t_true = time.perf_counter() - t0
        for how in settings.relocations:
            moved = relocate(pts, simplified, how, offset=settings.offset, original=grid)
            t0 = time.perf_counter()
            v_test = visibility_matrix(simplified, moved, sight=dataclasses.replace(sight, end_radius=base["end_radius"]))
            t_test = time.perf_counter() - t0
            for d in settings.max_distance:
                out.append(dict(base, set=s, relocation=how, max_distance=d, los_seconds=t_test,
                                los_seconds_original=t_true, star_seen=float(v_true[0, 1:].mean()),
                                **agreement(v_true, v_test, star)))
    return out


def unit_bytes(settings, grids):
    return 2 * settings.n_points ** 2


def n_points(settings):
    return settings.n_points


def n_sets(settings):
    return settings.n_sets


def tables(df):
    t = df.groupby("relocation")[["n_pairs"]].sum()
    t.attrs["title"] = "Stars: the pairs counted, by relocation"
    return {"stars": t}
'''


@pytest.fixture
def toy(tmp_path, monkeypatch):
    (tmp_path / "toy_stars.py").write_text(textwrap.dedent(_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    import toy_stars

    entry = measures.register(measures.Measure(
        "stars", toy_stars.sets, toy_stars.rows, "pairs", "the first point of each set against the others",
        n_points=toy_stars.n_points, n_sets=toy_stars.n_sets, unit_bytes=toy_stars.unit_bytes,
        tables=toy_stars.tables, columns=("star_seen",)))
    yield entry
    measures.unregister("stars")


def _kw(**extra):
    return {**dict(methods=["lls"], levels=[1], n_points=10, n_sets=2, repeats=1, seed=4,
                   relocations=["full", "half"]), **extra}


def test_compare_runs_it_and_counts_the_star(toy):
    grid = synthetic_terrain("hills", size=33, seed=3)
    df = compare({"g": grid}, measure="stars", workers=1, **_kw())
    assert df["error"].isna().all() and len(df) == 2 * 2 and set(df["measure"]) == {"stars"}
    assert (df["n_pairs"] == 9).all()  # n - 1 pairs per set
    # the same counts by hand from the public API
    from simplifiers import simplify

    S = simplify(grid, "lls", 1)
    pts = point_sets(grid, "g", 10, 2, 4, 0.0)[1]
    star = np.zeros((10, 10), dtype=bool)
    star[0, 1:] = True
    expected = agreement(visibility_matrix(grid, pts), visibility_matrix(S, relocate(pts, S, "half")), star)
    row = df[(df["set"] == 1) & (df["relocation"] == "half")].iloc[0]
    assert row["agree_visible"] == expected["agree_visible"] and row["accuracy"] == pytest.approx(expected["accuracy"])
    # its own column, after the agreement counts and the viewshed measure's own
    cols = list(df.columns)
    assert cols.index("star_seen") == cols.index("siting_ratio") + 1
    assert row["star_seen"] == pytest.approx(visibility_matrix(grid, pts)[0, 1:].mean())
    tables = report.paper_tables(df)
    assert tables["Table 1"].attrs["title"].startswith("Table 1: accuracy (%)")


def test_its_column_is_stored_and_resumed_and_empty_elsewhere(toy, tmp_path):
    """The stars' own column is written to the results file and read back on a resume; a
    pairs run beside it leaves it empty; a pairs file written before the measure was
    registered (without the column) still resumes."""
    grid = synthetic_terrain("hills", size=33, seed=3)
    csv = tmp_path / "stars.csv"
    first = compare({"g": grid}, measure="stars", workers=1, out_csv=csv, **_kw())
    assert "star_seen" in pd.read_csv(csv).columns
    again = compare({"g": grid}, measure="stars", workers=1, out_csv=csv, resume=True, **_kw())
    pd.testing.assert_series_equal(first["star_seen"], again["star_seen"])
    pairs = compare({"g": grid}, workers=1, **_kw())
    assert pairs["star_seen"].isna().all()
    measures.unregister("stars")
    old = tmp_path / "pairs.csv"
    compare({"g": grid}, workers=1, out_csv=old, **_kw())
    assert "star_seen" not in pd.read_csv(old).columns
    measures.register(toy)
    resumed = compare({"g": grid}, workers=1, out_csv=old, resume=True, **_kw())
    assert resumed["star_seen"].isna().all() and len(resumed) == len(pairs)


@pytest.mark.parametrize("name, fields, error, match", [
    ("pairs", {}, ValueError, "measure 'pairs' is built in and cannot be replaced"),
    ("fuzzy", {"predicates": ("fuzzy",)}, ValueError, r"predicates must be some of \['exact', 'paper'\], got \['fuzzy'\]"),
    ("broken", {"tables": "stars"}, TypeError, "measure 'broken': tables must be callable or None, got str"),
    ("broken", {"columns": ("accuracy",)}, ValueError, r"measure 'broken': columns \['accuracy'\] are taken"),
    ("broken", {"columns": ("star_seen",)}, ValueError, r"measure 'broken': columns \['star_seen'\] are taken"),
    ("broken", {"columns": "star_seen"}, TypeError, "measure 'broken': columns must be a tuple of column names"),
    ("broken", {"rows": None}, TypeError, "measure 'broken': rows must be callable"),
])
def test_the_registry_is_checked(toy, name, fields, error, match):
    entry = {"sets": toy.sets, "rows": toy.rows, "n_points": toy.n_points, "n_sets": toy.n_sets,
             "unit_bytes": toy.unit_bytes, **fields}
    with pytest.raises(error, match=match):
        measures.register(measures.Measure(name, counts="pairs", summary="x", **entry))


def test_compare_refuses_a_measure_not_registered(toy):
    with pytest.raises(ValueError, match=r"measure must be one of \['pairs', 'viewshed', 'stars'\], got 'star'"):
        compare({"g": synthetic_terrain("hills", size=33)}, measure="star", workers=1, **_kw())


@pytest.mark.slow
def test_worker_processes_get_it(toy):
    grid = synthetic_terrain("hills", size=33, seed=3)
    serial = compare({"g": grid}, measure="stars", workers=1, **_kw(levels=[1, 2]))
    pooled = compare({"g": grid}, measure="stars", workers=2, **_kw(levels=[1, 2]))
    cols = ["level", "set", "relocation", "accuracy", "n_pairs"]
    pd.testing.assert_frame_equal(serial[cols], pooled[cols])


def test_the_command_line_offers_it(toy, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["compare", "--terrain", "hills", "--levels", "1", "--methods", "lls", "--points", "8", "--sets", "1",
                 "--repeats", "1", "--workers", "1", "--measure", "stars", "--relocations", "full", "--no-plots",
                 "--out", str(out)]) == 0
    df = pd.read_csv(out / "results.csv")
    assert set(df["measure"]) == {"stars"} and (df["n_pairs"] == 7).all()
    # its own table in the report; not the paper's side by side, whose cells are the paper's matrices
    text = (out / "tables.md").read_text()
    assert "### Stars: the pairs counted, by relocation\n" in text and "| full | 7 |" in text, text
    assert "The paper side by side" not in text and "Table 1: accuracy" in text
    with pytest.raises(SystemExit):
        main(["compare", "--help"])
    assert "stars" in capsys.readouterr().out
