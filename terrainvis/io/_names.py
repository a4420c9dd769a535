"""A terrain by name or path, as ``compare`` and every command take it: a bundled name (the
five synthetic terrains, the ``cumberland`` GeoTIFF), ``jacksboro``, a DEM file.

Kept apart from the experiment so that a command that reads one terrain (``viewshed``,
``los``, ``info``) imports the readers and nothing of the experiment.
"""

from __future__ import annotations

import warnings
from pathlib import Path

from ..core.terrain import HeightGrid
from ..core.validate import describe, file_label

__all__ = ["JACKSBORO_WINDOW", "resolve_one"]

#: Rows and columns of the 344x403 Jacksboro DEM used as the "jacksboro" terrain: its
#: central 120x120 window at the native 74.57 m x 92.47 m cells (8.9 km x 11.0 km). A
#: window keeps the real sampling; resampling the whole DEM to 120x120 would smooth it.
JACKSBORO_WINDOW = ((112, 232), (141, 261))


def resolve_one(name, t, i):
    """``(name, HeightGrid)`` for one entry of the ``terrains`` argument (``name`` None: derived).

    A path that names an existing file is read, even when it is also a bundled name (a
    local ``hills`` wins over the bundled terrain, with a warning saying so); a file
    without a suffix is read by its content (``.npz``, ``.npy``, ``.tif`` or ``.asc``).
    """
    from ..core.synthetic import BUNDLED
    from ..io import bundled_terrain
    from ._sample import BUNDLED_DEMS

    if isinstance(t, HeightGrid):
        return name or t.attrs.get("name") or f"terrain{i}", t
    if not isinstance(t, (str, Path)):
        raise TypeError(f"terrains must hold HeightGrids, names or paths, got {describe(t)}")
    text = str(t)
    known = [*BUNDLED, *BUNDLED_DEMS, "jacksboro"]
    path = Path(text)
    if path.is_file():
        shadows = text in known
        try:
            grid = _load_local(path)
        except ValueError as exc:
            if not shadows:
                raise
            raise ValueError(f"{exc} (a local file wins over the bundled terrain {text!r}: rename or move it to "
                             "use the bundled one)") from None
        if shadows:
            warnings.warn(
                f"terrain {text!r}: read the local file {str(path.resolve())!r}, not the bundled terrain of that "
                "name (a local file always wins; rename or move it to use the bundled one)",
                UserWarning, stacklevel=3,
            )
        return name or file_label(path.stem if path.suffix else path.name), grid
    if text in BUNDLED or text in BUNDLED_DEMS:
        return name or text, bundled_terrain(text)
    if text == "jacksboro":
        return name or text, _jacksboro()
    if path.suffix:
        raise ValueError(f"terrain {text!r} is neither a bundled terrain {known} nor an existing file")
    raise ValueError(f"terrain must be a bundled terrain {known}, a DEM file or a HeightGrid, got {text!r}")


#: How a DEM file without a suffix is recognised: its first bytes.
_MAGIC = ((b"PK\x03\x04", ".npz"), (b"\x93NUMPY", ".npy"), (b"II*\x00", ".tif"), (b"MM\x00*", ".tif"),
          (b"II+\x00", ".tif"), (b"MM\x00+", ".tif"))


def _load_local(path: Path) -> HeightGrid:
    """A DEM file; one without a suffix is read by its content, through a link that has the suffix."""
    import os
    import shutil
    import tempfile

    from ..io import load_dem

    if path.suffix:
        return load_dem(path)
    with open(path, "rb") as fh:
        head = fh.read(512)
    suffix = next((s for magic, s in _MAGIC if head.startswith(magic)), None)
    if suffix is None and head.lstrip().lower().startswith((b"ncols", b"nrows", b"xllc", b"yllc")):
        suffix = ".asc"
    if suffix is None:
        raise ValueError(
            f"terrain {str(path)!r} is a file without a suffix whose content is not a DEM terrainvis reads "
            "(.npz, .npy, .tif, .asc); give it its suffix"
        )
    with tempfile.TemporaryDirectory(prefix="terrainvis-") as tmp:
        link = Path(tmp) / (path.name + suffix)
        companions = [(path.with_name(path.name + ".prj"), link.with_suffix(".prj"))] if suffix == ".asc" else []
        for src, dst in [(path, link)] + [c for c in companions if c[0].exists()]:
            try:
                os.symlink(src.resolve(), dst)
            except OSError:  # no symlinks here (Windows without the privilege): a copy
                shutil.copyfile(src, dst)
        try:
            grid = load_dem(link)
        except ValueError as exc:
            raise ValueError(f"terrain {str(path)!r} (read as {suffix} by its content): {exc}") from None
    grid.attrs["path"] = str(path)
    return grid


def _jacksboro() -> HeightGrid:
    from ..io import sample_dem

    (r0, r1), (c0, c1) = JACKSBORO_WINDOW
    grid = sample_dem("jacksboro").crop(rows=(r0, r1), cols=(c0, c1))
    grid.attrs["name"] = "jacksboro"
    return grid


def heights_dtype(t):
    """The dtype of the heights the grid read for the terrain argument ``t`` will hold
    (:attr:`terrainvis.HeightGrid.heights`), from the file's header: float32 for a GeoTIFF
    band the reader keeps as float32 (:func:`terrainvis.io._geotiff.held_dtype`), float64
    for any other file or name, or when it cannot tell (the read itself reports why). A
    command that loads its kernels beside the read loads those of this dtype."""
    import numpy as np

    from ._sample import BUNDLED_DEMS, _data_dir

    text = str(t)
    path = Path(text)
    if not path.is_file() and text in BUNDLED_DEMS:
        path = _data_dir() / BUNDLED_DEMS[text]
    if path.is_file() and path.suffix.lower() in (".tif", ".tiff"):
        from ._geotiff import held_dtype

        return held_dtype(path)
    return np.dtype(np.float64)
