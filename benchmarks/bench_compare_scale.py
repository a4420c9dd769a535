"""The whole comparison on full-size terrains: wall time and peak memory of ``terrainvis compare``.

Workloads (issue 10's targets):

* ``1024``: the default ``terrainvis compare`` (all seven methods, levels 1-3, all
  relocations, volume error, 6 sets of 50 points) on a synthetic 1024 x 1024 ``mountains``
  tile at 30 m, the size class of a real 0.7-1 Mpx DEM. Target: <= 3 min wall, peak RSS
  <= 2 GB.
* ``3601``: a synthetic 3601 x 3601 tile (an SRTM 1-arc-second tile), all seven methods,
  levels 1-3, 1 set of 2,000 points, volume error included. Target: <= 30 min wall,
  peak RSS <= 8 GB with 2 workers.
* ``default``: the paper-scale default run on the bundled terrains (target <= 30 s warm).

Each workload runs the real command line in a subprocess under ``/usr/bin/time -v``. The
peak memory is the largest *sum* of the resident sets of the command and its worker
processes, sampled every 0.2 s (``/usr/bin/time`` reports only the largest single
process), and both are printed. The per-method breakdown comes from the run's
``results.csv``.

Usage::

    python benchmarks/bench_compare_scale.py --workloads default 1024 [3601] [--keep DIR]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pandas as pd
import psutil

from terrainvis import save_dem, synthetic_terrain

TARGETS = {"default": (30.0, None), "1024": (180.0, 2.0), "3601": (1800.0, 8.0)}


def _tile(size: int, folder: Path) -> Path:
    path = folder / f"mountains_{size}.npz"
    if not path.exists():
        save_dem(synthetic_terrain("mountains", size=size, seed=0), path)
    return path


def _args(workload: str, folder: Path) -> list[str]:
    if workload == "default":
        return ["compare"]
    if workload == "1024":
        return ["compare", "--terrain", str(_tile(1024, folder))]
    if workload == "3601":
        return ["compare", "--terrain", str(_tile(3601, folder)), "--points", "2000", "--sets", "1"]
    raise ValueError(f"unknown workload {workload!r}")


def _sample_tree(pid: int, peak: list, stop: threading.Event) -> None:
    try:
        root = psutil.Process(pid)
    except psutil.NoSuchProcess:
        return
    while not stop.is_set():
        total = 0
        try:
            for p in [root] + root.children(recursive=True):
                try:
                    total += p.memory_info().rss
                except psutil.NoSuchProcess:
                    pass
        except psutil.NoSuchProcess:
            break
        peak[0] = max(peak[0], total)
        time.sleep(0.2)


def run(workload: str, folder: Path, extra: list[str]) -> dict:
    out = folder / f"out_{workload}"
    cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "terrainvis.cli", *_args(workload, folder), "--out", str(out),
           "--no-plots", *extra]
    peak = [0]
    stop = threading.Event()
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    sampler = threading.Thread(target=_sample_tree, args=(proc.pid, peak, stop), daemon=True)
    sampler.start()
    _, err = proc.communicate()
    stop.set()
    wall = time.perf_counter() - t0
    sampler.join()
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", err)
    single = int(m.group(1)) * 1024 if m else float("nan")
    if proc.returncode != 0:
        print(err[-3000:], file=sys.stderr)
    df = pd.read_csv(out / "results.csv", dtype={"error": str})
    return {"workload": workload, "exit": proc.returncode, "wall_s": wall, "peak_tree_gb": peak[0] / 1e9,
            "peak_single_gb": single / 1e9, "rows": len(df), "failed_units": df[df.error.notna()][["terrain", "method", "level"]].drop_duplicates().shape[0],
            "df": df}


def _breakdown(df: pd.DataFrame) -> pd.DataFrame:
    units = df.drop_duplicates(["terrain", "method", "level"])
    return units.pivot_table(index="method", columns="level", values="simplify_seconds", aggfunc="median")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workloads", nargs="+", default=["default", "1024"], choices=list(TARGETS))
    ap.add_argument("--keep", default=None, help="folder for the tiles and outputs (default: a temporary one)")
    ap.add_argument("extra", nargs=argparse.REMAINDER, help="extra arguments for terrainvis compare (after --)")
    a = ap.parse_args()
    folder = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="bench_compare_scale_"))
    folder.mkdir(parents=True, exist_ok=True)
    extra = [x for x in a.extra if x != "--"]
    print(f"load average before: {psutil.getloadavg()}; outputs in {folder}")
    for w in a.workloads:
        r = run(w, folder, extra)
        wall_t, mem_t = TARGETS[w]
        print(f"\n== {w}: exit {r['exit']}, {r['rows']} rows, {r['failed_units']} failed units")
        print(f"   wall {r['wall_s']:.1f} s (target <= {wall_t:.0f} s); peak RSS, command and workers together "
              f"{r['peak_tree_gb']:.2f} GB, largest single process {r['peak_single_gb']:.2f} GB"
              + (f" (target <= {mem_t:g} GB)" if mem_t else ""))
        print("   simplification seconds (median over terrains) by method and level:")
        print(_breakdown(r["df"]).round(2).to_string())
        ok = r["df"][r["df"].error.isna()]
        per = ok.drop_duplicates(["terrain", "method", "level"])
        print(f"   volume error computed for {per['volume_error'].notna().sum()} of {len(per)} units; "
              f"backends: {sorted(set(ok.get('backend', pd.Series(dtype=str)).dropna()))}")
        print(f"   load average after: {psutil.getloadavg()}")


if __name__ == "__main__":
    main()
