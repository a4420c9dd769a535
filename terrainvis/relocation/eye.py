"""The eye surface: the calibrated relocation shipped with S(T), for programs that have no T.

The calibrated relocation (:mod:`terrainvis.relocation.calibrated`) chooses each point's
height on S(T) by walking the original terrain T at query time. A program that ships only
S(T) (a game engine, a radio planner, a 3D globe) has no T to walk. An *eye surface* is a
small field of height offsets, fitted once from T and S(T) and shipped beside S(T), that
gives the relocated height of any fresh point without T:

    z(x, y) = S(x, y) + offset + e(x, y)

where ``offset`` is the observer height the points carry and ``e`` the eye surface.

The fit
-------
``e`` is known exactly at the nodes of a regular lattice over T's extent: at each node,
the calibrated height of a point standing there (against the calibrated relocation's
partners and the node's own neighbours on T) minus its full projection. The nodes are
the fitting sample: fixed by the lattice, never the points the surface will serve.
Between the nodes ``e`` is bilinear. Where full projection already keeps every verdict
of a node (against its partners and neighbours), the calibrated relocation does not move
it, and its offset is exactly 0.

Between nodes the calibrated offsets are not always what a fresh point needs: where
S(T) is close to T (level 1) they vary within a cell of T, and interpolated offsets can
keep fewer verdicts than full projection. So the fit checks itself (``validate=True``)
on :data:`VALIDATION_SETS` sets of :data:`VALIDATION_POINTS` points of its own (from its
own seed stream, never the points it will serve): their pairs' verdicts on T against
those on S(T) with the offsets scaled by each factor of :data:`SHRINKS`, and keeps a
factor only where it keeps clearly more verdicts than full projection on those pairs
(:func:`_choose_shrink`); otherwise the surface is full projection (factor 0).

The representation
------------------
The lattice is as fine as the byte budget allows (by default the bytes of S(T) itself:
a grid's heights, a TIN's vertices and faces), never finer than T's samples nor above
``max_nodes`` nodes (the fit's cost: one calibrated point per node). Each node holds one
byte: its offset quantised on a mu-law scale (:data:`MU`), fine near 0 and coarse for
large offsets. The calibrated relocation moves many points by a few millimetres (a
height margin across a threshold) and a few by metres; both matter: a uniform 8-bit
quantiser rounds the millimetres to 0 and gave up a quarter of the gain on hills at level
3 (docs/relocation.md, "The eye surface", has the measurements and the alternatives:
denser floats, 16-bit, an adaptive quadtree).

The file
--------
An eye surface travels with S(T) as a few arrays under keys starting with ``eye_``
(:data:`FORMAT`, version :data:`FORMAT_VERSION`): in a ``.npz`` of its own, inside the
terrainvis ``.npz`` of S(T) (the terrain readers ignore keys they do not know), or as a
sidecar ``<file>.eye.npz`` beside a GeoTIFF or a mesh (:meth:`EyeSurface.sidecar`). Every
write is atomic (:func:`terrainvis.core.fileio.atomic_path`): a reader sees the old file
or the complete new one. A reloaded surface gives the same heights bit for bit.
"""

from __future__ import annotations

import math
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..core.terrain import TIN, HeightGrid, fingerprint
from ..core.validate import as_bool, as_finite_scalar, as_int, as_points, describe
from ..tolerances import EXTENT_INSIDE_REL
from ..visibility import EARTH_RADIUS
from .calibrated import MIN_GAIN, N_PARTNERS, SWEEPS, predicate_of

__all__ = ["EyeSurface", "eye_surface", "relocate_eye", "shipped_bytes", "MU", "MAX_NODES", "FORMAT",
           "FORMAT_VERSION", "HEADER_BYTES", "SHRINKS", "VALIDATION_SETS", "VALIDATION_POINTS"]

