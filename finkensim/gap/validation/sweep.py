"""``finkensim gap-validate`` as a sweep: trials × cases (single effects, pairs, controls), each trial a
generated-and-diagnosed flight set, resumable from a JSON-lines file, with a progress bar, run serially,
on a local process pool or on Dask.

Every finished trial is added to ``trials.jsonl`` at once (the file is rewritten atomically), so an interrupted validation keeps what it
did and a rerun with the same settings continues where it stopped.
"""
from __future__ import annotations

import json
import multiprocessing
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Callable, Iterator

from ...atomic import write_text_atomic
from .cases import run_case

__all__ = ["trial_key", "load_done", "run_trials", "merged_rows", "summarize", "record_provenance", "provenance"]


def trial_key(case: str, seed: int, flights: int, duration: float, conventions: str) -> tuple:
    """The identity of a trial in ``trials.jsonl``."""
    return (case, int(seed), int(flights), float(duration), conventions)


def load_done(path: Path) -> dict:
    """Finished trials of an earlier run: key → row (unreadable lines are skipped: a run killed mid-write)."""
    done = {}
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                r = json.loads(line)
                done[trial_key(r["case"], r["seed"], r["flights"], r["duration"], r.get("convention_mode", "default"))] = r
            except (ValueError, KeyError, TypeError):
                continue
    return done


def _worker_init(parent_pid: int) -> None:
    """A process-pool worker: ignores Ctrl-C, ends with the sweep, and computes on one thread. The pool already runs one trial per
    core; numba's and scikit-learn's own thread pools on top of it would oversubscribe the cores. Every ``prange``
    of the diagnosis is per element (no reductions), so results do not depend on the thread count."""
    import os

    import numba

    from ...sweep.executors import quiet_worker

    quiet_worker(parent_pid)  # Ctrl-C is the validation's to answer (it stops the pool); end with it however it ends
    numba.set_num_threads(1)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # libraries loaded later
        os.environ[var] = "1"
    try:  # libraries loaded already
        from threadpoolctl import threadpool_limits
    except ImportError:  # scikit-learn (which brings it) is optional; without it there is no OpenMP pool to limit
        return
    threadpool_limits(1)


def _one(job: tuple) -> dict:
    case, seed, flights, duration, conventions, *calibrate = job
    if calibrate and calibrate[0]:  # gap-validate --calibrate
        from .calibrated import run_calibrated_case

        row = run_calibrated_case(case, seed, n_flights=flights, duration=duration,
                                  conventions="random" if conventions == "random" else None)
    else:
        row = run_case(case, seed, n_flights=flights, duration=duration,
                       conventions="random" if conventions == "random" else None)
    row.update(flights=flights, duration=duration, convention_mode=conventions)
    return row


def _completed(jobs: list[tuple], executor: str, workers: int, scheduler: str | None) -> Iterator[dict]:
    if executor == "serial":
        for job in jobs:
            yield _one(job)
        return
    if executor == "process":
        import os

        from ...sweep.executors import stop_pool

        # the workers end with this process, however it ends (SIGKILL included), and use one thread each
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_worker_init, initargs=(os.getpid(),))
        finished = False
        try:
            futs = [pool.submit(_one, j) for j in jobs]
            for fut in as_completed(futs):
                yield fut.result()
            finished = True
        finally:
            if finished:
                pool.shutdown(wait=True)
            else:  # interrupted: stop the running trials now
                stop_pool(pool)
        return
    from ...sweep.executors import dask_client
    from ...sweep.run import drop_interrupt_noise, quiet_dask_teardown
    from distributed import as_completed as dask_completed

    drop_interrupt_noise()
    client, cluster = dask_client(workers, scheduler)
    try:
        for fut in dask_completed([client.submit(_one, j, pure=False) for j in jobs]):
            yield fut.result()
    finally:
        with quiet_dask_teardown():
            client.close()
            if cluster is not None:
                cluster.close()


#: one line per run of :func:`run_trials` into an ``out`` directory: when, and which finkensim sources made its trials
PROVENANCE = "provenance.jsonl"


def record_provenance(out: Path) -> tuple[str, list[str]]:
    """Add this finkensim's sources (:func:`finkensim.numba_cache.source_hash`: every ``.py`` file of the package) and
    version to ``out/provenance.jsonl``; return (these sources, the other sources already recorded there, in order) —
    the others made trials with another version of the code, whose diagnosis may differ unless the change between
    them was bit-identical."""
    import datetime

    from ... import __version__
    from ...numba_cache import source_hash

    path = Path(out) / PROVENANCE
    mine = source_hash()
    seen = provenance(out)
    line = json.dumps({"sources": mine, "finkensim": __version__,
                       "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")})
    write_text_atomic(path, "".join(json.dumps(r) + "\n" for r in seen) + line + "\n")
    return mine, list(dict.fromkeys(r["sources"] for r in seen if r.get("sources") != mine))


def provenance(out: Path) -> list[dict]:
    """The runs recorded in ``out/provenance.jsonl`` (none for a directory made before it existed; unreadable lines
    skipped)."""
    path = Path(out) / PROVENANCE
    rows = []
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                rows.append(json.loads(line))
            except ValueError:
                continue
    return [r for r in rows if isinstance(r, dict)]


