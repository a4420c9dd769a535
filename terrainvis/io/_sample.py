"""Real DEMs that ship with a dependency, so they need no download."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np

from ..core._georef import metres_per_degree
from ..core.synthetic import BUNDLED
from ..core.terrain import HeightGrid
from ._npz import _read_npz

_SAMPLES = {"jacksboro": "jacksboro_fault_dem.npz"}


def _matplotlib_sample(filename: str) -> Path:
    """Path of a file in matplotlib's sample data, found without importing matplotlib."""
    import importlib.util

    spec = importlib.util.find_spec("matplotlib")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("sample_dem needs matplotlib (a core dependency of terrainvis): pip install matplotlib")
    for root in spec.submodule_search_locations:
        path = Path(root) / "mpl-data" / "sample_data" / filename
        if path.exists():
            return path
    raise FileNotFoundError(f"matplotlib's sample data has no {filename!r} (looked in {list(spec.submodule_search_locations)})")


def sample_dem(name: str = "jacksboro") -> HeightGrid:
    """A real DEM that ships with matplotlib, so it needs no download.

    Parameters
    ----------
    name : {"jacksboro"}
        ``"jacksboro"``: the USGS 3-arc-second DEM of the Jacksboro fault, Tennessee
        (344 x 403 samples, 236-1076 m), from matplotlib's sample data. Its lon/lat cells
        are converted to metres at the centre latitude: 74.57 m (east-west) x 92.47 m
        (north-south).

    Returns
    -------
    HeightGrid
        Rows flipped so that y grows northwards, origin (0, 0) in local metres; ``attrs``
        hold the CRS (``"EPSG:4326 (assumed; lon/lat degrees)"``) and ``xy_to_native``,
        the map back to lon/lat.

    Examples
    --------
    >>> g = sample_dem()
    >>> g.shape, round(g.dx, 2), round(g.dy, 2)
    ((344, 403), 74.57, 92.47)
    """
    if name not in _SAMPLES:
        raise ValueError(f"name must be one of {list(_SAMPLES)}, got {name!r}")
    with np.load(_matplotlib_sample(_SAMPLES[name]), allow_pickle=False) as data:
        z = np.asarray(data["elevation"], dtype=np.float64)
        dx_deg = float(data["dx"])
        dy_deg = float(data["dy"])
        # In this file 'ymin' holds the northern edge and 'ymax' the southern one.
        lon_w = float(data["xmin"])
        lat_n = max(float(data["ymin"]), float(data["ymax"]))
        lat_c = 0.5 * (float(data["ymin"]) + float(data["ymax"]))
    rows = z.shape[0]
    m_lon, m_lat = metres_per_degree(lat_c)
    # local x = (lon - lon of the western sample centres) * m_lon, likewise y from the southern ones
    affine = (1.0 / m_lon, lon_w + 0.5 * dx_deg, 1.0 / m_lat, lat_n - dy_deg * (rows - 0.5))
    attrs = {
        "name": name,
        "source": "matplotlib sample data jacksboro_fault_dem.npz (USGS 3-arc-second DEM)",
        "crs": "EPSG:4326 (assumed; lon/lat degrees)",
        "geographic": True,
        "xy_to_native": affine,
    }
    return HeightGrid(z[::-1], dx=dx_deg * m_lon, dy=dy_deg * m_lat, attrs=attrs)


def _data_dir() -> Path:
    # terrainvis/data/ holds the bundled terrains (the package terrainvis.data).
    return Path(str(resources.files("terrainvis.data")))


#: Real DEMs shipped as GeoTIFFs in ``terrainvis/data`` (read with rasterio), by name.
BUNDLED_DEMS = {"cumberland": "cumberland.tif"}


def bundled_terrain(name: str) -> HeightGrid:
    """A terrain that ships with terrainvis: one of the five frozen 120x120 synthetic
    terrains (``terrainvis/data/<name>.npz``) or the real DEM ``"cumberland"``.

    ``"cumberland"`` is a projected GeoTIFF as GIS users hold one (``cumberland.tif``,
    337 x 321 samples at 90 m in NAD83 / UTM zone 16N, EPSG:26916): the USGS DEM of the
    Jacksboro fault, Tennessee, from matplotlib's sample data, resampled (see
    ``terrainvis/data/README.md``). It is read as :func:`terrainvis.load_dem` reads a GeoTIFF, which needs
    rasterio (``pip install "terrainvis[geo]"``); the user guide's GIS examples run on it.

    Parameters
    ----------
    name : str
        One of :data:`BUNDLED` or ``"cumberland"``.

    Returns
    -------
    HeightGrid
        The synthetic ones are read with the same reader as
        :func:`terrainvis.io.load_terrain` (the files are in the terrainvis ``.npz``
        format); their ``attrs`` are ``name``, ``seed``, ``synthetic`` and ``bundled``.
        ``"cumberland"`` carries its CRS and transform as :func:`terrainvis.load_dem` reads them.

    Examples
    --------
    >>> g = bundled_terrain("hills")
    >>> g.shape, g.dx, g.attrs["name"]
    ((120, 120), 30.0, 'hills')
    """
    if isinstance(name, str) and name in BUNDLED_DEMS:
        from ._geotiff import _read_tif  # load_dem's reader (terrainvis.io imports this module)

        grid = _read_tif(_data_dir() / BUNDLED_DEMS[name], crs=None, band=None)
        grid.attrs["name"] = name
        return grid
    if not isinstance(name, str) or name not in BUNDLED:
        raise ValueError(f"name must be one of the bundled terrains {[*BUNDLED, *BUNDLED_DEMS]}, got {name!r}")
    grid = _read_npz(_data_dir() / f"{name}.npz")
    if not isinstance(grid, HeightGrid):
        raise ValueError(f"terrainvis/data/{name}.npz must hold a grid, got a {type(grid).__name__}; reinstall terrainvis")
    return grid
