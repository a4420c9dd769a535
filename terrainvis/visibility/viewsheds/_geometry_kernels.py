"""The viewshed sweep's records, constants and plane geometry (numba).

Part of the sweep's kernels, split by concern: this module (what every other part reads:
the records, the output codes, pseudo-angles, a point's height on the grid's surface),
:mod:`._walk_kernels` (the exact walk of a ray over the cells),
:mod:`._bound_kernels` (the wedges' upper and lower bounds, and the grid's tables) and
:mod:`._sector_kernels` (the sweep itself, sector by sector, which says how the parts
fit together). Kernels loop and never validate: :mod:`terrainvis.visibility.viewsheds.sweep`
checks the input, shifts coordinates to the grid's local origin and passes plain arrays.

Pseudo-angles
-------------
Directions are ordered by the diamond angle ``P`` in [0, 4) (east 0, north 1, west 2,
south 3), monotone in the true angle and cheap (one division). Quadrant ``Q`` holds
``P`` in [Q, Q + 1); near quadrant ``Q`` angles are unwrapped to [Q - 1.5, Q + 2.5)
(:func:`unwrap`) so that no cell of that quadrant wraps around.

Kernel arguments
----------------
The kernels read their state through named tuples built by
:mod:`terrainvis.visibility.viewsheds.sweep` (no function takes more than about ten
arguments):

* :data:`~terrainvis.core.surface.SurfaceGrid` the surface (the core's grid record:
  heights, NaN being nodata, local coordinate vectors from the grid's first sample,
  inverse widths, the strip maxima ``cmax``/``rmax`` of
  :func:`._bound_kernels.strip_max`, ``uniform``, ``has_nan``);
* :data:`Eye` the eye's cell ``(re, ce)`` and position ``(ex, ey, ez)``;
* :data:`Rules` the predicate's numbers and the bounds' margins (target height, trim,
  tolerance, rounding margin and error bound, exclusion radii, largest squared cell
  diagonal, maximum distance);
* :data:`Layout` the sectors and wedges (sectors, wedges near the eye, first refining
  ring, last edge-clipped ring, last ring);
* :data:`Targets` the targets and their output codes;
* :data:`Wedges` one sector's wedge bounds (``ubp``, ``ubold``, ``lb``, ``hist``, ``quads``, ``grp``).

A ray or segment is the 6-tuple ``(ex, ey, ez, dx, dy, dz)`` of the points
``E + t d``; a window of wedges is ``(glo, nloc, bsz)`` (first global wedge index held,
wedges held, wedges around the full turn); the limits of an edge update are
``(r_excl, r_lb, e_h, tolm)``.
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from ...core.compiling import KERNEL_ONLY
from ...core.surface import locate as _locate
from ...core.surface import tri_height
from ...tolerances import EDGE_CLIP_SLACK, PSEUDO_ANGLE_SLACK, SLOPE_REL

INF = np.inf

#: A ring index beyond every grid (the sector sweep's ``_box_exit`` of it is inf).
BEYOND = 1 << 40

# Arguments that are constants at a call site, as numpy scalars: numba compiles a function
# once for each literal (Python) int or bool it is called with, and once more for the
# plain type, so a literal argument cost a first run a second copy of the callee (and of
# every function inlined into it); a numpy scalar is typed as its plain type.
NO_END = np.int64(BEYOND)  # a walk to the end of the ray
NO_RING = np.int64(-1)  # no ring
UPPER = np.bool_(True)  # a cell's upper triangle
LOWER = np.bool_(False)
VERTICAL = np.int64(0)  # a grid line x = xs[c]
HORIZONTAL = np.int64(1)  # a grid line y = ys[r]

#: Codes of the sweep's output (int8 per sample).
BLOCKED = 0
VISIBLE = 1
UNDECIDED = 2
NOT_TARGET = 3

#: Relative slack on slopes (rounding of divisions and square roots, generously).
REL = SLOPE_REL
#: Pseudo-angle slack when a value is compared with a wedge boundary.
PEPS = PSEUDO_ANGLE_SLACK
#: Slack on clipping parameters along an edge.
LEPS = EDGE_CLIP_SLACK

#: The eye: its cell ``(re, ce)`` (ints) and its position ``(ex, ey, ez)`` (local coordinates).
Eye = namedtuple("Eye", ["re", "ce", "ex", "ey", "ez"])
#: The predicate's numbers and the bounds' margins (floats): ``ht`` target height above
#: the surface; ``delta`` trim length; ``tol`` clearance tolerance; ``marg`` the margin
#: kept from ``-tol`` by every decision; ``e_h`` bound of the absolute rounding error of a
#: computed height; ``r_excl`` radius around the eye inside every target's trimmed end;
#: ``r_lb`` smallest distance of a point used by a lower bound; ``diag2`` largest squared
#: cell diagonal; ``dmax`` maximum distance of a target (inf: none); ``kc`` the earth
#: curvature coefficient ``curvature / (2 R)`` (0: flat; :func:`terrainvis.visibility.curvature_coefficient`).
Rules = namedtuple("Rules", ["ht", "delta", "tol", "marg", "e_h", "r_excl", "r_lb", "diag2", "dmax", "kc"])
#: The sweep's layout (ints): ``nsec`` sectors (a multiple of 4), ``b0`` wedges near the
#: eye, ``r1`` first ring where the wedges double, ``jnear`` last ring clipped edge by
#: edge, ``jstop`` last ring swept.
Layout = namedtuple("Layout", ["nsec", "b0", "r1", "jnear", "jstop"])
#: The targets: ``own`` (bool) the grid's own samples, with ``code`` (rows, cols) int8
#: their codes; otherwise ``tx``, ``ty``, ``tz`` (m,) float64 (local coordinates, ``tz``
#: the target's height) sorted by :func:`._sector_kernels.bucket_targets` into ``tstart`` / ``torder``, with
#: ``tcode`` (m,) int8 their codes.
Targets = namedtuple("Targets", ["own", "code", "tx", "ty", "tz", "tstart", "torder", "tcode"])
#: One sector's wedge bounds, each (nfin + 2,) float64 (local wedge index i is global
#: ``s * n - 1 + i``): ``ubp`` upper bounds over the completed blocks of rings, ``ubold``
#: over the completed blocks older than the previous one, ``lb`` lower bounds of the
#: horizon over all rings swept, ``hist`` (blocks, nfin + 2) the upper bounds of each
#: completed block, ``quads`` (quads, nfin + 2) those of each quad of QUAD rings swept,
#: and ``grp`` (groups, nfin + 2) those of the old blocks (older than the previous one) of
#: each group of GROUP blocks. Each row is at the wedge resolution of its rings' level.
Wedges = namedtuple("Wedges", ["ubp", "ubold", "lb", "hist", "quads", "grp"])


# --------------------------------------------------------------------------- geometry
@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def diamond(dx, dy):
    """Diamond angle of the direction (dx, dy): monotone in the true angle, in [0, 4)."""
    if dy >= 0.0:
        if dx > 0.0:
            return dy / (dx + dy)
        if dy == 0.0:
            if dx == 0.0:
                return 0.0
            return 2.0
        return 1.0 - dx / (dy - dx)
    if dx <= 0.0:
        return 2.0 - dy / (-dx - dy)
    return 3.0 + dx / (dx - dy)


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def unwrap(p, q):
    """Pseudo-angle ``p`` unwrapped near quadrant ``q``: into [q - 1.5, q + 2.5)."""
    c = q + 0.5
    if p - c > 2.0:
        return p - 4.0
    if p - c < -2.0:
        return p + 4.0
    return p


@nb.njit(cache=True, nogil=True, error_model="numpy")
def direction(p):
    """A direction vector (not normalised) of pseudo-angle ``p`` (any real; taken mod 4)."""
    p = p % 4.0
    if p < 1.0:
        return 1.0 - p, p
    if p < 2.0:
        return 1.0 - p, 2.0 - p
    if p < 3.0:
        return p - 3.0, 2.0 - p
    return p - 3.0, p - 4.0


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def locate(v, iw, uniform, x):
    """Index i in [0, len(v) - 2] with v[i] <= x < v[i+1] (clamped); v local, from 0."""
    return _locate(v, iw, 0, v.shape[0] - 1, uniform, x)


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def _finite(v):
    return v == v and abs(v) < INF


@nb.njit(cache=True, nogil=True, error_model="numpy", **KERNEL_ONLY)
def tri_present(z, r, c, upper):
    """Whether the lower (u >= v) or upper triangle of cell (r, c) has no nodata vertex."""
    if not (_finite(z[r, c]) and _finite(z[r + 1, c + 1])):
        return False
    if upper:
        return _finite(z[r + 1, c])
    return _finite(z[r, c + 1])


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def plane_height(g, r, c, upper, x, y):
    """Height of the plane of one triangle of cell (r, c) at (x, y) (the core's
    :func:`~terrainvis.core.surface.tri_height`: the pair engine's cell height, not clamped)."""
    return tri_height(g.z, g.xs, g.ys, g.ixw, g.iyw, r, c, upper, x, y)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def surface_height(g, x, y):
    """Height of the surface of the :data:`~terrainvis.core.surface.SurfaceGrid` ``g`` at (x, y) (local
    coordinates), NaN on an absent triangle."""
    c = locate(g.xs, g.ixw, g.uniform, x)
    r = locate(g.ys, g.iyw, g.uniform, y)
    u = (x - g.xs[c]) * g.ixw[c]
    v = (y - g.ys[r]) * g.iyw[r]
    upper = v > u
    if not tri_present(g.z, r, c, upper):
        return np.nan
    return plane_height(g, r, c, upper, x, y)

