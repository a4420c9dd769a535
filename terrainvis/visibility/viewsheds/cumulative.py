"""Cumulative viewsheds: how many of K observers see each sample of a grid.

:func:`cumulative_viewshed` adds up K exact viewsheds (:func:`terrainvis.viewshed`, the
grid engine's sweep on a HeightGrid), one per observer, into a count raster: ``count[r, c]``
observers see the target above sample (r, c); ``count > 0`` is the area seen by at least
one of them. Every count is exact because every viewshed is: the sum is of integers, so the
result does not depend on the order in which the viewsheds finish or on where they run.

The observers are cut into chunks; each chunk is one unit of
:func:`terrainvis.core.runner.run_units`, which runs the units in this process, on a local
process pool or on a dask cluster, and stops them all on Ctrl-C. A unit returns the counts
of its chunk and the caller adds them up as units finish, so memory stays at one count
raster per running unit whatever K is. The run (the checks, the chunks, the units) is
:mod:`terrainvis.visibility.viewsheds.many`, which observer sets and siting share.

Costs: one viewshed per observer (:func:`terrainvis.viewshed`; docs/user-guide.md, "Many
observers", gives the measured figures), plus per unit the transfer of the terrain to the worker
(a pickle of the grid; on dask the grid is scattered once and shared by the units). A
worker keeps the last terrain it was sent, with its caches (the pyramid of the exact
walks, the sweep's bounds), for the units of the same call.
"""

from __future__ import annotations

import numpy as np

from .many import count_dtype, keep_terrain, prepare, run_chunks, sight_of_many
from ..predicate import EARTH_RADIUS
from .sweep import viewshed

__all__ = ["cumulative_viewshed"]


def cumulative_viewshed(
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
) -> np.ndarray:
    """How many observers see each sample of a grid (a cumulative viewshed).

    Parameters
    ----------
    terrain : HeightGrid or TIN
        The surface under test, as in :func:`terrainvis.viewshed` (NaN samples of a
        HeightGrid are nodata: their triangles are absent and do not block).
    observers : (K, 2) or (K, 3) array_like of float
        World coordinates (x, y) of the K >= 1 observers, each inside the footprint and
        not on nodata; or their eyes (x, y, z), and then ``observer_height`` is not used.
    observer_height : float or (K,) array_like of float
        Height (>= 0, z units) of each eye above the surface: one for all, or one per
        observer (towers of different heights).
    target_height : float
        Height (>= 0) of every target above the surface.
    max_distance : float, optional
        Each observer sees only the samples within this horizontal distance.
    at : HeightGrid, optional
        The grid whose samples are the targets, as in :func:`terrainvis.viewshed`
        (required for a TIN).
    engine : {"auto", "grid", "embree"}
        As in :func:`terrainvis.viewshed` ("auto": the exact grid engine on a HeightGrid).
    curvature : float, default 0.0
        Earth curvature and refraction, GDAL's ``-cc`` coefficient (0 flat earth, 1
        geometric, 0.85714 standard refraction).
    earth_radius : float, default 6378137.0
        Radius of the earth in the terrain's x/y units.
    azimuth, vertical, min_distance : optional
        A field of view, the same for every observer, as in :func:`terrainvis.viewshed`:
        each observer counts only the samples inside its field (``azimuth`` (start, end)
        degrees clockwise from north, ``vertical`` (low, high) elevation angles in degrees,
        ``min_distance`` beside ``max_distance``); samples outside it get nothing from
        that observer.
    sight : Sight, optional
        The options above but ``at`` as one value (:class:`~terrainvis.visibility.Sight`),
        instead of the keywords (a keyword set to other than its default beside it is a
        TypeError); ``observer_height`` may still be a (K,) array, one height per observer,
        which replaces the Sight's.
    workers : int, optional
        Local worker processes. By default (and with 1) the observers' viewsheds run in
        this process: on a HeightGrid, one viewshed per numba thread at a time, each
        on one core, which on two cores beats one process per CPU
        (docs/user-guide.md#many-observers has the figures). ``workers=N`` runs them on
        N processes of one core each. Workers are started with ``spawn``, which imports the caller's
        ``__main__`` again: in a script, call this under ``if __name__ == "__main__":``.
    client : dask.distributed.Client, optional
        Run on this dask cluster instead (the terrain is scattered to it once).
    progress : bool, default False
        Show a progress bar on stderr, counting observers.

    Returns
    -------
    (rows, cols) uint16, or uint32 when K > 65535
        ``out[r, c]``: how many observers see the target above sample (r, c) of ``at``
        (or of the terrain), each by :func:`terrainvis.viewshed` with the same options.
        ``out > 0`` is the area seen by at least one observer. Nodata samples are 0, and
        an observer adds nothing outside its field of view (``azimuth``, ``vertical``,
        ``min_distance``, ``max_distance``; its own nearest sample excepted, as in
        :func:`terrainvis.viewshed`).

    Raises
    ------
    OutsideFootprintError
        When an observer is outside the footprint or on nodata (the message names the
        first such row of ``observers`` and how many there are).
    ValueError, TypeError
        On invalid arguments (the message names the argument).
    terrainvis.core.runner.Interrupted
        On Ctrl-C or SIGTERM (the workers are stopped first).

    Notes
    -----
    The observers are cut into chunks of about K / (32 workers or threads) observers, each chunk one
    unit of :func:`terrainvis.core.runner.run_units`; the counts of a chunk are added to the
    total as the unit finishes. The sum of integers does not depend on the order, so any
    ``workers`` or cluster gives the same raster, bit for bit.

    Examples
    --------
    A 5 m wall along x = 2: two observers on either side each see their own side and the
    wall's crest; the crest is seen by both:

    >>> from terrainvis import HeightGrid
    >>> z = np.zeros((3, 5))
    >>> z[:, 2] = 5.0
    >>> cumulative_viewshed(HeightGrid(z), [[0.0, 1.0], [4.0, 1.0]], observer_height=1.0, workers=1)
    array([[1, 1, 2, 1, 1],
           [1, 1, 2, 1, 1],
           [1, 1, 2, 1, 1]], dtype=uint16)
    """
    s, each = sight_of_many(sight, observer_height, {
        "target_height": target_height, "max_distance": max_distance, "engine": engine, "curvature": curvature,
        "earth_radius": earth_radius, "azimuth": azimuth, "vertical": vertical, "min_distance": min_distance,
    })
    run = prepare(terrain, observers, each, s, at, workers=workers, client=client, progress=progress,
                  name="observers")
    k = run.obs.shape[0]
    total = np.zeros((terrain if at is None else at).shape, dtype=count_dtype(k))

    def add(key, counts):
        np.add(total, counts, out=total, casting="unsafe")  # counts <= K fit the total's dtype

    run_chunks(run, _unit, add, desc="cumulative viewshed")
    return total


def _unit(terrain, at, token: str, observers: np.ndarray, heights: np.ndarray, sight) -> np.ndarray:
    """The counts of one chunk of observers: the sum of their viewsheds."""
    terrain, at = keep_terrain(token, terrain, at)
    shape = (terrain if at is None else at).shape
    counts = np.zeros(shape, dtype=count_dtype(observers.shape[0]))
    for i in range(observers.shape[0]):
        counts += viewshed(terrain, observers[i], sight=sight.with_observer_height(heights[i]), at=at)
    return counts


