"""The tolerance module: every small float literal lives in ``terrainvis/tolerances.py``,
and the rules that were written twice now have one implementation each."""

from __future__ import annotations

import ast
import math
import re
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

import terrainvis.tolerances as T
from terrainvis import TIN, HeightGrid, relocate, sample_points, volume_error
from terrainvis.core._georef import lonlat_to_local, metres_per_degree, uniform_step
from terrainvis.core.mesh import footprint_matches
from terrainvis.experiment.options import finite

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("terrainvis", "simplifiers")
#: A literal this small (and not 0) is a tolerance (or a floor) and belongs in tolerances.py.
SMALL = 1e-5

#: Small literals still written in place, by file (path from the repository root) and value,
#: with how many times each may appear. Every entry says why it is still there.
ALLOWED = {
    # Literals that are not tolerances: none. (Divisor floors such as 1e-300 are named too,
    # as DIVISOR_FLOOR, so that one search finds every one of them.)
}


def _small_literals(path: Path) -> list[tuple[int, float]]:
    """(line, value) of every float literal with 0 < |value| < SMALL (``-1e-9`` is ``1e-9``
    under a unary minus, so it is found as well)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Constant) and isinstance(node.value, float) and node.value != 0.0:
            if abs(node.value) < SMALL:
                out.append((node.lineno, node.value))
    return sorted(out)


def _sources():
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if path.name != "tolerances.py" or path.parent.name != "terrainvis":
                yield path.relative_to(ROOT).as_posix(), path


def test_scanner_finds_small_literals(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("a = 1e-9\nb = -2.5e-7 * x\nc = 1e-5\nd = 0.0\ne = 1e-300\nf = 10\n'1e-9 in text'\n")
    assert _small_literals(src) == [(1, 1e-9), (2, 2.5e-7), (5, 1e-300)]


def test_no_small_float_literal_outside_tolerances():
    unexpected = []
    for rel, path in _sources():
        found = _small_literals(path)
        allowed = ALLOWED.get(rel, {})
        counts = Counter(v for _, v in found)
        for value, n in counts.items():
            if n > allowed.get(value, 0):
                lines = [line for line, v in found if v == value]
                unexpected.append(f"{rel}: {value!r} x{n} (allowed {allowed.get(value, 0)}) at lines {lines}")
    assert not unexpected, (
        "small float literals outside terrainvis/tolerances.py (name them there, with what they "
        "protect, and import them):\n" + "\n".join(unexpected)
    )


def test_allow_list_only_shrinks():
    """Every allowed literal is still there: an entry that is no longer needed is removed."""
    stale = []
    for rel, allowed in ALLOWED.items():
        path = ROOT / rel
        counts = Counter(v for _, v in _small_literals(path)) if path.exists() else Counter()
        for value, n in allowed.items():
            if counts[value] < n:
                stale.append(f"{rel}: {value!r} allowed x{n}, found x{counts[value]}")
    assert not stale, "allow-list entries no longer needed (lower or remove them):\n" + "\n".join(stale)


# ---------------------------------------------------------------------- the module itself
def _assignments():
    """(name, line) of the module-level assignments of tolerances.py, and its source lines."""
    path = ROOT / "terrainvis" / "tolerances.py"
    lines = path.read_text(encoding="utf-8").splitlines()
    names = []
    for node in ast.parse("\n".join(lines)).body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            if node.targets[0].id != "__all__":
                names.append((node.targets[0].id, node.lineno))
    return names, lines


def test_every_tolerance_is_exported_positive_and_documented():
    names, lines = _assignments()
    assert sorted(n for n, _ in names) == sorted(T.__all__)
    assert len({n for n, _ in names}) == len(names)  # each named once
    for name, line in names:
        assert re.fullmatch(r"[A-Z][A-Z0-9_]*", name), name
        value = getattr(T, name)
        assert isinstance(value, float) and math.isfinite(value) and value > 0, (name, value)
        assert lines[line - 2].startswith("#: "), f"{name} needs a '#:' line saying what it protects"


def test_clearance_band_is_the_predicates():
    """height_limit's default and the line-of-sight predicate must use the same band."""
    from terrainvis.core.validate import height_limit
    from terrainvis.visibility import TOL_REL, clearance_tolerance, terrain_scale

    assert T.CLEARANCE_REL == TOL_REL
    g = HeightGrid(np.arange(12.0).reshape(3, 4) * 7.0, dx=10.0)
    assert clearance_tolerance(g) == T.CLEARANCE_REL * terrain_scale(g)
    assert height_limit(1000.0) == T.CLEARANCE_REL * 1000.0 / 2.0**-52


def test_kernel_modules_hold_the_constants():
    """numba freezes the kernel modules' globals: they must be the tolerance module's values."""
    import simplifiers._gc_kernels as gc
    import terrainvis.core._kernels as tk

    assert tk.BUCKET_SLACK == T.BUCKET_SLACK and tk.RASTER_BOX_REL == T.RASTER_BOX_REL
    assert gc.ROW_SPAN_SNAP == T.ROW_SPAN_SNAP


