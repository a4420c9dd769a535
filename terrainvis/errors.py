"""Exceptions raised by terrainvis.

Every exception subclasses a built-in one, so ``except ValueError`` keeps working.
"""

from __future__ import annotations

__all__ = ["NodataError", "OutsideFootprintError", "SimplificationError", "NotEnoughMemoryError", "OutputError"]


class NodataError(ValueError):
    """An operation that needs every sample to be finite met NaN (nodata) samples."""

    def __init__(self, operation: str, n_nan: int, shape: tuple[int, int]):
        self.operation = operation
        self.n_nan = int(n_nan)
        self.shape = tuple(shape)
        super().__init__(
            f"{operation} needs a grid without nodata, but z has {self.n_nan} NaN "
            f"cell(s) out of {shape[0]}x{shape[1]}; fill them with "
            f"HeightGrid.fill_nodata() or cut them away with HeightGrid.crop(...) "
            f"(HeightGrid.valid_window() gives the largest NaN-free window)"
        )


class OutsideFootprintError(ValueError):
    """Query points lie outside the terrain's footprint (or on a nodata cell)."""


class SimplificationError(RuntimeError):
    """A simplifier could not produce a valid result; the message names the method and cause."""


class NotEnoughMemoryError(MemoryError, ValueError):
    """A request refused before allocating: its estimated memory exceeds what is available.

    A :class:`MemoryError`, and a :class:`ValueError` too: the size of the request is the
    problem (a file header that claims 100000 x 100000 samples, a grid too large for a
    method), so callers that report bad input in one line report this one too. The
    message says how much is needed and how much is available.
    """


class OutputError(OSError):
    """Writing ``filename`` failed (a full disk, no permission, ...): the message names the file."""

    def __init__(self, path, cause: BaseException, tmp=None):
        reason = (cause.strerror if isinstance(cause, OSError) and cause.strerror else str(cause)) or type(cause).__name__
        if tmp is not None:
            reason = reason.replace(str(tmp), str(path))
        super().__init__(getattr(cause, "errno", None), reason)
        self.filename = str(path)
        self.reason = reason

    def __str__(self) -> str:
        return f"could not write {self.filename}: {self.reason}"
