"""Figures: hillshades, LOS pairs, accuracy against size (or against a budget in vertical error), and the
speed/accuracy trade-off.

A run budgeted in maximum vertical error (``compare(..., max_errors=[E, ...])``) is drawn by
budget where a run by levels is drawn by level: :func:`accuracy_vs_budget` puts the budget on
the x axis, and :func:`tradeoff` and :func:`accuracy_vs_distance` label and split by budget.

This is the only module of terrainvis that imports matplotlib. Every function returns a
:class:`matplotlib.figure.Figure` and never calls ``show()``; in a notebook the figure
displays itself, and the CLI saves it as a PNG.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.colors import LightSource
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from ..core.validate import as_points, describe
from ..core.terrain import TIN, HeightGrid, as_terrain
from .report import step_column

__all__ = [
    "hillshade", "terrain_views", "los_pairs", "accuracy_vs_size", "accuracy_vs_budget", "accuracy_vs_zoom", "tradeoff",
    "accuracy_vs_distance", "viewshed",
    "viewshed_values", "cumulative_viewshed", "siting", "observer_network",
]


def _style(method: str) -> tuple[str, str]:
    """Colour and marker of a method (from the registry; black dots for unknown names)."""
    from simplifiers import METHODS

    info = METHODS.get(method)
    return info.style if info is not None else ("k", "o")


def _shade_image(terrain, resolution: int | None = None, vrange: tuple | None = None):
    """An RGB hillshade image of a terrain and its extent (TINs are rasterised); colours span
    ``vrange`` (z min, z max) when given (panels that share a colour bar), else the terrain's heights."""
    if isinstance(terrain, HeightGrid) and terrain.is_uniform:
        z, (xmin, xmax, ymin, ymax) = terrain.z, terrain.extent
        dx, dy = terrain.dx, terrain.dy
    else:
        xmin, xmax, ymin, ymax = terrain.extent
        n = resolution or 400
        xs = np.linspace(xmin, xmax, n)
        ys = np.linspace(ymin, ymax, max(2, int(round(n * (ymax - ymin) / (xmax - xmin)))))
        z = terrain.height_on_grid(xs, ys)
        dx, dy = xs[1] - xs[0], ys[1] - ys[0]
    zf = np.where(np.isnan(z), np.nanmin(z), z)
    import matplotlib as mpl

    ls = LightSource(azdeg=315, altdeg=45)
    # imshow with origin="lower" puts row 0 at the bottom, i.e. y grows upwards (north).
    # LightSource assumes row 0 at the top, so shade the flipped array and flip back.
    lo, hi = vrange if vrange is not None else (None, None)
    rgb = ls.shade(zf[::-1], cmap=mpl.colormaps["terrain"], vert_exag=1.0, dx=dx, dy=dy, blend_mode="soft",
                   vmin=lo, vmax=hi)[::-1]
    rgb[np.isnan(z)] = (1.0, 1.0, 1.0, 1.0)
    return rgb, (xmin, xmax, ymin, ymax)


def _draw_terrain(ax, terrain, *, wireframe: bool = True, title: str | None = None, axes: bool = True,
                  vrange: tuple | None = None):
    rgb, extent = _shade_image(terrain, vrange=vrange)
    ax.imshow(rgb, origin="lower", extent=extent, interpolation="nearest")
    if isinstance(terrain, TIN) and wireframe:
        v = terrain.vertices
        ax.triplot(v[:, 0], v[:, 1], terrain.faces, color="k", lw=0.25, alpha=0.5)
    ax.set_aspect("equal")
    if axes:
        from matplotlib.ticker import MaxNLocator

        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        # few enough ticks that long coordinates (a UTM easting of 664,692) do not run together
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.yaxis.set_major_locator(MaxNLocator(5))
    else:  # a panel of many: the picture alone (ticks cost most of the drawing time)
        ax.set_xticks([])
        ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=9)


def hillshade(terrain, *, wireframe: bool = True, title: str | None = None, figsize=(6, 5)) -> Figure:
    """A hillshade of a HeightGrid, or of a TIN with its wireframe.

    Parameters
    ----------
    terrain : HeightGrid or TIN
    wireframe : bool
        Draw a TIN's edges.
    title : str, optional
    """
    as_terrain(terrain)
    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.add_subplot()
    _draw_terrain(ax, terrain, wireframe=wireframe, title=title or repr(terrain))
    return fig


def terrain_views(original: HeightGrid, simplified: dict, *, ncols: int = 4, panel_size: float = 3.2) -> Figure:
    """The original terrain and its simplifications side by side.

    Parameters
    ----------
    original : HeightGrid
    simplified : dict of str to HeightGrid or TIN
        Panel title -> simplified terrain.
    """
    as_terrain(original, "original")
    if not isinstance(simplified, dict):
        raise TypeError(f"simplified must be a dict of title -> terrain, got {describe(simplified)}")
    panels = [("original", original)] + list(simplified.items())
    nrows = int(np.ceil(len(panels) / ncols))
    fig = Figure(figsize=(panel_size * ncols + 1.0, panel_size * nrows + 0.3))
    fig.subplots_adjust(left=0.01, right=1 - 1.0 / (panel_size * ncols + 1.0), bottom=0.06, top=0.92, wspace=0.04,
                        hspace=0.12)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    xmin, xmax, ymin, ymax = original.extent
    vrange = (float(np.nanmin(original.z)), float(np.nanmax(original.z)))  # one colour scale for every panel
    for ax, (title, t) in zip(axes, panels):
        as_terrain(t, f"simplified[{title!r}]")
        n = t.size if isinstance(t, HeightGrid) else t.n_vertices
        _draw_terrain(ax, t, title=f"{title} ({n:,} vertices)", axes=False, vrange=vrange)
    for ax in axes[len(panels):]:
        ax.set_axis_off()
    import matplotlib as mpl
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    bar_ax = fig.add_axes((1 - 0.8 / (panel_size * ncols + 1.0), 0.15, 0.12 / (panel_size * ncols + 1.0), 0.7))
    fig.colorbar(ScalarMappable(Normalize(*vrange), mpl.colormaps["terrain"]), cax=bar_ax, label="elevation (z units)")
    fig.text(0.01, 0.015, f"each panel {xmax - xmin:,.4g} x {ymax - ymin:,.4g} (x, y units); hillshade lit from the "
             "north-west", fontsize=8)
    return fig


