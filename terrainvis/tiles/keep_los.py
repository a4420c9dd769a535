"""``keep_los``: each zoom's vertical error chosen by line of sight (``terrainvis tiles --keep-los P``).

Every tiler sets one knob per zoom, the largest vertical error a tile may have, by a rule
of thumb (half of the zoom above). :func:`choose_budget` chooses it by what the tiles do to
line of sight instead: the largest error whose tiles keep at least a share ``P`` of the
line-of-sight verdicts of their sight lines.

The sight lines of a tile
-------------------------
A tile's sight lines are the pairs of :data:`N_POINTS` points (780 pairs) drawn uniformly
over its lattice (the tile's part of the tileset's rectangle; drawn with the seed ``(z, x,
y)``, so a run and its resume draw the same points), each ``height`` above the ground
(default :data:`DEFAULT_LOS_HEIGHT`, 2 m). Their lengths run up to the tile's diagonal,
the distances at which a client shows the tiles of that zoom. The reference is the tile's
lattice, the tile as it would be unsimplified: the verdicts on T are those of the exact
predicate on the lattice's surface (the DEM's heights at the lattice points, piecewise
linear between them), in the tile's local metric frame (equirectangular about its centre,
where the tile's error is measured too). The share thus counts what the simplification
loses, the only part the budget sets; what the lattice itself loses against the DEM
depends on the zoom and the lattice's size alone. On the tile, the same points stand
``height`` above the decoded mesh (the paper's full projection) and the verdicts are the same
predicate's on that TIN, as a client would see it: quantized positions and heights. A tile
keeps a pair when both verdicts agree.

The search
----------
The budgets tried (the rungs) run down from the largest height range of the zoom's
lattices, a budget that any tile meets with its coarsest mesh, each rung the one above
divided by sqrt(2), at most :data:`MAX_RUNGS` of them. Every rung simplifies every tile of
the zoom as :func:`terrainvis.tiles.write_tileset` makes them (encoded, decoded, retried
when over budget), and the zoom's budget is the first rung at which its tiles together
keep at least ``P`` of their pairs: the largest budget of the ladder that does, whether or
not the share falls steadily with the budget. The tiles of that rung are the ones
written. The cost is about the number of rungs tried times the zoom's tiles. When no rung
reaches ``P``, the zoom is written as whole lattices (budget 0) and the report says what
they keep: quantized heights can move grazing verdicts, so a share of 1 may not be
reachable at all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..core.sampling import sample_points
from ..core.terrain import TIN, HeightGrid

__all__ = ["N_POINTS", "DEFAULT_LOS_HEIGHT", "MAX_RUNGS", "Sights", "ZoomChoice", "tile_sights", "kept_pairs",
           "choose_budget", "check_keep_los"]

#: Points drawn in each tile; their pairs are its sight lines (40 points: 780 pairs).
N_POINTS = 40
#: Both ends of a sight line stand this high above the ground (m).
DEFAULT_LOS_HEIGHT = 2.0
#: The most budgets tried per zoom (each rung the one above divided by sqrt(2): a factor of 4,096 in all).
MAX_RUNGS = 24


def check_keep_los(keep_los, los_height, names: dict) -> tuple[float | None, float]:
    """``keep_los`` in (0, 1] (or None) and ``los_height`` a finite height >= 0, or a ValueError naming them."""
    if keep_los is not None:
        if isinstance(keep_los, (bool, np.bool_)) or not isinstance(keep_los, (int, float, np.integer, np.floating)) \
                or not math.isfinite(keep_los) or not 0.0 < keep_los <= 1.0:
            raise ValueError(f"{names['keep_los']} must be a share of the verdicts in (0, 1], got {keep_los!r}")
        keep_los = float(keep_los)
    from ..core.validate import as_nonnegative_finite

    return keep_los, as_nonnegative_finite(los_height, names["los_height"], "m")


@dataclass(frozen=True)
class Sights:
    """A tile's sight lines: the points' x, y (the tile's local frame), their height above the ground,
    and T's verdict of each pair (``i < j``, in ``np.triu_indices`` order)."""

    xy: np.ndarray
    height: float
    verdicts: np.ndarray


def _lattice_grid(lat_) -> HeightGrid:
    """The lattice as it lies: its heights at its points in the tile's local frame (not evenly spaced)."""
    xs, ys = lat_.to_local(lat_.lon, lat_.lat)
    return HeightGrid.from_coords(lat_.z, xs, ys)


def _pair_verdicts(terrain, pts: np.ndarray) -> np.ndarray:
    from ..visibility import visibility_matrix

    return visibility_matrix(terrain, pts)[np.triu_indices(pts.shape[0], 1)]


def tile_sights(lat_, z: int, x: int, y: int, height: float = DEFAULT_LOS_HEIGHT, n: int = N_POINTS) -> Sights:
    """The sight lines of tile ``(z, x, y)`` over its lattice ``lat_`` (:func:`terrainvis.tiles.tile_lattice`)
    and T's verdicts of them (the module docstring)."""
    grid = _lattice_grid(lat_)
    pts = sample_points(grid, n, seed=np.random.default_rng([int(z), int(x), int(y)]), offset=height)
    return Sights(pts[:, :2].copy(), float(height), _pair_verdicts(grid, pts))


def kept_pairs(lat_, sights: Sights, decoded) -> int:
    """How many of ``sights``' pairs keep T's verdict on the tile ``decoded`` (a :class:`DecodedTile` of
    ``lat_``'s tile), the points standing ``sights.height`` above its mesh."""
    xs, ys = lat_.to_local(decoded.lon, decoded.lat)
    tin = TIN(np.column_stack([xs, ys, decoded.height]), decoded.triangles)
    ground = tin.height_at(sights.xy)
    if not np.isfinite(ground).all():  # the decoded mesh covers the lattice: this would be a defect here
        raise AssertionError("a tile's mesh misses some of its own sight lines' points")
    pts = np.column_stack([sights.xy, ground + sights.height])
    return int(np.count_nonzero(_pair_verdicts(tin, pts) == sights.verdicts))


@dataclass(frozen=True)
class ZoomChoice:
    """A zoom's budget chosen by :func:`choose_budget`.

    ``budget`` is the largest rung at which the tiles keep at least the share asked for (``reached``),
    or 0.0 when none does (not ``reached``: whole lattices); ``kept`` of ``pairs`` is what the written
    tiles keep; ``tried`` holds ``(budget, share kept)`` for every rung tried, from the largest."""

    budget: float
    reached: bool
    kept: int
    pairs: int
    tried: tuple

    @property
    def share(self) -> float:
        return self.kept / self.pairs if self.pairs else 1.0

    def as_json(self) -> dict:
        return {"budget": self.budget, "reached": self.reached, "kept": self.kept, "pairs": self.pairs,
                "tried": [list(t) for t in self.tried]}

    @classmethod
    def from_json(cls, d: dict) -> "ZoomChoice":
        return cls(float(d["budget"]), bool(d["reached"]), int(d["kept"]), int(d["pairs"]),
                   tuple(tuple(t) for t in d["tried"]))


def choose_budget(lattices: dict, z: int, share: float, height: float, make: Callable) -> tuple[ZoomChoice, dict]:
    """The zoom's budget (the module docstring) and the tiles made at it.

    Parameters
    ----------
    lattices : {(x, y): lattice}
        The zoom's tiles (:func:`terrainvis.tiles.tile_lattice`).
    z : int
    share : float
        The share of the pairs to keep, in (0, 1].
    height : float
        The sight lines' ends above the ground (m).
    make : callable
        ``make(lattice, budget)`` -> the made tile (``.decoded`` its :class:`DecodedTile`), budget None for
        the whole lattice.

    Returns
    -------
    (ZoomChoice, {(x, y): made tile})
    """
    sights = {k: tile_sights(lat_, z, *k, height) for k, lat_ in lattices.items()}
    pairs = sum(s.verdicts.size for s in sights.values())
    top = max((float(np.ptp(lat_.z)) for lat_ in lattices.values()), default=0.0)
    tried = []
    for k in range(MAX_RUNGS if top > 0 else 0):
        budget = top * 2.0 ** (-k / 2)  # halves exactly every other rung
        made = {k: make(lat_, budget) for k, lat_ in lattices.items()}
        kept = sum(kept_pairs(lattices[k], sights[k], m.decoded) for k, m in made.items())
        tried.append((budget, kept / pairs if pairs else 1.0))
        if kept >= share * pairs:
            return ZoomChoice(budget, True, kept, pairs, tuple(tried)), made
    made = {k: make(lat_, None) for k, lat_ in lattices.items()}
    kept = sum(kept_pairs(lattices[k], sights[k], m.decoded) for k, m in made.items())
    return ZoomChoice(0.0, False, kept, pairs, tuple(tried)), made
