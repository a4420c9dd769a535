"""The paper's tables from a :func:`terrainvis.compare` result, and a check of its findings.

Tables 1-3 of Alderson and Samavati give the mean (μ) and standard deviation (σ) of the
accuracy for each method and relocation at 25 %, 6 % and 1.5 % of the samples (levels 1,
2 and 3 on 120x120 maps), with σ taken over terrains x point sets. Table 4 gives the
rate of visible and of blocked pairs that stay so, for the identity and half
relocations at the deepest level. The cost table adds what the paper did not measure:
the line-of-sight speedup and the memory ratio of S(T) against T.

A run budgeted in maximum vertical error (``compare(..., max_errors=[E, ...])``) gets the
same tables with the budget E in place of the level ("Max error E", Table 4 at the
largest budget, the cost table by method and budget); the paper side by side and its
findings are about its levels, and leave such rows out.

Rows follow the paper's order (the registry's): QEC, greedy cuts, greedy insertion,
simple, GLS, LLS, feature-aware, and the relocations identity, full, half. Accuracies
are in percent. σ is the sample standard deviation (ddof = 1).

:func:`paper_comparison` puts the paper's published figures (Tables 1-4, shipped as
``terrainvis/data/alderson_samavati_2012_tables.csv``) beside ours, cell by cell, and
:func:`findings` checks the paper's qualitative findings as the paper states them.

Reference: T. Alderson and F. Samavati, "Reverse subdivision for optimizing visibility
tests", GRAPP 2012, pp. 143-150, doi:10.5220/0003851501430150.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = [
    "paper_tables", "to_markdown", "findings", "findings_markdown", "paper_reference", "paper_comparison",
    "comparison_markdown", "oracle_gap", "accuracy_by_relocation", "relocation_tables", "method_notes", "localized",
    "viewshed_table", "budgeted_rows", "step_column",
]

_LEVEL_FRACTION = {1: "25%", 2: "6%", 3: "1.5%"}


def budgeted_rows(df: pd.DataFrame) -> pd.Series:
    """Which rows of a table belong to a run budgeted in maximum vertical error (a ``max_error_budget``)."""
    if "max_error_budget" not in df.columns:
        return pd.Series(False, index=df.index)
    return df["max_error_budget"].notna()


def step_column(df: pd.DataFrame) -> str:
    """The column a table's units are by: ``"level"``, or ``"max_error_budget"`` when its rows are of a
    run budgeted in maximum vertical error (the tables and figures put the budget in the level's place).

    Raises
    ------
    ValueError
        When ``df`` holds rows of both kinds of run.
    """
    budget = budgeted_rows(df)
    if not budget.any():
        return "level"
    if not budget.all():
        raise ValueError(f"df holds rows of a run by levels ({int((~budget).sum())}, max_error_budget empty) and of "
                         f"a run budgeted in maximum vertical error ({int(budget.sum())}); select one kind first")
    return "max_error_budget"


def _step_label(step: str, value) -> str:
    """``"level 2"``, or ``"max error ≤ 2.5"`` for a budget."""
    return f"level {value}" if step == "level" else f"max error ≤ {value:g}"


def _ok(df: pd.DataFrame, predicate: str | None = None) -> pd.DataFrame:
    """The rows without an error, of one predicate and one distance.

    The predicate is the only one present, or ``predicate``. Of a distance sweep, the
    rows counting every pair are used (or the only distance present).
    """
    if "error" in df.columns:
        df = df[df["error"].fillna("").astype(str) == ""]
    if "predicate" in df.columns:
        present = sorted(set(df["predicate"].dropna()))
        if predicate is None and len(present) > 1:
            raise ValueError(f"df holds rows of several predicates {present}; pass predicate= to choose one")
        if predicate is not None:
            df = df[df["predicate"] == predicate]
    if "max_distance" in df.columns and df["max_distance"].nunique(dropna=False) > 1:
        if not df["max_distance"].isna().any():
            raise ValueError(
                f"df holds a distance sweep without the all-pairs rows {sorted(df['max_distance'].unique())}; "
                "select one distance first"
            )
        df = df[df["max_distance"].isna()]
    return df


def _ordered(index_values, order):
    rank = {v: i for i, v in enumerate(order)}
    return sorted(index_values, key=lambda v: rank.get(v, len(rank)))


def _counts(data: pd.DataFrame) -> str:
    """What the rows' agreement counts (the measure's :attr:`~terrainvis.experiment.measures.Measure.counts`):
    ``"pairs"`` unless every row is of one measure that counts something else. The
    registry is looked up by kind (:func:`terrainvis.core.registry.registry`): its entries
    name tables of this module."""
    from ..core.registry import registry

    known = registry("measure") or {}
    measures = set(data["measure"]) if "measure" in data.columns else set()
    if len(measures) == 1 and next(iter(measures)) in known:
        return known[next(iter(measures))].counts
    return "pairs"


def paper_tables(df: pd.DataFrame, *, predicate: str | None = None) -> dict[str, pd.DataFrame]:
    """Tables 1-3, Table 4 and the cost table.

    Parameters
    ----------
    df : pandas.DataFrame
        The result of :func:`terrainvis.compare` (rows with an ``error`` are left out).
    predicate : str, optional
        The predicate whose rows to use, when ``df`` holds several.

    Returns
    -------
    dict of str to DataFrame
        ``"Table k"`` for each of the paper's levels k = 1, 2, 3 present (the paper's
        table numbers, whichever levels ran) and ``"Level k"`` for a deeper level,
        shallowest first: index (method, relocation), columns ``mu`` and ``sigma`` of accuracy
        (%) and ``n`` (terrain x set samples). ``"Table 4"``: index method, columns
        (relocation, ``visible_kept`` / ``blocked_kept``) in % at the deepest level, for
        identity and half. ``"Cost"``: index (method, level), columns ``size`` (% of
        the original samples), ``memory_ratio`` (bytes of S(T) / bytes of T),
        ``los_speedup`` (LOS time on T / on S(T)), ``simplify_s``, ``max_error``,
        ``rms_error`` and ``volume_error`` (medians over terrains). For a run budgeted in
        maximum vertical error, ``"Max error E"`` for each budget E (smallest first) in
        place of the levels' tables, Table 4 at the largest budget, and the cost table by
        (method, ``max_error_budget``).
    """
    from simplifiers import METHODS

    from ..relocation.registry import PAPER_RELOCATIONS as RELOCATIONS

    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"df must be a pandas DataFrame from terrainvis.compare, got {type(df).__name__}")
    missing = {"method", "level", "relocation", "accuracy"} - set(df.columns)
    if missing:
        raise ValueError(f"df must have the columns of terrainvis.compare, missing {sorted(missing)}")
    every = _ok(df, predicate)
    step = step_column(every)
    as_step = int if step == "level" else float
    data = every[every["relocation"].isin(RELOCATIONS)]  # the paper's tables: its relocations only
    counts = _counts(data)
    what = "accuracy (%)" if counts == "pairs" else f"{counts} whose verdict survives (%)"
    tables: dict[str, pd.DataFrame] = {}
    levels = sorted(as_step(v) for v in data[step].unique())
    for level in levels:
        sub = data[data[step] == level]
        g = sub.groupby(["method", "relocation"])["accuracy"]
        t = pd.DataFrame({"mu": 100 * g.mean(), "sigma": 100 * g.std(ddof=1), "n": g.size()})
        idx = [
            (m, r)
            for m in _ordered(sub["method"].unique(), METHODS)
            for r in _ordered(sub["relocation"].unique(), RELOCATIONS)
            if (m, r) in t.index
        ]
        t = t.loc[idx]
        if step == "level":
            # the paper's Tables 1-3 are its levels 1-3: the same numbers, whichever levels ran
            name = f"Table {level}" if level in _LEVEL_FRACTION else f"Level {level}"
            share = f" ({_LEVEL_FRACTION[level]})" if level in _LEVEL_FRACTION else ""
            t.attrs["title"] = f"{name}: {what} at level {level}{share}"
        else:
            name = f"Max error {level:g}"
            t.attrs["title"] = f"{name}: {what}, each method at its smallest result within {level:g} (z units)"
        tables[name] = t
    if levels:
        deepest = levels[-1]  # the deepest level, or the largest budget: the coarsest results
        sub = data[(data[step] == deepest) & data["relocation"].isin(["identity", "half"])]
        if len(sub):
            g = sub.groupby(["method", "relocation"])[["visible_kept", "blocked_kept"]].mean() * 100
            t4 = g.unstack("relocation")
            t4 = t4.swaplevel(0, 1, axis=1)
            cols = [(r, c) for r in ("identity", "half") for c in ("visible_kept", "blocked_kept") if (r, c) in t4.columns]
            t4 = t4[cols].loc[_ordered(t4.index, METHODS)]
            t4.attrs["title"] = f"Table 4: visible and blocked {counts} kept (%) at {_step_label(step, deepest)}"
            tables["Table 4"] = t4
    per_unit = every.drop_duplicates(["terrain", "method", step, "set", "relocation"])  # cost: every relocation
    per_unit = per_unit.assign(
        speedup=per_unit["los_seconds_original"] / per_unit["los_seconds"],
        memory_ratio=per_unit["nbytes"] / per_unit["nbytes_original"],
    )
    g = per_unit.groupby(["method", step])
    cost = pd.DataFrame(
        {
            "size": 100 * g["size_fraction"].median(),
            "memory_ratio": g["memory_ratio"].median(),
            "los_speedup": g["speedup"].median(),
            "simplify_s": g["simplify_seconds"].median(),
            "max_error": g["max_error"].median(),
            "rms_error": g["rms_error"].median(),
            "volume_error": g["volume_error"].median(),
        }
    )
    every_level = sorted(as_step(v) for v in every[step].unique())
    idx = [(m, lv) for m in _ordered({i[0] for i in cost.index}, METHODS) for lv in every_level if (m, lv) in cost.index]
    cost = cost.loc[idx]
    cost.attrs["title"] = "Cost: what S(T) buys (medians over terrains, point sets and relocations)"
    tables["Cost"] = cost
    return tables


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        if not np.isfinite(v):
            return "–"
        if v != 0 and (abs(v) >= 1e5 or abs(v) < 0.1):
            return f"{v:.3g}"
        return f"{v:.2f}"
    return str(v)


def to_markdown(tables: dict[str, pd.DataFrame]) -> str:
    """All tables as GitHub-flavoured markdown, each under its title."""
    out = []
    for name, t in tables.items():
        out.append(f"### {t.attrs.get('title', name)}\n")
        index_names = [n or "" for n in (t.index.names if isinstance(t.index, pd.MultiIndex) else [t.index.name])]
        cols = [" ".join(map(str, c)) if isinstance(c, tuple) else str(c) for c in t.columns]
        out.append("| " + " | ".join(index_names + cols) + " |")
        out.append("|" + "---|" * (len(index_names) + len(cols)))
        columns = [t[c].tolist() for c in t.columns]  # per column, so integers stay integers
        for i, idx in enumerate(t.index):
            keys = list(idx) if isinstance(idx, tuple) else [idx]
            out.append("| " + " | ".join([str(k) for k in keys] + [_fmt(col[i]) for col in columns]) + " |")
        out.append("")
    return "\n".join(out)


# ---------------------------------------------------------------------- findings
#: Differences smaller than this (percentage points) are ties: the tables print two decimals.
TIE = 0.005

#: The verdicts of :func:`findings`.
VERDICTS = ("held", "did not hold", "tie", "no data")


def _gap_verdict(gap: float) -> str:
    """``gap`` > 0 supports the claim; within :data:`TIE` of 0 is a tie."""
    if not np.isfinite(gap):
        return "no data"
    if abs(gap) <= TIE:
        return "tie"
    return "held" if gap > 0 else "did not hold"


def _means(data, by) -> pd.Series:
    return 100 * data.groupby(by)["accuracy"].mean().dropna()


def _list(series: pd.Series) -> str:
    return ", ".join(f"{k} {v:.2f}" for k, v in series.sort_values(ascending=False).items())


def _qec_best(data):
    parts, verdicts = [], []
    for level in sorted(data["level"].unique()):
        m = _means(data[data["level"] == level], "method")
        if "qec" not in m.index or len(m) < 2:
            continue
        others = m.drop("qec")
        verdicts.append(_gap_verdict(m["qec"] - others.max()))
        parts.append(f"level {level}: qec {m['qec']:.2f}, best other {others.idxmax()} {others.max():.2f}")
    if not verdicts:
        return "no data", "needs QEC and another method"
    verdict = ("did not hold" if "did not hold" in verdicts else "tie" if "tie" in verdicts else "held")
    return verdict, "; ".join(parts)


def _simple_weakest(data, regular):
    m = _means(data[data["method"].isin(regular)], "method")
    if "simple" not in m.index or len(m) < 2:
        return "no data", "needs simple and another regular method"
    return _gap_verdict(m.drop("simple").min() - m["simple"]), "mean accuracy over all levels: " + _list(m)


def _trio_equal(data):
    trio = ["gls", "lls", "feature"]
    sub = data[data["method"].isin(trio)]
    if set(sub["method"]) != set(trio):
        return "no data", "needs gls, lls and feature"
    g = sub.groupby(["level", "relocation", "method"])["accuracy"]
    mu = 100 * g.mean().unstack("method")
    sd = (100 * g.std(ddof=1).unstack("method")).dropna(how="any")
    spread = float((mu.max(axis=1) - mu.min(axis=1)).max())
    evidence = f"largest gap between their means in any level x relocation: {spread:.2f} points"
    if not len(sd) or not np.isfinite(spread):
        return "no data", evidence + "; σ needs at least two terrain x point-set samples per cell"
    lowest = float((sd.idxmin(axis=1) == "feature").mean())
    evidence += f"; feature-aware has the lowest σ in {100 * lowest:.0f}% of the level x relocation cells"
    return ("held" if spread <= 1.0 and lowest > 0.5 else "did not hold"), evidence


def _identity_best(data):
    m = _means(data, "relocation")
    sd = 100 * data.groupby("relocation")["accuracy"].std(ddof=1).dropna()
    if "identity" not in m.index or len(m) < 2:
        return "no data", "needs identity and another relocation"
    verdict = _gap_verdict(m["identity"] - m.drop("identity").max())
    evidence = "mean accuracy: " + _list(m)
    if "identity" in sd.index and len(sd) == len(m):
        evidence += "; σ: " + ", ".join(f"{k} {v:.2f}" for k, v in sd.sort_values().items())
        if verdict == "held" and sd.idxmin() != "identity":
            verdict = "did not hold"
            evidence += " (identity is best on average, but its σ is not the lowest)"
    return verdict, evidence


def _half_worst(data):
    deepest = 3 if 3 in set(data["level"]) else None
    if deepest is None:
        return "no data", "needs level 3 (1.5 % of the samples)"
    m = _means(data[data["level"] == deepest], "relocation")
    if "half" not in m.index or len(m) < 2:
        return "no data", "needs half and another relocation at level 3"
    return _gap_verdict(m.drop("half").min() - m["half"]), "level 3 mean accuracy: " + _list(m)


def _regular_marginal(data, regular, irregular):
    # by kind: a semi-regular method (rtin) is neither, so it counts on no side of the paper's claim
    data = data[data["method"].isin(regular) | data["method"].isin(irregular)]
    kinds = data.assign(_k=np.where(data["method"].isin(regular), "regular", "irregular"))
    m = _means(kinds, "_k")
    if len(m) < 2:
        return "no data", "needs regular and irregular methods"
    gap = m["irregular"] - m["regular"]
    per_level = _means(kinds, ["level", "_k"]).unstack("_k")
    evidence = (f"mean accuracy: irregular {m['irregular']:.2f}, regular {m['regular']:.2f} "
                f"(regular {'poorer' if gap >= 0 else 'better'} by {abs(gap):.2f} points; by level: "
                + ", ".join(f"{lv}: {r['irregular'] - r['regular']:+.2f}" for lv, r in per_level.iterrows()) + ")")
    if abs(gap) <= TIE:
        return "tie", evidence
    return ("held" if 0 < gap <= 2.0 else "did not hold"), evidence + "; 'marginally' is taken as at most 2 points"


#: The paper's qualitative findings, as the paper states them.
CLAIMS = (
    "QEC is best at every level",
    "simple reverse Faber is the weakest regular method",
    "GLS, LLS and feature-aware are about equal, and feature-aware has the lowest σ",
    "identity is the best relocation overall, with the lowest σ",
    "half projection is the worst relocation at 1.5%",
    "regular methods are only marginally poorer than irregular ones",
)


def findings(df: pd.DataFrame) -> list[dict]:
    """Check the paper's six qualitative findings against a result, for each predicate in it.

    Returns
    -------
    list of dict
        One per claim (:data:`CLAIMS`) and predicate, with ``claim``, ``predicate``,
        ``verdict`` (one of :data:`VERDICTS`: ``"tie"`` when the decisive difference is
        below :data:`TIE` points, ``"no data"`` when the result cannot tell) and
        ``evidence`` (the numbers behind the verdict).
    """
    from simplifiers import METHODS

    from ..relocation.registry import PAPER_RELOCATIONS as RELOCATIONS

    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"df must be a pandas DataFrame from terrainvis.compare, got {type(df).__name__}")
    rows = df[df["error"].fillna("").astype(str) == ""] if "error" in df.columns else df
    if "max_distance" in rows.columns and rows["max_distance"].nunique(dropna=False) > 1:
        rows = rows[rows["max_distance"].isna()]
    by_budget = budgeted_rows(rows)
    rows = rows[~by_budget]  # the paper's findings are about its levels
    measured = rows[rows["accuracy"].notna()]
    rows = measured[measured["relocation"].isin(RELOCATIONS)]
    reason = ("the paper's findings are about its levels, and these rows are budgeted in maximum vertical error"
              if by_budget.any() and measured.empty else
              "no row has an accuracy" if measured.empty else
              f"needs the paper's relocations ({', '.join(RELOCATIONS)}); this run has "
              f"{', '.join(sorted(set(measured['relocation'])))}")
    predicates = sorted(set(rows["predicate"])) if "predicate" in rows.columns and len(rows) else ["exact"]
    regular = [m for m, info in METHODS.items() if info.kind == "regular"]
    irregular = [m for m, info in METHODS.items() if info.kind == "irregular"]
    out = []
    for pred in predicates:
        data = rows[rows["predicate"] == pred] if "predicate" in rows.columns else rows
        checks = (
            _qec_best(data), _simple_weakest(data, regular), _trio_equal(data), _identity_best(data),
            _half_worst(data), _regular_marginal(data, regular, irregular),
        ) if len(data) else (("no data", reason),) * len(CLAIMS)
        for claim, (verdict, evidence) in zip(CLAIMS, checks):
            out.append({"claim": claim, "predicate": pred, "verdict": verdict, "evidence": evidence})
    return out


def findings_markdown(found: list[dict]) -> list[str]:
    """The findings as markdown lines, one section per predicate."""
    lines = []
    for pred in dict.fromkeys(f["predicate"] for f in found):
        lines += ["", f"### The paper's findings on these terrains (predicate: {pred})", ""]
        lines += [f"- **{f['claim']}**: {f['verdict']}. {f['evidence']}." for f in found if f["predicate"] == pred]
    return lines


# ---------------------------------------------------------------------- the paper side by side
def paper_reference() -> pd.DataFrame:
    """The paper's Tables 1-4 as published, one row per cell (in percent).

    Columns ``table``, ``level``, ``size_percent``, ``method``, ``relocation``,
    ``measure`` (``accuracy``, ``visible_kept``, ``blocked_kept``), ``mu``, ``sigma``.
    Source: Alderson and Samavati, GRAPP 2012, doi:10.5220/0003851501430150.
    """
    from importlib import resources

    with resources.files("terrainvis.data").joinpath("alderson_samavati_2012_tables.csv").open("r") as fh:
        return pd.read_csv(fh)


def _paper_convention(data: pd.DataFrame) -> pd.DataFrame:
    """Accuracy and visible-kept rates over |P x P| (n², self-pairs agree and are visible), as the paper counts."""
    n = data["n_points"].astype(float)
    whole = data["max_distance"].isna() if "max_distance" in data.columns else True
    vis = data["agree_visible"] + data["false_blocked"]
    visible_paper = (2 * data["agree_visible"] + n) / (2 * vis + n)
    return data.assign(
        accuracy=np.where(whole, data["accuracy_paper"], data["accuracy"]),
        visible_kept=np.where(whole, visible_paper, data["visible_kept"]),
    )


def paper_comparison(df: pd.DataFrame, *, predicate: str | None = None) -> pd.DataFrame:
    """Ours beside the paper's, for every cell of its Tables 1-4.

    Our figures are converted to the paper's convention first (accuracy over the n²
    ordered pairs of P x P, where the n self-pairs agree and are visible: ``accuracy_paper``,
    and the same for Table 4's visible rate), so the difference is about the
    experiment, not the counting.

    Returns
    -------
    pandas.DataFrame
        Index (table, level, method, relocation, measure) in the paper's order; columns
        ``ours``, ``paper``, ``difference`` (ours - paper, percentage points) and ``n``
        (our terrain x set samples). ``attrs["rms"]`` holds the RMS difference over the
        accuracy cells of Tables 1-3 (63 when all are present) and over Table 4 (28),
        with the number of cells each.
    """
    data = _ok(df, predicate)
    data = _paper_convention(data[~budgeted_rows(data)])  # the paper's cells are its levels
    ref = paper_reference()
    rows = []
    for r in ref.itertuples():
        sel = data[(data["level"] == r.level) & (data["method"] == r.method) & (data["relocation"] == r.relocation)]
        vals = sel[r.measure].dropna()
        ours = 100 * vals.mean() if len(vals) else np.nan
        rows.append((r.table, r.level, r.method, r.relocation, r.measure, ours, r.mu, ours - r.mu, len(vals)))
    out = pd.DataFrame(rows, columns=["table", "level", "method", "relocation", "measure", "ours", "paper",
                                      "difference", "n"]).set_index(["table", "level", "method", "relocation", "measure"])
    acc = out.loc[[1, 2, 3], "difference"].dropna() if len(out) else pd.Series(dtype=float)
    t4 = out.loc[[4], "difference"].dropna() if len(out) else pd.Series(dtype=float)
    out.attrs["rms"] = {
        "accuracy": (float(np.sqrt((acc**2).mean())) if len(acc) else np.nan, int(acc.size)),
        "table 4": (float(np.sqrt((t4**2).mean())) if len(t4) else np.nan, int(t4.size)),
    }
    out.attrs["title"] = "The paper side by side (the paper's |P x P| convention; difference = ours - paper, points)"
    return out


def comparison_markdown(cmp: pd.DataFrame) -> str:
    """:func:`paper_comparison` as markdown, with the RMS differences under it."""
    shown = cmp[cmp["n"] > 0]
    text = to_markdown({"paper": shown}) if len(shown) else "### The paper side by side\n\nno cell of the paper's tables is in this run\n"
    rms = cmp.attrs.get("rms", {})
    lines = [f"- RMS difference over the {n} {what} cells: {v:.2f} points" for what, (v, n) in rms.items() if n]
    return text + ("\n".join(lines) + "\n" if lines else "")


# ---------------------------------------------------------------------- beyond the paper
def oracle_gap(df: pd.DataFrame, *, predicate: str | None = None) -> pd.DataFrame:
    """How much relocation could recover: the oracle bound against the best practical relocation.

    Returns
    -------
    pandas.DataFrame
        Index (method, level; or method, ``max_error_budget`` in a run budgeted in vertical
        error); columns ``oracle`` (mean accuracy, %, of the ``"oracle"`` relocation: an
        upper bound that needs T's verdicts), ``best``
        (the best practical relocation's name), ``best_accuracy`` and ``gap`` (oracle -
        best, points). Empty when the result has no oracle rows. The oracle's own table
        (:func:`terrainvis.relocation.oracle.gap_table`), as :func:`relocation_tables` gives it.
    """
    from ..relocation.registry import ORACLE, RELOCATIONS

    return _in_method_order(RELOCATIONS[ORACLE].tables(accuracy_by_relocation(df, predicate=predicate))["oracle"])


def accuracy_by_relocation(df: pd.DataFrame, *, predicate: str | None = None) -> pd.DataFrame:
    """The mean accuracy (%) of each relocation (a column each, in the registry's order) per
    method and level (index: method and level, or method and ``max_error_budget``), of the
    rows without an error: what a relocation's own tables are made from
    (:attr:`terrainvis.relocation.Relocation.tables`)."""
    from ..relocation.registry import RELOCATIONS

    data = _ok(df, predicate)
    mu = 100 * data.groupby(["method", step_column(data), "relocation"])["accuracy"].mean().unstack("relocation")
    return mu[[r for r in RELOCATIONS if r in mu.columns] + [r for r in mu.columns if r not in RELOCATIONS]]


def relocation_tables(df: pd.DataFrame, shown: dict | None = None, *, predicate: str | None = None) -> dict:
    """The report tables of the relocations that ran (:attr:`terrainvis.relocation.Relocation.tables`),
    in the registry's order, rows in the methods' order; those of a relocation that a table
    of ``shown`` already reports (its ``attrs["covers"]`` names it) are left out."""
    from ..relocation.registry import RELOCATIONS

    covered = {r for t in (shown or {}).values() for r in t.attrs.get("covers", ())}
    ran = set(df["relocation"].dropna()) if "relocation" in df.columns else set()
    out = {}
    mu = None
    for name, entry in RELOCATIONS.items():
        if entry.tables is None or name not in ran or name in covered:
            continue
        mu = accuracy_by_relocation(df, predicate=predicate) if mu is None else mu
        for key, table in entry.tables(mu).items():
            if not table.empty:
                out[key] = _in_method_order(table)
    return out


def method_notes(df: pd.DataFrame) -> list[str]:
    """The lines the methods that ran add about their rows (:attr:`simplifiers.registry.Method.report_notes`),
    in the methods' order."""
    from simplifiers import METHODS

    ran = set(df["method"].dropna()) if "method" in df.columns else set()
    return [line for name in METHODS if name in ran for line in METHODS[name].notes(df[df["method"] == name])]


def _in_method_order(table: pd.DataFrame) -> pd.DataFrame:
    """``table``'s rows (index: method, step) in the methods' order, then by step."""
    from simplifiers import METHODS

    if table.empty:
        return table
    idx = [(m, lv) for m in _ordered({i[0] for i in table.index}, METHODS) for lv in sorted({i[1] for i in table.index})
           if (m, lv) in table.index]
    out = table.loc[idx]
    out.attrs = dict(table.attrs)
    return out


def beyond_paper(df: pd.DataFrame, *, predicate: str | None = None) -> pd.DataFrame:
    """The relocations beyond the paper's beside the paper's three and the bounds, per method and level.

    Returns
    -------
    pandas.DataFrame
        Index (method, level; or method, ``max_error_budget`` in a run budgeted in vertical
        error); columns: the mean accuracy (%) of every relocation present in registry order (the paper's ``identity``, ``full``, ``half``, then
        ``calibrated`` and any registered relocation, then bounds such as ``oracle``),
        ``best_paper`` (the best of the paper's three) and, with the calibrated
        relocation, ``gain`` (calibrated - best_paper, points) and, with the oracle too,
        ``closed`` (the share of the gap between the best of the paper's relocations and
        the oracle that the calibrated relocation closes, %) and ``to_oracle`` (oracle -
        calibrated, points). Empty when no relocation beyond the paper's ran.
    """
    from simplifiers import METHODS

    from ..relocation.registry import CALIBRATED, ORACLE, PAPER_RELOCATIONS, RELOCATIONS

    data = _ok(df, predicate)
    mu = 100 * data.groupby(["method", step_column(data), "relocation"])["accuracy"].mean().unstack("relocation")
    beyond = [r for r in RELOCATIONS if r not in PAPER_RELOCATIONS and not RELOCATIONS[r].bound and r in mu.columns]
    if not beyond:
        return pd.DataFrame()
    cols = [r for r in RELOCATIONS if r in mu.columns]
    out = mu[cols].copy()
    paper = [r for r in PAPER_RELOCATIONS if r in mu.columns]
    out["best_paper"] = mu[paper].max(axis=1) if paper else np.nan
    if CALIBRATED in mu.columns:
        out["gain"] = out[CALIBRATED] - out["best_paper"]
        if ORACLE in mu.columns:
            out["closed"] = 100 * (out[CALIBRATED] - out["best_paper"]) / (out[ORACLE] - out["best_paper"])
            out["to_oracle"] = out[ORACLE] - out[CALIBRATED]
    idx = [(m, lv) for m in _ordered({i[0] for i in out.index}, METHODS) for lv in sorted({i[1] for i in out.index})
           if (m, lv) in out.index]
    out = out.loc[idx]
    bounds = [r for r in cols if RELOCATIONS[r].bound]
    out.attrs["covers"] = bounds  # each bound's accuracy is here (with the calibrated one's distance to it)
    out.attrs["title"] = (f"Beyond the paper: the {' and '.join(beyond)} relocation{'s' if len(beyond) > 1 else ''} "
                          "beside the paper's relocations"
                          + (f" and the {' and '.join(bounds)} bound" if bounds else "") + " (accuracy %)")
    return out


def beyond_paper_findings(df: pd.DataFrame, *, predicate: str | None = None) -> list[str]:
    """What the calibrated relocation changes in the paper's regular-against-irregular finding, as markdown lines.

    Per level: the best regular method with the calibrated relocation against the best
    irregular method with any of the paper's relocations (and with the calibrated one).
    """
    from simplifiers import METHODS

    from ..relocation.registry import CALIBRATED, PAPER_RELOCATIONS

    t = beyond_paper(df, predicate=predicate)
    if t.empty or CALIBRATED not in t.columns or t["best_paper"].isna().all():
        return []
    lines = ["", "### Beyond the paper: regular against irregular, with the calibrated relocation", ""]
    step = t.index.names[1]  # level, or max_error_budget
    for level in sorted({lv for _, lv in t.index}):
        sub = t.xs(level, level=step)
        regular = [m for m in sub.index if m in METHODS and METHODS[m].kind == "regular"]
        irregular = [m for m in sub.index if m in METHODS and METHODS[m].kind == "irregular"]
        if not regular or not irregular:
            continue
        reg = sub.loc[regular, CALIBRATED]
        irr_paper = sub.loc[irregular, "best_paper"]
        irr_cal = sub.loc[irregular, CALIBRATED]
        r_best, i_best, i_cal = reg.idxmax(), irr_paper.idxmax(), irr_cal.idxmax()
        lines.append(
            f"- **{_step_label(step, level).capitalize()}:** the best regular method with the calibrated relocation, "
            f"{r_best} "
            f"({reg[r_best]:.2f}), against the best irregular method with the paper's relocations "
            f"({', '.join(r for r in PAPER_RELOCATIONS if r in sub.columns)}), {i_best} ({irr_paper[i_best]:.2f}): "
            f"{reg[r_best] - irr_paper[i_best]:+.2f} points; against the best irregular method with the "
            f"calibrated relocation, {i_cal} ({irr_cal[i_cal]:.2f}): {reg[r_best] - irr_cal[i_cal]:+.2f} points."
        )
    return lines


def localized(df: pd.DataFrame, *, predicate: str | None = None) -> pd.DataFrame:
    """Mean accuracy (%) against the pair distance, per level and relocation (a distance sweep).

    Returns
    -------
    pandas.DataFrame
        Index (level, or ``max_error_budget``, and relocation); one column per distance (in the run's
        ``distance_unit``), ``all`` for every pair.
    """
    from ..relocation.registry import RELOCATIONS

    data = df[df["error"].fillna("").astype(str) == ""] if "error" in df.columns else df
    if predicate is not None:
        data = data[data["predicate"] == predicate]
    elif "predicate" in data.columns and data["predicate"].nunique() > 1:
        raise ValueError(f"df holds rows of several predicates {sorted(set(data['predicate']))}; pass predicate=")
    d = data["max_distance"].fillna(np.inf)
    mu = 100 * data.assign(_d=d).groupby([step_column(data), "relocation", "_d"])["accuracy"].mean().unstack("_d")
    mu.columns = ["all" if c == np.inf else _fmt(float(c)) for c in mu.columns]
    idx = [(lv, r) for lv in sorted({i[0] for i in mu.index}) for r in RELOCATIONS if (lv, r) in mu.index]
    mu = mu.loc[idx]
    unit = data["distance_unit"].iloc[0] if "distance_unit" in data.columns and len(data) else "world"
    mu.attrs["title"] = f"Localized tests: mean accuracy (%) of the pairs within each distance ({unit} units)"
    return mu


def viewshed_table(df: pd.DataFrame) -> pd.DataFrame:
    """What simplification does to viewsheds: per method, level (or budget) and relocation.

    Columns ``cells_kept`` (share of cells whose verdict survives), ``visible_kept``,
    ``blocked_kept`` (means over terrains and observers, %), ``area_ratio`` (visible
    area on S(T) / on T, the median: an observer who sees little of T can see many times
    more of S(T), and a few such ratios would dominate a mean), ``min_height_rms`` and
    ``min_height_p95`` (the error of the minimum-visible-height raster on S(T), RMS and
    95th percentile of its absolute value, in z units: means over terrains and
    observers; NaN where no row has them, e.g. rows written before they existed),
    ``siting_share``, ``siting_share_original`` and ``siting_ratio`` (the share of T's
    area that k observers sited on S(T), and k sited on T, see on T, and the ratio of
    the two: means over terrains, in the table as fractions; a unit's rows all carry its
    one siting, so every relocation shows the same values; NaN where no row has them,
    e.g. with ``siting=0``) and ``n`` (rows), for a result of
    ``compare(..., measure="viewshed")``.
    """
    from simplifiers import METHODS

    from ..relocation.registry import RELOCATIONS

    data = _ok(df)
    if "measure" not in data.columns or not (data["measure"] == "viewshed").any():
        raise ValueError("df holds no viewshed rows (run compare with measure='viewshed')")
    data = data[data["measure"] == "viewshed"]
    g = data.groupby(["method", step_column(data), "relocation"])
    t = pd.DataFrame({
        "cells_kept": 100 * g["accuracy"].mean(), "visible_kept": 100 * g["visible_kept"].mean(),
        "blocked_kept": 100 * g["blocked_kept"].mean(), "area_ratio": g["visible_area_ratio"].median(),
        "min_height_rms": g["min_height_rms"].mean(), "min_height_p95": g["min_height_p95"].mean(),
        "siting_share": g["siting_share"].mean(), "siting_share_original": g["siting_share_original"].mean(),
        "siting_ratio": g["siting_ratio"].mean(), "n": g.size(),
    })
    idx = [(m, lv, r) for m in _ordered({i[0] for i in t.index}, METHODS) for lv in sorted({i[1] for i in t.index})
           for r in RELOCATIONS if (m, lv, r) in t.index]
    t = t.loc[idx]
    t.attrs["title"] = ("Viewsheds: cells whose verdict survives, visible and blocked cells kept (%), "
                        "visible-area ratio S(T) / T (median), error of the minimum visible height on S(T) "
                        "(RMS and 95th percentile, z units, means), share of T seen by the observers sited on "
                        "S(T) and on T, and their ratio (means)")
    return t
