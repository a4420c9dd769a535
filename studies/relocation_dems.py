"""The calibrated relocation on the shared real DEMs (issue 18, "Beyond the bundled terrains").

Not a timing: the accuracy measurement behind docs/relocation.md. Two workloads on the
four DEMs of ``../shared/data/dem``, each a ``terrainvis.compare`` run with every method at
levels 1-3 and the paper's relocations beside the calibrated one, with a localized sweep
(``max_distance`` 5, 10, 20, 40 cells and every pair):

* ``crops``: a 120 x 120 window from the middle of each DEM's valid part (West Bijou is
  67 samples high: 67 x 120), at the paper's settings (points on the surface, 6 sets of
  50 points);
* ``whole``: each whole DEM (Mount St Helens cut to its largest window without nodata),
  observers 1.7 m above the ground (``offset``), 6 sets of 50 points.

With ``--no-neighbours`` the calibrated relocation counts its partners alone
(``relocate(..., neighbours=False)``; results in ``OUT/<workload>-no-neighbours/``).

It prints, per workload, method and level, the accuracy of full projection and of the
calibrated relocation on every pair and within each distance, and whether calibrated
kept at least as many verdicts as full everywhere. Results go to ``OUT/<workload>/``
(``results.csv``; a rerun resumes).

    python studies/relocation_dems.py --out relocation-dems
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

import terrainvis as tv

DEMS = ("green_mountains_vt", "jacksboro_fault_tn", "mount_st_helens_wa", "west_bijou_escarpment_co")
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "dem"


def _valid(name: str, size: int | None = None) -> tv.HeightGrid:
    """A DEM's largest NaN-free window, or ``size`` x ``size`` (at most) from its middle."""
    grid = tv.load_dem(SHARED / f"{name}.npz")
    return grid.crop(*grid.valid_window(size=size))


def run(workload: str, out: Path, workers: int, neighbours: bool = True) -> pd.DataFrame:
    grids = {name: _valid(name, 120 if workload == "crops" else None) for name in DEMS}
    offset = 0.0 if workload == "crops" else 1.7
    folder = out / (workload + ("" if neighbours else "-no-neighbours"))
    folder.mkdir(parents=True, exist_ok=True)
    csv = folder / "results.csv"
    return tv.compare(grids, relocations=["identity", "full", "half", "calibrated"], offset=offset,
                      max_distance=[5, 10, 20, 40, None], distance_unit="cells", neighbours=neighbours,
                      workers=workers, out_csv=csv, resume=csv.exists(), progress=True)


def summary(df: pd.DataFrame, workload: str) -> None:
    ok = df[df["error"].fillna("") == ""]
    d = ok["max_distance"].fillna(np.inf)
    mu = 100 * ok.assign(_d=d).groupby(["method", "level", "relocation", "_d"])["accuracy"].mean()
    table = mu.unstack("relocation")
    print(f"\n### {workload}: accuracy (%), full against calibrated, by pair distance (cells of T)\n")
    print("| method | level | distance | full | calibrated | calibrated - full |")
    print("|---|---|---|---|---|---|")
    worse = []
    for (method, level, dist), row in table.iterrows():
        gain = row["calibrated"] - row["full"]
        if gain < 0:
            worse.append((method, level, dist, gain))
        label = "all" if dist == np.inf else f"{dist:g}"
        print(f"| {method} | {level} | {label} | {row['full']:.2f} | {row['calibrated']:.2f} | {gain:+.2f} |")
    allpairs = table.xs(np.inf, level="_d")
    print(f"\nevery pair: calibrated - full from {(allpairs['calibrated'] - allpairs['full']).min():+.2f} to "
          f"{(allpairs['calibrated'] - allpairs['full']).max():+.2f} points over {len(allpairs)} method x level cells")
    print("cells where calibrated keeps fewer verdicts than full:", worse if worse else "none")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("relocation-dems"))
    ap.add_argument("--workloads", nargs="+", default=["crops", "whole"], choices=["crops", "whole"])
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--no-neighbours", dest="neighbours", action="store_false",
                    help="the calibrated relocation without neighbours (relocate's neighbours=False)")
    args = ap.parse_args()
    if not SHARED.exists():
        raise SystemExit(f"the shared DEMs are not at {SHARED}")
    for workload in args.workloads:
        label = workload + ("" if args.neighbours else " (no neighbours)")
        summary(run(workload, args.out, args.workers, args.neighbours), label)


if __name__ == "__main__":
    main()
