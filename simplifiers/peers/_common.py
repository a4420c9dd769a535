"""What every peer adapter shares: the lazy import, the TIN in world coordinates, the budget search.

Nothing here imports a peer library: :func:`require` does, inside the adapters' ``build``.
"""

from __future__ import annotations

import importlib
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from terrainvis.core.terrain import TIN, HeightGrid
from terrainvis.errors import SimplificationError

from ..levels import budget_tolerance, check_budget

__all__ = [
    "INSTALL_HINT", "require", "index_tin", "grid_mesh", "BudgetSearch", "repaired", "check_input", "decimate_to_budget",
]

#: What a missing peer library's ImportError tells the user to run.
INSTALL_HINT = 'pip install "terrainvis[peers]"'


def require(library: str, method: str):
    """Import ``library`` for the peer ``method``, or raise ImportError with the install hint.

    Parameters
    ----------
    library : str
        The module to import (``"pymartini"``, ``"pydelatin"``, ``"pyfqmr"``,
        ``"meshoptimizer"``, ``"vtkmodules.vtkFiltersHybrid"``).
    method : str
        The terrainvis method that needs it (named in the message).

    Raises
    ------
    ImportError
        Naming the method, the library and ``pip install "terrainvis[peers]"``; the
        original error is chained.

    Examples
    --------
    >>> require("numpy", "example").__name__
    'numpy'
    >>> try:
    ...     require("terrainvis_no_such_library", "rtin")
    ... except ImportError as exc:
    ...     print(exc)
    the rtin simplifier needs terrainvis_no_such_library, which is not installed: pip install "terrainvis[peers]" (No module named 'terrainvis_no_such_library')
    """
    try:
        return importlib.import_module(library)
    except ImportError as exc:
        raise ImportError(
            f"the {method} simplifier needs {library}, which is not installed: {INSTALL_HINT} ({exc})"
        ) from exc


def check_input(grid: HeightGrid, n_vertices: int, method: str) -> int:
    """Validate a build's arguments once (a HeightGrid without nodata, a budget in range)."""
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {type(grid).__name__}")
    grid.require_finite(method)
    return check_budget(grid.shape, n_vertices, "n_vertices")


def index_tin(grid: HeightGrid, cols: np.ndarray, rows: np.ndarray, faces: np.ndarray, attrs=None) -> TIN:
    """The TIN whose vertices are the grid samples ``(rows[i], cols[i])``, with every face counter-clockwise.

    The libraries that keep samples (Martini, Delatin, VTK's greedy decimation) return
    sample indices; this places them at the grid's coordinates with the grid's float64
    heights (the libraries themselves compute in float32). When the faces' projected area
    sums to a negative number (the library's y axis points the other way) every face is
    reversed; a face folded against the others stays folded, for the height-field check
    to report.
    """
    cols = np.asarray(cols, dtype=np.int64)
    rows = np.asarray(rows, dtype=np.int64)
    vertices = np.column_stack([grid.xs[cols], grid.ys[rows], grid.z[rows, cols]])
    f = np.array(faces, dtype=np.int64).reshape(-1, 3)
    from terrainvis.core.mesh import signed_area2  # core.mesh imports numba: not at import time

    if signed_area2(vertices, f).sum() < 0:
        f = f[:, ::-1]
    return TIN(vertices, f, attrs=attrs)


def grid_mesh(grid: HeightGrid):
    """The grid's own triangulation in *cell units*: ``(vertices (n, 3) float64, faces (m, 3) int32, scale, origin)``.

    x and y are the world coordinates less the first sample's, divided by ``scale`` (the
    smaller mean cell size); z is the height less the mean height, divided by ``scale``
    too. The scaling is the same on all three axes, so the geometry the decimators see
    is the terrain's, in units of about one cell: their thresholds (pyfqmr's quadric
    schedule, meshoptimizer's float32 positions) then do not depend on the grid's unit.
    ``world = local * scale + origin``.
    """
    own = grid.to_tin()
    dx = (grid.xs[-1] - grid.xs[0]) / max(grid.shape[1] - 1, 1)
    dy = (grid.ys[-1] - grid.ys[0]) / max(grid.shape[0] - 1, 1)
    scale = float(min(dx, dy))
    origin = np.array([grid.xs[0], grid.ys[0], float(np.mean(grid.z))])
    local = (own.vertices - origin) / scale
    return local, np.asarray(own.faces, dtype=np.int32), scale, origin


