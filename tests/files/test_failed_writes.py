"""A write that fails (a full disk) leaves the earlier file intact and is reported as a failure.

GDAL reports some failed GeoTIFF writes only as lines on stderr and closes the file as if
it were complete; terrainvis must not rename such a file over a good one. Two ways to make
a write fail, both real failures of the operating system, no monkeypatching:

* a file-size limit (``RLIMIT_FSIZE``) on a subprocess: every write past the limit fails
  with EFBIG, as a full disk fails with ENOSPC; available wherever POSIX is;
* a full tmpfs, where this machine lets the tests mount one (root), else skipped.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import pytest

pytest.importorskip("rasterio")
resource = pytest.importorskip("resource")

#: bytes a subprocess may write into one file: the TIFF header and a little more
LIMIT = 400


def _terrainvis() -> list[str]:
    return [sys.executable, "-m", "terrainvis.cli"]


def _limited(argv, limit=LIMIT, cwd=None):
    """Run ``argv`` with files limited to ``limit`` bytes; SIGXFSZ ignored so the write fails with EFBIG."""

    def limit_files():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run([str(a) for a in argv], preexec_fn=limit_files, capture_output=True, text=True,
                          cwd=cwd, timeout=600)


def _good_file(path: Path, argv) -> bytes:
    """Write ``path`` with the command ``argv`` (no limit) and return its bytes."""
    r = subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return path.read_bytes()


def _assert_failed_cleanly(r, path: Path, before: bytes, command: str) -> None:
    assert r.returncode == 1, (r.returncode, r.stdout, r.stderr)
    lines = [line for line in r.stderr.strip().splitlines() if "%|" not in line]  # progress bars aside
    assert len(lines) == 1, r.stderr  # one line: GDAL's own messages are folded into it
    assert lines[0].startswith(f"terrainvis {command}: error: could not write {path}"), lines[0]
    assert "File too large" in lines[0] or "No space left" in lines[0], lines[0]
    assert "wrote" not in r.stdout
    assert path.read_bytes() == before  # the good file is untouched
    assert sorted(p.name for p in path.parent.iterdir() if p.name.startswith(".")) == []  # no temporary left


def test_viewshed_geotiff_on_a_full_disk_keeps_the_old_file(tmp_path):
    out = tmp_path / "old.tif"
    before = _good_file(out, _terrainvis() + ["viewshed", "hills", "--observer", 50, 50, "-o", out])
    r = _limited(_terrainvis() + ["viewshed", "hills", "--observer", 30, 50, "-o", out])
    _assert_failed_cleanly(r, out, before, "viewshed")


def test_cumulative_geotiff_on_a_full_disk_keeps_the_old_file(tmp_path):
    obs = tmp_path / "obs.csv"
    obs.write_text("x,y\n600,600\n1800,2400\n")
    out = tmp_path / "c.tif"
    before = _good_file(out, _terrainvis() + ["cumulative", "hills", "--observers", obs, "-o", out])
    obs.write_text("x,y\n600,600\n1800,2400\n3000,300\n")
    r = _limited(_terrainvis() + ["cumulative", "hills", "--observers", obs, "-o", out])
    _assert_failed_cleanly(r, out, before, "cumulative")


def test_simplify_geotiff_on_a_full_disk_keeps_the_old_file(tmp_path):
    # level 0 keeps the uniform grid, which a GeoTIFF stores as it is
    tif = tmp_path / "s.tif"
    before = _good_file(tif, _terrainvis() + ["simplify", "ridges", "-m", "simple", "-l", "0", "-o", tif])
    r = _limited(_terrainvis() + ["simplify", "hills", "-m", "simple", "-l", "0", "-o", tif])
    _assert_failed_cleanly(r, tif, before, "simplify")


def test_save_dem_on_a_full_disk_raises_and_keeps_the_old_file(tmp_path):
    out = tmp_path / "dem.tif"
    script = textwrap.dedent(f"""
        import sys
        import terrainvis as tv
        from terrainvis.errors import OutputError
        name = sys.argv[1]
        try:
            tv.save_dem(tv.synthetic_terrain(name), {str(out)!r})
        except OutputError as exc:
            print("OutputError:", exc)
            sys.exit(3)
        print("saved")
    """)
    before = _good_file(out, [sys.executable, "-c", script, "ridges"])
    r = _limited([sys.executable, "-c", script, "hills"])
    assert r.returncode == 3, (r.stdout, r.stderr)
    assert f"OutputError: could not write {out}: GDAL could not write the GeoTIFF" in r.stdout
    assert r.stderr == ""  # GDAL's lines are in the message, not left on stderr
    assert out.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_good_write_still_prints_what_gdal_warned(tmp_path):
    """The capture of GDAL's stderr only holds it back while the write runs: a plain write prints nothing extra."""
    out = tmp_path / "v.tif"
    r = subprocess.run(_terrainvis() + ["viewshed", "hills", "--observer", "50", "50", "-o", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and r.stderr == "" and f"wrote {out}" in r.stdout


@contextlib.contextmanager
def _small_tmpfs(size_kib: int):
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("a tmpfs needs root and mount(8); the file-size-limit tests above cover the same failure")
    where = Path("/tmp") / f"terrainvis-full-{uuid.uuid4().hex[:8]}"
    where.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kib}k", "tmpfs", str(where)], capture_output=True,
                       text=True)
    if r.returncode != 0:
        where.rmdir()
        pytest.skip(f"this machine does not let the tests mount a tmpfs ({r.stderr.strip()})")
    try:
        yield where
    finally:
        subprocess.run(["umount", str(where)], capture_output=True)
        with contextlib.suppress(OSError):
            where.rmdir()


