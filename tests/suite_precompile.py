"""The kernels several xdist workers of the suite need, compiled once before the workers start (tests/conftest.py).

numba's on-disk cache has no lock between processes: two workers that call a kernel before either has stored it
both compile it (``FINKENSIM_COMPILE_LOG``, docs/performance.md). :func:`precompile` compiles the kernels that most
test files call, with :func:`finkensim.precompile.compile_kernels` (the machinery of ``finkensim compile``: the
set-up once, then independent jobs on as many processes as there are workers) into the cache the workers then load.

Each job makes the calls the tests make, on the same argument types (numba compiles one machine code per
signature): the closed loop of every built-in behaviour (one process: the loops share their callees), the
reference path (the batched Python-path kernels of the world, the sensors and the behaviours), a flight log with
its figures, and a small diagnosis (one candidate effect: the same replay, prediction and scoring kernels as the
whole catalogue at a fraction of the fitting).
"""
from __future__ import annotations

import os
import time

#: set to 1 to precompile; off by default: in a cold run of the whole suite the workers compiled few kernels twice
#: (docs/performance.md, "Test-suite time"), less than the precompile's own processes cost
ENV_VAR = "FINKENSIM_PRECOMPILE"

#: a diagnosis that compiles the diagnosis's kernels cheaply (as tests/test_numba_cache.py's small [gap])
SMALL_GAP = {"gap.effects": ["sonar_bias"], "gap.draws": 12, "gap.max_samples_per_flight": 300,
             "gap.fit_max_readings": 5000, "gap.n_boot": 200}


def _closed_loops(cfg) -> None:
    """One step of each built-in behaviour's compiled engine, one after another (their callees compile once)."""
    from finkensim.configfields import BEHAVIOUR_KINDS
    from finkensim.precompile import _closed_loop

    for kind in BEHAVIOUR_KINDS.builtin:
        _closed_loop(cfg.replace({"behaviour.kind": kind}))


def _reference_path(cfg) -> None:
    """One step of the Python path of the default behaviour: the batched kernels of the world, sensors and
    behaviours."""
    from finkensim.precompile import _flight_swarm

    _, swarm, state0, names = _flight_swarm(cfg)
    swarm.rollout(state0, 1, record=names, python=True)


def _small_diagnosis(cfg) -> None:
    from finkensim.gap.warmup import compile_diagnosis

    compile_diagnosis(cfg.replace(SMALL_GAP))


def _flight_log_and_figures(cfg) -> None:
    from finkensim.precompile import JOBS

    JOBS["flight log and figures"](cfg)


#: name → calls (longest first: the pool starts them in this order)
SUITE_JOBS = {
    "closed loops": _closed_loops,
    "small diagnosis": _small_diagnosis,
    "reference path": _reference_path,
    "flight log and figures": _flight_log_and_figures,
}


def wanted(config) -> int:
    """How many processes to precompile on (0: none): the xdist controller of a run of the whole ``tests`` folder
    on two or more workers, with numba's JIT on and ``FINKENSIM_PRECOMPILE=1``."""
    from pathlib import Path

    if hasattr(config, "workerinput") or os.environ.get(ENV_VAR, "0") != "1":
        return 0
    if os.environ.get("NUMBA_DISABLE_JIT") == "1":
        return 0
    workers = getattr(config.option, "numprocesses", None)
    if not isinstance(workers, int) or workers < 2:
        return 0
    tests = Path(__file__).resolve().parent
    if not any(Path(str(arg).split("::")[0]).resolve() == tests for arg in config.args):
        return 0
    return workers


def precompile(workers: int) -> str:
    """Compile :data:`SUITE_JOBS` for the default scenario on ``workers`` processes; one line saying what it did."""
    from finkensim import load_scenario
    from finkensim.precompile import compile_kernels

    t0, cpu0 = time.perf_counter(), os.times()
    kernels, seconds = 0, 0.0
    for result in compile_kernels(load_scenario(), workers=workers, jobs=SUITE_JOBS):
        kernels += len(result.compiled)
        seconds += sum(k.seconds for k in result.compiled)
    cpu = os.times()
    children = (cpu.children_user + cpu.children_system) - (cpu0.children_user + cpu0.children_system)
    return (f"precompiled before the workers started ({ENV_VAR}=1): {len(SUITE_JOBS)} jobs on "
            f"{workers} processes, {kernels} kernels compiled ({seconds:.1f} s of compiling), "
            f"{children:.1f} s CPU in the processes, {time.perf_counter() - t0:.1f} s wall clock")
