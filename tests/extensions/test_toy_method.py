"""Adding a method touches the registry and the method's own module only.

A toy irregular method, a Delaunay triangulation of the four corners and randomly chosen
interior samples, is written as a module of its own (in a temporary folder) and given
one registry entry. Nothing else is edited, and every layer picks it up: ``simplify``
with its checks and errors, the block-wise guard, ``compare`` (serial and on the pool),
the report's tables, findings and notes (a line of its own, declared beside it), the
figures and the command line.
"""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

import simplifiers
from simplifiers import METHODS, Method
from terrainvis import bundled_terrain, compare, save_dem, synthetic_terrain
from terrainvis.experiment import plot
from terrainvis.experiment import report
from terrainvis.cli import main
from terrainvis.errors import SimplificationError

_MODULE = '''
"""A baseline irregular method: Delaunay over the corners and random interior samples."""
import numpy as np
from scipy.spatial import Delaunay
from terrainvis import TIN


def build(grid, n_vertices, seed=0):
    rows, cols = grid.shape
    inner = np.arange(rows * cols).reshape(rows, cols)[1:-1, 1:-1].ravel()
    rng = np.random.default_rng(seed)
    keep = np.sort(rng.choice(inner, size=n_vertices - 4, replace=False))
    corners = np.array([0, cols - 1, (rows - 1) * cols, rows * cols - 1])
    idx = np.concatenate([corners, keep])
    r, c = np.divmod(idx, cols)
    v = np.column_stack([grid.xs[c], grid.ys[r], grid.z[r, c]])
    f = Delaunay(v[:, :2]).simplices.astype(np.int32)
    a, b, d = v[f[:, 0], :2], v[f[:, 1], :2], v[f[:, 2], :2]
    cw = (b[:, 0] - a[:, 0]) * (d[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (d[:, 0] - a[:, 0]) < 0
    f[cw] = f[cw][:, [0, 2, 1]]
    return TIN(v, f)


def report_notes(rows):
    """The comparison report's line about the toy's rows."""
    return ["", f"Note: the toy triangulated {len(rows)} rows' terrains at random."]
'''


@pytest.fixture
def toy(tmp_path, monkeypatch):
    """The toy method's module on sys.path and its one registry entry; both undone afterwards."""
    (tmp_path / "toy_delaunay.py").write_text(textwrap.dedent(_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    entry = Method("toy", "irregular", "toy_delaunay", "build", "Delaunay of random samples (a test's toy)",
                   options=("seed",), cost_rank=4, style=("tab:brown", "*"), report_notes="report_notes")
    monkeypatch.setitem(METHODS, "toy", entry)
    return entry


def test_simplify_runs_it_with_the_registry_checks(toy):
    grid = synthetic_terrain("hills", size=33, seed=1)
    tin = simplifiers.simplify(grid, "toy", 2, seed=3)
    assert tin.n_vertices == simplifiers.vertex_budget(grid.shape, 2) == 81
    assert tin.attrs["method"] == "toy" and tin.attrs["kind"] == "irregular" and tin.attrs["budget"] == 81
    # its errors are the core's, on the vertices it kept (all grid samples): zero there
    tz = tin.vertices[:, 2]
    assert np.all(tz == grid.z[np.searchsorted(grid.ys, tin.vertices[:, 1]), np.searchsorted(grid.xs, tin.vertices[:, 0])])
    assert tin.attrs["max_error"] > 0 and tin.attrs["rms_error"] <= tin.attrs["max_error"]
    assert "toy" in simplifiers.available()
    with pytest.raises(TypeError, match=r"toy got unexpected option\(s\) \['weights'\]; it accepts \['seed'\]"):
        simplifiers.simplify(grid, "toy", 1, weights=1)
    with pytest.raises(ValueError, match="cannot run block-wise|block-wise"):
        simplifiers.blockwise.simplify_dask(grid.z, "toy", 1)


def test_a_broken_result_is_refused_by_the_registry(toy, monkeypatch):
    import toy_delaunay

    good = toy_delaunay.build

    def flipped(grid, n_vertices, seed=0):
        tin = good(grid, n_vertices, seed)
        return type(tin)(tin.vertices, tin.faces[:, [0, 2, 1]])

    monkeypatch.setattr(toy_delaunay, "build", flipped)
    with pytest.raises(SimplificationError, match=r"toy returned an invalid height field: every face \(\d+\) is wound "
                                                  "clockwise"):
        simplifiers.simplify(synthetic_terrain("hills", size=33), "toy", 1)


def test_compare_report_and_figures_pick_it_up(toy):
    # workers=1: spawned workers would import the registry afresh, without a test's entry
    df = compare(["hills"], methods=["toy", "lls", "qec"], levels=[1, 2], n_points=12, n_sets=2, workers=1)
    assert set(df["method"]) == {"toy", "lls", "qec"} and df["error"].isna().all()
    assert set(df.loc[df["method"] == "toy", "kind"]) == {"irregular"}
    tables = report.paper_tables(df)
    t1 = tables["Table 1"]
    assert "toy" in set(t1.index.get_level_values(0))
    # the paper's order first, then the new method where the registry puts it (last)
    assert list(dict.fromkeys(t1.index.get_level_values(0))) == ["qec", "lls", "toy"]
    # the kind comes from the registry: the toy counts among the irregular methods
    marginal = [f for f in report.findings(df) if f["claim"] == report.CLAIMS[-1]][0]
    paper = df["relocation"].isin(["identity", "full", "half"])  # the paper's findings are about its relocations
    irregular = 100 * df.loc[df["method"].isin(["qec", "toy"]) & paper, "accuracy"].mean()
    assert f"irregular {irregular:.2f}" in marginal["evidence"], marginal["evidence"]
    fig = plot.accuracy_vs_size(df)
    labels = [t.get_text() for ax in fig.axes for leg in [ax.get_legend()] if leg for t in leg.get_texts()]
    assert "toy" in labels
    bars = [c for ax in fig.axes for c in ax.containers if c.get_label() == "toy"][0]
    assert bars.lines[0].get_marker() == "*"
    # its line in the report, from its entry; QEC ran on pymeshlab here, so it has none
    n = int((df["method"] == "toy").sum())
    assert report.method_notes(df) == ["", f"Note: the toy triangulated {n} rows' terrains at random."]
    big = df[df["method"] == "qec"].assign(backend="fast-simplification", terrain="big")
    assert report.method_notes(big) == ["", "Note: QEC ran on fast-simplification for big (more than 1,200,000 "
                                            "samples, where pymeshlab takes minutes per level); pymeshlab, the "
                                            "paper's QEC, ran elsewhere."]


def test_the_command_line_offers_it(toy, tmp_path, capsys):
    dem = tmp_path / "dem.npz"
    save_dem(bundled_terrain("hills").crop(rows=(0, 33), cols=(0, 33)), dem)
    assert main(["simplify", str(dem), "-m", "toy", "-l", "1", "-o", str(tmp_path / "toy.ply")]) == 0
    assert "289 vertices" in capsys.readouterr().out.replace(",", "")
    assert main(["info", str(dem)]) == 0
    assert "toy" in capsys.readouterr().out
    # a comparison's report on the command line carries its line too
    out = tmp_path / "run"
    assert main(["compare", "--terrain", str(dem), "--methods", "toy", "--levels", "1", "--points", "8", "--sets", "1",
                 "--repeats", "1", "--workers", "1", "--relocations", "full", "--no-plots", "--out", str(out)]) == 0
    assert "Note: the toy triangulated 1 rows' terrains at random." in (out / "tables.md").read_text()