def los_pairs(terrain, points, V_true, V_test, *, only_changed: bool = False, title: str | None = None,
              figsize=(7, 6)) -> Figure:
    """Line-of-sight pairs over a terrain, coloured by whether their verdict survived.

    Colours: grey, the same verdict on both terrains; red, *false blocked* (visible on
    the original, blocked on the simplification); blue, *false visible*.

    Parameters
    ----------
    terrain : HeightGrid or TIN
        Drawn as the background.
    points : (n, 3) array_like
    V_true, V_test : (n, n) bool
        Visibility on the original and on the simplified terrain.
    only_changed : bool
        Draw only the pairs whose verdict changed.
    """
    as_terrain(terrain)
    pts = as_points(points, "points", 3)
    t = np.asarray(V_true, dtype=bool)
    s = np.asarray(V_test, dtype=bool)
    n = pts.shape[0]
    if t.shape != (n, n) or s.shape != (n, n):
        raise ValueError(f"V_true and V_test must have shape ({n}, {n}), got {t.shape} and {s.shape}")
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.add_subplot()
    _draw_terrain(ax, terrain, wireframe=False, title=title)
    i, j = np.triu_indices(n, k=1)
    segs = np.stack([pts[i, :2], pts[j, :2]], axis=1)
    same = t[i, j] == s[i, j]
    false_blocked = t[i, j] & ~s[i, j]
    false_visible = ~t[i, j] & s[i, j]
    if not only_changed:
        ax.add_collection(LineCollection(segs[same], colors="0.3", linewidths=0.3, alpha=0.35))
    ax.add_collection(LineCollection(segs[false_blocked], colors="tab:red", linewidths=1.0))
    ax.add_collection(LineCollection(segs[false_visible], colors="tab:blue", linewidths=1.0))
    ax.plot(pts[:, 0], pts[:, 1], "k.", ms=4)
    handles = [
        Line2D([], [], color="0.3", lw=1, label=f"same verdict ({int(same.sum())})"),
        Line2D([], [], color="tab:red", lw=1.5, label=f"false blocked ({int(false_blocked.sum())})"),
        Line2D([], [], color="tab:blue", lw=1.5, label=f"false visible ({int(false_visible.sum())})"),
    ]
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    return fig


def _panels(n: int, width: float, height: float, figsize=None, sharey: bool = True, legend: float = 1.5):
    """A figure of ``n`` panels in a row with fixed margins (``legend`` inches on the right for it).

    A layout engine measures every tick label and costs more than the drawing itself;
    these figures have a known shape, so fixed margins serve as well.
    """
    fig = Figure(figsize=figsize or (width * n + legend, height))
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=0.95 / w, right=1 - (0.15 + legend) / w, bottom=0.55 / h, top=1 - 0.35 / h,
                        wspace=0.3 if not sharey else 0.08)
    return fig, fig.subplots(1, n, squeeze=False, sharey=sharey).ravel()


def _check_df(df, needed, *, sweep: bool = False):
    """The error-free rows of a compare result; of a distance sweep, the all-pairs rows unless ``sweep``."""
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"df must be a pandas DataFrame from terrainvis.compare, got {describe(df)}")
    missing = set(needed) - set(df.columns)
    if missing:
        raise ValueError(f"df must have the columns of terrainvis.compare, missing {sorted(missing)}")
    if "error" in df.columns:
        df = df[df["error"].fillna("").astype(str) == ""]
    if not sweep and "max_distance" in df.columns and df["max_distance"].nunique(dropna=False) > 1:
        df = df[df["max_distance"].isna()]
    return df


