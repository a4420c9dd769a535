"""Every method, built-in and peer, at levels 1-3: LOS accuracy, vertices reached, errors and seconds.

The table of docs/peers.md (issue 27, part 3). :func:`terrainvis.compare` over the five
bundled 120x120 terrains and the 120x120 crops of the four shared DEMs
(``../shared/data/dem``; the middle of each DEM's NaN-free window, as
``tests/conftest.py``'s ``shared_dem_120``), every registered method (the built-in ones
and the peers of :mod:`simplifiers.peers`), levels 1-3,
with the full projection and the calibrated relocation. Per method and level it reports:

* ``failed``: terrains on which the method raised (out of all; the reason is in the CSV);
* ``full``, ``calibrated``: mean accuracy (%) over terrains x point sets, on the terrains
  where the method succeeded;
* ``vertices/budget``: the mean ratio of the vertex count reached to the level's budget,
  and the largest deviation (%);
* ``max err``, ``RMS err``: the mean over terrains of the max and RMS vertical error (z units);
* ``seconds``: the mean simplification time per terrain (the search included).

The defaults (``--points 50 --sets 2 --partners 256``) keep a run under about 15
minutes on 2 shared cores: everything but ``visopt`` takes about 3 minutes, ``visopt``
alone about 25-35 s per terrain and level on one free core (27 units: 7-8 minutes on
two free cores). ``visopt`` runs as a second comparison into its own file (so that each
resumes on its own); ``--no-visopt`` leaves it out. The results go to ``--out`` (``results.csv``
and ``visopt.csv``, resumable with ``--resume``, and ``peers_table.md``); the table is
printed too, followed by a table of VTK's stated error against the error it reaches.

Run: ``.venv/bin/python studies/peers_table.py [--out DIR] [--workers 2] [--no-visopt]``.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHARED_DEM = REPO.parent / "shared" / "data" / "dem"
BUNDLED = ("hills", "mesas", "rough", "mountains", "ridges")
DEMS = ("jacksboro_fault_tn", "mount_st_helens_wa", "green_mountains_vt", "west_bijou_escarpment_co")
LIBRARIES = ("pymartini", "pydelatin", "pyfqmr", "meshoptimizer", "vtk", "pymeshlab")


def dem_crop(name: str, side: int = 120):
    """The side x side crop from the middle of a shared DEM's NaN-free window (None when the DEM is absent)."""
    from terrainvis import load_dem

    path = SHARED_DEM / f"{name}.npz"
    if not path.exists():
        return None
    grid = load_dem(path)
    rs, cs = grid.valid_window()
    grid = grid.crop(rs, cs)
    rows, cols = grid.shape
    n_r, n_c = min(side, rows), min(side, cols)
    r0, c0 = (rows - n_r) // 2, (cols - n_c) // 2
    return grid.crop(rows=(r0, r0 + n_r), cols=(c0, c0 + n_c))


def terrains() -> dict:
    from terrainvis import synthetic_terrain

    out = {name: synthetic_terrain(name) for name in BUNDLED}
    for name in DEMS:
        grid = dem_crop(name)
        if grid is None:
            print(f"note: {SHARED_DEM / name}.npz is absent; the table goes without it", file=sys.stderr)
        else:
            out[name] = grid
    return out


