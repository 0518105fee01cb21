"""The diagnosis's bounded caches (:mod:`finkensim.gap.model.cache`): count and byte limits, least recently used first."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.gap.model.cache import LRU, nbytes_of


def test_nbytes_counts_each_array_once():
    a, b = np.zeros(10), np.zeros(3, dtype=np.int8)
    assert nbytes_of((a, [b, a], 3, "x")) == 83
    assert nbytes_of(None) == 0


@settings(max_examples=100, deadline=None)
@given(ops=st.lists(st.tuples(st.integers(0, 6), st.integers(0, 40), st.booleans()), max_size=40),
       size=st.integers(1, 5), max_bytes=st.one_of(st.none(), st.integers(0, 400)))
def test_lru_keeps_the_most_recent_entries_within_both_limits(ops, size, max_bytes):
    """Against a plain reference: a list of keys in use order, trimmed from the front."""
    lru, order, sizes = LRU(size, max_bytes), [], {}
    for key, n, is_put in ops:
        if is_put:
            lru.put(key, (np.zeros(n),))
            if key not in order:
                order.append(key)
            sizes[key] = 8 * n
            while len(order) > size or (max_bytes is not None and len(order) > 1
                                        and sum(sizes[k] for k in order) > max_bytes):
                order.pop(0)
        else:
            hit = lru.get(key)
            assert (hit is not None) == (key in order)
            if hit is not None:
                order.remove(key)
                order.append(key)
        assert list(lru.d) == order
        assert lru.total == sum(sizes[k] for k in order)
