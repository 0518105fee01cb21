"""The ``finkensim`` command line::

    finkensim run [scenario.toml] [--out DIR] [--duration S] [--seed N] [--no-gif] [--no-ideal] [--no-progress]
    finkensim sweep sweep.toml [--out DIR] [--executor serial|process|dask] [--workers N]
                    [--scheduler ADDRESS] [--resume] [--overwrite] [--no-progress]
    finkensim gap REAL.npz [REAL2.npz ...] [--config sim.toml] [--out DIR] [--heldout NAME ...]
    finkensim gap-validate [--cases CASE ...] [--trials N] [--flights K] [--duration S] [--out DIR]
    finkensim check FILE [FILE ...] [--arena W L]
    finkensim compile [scenario.toml] [--workers N]
    finkensim --version

Each subcommand is one ``_add_<name>(subparsers)`` function that registers its parser and sets
``func`` (``args -> exit code``); add new subcommands (sweep, gap, bench, ...) the same way in
:func:`build_parser`. Bad input (a missing or unreadable file, bad TOML, a config value out of
range, an unknown option) prints one line ``finkensim <command>: error: ...`` on stderr and
exits with code 2; there is no traceback for user errors.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Sequence

from . import __version__
from .cliargs import UsageError
from .cliargs import load_scenario_arg as _load_scenario_arg
from .cliargs import one_line as _one_line
from .cliargs import require_flight_log as _require_flight_log
from .cliargs import output_dir as _output_dir
from .cliargs import use_agg as _use_agg
from .gapvalidate_cli import add_parser as add_gap_validate

EXIT_OK = 0
EXIT_USAGE = 2
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, as a shell reports a reader that went away


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors become :class:`UsageError` (no usage dump, no SystemExit)."""

    def error(self, message):
        raise UsageError(self.prog, message)


# ------------------------------------------------------------------------------------------
# finkensim run
# ------------------------------------------------------------------------------------------

ARENA_TRAIL_SECONDS = 10.0  # trail length drawn in arena.png
SENSORS_COPTER = 0  # copter whose sonar and IMU time series sensors.png shows


def _add_run(sub) -> None:
    p = sub.add_parser(
        "run",
        help="simulate one flight, write its log, pictures and animation",
        description="Simulate one flight of a scenario and write DIR/flight.npz (flight log with sensor "
                    "readings and their error-free values), DIR/arena.png (arena at the largest wall "
                    "deflection), DIR/wall_response.png, DIR/sensors.png (sensors vs ideal values) "
                    "and DIR/flight.gif.",
    )
    p.add_argument("scenario", nargs="?", default=None,
                   help="scenario TOML file (default: the built-in scenario, 6 copters random-walking for 60 s)")
    p.add_argument("--out", default="out/run", metavar="DIR", help="output directory (default: %(default)s)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="flight length in s (default: simulation.duration of the scenario)")
    p.add_argument("--seed", type=int, default=None, metavar="N",
                   help="random seed (default: simulation.seed of the scenario)")
    p.add_argument("--no-gif", action="store_true", help="skip the animation")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--ideal", action=argparse.BooleanOptionalAction, default=True,
                   help="store the error-free sensor values in the log (extras *_ideal, ultrasonic_hit_type); "
                        "on by default, --no-ideal leaves them out")
    p.set_defaults(func=cmd_run)


