"""compare(..., max_errors=[E, ...]): budgets in maximum vertical error in place of levels (issue 39, item 1).

The expectations are computed apart from compare: each unit's simplification is made
again with simplifiers.simplify(grid, method, max_error=E), and every row's measured
error is checked against its budget.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import simplifiers
import terrainvis as tv
from terrainvis.experiment import COLUMNS
from terrainvis.experiment.collect import BUDGET_KEY, UNIT_KEY, unit_key
from terrainvis.experiment.report import step_column
from terrainvis.experiment.plan import settings_for
from terrainvis.experiment.units import stopped_by

METHODS = ["lls", "greedy-insertion"]
BUDGETS = [2.0, 8.0]
RELOCATIONS = ["identity", "full"]
RUN = dict(methods=METHODS, max_errors=BUDGETS, n_points=10, n_sets=2, relocations=RELOCATIONS, workers=1)


@pytest.fixture(scope="module")
def hills():
    return tv.bundled_terrain("hills")


@pytest.fixture(scope="module")
def budget_run(tmp_path_factory):
    """A small budgeted run written to a results file (the resume tests continue it)."""
    out = tmp_path_factory.mktemp("budgets") / "results.csv"
    df = tv.compare(["hills"], **RUN, out_csv=out)
    return df, out


def test_a_budget_run_has_the_columns_and_one_unit_per_method_and_budget(budget_run):
    df, _ = budget_run
    assert list(df.columns) == list(COLUMNS)
    assert df["error"].isna().all()
    units = df.groupby(list(BUDGET_KEY)).size()
    assert sorted(units.index) == sorted(("hills", m, e) for m in METHODS for e in BUDGETS)
    assert (units == 2 * len(RELOCATIONS)).all()  # sets x relocations


def test_every_row_is_within_its_budget_or_says_it_is_not(budget_run):
    df, _ = budget_run
    assert df["stopped_by"].notna().all()
    from terrainvis.tolerances import MAX_ERROR_TIE_REL

    within = df["max_error"] <= df["max_error_budget"] * (1.0 + MAX_ERROR_TIE_REL)  # a tie's rounding aside
    assert (within | (df["stopped_by"] != "max_error")).all()
    assert (df.loc[within, "stopped_by"] == "max_error").all()


def test_each_unit_is_simplifys_smallest_result_within_its_budget(budget_run, hills):
    df, _ = budget_run
    for (method, budget), rows in df.groupby(["method", "max_error_budget"]):
        want = simplifiers.simplify(hills, method, max_error=budget).attrs
        assert set(rows["n_vertices"]) == {want["n_vertices"]}, (method, budget)
        assert rows["max_error"].iloc[0] == pytest.approx(want["max_error"], rel=1e-12)
        if simplifiers.METHODS[method].regular:  # the level the method reached
            assert set(rows["level"]) == {want["level"]}
        else:  # simplify records none for an irregular method simplified to an error alone
            assert want["level"] is None and rows["level"].isna().all()


def test_a_larger_budget_never_gives_more_vertices(budget_run):
    df, _ = budget_run
    for _, rows in df.groupby(["terrain", "method"]):
        counts = rows.groupby("max_error_budget")["n_vertices"].first().sort_index()
        assert counts.is_monotonic_decreasing, counts
        assert len(counts) == len(BUDGETS)


def test_resuming_a_budget_run_measures_nothing_new(budget_run, monkeypatch):
    df, out = budget_run
    import simplifiers.registry

    def no_simplify(*args, **kwargs):
        raise AssertionError("a resumed budget run simplified again")

    monkeypatch.setattr(simplifiers.registry, "simplify", no_simplify)
    monkeypatch.setattr(simplifiers, "simplify", no_simplify)
    seen = []
    again = tv.compare(["hills"], **RUN, out_csv=out, resume=True, on_unit=lambda key, rows: seen.append(key))
    assert seen == []
    pd.testing.assert_frame_equal(again, df)


def test_a_resume_with_other_budgets_or_with_levels_is_refused(budget_run):
    _, out = budget_run
    with pytest.raises(ValueError, match=r"other settings \(.*max_errors: \[2\.0, 8\.0\] before, \[2\.0, 9\.0\] now"):
        tv.compare(["hills"], **{**RUN, "max_errors": [2.0, 9.0]}, out_csv=out, resume=True)
    levels = {k: v for k, v in RUN.items() if k != "max_errors"}
    with pytest.raises(ValueError, match=r"levels: \[\] before, \[1\] now.*max_errors: \[2\.0, 8\.0\] before, null now"):
        tv.compare(["hills"], **levels, levels=[1], out_csv=out, resume=True)


def test_budget_units_are_keyed_apart_from_level_units(hills):
    grids = {"hills": hills}
    assert unit_key(settings_for(grids, {"max_errors": [3]})) == BUDGET_KEY
    assert unit_key(settings_for(grids, {})) == UNIT_KEY
    assert settings_for(grids, {"max_errors": 3}).levels == ()


def test_a_run_by_levels_leaves_the_budget_columns_empty():
    df = tv.compare(["hills"], methods=["lls"], levels=[2], n_points=8, n_sets=1, relocations=["full"], workers=1)
    assert df["max_error_budget"].isna().all() and df["stopped_by"].isna().all()
    assert list(df["level"]) == [2] and step_column(df) == "level"


@pytest.mark.parametrize("bad, shown", [
    (0, "got 0.0"), (-1.5, "got -1.5"), (float("nan"), "got nan"), (float("inf"), "got inf"),
    ("2", "got str '2'"), (True, "got bool True"), ([2.0, None], "got NoneType None"),
])
def test_a_bad_budget_is_a_value_error_naming_max_errors(hills, bad, shown):
    with pytest.raises(ValueError, match=r"^max_errors must hold finite numbers > 0 \(maximum vertical errors, z "
                                         r"units\), got ") as info:
        tv.compare({"hills": hills}, methods=["lls"], max_errors=bad, workers=1)
    assert shown in str(info.value)


def test_empty_or_repeated_budgets_are_refused(hills):
    with pytest.raises(ValueError, match="max_errors must hold at least one maximum vertical error"):
        tv.compare({"hills": hills}, max_errors=[], workers=1)
    with pytest.raises(ValueError, match="max_errors must not repeat an error, got 2.0 twice"):
        tv.compare({"hills": hills}, max_errors=[2, 2.0], workers=1)


def test_levels_and_max_errors_together_are_refused_naming_both(hills):
    with pytest.raises(ValueError, match="^levels and max_errors cannot be given together"):
        tv.compare({"hills": hills}, levels=[1, 2, 3], max_errors=[2.0], workers=1)


def test_cascade_true_with_budgets_is_refused_and_auto_never_cascades_them(hills):
    from terrainvis.experiment.plan import cascades, tasks

    with pytest.raises(ValueError, match=r"^cascade=True \(--cascade\) chains the levels .* max_errors"):
        tv.compare({"hills": hills}, max_errors=[2.0], cascade=True, workers=1)
    settings = settings_for({"hills": hills}, {"methods": ["qec"], "max_errors": [2.0, 5.0], "cascade": "auto"})
    assert not cascades(settings, hills, "qec", auto_min_samples=0)  # "auto" would cascade levels on this grid
    assert sorted(t[2] for t in tasks({"hills": hills}, settings, auto_min_samples=0)) == [(2.0,), (5.0,)]


def test_stopped_by_flags_a_result_over_its_budget():
    assert stopped_by({"max_error": 1.0, "stopped_by": "max_error"}, 2.0) == "max_error"
    assert stopped_by({"max_error": 1.0, "stopped_by": "budget"}, 2.0) == "max_error"  # met all the same
    assert stopped_by({"max_error": 3.0, "stopped_by": "budget"}, 2.0) == "budget"
    assert stopped_by({"max_error": 3.0, "stopped_by": "max_error"}, 2.0) == "exceeded"  # a claim the error belies
    assert stopped_by({"max_error": 3.0}, 2.0) == "exceeded"
    assert stopped_by({"max_error": float("nan"), "stopped_by": "max_error"}, 2.0) == "exceeded"
    # a tie measured a rounding above the budget (Jacksboro's greedy cuts at E = 10: 1.1e-12 above) meets it;
    # a miss of a millionth of it does not
    assert stopped_by({"max_error": 10.0 + 1.1e-12, "stopped_by": "max_error"}, 10.0) == "max_error"
    assert stopped_by({"max_error": 10.0 + 1e-5, "stopped_by": "max_error"}, 10.0) == "exceeded"


def _corners(grid, n_vertices, max_error=None):
    """An irregular method that claims any error met and returns the grid's two corner triangles."""
    from terrainvis import TIN

    x, y = np.meshgrid(grid.xs[[0, -1]], grid.ys[[0, -1]])
    v = np.column_stack([x.ravel(), y.ravel(), grid.z[np.ix_([0, -1], [0, -1])].ravel()])
    tin = TIN(v, np.array([[0, 1, 3], [0, 3, 2]]))
    tin.attrs["stopped_by"] = "max_error"
    return tin