def test_viewshed_on_a_full_tmpfs_keeps_the_old_file():
    with _small_tmpfs(200) as disk:
        out = disk / "old.tif"
        before = _good_file(out, _terrainvis() + ["viewshed", "hills", "--observer", 50, 50, "-o", out])
        filler = disk / "filler"
        fd = os.open(filler, os.O_WRONLY | os.O_CREAT)
        try:
            while os.write(fd, b"\0" * 4096):
                pass
        except OSError:  # the disk is full
            pass
        finally:
            os.close(fd)
        r = subprocess.run(_terrainvis() + ["viewshed", "hills", "--observer", "30", "50", "-o", str(out)],
                           capture_output=True, text=True, timeout=600)
        assert r.returncode == 1, (r.stdout, r.stderr)
        assert r.stderr.strip().splitlines() == [r.stderr.strip()]
        assert "No space left on device" in r.stderr
        assert out.read_bytes() == before
        assert sorted(p.name for p in disk.iterdir()) == ["filler", "old.tif"]


@pytest.mark.parametrize("dtype", ["float32", "float64", "uint8", "int16", "uint16", "int32"])
def test_the_read_back_compares_as_array_equal_with_nan_does(dtype):
    """The bit-for-bit shortcut of the read-back check says what ``np.array_equal(...,
    equal_nan=True)`` says: NaN of other payloads and -0.0 are equal, other values are not."""
    import numpy as np
    from hypothesis import given, settings
    from hypothesis import strategies as st
    from hypothesis.extra.numpy import arrays

    from terrainvis.io._geotiff import _same_values

    dt = np.dtype(dtype)
    floats = dt.kind == "f"

    @settings(max_examples=60, deadline=None)
    @given(arrays(dt, st.tuples(st.integers(1, 6), st.integers(1, 6))), st.data())
    def check(a, data):
        b = a.copy()
        flat = b.reshape(-1)
        for i in data.draw(st.lists(st.integers(0, flat.size - 1), max_size=3)):
            kind = data.draw(st.sampled_from(["nan", "zero", "value"] if floats else ["value"]))
            if kind == "nan" and np.isnan(flat[i]):
                bits = flat[i:i + 1].view(f"u{dt.itemsize}")
                bits ^= 1  # another NaN (the payload's lowest bit)
            elif kind == "zero" and flat[i] == 0:
                flat[i] = -flat[i]
            else:
                flat[i] = data.draw(arrays(dt, 1))[0]
        assert _same_values(a, b) == bool(np.array_equal(a, b, equal_nan=True))
        assert _same_values(a, a.copy())

    check()