def accuracy_vs_size(df: pd.DataFrame, *, figsize=None) -> Figure:
    """Accuracy against terrain size (% of the original samples), per method and relocation.

    One panel per relocation; each method is a line through its levels (or its budgets, in
    a run budgeted in vertical error), with the standard deviation over terrains x point
    sets as an error bar (the methods' bars side by side at each size, so that wide ones do
    not merge into one block).
    """
    from simplifiers import METHODS

    from ..relocation.registry import practical_relocations

    data = _check_df(df, {"method", "relocation", "size_fraction", "accuracy", "level"})
    step = step_column(data)
    rels = [r for r in practical_relocations() if r in set(data["relocation"])]
    fig, axes = _panels(max(1, len(rels)), 4.2, 3.8, figsize)
    for ax, rel in zip(axes, rels):
        sub = data[data["relocation"] == rel]
        present = [m for m in METHODS if m in set(sub["method"])] + sorted(set(sub["method"]) - set(METHODS))
        for k, m in enumerate(present):
            g = sub[sub["method"] == m].groupby(step).agg(
                size=("size_fraction", "median"), mu=("accuracy", "mean"), sd=("accuracy", "std")
            ).sort_values("size")
            color, marker = _style(m)
            # side by side on the log axis: a few per cent of a size apart, centred on it
            x = 100 * g["size"].to_numpy() * 1.045 ** (k - (len(present) - 1) / 2)
            mu = 100 * g["mu"].to_numpy()
            sd = 100 * g["sd"].fillna(0).to_numpy()
            ax.errorbar(x, mu, yerr=sd, marker=marker, color=color, label=m, capsize=2, elinewidth=0.8,
                        markersize=5)
        sizes = sorted({round(100 * v, 2) for v in sub.groupby(step)["size_fraction"].median()})
        _log_panel(ax, sizes, [f"{v:g}%" for v in sizes], rel, "size of S(T) (% of samples of T)")
    axes[0].set_ylabel("accuracy (% of pairs agreeing)")
    _legend_outside(axes[-1])
    return fig


def accuracy_vs_budget(df: pd.DataFrame, *, figsize=None) -> Figure:
    """Accuracy against the budget in maximum vertical error, per method and relocation.

    For a run budgeted in vertical error (``compare(..., max_errors=[E, ...])``): one panel
    per relocation; each method is a line through its budgets E (x axis, log scale), each
    point the mean accuracy of its smallest results within E, with the standard deviation
    over terrains x point sets as an error bar (the methods' bars side by side at each
    budget). A result that could not reach its budget (``stopped_by`` other than
    ``"max_error"``) is drawn as its row says: its accuracy counts at that budget.

    Raises
    ------
    ValueError
        When ``df`` holds no budget (a run by levels: :func:`accuracy_vs_size`).
    """
    from simplifiers import METHODS

    from ..relocation.registry import practical_relocations

    data = _check_df(df, {"method", "relocation", "accuracy", "max_error_budget"})
    if step_column(data) != "max_error_budget":
        raise ValueError("df holds no budget in vertical error (max_error_budget is empty in every row); run compare "
                         "with max_errors=[...], or draw a run by levels with accuracy_vs_size")
    rels = [r for r in practical_relocations() if r in set(data["relocation"])]
    fig, axes = _panels(max(1, len(rels)), 4.2, 3.8, figsize)
    budgets = sorted(float(b) for b in data["max_error_budget"].unique())
    for ax, rel in zip(axes, rels):
        sub = data[data["relocation"] == rel]
        present = [m for m in METHODS if m in set(sub["method"])] + sorted(set(sub["method"]) - set(METHODS))
        for k, m in enumerate(present):
            g = sub[sub["method"] == m].groupby("max_error_budget").agg(mu=("accuracy", "mean"),
                                                                         sd=("accuracy", "std")).sort_index()
            color, marker = _style(m)
            x = g.index.to_numpy(dtype=float) * 1.045 ** (k - (len(present) - 1) / 2)
            ax.errorbar(x, 100 * g["mu"].to_numpy(), yerr=100 * g["sd"].fillna(0).to_numpy(), marker=marker,
                        color=color, label=m, capsize=2, elinewidth=0.8, markersize=5)
        _log_panel(ax, budgets, [f"{v:g}" for v in budgets], rel, "max vertical error budget (z units)")
    axes[0].set_ylabel("accuracy (% of pairs agreeing)")
    _legend_outside(axes[-1])
    return fig


def accuracy_vs_zoom(df: pd.DataFrame, *, figsize=None) -> Figure:
    """The verdicts a tileset keeps, against its zoom and against its measured vertical error.

    For the rows of tilesets measured by :func:`terrainvis.evaluate` (those with a ``zoom``):
    two panels, accuracy against zoom (left) and against the stitched TIN's maximum
    vertical error (right, log scale); a line per tileset and relocation (colour by
    relocation, marker by tileset), each point the mean over point sets with the standard
    deviation as an error bar.

    Raises
    ------
    ValueError
        When ``df`` holds no row with a zoom.
    """
    from ..relocation.registry import practical_relocations

    data = _check_df(df, {"method", "relocation", "accuracy", "zoom", "max_error"})
    data = data[data["zoom"].notna()]
    if data.empty:
        raise ValueError("df holds no tileset's rows (zoom is empty in every row); measure a tileset with "
                         "terrainvis.evaluate(DEM, TILESET_DIR, zoom=[...])")
    data = data.assign(tileset=[m[: -len(f"-z{int(z)}")] if str(m).endswith(f"-z{int(z)}") else str(m)
                                for m, z in zip(data["method"], data["zoom"])])
    rels = [r for r in practical_relocations() if r in set(data["relocation"])]
    rels += sorted(set(data["relocation"]) - set(rels))
    fig, axes = _panels(2, 4.2, 3.8, figsize, sharey=True, legend=2.2)
    from matplotlib import rcParams

    colors = rcParams["axes.prop_cycle"].by_key()["color"]
    markers = "osD^vP*X"
    for t, tileset in enumerate(dict.fromkeys(data["tileset"])):
        for r, rel in enumerate(rels):
            sub = data[(data["tileset"] == tileset) & (data["relocation"] == rel)]
            if sub.empty:
                continue
            g = sub.groupby("zoom").agg(mu=("accuracy", "mean"), sd=("accuracy", "std"),
                                        err=("max_error", "first")).sort_index()
            style = dict(marker=markers[t % len(markers)], color=colors[r % len(colors)], capsize=2,
                         elinewidth=0.8, markersize=5)
            mu, sd = 100 * g["mu"].to_numpy(), 100 * g["sd"].fillna(0).to_numpy()
            axes[0].errorbar(g.index.to_numpy(dtype=float), mu, yerr=sd, label=f"{tileset}, {rel}", **style)
            by_err = np.argsort(g["err"].to_numpy(dtype=float), kind="stable")
            axes[1].errorbar(g["err"].to_numpy(dtype=float)[by_err], mu[by_err], yerr=sd[by_err], **style)
    zooms = sorted(int(z) for z in data["zoom"].unique())
    axes[0].set_xticks(zooms, [str(z) for z in zooms])
    axes[0].set_xlabel("zoom")
    axes[0].set_ylabel("accuracy (% of pairs agreeing)")
    from matplotlib.ticker import FuncFormatter, LogLocator

    axes[1].set_xscale("log")
    axes[1].xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    axes[1].xaxis.set_minor_formatter(NullFormatter())
    axes[1].xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axes[1].set_xlabel("max vertical error of the stitched TIN (z units)")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_title("against zoom", fontsize=10)
    axes[1].set_title("against vertical error", fontsize=10)
    handles, labels = axes[0].get_legend_handles_labels()
    axes[1].legend(handles, labels, fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
                   frameon=False)
    return fig


