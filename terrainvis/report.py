"""The paper's tables from a :func:`terrainvis.compare` result, and a check of its findings.

Tables 1-3 of Alderson and Samavati give the mean (μ) and standard deviation (σ) of the
accuracy for each method and relocation at 25 %, 6 % and 1.5 % of the samples (levels 1,
2 and 3 on 120x120 maps), with σ taken over terrains x point sets. Table 4 gives the
rate of visible and of blocked pairs that stay so, for the identity and half
relocations at the deepest level. The cost table adds what the paper did not measure:
the line-of-sight speedup and the memory ratio of S(T) against T.

Rows follow the registry's order: the regular methods (simple, GLS, LLS, feature-aware)
then the irregular ones (QEC, greedy insertion, greedy cuts), and the relocations in the
order identity, full, half. Accuracies are in percent. σ is the sample standard
deviation (ddof = 1).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["paper_tables", "to_markdown", "findings"]

_LEVEL_FRACTION = {1: "25%", 2: "6%", 3: "1.5%"}


def _ok(df: pd.DataFrame) -> pd.DataFrame:
    if "error" in df.columns:
        df = df[df["error"].fillna("").astype(str) == ""]
    return df


def _ordered(index_values, order):
    rank = {v: i for i, v in enumerate(order)}
    return sorted(index_values, key=lambda v: rank.get(v, len(rank)))


def paper_tables(df: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """Tables 1-3, Table 4 and the cost table.

    Parameters
    ----------
    df : pandas.DataFrame
        The result of :func:`terrainvis.compare` (rows with an ``error`` are left out).

    Returns
    -------
    dict of str to DataFrame
        ``"Table 1"``, ``"Table 2"``, ``"Table 3"`` (one per level present, shallowest
        first): index (method, relocation), columns ``mu`` and ``sigma`` of accuracy
        (%) and ``n`` (terrain x set samples). ``"Table 4"``: index method, columns
        (relocation, ``visible_kept`` / ``blocked_kept``) in % at the deepest level, for
        identity and half. ``"Cost"``: index (method, level), columns ``size`` (% of
        the original samples), ``memory_ratio`` (bytes of S(T) / bytes of T),
        ``los_speedup`` (LOS time on T / on S(T)), ``simplify_s``, ``max_error``,
        ``rms_error`` and ``volume_error`` (medians over terrains).
    """
    from simplifiers import METHODS

    from .relocation import RELOCATIONS

    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"df must be a pandas DataFrame from terrainvis.compare, got {type(df).__name__}")
    missing = {"method", "level", "relocation", "accuracy"} - set(df.columns)
    if missing:
        raise ValueError(f"df must have the columns of terrainvis.compare, missing {sorted(missing)}")
    data = _ok(df)
    tables: dict[str, pd.DataFrame] = {}
    levels = sorted(int(v) for v in data["level"].unique())
    for k, level in enumerate(levels, start=1):
        sub = data[data["level"] == level]
        g = sub.groupby(["method", "relocation"])["accuracy"]
        t = pd.DataFrame({"mu": 100 * g.mean(), "sigma": 100 * g.std(ddof=1), "n": g.size()})
        idx = [
            (m, r)
            for m in _ordered(sub["method"].unique(), METHODS)
            for r in _ordered(sub["relocation"].unique(), RELOCATIONS)
            if (m, r) in t.index
        ]
        t = t.loc[idx]
        t.attrs["title"] = f"Table {k}: accuracy (%) at level {level} ({_LEVEL_FRACTION.get(level, f'level {level}')})"
        tables[f"Table {k}"] = t
    if levels:
        deepest = levels[-1]
        sub = data[(data["level"] == deepest) & data["relocation"].isin(["identity", "half"])]
        if len(sub):
            g = sub.groupby(["method", "relocation"])[["visible_kept", "blocked_kept"]].mean() * 100
            t4 = g.unstack("relocation")
            t4 = t4.swaplevel(0, 1, axis=1)
            cols = [(r, c) for r in ("identity", "half") for c in ("visible_kept", "blocked_kept") if (r, c) in t4.columns]
            t4 = t4[cols].loc[_ordered(t4.index, METHODS)]
            t4.attrs["title"] = f"Table 4: visible and blocked pairs kept (%) at level {deepest}"
            tables["Table 4"] = t4
    per_unit = data.drop_duplicates(["terrain", "method", "level", "set", "relocation"])
    per_unit = per_unit.assign(
        speedup=per_unit["los_seconds_original"] / per_unit["los_seconds"],
        memory_ratio=per_unit["nbytes"] / per_unit["nbytes_original"],
    )
    g = per_unit.groupby(["method", "level"])
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
    idx = [(m, lv) for m in _ordered({i[0] for i in cost.index}, METHODS) for lv in levels if (m, lv) in cost.index]
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


def findings(df: pd.DataFrame) -> list[dict]:
    """Check the paper's five qualitative findings against a result.

    Returns
    -------
    list of dict
        Each with ``claim``, ``held`` (bool, or None when the data cannot tell) and
        ``evidence`` (the numbers behind the verdict).
    """
    data = _ok(df)
    out = []
    acc = data.groupby(["level", "method"])["accuracy"].mean()

    def add(claim, held, evidence):
        out.append({"claim": claim, "held": held, "evidence": evidence})

    if 1 in data["level"].values:
        at1 = acc.loc[1].sort_values(ascending=False)
        add(
            "QEC is best at 25%",
            bool(at1.index[0] == "qec") if "qec" in at1.index else None,
            "level 1 mean accuracy: " + ", ".join(f"{m} {100 * v:.2f}" for m, v in at1.items()),
        )
    from simplifiers import METHODS

    regular = [m for m, info in METHODS.items() if info.regular and m in data["method"].values]
    if len(regular) >= 2 and "simple" in regular:
        by = data[data["method"].isin(regular)].groupby("method")["accuracy"].mean().sort_values()
        add(
            "simple reverse Faber is the weakest regular method",
            bool(by.index[0] == "simple"),
            "mean accuracy over all levels: " + ", ".join(f"{m} {100 * v:.2f}" for m, v in by.items()),
        )
    trio = [m for m in ("gls", "lls", "feature") if m in data["method"].values]
    if len(trio) == 3:
        g = data[data["method"].isin(trio)].groupby(["level", "relocation", "method"])["accuracy"]
        mu = g.mean().unstack("method")
        sd = g.std(ddof=1).unstack("method")
        spread = 100 * (mu.max(axis=1) - mu.min(axis=1)).max()
        sd = sd.dropna(how="any")  # σ needs at least two terrain x set samples per cell
        if len(sd):
            lowest = float((sd.idxmin(axis=1) == "feature").mean())
            add(
                "GLS, LLS and feature-aware are about equal, and feature-aware has the lowest σ",
                bool(spread <= 1.0 and lowest > 0.5),
                f"largest gap between their mean accuracies in any level x relocation: {spread:.2f} points; "
                f"feature-aware has the lowest σ in {100 * lowest:.0f}% of level x relocation cells",
            )
        else:
            add(
                "GLS, LLS and feature-aware are about equal, and feature-aware has the lowest σ",
                None,
                f"largest gap between their mean accuracies: {spread:.2f} points; σ needs at least two "
                "terrain x point-set samples per cell",
            )
    rel = data.groupby("relocation")["accuracy"].mean().sort_values(ascending=False)
    if len(rel) >= 2:
        add(
            "identity is the best relocation overall",
            bool(rel.index[0] == "identity") if "identity" in rel.index else None,
            "mean accuracy: " + ", ".join(f"{r} {100 * v:.2f}" for r, v in rel.items()),
        )
    if 3 in data["level"].values and {"half", "identity", "full"} <= set(data["relocation"]):
        r3 = data[data["level"] == 3].groupby("relocation")["accuracy"].mean()
        r1 = data[data["level"] == 1].groupby("relocation")["accuracy"].mean() if 1 in data["level"].values else None
        worst = r3.idxmin()
        drop = "" if r1 is None else "; drop from level 1: " + ", ".join(f"{r} {100 * (r1[r] - r3[r]):.2f}" for r in r3.index)
        add(
            "half projection degrades at 1.5%",
            bool(worst == "half" or (r1 is not None and (r1 - r3).idxmax() == "half")),
            "level 3 mean accuracy: " + ", ".join(f"{r} {100 * v:.2f}" for r, v in r3.items()) + drop,
        )
    return out
