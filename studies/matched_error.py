"""Line-of-sight verdicts kept at matched vertical error: every method simplified to a maximum vertical error E.

Production tilers are set by one knob, a maximum vertical (geometric) error per zoom
level, not by a vertex count (issue 39). This study asks the paper's question at that
knob: on each terrain, every one of the paper's seven methods is simplified to the
smallest result whose maximum vertical error is at most E
(:func:`simplifiers.simplify` with ``max_error=E``: a regular method at its coarsest level
within E, greedy insertion and greedy cuts stopping at E, QEC by a search on the vertex
count), and the results are measured together by :func:`terrainvis.evaluate` on the
comparison's point sets (the terrain's name and the seed), under the full projection and
the calibrated relocation. Per budget and method it reports the vertices kept (% of the
samples), the measured maximum error and the mean accuracy over terrains and point sets;
then, per budget, the paper's regular-against-irregular finding checked again: the best
regular method against the best irregular one.

The terrains are the comparison's defaults (the five bundled 120² terrains and the
Jacksboro window), with ``--shared`` also the 120² crops of the four shared DEMs
(``../shared/data/dem``; ``studies/peers_table.py``'s crops, as ``tests/conftest.py``'s
``shared_dem_120``).

Run: ``.venv/bin/python studies/matched_error.py [--errors 10 20 40 80] [--shared] [--out DIR]``
(about 6 minutes on 2 shared cores for the defaults; the rows go to ``DIR/matched_error.csv``
and the tables to ``DIR/matched_error.md``, and are printed).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time
from pathlib import Path

import pandas as pd

import simplifiers
import terrainvis as tv
from terrainvis.experiment import resolve_terrains
from terrainvis.experiment.plan import DEFAULT_TERRAINS

PAPER_METHODS = ("qec", "greedy-cuts", "greedy-insertion", "simple", "gls", "lls", "feature")
RELOCATIONS = ("full", "calibrated")


def terrains(shared: bool) -> dict:
    grids = resolve_terrains(list(DEFAULT_TERRAINS))
    if shared:
        from peers_table import DEMS, dem_crop  # the crops of docs/peers.md's table

        for name in DEMS:
            crop = dem_crop(name)
            if crop is None:
                raise SystemExit(f"--shared: the shared DEM {name!r} is absent (../shared/data/dem beside the clone)")
            grids[name] = crop
    return grids


def measure(grids: dict, errors, n_points: int, n_sets: int, seed: int) -> pd.DataFrame:
    """One evaluate() per terrain and budget, every method's simplification at that budget measured together."""
    frames = []
    for name, T in grids.items():
        for E in errors:
            t0 = time.perf_counter()
            simplified = {m: simplifiers.simplify(T, m, max_error=E) for m in PAPER_METHODS}
            t_simplify = time.perf_counter() - t0
            df = tv.evaluate({name: T}, simplified, relocations=list(RELOCATIONS), n_points=n_points, n_sets=n_sets,
                             seed=seed, repeats=1)
            df["max_error_budget"] = float(E)
            frames.append(df)
            sizes = ", ".join(f"{m} {s.size if isinstance(s, tv.HeightGrid) else s.n_vertices}"
                              for m, s in simplified.items())
            print(f"{name}: max error {E:g}: vertices {sizes}; {t_simplify:.1f} s simplifying, "
                  f"{time.perf_counter() - t0 - t_simplify:.1f} s measuring",
                  file=sys.stderr, flush=True)
    return pd.concat(frames, ignore_index=True)


def tables(df: pd.DataFrame) -> str:
    ok = df[df["error"].isna()]
    failed = df[df["error"].notna()].drop_duplicates(["terrain", "method", "max_error_budget"])
    per_unit = ok.groupby(["max_error_budget", "method", "terrain"]).agg(
        kind=("kind", "first"), vertices=("size_fraction", "first"), max_error=("max_error", "first"))
    acc = 100 * ok.groupby(["max_error_budget", "method", "relocation"])["accuracy"].mean().unstack("relocation")
    t = pd.DataFrame({
        "kind": per_unit.groupby(level=[0, 1])["kind"].first(),
        "vertices %": 100 * per_unit.groupby(level=[0, 1])["vertices"].mean(),
        "max error (mean)": per_unit.groupby(level=[0, 1])["max_error"].mean(),
        "max error (largest)": per_unit.groupby(level=[0, 1])["max_error"].max(),
    })
    t = t.join(acc[list(RELOCATIONS)])
    order = {m: i for i, m in enumerate(PAPER_METHODS)}
    t = t.sort_index(key=lambda idx: idx.map(order) if idx.name == "method" else idx)
    lines = ["| max error E | method | kind | vertices (% of samples) | max error: mean | largest | "
             + " | ".join(f"accuracy, {r} (%)" for r in RELOCATIONS) + " |",
             "|---|---|---|---|---|---|" + "---|" * len(RELOCATIONS)]
    for (E, m), r in t.iterrows():
        lines.append(f"| {E:g} | {m} | {r['kind']} | {r['vertices %']:.2f} | {r['max error (mean)']:.2f} | "
                     f"{r['max error (largest)']:.2f} | " + " | ".join(f"{r[x]:.2f}" for x in RELOCATIONS) + " |")
    lines += ["", "The paper's finding at matched error: the best regular method against the best irregular one "
                  "(mean accuracy %, and their vertices):", "",
              "| max error E | relocation | best regular | best irregular | regular - irregular (points) | "
              "vertices: regular / irregular |", "|---|---|---|---|---|---|"]
    for E, sub in t.groupby(level=0):
        sub = sub.droplevel(0)
        for rel in RELOCATIONS:
            reg, irr = sub[sub["kind"] == "regular"], sub[sub["kind"] != "regular"]
            if reg.empty or irr.empty:
                continue
            br, bi = reg[rel].idxmax(), irr[rel].idxmax()
            lines.append(f"| {E:g} | {rel} | {br} {reg.loc[br, rel]:.2f} | {bi} {irr.loc[bi, rel]:.2f} | "
                         f"{reg.loc[br, rel] - irr.loc[bi, rel]:+.2f} | "
                         f"{reg.loc[br, 'vertices %']:.2f} % / {irr.loc[bi, 'vertices %']:.2f} % |")
    if len(failed):
        lines += ["", "Failed: " + "; ".join(f"{r.terrain} / {r.method} / E {r.max_error_budget:g}: {r.error}"
                                            for r in failed.itertuples())]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--errors", type=float, nargs="+", default=[10.0, 20.0, 40.0, 80.0],
                    help="the budgets: maximum vertical errors, in the terrains' z units (default 10 20 40 80)")
    ap.add_argument("--shared", action="store_true", help="also the 120² crops of the four shared DEMs")
    ap.add_argument("--points", type=int, default=50)
    ap.add_argument("--sets", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="matched-error", help="folder for matched_error.csv and matched_error.md")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    df = measure(terrains(args.shared), args.errors, args.points, args.sets, args.seed)
    seconds = time.perf_counter() - t0
    df.to_csv(out / "matched_error.csv", index=False)
    head = (f"Run: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, {seconds:.0f} s on "
            f"{os.cpu_count()} cores ({platform.machine()}), load {load:.2f} before and {os.getloadavg()[0]:.2f} "
            f"after; {len(set(df['terrain']))} terrains, {args.sets} sets of {args.points} points, seed {args.seed}; "
            f"`.venv/bin/python studies/matched_error.py {' '.join(sys.argv[1:])}`.\n\n")
    text = head + tables(df)
    (out / "matched_error.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
