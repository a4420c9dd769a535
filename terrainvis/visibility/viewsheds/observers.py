"""Many observers, beyond the counts: which observers see each sample, and which see each other.

:func:`observer_sets` keeps, for every sample of a grid, the set of the K observers that
see it, as K bits packed into ``ceil(K / 8)`` bytes per sample (:class:`ObserverSets`):
1,000 observers on a 1024² grid take 125 MiB, where a boolean raster per observer would
take 1,000 MiB. The viewsheds are those of :func:`terrainvis.cumulative_viewshed` (the
same exact :func:`terrainvis.viewshed` per observer, the same chunks of observers run by
:func:`terrainvis.core.runner.run_units` here, on local processes or on dask), so
``ObserverSets.count()`` is the cumulative viewshed, bit for bit.

:func:`intervisibility_network` answers the other question of a network of observers
(towers, lookouts): which pairs see each other, and by how much the sight line clears the
terrain between them, with the pair engine's exact minimum clearance
(:func:`terrainvis.min_clearance`).

The chunked run (:mod:`terrainvis.visibility.viewsheds.many`) is the cumulative
viewshed's, shared with :mod:`terrainvis.visibility.viewsheds.siting`, whose units keep each
candidate's viewshed as packed bits instead.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...core.memory import check_memory
from ...core.terrain import as_terrain
from ...core.validate import as_int
from ...errors import OutsideFootprintError
from .many import (
    as_heights,
    as_observers,
    check_on_surface,
    count_dtype,
    eyes,
    keep_terrain,
    prepare,
    run_chunks,
    sight_of_many,
)
from ..predicate import EARTH_RADIUS, clearance_tolerance, curvature_coefficient
from .sweep import viewshed

__all__ = ["ObserverSets", "observer_sets", "intervisibility_network"]

#: What an ObserverSets file says it is (its ``format`` entry), and the version of its layout.
_FORMAT = "terrainvis.observer_sets"
_VERSION = 1


class ObserverSets:
    """Which of K observers see each sample of a grid, as packed bits.

    Made by :func:`observer_sets`; read back with :meth:`load`.

    Attributes
    ----------
    bits : (rows, cols, ceil(K / 8)) uint8
        Observer ``i`` sees sample (r, c) when bit ``7 - i % 8`` of ``bits[r, c, i // 8]``
        is set: ``numpy.unpackbits(bits[r, c])[:K]`` is the membership of the observers
        (numpy's default, big-endian bit order). The unused bits of the last byte are 0.
    n_observers : int
        K.
    xs, ys : (cols,), (rows,) float64
        The coordinates of the grid's samples (the terrain's frame).
    valid : (rows, cols) bool
        The samples that are not nodata.
    observers : (K, 2) or (K, 3) float64
        The observers as given (x, y), or their eyes (x, y, z).
    settings : dict
        The options the viewsheds were computed with (observer heights aside).
    """

    def __init__(self, bits, n_observers: int, xs, ys, valid, observers, settings=None):
        self.bits = np.asarray(bits, dtype=np.uint8)
        self.n_observers = as_int(n_observers, "n_observers", minimum=1)
        self.xs = np.asarray(xs, dtype=np.float64)
        self.ys = np.asarray(ys, dtype=np.float64)
        self.valid = np.asarray(valid, dtype=bool)
        self.observers = np.asarray(observers, dtype=np.float64)
        self.settings = dict(settings or {})
        shape = (self.ys.size, self.xs.size, -(-self.n_observers // 8))
        if self.bits.shape != shape or self.valid.shape != shape[:2] or self.observers.shape[0] != self.n_observers:
            raise ValueError(f"bits must have shape {shape} (rows, cols, ceil(K / 8)) and valid {shape[:2]}, with "
                             f"{self.n_observers} observers; got bits {self.bits.shape}, valid {self.valid.shape}, "
                             f"observers {self.observers.shape}")

    def __repr__(self) -> str:
        rows, cols = self.shape
        return f"ObserverSets({self.n_observers:,} observers on {rows}x{cols} samples, {self.nbytes:,} bytes of bits)"

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the grid."""
        return self.bits.shape[:2]

    @property
    def nbytes(self) -> int:
        """Bytes held by the packed bits: rows x cols x ceil(K / 8)."""
        return int(self.bits.nbytes)

    # ------------------------------------------------------------------ rasters
    def count(self) -> np.ndarray:
        """How many observers see each sample: (rows, cols) uint16 (uint32 past 65,535 observers), 0 on nodata.

        The cumulative viewshed (:func:`terrainvis.cumulative_viewshed`) of the same observers
        and options, bit for bit.
        """
        total = np.zeros(self.shape, dtype=np.uint32)
        for b in range(self.bits.shape[2]):  # one byte plane at a time: no (rows, cols, K / 8) temporary
            total += np.bitwise_count(self.bits[:, :, b])
        return total.astype(count_dtype(self.n_observers))

    def frequency(self) -> np.ndarray:
        """The normalised visibility frequency: count / K, (rows, cols) float64 in [0, 1], NaN on nodata."""
        out = self.count() / float(self.n_observers)
        out[~self.valid] = np.nan
        return out

    def seen_by(self, i: int) -> np.ndarray:
        """Observer ``i``'s viewshed: (rows, cols) bool."""
        i = as_int(i, "i", minimum=0, maximum=self.n_observers - 1)
        return (self.bits[:, :, i >> 3] & np.uint8(1 << (7 - (i & 7)))) != 0

    # ------------------------------------------------------------------ queries
    def observers_at_sample(self, row: int, col: int) -> np.ndarray:
        """The indices (ascending, int64) of the observers that see sample (row, col)."""
        rows, cols = self.shape
        r = as_int(row, "row", minimum=-rows, maximum=rows - 1) % rows
        c = as_int(col, "col", minimum=-cols, maximum=cols - 1) % cols
        member = np.unpackbits(self.bits[r, c], count=self.n_observers)
        return np.flatnonzero(member).astype(np.int64)

    def observers_at(self, x: float, y: float) -> np.ndarray:
        """The indices (ascending, int64) of the observers that see the sample nearest (x, y).

        (x, y) is in the terrain's frame and must lie inside the grid's footprint
        ``[xs[0], xs[-1]] x [ys[0], ys[-1]]``.
        """
        r, c = self.sample_at(x, y)
        return self.observers_at_sample(r, c)

    def sample_at(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the sample nearest (x, y), inside the footprint."""
        x, y = float(x), float(y)
        if not (self.xs[0] <= x <= self.xs[-1] and self.ys[0] <= y <= self.ys[-1]):
            raise OutsideFootprintError(
                f"(x, y) must lie inside the grid's footprint x [{self.xs[0]:g}, {self.xs[-1]:g}], "
                f"y [{self.ys[0]:g}, {self.ys[-1]:g}], got ({x!r}, {y!r})")
        return _nearest(self.ys, y), _nearest(self.xs, x)

    # ------------------------------------------------------------------ files
    def save(self, path) -> Path:
        """Write to an ``.npz`` file (compressed), atomically; :meth:`load` reads it back."""
        from ...core.fileio import atomic_path

        p = Path(path)
        if p.suffix.lower() != ".npz":
            raise ValueError(f"path must end in .npz, got {p.name!r}")
        with atomic_path(p) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, format=np.array(_FORMAT), version=np.array(_VERSION), bits=self.bits,
                                n_observers=np.array(self.n_observers), xs=self.xs, ys=self.ys, valid=self.valid,
                                observers=self.observers, settings=np.array(json.dumps(self.settings)))
        return p

    @classmethod
    def load(cls, path) -> "ObserverSets":
        """Read a file written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as f:
            if "format" not in f.files or str(f["format"]) != _FORMAT:
                raise ValueError(f"{str(path)!r} is not an observer-sets file (written by ObserverSets.save)")
            if int(f["version"]) != _VERSION:
                raise ValueError(f"{str(path)!r} is an observer-sets file of version {int(f['version'])}; "
                                 f"this terrainvis reads version {_VERSION}")
            return cls(f["bits"], int(f["n_observers"]), f["xs"], f["ys"], f["valid"], f["observers"],
                       json.loads(str(f["settings"])))


def _nearest(axis: np.ndarray, v: float) -> int:
    """Index of the value of an increasing ``axis`` nearest ``v`` (the lower one on a tie)."""
    i = int(np.searchsorted(axis, v))
    if i == 0:
        return 0
    if i == axis.size:
        return axis.size - 1
    return i - 1 if v - axis[i - 1] <= axis[i] - v else i


# ----------------------------------------------------------------- observer sets
def observer_sets(
    terrain,
    observers,
    *,
    observer_height=1.7,
    target_height: float = 0.0,
    max_distance=None,
    at=None,
    engine: str = "auto",
    curvature: float = 0.0,
    earth_radius: float = EARTH_RADIUS,
    azimuth=None,
    vertical=None,
    min_distance=None,
    sight=None,
    workers: int | None = None,
    client=None,
    progress: bool = False,
) -> ObserverSets:
    """Which observers see each sample of a grid: the set of observers per sample, packed in bits.

    Parameters
    ----------
    terrain, observers, observer_height, target_height, max_distance, at, engine, curvature, earth_radius, sight, workers, client, progress
        As in :func:`terrainvis.cumulative_viewshed`.
    azimuth, vertical, min_distance : optional
        Each observer's field of view, as in :func:`terrainvis.cumulative_viewshed`: an
        observer is in no sample's set outside its field.

    Returns
    -------
    ObserverSets
        ``ceil(K / 8)`` bytes per sample. ``.count()`` equals
        :func:`terrainvis.cumulative_viewshed` with the same arguments, bit for bit;
        ``.seen_by(i)`` is observer i's :func:`terrainvis.viewshed`; ``.observers_at(x, y)``
        lists the observers that see the sample nearest (x, y); ``.frequency()`` is the
        normalised visibility frequency, count / K.

    Raises
    ------
    OutsideFootprintError, ValueError, TypeError, terrainvis.core.runner.Interrupted
        As :func:`terrainvis.cumulative_viewshed`.
    NotEnoughMemoryError
        When rows x cols x ceil(K / 8) bytes would not fit in the available memory.

    Notes
    -----
    The observers are cut into chunks of whole bytes (multiples of 8 observers), each
    chunk one unit that returns its bytes of every sample; the caller places them, so the
    result does not depend on where or in which order the units ran.

    Examples
    --------
    The wall of :func:`terrainvis.cumulative_viewshed`'s example: observer 0 sees the
    west side, observer 1 the east side, both see the crest:

    >>> from terrainvis import HeightGrid
    >>> z = np.zeros((3, 5))
    >>> z[:, 2] = 5.0
    >>> sets = observer_sets(HeightGrid(z), [[0.0, 1.0], [4.0, 1.0]], observer_height=1.0, workers=1)
    >>> sets.observers_at(0.0, 0.0).tolist(), sets.observers_at(2.0, 2.0).tolist(), sets.observers_at(4.0, 1.0).tolist()
    ([0], [0, 1], [1])
    >>> sets.count()[0].tolist(), sets.nbytes
    ([1, 1, 2, 1, 1], 15)
    """
    s, each = sight_of_many(sight, observer_height, {
        "target_height": target_height, "max_distance": max_distance, "engine": engine, "curvature": curvature,
        "earth_radius": earth_radius, "azimuth": azimuth, "vertical": vertical, "min_distance": min_distance,
    })
    run = prepare(terrain, observers, each, s, at, workers=workers, client=client, progress=progress,
                  name="observers")
    grid = terrain if at is None else at
    k = run.obs.shape[0]
    n_bytes = -(-k // 8)
    check_memory(grid.size * n_bytes * 1.1, f"the observer sets of {k:,} observers on {grid.shape[0]}x{grid.shape[1]} "
                                            f"samples ({grid.size * n_bytes:,} bytes of bits)")
    bits = np.zeros(grid.shape + (n_bytes,), dtype=np.uint8)

    def place(key, part):
        bits[:, :, key[0] // 8: key[0] // 8 + part.shape[2]] = part

    run_chunks(run, _sets_unit, place, align=8, desc="observer sets")
    settings = {name: v for name, v in s.keywords().items() if name != "observer_height"}
    settings["observer_height"] = _heights_setting(run.heights)
    valid = np.isfinite(grid.z)
    return ObserverSets(bits, k, grid.xs, grid.ys, valid, run.obs, settings)


def _heights_setting(heights: np.ndarray):
    """The observer heights for ``settings``: one number when all are equal, else the list."""
    return float(heights[0]) if np.all(heights == heights[0]) else heights.tolist()


def _sets_unit(terrain, at, token: str, observers: np.ndarray, heights: np.ndarray, sight) -> np.ndarray:
    """The bytes of one chunk of observers (its first observer on a byte boundary): (rows, cols, ceil(n / 8))."""
    terrain, at = keep_terrain(token, terrain, at)
    shape = (terrain if at is None else at).shape
    out = np.zeros(shape + (-(-observers.shape[0] // 8),), dtype=np.uint8)
    for i in range(observers.shape[0]):
        v = viewshed(terrain, observers[i], sight=sight.with_observer_height(heights[i]), at=at)
        out[:, :, i >> 3] |= v.view(np.uint8) << np.uint8(7 - (i & 7))
    return out


# ----------------------------------------------------------------- the network
def intervisibility_network(
    terrain,
    observers,
    *,
    observer_height=1.7,
    curvature: float = 0.0,
    earth_radius: float = EARTH_RADIUS,
):
    """Which observers see each other: every pair with its exact minimum clearance.

    The convention: the sight line of a pair runs from eye i to eye j, **both at their
    observer heights** (eye i at ``observer_height[i]`` above the surface, and the target
    at j is eye j, ``observer_height[j]`` above the surface: a link between two towers),
    so the pair is symmetric and each unordered pair appears once (i < j).

    Parameters
    ----------
    terrain : HeightGrid or TIN
        A HeightGrid must be free of nodata (the pair engine's rule; fill it first with
        ``HeightGrid.fill_nodata()``).
    observers : (K, 2) or (K, 3) array_like of float
        As in :func:`terrainvis.cumulative_viewshed`: positions (x, y), or eyes (x, y, z).
    observer_height : float or (K,) array_like of float
        Height (>= 0) of each eye above the surface (not used with (K, 3) eyes).
    curvature, earth_radius : float
        The earth model, as in :func:`terrainvis.min_clearance`.

    Returns
    -------
    pandas.DataFrame
        One row per pair i < j, K (K - 1) / 2 rows, ordered by i then j, with columns
        ``i``, ``j`` (indices of the observers), ``x_i``, ``y_i``, ``z_i``, ``x_j``,
        ``y_j``, ``z_j`` (the two eyes), ``distance`` (horizontal, x/y units),
        ``clearance`` (:func:`terrainvis.min_clearance` of the segment eye i -> eye j:
        the least height of the sight line above the surface between them, negative
        where the terrain blocks it; ``inf`` for two eyes closer than twice
        :func:`~terrainvis.visibility.trim_length`) and ``visible`` (the exact
        predicate's verdict, ``clearance >= -clearance_tolerance(terrain)``, that of
        :func:`terrainvis.line_of_sight` on the exact engines).

    Raises
    ------
    OutsideFootprintError
        When an observer is outside the footprint or on nodata.
    NodataError
        When the grid holds NaN.
    NotEnoughMemoryError
        When the K (K - 1) / 2 rows would not fit.

    Examples
    --------
    The wall of :func:`terrainvis.cumulative_viewshed`'s example: the two observers on
    the west side see each other; across the 5 m wall no pair of 1 m eyes does:

    >>> from terrainvis import HeightGrid
    >>> z = np.zeros((3, 5))
    >>> z[:, 2] = 5.0
    >>> net = intervisibility_network(HeightGrid(z), [[0.0, 0.0], [0.0, 2.0], [4.0, 1.0]], observer_height=1.0)
    >>> net[["i", "j", "distance", "clearance", "visible"]].to_string(index=False)
    ' i  j  distance  clearance  visible\\n 0  1  2.000000        1.0     True\\n 0  2  4.123106       -4.0    False\\n 1  2  4.123106       -4.0    False'
    """
    import pandas as pd

    from ..los import min_clearance

    as_terrain(terrain)
    obs = as_observers(observers, "observers")
    k = obs.shape[0]
    heights = as_heights(observer_height, k, terrain)
    curvature_coefficient(curvature, earth_radius)
    check_on_surface(terrain, obs, "observers")
    n_pairs = k * (k - 1) // 2
    check_memory(n_pairs * 8 * 16, f"the intervisibility network of {k:,} observers ({n_pairs:,} pairs)")
    e = eyes(terrain, obs, heights)
    i, j = np.triu_indices(k, 1)
    clearance = min_clearance(terrain, e[i], e[j], curvature=curvature, earth_radius=earth_radius)
    distance = np.hypot(e[j, 0] - e[i, 0], e[j, 1] - e[i, 1])
    return pd.DataFrame({
        "i": i.astype(np.int64), "j": j.astype(np.int64),
        "x_i": e[i, 0], "y_i": e[i, 1], "z_i": e[i, 2],
        "x_j": e[j, 0], "y_j": e[j, 1], "z_j": e[j, 2],
        "distance": distance, "clearance": clearance, "visible": clearance >= -clearance_tolerance(terrain),
    })

