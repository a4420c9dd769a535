"""The progress bar class of terrainvis's long calls (compare, cumulative viewsheds)."""

from __future__ import annotations

import sys


def progress_bar_class():
    """tqdm's notebook bar in a Jupyter kernel that has ipywidgets, else the plain one.

    ``tqdm.auto`` would pick the notebook bar in any Jupyter kernel and, without
    ipywidgets, warn "IProgress not found" and fall back; this asks first.
    """
    from tqdm.std import tqdm as plain

    if not in_kernel():
        return plain
    try:
        import ipywidgets  # noqa: F401  (tqdm's notebook bar needs it)
        from tqdm import notebook
    except ImportError:
        return plain
    return notebook.tqdm if getattr(notebook, "IProgress", None) is not None else plain


def in_kernel() -> bool:
    """Whether this process is a Jupyter kernel (where a progress bar is drawn by the front end)."""
    shell = sys.modules["IPython"].get_ipython() if "IPython" in sys.modules else None
    try:
        return "ipykernel.zmqshell" in sys.modules or (shell is not None and "IPKernelApp" in shell.config)
    except Exception:  # an IPython without .config
        return False


def on_a_terminal() -> bool:
    """Whether stderr is a terminal, where bars are redrawn in place (a log file gets plain lines instead)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced or closed
        return False


def show_by_default() -> bool:
    """tqdm's convention: progress is shown where someone watches, a terminal or a notebook."""
    return on_a_terminal() or in_kernel()


class ProgressLines:
    """Progress as plain lines for a log file, where a bar redrawn in place leaves cursor
    escapes: ``desc: done/total unit, elapsed`` every :attr:`EVERY` seconds, and at the end
    when a line came before (a run shorter than that writes none: its own output says
    enough). tqdm's ``update``/``close`` interface, for the calls that show a bar elsewhere.

    >>> import io, contextlib
    >>> err = io.StringIO()
    >>> with contextlib.redirect_stderr(err):
    ...     p = ProgressLines(3, "cumulative", "observer", every=0.0)
    ...     p.update(1); p.update(2); p.close()
    >>> err.getvalue().splitlines()[-1].startswith("cumulative: 3/3 observers, ")
    True
    """

    #: Seconds between two lines.
    EVERY = 10.0

    def __init__(self, total: int, desc: str, unit: str, initial: int = 0, every: float | None = None):
        import time

        self.total, self.desc, self.unit, self.count = total, desc, unit, initial
        self.every = self.EVERY if every is None else every
        self.start = self.last = time.perf_counter()
        self.printed = False
        self.closed = False

    def update(self, n: int = 1) -> None:
        import time

        self.count += n
        now = time.perf_counter()
        if now - self.last >= self.every or (self.count >= self.total and self.printed):
            self.last = now
            self._line(now)

    def _line(self, now: float) -> None:
        units = self.unit if self.total == 1 else self.unit + "s"
        print(f"{self.desc}: {self.count}/{self.total} {units}, {now - self.start:.0f} s", file=sys.stderr, flush=True)
        self.printed = True

    def close(self) -> None:
        import time

        if not self.closed and self.printed and self.count < self.total:  # an interrupted run: where it stopped
            self._line(time.perf_counter())
        self.closed = True
