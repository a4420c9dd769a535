"""How far a simplified surface is from the original: vertical errors and the volume between.

These measurements sit beside the surfaces, below the simplifiers: :func:`simplifiers.simplify`
records ``max_error`` and ``rms_error`` with :func:`vertical_errors`, and the comparison
runner adds :func:`volume_error`.
"""

from __future__ import annotations

import math

import numpy as np

from . import _volume_kernels
from .interrupt import call
from .mesh import boundary_edges, footprint_matches
from .validate import describe
from .terrain import TIN, HeightGrid
from ..tolerances import COVER_EDGE_CELL_REL, EXTENT_MATCH_REL

__all__ = ["vertical_errors", "volume_error"]


def vertical_errors(fine: HeightGrid, coarse) -> tuple[float, float]:
    """Maximum and RMS vertical error of ``coarse`` against the samples of ``fine``.

    Parameters
    ----------
    fine : HeightGrid
        The original terrain (nodata samples are ignored).
    coarse : HeightGrid or TIN
        A simplification covering the same extent.

    Returns
    -------
    (max_error, rms_error) : (float, float)
        Over every finite sample of ``fine``: max |coarse(x, y) - z| and its RMS.
    """
    _check_pair(fine, coarse)
    # a coarse terrain read back from a file may end a little short of the fine one's extent
    # (COVER_EDGE_CELL_REL): samples that close are on its edge
    xmin, xmax, ymin, ymax = coarse.extent
    slack = COVER_EDGE_CELL_REL * _cell(coarse)
    approx = coarse.height_on_grid(_onto(fine.xs, xmin, xmax, slack), _onto(fine.ys, ymin, ymax, slack))
    if fine.n_nodata:
        valid = np.isfinite(fine.z)
        approx = approx[valid]
        z = fine.z[valid]
    else:  # every sample counts: no masked copies (0.29-0.36 s with them on 3601², 0.11-0.12 s without)
        approx = approx.ravel()
        z = fine.z.ravel()
    uncovered = int(np.count_nonzero(np.isnan(approx)))
    if uncovered:
        raise ValueError(f"coarse must cover the fine grid, but {uncovered} fine samples fall outside it")
    diff = np.subtract(approx, z, out=approx)  # approx is this call's own array
    np.abs(diff, out=diff)
    worst = float(diff.max())
    np.square(diff, out=diff)  # the squares of the differences, as diff**2 gives them
    return worst, float(np.sqrt(np.mean(diff)))


def _cell(terrain) -> float:
    """A cell of ``terrain``: a grid's smaller mean spacing, a TIN's mean vertex spacing."""
    if isinstance(terrain, HeightGrid):
        return float(min(terrain.dx, terrain.dy))
    xmin, xmax, ymin, ymax = terrain.extent
    return math.sqrt(max((xmax - xmin) * (ymax - ymin), 0.0) / max(terrain.n_vertices, 1))


def _onto(v: np.ndarray, lo: float, hi: float, slack: float) -> np.ndarray:
    """``v`` with the values outside ``[lo, hi]`` by at most ``slack`` put on ``lo`` or ``hi``."""
    v = np.array(v, dtype=np.float64, copy=True)
    v[(v < lo) & (v >= lo - slack)] = lo
    v[(v > hi) & (v <= hi + slack)] = hi
    return v


def _check_pair(fine, coarse) -> None:
    if not isinstance(fine, HeightGrid):
        raise TypeError(f"fine must be a terrainvis.HeightGrid, got {describe(fine)}")
    if not isinstance(coarse, (HeightGrid, TIN)):
        raise TypeError(f"coarse must be a terrainvis.HeightGrid or terrainvis.TIN, got {describe(coarse)}")


def _solid(vertices: np.ndarray, faces: np.ndarray, floor: float):
    """A closed manifold: the surface, a floor copy of it at ``floor``, and vertical walls."""
    import manifold3d

    n = vertices.shape[0]
    bottom = vertices.copy()
    bottom[:, 2] = floor
    # faces are counter-clockwise, so the footprint lies to the left of each boundary edge
    boundary = boundary_edges(faces, n)
    a, b = boundary[:, 0], boundary[:, 1]
    walls = np.concatenate([np.column_stack([b, a, a + n]), np.column_stack([b, a + n, b + n])])
    tris = np.concatenate([faces, faces[:, ::-1] + n, walls]).astype(np.uint64)
    mesh = manifold3d.Mesh64(np.ascontiguousarray(np.vstack([vertices, bottom])), np.ascontiguousarray(tris))
    solid = manifold3d.Manifold(mesh)
    if solid.status() != manifold3d.Error.NoError:
        raise ValueError(f"could not build a closed solid from the terrain: {solid.status()}")
    return solid


