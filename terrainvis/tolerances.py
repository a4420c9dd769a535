"""Every numeric tolerance of terrainvis and simplifiers, named once, with what it protects.

A tolerance is a small number that decides what counts as "the same" in float64 (or
float32): an axis evenly spaced, a position on an extent's edge, a point inside a
triangle, a footprint that covers the extent, a vertex count close enough to its budget.
Each one lives here, under one name per meaning: two equal values that mean different
things get two names (so either can change alone), and one meaning used in several
places gets one name.

Most are *relative*: the docstring says what they multiply (a step, a span, a cell, a
terrain's scale). The module has no dependencies; every module imports from it, the
numba kernel modules included.

Kernels: a numba kernel reads a module-level float as a constant frozen when it is
compiled. The kernel modules import the names they use into their own globals
(``from ..tolerances import X``) and keep ``cache=True``; numba's on-disk cache is keyed
on the kernel module's own source file, so after changing a value used by a kernel,
touch that module (or clear its ``__pycache__``) or the cached machine code keeps the
old value. The names a kernel reads are marked "(kernel)" below.

Adding one: a ``NAME = value`` here with a ``#:`` line (what it protects, what it is
relative to), then import it where it is used. ``tests/whole/test_tolerances.py`` fails on a
float literal below 1e-5 anywhere else in ``terrainvis/`` or ``simplifiers/``.
"""

from __future__ import annotations

__all__ = [
    "CLEARANCE_REL",
    "UNIFORM_STEP_REL", "ROUNDING_ULPS", "EDGE_SNAP_REL", "COVER_EDGE_CELL_REL", "FRAME_AXIS_REL", "DEGREE_CELL_SLACK", "SPACING_MATCH_REL",
    "RESAMPLE_SHIFT_REL", "METRIC_EDGE_MARGIN", "FLOAT32_ROUNDING_REL",
    "BUCKET_SLACK", "RASTER_BOX_REL", "BARYCENTRIC_SLACK", "FOOTPRINT_REL", "EXTENT_MATCH_REL", "DIVISOR_FLOOR",
    "BUDGET_WINDOW_REL", "MAX_ERROR_TIE_REL", "ROW_SPAN_SNAP", "WHOLE_UNIT_SLACK", "EPS_GUESS_FLOOR_REL", "EPS_BRACKET_FLOOR_REL", "SQUARE_CELL_REL",
    "TILE_BORDER_REL", "FACE_AREA_REL", "STAR_MARGIN_MIN",
    "EXTENT_INSIDE_REL", "THRESHOLD_MARGIN_REL", "VERTEX_WEIGHT_ZERO",
    "SLOPE_REL", "PSEUDO_ANGLE_SLACK", "EDGE_CLIP_SLACK", "DIAGONAL_SLACK", "PSEUDO_ANGLE_SPAN_MIN", "PARALLEL_SINE_MIN",
    "WEDGE_BOUNDARY_SLACK", "RING_BOUND_REL", "TRIM_MARGIN_REL", "TIN_ON_EDGE_REL", "TRACK_FACE_SLACK", "TRACK_EDGE_SLACK", "TRACK_STEP_MIN", "TRACK_PROBE_REL", "MOVED_ABS",
    "OUTPUT_SETTLE_REL", "HOLE_REACH_SLACK", "BUCKET_SLACK_REL",
    "HORIZON_DENOMINATOR_MIN", "TILE_RECTANGLE_SHRINK_REL", "QUANTIZED_SNAP", "TILE_BUDGET_REL",
    "TILE_RING_INSET_REL",
]

# ------------------------------------------------------------------ line of sight
#: Clearance band of the line-of-sight predicate, as a fraction of the terrain's scale
#: (``max(extent diagonal, relief)``): a segment still counts as visible down to a
#: clearance of ``-CLEARANCE_REL * scale``. Also sets how large a height float64 still
#: resolves against a terrain (``terrainvis.core.validate.height_limit``).
#: (``terrainvis.visibility.TOL_REL`` is this value, under the visibility package's name.)
CLEARANCE_REL = 1e-9
#: Segment ends and observers on a grid's edge: a position outside the extent by at most
#: this fraction of its diagonal still counts as inside (rounding of computed positions).
EXTENT_INSIDE_REL = 1e-9

