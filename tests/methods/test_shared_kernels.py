"""The indexed heap both greedy simplifiers use (simplifiers._shared_kernels), against a dict."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from simplifiers import _shared_kernels as sk

N_ITEMS = 12


def _heap(ties: bool, dtype=np.int64, indexed: bool = True) -> sk.Heap:
    pos = np.full(N_ITEMS if indexed else 0, -1, dtype=dtype)
    return sk.Heap(np.full(N_ITEMS, -1, dtype=dtype), np.zeros(N_ITEMS), pos, np.zeros(3, dtype=np.int64), 1, ties,
                   indexed)


def _check(h: sk.Heap, ref: dict[int, float]) -> None:
    """The heap holds exactly ``ref``, in heap order, with ``pos`` its inverse."""
    n = int(h.n[h.at])
    assert n == len(ref)
    assert {int(t): float(k) for t, k in zip(h.item[:n], h.key[:n])} == ref
    for i in range(n):
        assert not h.indexed or h.pos[h.item[i]] == i
        if i:
            p = (i - 1) // 2
            assert (h.key[p], h.item[p]) <= (h.key[i], h.item[i]) if h.ties else h.key[p] <= h.key[i]
    assert not h.indexed or all(h.pos[t] == -1 for t in range(N_ITEMS) if t not in ref)


KEYS = [-2.0, -1.0, 0.0, 0.5, 1.0, 3.0]
#: (item, key): set the item's key; (item, None): remove it; (-1, None): pop the first.
ops = st.lists(st.tuples(st.integers(-1, N_ITEMS - 1), st.none() | st.sampled_from(KEYS)), max_size=60)


@settings(max_examples=60, deadline=None)
@given(ops=ops, ties=st.booleans(), int32=st.booleans())
def test_set_and_remove_keep_the_heap(ops, ties, int32):
    """Inserting, re-keying (up and down), removing and popping keep the order and the index."""
    h = _heap(ties, np.int32 if int32 else np.int64)
    ref: dict[int, float] = {}
    for t, key in ops:
        if t < 0:
            if ref:
                first = min(ref, key=lambda u: (ref[u], u))
                got = int(sk.heap_pop(h))
                assert got == first if ties else ref[got] == ref[first]
                del ref[got]
        elif key is None:
            if t in ref:
                sk.heap_remove(h, np.int64(t))
                del ref[t]
        else:
            sk.heap_set(h, np.int64(t), key)
            ref[t] = key
        _check(h, ref)


@settings(max_examples=60, deadline=None)
@given(keys=st.lists(st.sampled_from([0.0, 1.0, 2.5, -1.0]), min_size=0, max_size=N_ITEMS), indexed=st.booleans(),
       seed=st.integers(0, 100))
def test_build_then_pop_gives_key_then_item_order(keys, indexed, seed):
    """With ties broken by item, popping gives the entries sorted by (key, item), indexed or not."""
    h = _heap(True, indexed=indexed)
    m = len(keys)
    items = np.random.default_rng(seed).permutation(N_ITEMS)[:m]
    h.item[:m] = items
    h.key[:m] = keys
    sk.heap_build(h, np.int64(m))
    _check(h, {int(t): k for t, k in zip(items, keys)})
    popped = []
    while h.n[h.at] > 0:
        popped.append(int(sk.heap_pop(h)))
    assert popped == sorted(items.tolist(), key=lambda t: (keys[list(items).index(t)], t))


def test_orient_signs_and_exact_integers():
    assert sk.orient(0, 0, 1, 0, 0, 1) == 1  # counter-clockwise
    assert sk.orient(0.0, 0.0, 0.0, 1.0, 1.0, 0.0) == -1.0  # clockwise
    assert sk.orient(0, 0, 2, 2, 5, 5) == 0  # collinear
    big = 30_000
    assert sk.orient(0, 0, big, 1, big - 1, 1) == big - (big - 1)
