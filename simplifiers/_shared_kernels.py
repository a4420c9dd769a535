"""Kernel primitives the simplifiers share: the orientation predicate and the binary heap.

Greedy cuts (:mod:`simplifiers._gc_kernels`) and greedy insertion
(:mod:`simplifiers._gi_kernels`) both import them; numba compiles each once per argument
type (float64 plane coordinates for greedy cuts, int64 grid indices for greedy insertion;
each method's heap arrays). Like the kernels around them, they loop and never validate,
allocate nothing and are compiled without the Numba runtime (``_nrt=False``, see
:mod:`simplifiers._gc_kernels`).

The heap
--------
A binary heap in two arrays per slot, ``key[i]`` and ``item[i]`` (slot 0 holds the
first entry), the first ``n`` slots in use (where ``n`` lives: below). Which entry comes
first is the ``before(ka, ta, kb, tb)`` argument: True when (key ``ka``, item ``ta``)
must come strictly before (``kb``, ``tb``). An order is a function passed as an argument,
so numba compiles the heap once per order, with the comparison called directly (and
inlined by LLVM): no branch on the order at run time. The two orders in use:

* :func:`larger` (greedy insertion): the largest key first, equal keys in whatever order
  the sifting leaves (an entry moves past another only on a strictly larger key);
* :func:`smaller_then_item` (greedy cuts): the smallest key first, equal keys by the
  smaller item; a total order, so the pops give the entries sorted whatever the heap's
  history.

``pos`` makes the heap indexed: ``pos[t]`` is the slot of item ``t`` or -1, kept up to
date by every function here, which :func:`heap_set` and :func:`heap_remove` need. A heap
that is only built and popped passes ``pos=None``: numba prunes the index's updates from
that compilation.

Where the size lives: an indexed heap that persists between kernel calls (greedy
insertion's) keeps it in a cell ``size[at]`` of the caller's counter array, which
:func:`heap_set` and :func:`heap_remove` update; a heap built and emptied within one call
(greedy cuts' candidates) keeps it in a local variable, passed to :func:`heapify` and
:func:`heap_pop` and returned by the latter. (Greedy insertion with the size passed and
returned instead ran 10-14 % slower, measured in one process against the former kernels,
every pair of runs but a few.)

The orders are ``register_jitable`` functions (plain Python functions that numba compiles
into each kernel that calls them), not ``njit`` dispatchers: a dispatcher passed as a value
is a process address in the machine code (a "dynamic global"), and numba refuses to cache
a kernel that passes one to a helper it does not inline (greedy insertion's ``run`` and
``init_state`` were no longer cached). A ``register_jitable`` function is a value without
data; a signature holding one cannot be written into numba's cache index, so the heap
functions themselves are compiled uncached (``_HEAP``), inside each caller's compilation,
and live in the callers' cached machine code.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numba.extending import register_jitable

from terrainvis.core.compiling import KERNEL_ONLY

_HOT = {"cache": True, "nogil": True, "_nrt": False}
#: The heap functions: as ``_HOT`` but uncached (their signatures hold the order, see the
#: module docstring).
_HEAP = {"cache": False, "nogil": True, "_nrt": False}


@nb.njit(**_HOT, **KERNEL_ONLY)
def orient(ax, ay, bx, by, cx, cy):
    """Twice the signed area of (a, b, c): > 0 counter-clockwise, 0 collinear.

    Exact on integers (int64 grid indices, or float64 holding integers below 2**26).
    """
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


# ------------------------------------------------------------------ the heap's orders
@register_jitable
def larger(ka, ta, kb, tb):
    """The heap order "largest key first" (a max-heap); equal keys are not ordered."""
    return ka > kb


@register_jitable
def smaller_then_item(ka, ta, kb, tb):
    """The heap order "smallest key first, equal keys by the smaller item" (a total order)."""
    return ka < kb or (ka == kb and ta < tb)


# ------------------------------------------------------------------------ the heap
@nb.njit(**_HEAP, **KERNEL_ONLY)
def sift_up(key, item, pos, i, before):
    """Move the entry at slot ``i`` up to its place (it may now come before its parent)."""
    t = item[i]
    v = key[i]
    while i > 0:
        p = (i - 1) >> 1
        if not before(v, t, key[p], item[p]):
            break
        item[i] = item[p]
        key[i] = key[p]
        if pos is not None:
            pos[item[i]] = i
        i = p
    item[i] = t
    key[i] = v
    if pos is not None:
        pos[t] = i


@nb.njit(**_HEAP, **KERNEL_ONLY)
def sift_down(key, item, pos, i, n, before):
    """Move the entry at slot ``i`` down to its place among the first ``n`` slots."""
    t = item[i]
    v = key[i]
    while True:
        c = 2 * i + 1
        if c >= n:
            break
        if c + 1 < n and before(key[c + 1], item[c + 1], key[c], item[c]):
            c += 1
        if not before(key[c], item[c], v, t):
            break
        item[i] = item[c]
        key[i] = key[c]
        if pos is not None:
            pos[item[i]] = i
        i = c
    item[i] = t
    key[i] = v
    if pos is not None:
        pos[t] = i


@nb.njit(**_HEAP)
def heapify(key, item, pos, n, before):
    """Make a heap of the ``n`` entries written in slots ``0 .. n-1``."""
    for i in range(n // 2 - 1, -1, -1):
        sift_down(key, item, pos, i, n, before)


@nb.njit(**_HEAP, **KERNEL_ONLY)
def heap_pop(key, item, pos, n, before):
    """Take the first entry out of the heap of ``n >= 1`` entries; returns the new size.

    The entry was ``item[0]`` (read it before the call); the last entry takes its slot and
    sifts down.
    """
    if pos is not None:
        pos[item[0]] = -1
    n -= 1
    if n > 0:
        key[0] = key[n]
        item[0] = item[n]
        sift_down(key, item, pos, np.int64(0), n, before)  # int64, not a literal: one compilation
    return n


@nb.njit(**_HEAP, **KERNEL_ONLY)
def heap_remove(key, item, pos, size, at, t, before):
    """Take item ``t`` (in the heap) out of an indexed heap of ``size[at]`` entries."""
    i = np.int64(pos[t])  # int64 whatever pos holds: one compilation of the sifts
    pos[t] = -1
    n = size[at] - 1
    size[at] = n
    if i == n:
        return
    key[i] = key[n]
    item[i] = item[n]
    pos[item[i]] = i
    if i > 0 and before(key[i], item[i], key[(i - 1) >> 1], item[(i - 1) >> 1]):
        sift_up(key, item, pos, i, before)
    else:
        sift_down(key, item, pos, i, n, before)


@nb.njit(**_HEAP, **KERNEL_ONLY)
def heap_set(key, item, pos, size, at, t, v, before):
    """Give item ``t`` the key ``v`` in an indexed heap of ``size[at]`` entries: insert it, or
    move it up or down when it changed."""
    i = np.int64(pos[t])
    if i < 0:
        n = size[at]
        size[at] = n + 1
        key[n] = v
        item[n] = t
        sift_up(key, item, pos, n, before)
        return
    old = key[i]
    key[i] = v
    t = item[i]  # as the sifts read it: one compilation of the order per item type
    if before(v, t, old, t):
        sift_up(key, item, pos, i, before)
    elif before(old, t, v, t):
        sift_down(key, item, pos, i, size[at], before)
