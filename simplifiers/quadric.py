"""Quadric edge collapse (Garland and Heckbert 1997) with an exact rectangular footprint.

The collapses themselves are done by a library: pymeshlab's
``meshing_decimation_quadric_edge_collapse`` (VCG; planar quadric, normal preservation
and optimal placement) or, as a faster backend, ``fast_simplification.simplify``
(Forstmann's threshold variant). Neither keeps a terrain's footprint: pymeshlab either
shrinks the border or freezes every border vertex, fast-simplification moves corners
away, and both can leave a few faces folded over in projection. So every decimated
mesh goes through the same post-processing, which turns it into a valid height field
over the grid's exact extent (the rules of
:func:`simplifiers.registry.check_height_field`):

pymeshlab runs with a high ``boundaryweight`` (1000): its boundary quadric then keeps
the border within a fraction of a cell of the lines (on 120² terrains at 900 and 225
vertices, weights 100 to 10,000 gave similar errors, while 1 and 10 pulled the border in
by up to 200 m and lost the corners).

1. **Boundary snapping.** The boundary loop of the decimated disk is split into four
   chains by the four corners. A boundary vertex within ``corner_tol`` of a corner
   becomes that corner exactly; a corner with no such vertex is *inserted* with one ear
   triangle (its height is the grid sample there). Every other boundary vertex is moved
   onto its chain's boundary line (the coordinate across the line is set exactly; its
   height is kept); a chain whose order along its line came out reversed somewhere
   takes its own coordinates in sorted order (``attrs["reordered"]``). Boundary vertices
   can therefore slide and collapse along the border, which is what a 1.5 % budget needs.
2. **Fold-over repair.** For each face whose projected (signed) area is not positive,
   one of its vertices is moved into the kernel of its star (the set of positions where
   all its faces are counter-clockwise; a 2-D linear programme, the Chebyshev centre,
   and then the closest point on the way to it with a margin). A boundary vertex moves
   only along its line and a corner never moves. A moved vertex takes the grid's height
   at its new position. When no vertex of a bad face can be moved, the face is removed
   by a half-edge collapse of one of its vertices (a documented last resort, counted in
   ``attrs["collapses"]``).
3. **Budget.** The vertex count of the *post-processed* mesh must be within
   :func:`~simplifiers.levels.budget_tolerance` of the budget. The libraries take a
   face target, and a disk has F = 2V - B - 2 faces (B boundary vertices), so the
   decimation runs in stages: a first pass to about the budget, then further passes
   on the decimated mesh with face targets corrected from the measured count (a later
   pass starts from fresh quadrics of the decimated mesh, so only the first pass, which
   does almost all the work, sees the original surface). An overshoot restarts from
   the last mesh above the budget with a smaller step.
4. **Last resort.** When a pass cannot be post-processed (the library returned a mesh
   that is not a disk, or whose border misses the corners' order; seen on tiny budgets)
   or the library stalls, the last valid result a little above the budget (at most
   ``max(16, min(budget // 10, 200))`` vertices) is finished by our own valid half-edge
   collapses, flattest vertex (umbrella operator) first.

Every moved, snapped, inserted or collapsed vertex is counted in ``tin.attrs``.
The vertex heights come from the library (optimal placement), except an inserted
corner and a relocated vertex, which take the grid's height at their position; a
snapped boundary vertex keeps its height.

References
----------
M. Garland and P. S. Heckbert, "Surface simplification using quadric error metrics",
SIGGRAPH 1997, DOI 10.1145/258734.258849.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from terrainvis._validate import as_int, describe
from terrainvis.errors import SimplificationError
from terrainvis.terrain import TIN, HeightGrid

__all__ = ["build", "BACKENDS", "PYMESHLAB_DEFAULTS", "FAST_DEFAULTS"]

#: The decimation libraries :func:`build` can use.
BACKENDS = ("pymeshlab", "fast-simplification")

#: pymeshlab filter settings used unless overridden through ``**tuning``.
PYMESHLAB_DEFAULTS = {
    "qualitythr": 0.3,
    "boundaryweight": 1000.0,
    "preservenormal": True,
    "preservetopology": True,
    "optimalplacement": True,
    "planarquadric": True,
    "planarweight": 0.001,
    "qualityweight": False,
}

#: fast-simplification settings used unless overridden through ``**tuning``.
FAST_DEFAULTS = {"agg": 7.0}

_BOOL_KEYS = {"preservenormal", "preservetopology", "optimalplacement", "planarquadric", "qualityweight"}

#: Options accepted by both backends (post-processing).
_COMMON_DEFAULTS = {"corner_tol": 0.25, "max_stages": 30}


# --------------------------------------------------------------------------- public
def build(grid: HeightGrid, n_vertices: int, *, backend: str = "pymeshlab", **tuning) -> TIN:
    """Quadric edge collapse of a height grid to a TIN with ``n_vertices`` vertices.

    Parameters
    ----------
    grid : HeightGrid
        The terrain, without nodata. Uniform or rectilinear; cells need not be square
        (everything runs in world coordinates, shifted to a local origin for the
        libraries).
    n_vertices : int
        The vertex budget, in [4, grid.size]. The result has this many vertices to
        within :func:`simplifiers.levels.budget_tolerance` (1 %, at least one).
    backend : {"pymeshlab", "fast-simplification"}
        The library that performs the collapses.
    **tuning
        For ``"pymeshlab"``: any of :data:`PYMESHLAB_DEFAULTS` (``qualitythr``,
        ``boundaryweight``, ``preservenormal``, ``preservetopology``,
        ``optimalplacement``, ``planarquadric``, ``planarweight``, ``qualityweight``).
        For ``"fast-simplification"``: ``agg`` (aggressiveness, default 7).
        For both: ``corner_tol`` (a boundary vertex closer than this many grid
        spacings to a corner becomes the corner, default 0.25) and ``max_stages``
        (decimation passes allowed to meet the budget, default 30).

    Returns
    -------
    TIN
        Counter-clockwise faces covering exactly ``grid.extent``. ``attrs`` records the
        backend, the ``settings``, ``stages`` (decimation passes), ``failures`` (passes
        whose output could not be post-processed), ``history`` (target faces, faces
        and vertices, or the error, per pass), ``target_faces`` (of the last pass),
        ``snapped`` (boundary vertices moved onto a boundary line), ``max_snap``
        (largest such move, in world units), ``reordered`` (boundary chains whose
        order had to be restored), ``corners_inserted``, ``boundary`` (boundary
        vertices), ``repairs`` (fold-over relocations) and ``collapses`` (vertex
        removals by our own half-edge collapses).

    Raises
    ------
    SimplificationError
        When the library fails or no valid height field within the budget is found;
        the message names the backend and the cause.

    Examples
    --------
    >>> import numpy as np
    >>> from terrainvis import HeightGrid
    >>> yy, xx = np.mgrid[0:20, 0:20]
    >>> g = HeightGrid(np.sin(xx / 3.0) * 10 + yy, dx=30.0, dy=30.0)
    >>> tin = build(g, 60)
    >>> abs(tin.n_vertices - 60) <= 1, tin.is_height_field(), tin.extent == g.extent
    (True, True, True)
    """
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {describe(grid)}")
    grid.require_finite("quadric edge collapse")
    n_vertices = as_int(n_vertices, "n_vertices")
    if n_vertices < 4 or n_vertices > grid.size:
        raise ValueError(
            f"n_vertices must be in [4, {grid.size}] for a {grid.shape[0]}x{grid.shape[1]} grid, got {n_vertices}"
        )
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
    settings, common = _check_tuning(backend, tuning)
    from .levels import budget_tolerance

    tol = budget_tolerance(n_vertices)
    fine = grid.to_tin()
    if n_vertices == grid.size:
        return TIN(fine.vertices, fine.faces, attrs={"backend": backend, "stages": 0})
    origin = np.array([grid.xs[0], grid.ys[0], float(np.mean(grid.z))])
    local = fine.vertices - origin  # a new float64 array: the libraries see a local origin
    faces = np.array(fine.faces, dtype=np.int32, copy=True)
    decimate = _pymeshlab_decimate if backend == "pymeshlab" else _fast_decimate
    post = _PostProcessor(grid, origin, common["corner_tol"])
    result, info = _meet_budget(decimate, settings, local, faces, post, n_vertices, tol, common["max_stages"], backend)
    vertices, out_faces, stats = result
    meta = {"backend": backend, "settings": dict(settings), **stats, **info}
    tin = TIN(vertices, out_faces, attrs=meta)
    _self_check(tin, grid, n_vertices, tol, backend)
    return tin


# --------------------------------------------------------------------------- options
def _check_tuning(backend: str, tuning: dict):
    defaults = PYMESHLAB_DEFAULTS if backend == "pymeshlab" else FAST_DEFAULTS
    settings = dict(defaults)
    common = dict(_COMMON_DEFAULTS)
    for key, value in tuning.items():
        if key in common:
            if key == "max_stages":
                common[key] = as_int(value, key, minimum=1)
            else:
                common[key] = _positive(value, key)
        elif key in settings:
            if key in _BOOL_KEYS:
                if not isinstance(value, (bool, np.bool_)):
                    raise TypeError(f"{key} must be a bool, got {describe(value)}")
                settings[key] = bool(value)
            else:
                settings[key] = _positive(value, key, allow_zero=(key == "qualitythr"))
        else:
            valid = sorted(list(defaults) + list(common))
            raise TypeError(f"unknown option {key!r} for backend {backend!r}; valid options are {valid}")
    if common["corner_tol"] >= 0.5:
        raise ValueError(f"corner_tol must be < 0.5 grid spacings, got {common['corner_tol']!r}")
    return settings, common


def _positive(value, name: str, allow_zero: bool = False) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {describe(value)}")
    out = float(value)
    if not math.isfinite(out) or out < 0 or (out == 0 and not allow_zero):
        raise ValueError(f"{name} must be finite and {'>=' if allow_zero else '>'} 0, got {value!r}")
    return out


# --------------------------------------------------------------------------- backends
def _pymeshlab_decimate(vertices: np.ndarray, faces: np.ndarray, target_faces: int, settings: dict):
    """One pymeshlab pass: (vertices, faces) of the decimated mesh, local coordinates."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces))
    ms.meshing_decimation_quadric_edge_collapse(
        targetfacenum=int(target_faces), targetperc=0.0, preserveboundary=False, autoclean=True, selected=False,
        **settings,
    )
    m = ms.current_mesh()
    return _compact(np.array(m.vertex_matrix(), dtype=np.float64), np.array(m.face_matrix(), dtype=np.int64))


