"""Height fields over a grid's extent: the rules a TIN must obey, and the repair that makes a mesh obey them.

A simplified terrain in TIN form must cover the grid's rectangle exactly once: its four
corners are vertices, no vertex lies outside, every face is counter-clockwise seen from
above, and the mesh is one disk whose boundary runs along the rectangle's sides.
:func:`height_field_problems` lists what a mesh breaks, each with where (the first folded
face's centre, the first vertex outside, a missing corner).

Mesh decimators do not keep a terrain's footprint: pymeshlab pulls the border in by a
fraction of a cell (or freezes every border vertex), fast-simplification and
meshoptimizer move corners away, and all can leave faces folded over in projection.
:func:`repair_tin` (built on :class:`PostProcessor`, which :mod:`simplifiers.quadric`
runs on every decimated mesh) repairs such a mesh and reports what it changed:

1. **Boundary snapping.** The boundary loop of the decimated disk is split into four
   chains by the four corners. A boundary vertex within ``corner_tol`` of a corner
   becomes that corner exactly; a corner with no such vertex is *inserted* with one ear
   triangle (its height is the grid sample there). Every other boundary vertex is moved
   onto its chain's boundary line (the coordinate across the line is set exactly; its
   height is kept); a chain whose order along its line came out reversed somewhere takes
   its own coordinates in sorted order (``reordered``). Boundary vertices can therefore
   slide and collapse along the border, which is what a 1.5 % budget needs.
2. **Fold-over repair.** For each face whose projected (signed) area is not positive, one
   of its vertices is moved into the kernel of its star (the set of positions where all
   its faces are counter-clockwise; a 2-D linear programme, the Chebyshev centre, and
   then the closest point on the way to it with a margin). A boundary vertex moves only
   along its line and a corner never moves. A moved vertex takes the grid's height at its
   new position. When no vertex of a bad face can be moved, the face is removed by a
   half-edge collapse of one of its vertices (a last resort, counted in ``collapses``).
3. **Finishing collapses.** :meth:`PostProcessor.remove_vertices` removes a few more
   vertices by valid half-edge collapses, flattest vertex (umbrella operator) first: the
   caller's last resort when a library cannot get closer to a vertex budget.

Everything here works in world coordinates on plain arrays; the mesh helpers (signed
areas, edge keys, the boundary loop) come from :mod:`terrainvis.core.mesh`.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SimplificationError
from ..tolerances import DIVISOR_FLOOR, FACE_AREA_REL, STAR_MARGIN_MIN
from .mesh import NotADiskError, boundary_loop, edge_keys, footprint_matches, half_edges, signed_area2
from .terrain import TIN, HeightGrid

__all__ = ["reversed_winding", "repair_summary", "PostError", "PostProcessor", "height_field_problems", "repair_tin"]

# side codes of a vertex: INTERIOR, k in 0..3 on side k (from corner k to corner k+1,
# counter-clockwise from (xmin, ymin)), CORNER + k for corner k
INTERIOR = -1
CORNER = 4


class PostError(SimplificationError):
    """A mesh could not be repaired into a valid height field (the message says why)."""


class PostProcessor:
    """Snap the boundary of a decimated mesh onto a grid's extent and repair fold-overs.

    Parameters
    ----------
    grid : HeightGrid
        The terrain: its extent is the target footprint, and inserted corners and
        relocated vertices take its heights.
    corner_tol : float
        A boundary vertex closer than this many (smallest) grid spacings to a corner
        becomes that corner.

    Examples
    --------
    A 3x3 grid's TIN whose middle bottom vertex drifted off the border (and outside it):

    >>> import numpy as np
    >>> from terrainvis import HeightGrid
    >>> grid = HeightGrid(np.arange(9.0).reshape(3, 3), dx=1.0, dy=1.0)
    >>> tin = grid.to_tin()
    >>> v = tin.vertices.copy()
    >>> v[1, :2] = [1.2, -0.1]
    >>> out_v, out_f, side, stats = PostProcessor(grid, corner_tol=0.25).run(v, tin.faces, "example")
    >>> out_v[1].tolist(), int(side[1]), stats["snapped"], stats["repairs"]
    ([1.2, 0.0, 1.0], 0, 1, 0)
    """

    def __init__(self, grid: HeightGrid, corner_tol: float):
        self.grid = grid
        xmin, xmax, ymin, ymax = grid.extent
        self.extent = (xmin, xmax, ymin, ymax)
        # corner k and the line of side k (from corner k to corner k+1, counter-clockwise)
        self.corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
        self.corner_tol = corner_tol * min(float(np.diff(grid.xs).min()), float(np.diff(grid.ys).min()))
        span = max(xmax - xmin, ymax - ymin)
        self.area_eps = FACE_AREA_REL * span * span  # twice-area threshold for a face to count as positive

    # ---------------------------------------------------------------- main
    def run(self, vertices: np.ndarray, faces: np.ndarray, backend: str):
        """Post-process one decimated mesh given in world coordinates.

        Parameters
        ----------
        vertices : (n, 3) float64
            The decimated mesh's vertices (not modified).
        faces : (m, 3) int
            Its faces; every vertex must be used.
        backend : str
            What produced the mesh, named in error messages (``"qec (pymeshlab backend)"``).

        Returns
        -------
        vertices : (n', 3) float64
        faces : (m', 3) int64
            The repaired mesh: counter-clockwise faces covering the extent once.
        side : (n',) int64
            -1 for an interior vertex, k in 0..3 for a vertex on side k, 4 + k for corner k.
        stats : dict
            ``snapped``, ``max_snap``, ``corners_inserted``, ``reordered``, ``repairs``,
            ``collapses`` and ``boundary`` (the number of boundary vertices).

        Raises
        ------
        PostError
            When the mesh is not a disk, its boundary misses the corners' order, or some
            fold-over cannot be repaired.
        """
        # no copies here (a copy of a 3601² level-1 mesh is large): _snap and the repair make their own
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        try:
            loop = boundary_loop(f, v.shape[0])
        except NotADiskError as exc:
            raise PostError(f"{backend} produced a mesh that is not a disk: {exc}") from None
        # a library never flips the whole mesh, but make sure rather than trust it: the faces'
        # signed areas sum to the boundary loop's (shoelace), which is cheaper to compute
        p, q = v[loop, :2], v[np.roll(loop, -1), :2]
        if (p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]).sum() < 0:
            f = f[:, ::-1]
            loop = loop[::-1]
        v, f, side, stats = self._snap(v, f, loop, backend)
        v, f, side, repairs, collapses = self._repair(v, f, side, backend)
        stats.update(repairs=repairs, collapses=collapses, boundary=int((side >= 0).sum()))
        return v, f, side, stats

    # ---------------------------------------------------------------- snapping
    def _corner_positions(self, P: np.ndarray, backend: str):
        """Where each corner sits on the boundary loop ``P`` (loop order), and which to insert."""
        L = P.shape[0]
        corner_at = []  # (position in the loop, inserted?) of each corner
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
                corner_at.append(((j + 1) % L if inc <= out else j, True))
        # the corners must appear in counter-clockwise order along the loop
        start = corner_at[0][0]
        rel = [(p - start) % L for p, _ in corner_at]
        # (an inserted corner may share its position with the next, existing, corner)
        ok = all(
            rel[i] < rel[i + 1] or (rel[i] == rel[i + 1] and corner_at[i][1] and not corner_at[i + 1][1])
            for i in range(3)
        )
        existing = [p for p, ins in corner_at if not ins]
        if not ok or len(set(existing)) != len(existing):
            raise PostError(
                f"{backend}: the boundary does not pass the four corners in order "
                f"(corner positions along the boundary loop: {rel})"
            )
        return corner_at, start, rel

    def _snap(self, v, f, loop, backend):
        xmin, xmax, ymin, ymax = self.extent
        L = loop.size
        corner_at, start, rel = self._corner_positions(v[loop, :2], backend)
        # side of every loop vertex: the chain from corner k to corner k+1 lies on side k
        side_loop = np.empty(L, dtype=np.int64)
        bounds = rel + [L]
        chains = []
        for k in range(4):
            first = bounds[k] + (0 if corner_at[k][1] else 1)  # an existing corner is not in the chain
            side_loop[(start + np.arange(bounds[k], bounds[k + 1])) % L] = k
            chains.append((start + np.arange(first, bounds[k + 1])) % L)
        side = np.full(v.shape[0], INTERIOR, dtype=np.int64)
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
                side[vid] = CORNER + k
        snapped = int((moves > 0).sum())
        max_snap = float(moves.max()) if moves.size else 0.0
        # insert the missing corners with one ear triangle each: (prev, corner, next)
        extra_v, extra_f, inserted = [], [], []
        n = new_v.shape[0]
        rows, cols = self.grid.shape
        for k, (p, ins) in enumerate(corner_at):
            if not ins:
                continue
            a = int(loop[(p - 1) % L])
            b = int(loop[p % L])
            cid = n + len(extra_v)
            r = 0 if k in (0, 1) else rows - 1
            c = 0 if k in (0, 3) else cols - 1
            extra_v.append([self.corners[k][0], self.corners[k][1], float(self.grid.z[r, c])])
            extra_f.append([a, cid, b])
            inserted.append(k)
        if extra_v:
            new_v = np.vstack([new_v, np.array(extra_v)])
            f = np.vstack([f, np.array(extra_f, dtype=np.int64)])
            side = np.concatenate([side, CORNER + np.array(inserted, dtype=np.int64)])
        else:
            f = f.copy()  # the caller's array: the repair changes faces in place
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
        area2 = signed_area2(v, f)
        if (area2 > self.area_eps).all():
            return v, f, side, 0, 0  # nothing folds over (the usual case): no stars to build
        mesh = LazyMesh(v, f, side, copy=False, stars=False)  # the arrays _snap made
        for _ in range(100):
            if area2 is None:
                area2 = signed_area2(mesh.v, mesh.f)
            bad = np.flatnonzero(mesh.alive & (area2 <= self.area_eps))
            area2 = None  # stale after this round's moves
            if bad.size == 0:
                v, f, side = mesh.compact()
                return v, f, side, repairs, collapses
            mesh.rebuild(active=np.unique(mesh.f[bad]))
            n_bad = np.bincount(mesh.f[bad].ravel(), minlength=mesh.v.shape[0])
            progress = False
            for fi in bad:
                if not mesh.alive[fi] or signed_area2(mesh.v, mesh.f[fi : fi + 1])[0] > self.area_eps:
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
        area2 = signed_area2(mesh.v, mesh.f)
        nbad = int((mesh.alive & (area2 <= self.area_eps)).sum())
        raise PostError(
            f"{backend}: {nbad} faces still fold over after {repairs} relocations and "
            f"{collapses} collapses"
        )

    @staticmethod
    def _order_candidates(f, fi, side, n_bad):
        """The movable vertices of face ``fi``: the one in most bad faces first (the vertex that
        caused the fold), then interior before boundary (two degrees of freedom), then by id."""
        cand = [int(x) for x in f[fi] if side[x] < CORNER]  # corners never move
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
        scale = max(float(np.abs(np.concatenate([A.ravel(), B.ravel()])).max()), DIVISOR_FLOOR)
        if s == INTERIOR:
            from scipy.optimize import linprog

            norm = np.hypot(n[:, 0], n[:, 1])
            A_ub = np.column_stack([-n / scale, norm / scale])
            b_ub = -c / scale**2
            bounds = [(xmin - p0[0]) / scale, (xmax - p0[0]) / scale], [(ymin - p0[1]) / scale, (ymax - p0[1]) / scale]
            res = linprog(
                [0.0, 0.0, -1.0], A_ub=A_ub, b_ub=b_ub,
                bounds=[tuple(bounds[0]), tuple(bounds[1]), (None, 1.0)], method="highs",
            )
            if res.status != 0 or res.x[2] <= STAR_MARGIN_MIN:
                return None
            centre = res.x[:2] * scale
            # the closest point on the way to the centre that leaves every face a margin
            for t in (0.125, 0.25, 0.5, 0.75, 1.0):
                q = t * centre
                if (n @ q - c > max(self.area_eps, 0.05 * t * res.x[2] * scale * norm.min())).all():
                    return p0 + q
            return p0 + centre
        # a boundary vertex slides along its side: p = p0 + u * e
        e = np.array([1.0, 0.0]) if s in (0, 2) else np.array([0.0, 1.0])
        lo_b, hi_b = (xmin, xmax) if s in (0, 2) else (ymin, ymax)
        u0 = p0[0] if s in (0, 2) else p0[1]
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

    # ---------------------------------------------------------------- finishing
    def remove_vertices(self, v, f, side, count):
        """Remove up to ``count`` vertices by valid half-edge collapses, flattest first.

        The last resort when the library cannot reach the budget: in each round the
        non-corner vertices are tried in order of how close their height is to the mean
        of their neighbours' (the umbrella operator), and every valid collapse is made.
        Returns ``(vertices, faces, side, removed)``.
        """
        removed = 0
        mesh = LazyMesh(v, f, side)
        n = mesh.v.shape[0]
        while removed < count:
            key = np.unique(edge_keys(half_edges(mesh.f[mesh.alive]), n))
            e0, e1 = key // n, key % n
            deg = np.bincount(e0, minlength=n) + np.bincount(e1, minlength=n)
            zsum = np.bincount(e0, mesh.v[e1, 2], n) + np.bincount(e1, mesh.v[e0, 2], n)
            flat = np.abs(mesh.v[:, 2] - zsum / np.maximum(deg, 1))
            flat[mesh.dead_v | (mesh.side >= CORNER)] = np.inf
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


class LazyMesh:
    """A mesh under half-edge collapses and vertex moves (a private copy of the arrays, unless
    ``copy=False`` hands them over).

    Removed faces are only marked dead and removed vertices are dropped by
    :meth:`compact`, so indices stay valid; the stars (faces around each vertex) are
    rebuilt between rounds by :meth:`rebuild`, and a vertex whose star changed in the
    current round is *dirty*: it neither moves nor takes part in a collapse until then.
    """

    def __init__(self, v, f, side, *, copy: bool = True, stars: bool = True):
        self.v = np.array(v, dtype=np.float64, copy=copy)
        self.f = np.array(f, dtype=np.int64, copy=copy)
        self.side = np.array(side, dtype=np.int64, copy=copy)
        self.alive = np.ones(self.f.shape[0], dtype=bool)
        self.dead_v = np.zeros(self.v.shape[0], dtype=bool)
        if stars:  # else the caller builds them (rebuild) before the first query
            self.rebuild()

    def rebuild(self, active=None):
        """Build the stars: of every vertex, or only of the ``active`` vertices and their neighbours.

        The stars are a CSR index over the faces; restricted to a few vertices (the repair
        touches only vertices of folded faces) they cost two passes over the faces instead
        of a sort of them all (O(faces) instead of O(faces log faces)).
        """
        n = self.v.shape[0]
        if active is None:
            sel = None
            self._covered = None
        else:
            near = np.flatnonzero(np.isin(self.f, active).any(axis=1))
            self._covered = np.zeros(n, dtype=bool)
            self._covered[self.f[near].ravel()] = True  # the active vertices and their neighbours
            sel = np.flatnonzero(self._covered[self.f].any(axis=1))
        flat = (self.f if sel is None else self.f[sel]).ravel()
        order = np.argsort(flat, kind="stable") // 3
        self._star_faces = order if sel is None else sel[order]
        self._star_start = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=n))])
        self.dirty = np.zeros(n, dtype=bool)

    def faces_of(self, i: int) -> np.ndarray:
        """Indices of the live faces around vertex ``i`` (as of the last rebuild, plus moves)."""
        if self._covered is not None and not self._covered[i]:
            idx = np.flatnonzero((self.f == i).any(axis=1))  # outside the built stars: scan
        else:
            idx = self._star_faces[self._star_start[i] : self._star_start[i + 1]]
        return idx[self.alive[idx]]

    def collapse(self, vid: int, area_eps: float) -> bool:
        """Half-edge collapse of ``vid`` into a neighbour, if one is valid.

        A boundary vertex collapses only along its side (into a neighbour on the same
        line, a corner included). The faces that move to the neighbour must all stay
        counter-clockwise, and the link condition must hold (no non-manifold edge).
        """
        if self.dirty[vid] or self.dead_v[vid] or self.side[vid] >= CORNER:
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
            if s >= 0 and not (side[w] == s or side[w] == CORNER + s or side[w] == CORNER + (s + 1) % 4):
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
            if not (signed_area2(self.v, new) > area_eps).all():
                continue
            f[moved] = new
            self.alive[shared] = False
            self.dead_v[vid] = True
            self.dirty[vid] = self.dirty[w] = True
            return True
        return False

    def compact(self):
        """(vertices, faces, side) without the removed vertices and faces."""
        if self.alive.all() and not self.dead_v.any():
            return self.v, self.f, self.side
        keep = ~self.dead_v
        new = np.cumsum(keep) - 1
        return self.v[keep], new[self.f[self.alive]], self.side[keep]


def _line_distance(p, k: int, extent) -> float:
    """Distance from point ``p`` to the line of side ``k`` of ``extent``."""
    xmin, xmax, ymin, ymax = extent
    return float((abs(p[1] - ymin), abs(p[0] - xmax), abs(p[1] - ymax), abs(p[0] - xmin))[k])


# ---------------------------------------------------------------------- the rules and the public repair
def height_field_problems(tin, grid, *, budget: int | None = None) -> list[str]:
    """What keeps ``tin`` from being a valid height field over ``grid``'s extent, each with where; [] when valid.

    The rules: the four corners are vertices and no vertex lies outside the extent; every
    face is counter-clockwise in projection; every vertex belongs to a face; the mesh is
    one triangulated disk (every edge shared by at most two faces, consistently oriented,
    one boundary loop) whose boundary edges all lie on the four boundary lines; the
    projected area equals the extent's; and, with ``budget``, the vertex count is within
    :func:`simplifiers.levels.budget_tolerance` of it.

    Together these mean the TIN covers the extent exactly once: with every face
    counter-clockwise, the number of faces over a point equals the winding number of the
    boundary loop around it. A loop running along the rectangle's sides has one winding
    number k everywhere inside, and the area rule makes k = 1. So no grid sample needs to
    be located to check coverage.

    Parameters
    ----------
    tin : TIN
    grid : HeightGrid
        Its extent is the footprint the TIN must cover.
    budget : int, optional

    Returns
    -------
    list of str
        One entry per broken rule, the first offender's position in the grid's
        coordinates: ``"corner (0, 3570) is missing"``, ``"12 vertices lie outside the
        extent (the first at (3581.2, 40))"``, ``"3 of 5,102 faces fold over (not
        counter-clockwise; the first around (1210.5, 877.3))"``, ...
    """
    xmin, xmax, ymin, ymax = grid.extent
    v = tin.vertices
    problems = []
    for cx, cy in ((xmin, ymin), (xmax, ymin), (xmin, ymax), (xmax, ymax)):
        if not ((v[:, 0] == cx) & (v[:, 1] == cy)).any():
            problems.append(f"corner ({cx:g}, {cy:g}) is missing")
    outside = (v[:, 0] < xmin) | (v[:, 0] > xmax) | (v[:, 1] < ymin) | (v[:, 1] > ymax)
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        problems.append(f"{int(outside.sum())} vertices lie outside the extent (the first at ({v[k, 0]:.6g}, "
                        f"{v[k, 1]:.6g}))")
    area2 = signed_area2(v, tin.faces)
    bad = area2 <= 0
    if (area2 < 0).all():
        problems.append(f"every face ({area2.size:,}) is wound clockwise: the mesh's orientation is reversed (rows "
                        "going down), not folded; reversing its faces makes it counter-clockwise")
    elif bad.any():
        f = int(np.flatnonzero(bad)[0])
        cx, cy = v[tin.faces[f], :2].mean(axis=0)
        problems.append(f"{int(bad.sum())} of {area2.size:,} faces fold over (not counter-clockwise; the first "
                        f"around ({cx:.6g}, {cy:.6g}))")
    area = (xmax - xmin) * (ymax - ymin)
    if not footprint_matches(0.5 * abs(area2.sum()) if (area2 < 0).all() else 0.5 * area2.sum(), area):
        problems.append(f"the projected area is {0.5 * area2.sum() / area:.6%} of the extent's")
    _, first, counts = np.unique(v[:, :2], axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():  # a disk's check below would only say "not a disk"
        k = int(first[np.flatnonzero(counts > 1)[0]])
        problems.append(f"{int((counts - 1).sum())} vertices share their x, y with another vertex (the first at "
                        f"({v[k, 0]:.6g}, {v[k, 1]:.6g})): a height field has one vertex, and one height, per point; "
                        "split vertices (one per face) must be merged")
    used = np.zeros(tin.n_vertices, dtype=bool)
    used[tin.faces.ravel()] = True
    if not used.all():
        k = int(np.flatnonzero(~used)[0])
        problems.append(f"{int((~used).sum())} vertices belong to no face (the first at ({v[k, 0]:.6g}, "
                        f"{v[k, 1]:.6g}))")
    else:
        try:
            loop = boundary_loop(tin.faces, tin.n_vertices)
        except NotADiskError as exc:
            problems.append(str(exc))
        else:
            p, q = v[loop], v[np.roll(loop, -1)]
            on_line = (
                ((p[:, 0] == xmin) & (q[:, 0] == xmin)) | ((p[:, 0] == xmax) & (q[:, 0] == xmax))
                | ((p[:, 1] == ymin) & (q[:, 1] == ymin)) | ((p[:, 1] == ymax) & (q[:, 1] == ymax))
            )
            if not on_line.all():
                k = int(np.flatnonzero(~on_line)[0])
                problems.append(f"{int((~on_line).sum())} boundary edges lie off the boundary lines (the first from "
                                f"({p[k, 0]:.6g}, {p[k, 1]:.6g}))")
    if budget is not None:
        tol = max(1, int(_budget_window() * budget))
        if abs(tin.n_vertices - budget) > tol:
            problems.append(f"it has {tin.n_vertices} vertices for a budget of {budget} +- {tol}")
    return problems


def reversed_winding(tin) -> bool:
    """Whether every face of ``tin`` is wound clockwise in projection: the other orientation of
    one consistent mesh (a raster's rows written going down), not a fold."""
    return bool((signed_area2(tin.vertices, tin.faces) < 0).all())


def repair_summary(record: dict) -> str:
    """One line of what :func:`repair_tin` (or a reversed winding) changed: ``"319 boundary vertices
    snapped onto the sides (by up to 204.5), 4 corners inserted, 6 vertices collapsed"``; "" for nothing.

    >>> repair_summary({"snapped": 2, "max_snap": 0.25, "corners_inserted": 1, "repairs": 0, "collapses": 0})
    '2 boundary vertices snapped onto the sides (by up to 0.25), 1 corner inserted'
    """
    parts = []
    if record.get("merged"):
        parts.append(f"{record['merged']} repeated vertices merged (the mesh was written face by face)")
    if record.get("reversed"):
        parts.append("faces reversed (the mesh was wound clockwise)")
    if record.get("unused_removed"):
        parts.append(f"{record['unused_removed']} vertices of no face removed")
    if record.get("snapped"):
        parts.append(f"{record['snapped']} boundary vertices snapped onto the sides (by up to {record['max_snap']:.4g})")
    if record.get("corners_inserted"):
        n = record["corners_inserted"]
        parts.append(f"{n} corner{'s' if n != 1 else ''} inserted")
    if record.get("reordered"):
        parts.append(f"the order along {record['reordered']} side(s) restored")
    if record.get("repairs"):
        parts.append(f"{record['repairs']} vertices moved to unfold faces")
    if record.get("collapses"):
        parts.append(f"{record['collapses']} vertices collapsed")
    return ", ".join(parts)


def _budget_window() -> float:
    from ..tolerances import BUDGET_WINDOW_REL

    return BUDGET_WINDOW_REL


def repair_tin(tin, grid: HeightGrid, *, corner_tol: float = 0.5, source: str = "the mesh") -> TIN:
    """A mesh made into a valid height field over ``grid``'s extent, with a record of what changed.

    What :mod:`simplifiers.quadric` does to every mesh a decimation library returns, for
    any mesh (:class:`PostProcessor`): boundary vertices are snapped onto the rectangle's
    sides (within ``corner_tol`` grid spacings of a corner: onto the corner), missing
    corners are inserted with the grid's heights, folded faces are repaired by moving a
    vertex into the kernel of its star (taking the grid's height there) or, as a last
    resort, by collapsing it. A mesh that is not one disk (holes, non-manifold edges,
    several pieces) cannot be repaired.

    Parameters
    ----------
    tin : TIN or (vertices, faces)
        The mesh, in the grid's coordinates. Never modified.
    grid : HeightGrid
        The terrain whose extent the result covers (and whose heights inserted or moved
        vertices take).
    corner_tol : float
        How close (in grid spacings) a boundary vertex must be to a corner to become it.
    source : str
        What produced the mesh, named in error messages.

    Returns
    -------
    TIN
        ``attrs`` keeps the input's and adds ``repair``: ``snapped`` (boundary vertices
        moved onto a side), ``max_snap`` (the farthest such move), ``corners_inserted``,
        ``reordered`` (sides whose order along the line was restored), ``repairs``
        (vertices moved to unfold faces), ``collapses`` (vertices removed) and
        ``unused_removed`` (vertices that belonged to no face).

    Raises
    ------
    PostError
        A :class:`~terrainvis.errors.SimplificationError` saying why the mesh cannot be
        repaired.

    Examples
    --------
    >>> import numpy as np
    >>> from terrainvis import HeightGrid
    >>> grid = HeightGrid(np.arange(9.0).reshape(3, 3), dx=1.0, dy=1.0)
    >>> t = grid.to_tin()
    >>> v = t.vertices.copy()
    >>> v[1, :2] = [1.2, -0.1]  # a border vertex drifted outside
    >>> for problem in height_field_problems(TIN(v, t.faces), grid):
    ...     print(problem)
    1 vertices lie outside the extent (the first at (1.2, -0.1))
    the projected area is 102.500000% of the extent's
    2 boundary edges lie off the boundary lines (the first from (0, 0))
    >>> fixed = repair_tin(TIN(v, t.faces), grid)
    >>> height_field_problems(fixed, grid), fixed.attrs["repair"]["snapped"]
    ([], 1)
    """
    if isinstance(tin, TIN):
        vertices, faces, attrs = tin.vertices, tin.faces, dict(tin.attrs)
    else:
        vertices, faces = tin
        vertices, faces, attrs = np.asarray(vertices, dtype=np.float64), np.asarray(faces), {}
    if not isinstance(grid, HeightGrid):
        raise TypeError(f"grid must be a terrainvis.HeightGrid, got {type(grid).__name__}")
    used = np.zeros(vertices.shape[0], dtype=bool)
    used[np.asarray(faces).ravel()] = True
    unused = int((~used).sum())
    if unused:
        remap = np.cumsum(used) - 1
        vertices, faces = vertices[used], remap[np.asarray(faces)]
    v, f, _, stats = PostProcessor(grid, corner_tol).run(vertices, faces, source)
    record = {k: (float(val) if isinstance(val, float) else int(val)) for k, val in stats.items() if k != "boundary"}
    record["unused_removed"] = unused
    out = TIN(v, f, attrs={**attrs, "repair": record})
    problems = height_field_problems(out, grid)
    if problems:
        raise PostError(f"{source} could not be repaired into a height field: {problems[0]}")
    return out
