"""Paired comparison of visopt against GLS and LLS from `terrainvis compare` results (issue 18, item 3).

Reads one or more results.csv written by

    terrainvis compare --methods gls lls visopt --relocations full calibrated --no-plots --no-volume --out DIR

and prints, per level and relocation, each method's mean accuracy (%) over the (terrain, set)
cells, then visopt minus each peer over the same cells: mean difference, its standard error,
wins / ties / losses, the Wilcoxon signed-rank p (zero differences dropped) and the mean per terrain.

    python studies/visopt_paired.py DIR/results.csv [DIR2/results.csv ...]
"""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd
from scipy.stats import wilcoxon


def main(paths):
    df = pd.concat([pd.read_csv(p) for p in paths], ignore_index=True)
    df = df[df["error"].isna()] if "error" in df else df
    df["acc"] = 100.0 * df["accuracy"]
    table = df.pivot_table(index=["level", "relocation"], columns="method", values="acc", aggfunc="mean")
    print("mean accuracy (%) over the (terrain, set) cells")
    print(table.round(3).to_string())
    print()
    for (level, rel), g in df.groupby(["level", "relocation"]):
        wide = g.pivot_table(index=["terrain", "set"], columns="method", values="acc")
        if "visopt" not in wide:
            continue
        for peer in [m for m in ("gls", "lls") if m in wide]:
            d = (wide["visopt"] - wide[peer]).dropna()
            nz = d[d != 0]
            p = wilcoxon(nz).pvalue if nz.size else 1.0
            per = d.groupby(level=0).mean().round(2).to_dict()
            print(f"level {level} {rel:>10s} visopt - {peer}: mean {d.mean():+.3f} (se {d.std(ddof=1) / np.sqrt(d.size):.3f}) "
                  f"wins {int((d > 0).sum())} ties {int((d == 0).sum())} losses {int((d < 0).sum())} of {d.size}, "
                  f"Wilcoxon p = {p:.3g}; per terrain {per}")
    cols = [c for c in ("simplify_seconds", "max_error", "rms_error") if c in df]
    print()
    print(df.groupby(["level", "method"])[cols].median().round(3).to_string())


if __name__ == "__main__":
    main(sys.argv[1:])