def table(df, grids: dict) -> str:
    """The markdown table of a compare result (one block per level)."""
    import simplifiers
    from simplifiers.levels import vertex_budget

    df = df.copy()
    df["error"] = df["error"].fillna("").astype(str)
    df["accuracy"] = 100.0 * df["accuracy"]
    order = list(simplifiers.available())
    lines = []
    for level in sorted(df["level"].unique()):
        lines += [f"**Level {level}**", "",
                  "| method | kind | failed | full (%) | calibrated (%) | vertices/budget (max dev.) | max err | "
                  "RMS err | seconds |",
                  "|---|---|---|---|---|---|---|---|---|"]
        sub = df[df["level"] == level]
        for method in [m for m in order if m in set(sub["method"])]:
            rows = sub[sub["method"] == method]
            units = rows.drop_duplicates("terrain")
            ok = units[units["error"] == ""]
            n_fail = len(units) - len(ok)
            good = rows[rows["error"] == ""]
            acc = good.groupby("relocation")["accuracy"].mean()
            budgets = np.array([vertex_budget(grids[t].shape, int(level)) for t in ok["terrain"]], dtype=float)
            if len(ok):
                ratio = ok["n_vertices"].to_numpy(dtype=float) / budgets
                reach = f"{ratio.mean():.3f} ({100 * np.abs(ratio - 1).max():.1f} %)"
                errs = f"{ok['max_error'].mean():.2f} | {ok['rms_error'].mean():.2f} | {ok['simplify_seconds'].mean():.3f}"
            else:
                reach, errs = "-", "- | - | -"
            full = f"{acc['full']:.2f}" if "full" in acc else "-"
            cal = f"{acc['calibrated']:.2f}" if "calibrated" in acc else "-"
            kind = simplifiers.METHODS[method].kind
            lines.append(f"| {method} | {kind} | {n_fail}/{len(units)} | {full} | {cal} | {reach} | {errs} |")
        lines.append("")
    lines += paired(df)
    failures = df[df["error"] != ""].drop_duplicates(["terrain", "method", "level"])
    if len(failures):
        lines += ["**Failures** (terrain and level, and the message's first clause)", ""]
        for method, rows in failures.groupby("method", sort=False):
            said = {}
            for r in rows.itertuples():
                clauses = r.error.removeprefix("SimplificationError: ").split("; ")
                short = clauses[0][:240]
                if "gave a valid height field" in short and len(clauses) > 1:  # then the reason is the next clause
                    short += ": " + clauses[1].split(": ", 1)[-1][:160]
                said.setdefault(short, []).append(f"{r.terrain} L{r.level}")
            lines += [f"- {method}, {', '.join(where)}: {short}" for short, where in said.items()]
        lines.append("")
    return "\n".join(lines)


#: The methods every peer is set beside, paired on the same terrains and point sets.
REFERENCES = ("qec", "greedy-insertion", "gls", "lls")


def paired(df) -> list[str]:
    """Markdown lines: each peer against :data:`REFERENCES`, paired on the terrains and point sets
    where both succeeded: the mean difference of accuracy (points) and its standard error,
    with the full projection and with the calibrated relocation."""
    from simplifiers.peers import PEERS

    ok = df[df["error"] == ""]
    wide = ok.pivot_table(index=["level", "relocation", "terrain", "set"], columns="method", values="accuracy")
    refs = [r for r in REFERENCES if r in wide.columns]
    rows = []
    for level in sorted(set(wide.index.get_level_values("level"))):
        for peer in [m for m in PEERS if m in wide.columns]:
            cells, n_pairs = [], 0
            own = []
            for rel in ("full", "calibrated"):
                try:
                    sub = wide.xs((level, rel), level=("level", "relocation"))
                except KeyError:
                    sub = None
                own.append("-" if sub is None or sub[peer].isna().all() else f"{sub[peer].mean():.2f}")
            for ref in refs:
                parts = []
                for rel in ("full", "calibrated"):
                    try:
                        sub = wide.xs((level, rel), level=("level", "relocation"))
                    except KeyError:
                        parts.append("-")
                        continue
                    d = (sub[peer] - sub[ref]).dropna()
                    n_pairs = max(n_pairs, len(d))
                    parts.append("-" if len(d) < 2 else f"{d.mean():+.2f} ± {d.std(ddof=1) / np.sqrt(len(d)):.2f}")
                cells.append(" / ".join(parts))
            if n_pairs:
                rows.append(f"| {level} | {peer} | {n_pairs} | {' / '.join(own)} | " + " | ".join(cells) + " |")
    if not rows:
        return []
    return ["**Each peer against the built-in methods, paired** on the terrains and point sets where both "
            "succeeded: the peer's mean accuracy (%), then its mean difference to each method (points) ± the "
            "standard error of that difference; full projection / calibrated relocation", "",
            "| level | peer | pairs | the peer | " + " | ".join(f"- {r}" for r in refs) + " |",
            "|---|---|---|---|" + "---|" * len(refs), *rows, ""]


