"""``python -m benchmarks.diagnosis_caches CASE:SEED …``: how often a diagnosis computes the same array twice.

Runs validation trials (2 flights × 30 s, random conventions, one numba thread, as ``benchmarks.diagnosis``) and
counts, per kind of cache entry of the diagnosis (:class:`~finkensim.gap.model.cache.LRU`: a table's ideal arrays
"sonar", "imu", "ranging", gathered draws "gather", scores keyed by the sensor's name …), how many entries were put
and how many of those were put before into the same cache (computed again after an eviction: work a larger or a
different cache could save, with the same numbers). Score entries are told apart by their rows' count (training,
held-out, all rows). Prints one line per kind.
"""
from __future__ import annotations

import argparse
import collections
import sys
import time
import warnings


def count_repeats(trials, log=print) -> dict:
    """{kind: [puts, repeated puts]} summed over ``trials`` ((case, seed) pairs); the LRU is restored after."""
    import numba

    from finkensim.gap.model import cache
    from finkensim.gap.validation.cases import run_case

    counts: dict = collections.defaultdict(lambda: [0, 0])
    seen: set = set()
    put = cache.LRU.put

    def counted(self, key, value, nbytes=None):
        kind = key[0] if isinstance(key, tuple) and key and isinstance(key[0], str) else type(key).__name__
        if kind in ("ultrasonic", "ranging", "imu") and isinstance(key[2], int) and not isinstance(key[2], bool):
            kind = f"{kind} ({key[2]} rows)" if len(key) == 4 else kind
        c = counts[kind]
        c[0] += 1
        c[1] += (id(self), key) in seen
        seen.add((id(self), key))
        return put(self, key, value, nbytes)

    numba.set_num_threads(1)
    cache.LRU.put = counted
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for case, seed in trials:
                t0 = time.process_time()
                row = run_case(case, seed, 2, 30.0, conventions="random")
                log(f"{case} seed {seed}: {time.process_time() - t0:.1f} s CPU, "
                    f"{'right' if row['correct'] else 'wrong'}")
    finally:
        cache.LRU.put = put
    return dict(counts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trials", nargs="+", help="CASE:SEED, e.g. sound_speed+crosstalk_geometric:51")
    a = ap.parse_args(argv)
    trials = [(t.rsplit(":", 1)[0], int(t.rsplit(":", 1)[1])) for t in a.trials]
    for kind, (n, again) in sorted(count_repeats(trials).items()):
        print(f"{kind:32s} put {n:6d}  put again {again:5d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
