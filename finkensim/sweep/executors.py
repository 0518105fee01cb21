"""Executors of a sweep's runs: serially in this process, on a local process pool, or on a Dask cluster.

Each executor takes a list of tasks (see :func:`execute`) and yields one result dict per task, in
order of completion. A run that raises is a result with status "error"; a worker that dies gives a
"lost" result (``_no_part``: no part is written, so ``resume`` retries the run).
"""
from __future__ import annotations

import contextlib
import threading
import math
import time
from typing import Any, Iterator, Mapping

from ..episode import run_episode
from ..usertext import suggest
from .parsing import SweepError

EXECUTORS = ("serial", "process", "dask")
"""Names of the sweep executors: one process, a local process pool, a Dask cluster."""


def check_executor(executor: str, scheduler: str | None) -> str:
    """``executor`` if it is one of :data:`EXECUTORS` and ``scheduler`` (an address) is only given with "dask"."""
    if executor not in EXECUTORS:
        raise SweepError(f"executor = {executor!r}: expected one of {', '.join(map(repr, EXECUTORS))}"
                         f"{suggest(executor, EXECUTORS)}")
    if scheduler and executor != "dask":
        raise SweepError(f"scheduler = {scheduler!r} needs executor 'dask', got {executor!r}")
    return executor


_THREADS_LIMITED = False


def _limit_threads() -> None:
    """One numba thread per worker process: each run is a single environment, parallelism is across runs."""
    global _THREADS_LIMITED
    if not _THREADS_LIMITED:
        try:
            import numba

            numba.set_num_threads(1)
        except Exception:  # noqa: BLE001 (pragma: no cover; limiting threads is best effort)
            pass
        _THREADS_LIMITED = True


PARENT_POLL_S = 0.5  # how often a worker checks that the sweep process is still there
"""Seconds between a worker's checks that the sweep process still runs."""


def die_with_parent(parent_pid: int) -> None:
    """Make this worker process end when the process ``parent_pid`` (the sweep) ends, by any signal.

    On Linux the kernel sends SIGKILL to this process when its parent dies (``prctl(PR_SET_PDEATHSIG)``,
    effective at once, even inside a compiled kernel); everywhere, a daemon thread checks every
    :data:`PARENT_POLL_S` s that the parent is still ``parent_pid`` and otherwise ends the process.
    With the workers gone, the multiprocessing resource tracker (kept alive by their pipe ends) ends too.
    """
    import os
    import sys
    import threading

    if sys.platform.startswith("linux"):
        try:
            import ctypes
            import signal

            libc = ctypes.CDLL(None, use_errno=True)
            PR_SET_PDEATHSIG = 1
            libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no libc prctl: the thread below suffices
            pass
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)

    def watch():
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(1)

    threading.Thread(target=watch, name="finkensim-parent-watch", daemon=True).start()


def quiet_worker(parent_pid: int) -> None:
    """Make this worker process ignore Ctrl-C and end with the sweep process ``parent_pid``: Ctrl-C in a terminal
    reaches every process of the group, and the sweep (which stops its workers itself) is the one to answer it —
    otherwise each worker prints its own KeyboardInterrupt traceback."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent_pid)


def _worker_init(parent_pid: int | None = None) -> None:
    """Initializer of a pool worker process: one numba thread, no Ctrl-C, and end with the sweep process."""
    _limit_threads()
    if parent_pid is not None:
        quiet_worker(parent_pid)


def execute(task: Mapping[str, Any]) -> dict[str, Any]:
    """Run one task in a worker: build its config, call the runner, catch its exception. Top-level (picklable).

    A task is a dict: run_id, config (``Config.to_dict()``), seed, metrics (names), runner (None:
    :func:`~finkensim.episode.run_episode`), single_thread (limit numba to one thread). The result is a
    dict: run_id, one float per metric (NaN on error), status ("ok" / "error"), error (text), elapsed (s).
    """
    from ..config import config_from_dict

    if task.get("single_thread"):
        _limit_threads()
    names = task["metrics"]
    out: dict[str, Any] = {"run_id": task["run_id"]}
    t0 = time.perf_counter()
    try:
        cfg = config_from_dict(task["config"])
        runner = task.get("runner")
        if runner is None:
            values = run_episode(cfg, task["seed"], 0, names)
        else:
            values = runner(cfg, task["seed"], 0)
        missing = [m for m in names if m not in values]
        if missing:
            raise KeyError(f"the runner returned no value for metric(s) {', '.join(missing)}")
        out.update({m: float(values[m]) for m in names})
        out["status"], out["error"] = "ok", ""
    except Exception as exc:  # noqa: BLE001 (a failing run is a result, not a crash of the sweep)
        out.update({m: math.nan for m in names})
        out["status"], out["error"] = "error", f"{type(exc).__name__}: {exc}"
    out["elapsed"] = time.perf_counter() - t0
    return out


#: set while a sweep's block (:func:`terminate_as_interrupt`) has received Ctrl-C or SIGTERM: the KeyboardInterrupt the
#: handler raises can land inside a weakref or ``__del__`` callback, where Python prints and drops it, so the sweep's
#: loop also asks :func:`interrupt_requested`
_REQUESTED = threading.Event()


def interrupt_requested() -> bool:
    """Whether Ctrl-C or SIGTERM arrived within the current :func:`terminate_as_interrupt` block."""
    return _REQUESTED.is_set()


@contextlib.contextmanager
def terminate_as_interrupt():
    """Within the block, SIGTERM raises KeyboardInterrupt in the main thread (as Ctrl-C does), so a sweep
    ends the same way for both: running runs stopped, finished parts kept, ``resume`` continues. Yields a
    list that holds the signal number once SIGTERM arrived. Either signal also sets :func:`interrupt_requested`.
    Outside the main thread it changes nothing."""
    import signal

    caught: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield caught
        return

    def on_term(signum, frame):
        caught.append(signum)
        _REQUESTED.set()
        raise KeyboardInterrupt

    def on_int(signum, frame):
        _REQUESTED.set()
        raise KeyboardInterrupt

    _REQUESTED.clear()
    old = signal.signal(signal.SIGTERM, on_term)
    old_int = signal.signal(signal.SIGINT, on_int)
    try:
        yield caught
    finally:
        signal.signal(signal.SIGTERM, old)
        signal.signal(signal.SIGINT, old_int)
        _REQUESTED.clear()


def _lost(task, exc: BaseException) -> dict[str, Any]:
    """Row of a run whose worker failed (no result came back); it gets no part, so resume retries it."""
    row = {"run_id": task["run_id"], **{m: math.nan for m in task["metrics"]}, "status": "error",
           "error": f"{type(exc).__name__}: {exc} (the worker failed; the run is retried by resume)",
           "elapsed": math.nan, "_no_part": True}
    return row


def run_serial(tasks: list[dict]) -> Iterator[dict]:
    """The results of ``tasks`` (see :func:`execute`), run one after another in this process."""
    for task in tasks:
        yield execute(task)


def stop_pool(pool) -> None:
    """Shut the ProcessPoolExecutor ``pool`` down now: queued tasks cancelled, running workers terminated."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        proc.terminate()
    for proc in procs:
        proc.join(5.0)
    # The pool's manager thread closes its wake-up pipe when it sees the workers gone; at interpreter exit
    # concurrent.futures wakes every manager thread still known, and one closing at that moment wrote "Bad file
    # descriptor" to stderr (a race in CPython 3.11). Waiting for the thread here ends the race.
    if manager is not None:
        manager.join(5.0)