def _fast_decimate(vertices: np.ndarray, faces: np.ndarray, target_faces: int, settings: dict):
    """One fast-simplification pass: (vertices, faces) of the decimated mesh, local coordinates."""
    import fast_simplification

    # Its collapse threshold grows as 1e-9 (iteration + 3) ** agg (squared metres here) for
    # at most 100 iterations, so a rough terrain may stop short of the target; the caller
    # then runs another pass, which starts from fresh quadrics.
    v, f = fast_simplification.simplify(
        np.array(vertices, dtype=np.float64, copy=True), np.array(faces, dtype=np.int32, copy=True),
        target_count=int(target_faces), agg=float(settings["agg"]),
    )
    return _compact(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64).reshape(-1, 3))


def _compact(v: np.ndarray, f: np.ndarray):
    """Drop unreferenced vertices (keeping their order) and renumber the faces."""
    used = np.zeros(v.shape[0], dtype=bool)
    used[f.ravel()] = True
    if used.all():
        return v, f
    new = np.cumsum(used) - 1
    return v[used], new[f]


# --------------------------------------------------------------------------- budget
def _finish_limit(budget: int) -> int:
    """Most vertices our own collapses may remove to finish a decimation (they are slow)."""
    return max(16, min(budget // 10, 200))


def _meet_budget(decimate, settings, local, faces, post, budget, tol, max_stages, backend):
    """Decimate in stages until the post-processed mesh is within ``tol`` of ``budget``.

    Returns ``((vertices, faces, stats), info)``. Each pass decimates ``base``, the last
    mesh known to post-process to more than ``budget`` vertices (at first the full grid).
    When a pass cannot be post-processed (a rare library output that is not a disk, or
    corners out of order) or the library cannot get closer, the last valid result above
    the budget is finished by our own valid half-edge collapses (``attrs["collapses"]``).
    """
    b_guess = int(math.sqrt(budget))
    # A disk has F = 2V - B - 2. Guess B low (a quarter of a uniform grid's boundary) so that
    # the first pass lands at or above the budget; later passes correct from measurements.
    target = 2 * budget - 2 - b_guess
    base_v, base_f = local, faces
    best = None  # the last valid post-processed result above the budget
    stages = failures = overshoots = 0
    history = []

    def info():
        return {"stages": stages, "failures": failures, "target_faces": int(target), "history": history}

    def finish(reason):
        excess = best[0].shape[0] - budget
        if excess > _finish_limit(budget):
            raise SimplificationError(
                f"qec ({backend} backend) cannot reach {budget} vertices: {reason}; the closest valid "
                f"mesh has {best[0].shape[0]} vertices (passes: target faces, faces, vertices or error: {history})"
            )
        v, f, side, stats = best
        v, f, side, removed = post.remove_vertices(v, f, side, excess)
        if abs(v.shape[0] - budget) > tol:
            raise SimplificationError(
                f"qec ({backend} backend) cannot reach {budget} vertices: {reason}, and only {removed} of "
                f"{excess} further vertices could be removed by valid collapses"
            )
        return (v, f, dict(stats, collapses=stats["collapses"] + removed)), info()

    while stages < max_stages:
        stages += 1
        target = int(min(max(target, 2), base_f.shape[0] - 1))
        try:
            v, f = decimate(base_v, base_f, target, settings)
        except (MemoryError, KeyboardInterrupt):
            raise
        except Exception as exc:  # the library failed: name it and the cause
            raise SimplificationError(
                f"qec ({backend} backend) failed in decimation pass {stages} (target {target} faces): "
                f"{type(exc).__name__}: {exc}"
            ) from exc
        try:
            if f.shape[0] == 0:
                raise _PostError(f"qec ({backend} backend) returned an empty mesh")
            result = post.run(v, f, backend)
        except _PostError as exc:
            failures += 1
            history.append((target, int(f.shape[0]), str(exc)))
            if best is not None and best[0].shape[0] - budget <= _finish_limit(budget):
                return finish(f"pass {stages} failed ({exc})")
            # decimate less: a result a little above the budget can be finished by our own collapses
            # (tiny meshes need a few tries; on large ones each try is expensive)
            if target >= base_f.shape[0] - 1 or failures >= (8 if base_f.shape[0] < 10_000 else 3):
                if best is not None:
                    return finish(f"pass {stages} failed ({exc})")
                raise SimplificationError(
                    f"{exc} ({failures} failed passes; target faces, faces and error per pass: {history})"
                ) from exc
            target = target + max(2, target // 20)
            continue
        n_out = result[0].shape[0]
        history.append((target, int(f.shape[0]), int(n_out)))
        excess = n_out - budget
        if abs(excess) <= tol:
            return result[:2] + (result[3],), info()
        if excess > 0:
            best = result
            if f.shape[0] > target + max(4, target // 50):
                # the library stopped short of the target (fast-simplification's threshold
                # schedule): a new pass starts from fresh quadrics and goes further
                if f.shape[0] < base_f.shape[0]:
                    base_v, base_f = v, f
                    continue
                return finish(f"the library stalls at {f.shape[0]} faces for a target of {target}")
            if target <= 2:
                return finish("the library reached its smallest target")
            base_v, base_f = v, f
            # each removed vertex costs about two faces (one on the border)
            b_frac = result[3]["boundary"] / max(n_out, 1)
            target = f.shape[0] - max(1, int(round(excess * (2.0 - b_frac))))
        else:
            overshoots += 1
            if best is not None and overshoots > 2:
                return finish("the library keeps overshooting")
            # go back to the base mesh with a smaller step
            target = target + max(1, int(round(-excess * 2.0)))
            if target >= base_f.shape[0]:
                if best is not None:
                    return finish("one collapse pass removes too many vertices")
                raise SimplificationError(
                    f"qec ({backend} backend) cannot reach {budget} vertices: the decimation jumps from "
                    f"{base_v.shape[0]} to {n_out} vertices"
                )
    if best is not None:
        return finish(f"the budget was not met in {max_stages} passes")
    raise SimplificationError(
        f"qec ({backend} backend) did not meet the budget of {budget} +- {tol} vertices in {max_stages} passes "
        f"(targets, faces and vertices per pass: {history})"
    )


# --------------------------------------------------------------------------- post-processing
class _PostError(SimplificationError):
    """Post-processing could not turn one decimated mesh into a valid height field."""


class _PostProcessor:
    """Snap the boundary of a decimated mesh onto the extent and repair fold-overs."""

    def __init__(self, grid: HeightGrid, origin: np.ndarray, corner_tol: float):
        self.grid = grid
        self.origin = origin
        xmin, xmax, ymin, ymax = grid.extent
        self.extent = (xmin, xmax, ymin, ymax)
        # corner k and the line of side k (from corner k to corner k+1, counter-clockwise)
        self.corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
        self.corner_tol = corner_tol * min(float(np.diff(grid.xs).min()), float(np.diff(grid.ys).min()))
        span = max(xmax - xmin, ymax - ymin)
        self.area_eps = 1e-12 * span * span  # twice-area threshold for a face to count as positive

    # ---------------------------------------------------------------- main
    def run(self, v_local: np.ndarray, faces: np.ndarray, backend: str):
        """Post-process one decimated mesh: ``(vertices, faces, side, stats)`` in world coordinates.

        ``side[i]`` is -1 for an interior vertex, k in 0..3 for a vertex on side k (from
        corner k to corner k+1, counter-clockwise from (xmin, ymin)) and 4 + k for corner k.
        """
        v = v_local + self.origin
        f = np.array(faces, dtype=np.int64)
        # orientation: the input is counter-clockwise; a library never flips the whole mesh,
        # but make sure rather than trusting it
        if _signed_area2(v, f).sum() < 0:
            f = f[:, ::-1].copy()
        loop = _boundary_loop(f, v.shape[0], backend)
        v, f, side, stats = self._snap(v, f, loop, backend)
        v, f, side, repairs, collapses = self._repair(v, f, side, backend)
        stats.update(repairs=repairs, collapses=collapses, boundary=int((side >= 0).sum()))
        return v, f, side, stats

    # ---------------------------------------------------------------- snapping
    def _snap(self, v, f, loop, backend):
        xmin, xmax, ymin, ymax = self.extent
        P = v[loop, :2]
        L = loop.size
        corner_at = []  # position in the loop of each corner (existing or to insert before)
        inserted = []
        for k in range(4):
            c = self.corners[k]
            d = np.hypot(P[:, 0] - c[0], P[:, 1] - c[1])
            j = int(np.argmin(d))
            if d[j] <= self.corner_tol:
                corner_at.append((j, False))
            else:
                # insert the corner between the nearest vertex and its neighbour on the other side
                # of the corner: the nearest vertex is on the incoming side (k-1) when it is closer
                # to that side's line than to the outgoing side's line.
                inc = _line_distance(P[j], (k - 1) % 4, self.extent)
                out = _line_distance(P[j], k, self.extent)
                pos = (j + 1) % L if inc <= out else j
                corner_at.append((pos, True))
                inserted.append(k)
        # the corners must appear in counter-clockwise order along the loop
        start = corner_at[0][0]
        rel = [((p - start) % L) for p, _ in corner_at]
        # (an inserted corner may share its position with the next, existing, corner)
        ok = all(
            rel[i] < rel[i + 1] or (rel[i] == rel[i + 1] and corner_at[i][1] and not corner_at[i + 1][1])
            for i in range(3)
        )
        existing = [p for p, ins in corner_at if not ins]
        if not ok or len(set(existing)) != len(existing):
            raise _PostError(
                f"qec ({backend} backend): the decimated boundary does not pass the four corners in order "
                f"(corner positions along the boundary loop: {rel})"
            )
        # side of every loop vertex: the chain from corner k to corner k+1 lies on side k
        side_loop = np.empty(L, dtype=np.int64)
        bounds = rel + [L]
        chains = []
        for k in range(4):
            first = bounds[k] + (0 if corner_at[k][1] else 1)  # an existing corner is not in the chain
            idx = (start + np.arange(bounds[k], bounds[k + 1])) % L
            side_loop[idx] = k
            chains.append((start + np.arange(first, bounds[k + 1])) % L)
        corner_vertex = np.full(4, -1, dtype=np.int64)
        side = np.full(v.shape[0], -1, dtype=np.int64)  # -1 interior, 0..3 side, 4..7 corner k
        side[loop] = side_loop
        new_v = v.copy()
        moves = np.zeros(L)
        # snap chains onto their lines (set the coordinate across the line exactly, clamp the other)
        fixed = np.array([ymin, xmax, ymax, xmin])
        reordered = 0
        for k in range(4):
            pos = chains[k]
            sel = loop[pos]
            axis = 1 if k in (0, 2) else 0  # coordinate fixed by side k
            other = 1 - axis
            lo, hi = (xmin, xmax) if other == 0 else (ymin, ymax)
            before = new_v[sel, :2].copy()
            new_v[sel, axis] = fixed[k]
            free = np.clip(new_v[sel, other], lo, hi)
            # along the loop the free coordinate must run the same way as the side
            # (x up on side 0, y up on 1, x down on 2, y down on 3); a dent in the
            # decimated border can swap two neighbours, which no relocation can undo,
            # so such a chain takes its own coordinates in sorted order
            ascending = k in (0, 1)
            steps = np.diff(free)
            if (steps < 0).any() if ascending else (steps > 0).any():
                free = np.sort(free) if ascending else np.sort(free)[::-1]
                reordered += 1
            new_v[sel, other] = free
            moves[pos] = np.hypot(*(new_v[sel, :2] - before).T)
        for k, (p, ins) in enumerate(corner_at):
            if not ins:
                vid = int(loop[p])
                moves[p] = math.hypot(*(self.corners[k] - v[vid, :2]))
                new_v[vid, :2] = self.corners[k]
                side[vid] = 4 + k
                corner_vertex[k] = vid
        snapped = int((moves > 0).sum())
        max_snap = float(moves.max()) if moves.size else 0.0
        # insert the missing corners with one ear triangle each: (prev, corner, next)
        extra_v = []
        extra_f = []
        n = new_v.shape[0]
        for k, (p, ins) in enumerate(corner_at):
            if not ins:
                continue
            a = int(loop[(p - 1) % L])
            b = int(loop[p % L])
            cid = n + len(extra_v)
            r = 0 if k in (0, 1) else self.grid.shape[0] - 1
            c = 0 if k in (0, 3) else self.grid.shape[1] - 1
            extra_v.append([self.corners[k][0], self.corners[k][1], float(self.grid.z[r, c])])
            extra_f.append([a, cid, b])
            corner_vertex[k] = cid
        if extra_v:
            new_v = np.vstack([new_v, np.array(extra_v)])
            f = np.vstack([f, np.array(extra_f, dtype=np.int64)])
            side = np.concatenate([side, 4 + np.array(inserted, dtype=np.int64)])
        stats = {"snapped": snapped, "max_snap": max_snap, "corners_inserted": len(inserted), "reordered": reordered}
        return new_v, f, side, stats

    # ---------------------------------------------------------------- fold-overs
    def _repair(self, v, f, side, backend):
        """Move vertices of non-positive faces into the kernels of their stars.

        Works in rounds: the stars are built once per round; a vertex whose star changed
        in a collapse during the round waits for the next one.
        """
        repairs = 0
        collapses = 0
        mesh = _LazyMesh(v.copy(), f, side)
        for _ in range(100):
            area2 = _signed_area2(mesh.v, mesh.f)
            bad = np.flatnonzero(mesh.alive & (area2 <= self.area_eps))
            if bad.size == 0:
                v, f, side = mesh.compact()
                return v, f, side, repairs, collapses
            n_bad = np.bincount(mesh.f[bad].ravel(), minlength=mesh.v.shape[0])
            progress = False
            for fi in bad:
                if not mesh.alive[fi] or _signed_area2(mesh.v, mesh.f[fi : fi + 1])[0] > self.area_eps:
                    continue  # removed, or fixed by an earlier move
                cand = [x for x in self._order_candidates(mesh.f, fi, mesh.side, n_bad) if not mesh.dirty[x]]
                done = False
                # move one vertex of the face into the kernel of its star
                for vid in cand:
                    pos = self._kernel_point(mesh.v, mesh.f, mesh.faces_of(vid), vid, int(mesh.side[vid]))
                    if pos is not None:
                        mesh.v[vid, :2] = pos
                        mesh.v[vid, 2] = float(self.grid.height_at(pos[None, :])[0])
                        repairs += 1
                        done = True
                        break
                if not done:
                    # last resort: remove one of its vertices by a valid half-edge collapse
                    for vid in sorted(cand, key=lambda x: (mesh.side[x] >= 0, x)):
                        if mesh.collapse(vid, self.area_eps):
                            collapses += 1
                            done = True
                            break
                progress = progress or done
            if not progress:
                break
            mesh.rebuild()
        area2 = _signed_area2(mesh.v, mesh.f)
        nbad = int((mesh.alive & (area2 <= self.area_eps)).sum())
        raise _PostError(
            f"qec ({backend} backend): {nbad} faces still fold over after {repairs} relocations and "
            f"{collapses} collapses"
        )

    def _order_candidates(self, f, fi, side, n_bad):
        """The movable vertices of face ``fi``: the one in most bad faces first (the vertex that
        caused the fold), then interior before boundary (two degrees of freedom), then by id."""
        cand = [int(x) for x in f[fi] if side[x] < 4]  # corners never move
        cand.sort(key=lambda x: (-n_bad[x], side[x] >= 0, x))
        return cand

    def _kernel_point(self, v, f, star_faces, vid, s):
        """A position for vertex ``vid`` at which all its faces are counter-clockwise, or None."""
        xmin, xmax, ymin, ymax = self.extent
        p0 = v[vid, :2]
        # each face (vid, a, b): orient(p, a, b) > 0  <=>  n . (p - p0) > c
        fa = f[star_faces]
        rot = np.argmax(fa == vid, axis=1)
        a = fa[np.arange(fa.shape[0]), (rot + 1) % 3]
        b = fa[np.arange(fa.shape[0]), (rot + 2) % 3]
        A = v[a, :2] - p0
        B = v[b, :2] - p0
        n = np.column_stack([A[:, 1] - B[:, 1], B[:, 0] - A[:, 0]])
        c = -(A[:, 0] * B[:, 1] - B[:, 0] * A[:, 1])
        scale = max(float(np.abs(np.concatenate([A.ravel(), B.ravel()])).max()), 1e-300)
        if s < 0:
            from scipy.optimize import linprog

            norm = np.hypot(n[:, 0], n[:, 1])
            A_ub = np.column_stack([-n / scale, norm / scale])
            b_ub = -c / scale**2
            bounds = [(xmin - p0[0]) / scale, (xmax - p0[0]) / scale], [(ymin - p0[1]) / scale, (ymax - p0[1]) / scale]
            res = linprog(
                [0.0, 0.0, -1.0], A_ub=A_ub, b_ub=b_ub,
                bounds=[tuple(bounds[0]), tuple(bounds[1]), (None, 1.0)], method="highs",
            )
            if res.status != 0 or res.x[2] <= 1e-9:
                return None
            centre = res.x[:2] * scale
            # the closest point on the way to the centre that leaves every face a margin
            for t in (0.125, 0.25, 0.5, 0.75, 1.0):
                q = t * centre
                if (n @ q - c > max(self.area_eps, 0.05 * t * res.x[2] * scale * norm.min())).all():
                    return p0 + q
            return p0 + centre
        # a boundary vertex slides along its side: p = p0 + u * e
        k = s
        e = np.array([1.0, 0.0]) if k in (0, 2) else np.array([0.0, 1.0])
        lo_b, hi_b = ((xmin, xmax) if k in (0, 2) else (ymin, ymax))
        u0 = p0[0] if k in (0, 2) else p0[1]
        lo, hi = lo_b - u0, hi_b - u0
        ne = n @ e
        rhs = c + self.area_eps
        for ni, ri in zip(ne, rhs):
            if ni > 0:
                lo = max(lo, ri / ni)
            elif ni < 0:
                hi = min(hi, ri / ni)
            elif ri >= 0:
                return None
        if not hi > lo:
            return None
        w = hi - lo
        u = min(max(0.0, lo + 0.1 * w), hi - 0.1 * w)
        return p0 + u * e

    def remove_vertices(self, v, f, side, count):
        """Remove up to ``count`` vertices by valid half-edge collapses, flattest first.

        The last resort when the library cannot reach the budget: in each round the
        non-corner vertices are tried in order of how close their height is to the mean
        of their neighbours' (the umbrella operator), and every valid collapse is made.
        """
        removed = 0
        mesh = _LazyMesh(v.copy(), f, side)
        n = mesh.v.shape[0]
        while removed < count:
            ff = mesh.f[mesh.alive]
            he = ff[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
            key = np.unique(np.minimum(he[:, 0], he[:, 1]) * n + np.maximum(he[:, 0], he[:, 1]))
            e0, e1 = key // n, key % n
            deg = np.bincount(e0, minlength=n) + np.bincount(e1, minlength=n)
            zsum = np.bincount(e0, mesh.v[e1, 2], n) + np.bincount(e1, mesh.v[e0, 2], n)
            flat = np.abs(mesh.v[:, 2] - zsum / np.maximum(deg, 1))
            flat[mesh.dead_v | (mesh.side >= 4)] = np.inf
            progress = False
            for vid in np.argsort(flat, kind="stable"):
                if removed >= count or not np.isfinite(flat[vid]):
                    break
                if mesh.collapse(int(vid), self.area_eps):
                    removed += 1
                    progress = True
            if not progress:
                break
            mesh.rebuild()
        v, f, side = mesh.compact()
        return v, f, side, removed


class _LazyMesh:
    """A mesh under half-edge collapses.

    Removed faces are only marked dead and removed vertices are dropped by
    :meth:`compact`, so indices stay valid; the stars (faces around each vertex) are
    rebuilt between rounds by :meth:`rebuild`, and a vertex whose star changed in the
    current round is *dirty*: it neither moves nor takes part in a collapse until then.
    """

    def __init__(self, v, f, side):
        self.v = v
        self.f = np.array(f, dtype=np.int64)
        self.side = np.array(side, dtype=np.int64)
        self.alive = np.ones(self.f.shape[0], dtype=bool)
        self.dead_v = np.zeros(self.v.shape[0], dtype=bool)
        self.rebuild()

    def rebuild(self):
        self.star = _Stars(self.f, self.v.shape[0])
        self.dirty = np.zeros(self.v.shape[0], dtype=bool)

    def faces_of(self, i: int) -> np.ndarray:
        idx = self.star.of(i)
        return idx[self.alive[idx]]

    def collapse(self, vid: int, area_eps: float) -> bool:
        """Half-edge collapse of ``vid`` into a neighbour, if one is valid.

        A boundary vertex collapses only along its side (into a neighbour on the same
        line, a corner included). The faces that move to the neighbour must all stay
        counter-clockwise, and the link condition must hold (no non-manifold edge).
        """
        if self.dirty[vid] or self.dead_v[vid] or self.side[vid] >= 4:
            return False
        f, side = self.f, self.side
        star = self.faces_of(vid)
        nbrs = np.unique(f[star])
        nbrs = nbrs[nbrs != vid]
        s = side[vid]
        for w in nbrs:
            w = int(w)
            if self.dirty[w]:
                continue
            if s >= 0 and not (side[w] == s or side[w] == 4 + s or side[w] == 4 + (s + 1) % 4):
                continue
            shared = star[(f[star] == w).any(axis=1)]
            if shared.size != (1 if s >= 0 else 2):
                continue  # a boundary vertex collapses along a boundary edge, an interior one inside
            # link condition: the common neighbours are the third vertices of the shared faces
            w_nbrs = np.unique(f[self.faces_of(w)])
            common = np.setdiff1d(np.intersect1d(nbrs, w_nbrs), [vid, w])
            third = np.setdiff1d(np.unique(f[shared]), [vid, w])
            if not np.array_equal(common, third):
                continue
            moved = np.setdiff1d(star, shared)
            new = np.where(f[moved] == vid, w, f[moved])
            if not (_signed_area2(self.v, new) > area_eps).all():
                continue
            f[moved] = new
            self.alive[shared] = False
            self.dead_v[vid] = True
            self.dirty[vid] = self.dirty[w] = True
            return True
        return False

    def compact(self):
        """(vertices, faces, side) without the removed vertices and faces."""
        keep = ~self.dead_v
        new = np.cumsum(keep) - 1
        return self.v[keep], new[self.f[self.alive]], self.side[keep]


# --------------------------------------------------------------------------- mesh helpers
def _signed_area2(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """(m,) twice the signed projected area of each face (positive: counter-clockwise)."""
    a = v[f[:, 0], :2]
    b = v[f[:, 1], :2]
    c = v[f[:, 2], :2]
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])


def _line_distance(p, k: int, extent) -> float:
    xmin, xmax, ymin, ymax = extent
    return float((abs(p[1] - ymin), abs(p[0] - xmax), abs(p[1] - ymax), abs(p[0] - xmin))[k])


class _Stars:
    """The faces around each vertex (CSR layout): ``star.of(i)`` is an index array."""

    def __init__(self, f: np.ndarray, n: int):
        flat = f.ravel()
        self.fidx = np.argsort(flat, kind="stable") // 3
        self.starts = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=n))])

    def of(self, i: int) -> np.ndarray:
        return self.fidx[self.starts[i] : self.starts[i + 1]]