#: The mu-law constant of the stored offsets: code k in [-127, 127] stands for
#: ``sign(k) * expm1(|k| / 127 * log1p(MU)) * scale / MU``, so the smallest step is about
#: ``scale / 133,000`` (0.07 mm for offsets up to 9 m) and each step above it 7.5 % of the value.
MU = 1.0e4
#: The largest code (int8).
LEVELS = 127
#: The most lattice nodes a fit computes by default (each is one calibrated point: about
#: a millisecond against 2,048 partners).
MAX_NODES = 16384
#: The file format's name and version (the value of the key ``eye_format``).
FORMAT = "terrainvis-eye"
FORMAT_VERSION = 1
#: Bytes an eye surface ships besides its codes: eight float64 (extent, scale, mu, offset,
#: target height).
HEADER_BYTES = 64
#: The shrink factors a fit tries on its validation points (0 is full projection; which one
#: is kept: :func:`_choose_shrink`).
SHRINKS = (1.0, 0.5, 0.0)
#: How clearly a factor must beat full projection on the validation pairs to be kept: its
#: McNemar statistic (pairs it gains minus pairs it loses, over the square root of their
#: sum) above this. Measured in docs/relocation.md ("The fit's check").
SHRINK_Z = 2.0
#: Validation point sets of a fit, and points per set.
VALIDATION_SETS = 4
VALIDATION_POINTS = 50

_KEYS = ("eye_format", "eye_format_version", "eye_codes", "eye_extent", "eye_scale", "eye_mu", "eye_offset",
         "eye_target_height")


def shipped_bytes(simplified) -> int:
    """The bytes S(T) ships: a grid's heights, a TIN's vertices and faces."""
    if isinstance(simplified, HeightGrid):
        return int(simplified.z.nbytes)
    if isinstance(simplified, TIN):
        return int(simplified.vertices.nbytes + simplified.faces.nbytes)
    raise TypeError(f"simplified must be a terrainvis.HeightGrid or TIN, got {describe(simplified)}")


def encode(offsets: np.ndarray, scale: float, mu: float = MU) -> np.ndarray:
    """The int8 mu-law codes of ``offsets`` (|offsets| <= ``scale``); 0 stays 0."""
    if scale <= 0:
        return np.zeros(np.shape(offsets), dtype=np.int8)
    mag = np.log1p(mu * np.minimum(np.abs(offsets) / scale, 1.0)) / np.log1p(mu)
    return (np.sign(offsets) * np.round(mag * LEVELS)).astype(np.int8)


def decode(codes: np.ndarray, scale: float, mu: float = MU) -> np.ndarray:
    """The offsets (float64) the int8 ``codes`` stand for (:func:`encode`'s inverse, to its step)."""
    c = codes.astype(np.float64)
    return np.sign(c) * np.expm1(np.abs(c) / LEVELS * np.log1p(mu)) * (scale / mu)


