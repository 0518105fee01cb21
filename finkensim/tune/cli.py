"""``finkensim tune STUDY.toml --out DIR``: the command-line front of :func:`finkensim.tune.run_study`.

``finkensim.cli`` registers it with :func:`add_parser`; :func:`run` returns the exit code (2 for bad
input, printed as one line; 130 when interrupted — the finished trials are in the storage, and the same
command resumes).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

__all__ = ["add_parser", "run"]

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


def add_parser(sub) -> None:
    """Register ``tune`` on the ``finkensim`` subparsers ``sub``."""
    p = sub.add_parser(
        "tune",
        help="Optuna study over scenario parameters: batched Monte-Carlo trials, held-out check of the best",
        description="Run (or resume) the Optuna study of a study file (see finkensim.tune.studyfile) and write "
                    "DIR/study.db (SQLite; a killed study resumes with the same command), DIR/trials.csv, "
                    "DIR/best.json, DIR/heldout.csv (defaults vs tuned on held-out environments, 95% CIs) and "
                    "DIR/figures/*.png. Several processes may run the same command at once to share the study. "
                    "Ctrl-C, SIGTERM or a killed process: the stopped trial is re-queued, and the same command "
                    "resumes to the trials an uninterrupted study has; a changed study file is refused in an old DIR.",
    )
    p.add_argument("study", help="study TOML file ([base], [params], [objectives], [evaluation], n_trials, ...)")
    p.add_argument("--out", default="out/tune", metavar="DIR", help="output directory (default: %(default)s)")
    p.add_argument("--trials", type=int, default=None, metavar="N",
                   help="finished trials to reach (default: n_trials of the study file)")
    p.add_argument("--storage", default=None, metavar="URL",
                   help="RDB URL (e.g. postgresql://user@host/db) or SQLite file instead of the study file's storage")
    p.add_argument("--no-heldout", action="store_true", help="skip the held-out comparison")
    p.add_argument("--no-figures", action="store_true", help="write no figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _error(prog: str, message: str) -> int:
    print(f"{prog}: error: {' '.join(str(message).split())}", file=sys.stderr)
    return EXIT_USAGE


def run(args) -> int:
    """Run ``finkensim tune`` with parsed ``args``; returns the exit code."""
    prog = getattr(args, "prog", "finkensim tune")
    try:
        import optuna  # noqa: F401
    except ImportError:
        return _error(prog, "finkensim tune needs optuna: pip install 'finkensim[tune]'")
    from ..config import ConfigError
    from .run import run_study
    from .studyfile import parse_study

    path = Path(args.study)
    if not path.is_file():
        return _error(prog, f"study file {args.study!r} " + ("is not a file" if path.exists() else "does not exist"))
    if args.trials is not None and args.trials < 1:
        return _error(prog, f"--trials {args.trials}: expected a positive number of trials")
    out = Path(args.out)
    if not str(args.out).strip():
        return _error(prog, "--out '': expected a directory name")
    if out.exists() and not out.is_dir():
        return _error(prog, f"--out {args.out!r} is a file: expected a directory")
    try:
        spec = parse_study(path)
    except ConfigError as exc:
        return _error(prog, str(exc))
    n = args.trials or spec.n_trials
    print(f"{prog}: {n} trials over {', '.join(p.key for p in spec.params)}; objectives "
          f"{', '.join(f'{m} ({d})' for m, d in spec.objectives)}; {spec.n_envs} environments x {spec.duration:g} s "
          f"per trial -> {out}")
    t0 = time.perf_counter()
    from ..sweep import terminate_as_interrupt

    try:
        with terminate_as_interrupt() as caught:  # SIGTERM ends the study like Ctrl-C
            res = run_study(spec, out, n_trials=args.trials, storage=args.storage, progress=not args.no_progress,
                            heldout=not args.no_heldout, figures=not args.no_figures)
    except ConfigError as exc:
        return _error(prog, str(exc))
    except KeyboardInterrupt:
        what = "terminated (SIGTERM)" if caught else "interrupted"
        print(f"{prog}: {what}; finished trials are kept in the storage, the stopped trial is re-queued: run the "
              "same command to resume", file=sys.stderr)
        return 128 + caught[0] if caught else EXIT_INTERRUPTED
    print(f"{prog}: done in {time.perf_counter() - t0:.1f} s; selected trial {res.best_trial}: "
          + ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in res.best.items()))
    if res.comparison is not None:
        for r in res.comparison.itertuples():
            print(f"  [{r.variant}] {r.metric}: default {r.default:.4g} [{r.default_lo:.4g}, {r.default_hi:.4g}] -> "
                  f"tuned {r.tuned:.4g} [{r.tuned_lo:.4g}, {r.tuned_hi:.4g}]; difference {r.diff:+.4g} "
                  f"[{r.diff_lo:+.4g}, {r.diff_hi:+.4g}] ({r.verdict})")
    for name in ("study.db", "trials.csv", "best.json", "heldout.csv"):
        if (out / name).exists():
            print(f"  {out / name}")
    for f in res.figures:
        print(f"  {f}")
    return 0
