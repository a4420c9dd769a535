"""The paper's experiment as one call: :func:`compare`.

For every terrain T, method, level and point set P, :func:`compare` simplifies T into
S(T), computes the visibility matrix of P on T, relocates P onto S(T) in each of the
three ways, computes the visibility matrix there, and counts how many verdicts agree.
It also measures what the paper claimed but never measured: the time and memory that
S(T) saves, and how far its shape is from T.

Work is split into *units*, one per terrain x method x level (a unit simplifies once and
then runs every point set and relocation). Units run on a local process pool, or on a
dask.distributed cluster when ``client`` is given; results do not depend on where they
ran. With ``out_csv``, each finished unit is appended to a CSV at once, so an
interrupted run loses no finished unit, and ``resume=True`` skips the units already
there.
"""

from __future__ import annotations

import io as _io
import os
import sys
import time
import zlib
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ._validate import as_int, describe
from .relocation import RELOCATIONS
from .terrain import HeightGrid

__all__ = [
    "compare", "resolve_terrains", "DEFAULT_TERRAINS", "JACKSBORO_WINDOW", "COLUMNS", "VOLUME_AUTO_LIMIT",
    "save_simplified", "load_simplified", "simplified_path",
]

#: The default terrains: the five bundled 120x120 terrains and a 120x120 window of the real Jacksboro DEM.
DEFAULT_TERRAINS = ("hills", "mesas", "rough", "mountains", "ridges", "jacksboro")

#: Rows and columns of the 344x403 Jacksboro DEM used as the "jacksboro" terrain: its
#: central 120x120 window at the native 74.57 m x 92.47 m cells (8.9 km x 11.0 km). A
#: window keeps the real sampling; resampling the whole DEM to 120x120 would smooth it.
JACKSBORO_WINDOW = ((112, 232), (141, 261))

#: Columns of the result table, in order.
COLUMNS = (
    "terrain", "set", "method", "kind", "level", "relocation",
    "accuracy", "visible_kept", "blocked_kept", "accuracy_paper",
    "n_pairs", "agree_visible", "agree_blocked", "false_visible", "false_blocked",
    "n_points", "n_vertices", "n_vertices_original", "size_fraction", "nbytes", "nbytes_original",
    "max_error", "rms_error", "volume_error",
    "simplify_seconds", "los_seconds", "los_seconds_original", "los_build_seconds",
    "seed", "max_distance", "offset", "error",
)
_KEY = ("terrain", "method", "level")


def _jacksboro() -> HeightGrid:
    from .io import sample_dem

    (r0, r1), (c0, c1) = JACKSBORO_WINDOW
    grid = sample_dem("jacksboro").crop(rows=(r0, r1), cols=(c0, c1))
    grid.attrs["name"] = "jacksboro"
    return grid


def resolve_terrains(terrains) -> dict[str, HeightGrid]:
    """Turn the ``terrains`` argument of :func:`compare` into ``{name: HeightGrid}``.

    Accepted: a HeightGrid; a bundled name (:data:`terrainvis.synthetic.BUNDLED`);
    ``"jacksboro"`` (see :data:`JACKSBORO_WINDOW`); a path to a DEM file (any format of
    :func:`terrainvis.load_dem`; named by its stem); a list of these; or a dict
    ``{name: HeightGrid or str}``.
    """
    from .synthetic import BUNDLED, bundled_terrain

    if isinstance(terrains, (HeightGrid, str, Path)):
        terrains = [terrains]
    items = list(terrains.items()) if isinstance(terrains, dict) else [(None, t) for t in terrains]
    if not items:
        raise ValueError("terrains must name at least one terrain, got an empty collection")
    out: dict[str, HeightGrid] = {}
    for i, (name, t) in enumerate(items):
        if isinstance(t, HeightGrid):
            grid = t
            name = name or grid.attrs.get("name") or f"terrain{i}"
        elif isinstance(t, (str, Path)):
            text = str(t)
            if text in BUNDLED:
                grid = bundled_terrain(text)
            elif text == "jacksboro":
                grid = _jacksboro()
            elif Path(text).suffix:
                from .io import load_dem

                if not Path(text).exists():
                    raise ValueError(
                        f"terrain {text!r} is neither a bundled terrain {list(BUNDLED) + ['jacksboro']} "
                        f"nor an existing file"
                    )
                grid = load_dem(text)
                name = name or Path(text).stem
            else:
                raise ValueError(
                    f"terrain must be a bundled terrain {list(BUNDLED) + ['jacksboro']}, a DEM file or a "
                    f"HeightGrid, got {text!r}"
                )
            name = name or text
        else:
            raise TypeError(f"terrains must hold HeightGrids, names or paths, got {describe(t)}")
        if name in out:
            raise ValueError(f"terrain names must be unique, got {name!r} twice")
        grid.require_finite(f"compare (terrain {name!r})")
        out[str(name)] = grid
    return out