class EyeSurface:
    """Height offsets over a lattice: the calibrated relocation without T.

    Made by :func:`eye_surface` (fitted) or :meth:`load` (from a file). Read-only.

    Parameters
    ----------
    codes : (ny, nx) int8
        The mu-law codes of the offsets at the lattice nodes, rows of increasing y
        (``codes[row, col]``); ny, nx >= 2.
    extent : (4,) float
        ``(xmin, xmax, ymin, ymax)`` of the lattice; the nodes are evenly spaced over it.
    scale : float
        The largest offset's magnitude (code +-127), >= 0.
    offset : float
        The observer height of the points it was fitted for (their height above the ground).
    target_height : float or None
        None: fitted for pairs of points; a number: for observers against targets that high
        (a viewshed's cells).
    mu : float
        The mu-law constant (:data:`MU`).
    """

    __slots__ = ("codes", "extent", "scale", "offset", "target_height", "mu", "_offsets")

    def __init__(self, codes, extent, scale: float, offset: float = 0.0, target_height=None, mu: float = MU):
        codes = np.asarray(codes)
        if codes.ndim != 2:
            raise ValueError(f"codes must be a 2-D array, got {codes.ndim} dimension(s)")
        if codes.dtype != np.int8:
            raise ValueError(f"codes must be int8, got dtype {codes.dtype}")
        if codes.shape[0] < 2 or codes.shape[1] < 2:
            raise ValueError(f"codes must have at least 2 rows and 2 columns, got shape {codes.shape}")
        if (codes == -128).any():
            raise ValueError(f"codes must lie in [-{LEVELS}, {LEVELS}], got -128")
        ext = np.asarray(extent, dtype=np.float64)
        if ext.shape != (4,) or not np.isfinite(ext).all() or not (ext[0] < ext[1] and ext[2] < ext[3]):
            raise ValueError(f"extent must be 4 finite numbers (xmin, xmax, ymin, ymax) with xmin < xmax and "
                             f"ymin < ymax, got {extent!r}")
        scale = as_finite_scalar(scale, "scale")
        if scale < 0:
            raise ValueError(f"scale must be >= 0, got {scale}")
        mu = as_finite_scalar(mu, "mu")
        if mu <= 0:
            raise ValueError(f"mu must be > 0, got {mu}")
        self.codes = codes.copy()
        self.codes.flags.writeable = False
        self.extent = tuple(float(v) for v in ext)
        self.scale = scale
        self.offset = as_finite_scalar(offset, "offset")
        self.target_height = None if target_height is None else as_finite_scalar(target_height, "target_height")
        self.mu = mu
        self._offsets = decode(self.codes, self.scale, self.mu)
        self._offsets.flags.writeable = False

    def __repr__(self) -> str:
        ny, nx = self.codes.shape
        setting = "points" if self.target_height is None else f"targets {self.target_height:g} high"
        return (f"EyeSurface({nx}x{ny} nodes, {self.nbytes:,} bytes, offsets up to {self.scale:.3g}, "
                f"eye height {self.offset:g}, {setting})")

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``: the lattice's rows and columns."""
        return self.codes.shape

    @property
    def nbytes(self) -> int:
        """What it ships: one byte per node and :data:`HEADER_BYTES`."""
        return int(self.codes.nbytes + HEADER_BYTES)

    @property
    def node_offsets(self) -> np.ndarray:
        """(ny, nx) float64: the offsets at the nodes (decoded; read-only)."""
        return self._offsets

    def node_xy(self) -> np.ndarray:
        """(ny * nx, 2) float64: the nodes' positions, row by row."""
        xs, ys = _axes(self.extent, self.codes.shape)
        X, Y = np.meshgrid(xs, ys)
        return np.column_stack([X.ravel(), Y.ravel()])

    def offset_at(self, xy) -> np.ndarray:
        """The offset e(x, y) at each position: bilinear between the four nodes around it.

        Parameters
        ----------
        xy : (n, 2) array_like
            Positions inside the lattice's extent.

        Returns
        -------
        (n,) float64

        Examples
        --------
        >>> e = EyeSurface(np.array([[0, 127], [0, 0]], dtype=np.int8), (0.0, 2.0, 0.0, 1.0), scale=4.0)
        >>> e.offset_at([[0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [1.0, 0.5]]).round(12).tolist()
        [0.0, 4.0, 2.0, 1.0]
        """
        q = as_points(xy, "xy", 2)
        x0, x1, y0, y1 = self.extent
        ny, nx = self.codes.shape
        tx, ty = EXTENT_INSIDE_REL * (x1 - x0), EXTENT_INSIDE_REL * (y1 - y0)
        outside = (q[:, 0] < x0 - tx) | (q[:, 0] > x1 + tx) | (q[:, 1] < y0 - ty) | (q[:, 1] > y1 + ty)
        if outside.any():
            first = int(np.flatnonzero(outside)[0])
            raise ValueError(f"xy must lie inside the eye surface's extent {self.extent}, but {int(outside.sum())} "
                             f"of {q.shape[0]} positions do not (first at index {first}: {q[first].tolist()})")
        fx = np.clip((q[:, 0] - x0) / (x1 - x0) * (nx - 1), 0.0, nx - 1)
        fy = np.clip((q[:, 1] - y0) / (y1 - y0) * (ny - 1), 0.0, ny - 1)
        i = np.minimum(fx.astype(np.int64), nx - 2)
        j = np.minimum(fy.astype(np.int64), ny - 2)
        u, v = fx - i, fy - j
        f = self._offsets
        return ((f[j, i] * (1 - u) + f[j, i + 1] * u) * (1 - v)
                + (f[j + 1, i] * (1 - u) + f[j + 1, i + 1] * u) * v)

    def heights(self, points, simplified) -> np.ndarray:
        """The relocated height of each point on ``simplified``: ``S(x, y) + offset + e(x, y)``.

        Parameters
        ----------
        points : (n, 2+) array_like
            Positions (a third column, the height on T, is not read).
        simplified : HeightGrid or TIN
            The S(T) the surface was fitted for.

        Returns
        -------
        (n,) float64
        """
        from .paper import ground_heights

        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] not in (2, 3):
            raise ValueError(f"points must be an (n, 2) or (n, 3) array, got {describe(points)}")
        pts = as_points(pts[:, :2], "points", 2)
        return ground_heights(simplified, pts) + self.offset + self.offset_at(pts[:, :2])

    # ------------------------------------------------------------------ files
    def arrays(self) -> dict:
        """The arrays of the file format (keys ``eye_*``), as :meth:`save` writes them."""
        return {
            "eye_format": np.asarray(FORMAT), "eye_format_version": np.int64(FORMAT_VERSION),
            "eye_codes": self.codes, "eye_extent": np.asarray(self.extent, dtype=np.float64),
            "eye_scale": np.float64(self.scale), "eye_mu": np.float64(self.mu),
            "eye_offset": np.float64(self.offset),
            "eye_target_height": np.float64(np.nan if self.target_height is None else self.target_height),
        }

    @staticmethod
    def sidecar(path) -> Path:
        """The sidecar file of a terrain file: ``<path>.eye.npz`` (``dem.tif`` -> ``dem.tif.eye.npz``)."""
        return Path(str(path) + ".eye.npz")

    def save(self, path, *, terrain=None) -> Path:
        """Write the eye surface, atomically, and return the path written.

        Parameters
        ----------
        path : str or Path
            A ``.npz`` file. Without ``terrain``: a file of its own (use :meth:`sidecar`
            for the file beside a GeoTIFF or a mesh). With ``terrain``: the terrainvis
            ``.npz`` of that terrain with the eye surface's arrays inside (readable by
            :func:`terrainvis.load_terrain` as before, and by :meth:`load`).
        terrain : HeightGrid or TIN, optional
            The S(T) to write beside it in one file.
        """
        from ..core.fileio import atomic_path, check_output_file

        p = Path(path)
        if p.suffix.lower() != ".npz":
            raise ValueError(f"path must end in .npz (use EyeSurface.sidecar({str(path)!r}) for the file beside a "
                             f"terrain file), got {str(path)!r}")
        p = check_output_file(p, "path")
        arrays = self.arrays()
        if terrain is not None:
            from ..io._npz import _npz_arrays

            if not isinstance(terrain, (HeightGrid, TIN)):
                raise TypeError(f"terrain must be a terrainvis.HeightGrid or TIN, got {describe(terrain)}")
            arrays = {**_npz_arrays(terrain), **arrays}
        with atomic_path(p) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)  # a file object: numpy appends no suffix
        return p

    @classmethod
    def load(cls, path) -> EyeSurface:
        """Read an eye surface: from a ``.npz`` holding its arrays (its own file or a
        terrain's), else from the sidecar ``<path>.eye.npz`` of a terrain file.

        Raises
        ------
        FileNotFoundError
            Neither the file nor its sidecar exists.
        ValueError
            The file is not a readable eye surface (says why).
        """
        p = Path(path)
        if p.suffix.lower() != ".npz" or not p.exists():
            side = cls.sidecar(p)
            if side.exists():
                p = side
            elif not p.exists():
                raise FileNotFoundError(f"path: no eye surface at {str(path)!r} nor beside it ({str(side)!r})")
        try:
            with np.load(p, allow_pickle=False) as data:
                if "eye_format" not in data.files:
                    side = cls.sidecar(p)
                    if side.exists():
                        return cls.load(side)
                    raise ValueError(f"path: {p.name!r} holds no eye surface (no key 'eye_format'; keys "
                                     f"{sorted(data.files)})")
                missing = [k for k in _KEYS if k not in data.files]
                if missing:
                    raise ValueError(f"path: {p.name!r} is not a complete eye surface: keys {missing} are missing")
                a = {k: data[k] for k in _KEYS}
        except (zipfile.BadZipFile, zlib.error, EOFError) as exc:
            raise ValueError(f"path: {p.name!r} is truncated or corrupt ({type(exc).__name__}: {exc})") from None
        except ValueError as exc:
            if str(exc).startswith("path:"):
                raise
            raise ValueError(f"path: {p.name!r} is not a readable eye surface ({exc})") from None
        if str(a["eye_format"]) != FORMAT:
            raise ValueError(f"path: {p.name!r} has eye_format {str(a['eye_format'])!r}, not {FORMAT!r}")
        version = int(a["eye_format_version"])
        if version != FORMAT_VERSION:
            raise ValueError(f"path: {p.name!r} is eye surface format version {version}; this terrainvis reads "
                             f"version {FORMAT_VERSION}")
        th = float(a["eye_target_height"])
        try:
            return cls(a["eye_codes"], a["eye_extent"], float(a["eye_scale"]), float(a["eye_offset"]),
                       None if math.isnan(th) else th, float(a["eye_mu"]))
        except ValueError as exc:
            raise ValueError(f"path: {p.name!r} holds an invalid eye surface: {exc}") from None


