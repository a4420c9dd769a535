"""Kernel primitives the simplifiers share: the orientation predicate and an indexed heap.

Greedy cuts (:mod:`simplifiers._gc_kernels`) and greedy insertion
(:mod:`simplifiers._gi_kernels`) both import them; numba compiles each once per argument
type (float64 plane coordinates for greedy cuts, int64 grid indices for greedy insertion).
Like the kernels around them, they loop and never validate, allocate nothing and are
compiled without the Numba runtime (``_nrt=False``, see :mod:`simplifiers._gc_kernels`).

The heap
--------
A binary min-heap of items (non-negative integers), held in a :data:`Heap` record:
``item[i]`` is the item at slot ``i`` and ``key[i]`` its key (slot 0 holds the least),
and the heap's size is ``n[at]`` (a cell of a counter array the caller owns, so that it
persists between kernel calls). With ``ties`` True, equal keys order by item (the smaller
first), so that the order is total and the pops do not depend on the heap's history;
with ``ties`` False equal keys keep whatever order the sifting leaves. With ``indexed``
True, ``pos[t]`` is the slot of item ``t`` or -1, which :func:`heap_set` (decrease or
increase a key) and :func:`heap_remove` need; a heap that is only built and popped
passes ``indexed`` False and any ``pos`` (it is never read or written). A max-heap is
this heap over negated keys (exact in floating point).
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

_HOT = {"cache": True, "nogil": True, "_nrt": False}
#: 0 as an int64 (not a literal): numba compiles a callee again for every literal argument.
_ZERO = np.int64(0)

#: A binary min-heap (see the module docstring): ``item``, ``key`` (per slot), ``pos``
#: (per item), the size ``n[at]``, ``ties`` (break equal keys by item) and ``indexed``
#: (keep ``pos``).
Heap = namedtuple("Heap", ["item", "key", "pos", "n", "at", "ties", "indexed"])


@nb.njit(**_HOT)
def orient(ax, ay, bx, by, cx, cy):
    """Twice the signed area of (a, b, c): > 0 counter-clockwise, 0 collinear.

    Exact on integers (int64 grid indices, or float64 holding integers below 2**26).
    """
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@nb.njit(**_HOT)
def _before(ties, ka, ta, kb, tb):
    """True when (key ka, item ta) comes strictly before (kb, tb) in the heap's order."""
    return ka < kb or (ties and ka == kb and ta < tb)


@nb.njit(**_HOT)
def heap_up(h, i):
    """Move the entry at slot ``i`` up to its place (after its key decreased)."""
    item, key, pos, ties, indexed = h.item, h.key, h.pos, h.ties, h.indexed
    t = item[i]
    v = key[i]
    while i > 0:
        p = (i - 1) >> 1
        if not _before(ties, v, t, key[p], item[p]):
            break
        item[i] = item[p]
        key[i] = key[p]
        if indexed:
            pos[item[i]] = i
        i = p
    item[i] = t
    key[i] = v
    if indexed:
        pos[t] = i


@nb.njit(**_HOT)
def heap_down(h, i, n):
    """Move the entry at slot ``i`` down to its place among the first ``n`` slots."""
    item, key, pos, ties, indexed = h.item, h.key, h.pos, h.ties, h.indexed
    t = item[i]
    v = key[i]
    while True:
        c = 2 * i + 1
        if c >= n:
            break
        if c + 1 < n and _before(ties, key[c + 1], item[c + 1], key[c], item[c]):
            c += 1
        if not _before(ties, key[c], item[c], v, t):
            break
        item[i] = item[c]
        key[i] = key[c]
        if indexed:
            pos[item[i]] = i
        i = c
    item[i] = t
    key[i] = v
    if indexed:
        pos[t] = i


@nb.njit(**_HOT)
def heap_build(h, m):
    """Make a heap of the ``m`` entries written in slots ``0 .. m-1`` (``item`` and ``key``)."""
    h.n[h.at] = m
    if h.indexed:
        for i in range(m):
            h.pos[h.item[i]] = i
    for i in range(m // 2 - 1, -1, -1):
        heap_down(h, i, m)


@nb.njit(**_HOT)
def heap_pop(h):
    """Take the first entry out of the (non-empty) heap and return its item."""
    item, key = h.item, h.key
    t = item[0]
    n = h.n[h.at] - 1
    h.n[h.at] = n
    if h.indexed:
        h.pos[t] = -1
    if n > 0:
        item[0] = item[n]
        key[0] = key[n]
        heap_down(h, _ZERO, n)
    return t


@nb.njit(**_HOT)
def heap_remove(h, t):
    """Take item ``t`` (which must be in the heap) out of an indexed heap."""
    item, key, pos = h.item, h.key, h.pos
    i = np.int64(pos[t])  # int64 whatever pos holds: one compilation of heap_up and heap_down
    pos[t] = -1
    n = h.n[h.at] - 1
    h.n[h.at] = n
    if i == n:
        return
    item[i] = item[n]
    key[i] = key[n]
    pos[item[i]] = i
    if i > 0 and _before(h.ties, key[i], item[i], key[(i - 1) >> 1], item[(i - 1) >> 1]):
        heap_up(h, i)
    else:
        heap_down(h, i, n)


@nb.njit(**_HOT)
def heap_set(h, t, v):
    """Give item ``t`` the key ``v`` in an indexed heap: insert it, or move it up (the key
    decreased) or down (it increased)."""
    item, key, pos = h.item, h.key, h.pos
    i = np.int64(pos[t])
    if i < 0:
        i = h.n[h.at]
        h.n[h.at] = i + 1
        item[i] = t
        key[i] = v
        pos[t] = i
        heap_up(h, i)
        return
    old = key[i]
    key[i] = v
    if v < old:
        heap_up(h, i)
    elif v > old:
        heap_down(h, i, h.n[h.at])