def repaired(vertices: np.ndarray, faces: np.ndarray, grid: HeightGrid, source: str) -> TIN:
    """The mesh made a height field over ``grid`` by :func:`terrainvis.repair_tin` (always run, so
    ``attrs["repair"]`` records what it did, zeros when nothing was wrong)."""
    from terrainvis.core.repair import repair_tin  # here: it imports numba, which registering the peers does not need

    return repair_tin(TIN(vertices, faces), grid, source=source)


@dataclass
class BudgetSearch:
    """Search one integer parameter of a library until the result's vertex count is within the budget's tolerance.

    ``probe(p)`` runs the library with parameter value ``p`` and returns a valid TIN (or
    raises :class:`SimplificationError` when that run's output cannot be made a height
    field). Its vertex count must not decrease as ``p`` grows: each probe narrows the
    bracket ``[lo, hi]``, and the next value is interpolated between the closest counts
    below and above the budget (a bisection when the interpolation stalls).

    The record (``attrs()``): ``parameter``, ``value`` (the one kept), ``probes``
    (``[value, vertices or None]`` per run; None for a run that failed) and ``failures``
    (each failed run's value and message).
    """

    method: str
    parameter: str
    probe: Callable[[int], TIN]
    budget: int
    lo: int
    hi: int
    max_probes: int = 40
    label: Callable[[int], object] | None = None
    found: int | None = None
    probes: list = field(default_factory=list)
    failures: list = field(default_factory=list)
    seconds: float = 0.0

    def run(self, guess: int) -> TIN:
        """The first result within the window, starting at ``guess``; SimplificationError when none is reached."""
        t0 = time.perf_counter()
        budget, tol = self.budget, budget_tolerance(self.budget)
        lo, hi = self.lo, self.hi
        below = above = None  # (value, count) closest to the budget on each side
        p = int(min(max(guess, lo), hi))
        tried = set()
        while len(self.probes) < self.max_probes:
            tried.add(p)
            try:
                tin = self.probe(p)
            except SimplificationError as exc:
                self.probes.append([self._label(p), None])
                self.failures.append([self._label(p), str(exc)])
                p = self._after_failure(p, lo, hi, tried)
                if p is None:
                    break
                continue
            n = tin.n_vertices
            self.probes.append([self._label(p), n])
            if abs(n - budget) <= tol:
                self.seconds = time.perf_counter() - t0
                self.found = p
                tin.attrs["search"] = self.attrs(self._label(p))
                return tin
            if n < budget:
                below = (p, n)
                lo = p + 1
            else:
                above = (p, n)
                hi = p - 1
            if lo > hi:
                break
            p = self._next(lo, hi, below, above, budget, tried)
            if p is None:
                break
        self.seconds = time.perf_counter() - t0
        raise SimplificationError(self._failure_message(below, above, tol))

    def result(self, guess: int, grid: HeightGrid, max_error: float | None) -> TIN:
        """:meth:`run` (``max_error`` None), or :meth:`run_within` (an error target)."""
        if max_error is None:
            return self.run(guess)
        return self.run_within(guess, grid, float(max_error))

    def run_within(self, guess: int, grid: HeightGrid, target: float) -> TIN:
        """The result with the fewest vertices found whose max vertical error is <= ``target``, at most the budget.

        The budget's result comes first (:meth:`run`; for a budget of every sample, the
        parameter's largest value, the library's finest result). When its error
        (:func:`terrainvis.vertical_errors`) is above the target it is returned with
        ``stopped_by = "budget"``, or SimplificationError when that finest result is not
        within the budget's tolerance (a library that cannot reach every sample).
        Otherwise a bisection over the parameter below it narrows to where the error
        crosses the target, and of every run within the target the one with the fewest
        vertices is kept (``stopped_by = "max_error"``). The error need not fall
        monotonically with the parameter, so this is the fewest found, not a proven
        minimum; a run whose output is not a height field counts as not within.
        ``attrs["search"]["errors"]`` has ``[value, vertices, max error]`` for every run
        measured.
        """
        from terrainvis.core.deviation import vertical_errors

        t0 = time.perf_counter()
        if self.budget >= grid.size:
            self.found = self.hi
            best = self.probe(self.hi)
            self.probes.append([self._label(self.hi), best.n_vertices])
        else:
            best = self.run(guess)
        top = self.found
        err = vertical_errors(grid, best)[0]
        errors = [[self._label(top), best.n_vertices, err]]
        within = err <= target
        if not within and abs(best.n_vertices - self.budget) > budget_tolerance(self.budget):
            raise SimplificationError(
                f"{self.method} cannot reach max_error {target:g}: its finest result ({self.parameter} "
                f"{self._label(top)}, {best.n_vertices} vertices) has a max error of {err:.4g}"
            )
        lo, hi, kept = self.lo, top, top  # invariant: hi is within the target
        while within and lo < hi and len(self.probes) < self.max_probes + 20:
            mid = (lo + hi) // 2
            try:
                tin = self.probe(mid)
            except SimplificationError as exc:
                self.probes.append([self._label(mid), None])
                self.failures.append([self._label(mid), str(exc)])
                lo = mid + 1
                continue
            e = vertical_errors(grid, tin)[0]
            self.probes.append([self._label(mid), tin.n_vertices])
            errors.append([self._label(mid), tin.n_vertices, e])
            if e <= target:
                hi = mid
                if tin.n_vertices < best.n_vertices:
                    best, err, kept = tin, e, mid
            else:
                lo = mid + 1
        self.seconds = time.perf_counter() - t0
        best.attrs["search"] = {**self.attrs(self._label(kept)), "max_error_target": target, "errors": errors}
        best.attrs["stopped_by"] = "max_error" if within else "budget"
        return best

    def _label(self, p):
        return p if self.label is None else self.label(p)

    def _next(self, lo, hi, below, above, budget, tried):
        if below is not None and above is not None and above[1] != below[1]:
            frac = (budget - below[1]) / (above[1] - below[1])
            p = int(round(below[0] + frac * (above[0] - below[0])))
        elif below is not None:  # only counts below: step up in proportion
            p = int(math.ceil(below[0] * budget / max(below[1], 1))) if below[0] > 0 else below[0] + 1
        elif above is not None:
            p = int(math.floor(above[0] * budget / max(above[1], 1)))
        else:
            p = (lo + hi) // 2
        p = min(max(p, lo), hi)
        if p in tried:
            p = (lo + hi) // 2
        # interpolation that lands on a bracket's end many times converges slowly: bisect every third probe
        if len(self.probes) % 3 == 2:
            p = (lo + hi) // 2
        return None if p in tried else p

    def _after_failure(self, p, lo, hi, tried):
        """The next value to try after a run that failed: the nearest untried value, alternating sides."""
        for d in range(1, 8):
            for q in (p + d, p - d):
                if lo <= q <= hi and q not in tried:
                    return q
        return None

    def _failure_message(self, below, above, tol):
        head = f"{self.method} cannot reach {self.budget} +- {tol} vertices by its {self.parameter}"
        if below is not None and above is not None:
            head += (f" ({self.parameter} {self._label(above[0])} gives {above[1]} vertices and "
                     f"{self._label(below[0])} gives {below[1]}, and no value in between lands within the tolerance)")
        elif above is not None:
            head += f" (the fewest it reached is {above[1]} vertices, at {self.parameter} {self._label(above[0])})"
        elif below is not None:
            head += f" (the most it reached is {below[1]} vertices, at {self.parameter} {self._label(below[0])})"
        else:
            head += f" (none of its {len(self.probes)} runs gave a valid height field)"
        parts = [head]
        if self.failures:
            parts.append(f"{len(self.failures)} run(s) failed, the last at {self.parameter} {self.failures[-1][0]}: "
                         f"{self.failures[-1][1]}")
        parts.append(f"probes ({self.parameter}, vertices): {self.probes}")
        return "; ".join(parts)

    def attrs(self, value) -> dict:
        return {"parameter": self.parameter, "value": value, "probes": [list(x) for x in self.probes],
                "failures": list(self.failures)}