def cmd_run(args) -> int:
    prog = args.prog
    t_start = time.perf_counter()
    from .compiletime import compile_timer
    from .config import ConfigError
    from .flightlog import save

    cfg = _load_scenario_arg(prog, args.scenario)
    _output_dir(prog, args.out, create=False)  # created once the flight ran: bad input leaves nothing behind
    from .scenario import simulate_flight  # the engine (numba): only once the input passed

    t0 = time.perf_counter()
    try:
        with compile_timer() as jit:
            log, traj, world = simulate_flight(cfg, duration=args.duration, seed=args.seed, ideal=args.ideal,
                                               progress=not args.no_progress)
    except ConfigError as exc:
        raise UsageError(prog, str(exc)) from None
    out = _output_dir(prog, args.out)
    t_sim = time.perf_counter() - t0
    sim = world.cfg.simulation
    print(f"{prog}: simulated {sim.duration:g} s of {world.n_copters} copters "
          f"({log.n_steps} samples, dt {sim.dt:g} s, seed {sim.seed}, {world.cfg.behaviour.kind}) in {t_sim:.2f} s: "
          f"JIT compile {jit.seconds:.2f} s ({jit.kernels} kernels; 0 when numba's cache is warm), the rest "
          f"{t_sim - jit.seconds:.2f} s")

    _use_agg()
    import matplotlib.pyplot as plt

    from . import viz
    from .analysis import peak_deflection_index

    written: list[tuple[str, Path, str]] = []
    try:
        path = out / "flight.npz"
        save(log, path)
        written.append(("flight log", path, f"{log.n_steps} x {log.n_copters} poses"))

        k = peak_deflection_index(traj)
        k0 = max(0, k - int(round(ARENA_TRAIL_SECONDS / sim.dt)))
        fig, _ = viz.plot_arena(world, traj.pose[k, 0, :, :2], traj.pose[k, 0, :, 2], traj.theta[k, 0],
                                trails=traj.pose[k0:k + 1, 0], t=float(traj.t[k]),
                                title="Arena at the largest wall deflection")
        path = viz.save_png(fig, out / "arena.png", dpi=130, colors=None)  # atomic, like every output
        plt.close(fig)
        written.append(("arena picture", path, f"t = {traj.t[k]:.1f} s, trails of the last {traj.t[k] - traj.t[k0]:.0f} s"))

        fig, _ = viz.plot_wall_response(world, traj)
        path = viz.save_png(fig, out / "wall_response.png", dpi=130, colors=None)
        plt.close(fig)
        written.append(("wall response", path, "amplitude law and simulated plate angles"))

        if log.ultrasonic is not None or log.ranging is not None or log.imu_acc is not None:
            fig, _ = viz.plot_sensors(log, copter=SENSORS_COPTER)
            path = viz.save_png(fig, out / "sensors.png", dpi=100)  # 256-colour palette: ~1/3 of the size
            plt.close(fig)
            what = "sonar, ranging, IMU" + (" vs ideal values" if args.ideal else " (no ideal values: --no-ideal)")
            written.append(("sensor picture", path, f"{what}, copter {SENSORS_COPTER}"))

        if not args.no_gif:
            path = viz.animate(world, traj, path=out / "flight.gif")
            from PIL import Image

            with Image.open(path) as im:
                n_frames = getattr(im, "n_frames", 1)
            written.append(("animation", path, f"{n_frames} frames"))
    except OSError as exc:
        raise UsageError(prog, f"cannot write to {str(out)!r}: {exc.strerror or exc}") from None

    width = max(len(w[0]) for w in written)
    for what, path, note in written:
        print(f"  {what:<{width}}  {path}  ({note})")
    print(f"{prog}: wrote {len(written)} files to {out} in {time.perf_counter() - t_start:.1f} s")
    return EXIT_OK


# ------------------------------------------------------------------------------------------
# finkensim sweep
# ------------------------------------------------------------------------------------------

EXIT_RUNS_FAILED = 1
MAX_FAILURES_SHOWN = 20


def _add_sweep(sub) -> None:
    p = sub.add_parser(
        "sweep",
        help="Monte-Carlo parameter sweep: metrics of many episodes, with summary table and plot",
        description="Run every parameter combination x replicate of a sweep file (see finkensim.sweep) and write "
                    "DIR/parts/run-XXXXX.parquet (one per finished run), DIR/results.parquet, DIR/summary.csv "
                    "(mean and 95% CI per combination) and DIR/summary.png. Exit code 1 if a run failed.",
    )
    p.add_argument("sweep", help="sweep TOML file ([base], [grid] or [random], [variants.NAME], replicates, duration, metrics, seed)")
    p.add_argument("--out", default="out/sweep", metavar="DIR", help="output directory (default: %(default)s)")
    p.add_argument("--executor", default=None, choices=("serial", "process", "dask"),
                   help="process: local process pool (default); dask: Dask cluster (--scheduler, else a local "
                        "cluster); serial: one run after another in this process (debugging)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes for the process pool or local Dask cluster (default: all cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (implies --executor dask)")
    p.add_argument("--resume", action="store_true", help="run only the runs whose result part is missing in DIR")
    p.add_argument("--overwrite", action="store_true", help="discard results already in DIR and start again")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep)


