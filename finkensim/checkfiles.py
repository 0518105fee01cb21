"""``finkensim check FILE ...``: validate flight logs, scenario and sweep files without running them.

Each file is read exactly as the command that uses it reads it (flight logs with
:func:`finkensim.flightlog.load` or, for ``.csv`` tracking data, :func:`~finkensim.flightlog.from_csv`;
scenarios with :func:`~finkensim.default_scenario.load_scenario`; sweeps with
:meth:`~finkensim.sweep.Sweep.from_toml`, which builds and checks every configuration of the design),
plus what a run would check next: room for the copters and the memory a flight would hold
(:mod:`finkensim.budget`). A good file gives one summary line on stdout::

    flight.npz: flight log, T = 1201 samples over 60 s (dt 0.05 s), N = 6 copters, sensors: ultrasonic (S = 4), ranging, imu; arena 3 x 4 m

a bad one one error line on stderr naming the file, the key or array and what was expected.
:func:`check_files` returns 0 if every file is good, else 2 (the exit code of a usage error).

Which kind a file is decides :func:`finkensim.filekinds.file_kind`, the detector ``gap`` and ``import``
use too: flight logs (``.npz``), tracking and readings CSV files (by their header), scenario, sweep, study
and topics TOML files (by their top-level keys) and recordings (ROS 1 / ROS 2 bags, MCAP). Study files are
read by :func:`finkensim.tune.parse_study` (every combination of the ranges checked), readings CSV files
cell by cell as ``import --readings`` reads them, topics files by ``import --topics``' parser, and bags
opened and their topics listed.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable, Sequence

from .budget import check_memory, flight_advice, flight_arrays, format_bytes
from .config import ConfigError
from .filekinds import SWEEP_KEYS, FileKindError, file_kind
from .flightlog import FlightLog, FlightLogError, from_csv, load

__all__ = ["SWEEP_KEYS", "file_kind", "check_file", "check_files", "log_summary"]

EXIT_OK, EXIT_BAD = 0, 2


def log_summary(log: FlightLog) -> str:
    """One line about a flight log: ``flight log, T = <T> samples over <s> s (dt <s>), N = <N> copters,
    sensors: <list>; arena W x L m``."""
    T, N = int(log.t.shape[0]), int(log.pose.shape[1])
    span = float(log.t[-1] - log.t[0])
    dt = f" (dt {span / (T - 1):.3g} s)" if T > 1 else ""
    sensors = []
    if log.ultrasonic is not None:
        sensors.append(f"ultrasonic (S = {log.ultrasonic.shape[2]})")
    if log.ranging is not None:
        sensors.append("ranging")
    if log.imu_acc is not None:
        sensors.append("imu")
    return (f"flight log, T = {T} sample{'s' if T != 1 else ''} over {span:g} s{dt}, N = {N} "
            f"copter{'s' if N != 1 else ''}, sensors: {', '.join(sensors) or 'none'}; "
            f"arena {float(log.arena[0]):g} x {float(log.arena[1]):g} m")


def _scenario_summary(path: Path) -> str:
    from .default_scenario import load_scenario

    cfg = load_scenario(path)
    from .scenario import preflight  # the engine (numba): only for a scenario that loads

    sim = cfg.simulation
    preflight(cfg)  # every check `run` makes before it flies (ranges, mixture files, sensors, steps, placement)
    T = int(round(sim.duration / sim.dt)) + 1
    total = check_memory(flight_arrays(cfg), f"a flight of {sim.duration:g} s of {cfg.copters.n} copters",
                         flight_advice(cfg))
    sensors = [name for name in ("sonar", "ranging", "imu") if getattr(cfg, name).enabled]
    return (f"scenario, T = {T} samples over {sim.duration:g} s (dt {sim.dt:g} s), N = {cfg.copters.n} copters "
            f"({cfg.behaviour.kind}), sensors: {', '.join(sensors) or 'none'}; arena {cfg.arena.width:g} x "
            f"{cfg.arena.length:g} m; a flight holds about {format_bytes(total)}")


def _sweep_summary(path: Path) -> str:
    from .sweep import Sweep

    sweep = Sweep.from_toml(path)
    cfg = sweep.base
    return (f"sweep, {sweep.n_runs} runs ({sweep.n_combinations} combinations x {sweep.replicates} replicates) "
            f"of {sweep.duration:g} s, {sweep.design} over {', '.join(sweep.parameters) or 'nothing'}; base: "
            f"N = {cfg.copters.n} copters, arena {cfg.arena.width:g} x {cfg.arena.length:g} m")


def _study_summary(path: Path) -> str:
    from .tune.studyfile import parse_study

    spec = parse_study(path)
    return (f"study, {spec.n_trials} trials over {', '.join(p.key for p in spec.params)}; objectives "
            f"{', '.join(f'{m} ({d})' for m, d in spec.objectives)}; {spec.n_envs} environments x {spec.duration:g} s "
            f"per trial ({spec.sampler})")


def _readings_summary(path: Path) -> str:
    from .flightlog.csv import numeric_column, read_table
    from .importing.recording import READING_COLUMNS, parse_channel

    where = f"readings CSV {str(path)!r}"
    df, lines = read_table(path, READING_COLUMNS, where)
    copter = df["copter"].str.strip().to_numpy()
    t = numeric_column(df, "t", lines, where, copter, "every reading needs its time")
    numeric_column(df, "value", lines, where, copter, "NaN marks a lost reading", allow_nan=True)
    channels = sorted(set(df["channel"].str.strip()))
    for name in channels:
        parse_channel(name)
    return (f"readings CSV, {len(df)} readings over {float(t.max() - t.min()):g} s, {len(set(copter))} copters, "
            f"channels: {', '.join(channels)}; read by finkensim import --readings (with --tracking)")


def _topics_summary(path: Path) -> str:
    from .importing.topics import parse_topics

    spec = parse_topics(path)
    return f"topics file, {len(spec.entries)} topics; read by finkensim import --bag ... --topics"


def _bag_summary(path: Path) -> str:
    from .importing.bags import list_topics

    try:
        topics = list_topics(path)
    except ImportError:
        return "recording (bag); reading it needs the [import] extra: pip install 'finkensim[import]'"
    return (f"recording (bag), {len(topics)} topics, {sum(topics.values())} messages; read by finkensim import "
            f"--bag ... --topics")


def check_file(path: str | Path, arena: Sequence[float] | None = None) -> str:
    """The summary of a good file (without its name); raises ConfigError / FlightLogError for a bad one.

    ``arena`` (width, length) m is needed for a ``.csv`` tracking file (default 3 x 4 m, the default arena).
    """
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{p}: file does not exist")
    try:
        kind = file_kind(p)
    except FileKindError as exc:
        raise ConfigError(str(exc)) from None
    except OSError as exc:
        raise ConfigError(f"cannot read {str(p)!r}: {exc.strerror or exc}") from None
    if kind == "log":
        return log_summary(load(p))
    if kind == "csv":
        return log_summary(from_csv(p, tuple(arena) if arena is not None else (3.0, 4.0))) + \
            "; also read by finkensim import --tracking"
    summary = {"sweep": _sweep_summary, "study": _study_summary, "readings": _readings_summary,
               "topics": _topics_summary, "bag": _bag_summary, "scenario": _scenario_summary}[kind]
    return summary(p)


def check_files(paths: Sequence[str], prog: str = "finkensim check", arena: Sequence[float] | None = None,
                out: Callable[[str], None] | None = None) -> int:
    """Check every file of ``paths``: a summary line per good file (``out``, default stdout), an error line
    ``<prog>: error: <message>`` per bad one on stderr. Returns 0 if all are good, else 2."""
    say = out or print
    status = EXIT_OK
    for path in paths:
        try:
            summary = check_file(path, arena)
        except (ConfigError, FlightLogError) as exc:
            msg = " ".join(str(exc).split())
            named = msg if str(path) in msg else f"{path}: {msg}"
            print(f"{prog}: error: {named}", file=sys.stderr)
            status = EXIT_BAD
            continue
        say(f"{path}: {summary}")
    return status
