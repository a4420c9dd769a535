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