def _boundary_loop(f: np.ndarray, n: int, backend: str) -> np.ndarray:
    """Vertex ids of the single boundary loop of a disk, counter-clockwise.

    Raises SimplificationError when the mesh is not a triangulated disk (an edge shared by
    more than two faces, inconsistent orientation, a pinched vertex or several loops).
    """
    he = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(he[:, 0] * n + he[:, 1])
    if (np.diff(key) == 0).any():
        raise _PostError(f"qec ({backend} backend) produced a non-manifold or inconsistently oriented mesh")
    twin = he[:, 1] * n + he[:, 0]
    pos = np.minimum(np.searchsorted(key, twin), key.size - 1)
    bh = he[key[pos] != twin]  # half-edges without a twin
    if bh.shape[0] == 0 or np.bincount(bh[:, 0]).max() > 1:
        raise _PostError(f"qec ({backend} backend) produced a mesh whose boundary is not one simple loop")
    nxt = np.full(n, -1, dtype=np.int64)
    nxt[bh[:, 0]] = bh[:, 1]
    loop = np.empty(bh.shape[0], dtype=np.int64)
    length = _walk_loop(nxt, int(bh[:, 0].min()), loop)
    n_edges = (3 * f.shape[0] + bh.shape[0]) // 2
    euler = n - n_edges + f.shape[0]
    if length != bh.shape[0] or euler != 1:
        raise _PostError(
            f"qec ({backend} backend) produced a mesh that is not a disk "
            f"({bh.shape[0]} boundary edges, {length} in the first loop, Euler characteristic {euler})"
        )
    return loop


