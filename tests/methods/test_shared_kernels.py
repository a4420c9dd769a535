"""The kernel primitives both greedy simplifiers use (simplifiers._shared_kernels)."""

from __future__ import annotations

import numba as nb
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from simplifiers import _shared_kernels as sk
from terrainvis.core.compiling import from_python

# kernel-only kernels (no Python entry of their own: terrainvis.core.compiling.KERNEL_ONLY), called
# here through one made for them
orient = from_python(sk.orient)


def test_orient_signs_and_exact_integers():
    assert orient(0, 0, 1, 0, 0, 1) == 1  # counter-clockwise
    assert orient(0.0, 0.0, 0.0, 1.0, 1.0, 0.0) == -1.0  # clockwise
    assert orient(0, 0, 2, 2, 5, 5) == 0  # collinear
    big = 30_000  # the largest grid side greedy insertion takes
    assert orient(0, 0, big, 1, big - 1, 1) == 1
    assert orient(np.int64(0), np.int64(0), np.int64(big), np.int64(1), np.int64(big - 1), np.int64(1)) == 1


# ---------------------------------------------------------------------------- the heap
# Numba drivers of the shared heap (uncached: they live in this test file only). Keys come
# from a few values so that ties are common: the order of ties is what the two greedy
# simplifiers depend on for their bits.
_KEYS = st.sampled_from([0.0, 0.5, 1.0, 2.0, 7.25])


@nb.njit(cache=False)
def _sorted_by_heap(key, item, indexed):
    """Greedy cuts' use: heapify then pop all (smallest key first, ties by item). Returns the
    items popped and, indexed, how often ``pos`` disagreed with the slots."""
    n = np.int64(key.shape[0])
    out = np.empty(n, np.int64)
    wrong = 0
    if indexed:
        pos = np.full(item.shape[0] * 3, -1, np.int64)
        for i in range(n):
            pos[item[i]] = i
        sk.heapify(key, item, pos, n, sk.smaller_then_item)
        for k in range(out.shape[0]):
            for s in range(n):
                wrong += pos[item[s]] != s
            out[k] = item[0]
            n = sk.heap_pop(key, item, pos, n, sk.smaller_then_item)
            wrong += pos[out[k]] != -1
    else:
        sk.heapify(key, item, None, n, sk.smaller_then_item)
        for k in range(out.shape[0]):
            out[k] = item[0]
            n = sk.heap_pop(key, item, None, n, sk.smaller_then_item)
    return out, wrong


@given(st.lists(_KEYS, min_size=0, max_size=40), st.randoms(use_true_random=False), st.booleans())
@settings(max_examples=300, deadline=None)
def test_heap_pops_smallest_key_first_ties_by_item(keys, rnd, indexed):
    ids = list(range(0, 3 * len(keys), 3))
    rnd.shuffle(ids)
    key = np.array(keys, dtype=np.float64)
    item = np.array(ids, dtype=np.int64)
    expected = [t for _, t in sorted(zip(keys, ids))]
    popped, wrong = _sorted_by_heap(key, item, indexed)
    assert popped.tolist() == expected
    assert wrong == 0


@nb.njit(cache=False)
def _indexed_ops(ops, ts, vs, key, item, pos):
    """Greedy insertion's use: set (0), remove (1) or pop (2) on an indexed max-heap; the
    first item and the size after each operation."""
    size = np.zeros(2, np.int64)  # the size in size[1], as greedy insertion keeps it in counts[NH]
    at = np.int64(1)
    trace = np.empty((ops.shape[0], 2), np.int64)
    for k in range(ops.shape[0]):
        t = np.int64(ts[k])
        if ops[k] == 0:
            sk.heap_set(key, item, pos, size, at, t, vs[k], sk.larger)
        elif ops[k] == 1 and pos[t] >= 0:
            sk.heap_remove(key, item, pos, size, at, t, sk.larger)
        elif ops[k] == 2 and size[at] > 0:
            sk.heap_remove(key, item, pos, size, at, np.int64(item[0]), sk.larger)  # run()'s pop
        trace[k, 0] = item[0] if size[at] > 0 else -1
        trace[k, 1] = size[at]
    return trace


