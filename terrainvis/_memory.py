"""Returning freed heap memory to the operating system."""

from __future__ import annotations

import contextlib
import sys


def release_freed_memory() -> None:
    """Ask glibc to give freed heap pages back to the OS (``malloc_trim(0)``); elsewhere nothing.

    Libraries that build large meshes in C++ (pymeshlab holds ~1.1 GB at its peak on a
    1024² grid) free them on return, but glibc keeps the pages: the process stays at
    ~690 MB for the rest of its life. Trimmed, it drops to ~240 MB (measured), which is
    what lets two workers share a machine's memory.
    """
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(Exception):  # not glibc (musl), or no libc found: nothing to do
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)


# ------------------------------------------------------------ memory before allocation
def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (``MemAvailable`` on Linux), or None when unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def format_bytes(n: float) -> str:
    """``n`` bytes as a short human figure (binary units).

    Examples
    --------
    >>> format_bytes(80_000_000_000), format_bytes(3 * 2**20)
    ('74.5 GiB', '3 MiB')
    """
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} bytes"


def check_memory(need: float, what: str) -> None:
    """Refuse (:class:`terrainvis.errors.NotEnoughMemoryError`) a request that needs more than is available.

    ``need`` is an estimate in bytes of the peak the request adds; ``what`` names the
    request in the message ("reading 'x.npy' (100000x100000 float64)"). Nothing is
    refused when the available memory is unknown.
    """
    from .errors import NotEnoughMemoryError

    avail = available_memory()
    if avail is not None and need > avail:
        raise NotEnoughMemoryError(
            f"{what} needs about {format_bytes(need)}; this machine has {format_bytes(avail)} available"
        )
