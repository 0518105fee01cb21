"""``run_sweep``: run every run of a sweep on an executor, store each result as it ends, resume, and
write the results table, the summary and its plot."""
from __future__ import annotations

import contextlib
import logging
import os
import sys
import warnings
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

from .parsing import SweepError
from .design import Sweep
from .executors import check_executor, dask_client, interrupt_requested, run_dask, run_process, run_serial
from .store import prepare_out, read_parts, write_outputs, write_part
from .tables import arrow_schema, result_row


def run_sweep(sweep: Sweep | str | Path | Mapping[str, Any], out: str | Path | None = None, *,
              executor: str = "process", workers: int | None = None, scheduler: str | None = None,
              resume: bool = False, overwrite: bool = False, progress: bool = True,
              runner: Callable[..., Mapping[str, float]] | None = None):
    """Run every run of ``sweep`` and return the results as a pandas DataFrame sorted by run id.

    Parameters
    ----------
    sweep : Sweep, str, Path or Mapping
        A :class:`Sweep`, a sweep TOML path or text, or the parsed tables.
    out : str, Path or None
        Output directory (see :mod:`finkensim.sweep`); None keeps the results in memory only.
    executor : str
        ``"process"`` (local process pool, the default), ``"serial"`` (in this process, for debugging) or
        ``"dask"`` (a Dask cluster: ``scheduler`` address, or a LocalCluster).
    workers : int, optional
        Worker processes (default: all cores) for ``"process"`` and the Dask LocalCluster.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); its workers need finkensim.
    resume : bool
        Run only the runs whose part is missing in ``out`` (same sweep only).
    overwrite : bool
        Start again in an ``out`` that holds results (otherwise that is an error).
    progress : bool
        Show a tqdm progress bar.
    runner : callable, optional
        ``f(cfg, seed, env_id) -> {metric: value}`` called instead of :func:`~finkensim.episode.run_episode`;
        must be a picklable top-level function.

    Returns
    -------
    pandas.DataFrame
        One row per run: ``run_id, combination, <parameters>, replicate, seed, <metrics>, status, error,
        elapsed`` (metrics in the units of :data:`~finkensim.metrics.METRICS`, elapsed in s). ``df.attrs``:
        "ran" (run ids executed by this call), "failed" (run ids with status "error"), "out" (the directory
        or None).

    Raises
    ------
    SweepError
        Before any run starts, for a bad sweep, executor, worker count, scheduler or ``out``.
    """
    if not isinstance(sweep, Sweep):
        sweep = Sweep.from_dict(sweep) if isinstance(sweep, Mapping) else Sweep.from_toml(sweep)
    executor = check_executor(executor, scheduler)
    n_cpu = os.cpu_count() or 1
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise SweepError(f"workers = {workers!r}: expected a positive integer")
    workers = workers or n_cpu
    if runner is not None and not callable(runner):
        raise SweepError(f"runner = {runner!r}: expected a function f(cfg, seed, env_id) -> dict of metrics")
    if resume and out is None:
        raise SweepError("resume needs an output directory (out)")

    import pyarrow as pa

    with warnings.catch_warnings():  # tqdm.auto warns in Jupyter without ipywidgets, then falls back to text
        warnings.simplefilter("ignore")
        from tqdm.auto import tqdm

    schema = arrow_schema(sweep)
    runs = sweep.runs()
    out_dir = Path(out) if out is not None else None
    dask: list = []  # [client, cluster or None] once connected
    if executor == "dask":
        drop_interrupt_noise()
    if executor == "dask" and scheduler:
        dask[:] = dask_client(workers, scheduler)  # an unreachable scheduler fails before out is touched
    results: Iterator[dict] = iter(())
    try:
        done: dict[int, dict] = {}
        if out_dir is not None:
            prepare_out(out_dir, sweep, resume, overwrite)
            if resume:
                done = read_parts(out_dir / "parts", sweep, schema)
        todo = [r for r in runs if r.run_id not in done]
        cfg_dicts = [c.to_dict() for c in sweep.configs]
        if sweep.calibration_samples:  # calibration = "sample": each run under its own draw
            cfg_dicts = {r.run_id: sweep.run_config(r).to_dict() for r in todo}
        tasks = [{"run_id": r.run_id, "config": cfg_dicts[r.run_id if sweep.calibration_samples else r.combination],
                  "seed": r.seed,
                  "metrics": list(sweep.metrics), "runner": runner, "single_thread": executor != "serial"}
                 for r in todo]
        if executor == "serial":
            results = run_serial(tasks)
        elif executor == "process":
            results = run_process(tasks, min(workers, max(1, len(tasks)))) if tasks else iter(())
        elif tasks:
            if not dask:
                dask[:] = dask_client(workers, None)
            results = run_dask(tasks, workers, dask[0])

        by_id = {r.run_id: r for r in runs}
        rows = dict(done)
        ran: list[int] = []
        n_failed = sum(1 for r in done.values() if r["status"] != "ok")
        with tqdm(total=sweep.n_runs, initial=len(done), desc="sweep", unit="run", disable=not progress,
                  dynamic_ncols=True, file=sys.stderr) as bar:
            for result in results:
                run = by_id[result["run_id"]]
                row = result_row(run, result, sweep)
                if out_dir is not None and not result.get("_no_part"):
                    write_part(out_dir / "parts", row, schema)
                rows[run.run_id] = row
                ran.append(run.run_id)
                n_failed += row["status"] != "ok"
                bar.update(1)
                if n_failed:
                    bar.set_postfix(failed=n_failed, refresh=False)
                if interrupt_requested():  # a Ctrl-C / SIGTERM whose KeyboardInterrupt a callback swallowed
                    raise KeyboardInterrupt
    finally:
        with quiet_dask_teardown(bool(dask)):
            close = getattr(results, "close", None)
            if close is not None:
                close()  # shuts a process pool down, cancels pending Dask futures
            if dask:
                dask[0].close()
                if dask[1] is not None:
                    dask[1].close()

    table = pa.Table.from_pylist([rows[k] for k in sorted(rows)], schema=schema)
    df = table.to_pandas()
    if out_dir is not None:
        write_outputs(out_dir, sweep, table, df)
    df.attrs["ran"] = sorted(ran)
    df.attrs["failed"] = [int(i) for i in df.loc[df["status"] != "ok", "run_id"]]
    df.attrs["out"] = str(out_dir) if out_dir is not None else None
    return df


