"""Monte-Carlo parameter sweeps: a design of configs × replicate seeds, run on a local process pool,
serially, or on a Dask cluster, with results written run by run so a crash loses only unfinished runs.

    from finkensim.sweep import Sweep, run_sweep
    sweep = Sweep.from_toml("sweep.toml")          # validates everything; builds every config
    df = run_sweep(sweep, out="out/sweep")         # pandas.DataFrame, one row per run
    df = run_sweep(sweep, out="out/sweep", resume=True)   # finish an interrupted sweep

The sweep file format: :mod:`finkensim.sweep.sweepfile`. Modules: ``sweepfile`` (TOML → design
arguments), ``design`` (:class:`Sweep`), ``parsing`` (:class:`SweepError`, the ``Parser`` and key checks shared by the sweep and study files), ``keys`` (run ids,
seeds, fingerprint), ``tables`` (results schema and rows), ``executors`` (serial / process pool / Dask),
``store`` (Parquet parts, resume), ``summary`` (statistics, plot), ``run`` (:func:`run_sweep`).

Runs are numbered ``run_id = combination * replicates + replicate``. Replicate r of combination k
flies with a seed derived from (sweep seed, k, r) alone (``numpy.random.SeedSequence``), so results
do not depend on the executor, the number of workers or the order of completion.

Output directory ``out``:

- ``parts/run-XXXXX.parquet`` — one row per finished run, written atomically (temp file + rename)
  as soon as the run ends; ``resume=True`` runs only the runs whose part is missing.
- ``results.parquet`` — all rows sorted by run id: ``run_id, combination, <parameters>, replicate,
  seed, <metrics>, status ("ok" / "error"), error (exception text), elapsed (s)``.
- ``summary.csv`` — per combination: n_runs, n_ok, n_error and ``<metric>_mean``, ``_ci_low``,
  ``_ci_high`` (95 % Student-t interval of the mean over the successful replicates).
- ``summary.png`` — one panel per metric, mean ± CI per combination.
- ``sweep.json`` — the design and its fingerprint (``resume`` refuses a directory of another sweep).

A run that raises is recorded with status "error" and its exception; every other run proceeds. A
worker that dies (the run never finished) gives an error row without a part, so ``resume`` retries it.
Pool and local Dask workers end with the sweep process, however it ends (SIGKILL included:
:func:`~finkensim.sweep.executors.die_with_parent`); ``finkensim sweep`` treats SIGTERM like Ctrl-C.
"""
from __future__ import annotations

from .parsing import SweepError
from .design import Sweep
from .executors import EXECUTORS, terminate_as_interrupt
from .keys import Run, format_params
from .run import run_sweep
from .store import load_results
from .summary import plot_summary, summarize

__all__ = ["SweepError", "Sweep", "Run", "EXECUTORS", "run_sweep", "load_results", "summarize", "plot_summary",
           "format_params", "terminate_as_interrupt"]