def _to_world(v: np.ndarray, local: np.ndarray, world: np.ndarray, shape, scale: float, origin: np.ndarray):
    """World coordinates of a decimator's vertices (cell units): a vertex the library left where it was
    (bit for bit one of ``local``'s) takes that sample's exact world coordinates, the others
    ``v * scale + origin`` (which may differ from a sample's coordinates in the last bits)."""
    rows, cols = shape
    out = v * scale + origin
    c = np.clip(np.searchsorted(local[:cols, 0], v[:, 0]), 0, cols - 1)
    r = np.clip(np.searchsorted(local[::cols, 1], v[:, 1]), 0, rows - 1)
    k = r * cols + c
    same = (local[k] == v).all(axis=1)
    out[same] = world[k[same]]
    return out


def decimate_to_budget(grid: HeightGrid, budget: int, method: str, parameter: str, decimate, *, max_probes: int,
                       label=None, samples_only: bool = False, max_error: float | None = None) -> TIN:
    """Search a mesh decimator's face target until its *repaired* result is within the budget's tolerance.

    ``decimate(local, faces, target_faces) -> (vertices, faces)`` runs the library once on
    the grid's mesh in cell units (:func:`grid_mesh`); its vertices come back in those
    units (``samples_only``: the library only drops vertices and its faces index the
    input's vertices, which then keep their exact world coordinates; ``vertices`` is
    ignored). Each result
    goes through :func:`repaired` (:func:`terrainvis.repair_tin`), and the search
    (:class:`BudgetSearch`) counts the repaired mesh's vertices: a disk with V vertices,
    B on its border, has 2V - B - 2 faces, so the first target is 2 x budget. With
    ``max_error``: :meth:`BudgetSearch.run_within`.
    """
    local, faces, scale, origin = grid_mesh(grid)
    world = grid.to_tin().vertices  # the samples' exact coordinates (the grid's TIN has the same vertex order)
    history = {}

    def probe(target: int) -> TIN:
        out_v, out_f = decimate(local, faces, int(target))
        out_f = np.asarray(out_f, dtype=np.int64).reshape(-1, 3)
        if out_f.shape[0] == 0:
            raise SimplificationError(f"{method}: the library returned no faces")
        used, inverse = np.unique(out_f, return_inverse=True)
        if samples_only:
            vertices = world[used]
        else:
            vertices = _to_world(np.asarray(out_v, dtype=np.float64)[used], local, world, grid.shape, scale, origin)
        tin = repaired(vertices, inverse.reshape(-1, 3), grid, source=method)
        history[int(target)] = int(out_f.shape[0])
        tin.attrs["library_vertices"] = int(used.size)
        tin.attrs["library_faces"] = int(out_f.shape[0])
        return tin

    search = BudgetSearch(method, parameter, probe, budget, lo=2, hi=faces.shape[0] - 1, max_probes=max_probes,
                          label=label)
    tin = search.result(2 * budget, grid, max_error)
    tin.attrs["seconds_search"] = search.seconds
    tin.attrs["unit"] = scale
    return tin