def test_a_result_over_its_budget_keeps_its_rows_and_is_flagged(hills):
    simplifiers.register("corners", _corners, kind="irregular", default=False, replace=True)
    try:
        df = tv.compare({"hills": hills}, methods=["corners", "lls"], max_errors=[2.0], n_points=8, n_sets=1,
                        relocations=["full"], workers=1)
    finally:
        simplifiers.unregister("corners")
    row = df[df["method"] == "corners"].iloc[0]
    assert pd.isna(row["error"]) and row["n_vertices"] == 4 and np.isfinite(row["accuracy"])
    assert row["max_error"] > 2.0 and row["stopped_by"] == "exceeded"
    assert df[df["method"] == "lls"]["stopped_by"].eq("max_error").all()


def test_the_tables_go_by_budget(budget_run):
    from terrainvis.experiment import report

    df, _ = budget_run
    tables = report.paper_tables(df)
    assert [k for k in tables if k.startswith("Max error")] == ["Max error 2", "Max error 8"]
    assert not any(k.startswith(("Table 1", "Table 2", "Table 3", "Level")) for k in tables)
    t2 = tables["Max error 2"]
    want = 100 * df[(df["max_error_budget"] == 2.0) & (df["method"] == "lls")
                    & (df["relocation"] == "full")]["accuracy"].mean()
    assert t2.loc[("lls", "full"), "mu"] == pytest.approx(want)
    assert "max error ≤ 8" in tables["Table 4"].attrs["title"]
    assert tables["Cost"].index.names == ["method", "max_error_budget"]
    assert set(tables["Cost"].index) == {(m, e) for m in METHODS for e in BUDGETS}
    text = report.to_markdown(tables)
    assert "### Max error 2: accuracy (%)" in text
    assert all(f["verdict"] == "no data" for f in report.findings(df))
    assert (report.paper_comparison(df)["n"] == 0).all()  # the paper's cells are at its levels