def _set_seed(seed: int, terrain: str, index: int) -> np.random.SeedSequence:
    # Keyed on the terrain's name, not its position, so adding a terrain changes nothing else.
    return np.random.SeedSequence([int(seed), zlib.crc32(terrain.encode()), int(index)])


def point_sets(grid: HeightGrid, terrain: str, n_points: int, n_sets: int, seed: int, offset: float):
    """The ``n_sets`` point sets of a terrain (deterministic for a seed and terrain name)."""
    from .sampling import sample_points

    return [
        sample_points(grid, n_points, seed=np.random.default_rng(_set_seed(seed, terrain, s)), offset=offset)
        for s in range(n_sets)
    ]


def _pair_mask(points: np.ndarray, max_distance):
    if max_distance is None:
        return None
    d = np.hypot(points[:, None, 0] - points[None, :, 0], points[:, None, 1] - points[None, :, 1])
    return d <= max_distance


def _timed(fn, *args, repeats: int = 3, **kwargs):
    best = np.inf
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        best = min(best, time.perf_counter() - t0)
    return out, best


@dataclass(frozen=True)
class _Settings:
    relocations: tuple
    n_points: int
    n_sets: int
    seed: int
    max_distance: float | None
    offset: float
    engine: str
    volume: object
    repeats: int
    save_dir: str | None = None


#: Largest grid (samples) for which ``volume="auto"`` computes the volume shape error.
VOLUME_AUTO_LIMIT = 1_000_000


def _want_volume(volume, grid: HeightGrid) -> bool:
    return bool(volume) if volume != "auto" else grid.size <= VOLUME_AUTO_LIMIT


def _run_unit(grid: HeightGrid, terrain: str, method: str, level: int, settings: _Settings) -> list[dict]:
    """Simplify once, then every point set and relocation: the rows of one unit."""
    from simplifiers import simplify
    from simplifiers import method_info

    from .deviation import volume_error
    from .metrics import agreement
    from .relocation import relocate
    from .visibility import visibility_matrix

    base = {
        "terrain": terrain, "method": method, "kind": method_info(method).kind, "level": level,
        "n_points": settings.n_points, "n_vertices_original": grid.size, "nbytes_original": grid.nbytes,
        "seed": settings.seed, "max_distance": settings.max_distance, "offset": settings.offset, "error": "",
    }
    sets = point_sets(grid, terrain, settings.n_points, settings.n_sets, settings.seed, settings.offset)
    rows = []
    try:
        simplified = simplify(grid, method, level)
        if settings.save_dir is not None:
            save_simplified(simplified, simplified_path(settings.save_dir, terrain, method, level))
        meta = simplified.attrs
        base.update(
            n_vertices=meta["n_vertices"], size_fraction=meta["n_vertices"] / grid.size, nbytes=meta["nbytes"],
            max_error=meta["max_error"], rms_error=meta["rms_error"], simplify_seconds=meta["seconds"],
            volume_error=volume_error(grid, simplified) if _want_volume(settings.volume, grid) else np.nan,
        )
        # The first query builds the acceleration structure (pyramid or Embree scene); time it apart.
        t0 = time.perf_counter()
        visibility_matrix(simplified, sets[0][:2], engine=settings.engine)
        base["los_build_seconds"] = time.perf_counter() - t0
        for s, pts in enumerate(sets):
            v_true, t_true = _timed(visibility_matrix, grid, pts, engine=settings.engine, repeats=settings.repeats)
            mask = _pair_mask(pts, settings.max_distance)
            for how in settings.relocations:
                moved = relocate(pts, simplified, how, offset=settings.offset)
                v_test, t_test = _timed(
                    visibility_matrix, simplified, moved, engine=settings.engine, repeats=settings.repeats
                )
                row = dict(base, set=s, relocation=how, los_seconds=t_test, los_seconds_original=t_true)
                row.update(agreement(v_true, v_test, mask))
                rows.append(row)
    except Exception as exc:  # record the failure in this unit's rows; the run goes on
        message = f"{type(exc).__name__}: {exc}".replace("\n", " ")
        rows = [dict(base, set=s, relocation=how, error=message) for s in range(settings.n_sets) for how in settings.relocations]
    return rows