#: The methods of :func:`volume_error`.
VOLUME_METHODS = ("exact", "manifold")


def volume_error(fine: HeightGrid, coarse, *, method: str = "exact") -> float:
    """Volume between the fine surface and a simplified one (a shape error, in units³).

    For two height fields over the same footprint this is the integral of
    ``|coarse(x, y) - fine(x, y)|`` over the footprint; divided by the footprint area it
    is the mean absolute vertical error.

    Parameters
    ----------
    fine : HeightGrid
        The original terrain (no nodata), uniform or rectilinear. Its surface splits each
        cell along the (r, c)-(r+1, c+1) diagonal.
    coarse : HeightGrid or TIN
        A simplification over the same extent: a grid (no nodata; rectilinear grids such
        as reverse Faber results with a wider last gap are fine) or a TIN whose faces are
        counter-clockwise and cover the footprint of ``fine``.
    method : {"exact", "manifold"}
        ``"exact"`` (the default) integrates ``|coarse - fine|`` in closed form on every
        piece of the overlay of the two triangulations (numba, parallel over the coarse
        faces, in a local origin, with compensated sums). ``"manifold"`` turns each
        terrain into a closed solid with manifold3d (its surface, vertical walls along the
        footprint boundary and a flat floor below both) and returns the volume of the
        symmetric difference, ``vol(A) + vol(B) - 2 vol(A and B)``: the independent
        reference, tens of times slower and far larger in memory.

    Returns
    -------
    float
        The volume, in (x, y units)² times z units.

    Raises
    ------
    TypeError
        When ``fine`` is not a HeightGrid or ``coarse`` is neither a HeightGrid nor a TIN.
    ValueError
        When ``method`` is unknown, ``coarse`` does not cover the extent or the footprint
        of ``fine``, or a face of ``coarse`` is clockwise.
    terrainvis.errors.NodataError
        When ``fine`` or a ``coarse`` grid holds NaN.

    Notes
    -----
    The exact method runs over the coarse triangles. Each one visits the fine cells of
    the grid rows it crosses. A fine triangle inside it costs one closed-form integral of
    the absolute value of a linear function (split where the function changes sign); one
    crossed by a single coarse edge (most of the crossed ones) is split along that edge in
    closed form as well; only fine triangles near a
    coarse vertex are clipped by several edges (Sutherland and Hodgman [1]_) and
    integrated as a fan. Neighbouring coarse triangles evaluate their shared edge with
    the same floating-point operations, so the pieces tile the footprint. The sums are
    compensated (Neumaier [2]_) per chunk of faces and the chunks added exactly
    (:func:`math.fsum`), so the result does not depend on the thread count. The tests
    check it against manifold3d (``method="manifold"``) to 1e-12 relative; its cost is
    O(coarse faces + fine cells crossed) (timings in docs/performance.md#simplifiers-figures-behind-their-defaults).

    References
    ----------
    .. [1] I. E. Sutherland and G. W. Hodgman, "Reentrant polygon clipping",
       Communications of the ACM 17(1), 32-42, 1974. DOI 10.1145/360767.360802
    .. [2] A. Neumaier, "Rundungsfehleranalyse einiger Verfahren zur Summation endlicher
       Summen", ZAMM 54(1), 39-51, 1974. DOI 10.1002/zamm.19740540106
    .. [3] T. Alderson and F. Samavati, "Reverse subdivision for optimizing visibility
       tests", GRAPP 2012, pp. 143-150. DOI 10.5220/0003851501430150 (the simplifications
       whose shape error this measures)

    Examples
    --------
    Two parallel planes 2.5 apart over a 30 x 40 footprint:

    >>> import numpy as np
    >>> from terrainvis import HeightGrid
    >>> fine = HeightGrid(np.zeros((3, 4)), dx=10.0, dy=20.0)
    >>> coarse = HeightGrid(np.full((2, 2), 2.5), dx=30.0, dy=40.0)
    >>> round(volume_error(fine, coarse), 9)
    3000.0

    A hat of height 6 on a flat plane; its support is six triangles of total area 3:

    >>> peak = np.zeros((3, 3))
    >>> peak[1, 1] = 6.0
    >>> flat = HeightGrid(np.zeros((2, 2)), dx=2.0, dy=2.0)
    >>> round(volume_error(HeightGrid(peak), flat), 9)
    6.0
    >>> round(volume_error(HeightGrid(peak), flat, method="manifold"), 9)
    6.0
    """
    _check_pair(fine, coarse)
    if not isinstance(method, str) or method not in VOLUME_METHODS:
        raise ValueError(f"method must be one of {list(VOLUME_METHODS)}, got {method!r}")
    fine.require_finite("volume_error")
    if isinstance(coarse, HeightGrid):
        coarse.require_finite("volume_error")
        coarse = coarse.to_tin()
    if not np.allclose(coarse.extent, fine.extent, rtol=0, atol=EXTENT_MATCH_REL * (1 + np.abs(fine.extent).max())):
        raise ValueError(f"coarse must cover the extent of fine {fine.extent}, got {coarse.extent}")
    xmin, xmax, ymin, ymax = fine.extent
    area = (xmax - xmin) * (ymax - ymin)
    vx, vy = _local_xy(fine, coarse)
    footprint, n_cw, first_cw = _volume_kernels.face_areas(vx, vy, coarse.faces)
    if n_cw:
        raise ValueError(
            f"coarse must have counter-clockwise faces (a height field seen from above), but {n_cw} "
            f"face(s) are clockwise, the first is face {first_cw}"
        )
    if not footprint_matches(footprint, area):
        raise ValueError(
            f"coarse must cover the footprint of fine (area {area:g}), but its faces cover {footprint:g}"
        )
    if method == "manifold":
        return _volume_manifold(fine, coarse)
    return _volume_exact(fine, coarse)[0]