@nb.njit(cache=True, nogil=True)
def _walk_loop(nxt, start, out):
    """Follow ``nxt`` from ``start`` until it returns to ``start``; the loop length (or -1)."""
    k = 0
    cur = start
    while True:
        if k >= out.shape[0] or cur < 0:
            return -1
        out[k] = cur
        k += 1
        cur = nxt[cur]
        if cur == start:
            return k


def _self_check(tin: TIN, grid: HeightGrid, budget: int, tol: int, backend: str) -> None:
    """Raise SimplificationError unless ``tin`` is a valid height field over the grid's extent.

    The same rules as :func:`simplifiers.registry.check_height_field`, checked the cheap
    way: a disk whose faces are all counter-clockwise, whose boundary loop lies on the
    four boundary lines and whose projected area is the extent's covers the extent once.
    """
    v = tin.vertices
    f = tin.faces.astype(np.int64)
    xmin, xmax, ymin, ymax = grid.extent
    problems = []
    for cx, cy in ((xmin, ymin), (xmax, ymin), (xmin, ymax), (xmax, ymax)):
        if not ((v[:, 0] == cx) & (v[:, 1] == cy)).any():
            problems.append(f"corner ({cx:g}, {cy:g}) is missing")
    if ((v[:, 0] < xmin) | (v[:, 0] > xmax) | (v[:, 1] < ymin) | (v[:, 1] > ymax)).any():
        problems.append("vertices lie outside the extent")
    area2 = _signed_area2(v, f)
    if not (area2 > 0).all():
        problems.append(f"{int((area2 <= 0).sum())} faces fold over")
    area = (xmax - xmin) * (ymax - ymin)
    if abs(0.5 * area2.sum() - area) > 1e-9 * area:
        problems.append(f"the projected area is {0.5 * area2.sum() / area:.6%} of the extent's")
    try:
        loop = _boundary_loop(f, v.shape[0], backend)
    except _PostError as exc:
        problems.append(str(exc))
    else:
        b = v[loop]
        on_line = (b[:, 0] == xmin) | (b[:, 0] == xmax) | (b[:, 1] == ymin) | (b[:, 1] == ymax)
        if not on_line.all():
            problems.append(f"{int((~on_line).sum())} boundary vertices lie off the boundary lines")
    if abs(v.shape[0] - budget) > tol:
        problems.append(f"it has {v.shape[0]} vertices for a budget of {budget}")
    if problems:
        raise SimplificationError(f"qec ({backend} backend) built an invalid height field: " + "; ".join(problems))