# ------------------------------------------------------------------ grid axes and positions
#: Uniform-axis test: each step of an axis may differ from the mean step by this fraction
#: of the step (plus :data:`ROUNDING_ULPS` of the largest coordinate) and the axis is still
#: uniform (``HeightGrid.is_uniform``, lon/lat axes converted to metres).
UNIFORM_STEP_REL = 1e-9
#: Float64 steps (ulps) of the largest |coordinate| allowed as rounding of coordinates that
#: were computed (``origin + step * i`` far from 0, a transform and its inverse): in the
#: uniform-axis test and when positions are snapped onto an extent's edge.
ROUNDING_ULPS = 8.0
#: ``vertical_errors``: a fine sample outside the coarse terrain's extent by at most this
#: fraction of a coarse cell counts as on its edge. A simplified grid written to a raster
#: and read back ends up to millimetres short of the fine extent (its georeferencing is
#: stored as an origin and a step, in degrees on a lon/lat DEM).
COVER_EDGE_CELL_REL = 1e-3
#: ``evaluate``: a raster moved into the DEM's frame must keep its rows and columns on the
#: frame's axes to this fraction of their span (a raster in another projection does not).
FRAME_AXIS_REL = 1e-6
#: Snapping of positions onto an extent's edge: a position outside ``[lo, hi]`` by at most
#: this fraction of ``hi - lo`` (plus :data:`ROUNDING_ULPS`) is put on the edge (positions
#: converted from the native CRS round to just outside the terrain).
EDGE_SNAP_REL = 1e-9
#: Lon/lat detection: a cell up to one arc-minute plus this many degrees still looks like
#: degrees (1/60 itself is not exact in float64).
DEGREE_CELL_SLACK = 1e-12
#: Reading an .npz of the former ``save_dem`` dialect: its stored ``dx``/``dy`` must equal the
#: mean spacing of its coordinates to this fraction (of the larger), or the file is refused.
SPACING_MATCH_REL = 1e-9
#: Writing a rectilinear grid as a uniform raster: a position moved by at most this fraction
#: of a cell is rounding, not counted among the moved positions of the warning.
RESAMPLE_SHIFT_REL = 1e-9
#: Metres kept inside the footprint's edges by ``footprint="inside"`` of the lon/lat to
#: metric resampling (``terrainvis.io.to_metric``): the edges are curves in the projection,
#: known at 256 points per edge; between them they bulge by less than 1e-4 m on a 1-degree tile.
METRIC_EDGE_MARGIN = 1e-3
#: float32 margin of mesh files (STL): coordinates rounded to float32 by more than this
#: fraction of the terrain's extent get a warning that names the rounding.
FLOAT32_ROUNDING_REL = 1e-6

# ------------------------------------------------------------------ TINs
#: (kernel) Locating points in a TIN: a point up to this many bucket widths outside the
#: bucket grid is still looked up (a point on the extent's edge rounds to just outside).
BUCKET_SLACK = 1e-9
#: (kernel) Rasterizing a TIN: each face's bounding box is widened by this fraction of
#: ``|coordinate| + 1`` before the grid nodes inside it are searched, so a node on the box's
#: edge is not lost to rounding.
RASTER_BOX_REL = 1e-9
#: Point in triangle: barycentric coordinates down to ``-BARYCENTRIC_SLACK`` count as
#: inside, so a point on an edge shared by two faces (or on the footprint's boundary) is
#: found in one of them.
BARYCENTRIC_SLACK = 1e-10
#: Height-field check: the faces' projected area must equal the extent's area to this
#: fraction of it (``terrainvis.core.mesh.footprint_matches``: ``TIN.is_height_field``,
#: ``volume_error``'s coverage check; the registry's check of simplified TINs holds the
#: same value).
FOOTPRINT_REL = 1e-9
#: ``volume_error``: the coarse terrain's extent must equal the fine one's to this fraction
#: of ``1 + max |extent coordinate|``.
EXTENT_MATCH_REL = 1e-9
#: Smallest span divided by: a zero-width extent (one row of samples, coincident vertices)
#: divides by this instead of 0. Not a tolerance of any comparison.
DIVISOR_FLOOR = 1e-300

