"""Every long kernel stops within about a second of SIGINT or SIGTERM (terrainvis.core.interrupt).

Each test runs the work in a subprocess on a grid large enough to take several seconds,
sends the signal while the kernel runs and checks that the process ends with the right
exception or exit code, promptly and without a crash. Before the mechanism, Ctrl-C in
greedy cuts ended in a segmentation fault or in "SystemError: CPUDispatcher(...)
returned a result with an exception set", and every kernel ran to its end first.

The latency is measured from the signal to the moment the script catches the
exception (the interpreter's exit is not counted), and again to the moment the kernel's
own thread has ended: the caller stops waiting after a grace second, so without the
second check a kernel that never saw its flag (a plain flag read hoisted out of a
``prange`` loop) would go unnoticed. The scripts print ``ready`` just
before the long call; where that call takes only a few seconds, the script first runs it
uninterrupted (twice, keeping the faster) and reports its duration, so that the test can
check the interrupt came well before the call would have ended.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest



_HEAD = """
import sys, threading, time
import numpy as np
import terrainvis as tv
"""

_TAIL = """
def main():
    warm()
    whole = None
    if MEASURE:  # the faster of two runs: a first run can be slower (pages touched, threads started)
        times = []
        for _ in range(2):
            t0 = time.perf_counter()
            work()
            times.append(time.perf_counter() - t0)
        whole = min(times)
    print("ready", whole, flush=True)
    t0 = time.perf_counter()
    try:
        work()
    except KeyboardInterrupt as exc:
        caught, took = time.time(), time.perf_counter() - t0
        # the kernel's own thread (interrupt.call's helper) must end too, not run on behind the caller
        for t in threading.enumerate():
            if t.name == "terrainvis-call":
                t.join(30.0)
        print("caught", type(exc).__name__, caught, took, time.time(), flush=True)
        sys.exit(130)
    print("done", time.perf_counter() - t0, flush=True)

main()
"""

_CASES = {
    # 2048^2 at epsilon 2: about 15 s uninterrupted on the 2-core machine
    "greedy-cuts": ("""
from simplifiers.greedy_cuts import greedy_cuts
def warm():
    greedy_cuts(tv.synthetic_terrain("mountains", size=33), 2.0)
g = tv.synthetic_terrain("mountains", size=2048)
def work():
    greedy_cuts(g, 2.0)
""", False),
    # 2048^2 to a quarter of the samples: about 10 s
    "greedy-insertion": ("""
from simplifiers.greedy_insertion import GreedyInserter
def warm():
    GreedyInserter(tv.synthetic_terrain("mountains", size=33)).run(n_vertices=100)
