"""``finkensim compile [scenario.toml] [--workers N] [--gap]``: the scenario's kernels into the shared cache before the first
run (:mod:`finkensim.precompile`), one line per compiled kernel."""
from __future__ import annotations

import os
import time

from .cliargs import UsageError
from .cliargs import load_scenario_arg as _load_scenario_arg

EXIT_OK = 0


def add_parser(sub) -> None:
    p = sub.add_parser("compile", help="compile a scenario's kernels now (first run only), in parallel processes",
                       description="Compile the numba kernels a flight of the scenario needs into finkensim's "
                                   "shared kernel cache (NUMBA_CACHE_DIR, else the user cache directory), independent "
                                   "ones in parallel processes, so that the first run does not wait for the compiler. "
                                   "A second call only loads them. See finkensim.precompile.")
    p.add_argument("scenario", nargs="?", default=None, help="scenario TOML file (default: the built-in scenario)")
    p.add_argument("--workers", type=int, default=2, metavar="N",
                   help="processes compiling side by side (default: %(default)s; 0 = in this process)")
    p.add_argument("--gap", action="store_true",
                   help="also the kernels of the sim-to-real diagnosis (finkensim gap), in a third job")
    p.set_defaults(func=cmd_compile)


def cmd_compile(args) -> int:
    prog = args.prog
    if args.workers < 0:
        raise UsageError(prog, f"--workers {args.workers}: expected 0 (this process) or a positive number")
    os.environ.setdefault("OMP_WAIT_POLICY", "passive")  # the workers inherit it: no spinning between kernels
    from .precompile import JOBS, compile_kernels

    cfg = _load_scenario_arg(prog, args.scenario)
    jobs = dict(JOBS)
    if args.gap:
        from .gap.warmup import compile_diagnosis

        jobs["gap diagnosis"] = compile_diagnosis
    t0 = time.perf_counter()
    print(f"{prog}: {len(jobs)} jobs ({', '.join(jobs)}) on {min(args.workers, len(jobs)) or 'this'} process"
          f"{'es' if args.workers > 1 else ''} into {os.environ.get('NUMBA_CACHE_DIR')}", flush=True)
    n_compiled = 0
    # the diagnosis's warm-up flies the configuration's closed loop too: it waits for that job and loads it
    for result in compile_kernels(cfg, workers=args.workers, jobs=jobs, after={"gap diagnosis": "closed loop"}):
        for kernel in result.compiled:
            print(f"  {kernel.name:<28} compiled in {kernel.seconds:5.1f} s  ({result.job})", flush=True)
        if not result.compiled:
            print(f"  {result.job}: loaded from the cache in {result.seconds:.1f} s", flush=True)
        n_compiled += len(result.compiled)
    print(f"{prog}: {n_compiled} kernels compiled in {time.perf_counter() - t0:.1f} s "
          f"({'later runs load them from the cache' if n_compiled else 'all were in the cache already'})")
    return EXIT_OK