def simplified_path(save_dir, terrain: str, method: str, level: int) -> Path:
    """Where :func:`compare` saves a simplified terrain when given ``save_dir``."""
    return Path(save_dir) / f"{terrain}__{method}__level{level}.npz"


def save_simplified(terrain, path) -> Path:
    """Save a HeightGrid (z, xs, ys) or a TIN (vertices, faces) to an ``.npz`` file."""
    from .terrain import TIN

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part.npz")
    if isinstance(terrain, TIN):
        np.savez_compressed(tmp, kind="tin", vertices=terrain.vertices, faces=terrain.faces)
    elif isinstance(terrain, HeightGrid):
        np.savez_compressed(tmp, kind="grid", z=terrain.z, xs=terrain.xs, ys=terrain.ys)
    else:
        raise TypeError(f"terrain must be a HeightGrid or a TIN, got {describe(terrain)}")
    os.replace(tmp, path)  # never leave a half-written file under the final name
    return path


def load_simplified(path):
    """Read a terrain written by :func:`save_simplified`."""
    from .terrain import TIN

    with np.load(path, allow_pickle=False) as data:
        if str(data["kind"]) == "tin":
            return TIN(data["vertices"], data["faces"])
        return HeightGrid.from_coords(data["z"], data["xs"], data["ys"])


def _frame(rows: list[dict]) -> pd.DataFrame:
    df = pd.DataFrame(rows)
    for col in COLUMNS:
        if col not in df.columns:
            df[col] = np.nan
    df["error"] = df["error"].astype(object).fillna("").astype(str)
    return df[list(COLUMNS)]


def _read_done(path: Path, settings: _Settings) -> tuple[pd.DataFrame, set]:
    """Rows already in ``path`` and the keys of the units that finished there without error."""
    try:
        old = pd.read_csv(path, keep_default_na=True)
    except (pd.errors.EmptyDataError, FileNotFoundError):
        return _frame([]), set()
    missing = [c for c in COLUMNS if c not in old.columns]
    if missing:
        raise ValueError(f"out_csv {str(path)!r} is not a terrainvis results file (missing columns {missing})")
    old["error"] = old["error"].astype(object).fillna("").astype(str)
    same = (
        (old["n_points"] == settings.n_points) & (old["seed"] == settings.seed) & (old["offset"] == settings.offset)
        & ((old["max_distance"].isna()) if settings.max_distance is None else (old["max_distance"] == settings.max_distance))
    )
    if not same.all():
        raise ValueError(
            f"out_csv {str(path)!r} was written with other settings (points, seed, offset or max_distance); "
            "resume with the same settings or write to a new file"
        )
    expected = settings.n_sets * len(settings.relocations)
    done = set()
    for key, grp in old.groupby(list(_KEY)):
        complete = (
            len(grp) == expected and (grp["error"] == "").all()
            and set(grp["relocation"]) == set(settings.relocations)
        )
        if complete:
            done.add((str(key[0]), str(key[1]), int(key[2])))
    keep = old[[(str(t), str(m), int(lv)) in done for t, m, lv in zip(old["terrain"], old["method"], old["level"])]]
    return keep[list(COLUMNS)], done


def _append_csv(path: Path, df: pd.DataFrame, header: bool) -> None:
    buf = _io.StringIO()
    df.to_csv(buf, index=False, header=header)
    with open(path, "a", encoding="utf-8") as fh:  # one write per unit, then flush to disk
        fh.write(buf.getvalue())
        fh.flush()
        os.fsync(fh.fileno())


def _worker_init(threads: int) -> None:
    import numba

    numba.set_num_threads(max(1, threads))


