"""Methods from outside the package: simplifiers.register, plugins, and their results measured by evaluate.

A registered function and an installed plugin run in ``compare`` like a built-in method
(in this process, on two worker processes, on a dask cluster), and for the same points
give the accuracies that ``terrainvis.evaluate`` gives for their output. The plugin is the
example package under ``examples/plugin``, installed here with pip into a folder of its
own and run in a fresh interpreter through ``terrainvis compare``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import simplifiers
from terrainvis import TIN, HeightGrid, compare, evaluate, synthetic_terrain
from terrainvis.errors import SimplificationError

REPO = Path(__file__).resolve().parents[2]

_MODULE = '''
"""Outside methods for the tests: a regular one and an irregular one."""
import numpy as np
from scipy.spatial import Delaunay

from simplifiers import coarse_coords
from terrainvis import TIN, HeightGrid


def corners_mean(grid, level):
    """Regular: the mean of each coarse position's sample and its four neighbours."""
    xs, ys = coarse_coords(grid.xs, level), coarse_coords(grid.ys, level)
    c = np.searchsorted(grid.xs, xs)
    r = np.searchsorted(grid.ys, ys)
    z = grid.z
    rr, cc = np.meshgrid(r, c, indexing="ij")
    up, down = np.clip(rr + 1, 0, z.shape[0] - 1), np.clip(rr - 1, 0, z.shape[0] - 1)
    right, left = np.clip(cc + 1, 0, z.shape[1] - 1), np.clip(cc - 1, 0, z.shape[1] - 1)
    mean = (z[rr, cc] + z[up, cc] + z[down, cc] + z[rr, right] + z[rr, left]) / 5.0
    return HeightGrid.from_coords(mean, xs, ys)


