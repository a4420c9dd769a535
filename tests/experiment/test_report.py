"""paper_tables, findings (as the paper states them), and the paper side by side."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from terrainvis import compare, synthetic_terrain
from terrainvis.experiment import report
from terrainvis.relocation.registry import PAPER_RELOCATIONS


@pytest.fixture(scope="module")
def df():
    grids = {"m": synthetic_terrain("mountains", size=33, seed=1), "r": synthetic_terrain("ridges", size=33, seed=2)}
    return compare(grids, methods=["simple", "lls", "greedy-insertion"], levels=[1, 2, 3], n_points=15, n_sets=2,
                   workers=1, repeats=1)


def test_paper_tables_values(df):
    t = report.paper_tables(df)
    assert list(t) == ["Table 1", "Table 2", "Table 3", "Table 4", "Cost"]
    t1 = t["Table 1"]
    # the paper's row order: irregular methods first
    assert list(t1.index) == [(m, r) for m in ("greedy-insertion", "simple", "lls") for r in ("identity", "full", "half")]
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


def test_errors_are_left_out_of_tables(df):
    bad = df.copy()
    bad.loc[bad.index[:3], "error"] = "RuntimeError: boom"
    bad.loc[bad.index[:3], "accuracy"] = np.nan
    assert np.isfinite(report.paper_tables(bad)["Table 1"]["mu"]).all()
    with pytest.raises(ValueError, match="missing"):
        report.paper_tables(df.drop(columns=["accuracy"]))


def test_several_predicates_need_a_choice(df):
    both = pd.concat([df, df.assign(predicate="paper")])
    with pytest.raises(ValueError, match=r"several predicates \['exact', 'paper'\]; pass predicate="):
        report.paper_tables(both)
    assert report.paper_tables(both, predicate="paper")["Table 1"]["n"].eq(4).all()
    assert {f["predicate"] for f in report.findings(both)} == {"exact", "paper"}


def test_findings_report_each_claim(df):
    found = report.findings(df)
    assert [f["claim"] for f in found] == list(report.CLAIMS)
    by = {f["claim"]: f for f in found}
    assert all(f["verdict"] in report.VERDICTS for f in found)
    paper = df[df["relocation"].isin(PAPER_RELOCATIONS)]  # the paper's claims are about its relocations
    rel = 100 * paper.groupby("relocation")["accuracy"].mean()
    sd = 100 * paper.groupby("relocation")["accuracy"].std(ddof=1)
    identity = by["identity is the best relocation overall, with the lowest σ"]
    expected = "held" if rel.idxmax() == "identity" and sd.idxmin() == "identity" else "did not hold"
    assert identity["verdict"] == expected and f"identity {rel['identity']:.2f}" in identity["evidence"]
    assert by["QEC is best at every level"]["verdict"] == "no data"  # QEC was not run
    half = by["half projection is the worst relocation at 1.5%"]
    r3 = paper[paper.level == 3].groupby("relocation")["accuracy"].mean()
    assert half["verdict"] == ("held" if r3.idxmin() == "half" else "did not hold")
    md = report.findings_markdown(found)
    assert any("predicate: exact" in line for line in md)


def _synthetic(acc: dict) -> pd.DataFrame:
    """Rows with chosen accuracies: {(method, level, relocation): [values]}."""
    rows = []
    for (m, lv, r), values in acc.items():
        for s, a in enumerate(values):
            rows.append({"terrain": "t", "set": s, "method": m, "level": lv, "relocation": r, "accuracy": a,
                         "predicate": "exact", "error": None})
    return pd.DataFrame(rows)


def test_findings_ties_and_no_data_are_not_did_not_hold():
    tie = _synthetic({("qec", 1, "full"): [0.9, 0.92], ("lls", 1, "full"): [0.9, 0.92],
                      ("qec", 1, "half"): [0.8, 0.8], ("lls", 1, "half"): [0.8, 0.8]})
    by = {f["claim"]: f["verdict"] for f in report.findings(tie)}
    assert by["QEC is best at every level"] == "tie"
    assert by["half projection is the worst relocation at 1.5%"] == "no data"  # no level 3
    assert by["identity is the best relocation overall, with the lowest σ"] == "no data"  # no identity rows
    allnan = tie.assign(accuracy=np.nan)
    assert {f["verdict"] for f in report.findings(allnan)} == {"no data"}
    worse = _synthetic({("qec", 1, "full"): [0.8], ("lls", 1, "full"): [0.9], ("qec", 2, "full"): [0.95],
                        ("lls", 2, "full"): [0.9]})
    assert {f["claim"]: f["verdict"] for f in report.findings(worse)}["QEC is best at every level"] == "did not hold"


def test_paper_reference_is_the_published_csv():
    ref = report.paper_reference()
    assert len(ref) == 63 + 28
    row = ref[(ref.table == 1) & (ref.method == "qec") & (ref.relocation == "identity")].iloc[0]
    assert (row.mu, row.sigma) == (98.2, 1.2)
    assert list(dict.fromkeys(ref["method"])) == ["qec", "greedy-cuts", "greedy-insertion", "simple", "gls", "lls",
                                                    "feature"]


def test_paper_comparison_uses_the_papers_convention(df):
    cmp = report.paper_comparison(df)
    cell = cmp.loc[(1, 1, "lls", "half", "accuracy")]
    sel = df[(df.level == 1) & (df.method == "lls") & (df.relocation == "half")]
    # the paper's |P x P|: 2 * agreeing distinct pairs + the n self-pairs, over n²
    n = 15
    paper_way = (2 * (sel["agree_visible"] + sel["agree_blocked"]) + n) / n**2
    assert cell["ours"] == pytest.approx(100 * paper_way.mean())
    assert cell["paper"] == 96.1 and cell["difference"] == pytest.approx(cell["ours"] - 96.1)
    vis = cmp.loc[(4, 3, "simple", "identity", "visible_kept")]
    s3 = df[(df.level == 3) & (df.method == "simple") & (df.relocation == "identity")]
    expected = (2 * s3["agree_visible"] + n) / (2 * (s3["agree_visible"] + s3["false_blocked"]) + n)
    assert vis["ours"] == pytest.approx(100 * expected.mean())
    rms, count = cmp.attrs["rms"]["accuracy"]
    diffs = cmp.loc[[1, 2, 3], "difference"].dropna()
    assert count == len(diffs) == 3 * 3 * 3 and rms == pytest.approx(np.sqrt((diffs**2).mean()))
    assert cmp.loc[(1, 1, "qec", "full", "accuracy"), "n"] == 0  # not run: no figure of ours
    text = report.comparison_markdown(cmp)
    assert "| 1 | 1 | lls | half | accuracy |" in text and "RMS difference over the 27 accuracy cells" in text


def test_oracle_gap_and_localized_tables():
    g = {"h": synthetic_terrain("hills", size=33, seed=4)}
    df = compare(g, methods=["lls"], levels=[2], n_points=15, n_sets=2, workers=1, repeats=1,
                 relocations=["identity", "full", "half", "oracle"], max_distance=[5, 10, None], distance_unit="cells")
    gap = report.oracle_gap(df)
    allpairs = df[df["max_distance"].isna()]
    mu = 100 * allpairs.groupby("relocation")["accuracy"].mean()
    row = gap.loc[("lls", 2)]
    assert row["oracle"] == pytest.approx(mu["oracle"])
    assert row["best"] == mu[["identity", "full", "half"]].idxmax()
    assert row["gap"] == pytest.approx(mu["oracle"] - mu[["identity", "full", "half"]].max()) and row["gap"] >= 0
    # the oracle's own table (its registry entry's), unless a table shown already covers the oracle
    own = report.relocation_tables(df)
    assert list(own) == ["oracle"]
    pd.testing.assert_frame_equal(own["oracle"], gap)
    assert own["oracle"].attrs["title"].startswith("Oracle bound")
    shown = {"beyond": pd.DataFrame({"x": [1.0]})}
    shown["beyond"].attrs["covers"] = ["oracle"]
    assert report.relocation_tables(df, shown) == {}
    loc = report.localized(df)
    assert list(loc.columns) == ["5.00", "10.00", "all"]
    sel = df[(df["relocation"] == "half") & (df["max_distance"] == 10)]["accuracy"]
    assert loc.loc[(2, "half"), "10.00"] == pytest.approx(100 * sel.mean())
    # the main tables and the findings use the all-pairs rows of a sweep
    assert report.paper_tables(df)["Table 2"]["n"].eq(2).all()  # level 2: the paper's Table 2
    assert "oracle" not in report.findings(df)[3]["evidence"]


def test_viewshed_table():
    g = {"h": synthetic_terrain("hills", size=33, seed=4)}
    df = compare(g, methods=["lls"], levels=[1, 2], workers=1, repeats=1, measure="viewshed", n_observers=3,
                 offset=1.7)
    t = report.viewshed_table(df)
    sel = df[(df.level == 2) & (df.relocation == "full")]
    assert t.loc[("lls", 2, "full"), "cells_kept"] == pytest.approx(100 * sel["accuracy"].mean())
    assert t.loc[("lls", 2, "full"), "area_ratio"] == pytest.approx(sel["visible_area_ratio"].median())
    # the error of the minimum visible height (m): means over the observers
    assert t.loc[("lls", 2, "full"), "min_height_rms"] == pytest.approx(sel["min_height_rms"].mean())
    assert t.loc[("lls", 2, "full"), "min_height_p95"] == pytest.approx(sel["min_height_p95"].mean())
    assert (t["min_height_p95"] > 0).all()
    # the siting: one per unit (every relocation shows it), means over terrains
    for c in ("siting_share", "siting_share_original", "siting_ratio"):
        assert t.loc[("lls", 2, "full"), c] == pytest.approx(sel[c].mean())
        assert t.loc[("lls", 2, "full"), c] == t.loc[("lls", 2, "identity"), c]
    assert t["siting_ratio"].between(0, 2).all() and (t["siting_share"] > 0).all()
    text = report.to_markdown({"viewsheds": t})
    assert "minimum visible height" in text and "sited on S(T) and on T" in text
    assert "| min_height_rms | min_height_p95 | siting_share | siting_share_original | siting_ratio | n |" in text
    assert f"| {t.loc[('lls', 2, 'full'), 'min_height_rms']:.2f} | {t.loc[('lls', 2, 'full'), 'min_height_p95']:.2f} |" in text
    tables = report.paper_tables(df)
    assert "cells whose verdict survives" in tables["Table 1"].attrs["title"]
    assert tables["Table 4"].attrs["title"].startswith("Table 4: visible and blocked cells kept (%)")
    with pytest.raises(ValueError, match="no viewshed rows"):
        report.viewshed_table(compare(g, methods=["lls"], levels=[1], n_points=5, n_sets=1, workers=1, repeats=1))


def test_a_semi_regular_method_counts_on_neither_side_of_regular_against_irregular():
    import simplifiers  # rtin is registered from terrainvis's entry points; its library is not needed here

    assert simplifiers.METHODS["rtin"].kind == "semi-regular"
    base = {("qec", 1, "full"): [0.95, 0.97], ("lls", 1, "full"): [0.90, 0.92]}
    claim = "regular methods are only marginally poorer than irregular ones"
    alone = {f["claim"]: f for f in report.findings(_synthetic(base))}[claim]
    assert "irregular 96.00, regular 91.00" in alone["evidence"], alone["evidence"]
    # rtin (a semi-regular RTIN) far below both: neither mean moves
    with_rtin = {f["claim"]: f for f in report.findings(_synthetic({**base, ("rtin", 1, "full"): [0.5, 0.5]}))}[claim]
    assert with_rtin["evidence"] == alone["evidence"]
