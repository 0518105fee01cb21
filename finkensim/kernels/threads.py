"""Run a compiled range kernel over [0, n) on several threads: ``run_ranges(kernel, n, *args)``.

The closed-loop rollout (:func:`finkensim.swarm.swarm_rollout`) loops over independent environments. It used
numba's ``prange``; its parallel lowering builds, optimizes and links a gufunc around the loop body, and with the
whole engine linked into that body it cost about a third of the engine's cold compile (≈ 13 s of ≈ 40 s,
``benchmarks.compile_probe finken``). Here the body is an ordinary ``nogil`` kernel
``kernel((i0, i1), *args)`` that handles items i0 … i1 − 1, and Python threads call it on contiguous ranges: one
compilation serves the serial and the parallel call, and the results are the same whatever the split (the items are
independent).

A hand-off to a Python thread costs more than numba's own launch, so it pays for long calls only (one step of two
4-copter environments on a 2-core VM: 36 µs on the calling thread, 45 µs with ``prange``, 187 µs split over two
threads here — the second thread wakes, takes the GIL and unboxes the arguments again): the rollout splits only
long calls, and one step of the vector env keeps its ``prange``.

The number of threads is numba's (:func:`numba.get_num_threads`, so :func:`numba.set_num_threads` and
``NUMBA_NUM_THREADS`` apply); one range runs on the calling thread. The pool is made again after a ``fork`` (a
child process inherits the parent's pool object but not its threads).
"""
from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numba

__all__ = ["run_ranges", "split_ranges"]

_lock = threading.Lock()
_pool: ThreadPoolExecutor | None = None
_pool_key = (0, 0)  # (pid, workers) the pool was made for


def split_ranges(n: int, parts: int) -> list[tuple[int, int]]:
    """[0, n) in ``parts`` contiguous ranges (i0, i1) of sizes differing by at most one (no empty range when
    parts ≤ n)."""
    return [(p * n // parts, (p + 1) * n // parts) for p in range(parts)]


def _executor(workers: int) -> ThreadPoolExecutor:
    global _pool, _pool_key
    with _lock:
        pid = os.getpid()
        if _pool is None or _pool_key[0] != pid or _pool_key[1] < workers:
            if _pool is not None and _pool_key[0] == pid:
                _pool.shutdown(wait=False)
            _pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="finkensim")
            _pool_key = (pid, workers)
        return _pool


def run_ranges(kernel, n: int, *args, parallel: bool = True) -> None:
    """``kernel((i0, i1), *args)`` for contiguous ranges covering [0, n): on ``min(numba.get_num_threads(), n)``
    threads when ``parallel`` (the caller's thread takes the first range), else once on the calling thread.

    ``kernel`` must release the GIL (``nogil=True``) for the threads to run at once, and the items must be
    independent. The first exception raised by any range is raised here, after every range has finished.
    """
    threads = min(numba.get_num_threads(), n) if parallel else 1
    if threads <= 1:
        kernel((0, n), *args)
        return
    ranges = split_ranges(n, threads)
    pool = _executor(threads - 1)
    futures = [pool.submit(kernel, span, *args) for span in ranges[1:]]
    error = None
    try:
        kernel(ranges[0], *args)
    except BaseException as exc:  # noqa: BLE001 — wait for the other ranges before raising
        error = exc
    for f in futures:
        exc = f.exception()
        if error is None and exc is not None:
            error = exc
    if error is not None:
        raise error