def _log_panel(ax, ticks, labels, relocation: str, xlabel: str) -> None:
    """One relocation's panel of :func:`accuracy_vs_size` or :func:`accuracy_vs_budget`: a log x axis
    ticked at ``ticks``, its title and labels."""
    ax.set_xscale("log")
    ax.set_xticks(ticks, labels)
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_title(f"relocation: {relocation}", fontsize=10)
    ax.set_xlabel(xlabel)
    ax.grid(True, which="both", alpha=0.3)


def _legend_outside(ax) -> None:
    """The legend to the right of the last panel, where it hides no data."""
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, frameon=False)


def _log_labels(ax) -> None:
    """Plain numbers at the 1-2-5 ticks of a log axis, so a range within one decade is labelled too."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))


def tradeoff(df: pd.DataFrame, *, relocation: str = "full", figsize=None) -> Figure:
    """What simplification buys against what it costs.

    Left: LOS speedup (time on T / time on S(T)) against accuracy lost; right: memory
    (bytes of S(T) / bytes of T) against accuracy lost. One point per method and level
    (per method and budget, labelled with the budget, in a run budgeted in vertical
    error), medians over terrains and point sets, for one relocation.
    """
    data = _check_df(df, {"method", "level", "relocation", "accuracy", "los_seconds", "los_seconds_original",
                          "nbytes", "nbytes_original"})
    data = data[data["relocation"] == relocation]
    if data.empty:
        raise ValueError(f"relocation {relocation!r} has no rows in df")
    data = data.assign(
        lost=100 * (1 - data["accuracy"]),
        speedup=data["los_seconds_original"] / data["los_seconds"],
        memory=data["nbytes"] / data["nbytes_original"],
    )
    step = step_column(data)
    g = data.groupby(["method", step]).agg(lost=("lost", "mean"), speedup=("speedup", "median"), memory=("memory", "median"))
    fig, (ax1, ax2) = _panels(2, 5.0, 4.0, figsize, sharey=False)
    from simplifiers import METHODS

    present = [m for m in METHODS if m in g.index.get_level_values(0)]
    present += sorted(set(g.index.get_level_values(0)) - set(present))
    # each method's level labels on its own side of its points, so that methods at the same place do not overprint
    sides = [(4, 3), (-9, 3), (4, -9), (-9, -9), (6, -3), (-11, -3)]
    for j, m in enumerate(present):
        color, marker = _style(m)
        for k, (lv, row) in enumerate(g.loc[m].iterrows()):
            for ax, col in ((ax1, "speedup"), (ax2, "memory")):
                ax.scatter(row["lost"], row[col], color=color, marker=marker, label=m if k == 0 else None)
                ax.annotate(str(lv) if step == "level" else f"{lv:g}", (row["lost"], row[col]), fontsize=7,
                            color=color, xytext=sides[j % len(sides)], textcoords="offset points")
    for ax in (ax1, ax2):
        ax.set_yscale("log")
        _log_labels(ax)
    ax1.axhline(1.0, color="k", lw=0.5)
    ax2.axhline(1.0, color="k", lw=0.5)
    ax1.set_xlabel("accuracy lost (percentage points)")
    ax2.set_xlabel("accuracy lost (percentage points)")
    ax1.set_ylabel("LOS speedup on S(T) (×)")
    ax2.set_ylabel("memory of S(T) / memory of T")
    ax1.set_title(f"speed gained ({relocation}; labels: {'level' if step == 'level' else 'max error budget'})",
                  fontsize=10)
    ax2.set_title("memory kept", fontsize=10)
    _legend_outside(ax2)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    return fig


def accuracy_vs_distance(df: pd.DataFrame, *, figsize=None) -> Figure:
    """Accuracy of localized tests against the pair distance, per relocation (a distance sweep).

    One panel per level (or budget); each relocation is a line through the distances of the run
    (mean over terrains, methods and point sets); the pairs at every distance ("all")
    are drawn at the right end.
    """
    from ..relocation.registry import RELOCATIONS

    data = _check_df(df, {"relocation", "accuracy", "level", "max_distance"}, sweep=True)
    if data["max_distance"].nunique(dropna=True) < 1:
        raise ValueError("df holds no distance sweep (max_distance is unlimited in every row)")
    step = step_column(data)
    levels = sorted(data[step].unique())
    finite = sorted(data["max_distance"].dropna().unique())
    x_all = finite[-1] * 2.0
    unit = data["distance_unit"].iloc[0] if "distance_unit" in data.columns else "world"
    fig, axes = _panels(len(levels), 4.2, 3.8, figsize)
    for ax, level in zip(axes, levels):
        sub = data[data[step] == level]
        for rel in [r for r in RELOCATIONS if r in set(sub["relocation"])]:
            g = sub[sub["relocation"] == rel].assign(_d=lambda t: t["max_distance"].fillna(x_all))
            mu = 100 * g.groupby("_d")["accuracy"].mean()
            style = RELOCATIONS[rel]
            ax.plot(mu.index, mu.to_numpy(), marker=style.marker, color=style.color, label=rel,
                    linestyle=style.linestyle)
        ax.set_xscale("log")
        ticks = finite + [x_all]
        ax.set_xticks(ticks, [f"{v:g}" for v in finite] + ["all"])
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(f"level {level}" if step == "level" else f"max error ≤ {level:g}", fontsize=10)
        ax.set_xlabel(f"pairs within this distance ({'cells' if unit == 'cells' else 'm'})")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("accuracy (% of pairs agreeing)")
    _legend_outside(axes[-1])
    return fig


def viewshed(terrain: HeightGrid, visible, *, observer=None, title: str | None = None, figsize=(6, 5),
             field=None) -> Figure:
    """A viewshed drawn over the terrain's hillshade.

    Parameters
    ----------
    terrain : HeightGrid
        The grid whose samples ``visible`` refers to (normally the terrain the viewshed
        was computed for, or the ``at`` grid of a viewshed on a simplification).
    visible : (rows, cols) bool
        :func:`terrainvis.viewshed`'s result.
    observer : (x, y), optional
        Marked with a star.
    title : str, optional
    field : (rows, cols) bool, optional
        The viewshed's field of view (:func:`terrainvis.visibility.field_of_view_mask`):
        samples outside it are drawn apart from the hidden ones, and the visible share is
        of the samples inside it.
    """
    as_terrain(terrain)
    if not isinstance(terrain, HeightGrid):
        raise TypeError(f"terrain must be the HeightGrid of the viewshed's samples, got {describe(terrain)}")
    vis = np.asarray(visible, dtype=bool)
    if vis.shape != terrain.shape:
        raise ValueError(f"visible must have the terrain's shape {terrain.shape}, got {vis.shape}")
    inside = np.ones(terrain.shape, dtype=bool) if field is None else np.asarray(field, dtype=bool)
    if inside.shape != terrain.shape:
        raise ValueError(f"field must have the terrain's shape {terrain.shape}, got {inside.shape}")
    from matplotlib.patches import Patch

    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.add_subplot()
    _draw_terrain(ax, terrain, wireframe=False, title=title or "viewshed")
    xmin, xmax, ymin, ymax = terrain.extent
    valid = np.isfinite(terrain.z) & inside
    rgba = np.zeros(terrain.shape + (4,))
    rgba[valid & vis] = (1.0, 0.83, 0.0, 0.55)  # visible: yellow
    rgba[valid & ~vis] = (0.05, 0.05, 0.15, 0.55)  # hidden: dark
    rgba[np.isfinite(terrain.z) & ~inside] = (0.95, 0.95, 0.95, 0.6)  # outside the field of view: pale
    ax.imshow(rgba, origin="lower", extent=(xmin, xmax, ymin, ymax), interpolation="nearest")
    share = 100 * vis[valid].mean() if valid.any() else 0.0
    handles = [Patch(color=(1.0, 0.83, 0.0, 0.8), label=f"visible ({share:.1f} %"
                     + (" of the field)" if field is not None else ")")),
               Patch(color=(0.05, 0.05, 0.15, 0.8), label="hidden")]
    if field is not None:
        handles.append(Patch(facecolor=(0.95, 0.95, 0.95, 0.9), edgecolor="0.5", label="outside the field of view"))
    if observer is not None:
        ax.plot([observer[0]], [observer[1]], marker="*", color="red", markersize=14, markeredgecolor="k")
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    return fig


def viewshed_values(terrain: HeightGrid, values, output: str, *, observer=None, title: str | None = None,
                    figsize=(6.5, 5)) -> Figure:
    """A viewshed's ``"min_height"`` or ``"angle"`` output drawn over the terrain's hillshade.

    Parameters
    ----------
    terrain : HeightGrid
        The grid whose samples ``values`` refers to.
    values : (rows, cols) float
        :func:`terrainvis.viewshed`'s result with ``output`` (NaN: no value, left as the hillshade).
    output : {"min_height", "angle"}
    observer : (x, y), optional
        Marked with a star.
    title : str, optional

    ``"min_height"``: samples whose ground is visible (0) in yellow, the others coloured by
    the height a target needs (a colour bar up to the 98th percentile). ``"angle"``: a
    diverging map centred on 0 (red above the horizon, blue below), symmetric up to the
    98th percentile of the absolute angles.
    """
    as_terrain(terrain)
    if not isinstance(terrain, HeightGrid):
        raise TypeError(f"terrain must be the HeightGrid of the values' samples, got {describe(terrain)}")
    v = np.asarray(values, dtype=np.float64)
    if v.shape != terrain.shape:
        raise ValueError(f"values must have the terrain's shape {terrain.shape}, got {v.shape}")
    if output not in ("min_height", "angle"):
        raise ValueError(f"output must be 'min_height' or 'angle', got {output!r}")
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.patches import Patch

    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.add_subplot()
    _draw_terrain(ax, terrain, wireframe=False, title=title or f"viewshed: {output}")
    extent = terrain.extent
    finite = np.isfinite(v)
    handles = []
    if output == "min_height":
        seen = finite & (v == 0.0)
        glow = np.zeros(terrain.shape + (4,))
        glow[seen] = (1.0, 0.83, 0.0, 0.6)
        ax.imshow(glow, origin="lower", extent=extent, interpolation="nearest")
        rest = finite & ~seen
        top = float(np.percentile(v[rest], 98)) if rest.any() else 1.0
        top = top if top > 0.0 else 1.0  # a colour scale needs some span
        image = ax.imshow(np.ma.masked_where(~rest, v), origin="lower", extent=extent, interpolation="nearest",
                          cmap="PuBu", vmin=-0.1 * top, vmax=top, alpha=0.85)
        fig.colorbar(image, ax=ax, shrink=0.85, label="least visible height above the ground", extend="max")
        handles.append(Patch(color=(1.0, 0.83, 0.0, 0.8), label="ground visible (0)"))
    else:
        below, above = v[finite & (v < 0)], v[finite & (v > 0)]
        low = float(np.percentile(-below, 98)) if below.size else 1.0  # below.size: each > 0
        high = float(np.percentile(above, 98)) if above.size else 1.0
        low = -low
        image = ax.imshow(np.ma.masked_where(~finite, v), origin="lower", extent=extent, interpolation="nearest",
                          cmap="RdBu_r", norm=TwoSlopeNorm(0.0, low, high), alpha=0.85)
        bar = fig.colorbar(image, ax=ax, shrink=0.85, label="degrees above (+) or below (-) the horizon",
                           extend="both")
        # ticks rounded inwards: one past an end of the norm's range has no place on the bar (matplotlib's
        # layout then multiplies by NaN and warns)
        ends = np.ceil(low * 100.0) / 100.0, np.floor(high * 100.0) / 100.0
        ticks = np.round(np.r_[np.linspace(ends[0], 0.0, 5), np.linspace(0.0, ends[1], 4)], 2)
        bar.set_ticks(np.unique(np.clip(ticks, *ends)))
    if observer is not None:
        ax.plot([observer[0]], [observer[1]], marker="*", color="red", markersize=14, markeredgecolor="k")
        from matplotlib.lines import Line2D

        handles.append(Line2D([], [], linestyle="none", marker="*", markersize=10, color="red", markeredgecolor="k",
                              label="observer"))
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    return fig


def cumulative_viewshed(terrain: HeightGrid, counts, *, observers=None, title: str | None = None,
                        figsize=(6.5, 5)) -> Figure:
    """A cumulative viewshed drawn over the terrain's hillshade: how many observers see each sample.

    Parameters
    ----------
    terrain : HeightGrid
        The grid whose samples ``counts`` refers to.
    counts : (rows, cols) array_like of int
        :func:`terrainvis.cumulative_viewshed`'s result (counts >= 0).
    observers : (K, 2) array_like, optional
        The observers' (x, y), marked with dots.
    title : str, optional

    Samples seen by at least one observer are coloured by their count (colour bar); those
    seen by none are darkened; nodata is left white.
    """
    as_terrain(terrain)
    if not isinstance(terrain, HeightGrid):
        raise TypeError(f"terrain must be the HeightGrid of the counts' samples, got {describe(terrain)}")
    c = np.asarray(counts)
    if c.shape != terrain.shape:
        raise ValueError(f"counts must have the terrain's shape {terrain.shape}, got {c.shape}")
    if not (np.issubdtype(c.dtype, np.integer) or np.issubdtype(c.dtype, np.bool_)) or (c.size and c.min() < 0):
        raise ValueError(f"counts must be integers >= 0 (cumulative_viewshed's result), got {describe(c)}")
    from matplotlib.patches import Patch
    from matplotlib.ticker import MaxNLocator

    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.add_subplot()
    _draw_terrain(ax, terrain, wireframe=False, title=title or "cumulative viewshed")
    extent = terrain.extent
    valid = np.isfinite(terrain.z)
    seen = valid & (c > 0)
    dark = np.zeros(terrain.shape + (4,))
    dark[valid & ~seen] = (0.05, 0.05, 0.15, 0.65)
    ax.imshow(dark, origin="lower", extent=extent, interpolation="nearest")
    top = int(c[valid].max()) if valid.any() else 0
    image = ax.imshow(np.ma.masked_where(~seen, c.astype(np.float64)), origin="lower", extent=extent,
                      interpolation="nearest", cmap="YlOrRd", vmin=1, vmax=max(top, 2), alpha=0.8)
    bar = fig.colorbar(image, ax=ax, shrink=0.85, label="observers that see the sample")
    bar.locator = MaxNLocator(integer=True)
    bar.update_ticks()
    n_valid = max(int(valid.sum()), 1)
    none = 100 * (valid & ~seen).sum() / n_valid
    handles = [Patch(color=(0.05, 0.05, 0.15, 0.8), label=f"seen by none ({none:.1f} %)"),
               Patch(color=image.cmap(0.5), label=f"seen by any ({100 * seen.sum() / n_valid:.1f} %)")]
    if observers is not None:
        obs = np.asarray(observers, dtype=np.float64)
        if obs.ndim != 2 or obs.shape[1] not in (2, 3):
            raise ValueError(f"observers must have shape (K, 2) (x, y) or (K, 3) (eyes), got shape {obs.shape}")
        ax.plot(obs[:, 0], obs[:, 1], linestyle="none", marker="o", markersize=4, color="cyan",
                markeredgecolor="k", markeredgewidth=0.4)
        from matplotlib.lines import Line2D

        handles.append(Line2D([], [], linestyle="none", marker="o", markersize=4, color="cyan", markeredgecolor="k",
                              label=f"{len(obs):,} observer{'s' if len(obs) != 1 else ''}"))
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    return fig



def fresnel_profile(result, a, b, *, title: str | None = None, figsize=(7.5, 3.8)) -> Figure:
    """A radio path's profile: the terrain, the sight line and its first Fresnel zone.

    Parameters
    ----------
    result : terrainvis.visibility.FresnelClearance
        :func:`terrainvis.visibility.fresnel_clearance`'s result, computed with
        ``profile=True``.
    a, b : (3,) array_like
        The path's ends (the antennas), as given to it.
    title : str, optional

    The terrain is drawn raised by the earth's bulge (what the sight line must clear), from
    the exact breakpoints of the result's profile; dashed lines bound the first Fresnel
    zone (the sight line +- r1), the dotted one is 60 % of it below the line, and the worst
    place is marked.
    """
    prof = getattr(result, "profile", None)
    if prof is None:
        raise ValueError("result must come from fresnel_clearance(..., profile=True), got one without a profile")
    ends = as_points(np.vstack([np.asarray(a, float).reshape(1, -1), np.asarray(b, float).reshape(1, -1)]), "a, b", 3)
    t, d = prof["t"], prof["distance"]
    line = ends[0, 2] + t * (ends[1, 2] - ends[0, 2])
    ground = line - prof["clearance"]
    r1 = prof["radius"]
    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.add_subplot()
    base = float(np.min(ground) - 0.1 * (np.max(line + r1) - np.min(ground)))
    ax.fill_between(d, base, ground, color=(0.55, 0.45, 0.3), alpha=0.6, label="terrain (+ earth bulge)")
    ax.plot([d[0], d[-1]], [line[0], line[-1]], color="k", lw=1.2, label="sight line")
    ax.plot(d, line - r1, "b--", lw=1.0, label="first Fresnel zone")
    ax.plot(d, line + r1, "b--", lw=1.0)
    ax.plot(d, line - 0.6 * r1, "b:", lw=1.0, label="60 % of the zone")
    worst_z = ends[0, 2] + result.t * (ends[1, 2] - ends[0, 2]) - result.clearance
    verdict = "clear" if result.clear_60 else "not clear"
    ax.plot([result.distance], [worst_z], "o", color="red", markeredgecolor="k",
            label=f"worst: {result.fraction:.2f} r1 at {result.distance:,.0f} (60 % {verdict})")
    ax.set_xlim(d[0], d[-1])
    ax.set_ylim(bottom=base)
    ax.set_xlabel("distance from the first antenna (m)")
    ax.set_ylabel("height (m)")
    freq = result.frequency
    ax.set_title(title or f"first Fresnel zone at {freq / 1e6:g} MHz", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, framealpha=0.9)
    return fig


def siting(terrain: HeightGrid, result, *, candidates=None, title: str | None = None, figsize=(11, 4.6)) -> Figure:
    """Observer siting: the chosen observers and their coverage on the map, and the covered-area curve.

    Parameters
    ----------
    terrain : HeightGrid
        The grid whose samples the siting covered.
    result : terrainvis.visibility.SitingResult
        :func:`terrainvis.site_observers`'s result.
    candidates : (K, 2) array_like, optional
        All the candidates' (x, y), drawn as small dots.
    title : str, optional

    The left panel darkens the samples no chosen observer sees and numbers the observers
    in the order chosen; the right one draws the share of the area covered after each
    choice (the curve), what each choice added (bars), and the run's upper bound on what
    the best k candidates could cover.
    """
    as_terrain(terrain)
    if not isinstance(terrain, HeightGrid):
        raise TypeError(f"terrain must be the HeightGrid the siting covered, got {describe(terrain)}")
    table = getattr(result, "table", None)
    if table is None or not {"x", "y", "gain_area", "covered_area"} <= set(table.columns):
        raise TypeError(f"result must be a SitingResult (terrainvis.site_observers), got {describe(result)}")
    covered = np.asarray(result.covered, dtype=bool)
    if covered.shape != terrain.shape:
        raise ValueError(f"result.covered must have the terrain's shape {terrain.shape}, got {covered.shape}")
    from matplotlib.patches import Patch

    fig = Figure(figsize=figsize, layout="constrained")
    ax, curve = fig.subplots(1, 2, width_ratios=(1.15, 1))
    _draw_terrain(ax, terrain, wireframe=False, title=title or "observer siting")
    valid = np.isfinite(terrain.z)
    dark = np.zeros(terrain.shape + (4,))
    dark[valid & ~covered] = (0.05, 0.05, 0.15, 0.6)
    ax.imshow(dark, origin="lower", extent=terrain.extent, interpolation="nearest")
    if candidates is not None:
        c = as_points(candidates, "candidates", 2)
        ax.plot(c[:, 0], c[:, 1], linestyle="none", marker=".", markersize=2.5, color="0.85", alpha=0.8)
    share = table["covered_area"].to_numpy() / result.total_area
    for n, (x, y) in enumerate(table[["x", "y"]].to_numpy(), 1):
        ax.plot([x], [y], marker="o", markersize=11, color="red", markeredgecolor="k", markeredgewidth=0.6)
        ax.annotate(str(n), (x, y), ha="center", va="center", fontsize=6.5, color="white", fontweight="bold")
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], linestyle="none", marker="o", markersize=9, color="red", markeredgecolor="k",
                      label="chosen observers, numbered in order"),
               Patch(color=(0.05, 0.05, 0.15, 0.8), label=f"seen by none of them ({100 * (1 - share[-1]):.1f} %)")]
    fig.legend(handles=handles, loc="outside lower left", ncols=2, fontsize=8, frameon=False)
    k = np.arange(len(share) + 1)
    curve.bar(k[1:], 100 * table["gain_area"].to_numpy() / result.total_area, color="0.75", label="added by each")
    curve.plot(k, 100 * np.r_[0.0, share], marker="o", color="C3", label="covered")
    curve.axhline(100 * result.bound / result.total_area, color="k", linestyle="--", linewidth=0.8,
                  label=f"at most, with {len(share)} (bound)")
    curve.set_xlabel("observers chosen")
    curve.set_ylabel("share of the area (%)")
    curve.set_ylim(0, 105)
    from matplotlib.ticker import MaxNLocator

    curve.xaxis.set_major_locator(MaxNLocator(integer=True))
    curve.legend(loc="center right", fontsize=8)
    curve.set_title("covered area after each choice", fontsize=9)
    return fig


def observer_network(terrain: HeightGrid, network, *, frequency=None, title: str | None = None,
                     figsize=(6.5, 6)) -> Figure:
    """The intervisibility network drawn over the terrain, optionally over the visibility frequency.

    Parameters
    ----------
    terrain : HeightGrid
    network : pandas.DataFrame
        :func:`terrainvis.intervisibility_network`'s result (columns ``i``, ``j``,
        ``x_i``, ``y_i``, ``x_j``, ``y_j``, ``clearance``, ``visible``).
    frequency : (rows, cols) array_like of float, optional
        The share of the observers that see each sample (``ObserverSets.frequency()``),
        drawn in colour (NaN left clear).
    title : str, optional

    Pairs that see each other are joined by a line coloured by the clearance of their
    sight line; blocked pairs are not drawn (the legend counts them).
    """
    as_terrain(terrain)
    if not isinstance(terrain, HeightGrid):
        raise TypeError(f"terrain must be a HeightGrid, got {describe(terrain)}")
    needed = {"i", "j", "x_i", "y_i", "x_j", "y_j", "clearance", "visible"}
    if not isinstance(network, pd.DataFrame) or not needed <= set(network.columns):
        raise TypeError(f"network must be the DataFrame of terrainvis.intervisibility_network, got {describe(network)}")
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.add_subplot()
    _draw_terrain(ax, terrain, wireframe=False, title=title or "intervisibility network")
    if frequency is not None:
        f = np.asarray(frequency, dtype=np.float64)
        if f.shape != terrain.shape:
            raise ValueError(f"frequency must have the terrain's shape {terrain.shape}, got {f.shape}")
        image = ax.imshow(np.ma.masked_invalid(f), origin="lower", extent=terrain.extent, interpolation="nearest",
                          cmap="magma", vmin=0.0, vmax=max(float(np.nanmax(f)) if np.isfinite(f).any() else 1.0, 1e-3),
                          alpha=0.6)
        fig.colorbar(image, ax=ax, shrink=0.8, location="bottom", label="share of the observers that see the sample")
    seen = network[network["visible"].to_numpy(dtype=bool)]
    segments = np.stack([seen[["x_i", "y_i"]].to_numpy(), seen[["x_j", "y_j"]].to_numpy()], axis=1)
    clearance = np.minimum(seen["clearance"].to_numpy(dtype=np.float64), np.finfo(np.float64).max)
    lines = LineCollection(segments.reshape(-1, 2, 2), array=clearance, cmap="viridis", linewidths=1.4)
    ax.add_collection(lines)
    if len(seen):
        fig.colorbar(lines, ax=ax, shrink=0.8, label="clearance of the sight line")
    ends = pd.concat([network[["i", "x_i", "y_i"]].set_axis(["n", "x", "y"], axis=1),
                      network[["j", "x_j", "y_j"]].set_axis(["n", "x", "y"], axis=1)]).drop_duplicates("n")
    ax.plot(ends["x"], ends["y"], linestyle="none", marker="o", markersize=5, color="cyan", markeredgecolor="k",
            markeredgewidth=0.5)
    handles = [Line2D([], [], color="C2", label=f"see each other ({len(seen):,} of {len(network):,} pairs)"),
               Line2D([], [], linestyle="none", marker="o", color="cyan", markeredgecolor="k",
                      label=f"{len(ends):,} observers")]
    fig.legend(handles=handles, loc="outside upper center", ncols=2, fontsize=8, frameon=False)
    return fig