def cmd_sweep(args) -> int:
    prog = args.prog
    t_start = time.perf_counter()
    from .config import ConfigError
    from .sweep import Sweep, format_params, run_sweep

    path = Path(args.sweep)
    if not path.exists():
        raise UsageError(prog, f"sweep file {args.sweep!r} does not exist")
    if not path.is_file():
        raise UsageError(prog, f"sweep {args.sweep!r} is not a file")
    executor = args.executor or ("dask" if args.scheduler else "process")
    if args.scheduler and executor != "dask":
        raise UsageError(prog, f"--scheduler needs --executor dask, got --executor {executor}")
    if args.workers is not None and args.workers < 1:
        raise UsageError(prog, f"--workers {args.workers}: expected a positive number of workers")
    _output_dir(prog, args.out, create=False)
    try:
        sweep = Sweep.from_toml(path)
    except ConfigError as exc:
        raise UsageError(prog, str(exc)) from None

    workers = args.workers or os.cpu_count() or 1
    where = {"serial": "serially", "process": f"on a process pool of {min(workers, sweep.n_runs)} workers",
             "dask": f"on the Dask scheduler {args.scheduler}" if args.scheduler
             else f"on a local Dask cluster of {workers} workers"}[executor]
    print(f"{prog}: {sweep.n_runs} runs ({sweep.n_combinations} combinations x {sweep.replicates} replicates) "
          f"of {sweep.duration:g} s, {sweep.design} over {', '.join(sweep.parameters) or 'nothing'}, {where} -> {args.out}")
    from .sweep import terminate_as_interrupt

    try:
        with terminate_as_interrupt() as caught:  # SIGTERM ends the sweep like Ctrl-C
            df = run_sweep(sweep, args.out, executor=executor, workers=args.workers, scheduler=args.scheduler,
                           resume=args.resume, overwrite=args.overwrite, progress=not args.no_progress)
    except ConfigError as exc:  # SweepError: raised before any run
        raise UsageError(prog, str(exc)) from None
    except KeyboardInterrupt:
        what = "terminated (SIGTERM)" if caught else "interrupted"
        print(f"{prog}: {what}; finished runs are kept in {args.out}/parts, finish with --resume", file=sys.stderr)
        return 128 + caught[0] if caught else 130

    n_ran, skipped = len(df.attrs["ran"]), len(df) - len(df.attrs["ran"])
    failed = df[df["status"] != "ok"]
    note = f" ({skipped} already done)" if skipped else ""
    print(f"{prog}: {n_ran} runs in {time.perf_counter() - t_start:.1f} s{note}; {len(df) - len(failed)} ok, "
          f"{len(failed)} failed")
    out = Path(args.out)
    for name in ("results.parquet", "summary.csv", "summary.png"):
        print(f"  {out / name}")
    if len(failed):
        print(f"{prog}: {len(failed)} of {len(df)} runs failed:", file=sys.stderr)
        for _, row in failed.head(MAX_FAILURES_SHOWN).iterrows():
            params = format_params({k: row[k] for k in sweep.parameters})
            print(f"  run {row['run_id']} ({params}, replicate {row['replicate']}, seed {row['seed']}): "
                  f"{_one_line(row['error'])}", file=sys.stderr)
        if len(failed) > MAX_FAILURES_SHOWN:
            print(f"  ... and {len(failed) - MAX_FAILURES_SHOWN} more (see {out / 'results.parquet'})", file=sys.stderr)
        return EXIT_RUNS_FAILED
    return EXIT_OK


# ------------------------------------------------------------------------------------------
# finkensim gap / gap-validate
# ------------------------------------------------------------------------------------------

