"""``terrainvis compare --max-error E [E ...]``: budgets in maximum vertical error from the command line."""

from __future__ import annotations

import pandas as pd
import pytest

import simplifiers
import terrainvis as tv
from conftest import one_line_error
from terrainvis.cli import main

SMALL = ["--terrain", "hills", "--methods", "lls", "greedy-insertion", "--points", "8", "--sets", "1",
         "--relocations", "full", "--workers", "1"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One budgeted run of the command, its output folder and what it printed."""
    out = tmp_path_factory.mktemp("cli") / "run"
    capture = pytest.MonkeyPatch()
    import io
    import sys

    printed = io.StringIO()
    capture.setattr(sys, "stdout", printed)
    try:
        code = main(["compare", *SMALL, "--max-error", "3", "10", "--out", str(out)])
    finally:
        capture.undo()
    return code, out, printed.getvalue()


def test_compare_max_error_writes_the_budgets(run):
    code, out, printed = run
    assert code == 0
    df = pd.read_csv(out / "results.csv")
    assert {"max_error_budget", "stopped_by"} <= set(df.columns)
    assert sorted(set(df["max_error_budget"])) == [3.0, 10.0]
    assert ((df["max_error"] <= df["max_error_budget"]) | (df["stopped_by"] != "max_error")).all()
    hills = tv.bundled_terrain("hills")
    for (method, budget), rows in df.groupby(["method", "max_error_budget"]):
        assert set(rows["n_vertices"]) == {simplifiers.simplify(hills, method, max_error=budget).attrs["n_vertices"]}
    tables = (out / "tables.md").read_text()
    assert "### Max error 3: accuracy (%)" in tables and "### Max error 10: accuracy (%)" in tables
    assert "Table 1" not in tables and "The paper side by side and its findings are at its levels" in tables
    assert "### Max error 3: accuracy (%)" in printed
    assert (out / "accuracy_vs_budget.png").is_file() and (out / "views_hills.png").is_file()
    saved = sorted(p.name for p in (out / "simplified").iterdir())
    assert saved == [f"hills__{m}__max_error{e}.npz" for m in ("greedy-insertion", "lls") for e in ("10.0", "3.0")]


def test_resume_of_a_budget_run_runs_no_unit(run, monkeypatch):
    _, out, _ = run
    before = pd.read_csv(out / "results.csv")

    def no_simplify(*args, **kwargs):  # a unit that ran would record this in its rows' error
        raise RuntimeError("a resumed budget run simplified again")

    monkeypatch.setattr(simplifiers, "simplify", no_simplify)
    assert main(["compare", *SMALL, "--max-error", "3", "10", "--out", str(out), "--resume", "--no-plots"]) == 0
    after = pd.read_csv(out / "results.csv")
    pd.testing.assert_frame_equal(after, before)


def test_resume_with_other_budgets_is_one_line(run, capsys):
    _, out, _ = run
    err = one_line_error(capsys, 2, ["compare", *SMALL, "--max-error", "3", "--out", str(out), "--resume"])
    assert "max_errors: [3.0, 10.0] before, [3.0] now" in err


def test_overwrite_removes_the_budget_runs_simplified_terrains(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["compare", "--terrain", "hills", "--methods", "lls", "--points", "6", "--sets", "1", "--relocations",
            "full", "--workers", "1", "--no-plots", "--out", str(out)]
    assert main([*args, "--max-error", "4"]) == 0
    assert (out / "simplified" / "hills__lls__max_error4.0.npz").is_file()
    assert main([*args, "--max-error", "6", "--overwrite"]) == 0
    assert sorted(p.name for p in (out / "simplified").iterdir()) == ["hills__lls__max_error6.0.npz"]


@pytest.mark.parametrize("extra, words", [
    (["--max-error", "2", "--levels", "1"], ["--levels and --max-error cannot be given together"]),
    (["--max-error", "-1"], ["--max-error must hold finite numbers > 0", "got -1.0"]),
    (["--max-error", "nan"], ["--max-error must hold finite numbers > 0", "got nan"]),
    (["--max-error", "abc"], ["--max-error", "expected a maximum vertical error", "'abc'"]),
    (["--max-error", "2", "--cascade"], ["cascade=True (--cascade)", "max_errors (--max-error)"]),
])
def test_bad_max_error_is_one_line(tmp_path, capsys, extra, words):
    err = one_line_error(capsys, 2, ["compare", *SMALL, *extra, "--out", str(tmp_path / "o")])
    for w in words:
        assert w in err, err


def test_quick_keeps_the_budgets_in_place_of_its_levels(monkeypatch, tmp_path):
    from terrainvis.experiment import comparison as experiment

    seen = {}

    class Stop(Exception):
        pass

    def fake(terrains, **kw):
        seen.update(kw)
        raise Stop

    monkeypatch.setattr(experiment, "compare", fake)
    with pytest.raises(Stop):
        main(["compare", "--quick", "--max-error", "5", "--out", str(tmp_path)])
    assert seen["max_errors"] == [5.0] and "levels" not in seen and seen["n_points"] == 20


def test_the_help_names_max_error(capsys):
    with pytest.raises(SystemExit):
        main(["compare", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--max-error E [E ...]" in text and "budgets in maximum vertical error" in text
