"""The figures, and matplotlib kept inside terrainvis.experiment.plot."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import pytest
from matplotlib.figure import Figure

from terrainvis import compare, synthetic_terrain
from terrainvis.experiment import plot


@pytest.fixture(scope="module")
def df():
    g = {"r": synthetic_terrain("ridges", size=33, seed=2)}
    return compare(g, methods=["simple", "lls", "greedy-insertion"], levels=[1, 2], n_points=10, n_sets=2, workers=1,
                   repeats=1)


def test_figures(df):
    from simplifiers import METHODS, simplify

    g = synthetic_terrain("ridges", size=33, seed=2)
    views = {"lls": simplify(g, "lls", 1), "gi": simplify(g, "greedy-insertion", 1)}
    figs = [
        plot.hillshade(g), plot.hillshade(views["gi"]), plot.terrain_views(g, views),
        plot.accuracy_vs_size(df), plot.tradeoff(df, relocation="half"),
    ]
    from terrainvis import sample_points, visibility_matrix

    P = sample_points(g, 10, seed=0)
    V = visibility_matrix(g, P)
    W = V.copy()
    W[0, 1] = W[1, 0] = not V[0, 1]
    figs.append(plot.los_pairs(g, P, V, W))
    assert all(isinstance(f, Figure) for f in figs)
    legend = [t.get_text() for t in figs[-1].axes[0].get_legend().get_texts()]
    changed = "false blocked (1)" if V[0, 1] else "false visible (1)"
    assert changed in legend
    # every method is drawn in its registry colour
    bars = {c.get_label(): c.lines[0].get_color() for c in figs[3].axes[0].containers}
    assert bars["lls"] == METHODS["lls"].style[0] and bars["greedy-insertion"] == METHODS["greedy-insertion"].style[0]
    # the methods' error bars stand side by side at a size, not on top of each other
    xs = {c.get_label(): c.lines[0].get_xdata()[0] for c in figs[3].axes[0].containers}
    assert len(set(xs.values())) == len(xs) == 3
    assert max(xs.values()) / min(xs.values()) < 1.2  # ... and near the size they stand for
    # the legend is outside the panels, where it hides no data
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(figs[3]).get_renderer()
    legend_box = figs[3].axes[-1].get_legend().get_window_extent(renderer)
    assert legend_box.x0 >= figs[3].axes[-1].get_window_extent(renderer).x1
    assert legend_box.x1 <= figs[3].bbox.x1  # ... and inside the figure
    with pytest.raises(ValueError, match="no rows"):
        plot.tradeoff(df[df.relocation == "full"], relocation="half")


def test_only_plot_imports_matplotlib():
    import subprocess
    import sys

    code = (
        "import sys\n"
        "import terrainvis as tv, simplifiers\n"
        "from terrainvis import experiment, report, cli, relocation, metrics, io, visibility, deviation\nfrom terrainvis.core import runner\n"
        "g = tv.sample_dem('jacksboro').crop(rows=(0, 40), cols=(0, 40))\n"
        "for m in simplifiers.registry.BUILTIN: simplifiers.simplify(g, m, 1, **({'n_train': 20} if m == 'visopt' else {}))\n"
        "P = tv.sample_points(g, 5)\n"
        "tv.visibility_matrix(g, P); tv.visibility_matrix(g.to_tin(), P)\n"
        "print('matplotlib' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_accuracy_vs_distance():
    g = {"h": synthetic_terrain("hills", size=33, seed=4)}
    df = compare(g, methods=["lls"], levels=[1, 2], n_points=12, n_sets=1, workers=1, repeats=1,
                 max_distance=[5, 10, None], distance_unit="cells")
    fig = plot.accuracy_vs_distance(df)
    assert len(fig.axes) == 2
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["5", "10", "all"]
    from terrainvis.relocation import default_relocations

    assert {ln.get_label() for ln in ax.get_lines()} == set(default_relocations())  # the run's relocations
    with pytest.raises(ValueError, match="no distance sweep"):
        plot.accuracy_vs_distance(df[df["max_distance"].isna()])


def test_viewshed_figure():
    from terrainvis import viewshed

    g = synthetic_terrain("ridges", size=33, seed=2)
    v = viewshed(g, (400.0, 500.0))
    fig = plot.viewshed(g, v, observer=(400.0, 500.0))
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert legend[0] == f"visible ({100 * v.mean():.1f} %)"
    with pytest.raises(ValueError, match="visible must have the terrain's shape"):
        plot.viewshed(g, v[:3])


@pytest.mark.parametrize("low, high", [(-12.998, 3.289), (-0.004, 0.006), (-5.0, 2.0)])
def test_angle_figure_draws_without_warnings(low, high):
    """The angle bar's ticks stay inside the norm's range: -12.998 rounded to -13.0 lay past
    its end, and matplotlib's layout warned 'invalid value encountered in scalar multiply'."""
    import io
    import warnings

    import numpy as np

    g = synthetic_terrain("hills", size=20, seed=0)
    values = np.linspace(low, high, g.size).reshape(g.shape)
    values[0, 0] = np.nan
    fig = plot.viewshed_values(g, values, "angle", observer=(100.0, 100.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig.savefig(io.BytesIO(), format="png")
    ticks = fig.axes[1].get_yticks()
    assert ticks.min() >= low and ticks.max() <= high and 0.0 in ticks
