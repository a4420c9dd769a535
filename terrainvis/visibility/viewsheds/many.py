"""The run of one viewshed per observer that :func:`terrainvis.cumulative_viewshed`,
:func:`terrainvis.observer_sets` and :func:`terrainvis.site_observers` share.

:func:`prepare` checks a call's arguments once (the observers, their eye heights, the
:class:`~terrainvis.visibility.Sight` on the terrain, ``at``, where the units run) into a
:class:`Run`; :func:`run_chunks` cuts the observers into chunks, each chunk one unit of
:func:`terrainvis.core.runner.run_units` (in this process, on a local process pool or on
dask), and hands each unit's result to the caller as it finishes. A unit gets the terrain,
``at``, the chunk's observers and heights and the Sight (which pickles whole); it keeps the
terrain it was sent for the call's next units (:func:`keep_terrain`).
"""

from __future__ import annotations

import math
import os
import sys
import uuid
from dataclasses import dataclass

import numpy as np

from ...core.terrain import HeightGrid, as_terrain
from ...core.validate import as_float_array, describe
from ...errors import OutsideFootprintError
from ..predicate import _height_above, target_grid
from ..sight import Sight, engine_on, sight_of
from .sweep import _surface_at

__all__ = ["Run", "sight_of_many", "prepare", "run_chunks", "keep_terrain", "as_observers", "as_heights",
           "check_on_surface", "count_dtype", "eyes"]

#: Units per worker: small enough chunks that the workers finish together (the last unit
#: of a worker is at most 1/32 of its share) and the progress bar moves; large enough that
#: sending the terrain with each unit costs little next to the unit's viewsheds.
_UNITS_PER_WORKER = 32

#: The terrain (and ``at``) of the last call a worker process served: ``{token: (terrain, at)}``.
_WORKER_TERRAIN: dict = {}


@dataclass(frozen=True)
class Run:
    """A checked run of one viewshed per observer (:func:`prepare`).

    ``obs`` (K, 2) or (K, 3) float64 and ``heights`` (K,) float64 are the observers and their
    eye heights; ``sight`` the Sight of every viewshed (its ``observer_height`` replaced by
    ``heights[i]`` for observer i); ``workers``, ``client`` and ``progress`` where and how the
    units run.
    """

    terrain: object
    at: object
    obs: np.ndarray
    heights: np.ndarray
    sight: Sight
    workers: int
    client: object
    progress: bool


def sight_of_many(sight, observer_height, keywords: dict):
    """The Sight of a call of many observers, and their heights given one per observer (else None).

    ``observer_height`` is one number (then a keyword of the Sight, as in
    :func:`~terrainvis.visibility.sight.sight_of`) or a (K,) array of heights, one per
    observer, which a Sight cannot hold: it is kept beside the Sight (with ``sight=`` too)
    and checked by :func:`prepare`. ``keywords`` are the Sight's other keywords.
    """
    if np.ndim(observer_height) == 0:
        return sight_of(sight, {"observer_height": observer_height, **keywords}), None
    return sight_of(sight, keywords), observer_height


def prepare(terrain, observers, each, sight: Sight, at, *, workers, client, progress, name: str) -> Run:
    """Check the arguments of a run of one viewshed per observer, once.

    ``each`` is the (K,) heights given one per observer, or None (the Sight's height for
    all); ``name`` names the observers' argument in messages.
    """
    from ...core.runner import check_client, check_workers

    as_terrain(terrain)
    obs = as_observers(observers, name)
    heights = as_heights(sight.observer_height if each is None else each, obs.shape[0], terrain)
    engine_on(terrain, sight)
    target_grid(terrain, at)
    workers = check_workers(workers)
    client = check_client(client)
    check_on_surface(terrain, obs, name)
    if not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"progress must be True or False, got {describe(progress)}")
    return Run(terrain, at, obs, heights, sight, 1 if workers is None else workers, client, bool(progress))