def _axes(extent, shape) -> tuple[np.ndarray, np.ndarray]:
    """The lattice's node coordinates (xs, ys), evenly spaced, ends exact."""
    x0, x1, y0, y1 = extent
    ny, nx = shape
    xs = x0 + (x1 - x0) * (np.arange(nx) / (nx - 1))
    ys = y0 + (y1 - y0) * (np.arange(ny) / (ny - 1))
    xs[-1], ys[-1] = x1, y1
    return xs, ys


def lattice_shape(original: HeightGrid, nodes: int) -> tuple[int, int]:
    """The (ny, nx) lattice of at most ``nodes`` nodes over T's extent: T's own samples when
    they fit, else as many as fit, in T's proportions (at least 2 x 2)."""
    ty, tx = original.shape
    if nodes >= tx * ty:
        return ty, tx
    s = math.sqrt(nodes / (tx * ty))
    nx, ny = max(2, int(tx * s)), max(2, int(ty * s))
    while nx * ny > nodes and max(nx, ny) > 2:
        if nx >= ny:
            nx -= 1
        else:
            ny -= 1
    return ny, nx


def eye_surface(original, simplified, *, offset: float = 0.0, target_height=None, budget=None, shape=None,
                max_nodes: int = MAX_NODES, n_partners: int = N_PARTNERS, sweeps: int = SWEEPS, seed: int = 0,
                end_radius: float = 0.0, curvature: float = 0.0, earth_radius: float = EARTH_RADIUS,
                min_gain: int = MIN_GAIN, neighbours: bool = True, validate: bool = True) -> EyeSurface:
    """Fit the eye surface of a simplification: the calibrated relocation, shipped without T.

    Parameters
    ----------
    original : HeightGrid
        T, free of nodata.
    simplified : HeightGrid or TIN
        S(T).
    offset : float
        The observer height of the points it will serve (their height above the ground).
    target_height : float or None
        None: pairs of points (``relocate``'s points setting); a number: observers against
        targets that high above the surface (a viewshed's cells).
    budget : int, optional
        Bytes the surface may take (:attr:`EyeSurface.nbytes`); default the bytes of S(T)
        itself (:func:`shipped_bytes`). The lattice is the finest that fits, never finer
        than T's samples nor above ``max_nodes``.
    shape : (int, int), optional
        The lattice's (ny, nx) instead (``budget`` and ``max_nodes`` are then not used).
    max_nodes : int
        The most nodes the fit computes (each is one calibrated point).
    n_partners, sweeps, seed, end_radius, curvature, earth_radius, min_gain, neighbours
        The calibrated relocation's (:func:`terrainvis.relocation.calibrated.relocate_calibrated`);
        the lattice's nodes are the points it relocates.
    validate : bool
        Scale the offsets by the factor of :data:`SHRINKS` that keeps the most verdicts of
        the fit's own validation points (see the module docstring); False: keep them whole.

    Returns
    -------
    EyeSurface

    Examples
    --------
    >>> import terrainvis as tv, simplifiers
    >>> T = tv.synthetic_terrain("hills", size=33, seed=1)
    >>> S = simplifiers.simplify(T, "lls", 2)
    >>> e = tv.eye_surface(T, S, n_partners=64)
    >>> e.nbytes <= S.z.nbytes
    True
    """
    from .calibrated import relocate_calibrated

    if not isinstance(original, HeightGrid):
        raise TypeError(f"original must be a terrainvis.HeightGrid, got {describe(original)}")
    if not isinstance(simplified, (HeightGrid, TIN)):
        raise TypeError(f"simplified must be a terrainvis.HeightGrid or TIN, got {describe(simplified)}")
    if original.shape[0] < 2 or original.shape[1] < 2:
        raise ValueError(f"original must have at least 2 x 2 samples, got shape {original.shape}")
    if shape is not None:
        if (not isinstance(shape, (tuple, list)) or len(shape) != 2):
            raise ValueError(f"shape must be (ny, nx), two integers >= 2, got {shape!r}")
        ny, nx = (as_int(shape[0], "shape[0]", minimum=2), as_int(shape[1], "shape[1]", minimum=2))
    else:
        max_nodes = as_int(max_nodes, "max_nodes", minimum=4)
        if budget is None:
            budget = shipped_bytes(simplified)
        budget = as_int(budget, "budget", minimum=HEADER_BYTES + 4)
        ny, nx = lattice_shape(original, min(budget - HEADER_BYTES, max_nodes))
    extent = original.extent
    xs, ys = _axes(extent, (ny, nx))
    X, Y = np.meshgrid(xs, ys)
    xy = np.column_stack([X.ravel(), Y.ravel()])
    off = float(offset)
    nodes = np.column_stack([xy, original.height_at(xy) + off])
    moved = relocate_calibrated(nodes, simplified, offset=off, original=original, target_height=target_height,
                                end_radius=end_radius, curvature=curvature, earth_radius=earth_radius,
                                n_partners=n_partners, sweeps=sweeps, seed=seed, min_gain=min_gain,
                                neighbours=neighbours)
    offsets = moved[:, 2] - (simplified.height_at(xy) + off)
    scale = float(np.max(np.abs(offsets))) if offsets.size else 0.0
    codes = encode(offsets, scale).reshape(ny, nx)
    out = EyeSurface(codes, extent, scale, off, target_height)
    if as_bool(validate, "validate") and scale > 0:
        shrink = _validated_shrink(out, original, simplified, seed, curvature, earth_radius, end_radius)
        if shrink != 1.0:
            out = EyeSurface(codes, extent, scale * shrink, off, target_height)
    return out


