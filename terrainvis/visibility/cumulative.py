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
raster per running unit whatever K is.

Costs: one viewshed per observer (:func:`terrainvis.viewshed`; docs/user-guide.md, "Many
observers", gives the measured figures), plus per unit the transfer of the terrain to the worker
(a pickle of the grid; on dask the grid is scattered once and shared by the units). A
worker keeps the last terrain it was sent, with its caches (the pyramid of the exact
walks, the sweep's bounds), for the units of the same call.
"""

from __future__ import annotations

import math
import os
import sys
import uuid

import numpy as np

from ..core.validate import as_float_array, as_nonnegative_finite, describe
from ..errors import OutsideFootprintError
from ..core.terrain import TIN, HeightGrid, as_terrain
from .engines import choose
from .field_of_view import field_of_view
from .predicate import EARTH_RADIUS, _height_above, curvature_coefficient
from .sweep import _check_overlap, _surface_at, viewshed

__all__ = ["cumulative_viewshed"]

#: Units per worker: small enough chunks that the workers finish together (the last unit
#: of a worker is at most 1/32 of its share) and the progress bar moves; large enough that
#: sending the terrain with each unit costs little next to the unit's viewsheds.
_UNITS_PER_WORKER = 32

#: The terrain (and ``at``) of the last call a worker process served: ``{token: (terrain, at)}``.
_WORKER_TERRAIN: dict = {}


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
    run = _prepare(terrain, observers, observer_height,
                   (target_height, max_distance, at, engine, curvature, earth_radius), workers, client, progress,
                   "observers", fov=(azimuth, vertical, min_distance))
    k = run["obs"].shape[0]
    total = np.zeros((terrain if at is None else at).shape, dtype=_count_dtype(k))

    def add(key, counts):
        np.add(total, counts, out=total, casting="unsafe")  # counts <= K fit the total's dtype

    _run_chunks(run, _unit, add, desc="cumulative viewshed")
    return total


# ----------------------------------------------------------------- validation
def _as_observers(observers, name: str = "observers") -> np.ndarray:
    """``observers`` as a (K, 2) or (K, 3) float64 array, K >= 1, finite (``name``: the argument, for messages)."""
    arr = as_float_array(observers, name)
    if arr.ndim != 2:
        hint = " (one observer: [[x, y]])" if arr.ndim == 1 else ""
        raise ValueError(
            f"{name} must be a 2-D array of shape (K, 2) (x, y) or (K, 3) (eyes x, y, z), got {arr.ndim}-D "
            f"with shape {arr.shape}{hint}"
        )
    if arr.shape[1] not in (2, 3):
        raise ValueError(f"{name} must have shape (K, 2) (x, y) or (K, 3) (eyes x, y, z), got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"{name} must hold at least one observer (K >= 1), got shape " f"{arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if bad.size:
        raise ValueError(
            f"{name} must be finite, but {bad.size} row(s) hold NaN or inf (first {name}[{int(bad[0])}] = "
            f"{arr[bad[0]].tolist()})"
        )
    return np.array(arr, dtype=np.float64, order="C")  # our own copy: the caller's array is never held


def _as_heights(observer_height, k: int, terrain) -> np.ndarray:
    """One eye height per observer: a scalar repeated, or a (K,) array; finite and >= 0."""
    if np.ndim(observer_height) == 0:
        return np.full(k, _height_above(observer_height, "observer_height", terrain))
    h = as_float_array(observer_height, "observer_height")
    if h.ndim != 1 or h.shape[0] != k:
        raise ValueError(
            f"observer_height must be one number or one per observer (shape ({k},)), got shape {h.shape}"
        )
    bad = np.flatnonzero(~(np.isfinite(h) & (h >= 0)))
    if bad.size:
        raise ValueError(
            f"observer_height must be finite and >= 0 (z units), but {bad.size} value(s) are not "
            f"(first observer_height[{int(bad[0])}] = {h[bad[0]]!r})"
        )
    if h.size:
        _height_above(float(h.max()), "observer_height", terrain)  # the largest: within what float64 resolves
    return np.array(h, dtype=np.float64)


def _options(terrain, target_height, max_distance, at, engine, curvature, earth_radius) -> dict:
    """The viewshed options of every unit, validated here once (the units run them as given)."""
    kc = curvature_coefficient(curvature, earth_radius)
    choose(engine, terrain, kc)
    _height_above(target_height, "target_height", terrain)
    if max_distance is not None:
        as_nonnegative_finite(max_distance, "max_distance", "xy units")
    if at is not None and not isinstance(at, HeightGrid):
        raise TypeError(f"at must be a terrainvis.HeightGrid (the grid of target samples) or None, got {describe(at)}")
    if at is None and isinstance(terrain, TIN):
        raise ValueError(
            "at is required for a TIN: pass the HeightGrid whose samples are the targets "
            "(normally the original terrain the TIN simplifies)"
        )
    if at is not None:
        _check_overlap(terrain, at)
    dmax = None if max_distance is None else float(max_distance)
    return {"target_height": float(target_height), "max_distance": dmax, "engine": engine,
            "curvature": float(curvature), "earth_radius": float(earth_radius)}


def _check_inside(terrain, obs: np.ndarray, name: str = "observers") -> None:
    """Every observer stands on the surface (by the viewshed's own rule, so no unit fails later)."""
    outside = [i for i in range(obs.shape[0]) if not math.isfinite(_surface_at(terrain, obs[i, 0], obs[i, 1]))]
    if outside:
        i = outside[0]
        raise OutsideFootprintError(
            f"{name}[{i}] = ({float(obs[i, 0])!r}, {float(obs[i, 1])!r}) is outside the terrain's footprint {terrain.extent} "
            f"or on nodata (a triangle touching a NaN sample); {len(outside)} of {obs.shape[0]} {name} are"
        )


def _count_dtype(k: int):
    """uint16 while every count fits (K <= 65535), else uint32."""
    return np.uint16 if k <= np.iinfo(np.uint16).max else np.uint32


# ----------------------------------------------------------------- units
def _n_slots(workers: int | None, client) -> int:
    """How many units can run at once: the cluster's threads, or the local workers."""
    if client is not None:
        try:
            return max(1, int(sum(client.nthreads().values())))
        except Exception:  # a client without nthreads() (or a cluster that is still starting)
            return 1
    return (os.cpu_count() or 1) if workers is None else workers


def _local_threads(terrain, engine: str, workers: int, client) -> int:
    """How many units run at once in this process (``workers=1``, no client): numba's threads
    for the grid engine, whose sweep then runs on one core per viewshed; else 1.

    Two viewsheds at a time, one per core, beat one viewshed's sweep spread over both: on a
    million samples that sweep gained little over one core, and its pair walks start a
    parallel loop for a few segments (docs/user-guide.md, "Many observers"). Embree and registered engines keep
    their own threads, so their units run one after the other.
    """
    if client is not None or workers != 1 or not isinstance(terrain, HeightGrid) or engine not in ("auto", "grid"):
        return 1
    import numba

    return max(1, numba.get_num_threads())


def _chunks(k: int, slots: int) -> list[tuple[int, int]]:
    """``[start, end)`` of each chunk of observers: about ``_UNITS_PER_WORKER`` units per slot."""
    n = min(k, _UNITS_PER_WORKER * max(1, slots))
    edges = np.linspace(0, k, n + 1).round().astype(int)
    return [(int(s), int(e)) for s, e in zip(edges[:-1], edges[1:]) if e > s]


def _unit(terrain, at, token: str, observers: np.ndarray, heights: np.ndarray, options: dict) -> np.ndarray:
    """The counts of one chunk of observers: the sum of their viewsheds."""
    terrain, at = _keep_terrain(token, terrain, at)
    shape = (terrain if at is None else at).shape
    counts = np.zeros(shape, dtype=_count_dtype(observers.shape[0]))
    for i in range(observers.shape[0]):
        counts += viewshed(terrain, observers[i], observer_height=heights[i], at=at, **options)
    return counts


def _keep_terrain(token: str, terrain, at):
    """The terrain this process already holds for the call ``token`` (with its caches), else
    ``terrain``, kept for the call's next units. In the calling process it is the same object."""
    held = _WORKER_TERRAIN.get(token)
    if held is not None:
        return held
    _WORKER_TERRAIN.clear()  # one call at a time per worker: drop an earlier call's terrain
    _WORKER_TERRAIN[token] = (terrain, at)
    return terrain, at


# ----------------------------------------------------------------- the chunked run (shared with observer sets and siting)
def _prepare(terrain, observers, observer_height, options, workers, client, progress, name: str, *,
             fov=(None, None, None)) -> dict:
    """Validate the arguments of a run of one viewshed per observer (:func:`cumulative_viewshed`,
    :func:`terrainvis.observer_sets`, :func:`terrainvis.site_observers`).

    ``options`` is ``(target_height, max_distance, at, engine, curvature, earth_radius)``;
    ``name`` names the observers' argument in messages; ``fov`` is ``(azimuth, vertical,
    min_distance)``, each observer's field of view.
    """
    from ..core.runner import check_client, check_workers

    as_terrain(terrain)
    obs = _as_observers(observers, name)
    heights = _as_heights(observer_height, obs.shape[0], terrain)
    opts = _options(terrain, *options)
    limits = field_of_view(azimuth=fov[0], vertical=fov[1], min_distance=fov[2], max_distance=options[1])
    opts.update(azimuth=limits.azimuth, vertical=limits.vertical, min_distance=limits.min_distance)
    workers = check_workers(workers)
    client = check_client(client)
    _check_inside(terrain, obs, name)
    if not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"progress must be True or False, got {describe(progress)}")
    return {"terrain": terrain, "at": options[2], "obs": obs, "heights": heights, "options": opts,
            "workers": 1 if workers is None else workers, "client": client, "progress": bool(progress)}


def _run_chunks(run: dict, unit, on_result, *, align: int = 1, desc: str) -> None:
    """Run ``unit`` over chunks of the observers (starting on multiples of ``align``; each
    chunk one unit of :func:`terrainvis.core.runner.run_units`), showing a progress bar
    of observers (``desc``); ``on_result((start, end), result)`` as each unit finishes."""
    from ..core.runner import run_units

    k = run["obs"].shape[0]
    threads = _local_threads(run["terrain"], run["options"]["engine"], run["workers"], run["client"])
    token = uuid.uuid4().hex

    def task(s, e):
        return (s, e), (run["terrain"], run["at"], token, run["obs"][s:e], run["heights"][s:e], run["options"])

    # the first observers (one chunk of ``align``) here, before the bar: on a first run
    # they compile the kernels (terrainvis.core.compiling says so), and the bar's rate and
    # time left count the viewsheds only; the workers then load the kernels from the cache
    first = min(align, k)
    try:
        key, args = task(0, first)
        on_result(key, unit(*args))
        groups = _chunks(-(-(k - first) // align), max(_n_slots(run["workers"], run["client"]), threads))
        tasks = [task(first + s * align, min(first + e * align, k)) for s, e in groups]
        bar = _progress_bar(k, run["progress"], desc, done=first)
        try:
            def add(key, result):
                on_result(key, result)
                bar.update(key[1] - key[0])

            run_units(tasks, unit, on_result=add, workers=run["workers"], client=run["client"], threads=threads)
        finally:
            bar.close()
    finally:
        _WORKER_TERRAIN.pop(token, None)  # units that ran here held the terrain


def _progress_bar(k: int, show: bool, desc: str, done: int = 0):
    """A tqdm bar counting observers, ``done`` of them done already (disabled unless ``show``);
    into a file (a log), plain lines instead (:class:`terrainvis.core._progress.ProgressLines`)."""
    from tqdm.std import tqdm

    bar = tqdm
    if show:
        from ..core._progress import ProgressLines, in_kernel, on_a_terminal, progress_bar_class

        if not (on_a_terminal() or in_kernel()):
            return ProgressLines(k, desc, "observer", initial=done)
        bar = progress_bar_class()  # the notebook's bar in Jupyter
    return bar(total=k, initial=done, desc=desc, unit="observer", file=sys.stderr, disable=not show)