def compare(
    terrains=DEFAULT_TERRAINS,
    methods=None,
    levels=(1, 2, 3),
    relocations=RELOCATIONS,
    n_points: int = 50,
    n_sets: int = 6,
    seed: int = 0,
    max_distance: float | None = None,
    workers: int | None = None,
    client=None,
    *,
    offset: float = 0.0,
    engine: str = "auto",
    volume="auto",
    repeats: int = 3,
    out_csv=None,
    resume: bool = False,
    save_dir=None,
    progress: bool = False,
) -> pd.DataFrame:
    """Run the paper's experiment: how many LOS verdicts survive each simplification.

    Parameters
    ----------
    terrains : terrain or list or dict
        See :func:`resolve_terrains`. Default: the five bundled 120x120 terrains and the
        central 120x120 window of the Jacksboro DEM.
    methods : list of str, optional
        Simplifiers (default: all seven, :func:`simplifiers.available`).
    levels : sequence of int
        Simplification levels; for 120x120 grids 1, 2, 3 are the paper's 25 %, 6 % and 1.5 %.
    relocations : sequence of str
        Any of ``"identity"``, ``"full"``, ``"half"`` (:func:`terrainvis.relocate`).
    n_points, n_sets : int
        Each terrain gets ``n_sets`` sets of ``n_points`` uniform random points; every
        method sees the same sets.
    seed : int
        The point sets depend only on ``seed`` and the terrain's name.
    max_distance : float, optional
        Count only the pairs whose horizontal distance is at most this (localized
        visibility tests).
    workers : int, optional
        Processes of the local pool (default: the number of CPUs; 1 runs in this process).
        Workers are started with ``spawn``, which imports the caller's ``__main__``
        module again: in a script, call :func:`compare` under
        ``if __name__ == "__main__":`` (notebooks and the CLI need nothing).
    client : dask.distributed.Client, optional
        Run the units on this cluster instead (needs the ``dask`` extra).
    offset : float
        Observer height above the original surface (see :mod:`terrainvis.relocation`).
    engine : str
        Visibility engine (:func:`terrainvis.visibility_matrix`).
    volume : bool or "auto"
        Compute the volume shape error with manifold3d. It builds closed solids of both
        terrains, which takes minutes and gigabytes at SRTM sizes; ``"auto"`` computes it
        for grids of at most :data:`VOLUME_AUTO_LIMIT` samples and leaves NaN above.
    repeats : int
        Each visibility matrix is timed this many times; the fastest run is kept.
    out_csv : str or Path, optional
        Append each finished unit's rows to this CSV as soon as it finishes.
    resume : bool
        With ``out_csv``: keep the units already completed there and run only the rest.
    save_dir : str or Path, optional
        Save every simplified terrain there (:func:`simplified_path`,
        :func:`load_simplified`).
    progress : bool
        Show a tqdm progress bar on stderr.

    Returns
    -------
    pandas.DataFrame
        One row per terrain x point set x method x level x relocation, with the columns
        :data:`COLUMNS`, sorted in that order (terrains as given, methods and
        relocations in the paper's order). A unit whose simplification failed keeps
        its rows, with the message in ``error`` and NaN measurements.

    Examples
    --------
    >>> df = compare(["hills"], methods=["lls"], levels=[1], n_points=10, n_sets=1, workers=1)
    >>> len(df), set(df["relocation"]) == {"identity", "full", "half"}
    (3, True)
    """
    from simplifiers import METHODS, method_info

    grids = resolve_terrains(terrains)
    methods = list(METHODS if methods is None else ([methods] if isinstance(methods, str) else methods))
    if not methods:
        raise ValueError("methods must name at least one method, got an empty list")
    for m in methods:
        method_info(m)
    levels = [as_int(lv, "levels", minimum=0) for lv in ([levels] if isinstance(levels, (int, np.integer)) else levels)]
    relocations = tuple([relocations] if isinstance(relocations, str) else relocations)
    for how in relocations:
        if how not in RELOCATIONS:
            raise ValueError(f"relocations must be drawn from {list(RELOCATIONS)}, got {how!r}")
    if not relocations:
        raise ValueError("relocations must name at least one relocation, got an empty list")
    n_points = as_int(n_points, "n_points", minimum=2)
    n_sets = as_int(n_sets, "n_sets", minimum=1)
    seed = as_int(seed, "seed", minimum=0)
    repeats = as_int(repeats, "repeats", minimum=1)
    if max_distance is not None:
        max_distance = float(max_distance)
        if not np.isfinite(max_distance) or max_distance <= 0:
            raise ValueError(f"max_distance must be finite and > 0, got {max_distance!r}")
    if volume not in (True, False, "auto"):
        raise ValueError(f"volume must be True, False or 'auto', got {volume!r}")
    settings = _Settings(
        relocations, n_points, n_sets, seed, max_distance, float(offset), engine, volume, repeats,
        None if save_dir is None else str(save_dir),
    )

    units = [(t, m, lv) for t in grids for m in methods for lv in levels]
    done_rows = _frame([])
    path = None
    if out_csv is not None:
        path = Path(out_csv)
        path.parent.mkdir(parents=True, exist_ok=True)
        if resume and path.exists():
            done_rows, done = _read_done(path, settings)
            units = [u for u in units if u not in done]
            # Rewrite the file with the completed units only (drops failed or partial ones).
            tmp = path.with_suffix(path.suffix + ".tmp")
            done_rows.to_csv(tmp, index=False)
            os.replace(tmp, path)
        else:
            _frame([]).to_csv(path, index=False)

    # Expensive units first keeps the pool busy to the end.
    units.sort(key=lambda u: (METHODS[u[1]].cost_rank, u[2]))

    from tqdm.auto import tqdm

    bar = tqdm(total=len(units), desc="compare", unit="unit", file=sys.stderr, disable=not progress)
    new_rows: list[dict] = []

    def collect(rows):
        new_rows.extend(rows)
        if path is not None:
            _append_csv(path, _frame(rows), header=False)
        bar.update(1)

    try:
        if not units:
            pass
        elif client is not None:
            futures = {}
            scattered = {name: client.scatter(grids[name], broadcast=False) for name in {u[0] for u in units}}
            for t, m, lv in units:
                futures[client.submit(_run_unit, scattered[t], t, m, lv, settings, pure=False)] = (t, m, lv)
            from dask.distributed import as_completed as dask_completed

            for fut in dask_completed(list(futures)):
                collect(fut.result())
        else:
            n_workers = (os.cpu_count() or 1) if workers is None else as_int(workers, "workers", minimum=1)
            if n_workers == 1 or len(units) == 1:
                for t, m, lv in units:
                    collect(_run_unit(grids[t], t, m, lv, settings))
            else:
                import multiprocessing as mp

                threads = max(1, (os.cpu_count() or 1) // n_workers)
                from concurrent.futures.process import BrokenProcessPool

                try:
                    with ProcessPoolExecutor(
                        max_workers=min(n_workers, len(units)), mp_context=mp.get_context("spawn"),
                        initializer=_worker_init, initargs=(threads,),
                    ) as pool:
                        futures = {
                            pool.submit(_run_unit, grids[t], t, m, lv, settings): (t, m, lv) for t, m, lv in units
                        }
                        for fut in as_completed(futures):
                            collect(fut.result())
                except BrokenProcessPool as exc:
                    raise RuntimeError(
                        "compare's worker processes died. They are started with 'spawn', which imports "
                        "your __main__ module again: in a script, call compare() under "
                        "`if __name__ == \"__main__\":`, or pass workers=1 to run in this process. "
                        f"Units finished before the failure are in out_csv if one was given ({exc})"
                    ) from exc
    finally:
        bar.close()

    df = pd.concat([done_rows, _frame(new_rows)], ignore_index=True) if len(done_rows) else _frame(new_rows)
    order_t = {t: i for i, t in enumerate(grids)}
    order_m = {m: i for i, m in enumerate(METHODS)}
    order_r = {r: i for i, r in enumerate(RELOCATIONS)}
    df = df.assign(
        _t=df["terrain"].map(order_t), _m=df["method"].map(order_m), _r=df["relocation"].map(order_r)
    ).sort_values(["_t", "set", "_m", "level", "_r"], kind="stable")
    return df.drop(columns=["_t", "_m", "_r"]).reset_index(drop=True)