# ---------------------------------------------------------------------- one rule, one implementation
def _axis_with_bump(bump: float) -> np.ndarray:
    v = 1000.0 + 2.0 * np.arange(11)  # exact in float64: step 2, the mean step stays 2
    v[5] += bump
    return v


@pytest.mark.parametrize("bump, uniform", [(0.0, True), (1.5e-9, True), (-1.5e-9, True), (3e-9, False),
                                           (-3e-9, False), (1e-6, False)])
def test_uniform_axis_rule_by_hand(bump, uniform):
    # Steps 2 + bump and 2 - bump next to the bump; the allowance is UNIFORM_STEP_REL x 2
    # plus ROUNDING_ULPS ulps of 1020 (2e-9 + 1.8e-12).
    v = _axis_with_bump(bump)
    allowance = T.UNIFORM_STEP_REL * 2.0 + T.ROUNDING_ULPS * np.finfo(np.float64).eps * 1020.0
    assert (abs(v[5] - v[4] - 2.0) <= allowance) == uniform  # the hand-worked verdict
    assert (uniform_step(v) is not None) == uniform
    z = np.zeros((3, v.size))
    assert HeightGrid.from_coords(z, v, np.array([0.0, 1.0, 2.0])).is_uniform == uniform
    # the lon/lat conversion uses the same test: a uniform axis gets index * step * m/degree,
    # an uneven one its own offsets times m/degree
    lon = v / 100.0
    xs, _, _ = lonlat_to_local(lon, np.array([40.0, 40.01, 40.02]))
    m = metres_per_degree(0.5 * (40.0 + 40.02))[0]
    expected = np.arange(lon.size) * ((lon[-1] - lon[0]) / (lon.size - 1) * m) if uniform else (lon - lon[0]) * m
    assert np.array_equal(xs, expected)


def test_uniform_step_of_short_axes():
    assert uniform_step(np.array([3.0])) is None
    assert uniform_step(np.array([3.0, 4.5])) == 1.5
    assert HeightGrid.from_coords(np.zeros((2, 2)), [0.0, 1.0], [0.0, 7.0]).is_uniform


def _notched_square(depth: float) -> TIN:
    """The unit square with its bottom edge's midpoint pushed in by ``depth``: all faces
    counter-clockwise, the extent unchanged, the footprint ``1 - depth / 2``."""
    v = [[0, 0, 0], [0.5, depth, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0]]
    f = [[0, 1, 5], [1, 2, 5], [2, 3, 5], [3, 4, 5], [4, 0, 5]]
    return TIN(np.array(v, dtype=float), np.array(f))


@pytest.mark.parametrize("depth, covers", [(0.0, True), (1e-9, True), (1.9e-9, True), (4e-9, False), (1e-3, False)])
def test_footprint_rule_is_shared(depth, covers):
    tin = _notched_square(depth)
    assert (abs(tin.footprint_area() - 1.0) <= T.FOOTPRINT_REL * 1.0) == covers  # by hand: depth / 2 missing
    assert footprint_matches(tin.footprint_area(), 1.0) == covers
    assert tin.is_height_field() == covers
    fine = HeightGrid(np.zeros((3, 3)), dx=0.5, dy=0.5)
    if covers:
        assert volume_error(fine, tin) == 0.0
    else:
        with pytest.raises(ValueError, match="coarse must cover the footprint of fine"):
            volume_error(fine, tin)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), [1.0, 2.0], np.zeros((1,))])
def test_finite_scalar_checks_are_one(bad):
    g = HeightGrid(np.zeros((3, 3)))
    p = np.array([[0.5, 0.5, 1.0]])
    calls = (lambda: sample_points(g, 2, offset=bad), lambda: relocate(p, g, "full", offset=bad),
             lambda: finite(bad, "offset"))
    messages = set()
    for call in calls:
        with pytest.raises(ValueError, match="offset must be a finite scalar") as info:
            call()
        messages.add(str(info.value))
    assert len(messages) == 1


def test_finite_scalar_accepts_numbers():
    g = HeightGrid(np.zeros((3, 3)))
    assert sample_points(g, 1, offset=np.float32(1.5))[0, 2] == 1.5
    assert relocate(np.array([[0.5, 0.5, -4.0]]), g, "half", offset=np.array(2.0))[0, 2] == 2.0
    assert finite(3, "x") == 3.0 and isinstance(finite(3, "x"), float)


@pytest.mark.parametrize("bad", ["1.5", b"1", True, np.bool_(False), None, object()])
def test_real_number_parse_is_shared(bad):
    """as_positive_finite, as_nonnegative_finite and as_height refuse the same non-numbers alike."""
    from terrainvis.core.validate import as_height, as_nonnegative_finite, as_positive_finite

    for check in (lambda: as_positive_finite(bad, "v"), lambda: as_nonnegative_finite(bad, "v"),
                  lambda: as_height(bad, "v", scale=1000.0)):
        with pytest.raises(TypeError, match=r"^v must be a real number, got "):
            check()
