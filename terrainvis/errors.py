"""Exceptions raised by terrainvis.

Every exception subclasses a built-in one, so ``except ValueError`` keeps working.
"""

from __future__ import annotations

import signal

__all__ = ["NodataError", "OutsideFootprintError", "SimplificationError", "NotEnoughMemoryError", "OutputError",
           "Interrupted", "WorkersDied"]


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


class Interrupted(KeyboardInterrupt):
    """The run was interrupted by SIGINT or SIGTERM; ``signum`` says which."""

    def __init__(self, signum: int = signal.SIGINT):
        self.signum = int(signum)
        super().__init__(f"interrupted by {signal.Signals(self.signum).name}")


class WorkersDied(RuntimeError):
    """The worker processes died (killed, out of memory, or a script re-imported by spawn without its guard).

    ``cause`` is the pool's own message. ``str()`` gives the advice for a script; the
    command line, which has no script to guard, says what to do there itself.
    """

    def __init__(self, cause: str):
        self.cause = cause
        super().__init__(
            "the worker processes died. They are started with 'spawn', which imports your __main__ module "
            "again: in a script, call compare() under `if __name__ == \"__main__\":`, or pass workers=1 to run in "
            f"this process. Units finished before the failure are in out_csv if one was given ({cause})"
        )
