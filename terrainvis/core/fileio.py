"""Writing files safely: atomically, never over an input, one run per output.

* Every file terrainvis writes (DEMs, meshes, result tables, figures, simplified
  terrains) goes through :func:`atomic_path`: the writer fills a temporary file in the
  destination's folder, which is flushed to disk and renamed over the destination only
  when the writer finished without an exception. A rename within one folder is atomic on
  POSIX and Windows, so a reader sees either the old file or the complete new one. A
  failed write (a full disk, no permission) raises :class:`OutputError`, naming the
  destination, not the temporary file.
* :func:`check_output_file` checks an output before anything is computed: its folder
  exists and is writable, and it is neither one of the inputs (under any spelling or
  through a symlink) nor a file of the installed package (:func:`protected_folders`).
* :class:`RunLock` keeps a second process from writing the same results.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import tempfile
import time
import warnings
from pathlib import Path

from ..errors import OutputError

__all__ = [
    "atomic_path", "atomic_write_text", "check_writable_dir", "check_output_file", "refuse_protected",
    "protected_folders", "OutputError", "RunLock", "OutputBusyError",
]


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
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix if suffix is None else suffix, dir=folder)
    except OSError as exc:
        raise OutputError(path, exc) from exc
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
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError) and not isinstance(exc, OutputError):
            raise OutputError(path, exc, tmp) from exc
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


# ---------------------------------------------------------------------- inputs and the package
def protected_folders() -> list[Path]:
    """The folders of the installed package, which terrainvis never writes into:
    ``terrainvis``, ``simplifiers`` and the bundled data (``terrainvis.data``)."""
    from importlib import resources, util

    out = [Path(__file__).resolve().parents[1]]  # terrainvis/, not terrainvis/core/
    spec = util.find_spec("simplifiers")
    if spec is not None and spec.submodule_search_locations:
        out += [Path(p).resolve() for p in spec.submodule_search_locations]
    with contextlib.suppress(Exception):
        out.append(Path(str(resources.files("terrainvis.data"))).resolve())
    return out


def refuse_protected(path, name: str, inputs=(), outputs=None) -> None:
    """Refuse ``path`` as an output when it is one of ``inputs``, another output of the
    command (``outputs``), or lies inside the installed package.

    ``inputs`` are paths (others, e.g. bundled names, are ignored). ``outputs`` maps the
    flags of the command's other outputs to their paths, which need not exist yet. The
    same file is found under any spelling (``./x``, ``a/../x``), through symlinks (a
    dangling one too) and hard links.

    Raises
    ------
    ValueError
        Naming ``name``, the output and the input, other output or package folder it
        would overwrite.
    """
    p = Path(path)
    real = Path(os.path.realpath(p))
    for flag, other in (outputs or {}).items():
        same = real == Path(os.path.realpath(other))
        if not same and p.exists() and Path(other).exists():
            with contextlib.suppress(OSError):
                same = os.path.samefile(p, other)
        if same:
            how = "" if str(p) == str(other) else f" (the same file as {str(other)!r})"
            raise ValueError(f"{name} {str(p)!r} is also this command's {flag}{how}: one would overwrite the "
                             "other; give each output its own file")
    for inp in inputs:
        if not isinstance(inp, (str, Path)) or not Path(inp).exists():
            continue
        same = real == Path(os.path.realpath(inp))
        if not same and p.exists():
            with contextlib.suppress(OSError):
                same = os.path.samefile(p, inp)
        if same:
            how = "" if str(p) == str(inp) else f" (the same file as {str(inp)!r})"
            raise ValueError(
                f"{name} {str(p)!r} is an input of this command{how}; terrainvis never overwrites its input: "
                "choose another output file"
            )
    for folder in protected_folders():
        if real == folder or folder in real.parents:
            raise ValueError(
                f"{name} {str(p)!r} lies inside the installed terrainvis package ({folder}); "
                "write it somewhere else"
            )


def check_output_file(path, name: str, *, inputs=(), outputs=None) -> Path:
    """``path`` as a file that can be written, checked before anything is computed.

    Its folder must exist and be writable; it must not be a folder, one of ``inputs``,
    one of the command's other ``outputs`` ({flag: path}), or inside the installed package
    (:func:`refuse_protected`).

    Raises
    ------
    ValueError
        Naming ``name``, the path and what is wrong.
    """
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise ValueError(f"{name} {str(p)!r} is a folder; give a file name")
    if not folder.exists():
        raise ValueError(f"{name} {str(p)!r}: the folder {str(folder)!r} does not exist")
    if not folder.is_dir():
        raise ValueError(f"{name} {str(p)!r} lies under {str(folder)!r}, which is a file, not a folder")
    refuse_protected(p, name, inputs, outputs)
    try:
        fd, probe = tempfile.mkstemp(prefix=".write-test.", dir=folder)
    except OSError as exc:
        raise ValueError(f"{name} {str(p)!r} cannot be written: the folder {str(folder)!r} is not writable "
                         f"({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(probe)
    return p


# ---------------------------------------------------------------------- one run per output
class OutputBusyError(ValueError):
    """Another process holds the output (:class:`RunLock`); the message names it."""


_HELD: dict[str, list] = {}  # lock path -> [lock, depth]: a process may take its own lock again


class RunLock:
    """An exclusive, advisory lock on an output, held by one process for the length of a run.

    The lock is the file ``path`` (for ``terrainvis compare``, ``results.lock`` beside
    ``results.csv``), holding the holder's pid, host, start time and command as JSON,
    locked with ``flock`` where the platform has it. A second process is refused with
    :class:`OutputBusyError` naming the first. A lock file left by a process that died
    (SIGKILL, power loss) holds no ``flock``: it is taken over with a warning. The same
    process may take its lock again (``compare`` inside ``terrainvis compare``); it is
    released when the outermost holder leaves. Without ``flock`` (or on a file system
    that refuses it), the pid in the file decides: a live pid on this host holds it.

    Parameters
    ----------
    path : str or Path
        The lock file (its folder must exist).
    label : str
        How messages name the output (``"--out 'run'"``, ``"out_csv 'r.csv'"``).
    command : str
        What the holder is doing, recorded for the message a second process gets.
    """

    def __init__(self, path, label: str, command: str = "terrainvis"):
        self.path = Path(path)
        self.label = label
        self.command = command
        self._fd: int | None = None
        self._key = os.path.realpath(self.path)

    def __enter__(self) -> RunLock:
        held = _HELD.get(self._key)
        if held is not None:
            held[1] += 1
            return self
        self._acquire()
        _HELD[self._key] = [self, 1]
        return self

    def __exit__(self, *exc) -> None:
        held = _HELD[self._key]
        held[1] -= 1
        if held[1] == 0:
            del _HELD[self._key]
            held[0]._release()

    # ---------------------------------------------------------------- taking it
    def _acquire(self) -> None:
        try:
            import fcntl
        except ImportError:  # not POSIX
            fcntl = None
        for _ in range(20):  # another process may remove the file between our open and our flock
            if fcntl is None:
                if self._acquire_by_pid():
                    return
                continue
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
            except OSError as exc:
                raise OutputError(self.path, exc) from exc
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read_holder(fd)
                os.close(fd)
                raise self._busy(holder) from None
            except OSError:  # a file system without flock: the pid decides
                os.close(fd)
                fcntl = None
                continue
            if not _same_file(fd, self.path):
                os.close(fd)
                continue
            previous = _read_holder(fd)
            self._fd = fd
            self._write_holder()
            if previous:
                self._note_stale(previous)
            return
        raise OutputBusyError(f"{self.label}: could not take its lock {str(self.path)!r} (it keeps changing)")

    def _acquire_by_pid(self) -> bool:
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666)
        except OSError as exc:
            if not isinstance(exc, FileExistsError):
                raise OutputError(self.path, exc) from exc
            try:
                holder = json.loads(self.path.read_text(encoding="utf-8") or "{}")
            except (OSError, ValueError):
                holder = {}
            if _alive(holder):
                raise self._busy(holder) from None
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
            if holder:
                self._note_stale(holder)
            return False
        self._fd = fd
        self._write_holder()
        return True

    def _write_holder(self) -> None:
        record = {"pid": os.getpid(), "host": socket.gethostname(), "command": self.command,
                  "started": time.strftime("%Y-%m-%d %H:%M:%S %z")}
        try:
            os.ftruncate(self._fd, 0)
            os.lseek(self._fd, 0, os.SEEK_SET)
            os.write(self._fd, (json.dumps(record) + "\n").encode())
        except OSError as exc:
            self._release()
            raise OutputError(self.path, exc) from exc
        with contextlib.suppress(OSError):
            os.fsync(self._fd)

    def _busy(self, holder: dict) -> OutputBusyError:
        return OutputBusyError(
            f"{self.label} is in use by another run: {_describe_holder(holder)}; wait for it to finish, or write "
            "to another output"
        )

    def _note_stale(self, holder: dict) -> None:
        warnings.warn(
            f"{self.label}: took over the lock left by {_describe_holder(holder)}, which is no longer running",
            RuntimeWarning, stacklevel=4,
        )

    # ---------------------------------------------------------------- giving it back
    def _release(self) -> None:
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            self.path.unlink()  # while still holding it: a waiting process re-checks the file it locked
        os.close(self._fd)
        self._fd = None


def _read_holder(fd: int) -> dict:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        text = os.read(fd, 4096).decode("utf-8", "replace").strip()
        return json.loads(text) if text else {}
    except (OSError, ValueError):
        return {"unreadable": True}


def _same_file(fd: int, path: Path) -> bool:
    try:
        a, b = os.fstat(fd), os.stat(path)
    except OSError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def _alive(holder: dict) -> bool:
    pid = holder.get("pid")
    if not isinstance(pid, int):
        return False
    if holder.get("host", socket.gethostname()) != socket.gethostname():
        return True  # a process on another host (a shared file system): it cannot be checked from here
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # it exists, owned by someone else
        return True
    return True


def _describe_holder(holder: dict) -> str:
    if not holder.get("pid"):
        return "an unknown process (its lock file is unreadable)"
    where = f" on {holder['host']}" if holder.get("host") and holder["host"] != socket.gethostname() else ""
    what = f"{holder.get('command', 'terrainvis')}, " if holder.get("command") else ""
    return f"{what}pid {holder['pid']}{where}, started {holder.get('started', 'at an unknown time')}"
