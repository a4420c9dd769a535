"""Returning freed heap memory to the operating system."""

from __future__ import annotations

import contextlib
import sys


def release_freed_memory() -> None:
    """Ask glibc to give freed heap pages back to the OS (``malloc_trim(0)``); elsewhere nothing.

    Libraries that build large meshes in C++ (pymeshlab) free them on return, but glibc
    keeps the pages, and the process keeps its peak size for the rest of its life.
    Trimmed, it gives most of them back (docs/performance.md), which is what lets two
    workers share a machine's memory.
    """
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(Exception):  # not glibc (musl), or no libc found: nothing to do
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)


# ------------------------------------------------------------ memory before allocation
def available_memory() -> int | None:
    """Bytes of memory this process could still allocate, or None when it cannot tell.

    The least of: the kernel's estimate of available memory (``MemAvailable`` in
    ``/proc/meminfo``), the room left under this process's cgroup memory limit (v2
    ``memory.max``, v1 ``memory.limit_in_bytes``; containers and CI runners set one),
    and, elsewhere, the free physical pages (``sysconf``). An estimate: the page cache
    counts as available, and other processes may take memory meanwhile.
    """
    found = [v for v in (_meminfo_available(), _cgroup_room(), _sysconf_available()) if v is not None]
    return min(found) if found else None


def format_bytes(n: float) -> str:
    """``n`` bytes as a short human figure (binary units, 3 significant digits).

    Examples
    --------
    >>> format_bytes(80_000_000_000), format_bytes(3 * 2**20), format_bytes(1.8e15), format_bytes(999)
    ('74.5 GiB', '3 MiB', '1.6 PiB', '999 bytes')
    """
    for unit, size in (("PiB", 2**50), ("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} bytes"


def check_memory(need: float, what: str) -> None:
    """Refuse (:class:`terrainvis.errors.NotEnoughMemoryError`) a request that needs more than is available.

    ``need`` is an estimate in bytes of the peak the request adds; ``what`` names the
    request in the message ("reading 'x.npy' (100000x100000 float64)"). Nothing is
    refused when the available memory is unknown.
    """
    from ..errors import NotEnoughMemoryError

    avail = available_memory()
    if avail is not None and need > avail:
        raise NotEnoughMemoryError(
            f"{what} needs about {format_bytes(need)}; this machine has {format_bytes(avail)} available"
        )


def _read_int(path) -> int | None:
    try:
        with open(path, encoding="ascii") as fh:
            text = fh.read().strip()
    except (OSError, UnicodeDecodeError):
        return None
    return int(text) if text.isdigit() else None


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError, UnicodeDecodeError):
        return None
    return None


#: The cgroup files that bound this process's memory, ``(limit, usage)``: looked up once
#: (:func:`_cgroup_files`; a process stays in its cgroup), since a run checks memory before
#: every visibility matrix, thousands of times. ``()``: no limit was found.
_CGROUP_FILES: tuple | None = None


def _cgroup_files() -> tuple:
    """``(limit path, usage path)`` of the first cgroup folder with a memory limit, or ``()``."""
    global _CGROUP_FILES
    if _CGROUP_FILES is not None:
        return _CGROUP_FILES
    found = ()
    try:
        with open("/proc/self/cgroup", encoding="ascii") as fh:
            lines = fh.read().splitlines()
    except (OSError, UnicodeDecodeError):
        lines = []
    for line in lines:
        parts = line.split(":", 2)
        if len(parts) != 3:
            continue
        _, controllers, group = parts
        if controllers == "":  # cgroup v2 (unified)
            names, base = ("memory.max", "memory.current"), "/sys/fs/cgroup"
        elif "memory" in controllers.split(","):
            names, base = ("memory.limit_in_bytes", "memory.usage_in_bytes"), "/sys/fs/cgroup/memory"
        else:
            continue
        for folder in (base + group.rstrip("/"), base):  # the group's own folder, or the namespace's root
            paths = tuple(f"{folder}/{name}" for name in names)
            limit, used = (_read_int(p) for p in paths)
            if limit is not None and used is not None and limit < (1 << 60):
                found = paths
                break
        if found:
            break
    _CGROUP_FILES = found
    return found


def _cgroup_room() -> int | None:
    """The memory limit of this process's cgroup minus its usage (None: no limit, or not Linux)."""
    files = _cgroup_files()
    if not files:
        return None
    limit, used = (_read_int(p) for p in files)
    if limit is None or used is None or limit >= (1 << 60):
        return None
    return max(0, limit - used)


def _sysconf_available() -> int | None:
    if sys.platform.startswith("linux"):
        return None  # MemAvailable is the better figure there (it counts reclaimable cache)
    try:
        import os

        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def fresh_array(shape, dtype):
    """An empty array for a raster-sized buffer, without numpy's advice to back it with huge
    pages: this machine's kernel compacts memory synchronously to find huge pages on first
    touch, and after a large raster was read that stalled unpredictably (filling a 20000²
    grid took 2.3 to 6.7 s instead of 1.1 to 1.8 s; reading 8192²: 1.0-1.5 s against 0.75 s;
    a viewshed's 64 MiB of codes on 8192²: 0.04-0.15 s against 0.025 s). The sweep over
    such buffers was no slower without them."""
    import numpy as np

    multiarray = getattr(getattr(np, "_core", None), "multiarray", None) or getattr(np.core, "multiarray", None)
    toggle = getattr(multiarray, "_set_madvise_hugepage", None)
    if toggle is None:
        return np.empty(shape, dtype=dtype)
    before = toggle(False)
    try:
        return np.empty(shape, dtype=dtype)
    finally:
        toggle(before)