def _validated_shrink(eye: EyeSurface, original, simplified, seed: int, curvature: float, earth_radius: float,
                      end_radius: float) -> float:
    """The factor of :data:`SHRINKS` the fit's own validation pairs choose (points
    ``eye.offset`` above T; their own seed stream): :func:`_choose_shrink` of whether each
    pair's verdict on S(T), with the offsets scaled by each factor, is its verdict on T."""
    from ..core.sampling import sample_points
    from ..visibility import visibility_matrix

    curve = {"curvature": curvature, "earth_radius": earth_radius}
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xE7E5]))
    kept = [[] for _ in SHRINKS]
    for _ in range(VALIDATION_SETS):
        pts = sample_points(original, VALIDATION_POINTS, seed=rng, offset=eye.offset)
        truth = visibility_matrix(original, pts, engine="grid", **curve)
        ground = simplified.height_at(pts[:, :2]) + eye.offset
        e = eye.offset_at(pts[:, :2])
        upper = np.triu(np.ones(truth.shape, dtype=bool), 1)
        for k, f in enumerate(SHRINKS):
            placed = np.column_stack([pts[:, :2], ground + f * e])
            seen = visibility_matrix(simplified, placed, end_radius=end_radius, **curve)
            kept[k].append((seen == truth)[upper])
    return _choose_shrink(np.array([np.concatenate(k) for k in kept]))