# ------------------------------------------------------------------ simplifiers
#: Budget window of the irregular methods: a vertex count within this fraction of the
#: budget (and at least one vertex) meets it (``simplifiers.levels.budget_tolerance``).
BUDGET_WINDOW_REL = 0.01
#: A run budgeted in maximum vertical error (``compare(max_errors=)``): a result whose
#: measured maximum error exceeds the budget E by at most this fraction of E meets it. The
#: methods stop on their own error computation and ``vertical_errors`` measures it
#: independently; at a tie (the Jacksboro DEM's whole-metre heights met E = 10, 20, 40 and 80
#: exactly) the two round apart: greedy cuts and greedy insertion measured 1e-13 to 1.1e-12
#: above E.
MAX_ERROR_TIE_REL = 1e-9
#: (kernel) Greedy cuts, index space: the ends of a face's span along a grid row are
#: snapped to whole columns within this many columns (the span is computed from the
#: face's edges and rounds to just inside a column the face touches).
ROW_SPAN_SNAP = 1e-7
#: Greedy cuts, a rectilinear grid: a coordinate within this many units of a whole multiple
#: of its axis's unit counts as that multiple, and the kernel computes on the whole numbers
#: (floating-point rounding of coordinates that are multiples of a cell, like a reverse Faber
#: S(T)'s; ``simplifiers.greedy_cuts._whole_units``).
WHOLE_UNIT_SLACK = 1e-9
#: Greedy cuts' first guess of ε: the bisection on log ε searches down to this fraction
#: of the largest error.
EPS_GUESS_FLOOR_REL = 1e-7
#: Greedy cuts' bracket stage: when a step leaves the bracket, the geometric mean of its
#: ends is taken with the lower end raised to at least this fraction of the upper one.
EPS_BRACKET_FLOOR_REL = 1e-9
#: Greedy insertion: cells whose squared aspect ratio ``(dy / dx)**2`` is within this of 1
#: are square (the in-circle test then runs in index space without the ratio).
SQUARE_CELL_REL = 1e-12
#: Quadric, tiled: a decimated tile's boundary vertex matches a border sample when within
#: this fraction of the grid's larger side.
TILE_BORDER_REL = 1e-9
#: Quadric repair: a face counts as counter-clockwise when its twice-area exceeds this
#: fraction of the square of the grid's larger side.
FACE_AREA_REL = 1e-12
#: Quadric repair: a vertex's star has a usable interior (a point strictly inside every
#: face) when the linear program's margin, in units of the star's size, exceeds this.
STAR_MARGIN_MIN = 1e-9

# ------------------------------------------------------------------ calibrated relocation
#: Height margin kept from the thresholds, as a fraction of the terrain's scale (about 5 mm
#: on a 5 km grid): a chosen height stands this far from every threshold, so that the
#: verdicts the relocation counted are the ones a LOS engine gives there
#: (``terrainvis.relocation.calibrated``).
THRESHOLD_MARGIN_REL = 1e-6
#: (kernel) The threshold walk over a TIN: a track position counts as inside a face down to
#: barycentric coordinates of ``-TRACK_FACE_SLACK`` (a track along an edge is found in one
#: of its two faces).
TRACK_FACE_SLACK = 1e-9
#: (kernel) ... a track leaves a face across an edge whose parameter is within this of
#: [0, 1] (crossings through a vertex are not lost to rounding).
TRACK_EDGE_SLACK = 1e-9
#: (kernel) ... the least step in the track's parameter u (in [0, 1]) that counts as
#: progress: an exit at most this far past the current position is the same position.
TRACK_STEP_MIN = 1e-12
#: (kernel) ... probes a little past a vertex or a hole: this fraction of the rest of the
#: track (the first probe; then tenfold steps), and the step past an edge without a
#: neighbour.
TRACK_PROBE_REL = 1e-9
#: ``terrainvis relocate`` reports a point as moved off the full projection when its height
#: differs from it by more than this (z units; the margin above is far larger on any real
#: terrain).
MOVED_ABS = 1e-9

# ------------------------------------------------------------------ visopt
#: (kernel) visopt's coordinate descent: a sight line's breakpoint whose height depends on
#: a coarse vertex with a barycentric weight below this is not influenced by that vertex
#: (``simplifiers._visopt_kernels``).
VERTEX_WEIGHT_ZERO = 1e-12

