"""Bounded caches of the diagnosis's arrays (ideal draws, gathered draws, scores): least recently used entries go
first, by count and by bytes. A cache changes no result: an evicted entry is computed again, to the same numbers
(common random numbers), so its limits trade CPU time for memory only."""
from __future__ import annotations

import numpy as np

#: bytes of arrays each of a table's caches keeps (beside its count limit): the caches are most of a diagnosis's
#: memory on a long log with many copters, and an evicted entry is only computed again, to the same numbers
CACHE_BYTES = 32 * 2**20


def nbytes_of(value) -> int:
    """Bytes of the arrays in value (an array, or tuples / lists of them, nested; each array once)."""
    seen, todo, total = set(), [value], 0
    while todo:
        v = todo.pop()
        if isinstance(v, np.ndarray):
            if id(v) not in seen:
                seen.add(id(v))
                total += v.nbytes
        elif isinstance(v, (tuple, list)):
            todo.extend(v)
    return total


class LRU:
    """A small bounded cache (insertion-ordered dict, least recently used evicted first): at most ``size``
    entries and, when ``max_bytes`` is given, at most that many bytes of arrays (the newest entry is kept even
    when it alone is larger)."""

    def __init__(self, size=16, max_bytes: int | None = None):
        self.size = size
        self.max_bytes = max_bytes
        self.d = {}
        self.nbytes = {}
        self.total = 0

    def get(self, key):
        v = self.d.pop(key, None)
        if v is not None:
            self.d[key] = v
        return v

    def put(self, key, value, nbytes: int | None = None):
        """Keep value under key (``nbytes``: the bytes it holds, by default those of its arrays); returns value."""
        self.d[key] = value
        size = nbytes_of(value) if nbytes is None else nbytes
        self.total += size - self.nbytes.get(key, 0)
        self.nbytes[key] = size
        while len(self.d) > self.size or (self.max_bytes is not None and self.total > self.max_bytes
                                          and len(self.d) > 1):
            old = next(iter(self.d))
            self.d.pop(old)
            self.total -= self.nbytes.pop(old)
        return value
