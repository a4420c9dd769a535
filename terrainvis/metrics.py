"""How far a simplified terrain is from the original, and how many LOS verdicts survive."""

from __future__ import annotations

import numpy as np

from ._validate import describe
from .terrain import TIN, HeightGrid

__all__ = ["vertical_errors"]


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
    if not isinstance(fine, HeightGrid):
        raise TypeError(f"fine must be a terrainvis.HeightGrid, got {describe(fine)}")
    if isinstance(coarse, TIN):
        approx = coarse.height_on_grid(fine.xs, fine.ys)
    elif isinstance(coarse, HeightGrid):
        approx = coarse.height_at(fine.sample_xy()).reshape(fine.shape)
    else:
        raise TypeError(f"coarse must be a terrainvis.HeightGrid or terrainvis.TIN, got {describe(coarse)}")
    valid = np.isfinite(fine.z)
    if np.isnan(approx[valid]).any():
        n = int(np.isnan(approx[valid]).sum())
        raise ValueError(f"coarse does not cover the fine grid: {n} fine samples fall outside it")
    diff = approx[valid] - fine.z[valid]
    return float(np.abs(diff).max()), float(np.sqrt(np.mean(diff**2)))