def vtk_stated_error(grids: dict, targets=(2.0, 10.0)) -> str:
    """VTK's greedy decimation run to an ``AbsoluteError`` target: the max error it reaches, overall and
    three samples in from the border, with ``BoundaryVertexDeletion`` on (VTK's default, the adapter's)
    and off. A markdown table."""
    from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkFiltersHybrid import vtkGreedyTerrainDecimation

    from terrainvis import TIN

    lines = ["| terrain | AbsoluteError | deletion | vertices | max error | max error 3+ samples in |",
             "|---|---|---|---|---|---|"]
    for name, grid in grids.items():
        rows, cols = grid.shape
        image = vtkImageData()
        image.SetDimensions(cols, rows, 1)
        image.GetPointData().SetScalars(numpy_to_vtk(np.ascontiguousarray(grid.z, dtype=np.float64).ravel(), deep=True))
        for target in targets:
            for deletion in (1, 0):
                f = vtkGreedyTerrainDecimation()
                f.SetInputData(image)
                f.SetBoundaryVertexDeletion(deletion)
                f.SetErrorMeasureToAbsoluteError()
                f.SetAbsoluteError(target)
                f.Update()
                out = f.GetOutput()
                pts = vtk_to_numpy(out.GetPoints().GetData())
                conn = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).reshape(-1, 3)
                used, faces = np.unique(conn, return_inverse=True)
                c, r = np.rint(pts[used, 0]).astype(int), np.rint(pts[used, 1]).astype(int)
                tin = TIN(np.column_stack([grid.xs[c], grid.ys[r], grid.z[r, c]]), faces.reshape(-1, 3))
                err = np.abs(tin.height_on_grid(grid.xs, grid.ys) - grid.z)
                lines.append(f"| {name} | {target:g} | {'on' if deletion else 'off'} | {used.size} | "
                             f"{err.max():.2f} | {err[3:-3, 3:-3].max():.2f} |")
    return "\n".join(lines)


def versions() -> str:
    from importlib.metadata import PackageNotFoundError, version

    out = []
    for lib in LIBRARIES:
        try:
            out.append(f"{lib} {version(lib)}")
        except PackageNotFoundError:
            out.append(f"{lib} (absent)")
    return ", ".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="peers_table_out", help="folder for results.csv and peers_table.md")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--points", type=int, default=50, help="points per set")
    p.add_argument("--sets", type=int, default=2, help="point sets per terrain")
    p.add_argument("--partners", type=int, default=256, help="partners of the calibrated relocation")
    p.add_argument("--methods", nargs="+", default=None, help="default: every registered method")
    p.add_argument("--resume", action="store_true", help="keep the units already in --out/results.csv")
    p.add_argument("--no-visopt", dest="visopt", action="store_false",
                   help="leave visopt out (about 25-35 s per terrain and level on one core; --out/visopt.csv)")
    p.add_argument("--vtk-only", action="store_true", help="only the table of VTK's stated against reached error")
    given = list(sys.argv[1:] if argv is None else argv)
    args = p.parse_args(given)

    import pandas as pd

    import terrainvis
    import simplifiers

    grids = terrains()
    if args.vtk_only:
        print(vtk_stated_error(grids))
        return 0
    methods = args.methods or [m for m in simplifiers.available() if m != "visopt"]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    t0 = time.perf_counter()
    common = dict(levels=[1, 2, 3], relocations=["full", "calibrated"], n_points=args.points, n_sets=args.sets,
                  n_partners=args.partners, workers=args.workers, resume=args.resume)
    df = terrainvis.compare(grids, methods=methods, out_csv=out / "results.csv", **common)
    if args.visopt and args.methods is None:  # its own file: a resume checks the method list, and visopt is most of the time
        extra = terrainvis.compare(grids, methods=["visopt"], out_csv=out / "visopt.csv", **common)
        df = pd.concat([df, extra], ignore_index=True)
    wall = time.perf_counter() - t0
    load_after = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    head = [
        "Command: `" + " ".join([".venv/bin/python studies/peers_table.py", *given]) + "`",
        f"Run: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, {wall:.0f} s wall on "
        f"{os.cpu_count()} cores ({platform.processor() or platform.machine()}), workers={args.workers}; "
        f"uptime before: `{load}`; after: `{load_after}`",
        f"Settings: {len(grids)} terrains ({', '.join(grids)}), levels 1-3, {args.sets} sets of {args.points} "
        f"points, calibrated relocation with {args.partners} partners; {versions()}",
        "",
    ]
    text = "\n".join(head) + "\n" + table(df, grids) + "\n**VTK's stated error against the error it reaches**\n\n" + \
        vtk_stated_error(grids) + "\n"
    (out / "peers_table.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