def run_process(tasks: list[dict], workers: int) -> Iterator[dict]:
    """The results of ``tasks`` in order of completion, from a pool of ``workers`` spawned processes
    (at most 4 tasks per worker in flight); closing the iterator shuts the pool down."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    import os

    # spawn: numba's OpenMP threads make fork unsafe; the workers import finkensim afresh
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_worker_init, initargs=(os.getpid(),))
    pending: dict = {}
    todo = iter(tasks)
    try:
        def fill():
            while len(pending) < 4 * workers:
                task = next(todo, None)
                if task is None:
                    return
                pending[pool.submit(execute, task)] = task

        fill()
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                task = pending.pop(fut)
                exc = fut.exception()
                yield _lost(task, exc) if exc is not None else fut.result()
            fill()
    finally:
        if pending:  # interrupted (Ctrl-C, SIGTERM, an error): stop the running runs now, not when they end
            stop_pool(pool)
        else:
            pool.shutdown(wait=True)


def dask_client(workers: int, scheduler: str | None):
    """(client, cluster): a Dask client of the scheduler at ``scheduler`` (cluster None), or of a new
    LocalCluster of ``workers`` single-threaded processes. SweepError when dask.distributed is missing
    or the scheduler cannot be reached."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise SweepError("executor 'dask' needs dask.distributed: pip install 'finkensim[dask]'") from None
    import logging

    if scheduler:
        try:
            return Client(scheduler, timeout="10s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise SweepError(f"cannot connect to the Dask scheduler at {scheduler!r}: {exc}") from None
    import os

    # a random port for the scheduler's HTTP server: with None it still takes 8787 when free, and a second sweep (or
    # any other Dask cluster) then printed "Port 8787 is already in use" as a warning line
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR)
    client = Client(cluster)
    client.run(quiet_worker, os.getpid())  # local workers are children of this process: end with it, no Ctrl-C
    return client, cluster


def run_dask(tasks: list[dict], workers: int, client) -> Iterator[dict]:
    """The results of ``tasks`` in order of completion, run on the Dask ``client`` (at most 4 tasks per
    worker in flight); a failed future gives a lost-run row; closing the iterator cancels the rest."""
    from distributed import as_completed

    n_inflight = 4 * max(1, len(client.scheduler_info().get("workers", {})) or workers)
    pending: dict = {}
    todo = iter(tasks)
    ac = as_completed()
    try:
        def fill():
            while len(pending) < n_inflight:
                task = next(todo, None)
                if task is None:
                    return
                fut = client.submit(execute, task, pure=False)
                pending[fut] = task
                ac.add(fut)

        fill()
        for fut in ac:
            task = pending.pop(fut)
            if fut.status == "finished":
                yield fut.result()
            else:
                try:
                    exc = fut.exception()
                except Exception as e:  # noqa: BLE001 (pragma: no cover; a cancelled future raises anything)
                    exc = e
                yield _lost(task, exc)
            fill()
    finally:
        for fut in pending:
            fut.cancel()
