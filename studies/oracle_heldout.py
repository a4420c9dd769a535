"""How much of the oracle bound's lead over the calibrated relocation is fitting the pairs it is scored on.

Not a timing. The oracle (``relocate(..., "oracle")``) moves each point to agree with
the verdicts of the very pairs it is then scored on; the calibrated relocation sees no
evaluated pair. To tell what the oracle learns about a point from what it fits to a
pair, this splits each point set's pairs at random into two halves A and B (symmetric,
seeded), fits the oracle on A only, and scores every relocation on B only:

* ``full``, ``calibrated``: the practical relocations (they never see A or B);
* ``oracle fitted on A``: the held-out oracle: it peeks at half of each point's pairs,
  and is scored on the other half;
* ``oracle fitted on A+B``: the oracle as ``compare`` runs it, scored on B (in sample).

Both oracles start from the calibrated heights, as in ``compare``. The work is the
default experiment's (6 terrains, the 7 default methods, 6 sets of 50 points, the same
point sets) at the given levels:

    python studies/oracle_heldout.py                 # level 3
    python studies/oracle_heldout.py --levels 1 2 3 --split-seed 2
"""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd

import simplifiers
import terrainvis as tv
from terrainvis.experiment.plan import DEFAULT_TERRAINS, resolve_terrains
from terrainvis.experiment.measures import point_sets


def halves(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Two complementary symmetric (n, n) masks of the distinct pairs, about half each."""
    upper = np.triu(rng.random((n, n)) < 0.5, 1)
    a = upper | upper.T
    b = ~a
    np.fill_diagonal(b, False)
    return a, b


def score(v_true, grid_s, placed, mask) -> float:
    return tv.agreement(v_true, tv.visibility_matrix(grid_s, placed), mask)["accuracy"]


def run(levels, split_seed: int) -> pd.DataFrame:
    methods = simplifiers.default_methods()
    rows = []
    for name, T in resolve_terrains(list(DEFAULT_TERRAINS)).items():
        sets = point_sets(T, name, 50, 6, 0, 0.0)
        rng = np.random.default_rng([split_seed, len(name)])
        splits = [halves(P.shape[0], rng) for P in sets]
        truths = [tv.visibility_matrix(T, P) for P in sets]
        for method in methods:
            for level in levels:
                S = simplifiers.simplify(T, method, level)
                for P, v_true, (a, b) in zip(sets, truths, splits):
                    full = tv.relocate(P, S, "full")
                    cal = tv.relocate(P, S, "calibrated", original=T)
                    start = cal[:, 2]
                    held = tv.relocate(P, S, "oracle", reference=v_true, original=T, mask=a, start=start)
                    whole = tv.relocate(P, S, "oracle", reference=v_true, original=T, start=start)
                    rows.append({"terrain": name, "method": method, "level": level,
                                 "full": score(v_true, S, full, b), "calibrated": score(v_true, S, cal, b),
                                 "oracle fitted on A": score(v_true, S, held, b),
                                 "oracle fitted on A+B": score(v_true, S, whole, b)})
        print(f"{name} done", flush=True)
    return pd.DataFrame(rows)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[3])
    ap.add_argument("--split-seed", type=int, default=1, help="seed of the random halves of the pairs")
    args = ap.parse_args()
    df = run(args.levels, args.split_seed)
    cols = ["full", "calibrated", "oracle fitted on A", "oracle fitted on A+B"]
    table = 100 * df.groupby(["method", "level"], sort=False)[cols].mean()
    table["held-out - calibrated"] = table["oracle fitted on A"] - table["calibrated"]
    table["in sample - calibrated"] = table["oracle fitted on A+B"] - table["calibrated"]
    print("\naccuracy (%) on the pairs of half B, mean over 6 terrains x 6 sets of 50 points\n")
    print(table.round(2).to_string())
    pooled = 100 * df.groupby("level")[cols].mean()
    print("\nall methods\n")
    print(pooled.round(2).to_string())


if __name__ == "__main__":
    main()