def _choose_shrink(kept: np.ndarray) -> float:
    """The factor of :data:`SHRINKS` that ``kept`` (factors, pairs) bool, whether each
    validation pair keeps its verdict with the offsets scaled by each factor, chooses.

    Against full projection (the factor 0, when :data:`SHRINKS` holds it) a factor counts
    the pairs it keeps that full projection loses (``b``) and those it loses that full
    projection keeps (``c``); it is a candidate when ``b - c`` exceeds
    :data:`SHRINK_Z` times ``sqrt(b + c)`` (McNemar's statistic: on the few pairs where
    the two differ, a gain larger than chance). The candidate that keeps the most is
    chosen (the first on ties), full projection when there is none: a fit whose offsets
    do not clearly help on its own points ships full projection rather than a coin's
    toss. Without a factor 0, the factor that keeps the most.
    """
    totals = kept.sum(axis=1)
    if 0.0 not in SHRINKS:
        return float(SHRINKS[int(np.argmax(totals))])
    zero = SHRINKS.index(0.0)
    best = zero
    for k in range(len(SHRINKS)):
        b = int(np.count_nonzero(kept[k] & ~kept[zero]))
        c = int(np.count_nonzero(kept[zero] & ~kept[k]))
        if k != zero and b - c > SHRINK_Z * np.sqrt(b + c) and (best == zero or totals[k] > totals[best]):
            best = k
    return float(SHRINKS[best])


