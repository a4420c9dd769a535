"""Atomic file writes: a failure never leaves a damaged file where a good one was.

Every file terrainvis writes (DEMs, meshes, result tables, figures, simplified terrains)
goes through :func:`atomic_path`: the writer fills a temporary file in the destination's
folder, which is flushed to disk and renamed over the destination only when the writer
finished without an exception. A rename within one folder is atomic on POSIX and
Windows, so a reader sees either the old file or the complete new one.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_path", "atomic_write_text", "check_writable_dir"]


@contextlib.contextmanager
def atomic_path(path, *, suffix: str | None = None):
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    Parameters
    ----------
    path : str or Path
        The destination. Its folder must exist.
    suffix : str, optional
        Suffix of the temporary file (default: the destination's, so that writers that
        choose a format by extension, or append one, behave the same).

    Examples
    --------
    >>> import numpy as np, tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with atomic_path(d / "a.npy") as tmp:
    ...     np.save(tmp, np.arange(3))
    >>> np.load(d / "a.npy").tolist()
    [0, 1, 2]
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix if suffix is None else suffix, dir=folder)
    os.close(fd)
    tmp = Path(tmp)
    # mkstemp makes the file owner-only (0600); give it the mode a plain open() would
    # (0666 less the umask), or keep the mode of the file it replaces
    try:
        mode = path.stat().st_mode & 0o7777 if path.exists() else 0o666 & ~_umask()
        os.chmod(tmp, mode)
    except OSError:
        pass
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def atomic_write_text(path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_path`)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding=encoding)
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync(path: Path) -> None:
    with open(path, "rb+") as fh:
        os.fsync(fh.fileno())


def check_writable_dir(path, name: str) -> Path:
    """``path`` as a folder that exists (created when missing) and can be written to.

    Raises
    ------
    ValueError
        When ``path`` is an existing file, lies under a file, or cannot be created or
        written to; the message names ``name`` and the path.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ValueError(f"{name} must be a folder, but {str(p)!r} is an existing file")
    for parent in p.parents:
        if parent.exists():
            if not parent.is_dir():
                raise ValueError(f"{name} {str(p)!r} lies under {str(parent)!r}, which is a file, not a folder")
            break
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"{name} {str(p)!r} cannot be created: {exc.strerror or exc}") from None
    try:
        fd, probe = tempfile.mkstemp(prefix=".write-test.", dir=p)
    except OSError as exc:
        raise ValueError(f"{name} {str(p)!r} is not writable: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)
    return p