def test_a_table_of_level_and_budget_rows_together_is_refused(budget_run):
    from terrainvis.experiment import report

    df, _ = budget_run
    mixed = pd.concat([df, df.assign(max_error_budget=np.nan, level=1)], ignore_index=True)
    with pytest.raises(ValueError, match="rows of a run by levels .* and of a run budgeted in maximum vertical error"):
        report.paper_tables(mixed)


def test_the_figures_go_by_budget(budget_run):
    from matplotlib.figure import Figure

    from terrainvis.experiment import plot

    df, _ = budget_run
    fig = plot.accuracy_vs_budget(df)
    assert isinstance(fig, Figure)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "max vertical error budget (z units)"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["2", "8"]
    assert len(ax.containers) == len(METHODS)  # one error-bar line per method
    assert "max error budget" in plot.tradeoff(df, relocation="full").axes[0].get_title()
    assert isinstance(plot.accuracy_vs_size(df), Figure)
    levels = df.assign(max_error_budget=np.nan, level=1)
    with pytest.raises(ValueError, match="df holds no budget in vertical error"):
        plot.accuracy_vs_budget(levels)


def test_a_results_file_from_before_budgets_resumes_as_a_run_by_levels(tmp_path, monkeypatch):
    out = tmp_path / "results.csv"
    run = dict(methods=["lls"], levels=[1], n_points=8, n_sets=1, relocations=["full"], workers=1, out_csv=out)
    first = tv.compare(["hills"], **run)
    old = pd.read_csv(out).drop(columns=["max_error_budget", "stopped_by"])  # as terrainvis wrote it before
    old.to_csv(out, index=False, lineterminator="\n")
    seen = []
    again = tv.compare(["hills"], **run, resume=True, on_unit=lambda key, rows: seen.append(key))
    assert seen == []
    pd.testing.assert_frame_equal(again, first)
    assert {"max_error_budget", "stopped_by"} <= set(pd.read_csv(out).columns)  # written back with them
