"""Positions as a user gives them on the command line: the frame, the conversions, the messages.

Every command that takes or prints positions (``los``, ``viewshed``, ``relocate``, and
observer CSVs of later commands) goes through one :class:`PositionFrame`:

* ``frame="native"`` (the default of the commands): the DEM's native CRS, lon/lat
  degrees on a lon/lat DEM (as GDAL and GRASS take them), the projected coordinates on
  a projected one, and the lon/lat CRS a grid was resampled from with ``--metric``
  (:func:`terrainvis.io.to_metric`);
* ``frame="local"``: the terrain's own frame, that of ``grid.xs`` and ``grid.ys`` and of
  the Python API (local metres from the south-west sample on a lon/lat DEM; the same as
  native on a projected DEM).

:meth:`PositionFrame.to_grid` moves positions to the terrain's frame,
:meth:`PositionFrame.from_grid` moves results back, :meth:`PositionFrame.point` and
:meth:`PositionFrame.footprint` write them with the digits the grid's cells need, so the
outputs and the error messages use the frame of the input.
"""

from __future__ import annotations

import math

import numpy as np

from ._georef import position_crs, xy_to_native
from .validate import choice
from ..tolerances import DIVISOR_FLOOR

__all__ = ["FRAMES", "PositionFrame"]

#: The frames positions can be given in (``--frame``).
FRAMES = ("native", "local")

#: Points per edge of the terrain's outline when its footprint is mapped to a non-affine frame.
_EDGE_POINTS = 64


class PositionFrame:
    """How positions are given on one terrain: ``"native"`` (its CRS) or ``"local"`` (its own frame).

    Parameters
    ----------
    terrain : HeightGrid or TIN
        The terrain the positions are on (its ``attrs`` hold the georeferencing).
    frame : {"native", "local"}

    Examples
    --------
    >>> from terrainvis import HeightGrid
    >>> g = HeightGrid(np.zeros((3, 3)), dx=500.0, dy=1000.0,
    ...                attrs={"crs": "EPSG:4326", "geographic": True, "xy_to_native": (0.001, -72.8, 0.001, 44.1)})
    >>> f = PositionFrame(g)
    >>> f.names, f.to_grid([[-72.3, 45.1]]).round(6).tolist()
    (('lon', 'lat'), [[500.0, 1000.0]])
    >>> f.footprint()
    'lon [-72.8, -71.8], lat [44.1, 46.1] (EPSG:4326, degrees)'
    >>> PositionFrame(g, "local").footprint()
    'x [0, 1000], y [0, 2000] (local metres)'
    """

    def __init__(self, terrain, frame: str = "native"):
        self.frame = choice(frame, "frame", FRAMES)
        self.terrain = terrain
        attrs = terrain.attrs
        self.crs = position_crs(attrs)
        geographic = bool(attrs.get("geographic") or attrs.get("source_crs"))
        self.identity = frame == "local" or (not attrs.get("source_crs") and xy_to_native(attrs) == (1.0, 0.0, 1.0, 0.0))
        self.degrees = frame == "native" and geographic
        self.names = ("lon", "lat") if self.degrees else ("x", "y")
        if frame == "local":
            units = "local metres" if geographic else (self.crs or "")
        elif self.crs:
            units = f"{self.crs}, degrees" if self.degrees else self.crs
        else:
            units = ""
        #: What the positions are, for messages: "EPSG:4326, degrees", "local metres", "EPSG:26918" or "".
        self.units = units
        self._step = None

    # ---------------------------------------------------------- conversions
    def to_grid(self, xy) -> np.ndarray:
        """Positions in this frame (x, y first along the last axis; z passes) in the terrain's frame."""
        if self.identity:
            return np.array(xy, dtype=np.float64)
        return self.terrain.from_native(xy)

    def from_grid(self, xy) -> np.ndarray:
        """Positions in the terrain's frame moved to this frame (the inverse of :meth:`to_grid`)."""
        if self.identity:
            return np.array(xy, dtype=np.float64)
        return self.terrain.to_native(xy)

    # ---------------------------------------------------------- text
    def _bounds(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the terrain's footprint in this frame (of its outline when not affine)."""
        xmin, xmax, ymin, ymax = self.terrain.extent
        if self.identity:
            return xmin, xmax, ymin, ymax
        t = np.linspace(0.0, 1.0, 2 if not self.terrain.attrs.get("source_crs") else _EDGE_POINTS)
        ring = np.concatenate([
            np.column_stack([xmin + (xmax - xmin) * t, np.full(t.size, ymin)]),
            np.column_stack([np.full(t.size, xmax), ymin + (ymax - ymin) * t]),
            np.column_stack([xmin + (xmax - xmin) * t, np.full(t.size, ymax)]),
            np.column_stack([np.full(t.size, xmin), ymin + (ymax - ymin) * t]),
        ])
        native = self.from_grid(ring)
        return (float(native[:, 0].min()), float(native[:, 0].max()), float(native[:, 1].min()),
                float(native[:, 1].max()))

    def step(self) -> float:
        """About one cell of the terrain in this frame's units (for the digits positions are written with)."""
        if self._step is None:
            xmin, xmax, ymin, ymax = self.terrain.extent
            self._step = self._local_step()
            if not self.identity:
                bx0, bx1, by0, by1 = self._bounds()
                self._step *= min((bx1 - bx0) / max(xmax - xmin, DIVISOR_FLOOR), (by1 - by0) / max(ymax - ymin, DIVISOR_FLOOR))
        return self._step

    def _local_step(self) -> float:
        t = self.terrain
        if hasattr(t, "dx"):
            return min(t.dx, t.dy)
        xmin, xmax, ymin, ymax = t.extent  # a TIN: the mean spacing of its vertices
        return math.sqrt(max((xmax - xmin) * (ymax - ymin), DIVISOR_FLOOR) / max(t.n_vertices, 1))

    def value(self, v: float) -> str:
        """One coordinate with the digits that show a tenth of a cell (``.6g`` would round a UTM northing to 10 m)."""
        if not math.isfinite(v):
            return str(v)
        step = self.step()
        decimals = max(0, 1 - math.floor(math.log10(step))) if step > 0 else 6
        whole = math.floor(math.log10(abs(v))) + 1 if v else 1
        digits = max(6, whole + decimals)
        if digits > 17:  # more than float64 holds (1e300 would be written out in full): its shortest form
            return repr(float(v))
        return f"{v:.{digits}g}"

    def point(self, xy) -> str:
        """``"(x, y)"`` of one position in this frame."""
        return f"({self.value(float(xy[0]))}, {self.value(float(xy[1]))})"

    def footprint(self, units: bool = True) -> str:
        """The terrain's footprint in this frame: ``"lon [a, b], lat [c, d] (EPSG:4326, degrees)"``."""
        xmin, xmax, ymin, ymax = self._bounds()
        (nx, ny), units = self.names, f" ({self.units})" if self.units and units else ""
        return f"{nx} [{self.value(xmin)}, {self.value(xmax)}], {ny} [{self.value(ymin)}, {self.value(ymax)}]{units}"

    def describe(self) -> str:
        """What positions in this frame are, for ``info`` and messages."""
        if self.frame == "local":
            return "the terrain's own x, y" + (f" ({self.units})" if self.units else "")
        if self.degrees:
            return f"lon, lat in degrees ({self.crs})"
        return f"x, y in {self.crs}" if self.crs else "the grid's x, y (no CRS recorded)"
