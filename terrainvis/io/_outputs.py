"""Figures and tables written as terrainvis writes every file: atomically, marked as its own."""

from __future__ import annotations

from pathlib import Path

from ..core.fileio import atomic_path

#: The PNG ``Software`` text of every figure terrainvis writes: how ``compare --overwrite``
#: recognises a figure as its own.
FIGURE_SOFTWARE = "terrainvis"


def figure_metadata() -> dict:
    """The PNG text that marks a figure as written by terrainvis (``savefig(..., metadata=...)``)."""
    from .. import __version__

    return {"Software": f"{FIGURE_SOFTWARE} {__version__}"}


def save_figure(fig, path, *, dpi: int = 110) -> Path:
    """Save a matplotlib figure as a PNG, atomically, with terrainvis's mark in its text.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : str or Path
        A ``.png`` file.
    dpi : int
        Resolution.

    Returns
    -------
    Path
    """
    p = Path(path)
    if p.suffix.lower() != ".png":
        raise ValueError(f"path must end in .png, got {p.name!r}")
    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png", metadata=figure_metadata())
    return p


def write_csv(table, path, *, float_format: str | None = None) -> Path:
    """Write a pandas DataFrame as a CSV file (no index), atomically.

    Parameters
    ----------
    table : pandas.DataFrame
    path : str or Path
    float_format : str, optional
        printf-style format of floats (``"%.6f"``); default: as many digits as round-trip.

    Returns
    -------
    Path
    """
    p = Path(path)
    with atomic_path(p) as tmp:
        table.to_csv(tmp, index=False, float_format=float_format)
    return p
