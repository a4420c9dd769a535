"""How the calibrated relocation's neighbours were chosen, by pair distance, on terrains it is not reported on.

Not a timing. The neighbours (``relocate(..., neighbours=True)``, terrainvis.relocation.calibrated)
guard each point's short sight lines; their weight against the partners trades accuracy
among close pairs for accuracy over all pairs. This sweeps the weight on five synthetic
120x120 terrains of the bundled kinds made with seed 11, point sets from seed 1 (a
generator per terrain) and partners from seed 3, and prints, per level and per method,
the accuracy of each variant among the pairs within 5, 10, 20 and 40 cells of T and over
every pair, beside full projection and the partners alone ("none").

    python studies/tune_neighbours.py                      # weights 0.5, 1, 3 and inf
    python studies/tune_neighbours.py --weights 0.25 0.5 --levels 1

A weight is a neighbour's against a partner when there are 512 partners; with K partners
it counts K / 512 times as much (terrainvis.relocation.calibrated.neighbour_weight), so the
neighbours keep their share of the agreement. ``--partners 512`` gives the setting in
which the weight was chosen (before 2,048 partners became the default).

"inf" is the hard rule (a point never agrees with fewer neighbours than at full
projection). The variant with neighbours fixed at their full projection, which
docs/relocation.md also lists, was an earlier version of the code (commit bd7b844).
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np
import pandas as pd

import simplifiers
import terrainvis as tv
from terrainvis.relocation import calibrated as calibration
from terrainvis.core.synthetic import KINDS

BANDS = (5.0, 10.0, 20.0, 40.0, np.inf)
DEFAULT_WEIGHT = calibration.NEIGHBOUR_WEIGHT


def agreement_by_band(v_true, v_test, points, cell) -> dict:
    """{band: (pairs that agree, pairs)} over the pairs within each distance (cells)."""
    d = np.hypot(points[:, None, 0] - points[None, :, 0], points[:, None, 1] - points[None, :, 1]) / cell
    iu = np.triu_indices(points.shape[0], 1)
    same = v_true[iu] == v_test[iu]
    return {b: (int((same & (d[iu] <= b)).sum()), int((d[iu] <= b).sum())) for b in BANDS}


def run(weights, methods, levels, n_sets, terrain_seed, point_seed, partner_seed, n_partners) -> pd.DataFrame:
    rows = []
    for kind in KINDS:
        T = tv.synthetic_terrain(kind, size=120, seed=terrain_seed)
        rng = np.random.default_rng([point_seed, len(kind)])
        sets = [tv.sample_points(T, 50, seed=rng) for _ in range(n_sets)]
        cell = max(abs(T.dx), abs(T.dy))
        for method, level in itertools.product(methods, levels):
            S = simplifiers.simplify(T, method, level)
            for s, P in enumerate(sets):
                v_true = tv.visibility_matrix(T, P)
                variants = {"full": tv.relocate(P, S, "full"),
                            "none": tv.relocate(P, S, "calibrated", original=T, seed=partner_seed, neighbours=False,
                                                n_partners=n_partners)}
                for w in weights:
                    calibration.NEIGHBOUR_WEIGHT = w
                    try:
                        variants[f"{w:g}"] = tv.relocate(P, S, "calibrated", original=T, seed=partner_seed,
                                                         n_partners=n_partners)
                    finally:
                        calibration.NEIGHBOUR_WEIGHT = DEFAULT_WEIGHT
                for name, moved in variants.items():
                    counts = agreement_by_band(v_true, tv.visibility_matrix(S, moved), P, cell)
                    rows += [dict(terrain=kind, method=method, level=level, set=s, variant=name, band=b,
                                  agree=a, pairs=n) for b, (a, n) in counts.items()]
        print(f"{kind} done", flush=True)
    return pd.DataFrame(rows)



def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", type=float, nargs="+", default=[0.5, 1.0, 3.0, np.inf])
    ap.add_argument("--methods", nargs="+", default=["lls", "gls", "qec", "greedy-insertion"])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 3])
    ap.add_argument("--sets", type=int, default=3)
    ap.add_argument("--terrain-seed", type=int, default=11)
    ap.add_argument("--point-seed", type=int, default=1)
    ap.add_argument("--partner-seed", type=int, default=3)
    ap.add_argument("--partners", type=int, default=calibration.N_PARTNERS,
                    help=f"partners of the calibrated relocation (default {calibration.N_PARTNERS})")
    args = ap.parse_args()
    df = run(args.weights, args.methods, args.levels, args.sets, args.terrain_seed, args.point_seed,
             args.partner_seed, args.partners)
    for keys in (["level", "variant"], ["method", "level", "variant"]):
        g = df.groupby(keys + ["band"])[["agree", "pairs"]].sum()
        table = (100 * g["agree"] / g["pairs"]).unstack("band").round(2)
        table.columns = [f"<= {b:g}" if np.isfinite(b) else "all pairs" for b in table.columns]
        print("\naccuracy (%) by pair distance (cells of T)\n")
        print(table.to_string())
    per_method = df[df["variant"] == "full"].groupby(["level", "band"])["pairs"].sum() / len(args.methods)
    print("\npairs per method and level within each distance:", per_method.round().astype(int).to_dict())


if __name__ == "__main__":
    main()
