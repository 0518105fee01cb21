"""Compile a configuration's kernels ahead of its first run, in parallel processes, into the shared cache.

    finkensim compile [scenario.toml] [--workers N] [--gap]

numba compiles a kernel at its first call and keeps it in the on-disk cache (:mod:`finkensim.numba_cache`), so the
first ``finkensim run`` or :class:`~finkensim.swarm.SwarmSim` rollout of a fresh install waits for the compiler.
:func:`compile_kernels` does that wait up front: each :data:`JOBS` entry makes the calls a flight of the configuration
makes (on tiny inputs of the same types, so numba compiles the same signatures) in its own process, independent jobs
side by side; every later process loads the kernels from the cache. Compiling only what the configuration calls
follows from numba's lazy compilation.

The jobs:

* ``closed loop``: one step of :meth:`SwarmSim.rollout <finkensim.swarm.SwarmSim.rollout>` as
  :func:`~finkensim.scenario.simulate_flight` records it (the compiled engine ``swarm_env_<behaviour>`` and its callees, the
  initial placement);
* ``flight log and figures``: :func:`~finkensim.scenario.flight_log` with the error-free values and the wall figure of
  ``finkensim run`` on a two-sample record of zeros (the ideal ranging table and readings, the plate distances).

Every job builds the configuration's swarm and its initial state first (the placement kernel, the ranging table's
alias builder): :data:`SETUP` compiles those once, in one process, before the jobs start (while the other processes
import the package), so that no two jobs compile them side by side.

``finkensim compile --gap`` adds the diagnosis's kernels (:func:`finkensim.gap.warmup.compile_diagnosis`: a
diagnosis of two short simulated flights), so that the first ``finkensim gap`` does not compile either.
"""
from __future__ import annotations

import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from multiprocessing import get_context
from typing import Callable, Iterator

import numpy as np

from .config import Config

__all__ = ["JOBS", "SETUP", "CompiledKernel", "JobResult", "compile_kernels", "run_job"]


@dataclass(frozen=True)
class CompiledKernel:
    """One outermost numba compilation: the kernel's qualified name and its compile time (s, callees included)."""

    name: str
    seconds: float


@dataclass(frozen=True)
class JobResult:
    """What one job did: ``job`` (its name), ``seconds`` wall time (s) of its calls in the worker (compiling and
    loading from the cache), ``compiled`` (the kernels it compiled; empty when the cache had them all)."""

    job: str
    seconds: float
    compiled: tuple[CompiledKernel, ...]


def _flight_swarm(cfg: Config):
    from .scenario import flight_record_names
    from .swarm import SwarmSim

    cfg = cfg.replace({"simulation.n_envs": 1}) if cfg.simulation.n_envs != 1 else cfg
    swarm = SwarmSim(cfg)
    return cfg, swarm, swarm.init(n_envs=1, seed=cfg.simulation.seed), flight_record_names(swarm, ideal=True)


def _swarm_setup(cfg: Config) -> None:
    _flight_swarm(cfg)


def _imports(cfg: Config) -> None:
    """What the jobs import (while :data:`SETUP` compiles in another process)."""
    import matplotlib.pyplot  # noqa: F401 - imported for its import time

    from . import scenario, swarm, viz  # noqa: F401


def _closed_loop(cfg: Config) -> None:
    _, swarm, state0, names = _flight_swarm(cfg)
    swarm.rollout(state0, 1, record=names)


def _flight_log_and_figures(cfg: Config) -> None:
    import matplotlib.pyplot as plt

    from . import viz
    from .scenario import flight_log

    cfg, swarm, state0, names = _flight_swarm(cfg)
    _, empty = swarm.rollout(state0, 0, record=names, python=True)  # T = 0: no kernel runs, the record's types
    T = 2
    arrays = {name: np.zeros((T,) + getattr(empty, name).shape[1:], getattr(empty, name).dtype) for name in names}
    arrays["pose"][:] = state0.world.pose
    rec = empty._replace(t=np.arange(T) * swarm.dt, **arrays)
    _, traj = flight_log(cfg, swarm, state0, rec, ideal=True)
    fig, _ = viz.plot_wall_response(swarm.world, traj)
    plt.close(fig)


#: name → calls that compile what a flight of the configuration compiles (module doc); independent of each other
JOBS: dict[str, Callable[[Config], None]] = {
    "closed loop": _closed_loop,
    "flight log and figures": _flight_log_and_figures,
}


#: the calls every job makes first (the swarm of the configuration and its initial state), compiled once before them
SETUP: tuple[str, Callable[[Config], None]] = ("set-up shared by the jobs", _swarm_setup)


def run_job(cfg: Config, job: str, calls: Callable[[Config], None]) -> JobResult:
    """Run the job named ``job``, ``calls(cfg)``, in this process; what it compiled (warnings of the tiny inputs
    muted)."""
    import warnings

    from .compiletime import compile_timer

    t0 = time.perf_counter()
    with warnings.catch_warnings(), compile_timer() as jit:
        warnings.simplefilter("ignore")
        calls(cfg)
    compiled = tuple(CompiledKernel(r["name"], r["seconds"]) for r in jit.profile(max_depth=0, min_seconds=0.0))
    return JobResult(job, time.perf_counter() - t0, compiled)


def compile_kernels(cfg: Config, workers: int = 2, jobs: dict | None = None,
                    setup: tuple[str, Callable[[Config], None]] | None = SETUP,
                    after: dict[str, str] | None = None) -> Iterator[JobResult]:
    """Compile ``cfg``'s kernels into the shared cache: ``setup`` (name, top-level function of the config: the calls
    every job makes first; None: no set-up) in one process, then ``jobs`` (name → top-level function of the config;
    default :data:`JOBS`) on ``workers`` fresh processes (spawned: a forked numba runtime is not safe); yields the
    set-up's and each job's :class:`JobResult` as it finishes. ``after`` (job → job): a job that calls another's
    kernels too starts only once that one has finished and loads them from the cache (two processes side by side
    would both compile them: numba's cache has no lock). ``workers=0`` runs them one after another in this process,
    each after the one it waits for."""
    jobs = JOBS if jobs is None else jobs
    after = {job: first for job, first in (after or {}).items() if job in jobs and first in jobs and job != first}
    if workers == 0:
        order = [job for job in jobs if job not in after] + [job for job in jobs if job in after]
        for job, calls in ((setup,) if setup else ()) + tuple((job, jobs[job]) for job in order):
            yield run_job(cfg, job, calls)
        return
    n = min(workers, len(jobs))
    with ProcessPoolExecutor(max_workers=n, mp_context=get_context("spawn")) as pool:
        if setup is not None:
            first = pool.submit(run_job, cfg, *setup)
            # the other processes start now and import the package meanwhile (a pool spawns a process per submit)
            for future in [pool.submit(run_job, cfg, "imports", _imports) for _ in range(n - 1)]:
                future.result()
            yield first.result()
        running = {pool.submit(run_job, cfg, job, calls): job for job, calls in jobs.items() if job not in after}
        waiting = [job for job in jobs if job in after]
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                finished = running.pop(future)
                yield future.result()
                for job in [j for j in waiting if after[j] == finished]:
                    waiting.remove(job)
                    running[pool.submit(run_job, cfg, job, jobs[job])] = job