class _FormerGreedyInsertionHeap:
    """The indexed max-heap greedy insertion had before issue 41 (simplifiers/_gi_kernels.py,
    ``_heap_up``, ``_heap_down``, ``_heap_remove``, ``_heap_set``), transcribed: the tie
    order the shared heap must keep."""

    def __init__(self, n_items):
        self.heap, self.hval, self.pos, self.n = [0] * n_items, [0.0] * n_items, [-1] * n_items, 0

    def up(self, i):
        heap, hval, pos = self.heap, self.hval, self.pos
        t, v = heap[i], hval[i]
        while i > 0:
            p = (i - 1) >> 1
            if hval[p] >= v:
                break
            heap[i], hval[i] = heap[p], hval[p]
            pos[heap[i]] = i
            i = p
        heap[i], hval[i], pos[t] = t, v, i

    def down(self, i, n):
        heap, hval, pos = self.heap, self.hval, self.pos
        t, v = heap[i], hval[i]
        while True:
            c = 2 * i + 1
            if c >= n:
                break
            if c + 1 < n and hval[c + 1] > hval[c]:
                c += 1
            if hval[c] <= v:
                break
            heap[i], hval[i] = heap[c], hval[c]
            pos[heap[i]] = i
            i = c
        heap[i], hval[i], pos[t] = t, v, i

    def remove(self, t):
        heap, hval, pos = self.heap, self.hval, self.pos
        i = pos[t]
        pos[t] = -1
        self.n -= 1
        n = self.n
        if i == n:
            return
        heap[i], hval[i] = heap[n], hval[n]
        pos[heap[i]] = i
        if i > 0 and hval[i] > hval[(i - 1) >> 1]:
            self.up(i)
        else:
            self.down(i, n)

    def set(self, t, v):
        i = self.pos[t]
        if i < 0:
            i = self.n
            self.n += 1
            self.heap[i], self.hval[i], self.pos[t] = t, v, i
            self.up(i)
            return
        old = self.hval[i]
        self.hval[i] = v
        if v > old:
            self.up(i)
        elif v < old:
            self.down(i, self.n)


_N_ITEMS = 12


@given(st.lists(st.tuples(st.sampled_from([0, 0, 0, 1, 2]), st.integers(0, _N_ITEMS - 1), _KEYS), max_size=120))
@settings(max_examples=300, deadline=None)
def test_indexed_max_heap_keeps_greedy_insertions_former_tie_order(steps):
    ops = np.array([s[0] for s in steps], dtype=np.int64)
    ts = np.array([s[1] for s in steps], dtype=np.int64)
    vs = np.array([s[2] for s in steps], dtype=np.float64)
    # greedy insertion's dtypes: int32 triangles and slots, float64 errors
    key, item, pos = np.zeros(_N_ITEMS), np.zeros(_N_ITEMS, np.int32), np.full(_N_ITEMS, -1, np.int32)
    trace = _indexed_ops(ops, ts, vs, key, item, pos)
    ref = _FormerGreedyInsertionHeap(_N_ITEMS)
    for k, (op, t, v) in enumerate(steps):
        if op == 0:
            ref.set(t, v)
        elif op == 1 and ref.pos[t] >= 0:
            ref.remove(t)
        elif op == 2 and ref.n > 0:
            ref.remove(ref.heap[0])
        assert trace[k].tolist() == [ref.heap[0] if ref.n > 0 else -1, ref.n]
        if ref.n:  # the max-heap property holds
            assert ref.hval[0] == max(ref.hval[: ref.n])
    n = ref.n
    assert item[:n].tolist() == ref.heap[:n]
    assert key[:n].tolist() == ref.hval[:n]
    assert pos.tolist() == ref.pos