def _add_gap(sub) -> None:
    p = sub.add_parser(
        "gap", help="diagnose the sim-to-real gap of real flight logs",
        description="Replay real flight logs in the simulator, find where simulated and real sensor data disagree, "
                    "which catalogued effect explains it and how far the gap shrinks on held-out flights. Writes "
                    "DIR/report.json (docs/formats/gap-report.md), DIR/report.md, figures and DIR/calibrated.toml.")
    p.add_argument("logs", nargs="+", metavar="REAL.npz", help="flight logs (docs/formats/flightlog.md)")
    p.add_argument("--config", default=None, metavar="sim.toml",
                   help="simulator config (error models, walls, [gap]); default: finkensim's default config "
                        "(finkensim.config defaults, not the built-in `run` scenario); the geometry (arena, "
                        "copters, sonar mounting, copter radius) and the times always come from each log")
    p.add_argument("--out", default="out/gap", metavar="DIR",
                   help="output directory: report.json, report.md, figures, calibrated.toml (default: %(default)s)")
    p.add_argument("--heldout", nargs="+", default=None, metavar="NAME",
                   help="held-out flights by file name (default: every other flight; one flight: its second half)")
    p.add_argument("--effects", nargs="+", default=None, metavar="EFFECT", help="only try these catalogued effects")
    p.add_argument("--limits", choices=("config", "from-log"), default="config",
                   help="range limits (sonar.max_range, ranging.max_range): from the config, where readings beyond "
                        "them are an error, or raised to the logs' largest reading (default: %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress messages")
    p.set_defaults(func=cmd_gap)


def cmd_gap(args) -> int:
    prog = args.prog
    # The diagnosis runs many short parallel kernels; OpenMP's idle threads spin between them by default, which
    # costs nothing on a quiet machine and a lot when other processes share the cores (examples/gap_timing.py
    # beside a two-worker sweep: 47.6 s spinning, 29.7 s sleeping; 17.0 and 16.9 s on the quiet machine). Read
    # when OpenMP starts, i.e. at the first parallel kernel; a policy the user set wins.
    os.environ.setdefault("OMP_WAIT_POLICY", "passive")
    from .config import ConfigError, load_config
    from .flightlog import FlightLogError, load
    from .gap.model.inputs import GapInputError, check_heldout

    _output_dir(prog, args.out, create=False)
    try:  # every argument is checked before any flight is read or replayed
        check_heldout([Path(p).name for p in args.logs], args.heldout)
        if args.effects is not None:
            from .gap import check_effects  # the effect registry: the diagnosis's modules

            check_effects(args.effects)
    except GapInputError as exc:
        raise UsageError(prog, str(exc)) from None
    cfg = load_config(None)
    if args.config is not None:
        cfg = _load_scenario_arg(prog, args.config)
    for path in args.logs:
        _require_flight_log(prog, path)  # a CSV, bag or TOML file: said so, with what to do
    logs, names = [], []
    for path in args.logs:
        try:
            logs.append(load(path))
        except FlightLogError as exc:
            raise UsageError(prog, str(exc)) from None
        names.append(Path(path).name)
    if len(set(names)) != len(names):
        raise UsageError(prog, f"flight file names must be unique (they name the flights): {names}")
    # the diagnosis (numba, scipy, matplotlib: ≈ 0.9 s of CPU to import) loads once every input has passed
    from .gap import Diagnosis, run_diagnosis

    _use_agg()
    say = None if args.no_progress else (lambda msg: print(f"{prog}: {msg}", file=sys.stderr, flush=True))
    t0 = time.perf_counter()
    try:
        diag = Diagnosis(logs, names, cfg, heldout=args.heldout, progress=say, limits=args.limits)
        for note in diag.limit_notes.values():
            print(f"{prog}: {note}", file=sys.stderr)
        report = run_diagnosis(diag, args.effects)
    except (GapInputError, ConfigError) as exc:
        raise UsageError(prog, str(exc)) from None
    try:
        paths = report.write(args.out)
    except OSError as exc:
        raise UsageError(prog, f"cannot write to {args.out!r}: {exc.strerror or exc}") from None
    v = report["verdict"]
    if not v["significant_gap"]:
        verdict = "no significant gap"
    elif v["unexplained"] and all(s in report.details.too_little_data for s in report.details.gap_sensors or ["-"]):
        verdict = "significant gap; too little data to decide what explains it (see report.md)"
    elif v["unexplained"]:
        verdict = "significant gap, unexplained by the catalogue"
    else:
        verdict = f"{v['effect']} explains it (held-out shrink {100 * v['shrink_heldout']:.0f} %)"
    print(f"{prog}: gap {report['gap_before']:.4f}: {verdict}")
    print(f"{prog}: wrote {paths['json']} and {paths['md']} in {time.perf_counter() - t0:.1f} s")
    if "calibrated" in paths:
        print(f"{prog}: wrote {paths['calibrated']}: the diagnosed config with the selected effects at their fitted "
              f"parameters (finkensim run/sweep/tune read it as it is)")
    return EXIT_OK