def run_trials(cases: list[str], trials: int, seed: int, flights: int, duration: float, conventions: str,
               out: Path, executor: str = "serial", workers: int = 2, scheduler: str | None = None,
               progress: Callable | None = None, calibrate: bool = False,
               note: Callable[[str], None] | None = None) -> list[dict]:
    """Every (case, trial) row, running those not already in ``out/trials.jsonl``; trial-major order so an
    interrupted run has every case's first trials. progress: a tqdm-like factory ``progress(total=...)``;
    calibrate: each trial also calibrates and diagnoses new flights (:mod:`finkensim.gap.validation.calibrated`; keep
    its rows in their own ``out``). A run that adds trials is recorded in ``out/provenance.jsonl``
    (:func:`record_provenance`); when ``out`` already holds trials of other finkensim sources, ``note`` (default
    ``warnings.warn``) is told so before any trial runs."""
    import warnings

    from ...sweep.executors import interrupt_requested

    log_path = Path(out) / "trials.jsonl"
    done = load_done(log_path)
    keys = [trial_key(c, seed + t, flights, duration, conventions) for t in range(trials) for c in cases]
    todo = [k for k in keys if k not in done]
    mine, others = record_provenance(out) if todo else ("", [])
    if others and done:
        (note or (lambda m: warnings.warn(m, stacklevel=3)))(
            f"{log_path} holds trials of other finkensim sources ({', '.join(others)}; these are {mine}): the trials "
            f"added now come from another version of the code; the runs are listed in {Path(out) / PROVENANCE}")
    bar = progress(total=len(keys), initial=len(keys) - len(todo)) if progress else None
    try:
        for row in _completed([k + (True,) for k in todo] if calibrate else todo, executor, workers, scheduler):
            done[trial_key(row["case"], row["seed"], flights, duration, conventions)] = row
            # rewritten whole after every trial (atomically, like every output): never a torn line
            write_text_atomic(log_path, "".join(json.dumps(r, default=float) + "\n" for r in done.values()))
            if bar is not None:
                bar.update(1)
            if interrupt_requested():  # a Ctrl-C / SIGTERM whose KeyboardInterrupt a callback swallowed
                raise KeyboardInterrupt
    finally:
        if bar is not None:
            bar.close()
    return [done[k] for k in keys]


def merged_rows(outs) -> list[dict]:
    """The finished trials of several runs' ``OUT/trials.jsonl`` (e.g. one matrix run in parts, in any order), each
    trial once. ValueError when a trial is in two files with different results (the ``seconds`` it took aside):
    parts of one matrix must come from one diagnosis."""
    rows: dict = {}
    where: dict = {}
    for out in outs:
        for key, row in load_done(Path(out) / "trials.jsonl").items():
            if key in rows:
                a, b = ({k: v for k, v in r.items() if k != "seconds"} for r in (rows[key], row))
                if json.dumps(a, sort_keys=True, default=float) != json.dumps(b, sort_keys=True, default=float):
                    differ = sorted(k for k in a.keys() | b.keys() if json.dumps(a.get(k), default=float)
                                    != json.dumps(b.get(k), default=float))
                    raise ValueError(f"trial {row['case']} seed {row['seed']} differs between {where[key]} and {out} "
                                     f"in {', '.join(differ)}: expected runs of one diagnosis")
                continue
            rows[key], where[key] = row, out
    return list(rows.values())


def summarize(*outs: Path) -> str:
    """The matrix (Markdown) of whatever trials the runs ``outs`` hold (``OUT/trials.jsonl``, finished or not, merged
    by :func:`merged_rows`); with pair trials also their effect × effect grid and each effect's pairs
    (:func:`~finkensim.gap.validation.tables.pair_grid`, :func:`~finkensim.gap.validation.tables.effect_pairs`), with
    ``--calibrate`` rows also the calibration table (:func:`~finkensim.gap.validation.calibrated.calibrated_table`)."""
    from .tables import confusion, effect_pairs, pair_grid

    rows = merged_rows(outs)
    if not rows:
        raise FileNotFoundError(f"{' '.join(str(Path(o) / 'trials.jsonl') for o in outs)}: no finished trials")
    out = confusion(rows)[1]
    sources = list(dict.fromkeys(r.get("sources") for o in outs for r in provenance(o) if r.get("sources")))
    if len(sources) > 1:
        out += (f"\nThese trials were made by {len(sources)} versions of finkensim (sources {', '.join(sources)}; "
                f"{PROVENANCE}): the same diagnosis only if the changes between them were bit-identical.\n")
    grid = pair_grid(rows)
    if grid:
        out += ("\nPairs (rows and columns: the two withheld effects):\n\n" + grid
                + "\nEach effect with every other effect:\n\n" + effect_pairs(rows))
    if any("calibrated_significant" in r for r in rows):  # gap-validate --calibrate
        from .calibrated import calibrated_table

        out += "\nAfter calibration (new flights of the same truth, diagnosed with the calibrated config):\n\n"
        out += calibrated_table(rows)
    return out


if __name__ == "__main__":  # python -m finkensim.gap.validation.sweep OUT [OUT ...] [--figure PNG] [--against BASE ...]
    import argparse
    import sys

    ap = argparse.ArgumentParser(description="The matrix of gap-validate runs (finished or not) from OUT/trials.jsonl; "
                                             "several OUT directories (parts of one matrix) are merged")
    ap.add_argument("out", nargs="*", default=["out/gap-validate"], help="the runs' --out directories")
    ap.add_argument("--figure", metavar="PNG", help="also draw the pair trials as an effect × effect grid")
    ap.add_argument("--against", metavar="BASE", nargs="+",
                    help="also compare, trial by trial, with the runs BASE of the same matrix at another diagnosis")
    args = ap.parse_args()
    try:
        print(summarize(*args.out), end="")
        if args.against:
            from .tables import paired

            print(f"\nTrial by trial against {' '.join(args.against)}:\n")
            print(paired(merged_rows(args.out), merged_rows(args.against)), end="")
    except (FileNotFoundError, ValueError) as exc:
        sys.exit(f"{ap.prog}: {exc}")
    if args.figure:
        from .plot import pair_grid_figure

        print(pair_grid_figure(merged_rows(args.out), args.figure))
