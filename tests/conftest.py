"""Shared fixtures: the real DEMs in ../shared/data/dem and the bundled terrains."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DEM = REPO.parent / "shared" / "data" / "dem"
DEM_NAMES = ("jacksboro_fault_tn", "mount_st_helens_wa", "green_mountains_vt", "west_bijou_escarpment_co")
#: The real DEMs the simplifiers' tests run on: the shared ones and the Jacksboro window that
#: ``compare`` uses by default (from the DEM that ships with matplotlib), which is always
#: present, so that a clone without ../shared still tests a real DEM.
REAL_DEM_NAMES = DEM_NAMES + ("jacksboro_window",)


def one_line_error(capsys, code: int, argv: list) -> str:
    """Run the command line on ``argv``: it must exit with ``code`` and print one line on
    stderr, without a traceback; that line."""
    from terrainvis.cli import main

    capsys.readouterr()
    got = main(argv)
    err = capsys.readouterr().err.strip()
    assert got == code, err
    assert "\n" not in err and "Traceback" not in err, err
    return err


def shared_dem_path(name: str, suffix: str = ".npz") -> Path:
    """Path of a shared DEM, skipping the test (with the reason) when it is absent."""
    path = SHARED_DEM / f"{name}{suffix}"
    if not path.exists():
        pytest.skip(f"shared DEM {path} is absent (the ../shared folder is not beside this checkout)")
    return path


@pytest.fixture(scope="session")
def shared_dems():
    """Every shared DEM as a HeightGrid, keyed by name (loaded once per session)."""
    from terrainvis import load_dem

    out = {}
    for name in DEM_NAMES:
        out[name] = load_dem(shared_dem_path(name))
    return out


def shared_dem_120(name: str):
    """A NaN-free 120x120 crop from the middle of a shared DEM's valid window (or, for
    ``"jacksboro_window"``, compare's default Jacksboro window, 120x120 too)."""
    from terrainvis import load_dem

    if name == "jacksboro_window":
        from terrainvis.experiment import resolve_terrains

        return resolve_terrains(["jacksboro"])["jacksboro"]

    grid = load_dem(shared_dem_path(name))
    return grid.crop(*grid.valid_window(size=120))


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def pytest_configure(config):
    """Give this process Python's own SIGINT handler if it started with SIGINT ignored.

    A POSIX shell without job control starts a background job (``command &``) with SIGINT
    ignored, and an ignored disposition survives exec: every subprocess the interrupt
    tests start would then ignore the Ctrl-C they send and time out. The tests need the
    disposition a user's terminal gives.
    """
    import signal

    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
