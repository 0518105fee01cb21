"""``finkensim gap-validate``: the gap diagnosis checked on simulated flights with a withheld effect
(:mod:`finkensim.gap.validation.cases`, :mod:`finkensim.gap.validation.sweep`)."""
from __future__ import annotations

import math
import os
import sys

from .cliargs import UsageError
from .cliargs import output_dir as _output_dir
from .cliargs import use_agg as _use_agg

EXIT_OK = 0


def add_parser(sub) -> None:
    """Register ``gap-validate`` on the ``finkensim`` subparsers ``sub``."""
    p = sub.add_parser(
        "gap-validate", help="check the gap diagnosis on simulated flights with a withheld effect",
        description="Generate 'real' flights with one catalogued effect switched on at a random strength (plus tracking "
                    "noise), diagnose them with a model that lacks it, and print the confusion matrix; also the null "
                    "case (nothing withheld) and a foreign effect outside the catalogue (must be unexplained).")
    p.add_argument("--cases", nargs="+", default=None, metavar="CASE",
                   help="cases to run (default: every single case and the controls; 'pairs' stands for every pair)")
    p.add_argument("--trials", type=int, default=3, metavar="N", help="trials per case (default: %(default)s)")
    p.add_argument("--flights", type=int, default=2, metavar="K", help="flights per trial (default: %(default)s)")
    p.add_argument("--duration", type=float, default=60.0, metavar="S", help="seconds per flight (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, metavar="N", help="first trial seed (default: %(default)s)")
    p.add_argument("--out", default="out/gap-validate", metavar="DIR", help="output directory (default: %(default)s)")
    p.add_argument("--conventions", choices=("default", "random"), default="default",
                   help="how the 'real' flights are recorded: finkensim's defaults, or a random point of the "
                        "conventions axis per trial (altitude, sonar offset, no-echo value, noise shape, rate, "
                        "swarm size, tracking noise) (default: %(default)s)")
    p.add_argument("--pairs", action="store_true", help="also every pair of catalogued effects at once")
    p.add_argument("--executor", choices=("serial", "process", "dask"), default="serial",
                   help="where trials run (default: %(default)s)")
    p.add_argument("--workers", type=int, default=2, metavar="N", help="process/Dask workers (default: %(default)s)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="a running Dask scheduler (with --executor dask)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--calibrate", action="store_true",
                   help="also close the loop: write each trial's calibrated config, diagnose new flights of the same "
                        "truth with it, and tabulate 'no significant gap after calibration' (OUT/calibrated.md; "
                        "use its own --out)")
    p.set_defaults(func=cmd_gap_validate)


def cmd_gap_validate(args) -> int:
    """Run ``finkensim gap-validate``; returns the exit code."""
    prog = args.prog
    os.environ.setdefault("OMP_WAIT_POLICY", "passive")  # as in cmd_gap: serial trials run many short kernels
    from .atomic import write_atomic
    from .gap.validation.cases import CASES, expand_cases, get_case
    from .gap.validation.tables import confusion
    from .gap.validation.sweep import run_trials

    cases = expand_cases(args.cases, args.pairs)
    unknown = []
    for c in cases:
        try:
            get_case(c)
        except (KeyError, ValueError):
            unknown.append(c)
    if unknown:
        raise UsageError(prog, f"unknown cases {unknown}; expected some of {', '.join(CASES)} or pairs EFFECT+EFFECT")
    if args.trials < 1 or args.flights < 1 or args.workers < 1:
        raise UsageError(prog, f"--trials {args.trials}, --flights {args.flights}, --workers {args.workers}: "
                               "expected integers >= 1")
    if not (math.isfinite(args.duration) and args.duration > 0):
        raise UsageError(prog, f"--duration {args.duration}: expected a finite number of seconds > 0")
    if args.seed < 0:
        raise UsageError(prog, f"--seed {args.seed}: expected an integer >= 0")
    if args.scheduler and args.executor != "dask":
        raise UsageError(prog, f"--scheduler {args.scheduler!r} needs --executor dask")
    from .budget import check_memory, flight_arrays
    from .config import ConfigError, load_config

    try:  # every trial simulates --flights flights of --duration s of the default scenario
        check_memory(flight_arrays(load_config(None), duration=args.duration), f"a flight of --duration {args.duration:g} s",
                     "lower --duration")
    except ConfigError as exc:
        raise UsageError(prog, str(exc)) from None
    out = _output_dir(prog, args.out)
    _use_agg()
    from functools import partial

    from tqdm import tqdm

    bar = None if args.no_progress else partial(tqdm, desc="gap-validate", file=sys.stderr)
    from .sweep.executors import terminate_as_interrupt

    try:
        with terminate_as_interrupt() as caught:  # SIGTERM ends the validation like Ctrl-C
            rows = run_trials(cases, args.trials, args.seed, args.flights, args.duration, args.conventions, out,
                              executor=args.executor, workers=args.workers, scheduler=args.scheduler, progress=bar,
                              calibrate=args.calibrate, note=lambda m: print(f"{prog}: note: {m}", file=sys.stderr))
    except ConfigError as exc:
        raise UsageError(prog, str(exc)) from None
    except KeyboardInterrupt:
        what = "terminated (SIGTERM)" if caught else "interrupted"
        print(f"{prog}: {what}; finished trials are kept in {out / 'trials.jsonl'}, the same command continues",
              file=sys.stderr)
        return 128 + caught[0] if caught else 130
    table, md = confusion(rows)
    write_atomic(out / "results.csv", lambda p: table.to_csv(p, index=False))
    write_atomic(out / "matrix.md", lambda p: p.write_text(md))
    print(md)
    if args.calibrate:
        from .gap.validation.calibrated import calibrated_table

        cal_md = calibrated_table(rows)
        write_atomic(out / "calibrated.md", lambda p: p.write_text(cal_md))
        print(cal_md)
    print(f"{prog}: wrote {out / 'matrix.md'} and {out / 'results.csv'}")
    return EXIT_OK