def _add_check(sub) -> None:
    p = sub.add_parser("check", help="validate flight logs, scenario and sweep files without running them",
                       description="Read each file as the command using it would (flight logs .npz/.csv, scenario "
                                   "or sweep TOML), print a one-line summary of a good file and a named error for a "
                                   "bad one (exit code 2 if any file is bad). See finkensim.checkfiles.")
    p.add_argument("files", nargs="*", metavar="FILE",
                   help="flight logs (.npz), tracking or readings CSV files, scenario, sweep, study or topics TOML "
                        "files, bags (.bag, .mcap, ROS 2 bag folders)")
    p.add_argument("--arena", nargs="+", default=None, metavar="W,L",
                   help="arena width and length in m for .csv tracking files: 3,4 or 3 4, as in finkensim import "
                        "(default 3,4)")
    p.set_defaults(func=cmd_check)


def cmd_check(args) -> int:
    from .checkfiles import check_files
    from .usertext import arena_size

    files, arena = list(args.files), None
    if args.arena is not None:  # --arena takes W,L (one word) or W L (two): later words are files
        n = 1 if "," in args.arena[0] else 2
        files += args.arena[n:]
        try:
            arena = arena_size(args.arena[:n])
        except ValueError as exc:
            raise UsageError(args.prog, str(exc)) from None
    if not files:
        raise UsageError(args.prog, "the following arguments are required: FILE")
    return check_files(files, args.prog, arena=arena)


# ------------------------------------------------------------------------------------------
# entry point
# ------------------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    """The ``finkensim`` parser with one subparser per command."""
    parser = _Parser(
        prog="finkensim",
        description="finkensim: fast simulator of FINken quadcopter swarms with Bernoulli walls and realistic sensors.",
    )
    parser.add_argument("--version", action="version", version=f"finkensim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    _add_run(sub)
    _add_sweep(sub)
    _add_gap(sub)
    add_gap_validate(sub)
    _add_check(sub)
    from .importing.cli import add_parser as add_import
    from .precompile_cli import add_parser as add_compile
    from .tune.cli import add_parser as add_tune  # optuna is imported only when the command runs

    add_import(sub)
    add_compile(sub)
    add_tune(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            raise UsageError(parser.prog, "a command is required; try 'finkensim run' or 'finkensim --help'")
        # the prog of the chosen subparser, e.g. "finkensim run", for messages
        args.prog = f"{parser.prog} {args.command}"
        with warnings.catch_warnings():
            # a warning is one line "finkensim run: warning: ...", without the Python source line
            warnings.showwarning = lambda msg, *_, **__: print(f"{args.prog}: warning: {_one_line(msg)}", file=sys.stderr)
            return int(args.func(args))
    except UsageError as exc:
        print(f"{exc.prog}: error: {_one_line(str(exc))}", file=sys.stderr)
        return EXIT_USAGE
    except SystemExit as exc:  # --help / --version
        code = exc.code
        return code if isinstance(code, int) else (0 if code is None else EXIT_USAGE)
    except BrokenPipeError:
        # the reader went away (`finkensim run ... | head -1`): stop quietly, like other command-line tools;
        # stdout now points at /dev/null so that the interpreter's final flush does not complain either
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError, AttributeError):
            pass
        return EXIT_BROKEN_PIPE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
