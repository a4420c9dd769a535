"""The progress bar class of terrainvis's long calls (compare, cumulative viewsheds)."""

from __future__ import annotations

import sys


def progress_bar_class():
    """tqdm's notebook bar in a Jupyter kernel that has ipywidgets, else the plain one.

    ``tqdm.auto`` would pick the notebook bar in any Jupyter kernel and, without
    ipywidgets, warn "IProgress not found" and fall back; this asks first.
    """
    from tqdm.std import tqdm as plain

    try:
        shell = sys.modules["IPython"].get_ipython() if "IPython" in sys.modules else None
        kernel = "ipykernel.zmqshell" in sys.modules or (shell is not None and "IPKernelApp" in shell.config)
        if not kernel:
            return plain
        import ipywidgets  # noqa: F401

        from tqdm import notebook

        return notebook.tqdm if getattr(notebook, "IProgress", None) is not None else plain
    except Exception:  # no ipywidgets, or an IPython without .config
        return plain
