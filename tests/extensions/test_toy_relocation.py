"""Adding a relocation touches the registry and the relocation's own module only.

A toy relocation, full projection raised by a ``lift`` option, is written as a module of
its own (in a temporary folder) and given one :func:`terrainvis.relocation.register`
call. Nothing else is edited, and every layer picks it up: ``relocate`` with its option
checks, ``compare`` in this process and on two worker processes (which import terrainvis
afresh and get the entry sent with each unit), the report's tables, the figures (in its
declared style) and the command line.
"""

from __future__ import annotations

import re
import textwrap

import numpy as np
import pandas as pd
import pytest

from terrainvis import HeightGrid, compare, relocate, synthetic_terrain
from terrainvis.cli import main
from terrainvis.experiment import plot, report
from terrainvis.relocation import RELOCATIONS, Relocation, available, default_relocations, register, unregister

_MODULE = '''
"""A toy relocation: full projection, raised by ``lift``."""
from terrainvis import relocate


def lifted(points, simplified, *, offset=0.0, lift=1.0):
    out = relocate(points, simplified, "full", offset=offset)
    out[:, 2] += lift
    return out
'''


@pytest.fixture
def toy(tmp_path, monkeypatch):
    """The toy's module on sys.path (and on the workers' PYTHONPATH) and its one registration, undone afterwards."""
    (tmp_path / "toy_lift.py").write_text(textwrap.dedent(_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    import toy_lift

    entry = register(Relocation("toy", toy_lift.lifted, "full projection, lifted", options=("lift",),
                                color="tab:olive", marker="P"))
    yield entry
    unregister("toy")


def _small(**kw):
    return {**dict(methods=["lls"], levels=[1], n_points=8, n_sets=1, repeats=1), **kw}


def test_relocate_runs_it_with_its_options(toy):
    S = HeightGrid(np.full((3, 3), 10.0))
    P = np.array([[0.5, 0.5, 4.0], [1.5, 1.0, 30.0]])
    assert relocate(P, S, "toy", offset=2.0, lift=0.5)[:, 2].tolist() == [12.5, 12.5]
    assert relocate(P, S, "toy")[:, 2].tolist() == [11.0, 11.0]
    # an option of another relocation is ignored (one set of options serves a loop); an unknown one is refused
    assert relocate(P, S, "toy", n_partners=5)[:, 2].tolist() == [11.0, 11.0]
    with pytest.raises(TypeError, match=re.escape("relocate got unknown option(s) ['lfit']; 'toy' takes ['lift']")):
        relocate(P, S, "toy", lfit=2.0)
    assert available()[-1] == "toy" and "toy" not in default_relocations() and RELOCATIONS["toy"] is toy


def test_registering_is_checked(toy):
    def no_offset(points, simplified):
        return points

    with pytest.raises(ValueError, match="relocation 'full' is built in and cannot be replaced"):
        register(Relocation("full", no_offset, "x"))
    with pytest.raises(ValueError, match="a relocation named 'toy' is registered already; pass replace=True"):
        register(Relocation("toy", toy.function, "again", options=("lift",)))
    with pytest.raises(TypeError, match="relocation 'bad': its function takes no keyword 'offset'"):
        register(Relocation("bad", no_offset, "no offset"))
    with pytest.raises(ValueError, match=r"measures must be None \(every measure\) or a non-empty tuple"):
        register(Relocation("bad", toy.function, "x", measures="pairs"))
    with pytest.raises(ValueError, match="relocation 'oracle' is built in and cannot be removed"):
        unregister("oracle")
    with pytest.raises(ValueError, match="how must be one of"):
        relocate(np.zeros((1, 3)), HeightGrid(np.zeros((2, 2))), "tyo")


def test_a_relocation_that_moves_points_sideways_is_refused():
    def sideways(points, simplified, *, offset=0.0):
        out = points.copy()
        out[:, 0] += 1.0
        return out

    register(Relocation("sideways", sideways, "a broken relocation"))
    try:
        with pytest.raises(ValueError, match="relocation 'sideways' moved points horizontally"):
            relocate(np.array([[0.5, 0.5, 1.0]]), HeightGrid(np.zeros((2, 2))), "sideways")
    finally:
        unregister("sideways")


def test_compare_the_report_and_the_figures_pick_it_up(toy):
    grid = synthetic_terrain("hills", size=33, seed=2)
    df = compare({"g": grid}, relocations=["full", "toy"], workers=1, **_small(max_distance=[None, 300.0]))
    assert df["error"].isna().all() and list(dict.fromkeys(df["relocation"])) == ["full", "toy"]
    beyond = report.beyond_paper(df)
    assert "toy" in beyond.columns and "beyond the paper" in beyond.attrs["title"].lower()
    assert "toy" in beyond.attrs["title"] and "gain" not in beyond.columns  # no calibrated rows: no gain column
    assert list(report.localized(df).index.get_level_values("relocation").unique()) == ["full", "toy"]
    fig = plot.accuracy_vs_size(df)
    assert [ax.get_title() for ax in fig.axes[:2]] == ["relocation: full", "relocation: toy"]
    fig = plot.accuracy_vs_distance(df)
    line = [ln for ln in fig.axes[0].get_lines() if ln.get_label() == "toy"][0]
    assert line.get_color() == "tab:olive" and line.get_marker() == "P"
    # a measure it does not serve is refused, naming it
    register(Relocation("pairs-only", toy.function, "x", options=("lift",), measures=("pairs",)))
    try:
        with pytest.raises(ValueError, match="measure 'viewshed' does not support the 'pairs-only' relocation"):
            compare({"g": grid}, relocations=["pairs-only"], measure="viewshed", workers=1, **_small())
    finally:
        unregister("pairs-only")


@pytest.mark.slow
def test_worker_processes_get_it_and_give_the_same_rows(toy):
    grid = synthetic_terrain("hills", size=33, seed=2)
    kw = _small(levels=[1, 2])
    serial = compare({"g": grid}, relocations=["toy"], workers=1, **kw)
    pooled = compare({"g": grid}, relocations=["toy"], workers=2, **kw)
    cols = ["terrain", "method", "level", "relocation", "accuracy", "n_pairs", "agree_visible"]
    pd.testing.assert_frame_equal(serial[cols], pooled[cols])
    assert pooled["error"].isna().all()


def test_a_function_workers_cannot_import_is_refused_before_the_run(tmp_path):
    grid = synthetic_terrain("hills", size=33, seed=2)
    register(Relocation("inline", lambda points, simplified, *, offset=0.0: points.copy(), "a lambda"))
    try:
        with pytest.raises(TypeError, match=r"relocation 'inline': its function \S*<lambda> cannot be sent to worker "
                                            r"processes .*top level of a module.*workers=1"):
            compare({"g": grid}, relocations=["inline"], workers=2, out_csv=tmp_path / "r.csv", **_small(levels=[1, 2]))
        assert not (tmp_path / "r.csv").exists()  # refused before anything was written
        assert (compare({"g": grid}, relocations=["inline"], workers=1, **_small())["error"].isna()).all()
    finally:
        unregister("inline")


def test_the_command_line_picks_it_up(toy, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["compare", "--terrain", "hills", "--levels", "1", "--methods", "lls", "--points", "8", "--sets", "1",
                 "--repeats", "1", "--workers", "1", "--relocations", "full", "toy", "--out", str(out)]) == 0
    assert "| toy |" in (out / "tables.md").read_text() or " toy " in (out / "tables.md").read_text()
    assert (out / "tradeoff_toy.png").exists()
    pts = tmp_path / "p.csv"
    pts.write_text("x,y\n600,600\n1800,2400\n")
    capsys.readouterr()
    assert main(["relocate", "hills", "-m", "lls", "-l", "1", "--points", str(pts), "--how", "toy",
                 "-o", str(tmp_path / "moved.csv")]) == 0
    moved = pd.read_csv(tmp_path / "moved.csv")
    np.testing.assert_allclose(moved["z"], moved["ground_simplified"] + 1.0, atol=1e-6)
    with pytest.raises(SystemExit):
        main(["relocate", "--help"])
    assert "toy: full projection, lifted" in " ".join(capsys.readouterr().out.split())


def test_its_memory_estimate_is_checked_before_a_run_and_named(tmp_path, monkeypatch):
    # a relocation declares what it allocates per unit; the run is refused before it starts, naming it
    from terrainvis.errors import NotEnoughMemoryError
    from terrainvis.experiment import plan

    def huge(settings):
        return 10 * 2**40, f"the toy's table of {settings.n_points:,} points"

    register(Relocation("toy-memory", lambda points, simplified, *, offset=0.0: points.copy(), "keeps the points",
                        memory=huge))
    try:
        monkeypatch.setattr("terrainvis.core.memory.available_memory", lambda: 2**30)
        grids = {"h": synthetic_terrain("hills", size=17, seed=0)}
        settings = plan.settings_for(grids, _small(relocations=["full", "toy-memory"]))
        assert plan.unit_bytes(settings, grids) - plan.unit_bytes(
            plan.settings_for(grids, _small(relocations=["full"])), grids) == 10 * 2**40
        with pytest.raises(NotEnoughMemoryError,
                           match=r"^the toy.s table of 8 points needs at least 10 TiB of memory, but this machine "
                                 r"has 1 GiB "):
            compare(grids, relocations=["full", "toy-memory"], workers=1, **{k: v for k, v in _small().items()})
    finally:
        unregister("toy-memory")
