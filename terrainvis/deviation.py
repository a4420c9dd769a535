"""How far a simplified surface is from the original: vertical errors and the volume between.

These measurements sit beside the surfaces, below the simplifiers: :func:`simplifiers.simplify`
records ``max_error`` and ``rms_error`` with :func:`vertical_errors`, and the comparison
runner adds :func:`volume_error`.
"""

from __future__ import annotations

import numpy as np

from ._mesh import boundary_edges
from ._validate import describe
from .terrain import TIN, HeightGrid

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
    approx = coarse.height_on_grid(fine.xs, fine.ys)
    valid = np.isfinite(fine.z)
    uncovered = int(np.isnan(approx[valid]).sum())
    if uncovered:
        raise ValueError(f"coarse must cover the fine grid, but {uncovered} fine samples fall outside it")
    diff = approx[valid] - fine.z[valid]
    return float(np.abs(diff).max()), float(np.sqrt(np.mean(diff**2)))


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


def volume_error(fine: HeightGrid, coarse) -> float:
    """Volume between the fine surface and a simplified one (a shape error, in units³).

    Each terrain is turned into a closed solid with manifold3d (its surface, vertical
    walls along the footprint boundary and a flat floor below both), and the volume of
    the symmetric difference, ``vol(A) + vol(B) - 2 vol(A and B)``, is returned. For two height
    fields over the same footprint this equals the integral of ``|coarse - fine|`` over
    the footprint; divided by the footprint area it is the mean absolute vertical error.

    Parameters
    ----------
    fine : HeightGrid
        The original terrain (no nodata).
    coarse : HeightGrid or TIN
        A simplification over the same extent.

    Returns
    -------
    float
    """
    _check_pair(fine, coarse)
    fine.require_finite("volume_error")
    if isinstance(coarse, HeightGrid):
        coarse.require_finite("volume_error")
        coarse = coarse.to_tin()
    if not np.allclose(coarse.extent, fine.extent, rtol=0, atol=1e-9 * (1 + np.abs(fine.extent).max())):
        raise ValueError(f"coarse must cover the extent of fine {fine.extent}, got {coarse.extent}")
    xmin, xmax, ymin, ymax = fine.extent
    area = (xmax - xmin) * (ymax - ymin)
    if abs(coarse.footprint_area() - area) > 1e-9 * area:
        raise ValueError(
            f"coarse must cover the footprint of fine (area {area:g}), but its faces cover {coarse.footprint_area():g}"
        )
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