def _volume_manifold(fine: HeightGrid, coarse: TIN) -> float:
    """|A xor B| of the two closed solids built by :func:`_solid` (the reference)."""
    ft = fine.to_tin()
    # A local origin keeps the coordinates small (UTM northings lose digits otherwise).
    origin = np.array([fine.xs[0], fine.ys[0], 0.0])
    zmin = min(ft.vertices[:, 2].min(), coarse.vertices[:, 2].min())
    zmax = max(ft.vertices[:, 2].max(), coarse.vertices[:, 2].max())
    floor = zmin - max(1.0, 0.1 * (zmax - zmin))
    a = _solid(ft.vertices - origin, ft.faces, floor)
    b = _solid(coarse.vertices - origin, coarse.faces, floor)
    # |A xor B| = |A| + |B| - 2 |A and B|: one boolean instead of two differences, and in
    # float64 the cancellation costs a few digits of 16 (checked against the two
    # differences to 3e-14 relative on the bundled terrains).
    return float(a.volume() + b.volume() - 2.0 * (a ^ b).volume())


def _local_xy(fine: HeightGrid, coarse: TIN) -> tuple[np.ndarray, np.ndarray]:
    """The x and y of the coarse vertices in a local origin at fine's first sample.

    UTM northings near 5e6 lose digits in the edge tests and areas otherwise.
    """
    v = coarse.vertices
    return v[:, 0] - fine.xs[0], v[:, 1] - fine.ys[0]


def _volume_exact(fine: HeightGrid, coarse: TIN) -> tuple[float, float]:
    """The integral of |coarse - fine| and the area the overlay pieces cover (compensated sums).

    The covered area equals the footprint's when the pieces tile it: the tests check it.
    """
    vk = _volume_kernels
    xs = fine.xs - fine.xs[0]
    ys = fine.ys - fine.ys[0]
    vx, vy = _local_xy(fine, coarse)
    vz = np.ascontiguousarray(coarse.vertices[:, 2])
    faces = coarse.faces
    order = vk.faces_by_row(vy, faces, ys)
    nchunks = int(min(faces.shape[0], _VOLUME_CHUNKS))
    out = np.zeros((nchunks, vk.N_OUT))
    # work: the fine cells and the coarse faces visited
    call(vk.volume_between, (xs, ys, fine.z), (vx, vy, vz, faces, order), nchunks, out,
         work=fine.size + faces.shape[0], items=nchunks)
    volume = math.fsum(np.concatenate([out[:, vk.VOL], out[:, vk.VOL_C]]))
    covered = math.fsum(np.concatenate([out[:, vk.AREA], out[:, vk.AREA_C]]))
    return volume, covered


# Chunks of coarse faces of the kernel's loop: a constant, so that the result does not
# depend on the thread count, and many more than the threads, so that the load balances.
_VOLUME_CHUNKS = 256