# ---------------------------------------------------------------------- the relocation
def relocate_eye(points, simplified, *, offset: float = 0.0, eye=None, original=None, target_height=None,
                 end_radius: float = 0.0, curvature: float = 0.0, earth_radius: float = EARTH_RADIUS,
                 n_partners: int = N_PARTNERS, sweeps: int = SWEEPS, seed: int = 0, min_gain: int = MIN_GAIN,
                 neighbours: bool = True, sight=None) -> np.ndarray:
    """The eye relocation, registered as ``"eye"``: each point at ``S(x, y) + offset + e(x, y)``.

    Parameters
    ----------
    points : (n, 3) array_like
        Points on (or ``offset`` above) T. Never modified.
    simplified : HeightGrid or TIN
        S(T).
    eye : EyeSurface, optional
        The eye surface shipped with S(T) (:func:`eye_surface`), fitted for this ``offset``.
        Without it, ``original`` is required and one is fitted (once per S(T) and
        options: it is cached on ``simplified``), as :func:`terrainvis.compare` does.
    original : HeightGrid, optional
        T, to fit the eye surface when ``eye`` is not given.
    offset, target_height, end_radius, curvature, earth_radius, n_partners, sweeps, seed, min_gain, neighbours
        The fit's (:func:`eye_surface`), when it is fitted here.
    sight : Sight, optional
        The fit's predicate as one value, instead of ``end_radius``, ``curvature`` and
        ``earth_radius`` (:func:`terrainvis.relocation.calibrated.predicate_of`).

    Returns
    -------
    (n, 3) float64
        A new array; x and y are unchanged.
    """
    pts = as_points(points, "points", 3)
    off = as_finite_scalar(offset, "offset")
    end_radius, curvature, earth_radius = predicate_of(sight, end_radius=end_radius, curvature=curvature,
                                                       earth_radius=earth_radius).values()
    if eye is None:
        if original is None:
            raise TypeError("relocate(..., 'eye') needs eye=, an EyeSurface shipped with S(T) "
                            "(terrainvis.eye_surface(T, S)), or original=, T, to fit one")
        eye = _fitted(original, simplified, off, target_height, dict(
            end_radius=end_radius, curvature=curvature, earth_radius=earth_radius, n_partners=n_partners,
            sweeps=sweeps, seed=seed, min_gain=min_gain, neighbours=neighbours))
    elif not isinstance(eye, EyeSurface):
        raise TypeError(f"eye must be a terrainvis.relocation.eye.EyeSurface, got {describe(eye)}")
    if eye.offset != off:
        raise ValueError(f"eye was fitted for points {eye.offset:g} above the ground, but offset is {off:g}; fit "
                         f"one with terrainvis.eye_surface(T, S, offset={off:g})")
    if target_height is not None and eye.target_height != float(target_height):
        raise ValueError(f"eye was fitted for target_height={eye.target_height}, but target_height is "
                         f"{target_height!r}")
    out = pts.copy()
    if pts.shape[0]:
        out[:, 2] = eye.heights(pts, simplified)
    return out


def _fitted(original, simplified, offset: float, target_height, options: dict) -> EyeSurface:
    """The eye surface of ``simplified`` fitted from ``original`` (cached on ``simplified``)."""
    if not isinstance(original, HeightGrid):
        raise TypeError(f"original must be a terrainvis.HeightGrid, got {describe(original)}")
    key = ("eye surface", fingerprint(original), float(offset),
           None if target_height is None else float(target_height)) + tuple(sorted(options.items()))
    cached = simplified._cache.get(key)
    if cached is None:
        cached = eye_surface(original, simplified, offset=offset, target_height=target_height, **options)
        simplified._cache[key] = cached
    return cached