# ------------------------------------------------------------------ viewshed sweep (kernel)
#: (kernel) Relative slack on the sweep's slopes (rounding of divisions and square roots,
#: generously): a bound decides a target only beyond it.
SLOPE_REL = 1e-13
#: (kernel) Pseudo-angle slack when a value is compared with a wedge boundary.
PSEUDO_ANGLE_SLACK = 1e-12
#: (kernel) Slack on the clipping parameters of an edge against a wedge.
EDGE_CLIP_SLACK = 1e-9
#: (kernel) A piece of a ray on a cell's diagonal (both ends within this of it, in the
#: cell's unit coordinates) is tested against the other triangle's plane too.
DIAGONAL_SLACK = 1e-12
#: (kernel) An edge whose pseudo-angle span is below this is a point for the wedge clipping.
PSEUDO_ANGLE_SPAN_MIN = 1e-9
#: (kernel) A wedge's boundary ray and an edge are parallel (no cut) when the sine of their
#: angle is below this.
PARALLEL_SINE_MIN = 1e-6
#: (kernel) A pseudo-angle within this fraction of a wedge's width of its boundary lies on
#: it: the neighbouring wedge counts too.
WEDGE_BOUNDARY_SLACK = 1e-9
#: (kernel) The ring bound's relative margin (cells bounded from their corners only when
#: a diagonal is below the ring distance by more than rounding).
RING_BOUND_REL = 1e-12
#: The sweep runs only when every cell is wider than both trims by this fraction, and the
#: trimmed ends it excludes are widened by it.
TRIM_MARGIN_REL = 1e-6
#: The TIN engine: a point within this fraction of the extent's diagonal of an edge is on it.
TIN_ON_EDGE_REL = 1e-12
#: (kernel) The TIN clipper visits the buckets its track passes through, widened by this
#: fraction of a bucket's side (far more than rounding and :data:`TIN_ON_EDGE_REL`).
BUCKET_SLACK_REL = 1e-6

# ----------------------------------------------------------------- viewshed output modes
#: ``viewshed(output="min_height" | "angle")`` on a grid with nodata: the height step (a
#: fraction of the terrain's scale) at which each threshold is checked by the exact
#: nodata-aware walk (blocked just below, visible just above), and to which the bisection
#: narrows a threshold that fails the check.
OUTPUT_SETTLE_REL = 1e-9
#: The same: a target counts as reaching a hole's angular bin when its distance is at least
#: the bin's nearest hole distance times ``1 - HOLE_REACH_SLACK`` (the conservative side:
#: a target at the hole's rounded distance is checked exactly).
HOLE_REACH_SLACK = 1e-9


# ----------------------------------------------------------------- terrain tiles
#: The horizon occlusion point of a quantized-mesh tile: a vertex whose term
#: ``cos(alpha) cos(beta) - sin(alpha) sin(beta)`` is at most this (it lies 90 degrees or more
#: from the tile's centre, seen from the earth's centre) leaves no such point.
HORIZON_DENOMINATOR_MIN = 1e-12
#: The tileset's lon/lat rectangle is shrunk by this fraction of its width and height, so
#: that the transforms' rounding never puts a lattice point on its edge outside the DEM.
TILE_RECTANGLE_SHRINK_REL = 1e-9
#: A tile's part of the rectangle, in quantization steps (0 to 32767): a bound within this
#: of an integer step is taken as that step (ceil and floor would otherwise lose a step to
#: rounding).
QUANTIZED_SNAP = 1e-9
#: A tile's measured error meets its budget (the zoom's max error plus half the height
#: step) when it is at most the budget times ``1 + TILE_BUDGET_REL`` (the rounding of the
#: measurement itself).
TILE_BUDGET_REL = 1e-12
#: Reading a tileset: the DEM footprint's boundary, in tile units, is pulled this fraction of
#: each point's distance to its centre inwards before the tiles it crosses are listed, so a
#: footprint whose edge runs along a tile edge (a DEM cut at the tiles) does not claim the
#: neighbouring tile, which it only touches.
TILE_RING_INSET_REL = 1e-9