# ----------------------------------------------------------------- validation
def as_observers(observers, name: str = "observers") -> np.ndarray:
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


def as_heights(observer_height, k: int, terrain) -> np.ndarray:
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


def check_on_surface(terrain, obs: np.ndarray, name: str = "observers") -> None:
    """Every observer stands on the surface (by the viewshed's own rule, so no unit fails later)."""
    outside = [i for i in range(obs.shape[0]) if not math.isfinite(_surface_at(terrain, obs[i, 0], obs[i, 1]))]
    if outside:
        i = outside[0]
        raise OutsideFootprintError(
            f"{name}[{i}] = ({float(obs[i, 0])!r}, {float(obs[i, 1])!r}) is outside the terrain's footprint {terrain.extent} "
            f"or on nodata (a triangle touching a NaN sample); {len(outside)} of {obs.shape[0]} {name} are"
        )


def count_dtype(k: int):
    """uint16 while every count fits (K <= 65535), else uint32."""
    return np.uint16 if k <= np.iinfo(np.uint16).max else np.uint32


def eyes(terrain, obs: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """(K, 3) eyes: (x, y, surface + height) as :func:`terrainvis.viewshed` places them, or the given eyes."""
    if obs.shape[1] == 3:
        return obs.copy()
    ground = np.array([_surface_at(terrain, x, y) for x, y in obs])
    return np.column_stack([obs, ground + heights])


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


def keep_terrain(token: str, terrain, at):
    """The terrain this process already holds for the call ``token`` (with its caches), else
    ``terrain``, kept for the call's next units. In the calling process it is the same object."""
    held = _WORKER_TERRAIN.get(token)
    if held is not None:
        return held
    _WORKER_TERRAIN.clear()  # one call at a time per worker: drop an earlier call's terrain
    _WORKER_TERRAIN[token] = (terrain, at)
    return terrain, at


# ----------------------------------------------------------------- the chunked run
def run_chunks(run: Run, unit, on_result, *, align: int = 1, desc: str) -> None:
    """Run ``unit`` over chunks of the observers (starting on multiples of ``align``; each
    chunk one unit of :func:`terrainvis.core.runner.run_units`), showing a progress bar
    of observers (``desc``); ``on_result((start, end), result)`` as each unit finishes.

    A unit is called as ``unit(terrain, at, token, observers, heights, sight)``.
    """
    from ...core.runner import run_units

    k = run.obs.shape[0]
    threads = _local_threads(run.terrain, run.sight.engine, run.workers, run.client)
    token = uuid.uuid4().hex

    def task(s, e):
        return (s, e), (run.terrain, run.at, token, run.obs[s:e], run.heights[s:e], run.sight)

    # the first observers (one chunk of ``align``) here, before the bar: on a first run
    # they compile the kernels (terrainvis.core.compiling says so), and the bar's rate and
    # time left count the viewsheds only; the workers then load the kernels from the cache
    first = min(align, k)
    try:
        key, args = task(0, first)
        on_result(key, unit(*args))
        groups = _chunks(-(-(k - first) // align), max(_n_slots(run.workers, run.client), threads))
        tasks = [task(first + s * align, min(first + e * align, k)) for s, e in groups]
        bar = _progress_bar(k, run.progress, desc, done=first)
        try:
            def add(key, result):
                on_result(key, result)
                bar.update(key[1] - key[0])

            run_units(tasks, unit, on_result=add, workers=run.workers, client=run.client, threads=threads)
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
        from ...core._progress import ProgressLines, in_kernel, on_a_terminal, progress_bar_class

        if not (on_a_terminal() or in_kernel()):
            return ProgressLines(k, desc, "observer", initial=done)
        bar = progress_bar_class()  # the notebook's bar in Jupyter
    return bar(total=k, initial=done, desc=desc, unit="observer", file=sys.stderr, disable=not show)