class _SyncCancelNoise(logging.Filter):
    """Drops tornado's record of distributed's ``sync`` cancel callback failing with a NameError (a Ctrl-C or SIGTERM
    that lands before ``sync`` bound its future makes its callback read an unbound name); any other record passes."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[0] if record.exc_info else None
        return not (exc is NameError and "sync.<locals>.cancel" in record.getMessage())


class _InterruptNoise(logging.Filter):
    """Drops a local Dask cluster's records below CRITICAL once Ctrl-C or SIGTERM arrived
    (:func:`~.executors.interrupt_requested`): a signal sent to the sweep's process group ends the workers too, and
    the scheduler, on its event-loop thread, logs keys it can no longer gather before the main thread has reached
    the quiet teardown below."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno >= logging.CRITICAL or not interrupt_requested()


#: the loggers of a local cluster's parts that run in the sweep's own process
_CLUSTER_LOGGERS = ("distributed.scheduler", "distributed.client", "distributed.core", "distributed.nanny")


def drop_interrupt_noise() -> None:
    """Install :class:`_SyncCancelNoise` on ``tornado.application`` and :class:`_InterruptNoise` on the local
    cluster's loggers, once, for the rest of the process: the callbacks run on Dask's event-loop thread whenever
    the loop gets to them, during the interrupted sweep or after its teardown, so a filter bound to a block cannot
    catch them every time."""
    for name, kind in (("tornado.application", _SyncCancelNoise),
                       *((name, _InterruptNoise) for name in _CLUSTER_LOGGERS)):
        logger = logging.getLogger(name)
        if not any(isinstance(f, kind) for f in logger.filters):
            logger.addFilter(kind())


@contextlib.contextmanager
def quiet_dask_teardown(dask: bool = True):
    """Within the block (a Dask client's and cluster's teardown), distributed's and tornado's loggers pass only
    CRITICAL records: tearing a local cluster down while futures are cancelled (Ctrl-C, SIGTERM) logs scheduler errors
    about keys it can no longer gather, and distributed's ``sync`` helper can fail in its cancel callback — noise at
    that point, when every finished run is kept. ``dask`` False: nothing is silenced."""
    with contextlib.ExitStack() as quiet:
        for name in ("distributed", "tornado.application") if dask else ():
            quiet.enter_context(_quiet_logger(name))
        yield


@contextlib.contextmanager
def _quiet_logger(name: str):
    """Within the block, the logger ``name`` passes only CRITICAL records (its level is restored after)."""
    logger = logging.getLogger(name)
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)