g = tv.synthetic_terrain("mountains", size=2048)
def work():
    GreedyInserter(g).run(n_vertices=g.size // 4)
""", False),
    # the parallel volume kernel (prange over chunks of faces)
    "volume": ("""
import simplifiers
def warm():
    s = tv.synthetic_terrain("mountains", size=33)
    tv.volume_error(s, simplifiers.simplify(s, "simple", 1))
g = tv.synthetic_terrain("mountains", size=3073)
c = simplifiers.simplify(g, "simple", 1).to_tin()
def work():
    tv.volume_error(g, c)
""", True),
    # the parallel feature-aware solve
    "feature": ("""
from simplifiers.reverse_faber import feature
def warm():
    feature(np.random.default_rng(0).normal(size=(64, 64)), axis=1)
z = np.random.default_rng(0).normal(size=(3072, 8192))
def work():
    feature(z, axis=1)
""", True),
    # a TIN sampled on a grid (vertical errors, rasters from TINs)
    "rasterize": ("""
import simplifiers
def warm():
    tv.synthetic_terrain("mountains", size=33).to_tin().height_on_grid(np.arange(3.0), np.arange(3.0))
g = tv.synthetic_terrain("mountains", size=1025)
tin = g.to_tin()
xs = np.linspace(g.xs[0], g.xs[-1], 6000)
ys = np.linspace(g.ys[0], g.ys[-1], 6000)
def work():
    tin.height_on_grid(xs, ys)
""", True),
    # the calibrated relocation's Gauss-Seidel sweeps over a core of 2048 partners (serial; T's verdicts cached first)
    "calibrated-sweeps": ("""
import simplifiers
from terrainvis.relocation import calibrated as calibration
def warm():
    s = tv.synthetic_terrain("mountains", size=65)
    calibration.partners(s, simplifiers.simplify(s, "lls", 1), height=0.0, move=True, n_partners=16, sweeps=1)
g = tv.synthetic_terrain("mountains", size=1025)
S = simplifiers.simplify(g, "lls", 1)
calibration.partners(g, S, height=0.0, move=True, n_partners=2048, core=2048, sweeps=0)  # T's verdicts, cached
def work():
    calibration.partners(g, S, height=0.0, move=True, n_partners=2048, core=2048, sweeps=3)
""", False),
    # the calibrated relocation's best heights of many points (on threads, over points)
    "calibrated-points": ("""
import simplifiers
from terrainvis.visibility import thresholds, _threshold_kernels as ck
from terrainvis.core.interrupt import call
def setup(size, n):
    g = tv.synthetic_terrain("mountains", size=size)
    S = simplifiers.simplify(g, "lls", 1)
    surf = thresholds.ThresholdSurface(S)
    q = surf.local(tv.sample_points(S, 512, seed=1))
    p = surf.local(tv.sample_points(S, n, seed=2))
    vis = np.random.default_rng(0).random((n, 512)) < 0.3
    out, score = np.empty(n), np.empty(n, dtype=np.int64)
    lthr, lvis = np.full((n, 48), -np.inf), np.ones((n, 48), dtype=np.int8)  # neighbours seen at any height
    near = ck.Neighbours(lthr, lvis, 0.5)
    return (surf.data, p, q, vis, near, surf.rules(), out, score), n * 512
def warm():
    args, work_ = setup(65, 4)
    call(ck.grid_heights, *args, work=work_, items=4)
ARGS, WORK = setup(1025, 40000)
def work():
    call(ck.grid_heights, *ARGS, work=WORK, items=40000)
""", False),
    # one coordinate-descent sweep of visopt (serial over the coarse heights): 120^2 at level 1,
    # 1200 training points, about 30 s uninterrupted
    "visopt": ("""
from simplifiers import visopt as vo, _visopt_kernels as vk
from terrainvis.core.interrupt import call
def warm():
    vo.visopt(tv.synthetic_terrain("hills", size=33), 1, n_train=20)
g = tv.synthetic_terrain("hills", size=120)
S0 = vo.start_grid(g, 1)
W = tv.sample_points(g, 1200, seed=0)
p = np.column_stack([W[:, 0] - S0.xs[0], W[:, 1] - S0.ys[0], S0.height_at(W[:, :2])])
pairs = vo._Pairs(S0, p, 1200, vo.MAX_BREAKPOINTS, np.random.default_rng(0))
vt = np.ascontiguousarray(tv.visibility_matrix(g, W)[pairs.ii, pairs.jj])
ev = np.empty((1200, 3), dtype=np.int64)
ew = np.empty((1200, 3))
vk.barycentric(pairs.xs, pairs.ys, p[:, 0].copy(), p[:, 1].copy(), ev, ew)
c0 = S0.z.ravel().copy()
d = np.zeros(1200)
rad = np.full(S0.size, 50.0)
order = np.arange(S0.size, dtype=np.int64)
def work():
    call(vk.c_sweep, c0.copy(), c0, rad, vk.Riders(d, ev, ew), vt, pairs.tracks, 1e-6, 1e-6, order,
         work=pairs.n_breakpoints)
""", False),
}


# the viewshed sweep (parallel over sectors) on a grazing worst case: a noisy tilted
# plane seen from a corner, every ray skimming the ground (well over 5 s uninterrupted)
_CASES["viewshed"] = ("""
from terrainvis import HeightGrid
def warm():
    s = tv.synthetic_terrain("mountains", size=33)
    tv.viewshed(s, (s.xs[3], s.ys[5]))
n = 3072
y, x = np.mgrid[0:n, 0:n] * 30.0
g = HeightGrid(100.0 + 0.05 * x + 0.02 * y + np.random.default_rng(0).normal(0.0, 0.5, (n, n)), dx=30.0, dy=30.0)
del x, y
def work():
    tv.viewshed(g, (g.xs[0], g.ys[0]), observer_height=2.0)
""", False)
# the viewshed's min_height output (the threshold engine, parallel over chunks of targets)
# on the same grazing worst case, smaller
_CASES["viewshed-min-height"] = ("""
from terrainvis import HeightGrid
def warm():
    s = tv.synthetic_terrain("mountains", size=33)
    tv.viewshed(s, (s.xs[3], s.ys[5]), output="min_height")
n = 2048
y, x = np.mgrid[0:n, 0:n] * 30.0
g = HeightGrid(100.0 + 0.05 * x + 0.02 * y + np.random.default_rng(0).normal(0.0, 0.5, (n, n)), dx=30.0, dy=30.0)
del x, y
def work():
    tv.viewshed(g, (g.xs[0], g.ys[0]), observer_height=2.0, output="min_height")
""", False)
# the parallel visibility matrix of the grid engine: 8,000 points, 32 million pairs
_CASES["visibility-matrix"] = ("""
def warm():
    s = tv.synthetic_terrain("mountains", size=33)
    tv.visibility_matrix(s, np.column_stack([s.xs[:4], s.ys[:4], s.z[0, :4] + 1.0]))
g = tv.synthetic_terrain("mountains", size=1025)
rng = np.random.default_rng(0)
xy = np.column_stack([rng.uniform(0, g.xs[-1], 8000), rng.uniform(0, g.ys[-1], 8000)])
pts = np.column_stack([xy, g.height_at(xy) + 2.0])
def work():
    tv.visibility_matrix(g, pts)
""", False)

# the parallel pair walks of min_clearance (and line_of_sight) on the grid engine: the
# exact least clearance of 6 million segments across a 1025² grid (no early exits)
_CASES["min-clearance"] = ("""
def warm():
    s = tv.synthetic_terrain("mountains", size=33)
    p = np.column_stack([s.xs[:4], s.ys[:4], s.z[0, :4] + 1.0])
    tv.min_clearance(s, p, p[::-1])
g = tv.synthetic_terrain("mountains", size=1025)
rng = np.random.default_rng(0)
def ends(k):
    xy = np.column_stack([rng.uniform(0, g.xs[-1], k), rng.uniform(0, g.ys[-1], k)])
    return np.column_stack([xy, g.height_at(xy) + 2.0])
a, b = ends(6_000_000), ends(6_000_000)
def work():
    tv.min_clearance(g, a, b)
""", True)

# the same on a TIN (the exact clipping of each segment against every face it crosses):
# 40,000 segments across the 524,288 faces of a 513² grid's triangulation
_CASES["tin-min-clearance"] = ("""
def warm():
    s = tv.synthetic_terrain("mountains", size=33).to_tin()
    p = np.array([[10.0, 10.0, 2000.0], [900.0, 500.0, 2000.0]])
    tv.min_clearance(s, p, p[::-1])
g = tv.synthetic_terrain("mountains", size=513)
tin = g.to_tin()
rng = np.random.default_rng(0)
def ends(k):
    xy = np.column_stack([rng.uniform(0, g.xs[-1], k), rng.uniform(0, g.ys[-1], k)])
    return np.column_stack([xy, g.height_at(xy) + 2.0])
a, b = ends(40_000), ends(40_000)
def work():
    tv.min_clearance(tin, a, b)
""", True)


def _script(tmp_path, name: str) -> tuple[str, bool]:
    body, measure = _CASES[name]
    path = tmp_path / f"{name}.py"
    path.write_text(_HEAD + f"MEASURE = {measure}\n" + textwrap.dedent(body) + _TAIL)
    return str(path), measure


def _run_and_signal(cmd, sig, *, after: float | None = None, env=None, ready="ready"):
    """Start ``cmd``, wait for its ``ready`` line, send ``sig`` and return (process, stdout rest, stderr, sent)."""
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    line = p.stdout.readline()
    if not line.startswith(ready):
        p.kill()
        out, err = p.communicate()
        pytest.fail(f"the script did not get ready: {line!r} {out!r} {err[-2000:]}")
    whole = line.split()[1] if len(line.split()) > 1 else "None"
    whole = None if whole == "None" else float(whole)
    time.sleep(after if after is not None else 0.3 * whole)
    sent = time.time()
    p.send_signal(sig)
    try:
        out, err = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        p.kill()
        out, err = p.communicate()
        pytest.fail(f"no exit within 60 s of the signal: {out!r} {err[-2000:]}")
    return p, out, err, sent, whole


@pytest.mark.slow
@pytest.mark.parametrize("name", list(_CASES))
def test_sigint_stops_the_kernel_promptly(tmp_path, name):
    script, measure = _script(tmp_path, name)
    p, out, err, sent, whole = _run_and_signal([sys.executable, script], signal.SIGINT, after=None if measure else 2.0)
    assert p.returncode == 130, (p.returncode, out, err[-2000:])
    assert "done" not in out, out
    caught = out.split()
    assert caught[0] == "caught" and caught[1] == "KeyboardInterrupt", out
    latency = float(caught[2]) - sent
    assert latency < 2.0, f"{name}: the interrupt took {latency:.2f} s"
    kernel = float(caught[4]) - sent
    assert kernel < 2.0, f"{name}: the kernel's thread ran on {kernel:.2f} s after the signal"
    if measure:
        # the call was stopped well before it would have ended on its own
        assert float(caught[3]) < 0.8 * whole, (float(caught[3]), whole)
    assert "SystemError" not in err and "Segmentation" not in err, err[-2000:]


def _big_dem(tmp_path, size: int = 2048) -> str:
    """A DEM file of ``size``^2 samples; the CLI's greedy cuts are compiled (cached) on a small one first."""
    from terrainvis import synthetic_terrain

    small = tmp_path / "small.npy"
    np.save(small, synthetic_terrain("mountains", size=33).z)
    subprocess.run([sys.executable, "-m", "terrainvis.cli",
                   "simplify", str(small), "-m", "greedy-cuts", "-l", "1", "-o", str(tmp_path / "small_out.npz")],
                   check=True, capture_output=True)
    path = tmp_path / "big.npy"
    np.save(path, synthetic_terrain("mountains", size=size).z)
    return str(path)


def _cli(*args) -> list[str]:
    """The terrainvis command line, printing ``ready`` before it starts (imports and all)."""
    return [sys.executable, "-c", "import sys; print('ready', flush=True); from terrainvis.cli import main; "
            "sys.exit(main(sys.argv[1:]))", *args]


@pytest.mark.slow
@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_cli_simplify_stops_on_a_signal(tmp_path, sig, code):
    """``terrainvis simplify`` in greedy cuts: exit 130 on SIGINT, 143 on SIGTERM, one line, no traceback."""
    dem = _big_dem(tmp_path)
    # greedy cuts at level 1 on 2048^2: tens of seconds; the CLI compiles first when the cache is cold
    cmd = _cli("simplify", dem, "-m", "greedy-cuts", "-l", "1", "-o", str(tmp_path / "out.npz"))
    t0 = time.perf_counter()
    p, out, err, sent, _ = _run_and_signal(cmd, sig, after=8.0)
    assert p.returncode == code, (p.returncode, out, err[-2000:])
    assert time.time() - sent < 3.0
    assert "Traceback" not in err and "interrupted" in err, err
    assert time.perf_counter() - t0 < 40.0


@pytest.mark.slow
def test_compare_with_one_worker_does_not_swallow_the_interrupt(tmp_path):
    """``compare --workers 1`` runs the units here: an interrupt in greedy cuts is the user's stop, not a failed unit."""
    dem = _big_dem(tmp_path, 1536)
    out_dir = tmp_path / "out"
    cmd = _cli("compare", "--terrain", dem, "--methods", "greedy-cuts", "--levels", "1", "--points", "5", "--sets", "1",
               "--no-plots", "--no-volume", "--workers", "1", "--out", str(out_dir))
    p, out, err, sent, _ = _run_and_signal(cmd, signal.SIGINT, after=10.0)
    assert p.returncode == 130, (p.returncode, _failures(out_dir), err[-2000:])
    assert time.time() - sent < 3.0
    assert "Traceback" not in err and "SystemError" not in err, err


def _failures(out_dir) -> list[str]:
    """The errors compare recorded for failed units (for the message of a failed assertion)."""
    import pandas as pd

    path = out_dir / "results.csv"
    if not path.exists():
        return []
    table = pd.read_csv(path)
    return sorted(set(table["error"].dropna())) if "error" in table else []


_IMPORT_SCRIPT = """
import os, signal, sys, threading, time
from terrainvis.core.interrupt import import_library
threading.Timer(0.05, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
try:
    import_library("pymeshlab")
    time.sleep(0.5)
except KeyboardInterrupt:
    print("KeyboardInterrupt", "pymeshlab" in sys.modules)
    sys.exit(130)
"""


def test_ctrl_c_while_a_library_is_imported_is_an_interrupt(tmp_path):
    """Ctrl-C during ``import pymeshlab`` made it fail with "ImportError: initialization failed"."""
    script = tmp_path / "imp.py"
    script.write_text(_IMPORT_SCRIPT)
    p = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert p.returncode == 130, (p.stdout, p.stderr[-2000:])
    assert p.stdout.split() == ["KeyboardInterrupt", "True"]


def test_every_kernel_reads_its_flag_with_stopped():
    """A plain ``stop[0]`` read can be hoisted out of a ``prange`` loop (terrainvis.core.stopflag)."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    plain = re.compile(r"\bstop\[0\]\s*(!=|==|>|<)")
    readers = 0
    for path in sorted([*root.joinpath("terrainvis").rglob("*.py"), *root.joinpath("simplifiers").rglob("*.py")]):
        text = path.read_text(encoding="utf-8")
        code = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith(("#", "...", ">>>")))
        assert not plain.search(code) or path.name in ("stopflag.py", "interrupt.py"), \
            f"{path.relative_to(root)} reads its stop flag as stop[0]: use terrainvis.core.stopflag.stopped"
        readers += "stopped(stop)" in text
    assert readers >= 10  # the kernel modules (the check above would pass on none)
