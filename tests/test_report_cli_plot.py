"""paper_tables, findings, the CLI and the figures."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from terrainvis import compare, plot, report, synthetic_terrain
from terrainvis.cli import main


@pytest.fixture(scope="module")
def df():
    grids = {"m": synthetic_terrain("mountains", size=33, seed=1), "r": synthetic_terrain("ridges", size=33, seed=2)}
    return compare(grids, methods=["simple", "lls", "greedy-insertion"], levels=[1, 2, 3], n_points=15, n_sets=2,
                   workers=1, repeats=1)


def test_paper_tables_values(df):
    t = report.paper_tables(df)
    assert list(t) == ["Table 1", "Table 2", "Table 3", "Table 4", "Cost"]
    t1 = t["Table 1"]
    assert list(t1.index) == [(m, r) for m in ("simple", "lls", "greedy-insertion") for r in ("identity", "full", "half")]
    sel = df[(df.level == 1) & (df.method == "lls") & (df.relocation == "half")]["accuracy"]
    assert t1.loc[("lls", "half"), "mu"] == pytest.approx(100 * sel.mean())
    assert t1.loc[("lls", "half"), "sigma"] == pytest.approx(100 * sel.std(ddof=1))
    assert t1["n"].eq(4).all()  # 2 terrains x 2 sets
    t4 = t["Table 4"]
    sel = df[(df.level == 3) & (df.method == "simple") & (df.relocation == "identity")]["visible_kept"]
    assert t4.loc["simple", ("identity", "visible_kept")] == pytest.approx(100 * sel.mean())
    cost = t["Cost"]
    assert cost.loc[("lls", 1), "memory_ratio"] == pytest.approx(
        df[(df.method == "lls") & (df.level == 1)]["nbytes"].iloc[0] / df["nbytes_original"].iloc[0])
    assert cost.loc[("lls", 2), "size"] == pytest.approx(100 * 81 / 33**2)
    md = report.to_markdown(t)
    assert "### Table 1: accuracy (%) at level 1 (25%)" in md and "| lls | half |" in md


def test_findings_report_each_claim(df):
    found = report.findings(df)
    claims = [f["claim"] for f in found]
    assert "identity is the best relocation overall" in claims
    rel = df.groupby("relocation")["accuracy"].mean()
    held = {f["claim"]: f["held"] for f in found}
    assert held["identity is the best relocation overall"] == bool(rel.idxmax() == "identity")
    assert held["QEC is best at 25%"] is None  # QEC was not run


def test_errors_are_left_out_of_tables(df):
    bad = df.copy()
    bad.loc[bad.index[:3], "error"] = "RuntimeError: boom"
    bad.loc[bad.index[:3], "accuracy"] = np.nan
    assert np.isfinite(report.paper_tables(bad)["Table 1"]["mu"]).all()
    with pytest.raises(ValueError, match="missing"):
        report.paper_tables(df.drop(columns=["accuracy"]))


def test_figures(df):
    from simplifiers import simplify

    g = synthetic_terrain("ridges", size=33, seed=2)
    views = {"lls": simplify(g, "lls", 1), "gi": simplify(g, "greedy-insertion", 1)}
    figs = [
        plot.hillshade(g), plot.hillshade(views["gi"]), plot.terrain_views(g, views),
        plot.accuracy_vs_size(df), plot.tradeoff(df, relocation="half"),
    ]
    from terrainvis import sample_points, visibility_matrix

    P = sample_points(g, 10, seed=0)
    V = visibility_matrix(g, P)
    W = V.copy()
    W[0, 1] = W[1, 0] = not V[0, 1]
    figs.append(plot.los_pairs(g, P, V, W))
    assert all(isinstance(f, Figure) for f in figs)
    legend = [t.get_text() for t in figs[-1].axes[0].get_legend().get_texts()]
    changed = "false blocked (1)" if V[0, 1] else "false visible (1)"
    assert changed in legend
    with pytest.raises(ValueError, match="no rows"):
        plot.tradeoff(df[df.relocation == "full"], relocation="half")


def test_cli_compare_writes_results(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["compare", "--terrain", "hills", "--levels", "1", "--methods", "simple", "lls", "--points", "10",
                 "--sets", "2", "--workers", "1", "--out", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "Table 1" in text and "identity is the best relocation overall" in text
    df = pd.read_csv(out / "results.csv")
    assert len(df) == 1 * 2 * 2 * 3
    assert (out / "tables.md").read_text().startswith("# terrainvis compare")
    for png in ("accuracy_vs_size.png", "tradeoff_full.png", "views_hills.png"):
        assert (out / png).stat().st_size > 1000
    # --resume with everything done runs nothing and gives the same rows
    assert main(["compare", "--terrain", "hills", "--levels", "1", "--methods", "simple", "lls", "--points", "10",
                 "--sets", "2", "--workers", "1", "--out", str(out), "--resume", "--no-plots"]) == 0
    again = pd.read_csv(out / "results.csv")
    pd.testing.assert_frame_equal(again[["accuracy", "method"]], df[["accuracy", "method"]])


def test_cli_errors_list_valid_names(tmp_path, capsys):
    assert main(["compare", "--terrain", "atlantis", "--out", str(tmp_path)]) == 2
    assert "bundled terrain ['hills'" in capsys.readouterr().err
    assert main(["compare", "--terrain", "hills", "--methods", "nope", "--out", str(tmp_path)]) == 2
    assert "method must be one of ['simple'" in capsys.readouterr().err
    assert main(["compare", "--terrain", "hills", "--relocations", "lift", "--out", str(tmp_path)]) == 2
    assert "relocations must be drawn from ['identity', 'full', 'half']" in capsys.readouterr().err


def test_cli_info(capsys):
    assert main(["info", "jacksboro"]) == 0
    assert "120 x 120" in capsys.readouterr().out


def test_single_sample_cells_do_not_break_the_report():
    # One terrain and one point set: every σ is undefined (NaN), which must not raise.
    g = synthetic_terrain("hills", size=17, seed=0)
    df = compare({"h": g}, methods=["gls", "lls", "feature"], levels=[1], n_points=8, n_sets=1, workers=1, repeats=1)
    tables = report.paper_tables(df)
    assert tables["Table 1"]["sigma"].isna().all()
    held = {f["claim"]: f["held"] for f in report.findings(df)}
    assert held["GLS, LLS and feature-aware are about equal, and feature-aware has the lowest σ"] is None
    assert "| gls | identity |" in report.to_markdown(tables)


def test_only_plot_imports_matplotlib():
    import subprocess
    import sys

    code = (
        "import sys\n"
        "import terrainvis as tv, simplifiers\n"
        "from terrainvis import experiment, report, cli, relocation, metrics, io, visibility\n"
        "g = tv.sample_dem('jacksboro').crop(rows=(0, 40), cols=(0, 40))\n"
        "for m in simplifiers.available(): simplifiers.simplify(g, m, 1)\n"
        "P = tv.sample_points(g, 5)\n"
        "tv.visibility_matrix(g, P); tv.visibility_matrix(g.to_tin(), P)\n"
        "print('matplotlib' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