def stride(grid, n_vertices, *, seed=0):
    """Irregular: the corners and random interior samples, triangulated (Delaunay)."""
    rows, cols = grid.shape
    inner = np.arange(rows * cols).reshape(rows, cols)[1:-1, 1:-1].ravel()
    keep = np.sort(np.random.default_rng(seed).choice(inner, size=n_vertices - 4, replace=False))
    idx = np.concatenate([[0, cols - 1, (rows - 1) * cols, rows * cols - 1], keep])
    r, c = np.divmod(idx, cols)
    v = np.column_stack([grid.xs[c], grid.ys[r], grid.z[r, c]])
    f = Delaunay(v[:, :2]).simplices.astype(np.int64)
    a, b, d = v[f[:, 0], :2], v[f[:, 1], :2], v[f[:, 2], :2]
    cw = (b[:, 0] - a[:, 0]) * (d[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (d[:, 0] - a[:, 0]) < 0
    f[cw] = f[cw][:, [0, 2, 1]]
    return TIN(v, f)


def wrong_type(grid, n_vertices):
    return grid.to_tin().vertices


def too_few(grid, n_vertices):
    return stride(grid, max(4, n_vertices // 2))
'''


@pytest.fixture
def outside(tmp_path, monkeypatch):
    """The outside methods' module importable here and in worker processes; registered, then unregistered."""
    (tmp_path / "outside_methods.py").write_text(textwrap.dedent(_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    import outside_methods

    names = []
    names.append(simplifiers.register("corners-mean", outside_methods.corners_mean, kind="regular").name)
    names.append(simplifiers.register("stride", outside_methods.stride, kind="irregular", options=("seed",),
                                      style=("tab:brown", "*")).name)
    yield outside_methods
    for n in names:
        simplifiers.unregister(n)


def _kw(**extra):
    return {**dict(levels=[1, 2], n_points=12, n_sets=2, repeats=1, seed=3, relocations=["full", "half"]), **extra}


_SAME = ["terrain", "set", "method", "level", "relocation", "accuracy", "agree_visible", "agree_blocked",
         "n_vertices"]


def test_registered_functions_are_methods(outside):
    g = synthetic_terrain("hills", size=33, seed=1)
    S = simplifiers.simplify(g, "corners-mean", 2)
    assert S.shape == (9, 9) and S.attrs["method"] == "corners-mean" and S.attrs["kind"] == "regular"
    T = simplifiers.simplify(g, "stride", 2, seed=4)
    assert T.n_vertices == 81 and T.attrs["kind"] == "irregular"
    assert "stride" in simplifiers.available() and simplifiers.METHODS["stride"].kind == "irregular"
    assert "stride" not in simplifiers.default_methods()
    assert simplifiers.METHODS["corners-mean"].description.startswith("Regular: the mean")
    with pytest.raises(TypeError, match=r"stride got unexpected option\(s\) \['weights'\]"):
        simplifiers.simplify(g, "stride", 1, weights=1)


def test_outside_methods_in_compare_give_what_evaluate_gives(outside):
    g = {"g": synthetic_terrain("mountains", size=33, seed=2)}
    df = compare(g, methods=["stride", "corners-mean", "lls"], workers=1, **_kw())
    assert df["error"].isna().all() and set(df["method"]) == {"stride", "corners-mean", "lls"}
    for method in ("stride", "corners-mean"):
        for level in (1, 2):
            out = simplifiers.simplify(g["g"], method, level)
            ev = evaluate(g, out, name=method, **{k: v for k, v in _kw().items() if k != "levels"})
            ours = df[(df["method"] == method) & (df["level"] == level)].reset_index(drop=True)
            pd.testing.assert_frame_equal(ev[_SAME], ours[_SAME])


@pytest.mark.slow
def test_outside_methods_on_two_workers_and_on_dask(outside):
    distributed = pytest.importorskip("distributed")
    g = {"g": synthetic_terrain("mountains", size=33, seed=2)}
    serial = compare(g, methods=["stride", "corners-mean"], workers=1, **_kw())
    pooled = compare(g, methods=["stride", "corners-mean"], workers=2, **_kw())
    pd.testing.assert_frame_equal(serial[_SAME], pooled[_SAME])
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        with distributed.Client(c) as client:
            on_dask = compare(g, methods=["stride", "corners-mean"], client=client, **_kw())
    pd.testing.assert_frame_equal(serial[_SAME], on_dask[_SAME])


def test_a_method_object_is_taken_by_compare(outside):
    from simplifiers import Method

    entry = Method("stride-b", "irregular", "outside_methods", "stride", "the same, named by module")
    g = {"g": synthetic_terrain("hills", size=33, seed=2)}
    try:
        df = compare(g, methods=[entry, "lls"], workers=1, **_kw(levels=[1]))
        assert set(df["method"]) == {"stride-b", "lls"} and df["error"].isna().all()
    finally:
        simplifiers.unregister("stride-b")


def test_bad_outside_methods_are_refused_clearly(outside):
    g = synthetic_terrain("hills", size=33, seed=1)
    with pytest.raises(ValueError, match="method 'lls' is built in and cannot be replaced; register yours under another name"):
        simplifiers.register("lls", outside.corners_mean, kind="regular")
    with pytest.raises(ValueError, match="a method named 'stride' is registered already"):
        simplifiers.register("stride", outside.stride, kind="irregular")
    with pytest.raises(ValueError, match=r"kind must be one of \['regular', 'irregular', 'semi-regular'\]"):
        simplifiers.register("x", outside.stride, kind="tin")
    with pytest.raises(TypeError, match=r"method 'x': its function must take \(grid, n_vertices, seed=...\)"):
        simplifiers.register("x", lambda grid: grid, kind="irregular", options=("seed",))
    with pytest.raises(TypeError, match=r"report_notes must be callable or None, got str 'a note'"):
        simplifiers.register("x", outside.stride, kind="irregular", report_notes="a note")
    assert "x" not in simplifiers.METHODS
    simplifiers.register("wrong-type", outside.wrong_type, kind="irregular")
    simplifiers.register("too-few", outside.too_few, kind="irregular")
    try:
        with pytest.raises(SimplificationError,
                           match=r"wrong-type returned array of shape \(1089, 3\) and dtype float64, not a terrainvis.TIN"):
            simplifiers.simplify(g, "wrong-type", 2)
        with pytest.raises(SimplificationError,
                           match=r"too-few returned an invalid height field: it has 40 vertices for a budget of 81"):
            simplifiers.simplify(g, "too-few", 2)
        df = compare({"g": g}, methods=["too-few"], workers=1, **_kw(levels=[2]))
        assert df["error"].str.contains("invalid height field").all()  # the unit fails, the run goes on
    finally:
        simplifiers.unregister("wrong-type")
        simplifiers.unregister("too-few")


def test_a_function_the_workers_cannot_import_is_refused_before_the_run(outside, tmp_path):
    def local_method(grid, level):
        return outside.corners_mean(grid, level)

    simplifiers.register("local", local_method, kind="regular")
    try:
        with pytest.raises(TypeError, match=r"method 'local': its function \S*local_method cannot be sent to worker "
                                            r"processes.*workers=1"):
            compare({"g": synthetic_terrain("hills", size=33)}, methods=["local"], workers=2,
                    out_csv=tmp_path / "r.csv", **_kw())
        assert not (tmp_path / "r.csv").exists()
    finally:
        simplifiers.unregister("local")


# ---------------------------------------------------------------------- plugins
def _dist_info(root: Path, name: str, entries: dict, module: str | None = None, code: str = "") -> None:
    """An installed distribution as importlib.metadata finds it: a .dist-info folder with its entry points."""
    info = root / f"{name}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    lines = ["[terrainvis.simplifiers]"] + [f"{k} = {v}" for k, v in entries.items()]
    (info / "entry_points.txt").write_text("\n".join(lines) + "\n")
    if module:
        (root / f"{module}.py").write_text(textwrap.dedent(code))


def _fresh(code: str, path: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(path)}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                          timeout=600)


def test_a_broken_plugin_is_reported_once_and_the_others_load(tmp_path):
    good = '''
        from simplifiers import Method
        METHOD = Method("plugged", "regular", "terrainvis_box_average", "box_average", "x", whole_grid=True)
    '''
    _dist_info(tmp_path, "good-plugin", {"plugged": "good_plugin:METHOD"}, "good_plugin", good)
    _dist_info(tmp_path, "raising-plugin", {"raising": "raising_plugin:METHOD"}, "raising_plugin",
               "raise RuntimeError('the plugin is broken')\n")
    _dist_info(tmp_path, "wrong-plugin", {"wrong": "wrong_plugin:METHOD"}, "wrong_plugin", "METHOD = 42\n")
    _dist_info(tmp_path, "shadow-plugin", {"shadow": "shadow_plugin:METHOD"}, "shadow_plugin", '''
        from simplifiers import Method
        METHOD = Method("lls", "regular", "shadow_plugin", "x", "pretends to be lls")
    ''')
    _dist_info(tmp_path, "missing-plugin", {"missing": "no_such_module:METHOD"})
    r = _fresh('''
        import warnings
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            import simplifiers
            simplifiers.load_plugins()  # a second call reports nothing again
        print(sorted(simplifiers.available()))
        for w in caught:
            print("WARNING", w.message)
        print(sorted(simplifiers.registry.PLUGIN_FAILURES))
    ''', tmp_path)
    assert r.returncode == 0, r.stderr
    out = r.stdout.splitlines()
    assert "plugged" in out[0] and "'lls'" in out[0]
    warnings_ = [line for line in out if line.startswith("WARNING")]
    assert len(warnings_) == 4, out
    text = "\n".join(warnings_)
    assert "simplifier plugin 'raising' (raising_plugin:METHOD) was not loaded: RuntimeError: the plugin is broken" in text
    assert "'wrong' (wrong_plugin:METHOD) was not loaded: TypeError: its value 'wrong_plugin:METHOD' is a int" in text
    assert "'shadow' (shadow_plugin:METHOD) was not loaded: ValueError: its method name 'lls' is taken by a built-in" in text
    assert "'missing' (no_such_module:METHOD) was not loaded: ModuleNotFoundError" in text
    assert out[-1] == "['missing', 'raising', 'shadow', 'wrong']"


@pytest.mark.slow
def test_the_example_plugin_installs_and_runs_in_compare(tmp_path):
    """pip installs examples/plugin into a folder of its own; a fresh interpreter finds it by its entry point."""
    target = tmp_path / "site"
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target),
                        str(REPO / "examples" / "plugin")], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert (target / "terrainvis_box_average").is_dir() and list(target.glob("terrainvis_box_average-*.dist-info"))
    env = {**os.environ, "PYTHONPATH": str(target)}
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "terrainvis", "compare", "--terrain", "hills", "--methods", "box-average", "lls",
           "--levels", "1", "2", "--points", "12", "--sets", "2", "--seed", "3", "--relocations", "full", "half",
           "--repeats", "1", "--workers", "2", "--no-plots", "--out", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=900)
    assert r.returncode == 0, r.stderr
    df = pd.read_csv(out / "results.csv")
    assert set(df["method"]) == {"box-average", "lls"} and df["error"].isna().all()
    wrong = subprocess.run([sys.executable, "-m", "terrainvis", "compare", "--methods", "box-avg", "--out",
                            str(tmp_path / "x")], capture_output=True, text=True, env=env, timeout=300)
    assert wrong.returncode == 2 and "'box-average'" in wrong.stderr  # offered among the methods
    # the plugin's output measured by evaluate gives the same rows as compare gave it
    r = subprocess.run([sys.executable, "-c", textwrap.dedent(f'''
        import pandas as pd, simplifiers, terrainvis as tv
        T = tv.bundled_terrain("hills")
        rows = [tv.evaluate({{"hills": T}}, simplifiers.simplify(T, "box-average", lv), name="box-average",
                            n_points=12, n_sets=2, seed=3, relocations=["full", "half"], repeats=1) for lv in (1, 2)]
        pd.concat(rows).to_csv({str(tmp_path / "ev.csv")!r}, index=False)
    ''')], capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr
    ev = pd.read_csv(tmp_path / "ev.csv")
    ours = df[df["method"] == "box-average"].reset_index(drop=True)
    cols = ["set", "level", "relocation", "accuracy", "agree_visible", "agree_blocked"]
    pd.testing.assert_frame_equal(ev.sort_values(["level", "set", "relocation"]).reset_index(drop=True)[cols],
                                  ours.sort_values(["level", "set", "relocation"]).reset_index(drop=True)[cols])


def test_registered_methods_are_unregistered_cleanly(outside):
    assert "stride" in simplifiers.METHODS
    m = simplifiers.unregister("stride")
    assert m.name == "stride" and "stride" not in simplifiers.METHODS
    simplifiers.register("stride", m.function, kind="irregular", options=("seed",))
    with pytest.raises(ValueError, match="method 'qec' is built in and cannot be removed"):
        simplifiers.unregister("qec")
    assert isinstance(simplifiers.simplify(synthetic_terrain("hills", size=17), "stride", 1), TIN)
    assert isinstance(simplifiers.simplify(synthetic_terrain("hills", size=17), "corners-mean", 1), HeightGrid)
    assert np.isfinite(simplifiers.simplify(synthetic_terrain("hills", size=17), "corners-mean", 1).z).all()
