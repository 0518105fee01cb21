"""``python -m benchmarks.compile_probe compare|finken``: time to import and to make the first call.

Run by ``benchmarks.run`` in a subprocess with NUMBA_CACHE_DIR set: with an empty cache directory
the first call compiles every kernel it needs (and writes the cache) — the cold JIT cost; with the
same directory again it only loads them — the warm cost. Prints one JSON line:
{"import_s": …, "first_call_s": …, "compile_s": …, "profile": [...]} (first call = building a 4-copter,
1-environment workload and running one step; compile_s and profile from :mod:`finkensim.compiletime`: the
seconds numba spent compiling, and the kernels that took ≥ 0.2 s, nested to depth 2).
"""
from __future__ import annotations

import json
import sys
import time
import warnings


def main(argv=None) -> int:
    which = (argv or sys.argv[1:] or ["compare"])[0]
    t0 = time.perf_counter()
    from benchmarks import workloads

    if which == "finken":
        if workloads.swarm_status() is None:
            import finkensim.swarm
        else:
            import finkensim.sensors.imu
            import finkensim.sensors.ranging
            import finkensim.sensors.sonar
            import finkensim.world  # noqa: F401
    from finkensim.compiletime import compile_timer

    t1 = time.perf_counter()
    with warnings.catch_warnings(), compile_timer() as jit:
        warnings.simplefilter("ignore", RuntimeWarning)
        if which == "compare":
            wl, label = workloads.CompareWorkload(4, 1), "compare"
        elif which == "finken":
            wl, label = workloads.finken_workload(4, 1)
        else:
            raise SystemExit(f"unknown workload {which!r}: expected compare or finken")
        wl.run(1)
    t2 = time.perf_counter()
    print(json.dumps(dict(workload=which, impl=label, import_s=t1 - t0, first_call_s=t2 - t1, compile_s=jit.seconds,
                          profile=jit.profile())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
