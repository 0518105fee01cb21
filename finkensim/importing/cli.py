"""``finkensim import``: an arena recording (CSV pair, ROS 1 / ROS 2 bag, MCAP) into one flight log::

    finkensim import --tracking TRACK.csv --readings READ.csv --arena 3,4 --sonar-yaw-deg 0,90,180,-90 \\
                     --sonar-offset 0.1 [--copter-radius M] [--altitude M] [--clock-offset auto|SECONDS] \\
                     [--rate HZ] [--config SCENARIO.toml] --out FLIGHT.npz
    finkensim import --bag FILE --topics topics.toml --arena 3,4 ... --out FLIGHT.npz
    finkensim import --paparazzi LOG.data[.gz] [--messages messages.xml] [--paparazzi-map MAP.toml] \\
                     --tracking TRACK.csv --arena 4,3 --sonar-offset 0.1 ... --out FLIGHT.npz

``finkensim.cli`` registers it with :func:`add_parser`; bad input is one line naming the argument, file, column
or channel (exit code 2); the import decisions (rates, clock offset ± uncertainty, what was dropped and why) are
printed and written into the log's ``meta["import"]``.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

__all__ = ["add_parser", "run"]

EXIT_USAGE = 2


class _Usage(Exception):
    """Bad input: printed as one line ``finkensim import: error: ...``, exit code 2."""


def add_parser(sub) -> None:
    """Register ``import`` on the ``finkensim`` subparsers ``sub``."""
    p = sub.add_parser(
        "import",
        help="import an arena recording (CSV, ROS bag, MCAP, Paparazzi telemetry) into a flight log: clocks aligned, readings unchanged",
        description="Read tracking and sensor readings recorded at their own rates (CSV pair, or a ROS 1 / ROS 2 "
                    "bag or MCAP file with a topics TOML, or Paparazzi telemetry with a tracking CSV), estimate or apply the offset between the sensors' clock "
                    "and the tracking clock, place every reading unchanged on a common time base, interpolate the "
                    "poses to it, and write one flight log (docs/formats/flightlog.md). The decisions are printed and "
                    "kept in the log's meta['import'].",
    )
    src = p.add_argument_group("input (a CSV pair, a bag, or Paparazzi telemetry with a tracking CSV)")
    src.add_argument("--tracking", metavar="TRACK.csv", help="CSV with columns t, copter, x, y, yaw (s, name, m, m, rad) "
                                                            "and optionally z (m, height: ranging is then 3-D)")
    src.add_argument("--readings", metavar="READ.csv",
                     help="CSV with columns t, copter, channel, value; channels ultrasonic/<i>, ranging/<copter>, "
                          "imu/acc_x, imu/acc_y, imu/gyro")
    src.add_argument("--bag", metavar="FILE", help="ROS 1 .bag, ROS 2 bag directory, or .mcap file (needs the "
                                                   "[import] extra)")
    src.add_argument("--topics", metavar="TOPICS.toml", help="with --bag: which topic is which copter's channel")
    src.add_argument("--paparazzi", metavar="LOG.data", help="Paparazzi telemetry .data (gzip or not); its .log "
                                                             "(same name) gives the message layouts")
    src.add_argument("--messages", metavar="messages.xml", help="with --paparazzi: message layouts to add to (or "
                                                                "replace in) the .log's protocol")
    src.add_argument("--paparazzi-map", metavar="MAP.toml", help="with --paparazzi: which message field is which "
                     "channel, its unit and sonar yaw (default: the FINken's, finkensim/data/paparazzi_finken.toml)")
    p.add_argument("--arena", required=True, metavar="W,L", help="arena width and length in m, e.g. 3,4")
    p.add_argument("--sonar-yaw-deg", metavar="A,B,...",
                   help="mounting yaw of ultrasonic/0, /1, ... relative to the heading, degrees (front 0, left 90; "
                        "default with --paparazzi: the map's)")
    p.add_argument("--sonar-offset", type=float, metavar="M", help="distance from the copter centre to each sonar (m)")
    p.add_argument("--copter-radius", type=float, default=None, metavar="M", help="copter body radius (m; default "
                   "0.15, or the --config scenario's)")
    p.add_argument("--altitude", type=float, default=None, metavar="M", help="flight height (m), written to meta")
    p.add_argument("--clock-offset", default="auto", metavar="auto|SECONDS",
                   help="seconds to add to the readings' times to put them on the tracking clock, or 'auto' to "
                        "estimate it from the data (default: %(default)s)")
    p.add_argument("--max-offset", type=float, default=2.0, metavar="SECONDS",
                   help="half-width of the 'auto' search (default: %(default)s)")
    p.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="samples per second of the time base (default: the tracking rate)")
    p.add_argument("--config", default=None, metavar="SCENARIO.toml",
                   help="the simulator scenario the flight will be diagnosed against: its walls model (bending "
                        "curtains) sharpens the 'auto' clock offset")
    p.add_argument("--out", required=True, metavar="FLIGHT.npz", help="the flight log to write")
    p.set_defaults(func=run)


def _floats(flag, text, n=None):
    try:
        vals = [float(x) for x in str(text).split(",")]
    except ValueError:
        raise _Usage(f"{flag} {text!r}: expected comma-separated numbers") from None
    if n is not None and len(vals) != n:
        raise _Usage(f"{flag} {text!r}: expected {n} comma-separated numbers, got {len(vals)}")
    if not all(math.isfinite(v) for v in vals):
        raise _Usage(f"{flag} {text!r}: expected finite numbers")
    return vals


def _paparazzi(args):
    """(recording, sonar yaw from the map) of --paparazzi with the --tracking CSV (or sensor-only without it)."""
    import numpy as np

    from .csvtables import read_csv
    from .paparazzi import read_paparazzi
    from .paparazzi_protocol import DEFAULT_MAP

    if args.bag is not None or args.readings is not None:
        raise _Usage("give --paparazzi (with --tracking) or --bag or --tracking/--readings, not several")
    pp = read_paparazzi(args.paparazzi, messages=args.messages,
                        map=Path(args.paparazzi_map) if args.paparazzi_map else DEFAULT_MAP)
    if args.tracking is None:  # sensor-only: say what was read before build_flight says what is missing
        for (copter, channel), g in pp.readings.groupby(["copter", "channel"], sort=False):
            t, v = g["t"].to_numpy(), g["value"].to_numpy()
            step = float(np.median(np.diff(t))) if t.size > 1 else float("nan")
            print(f"  read {copter} {channel}: {t.size} readings over {t[-1] - t[0]:.1f} s, median interval "
                  f"{1000 * step:.3g} ms, {v.min():.4g} to {v.max():.4g} ({pp.notes['units'][channel]}; in SI units)")
    tracking = read_csv(args.tracking).tracking if args.tracking is not None else None
    return pp.recording(tracking), pp.sonar_yaw


def _recording(args):
    """(recording, default sonar yaw or None) of the input arguments."""
    from .csvtables import read_csv

    if args.paparazzi is not None:
        return _paparazzi(args)
    if args.messages is not None or args.paparazzi_map is not None:
        raise _Usage("--messages and --paparazzi-map go with --paparazzi LOG.data")
    if args.bag is not None:
        if args.tracking or args.readings:
            raise _Usage("give either --bag (with --topics) or --tracking/--readings, not both")
        if args.topics is None:
            raise _Usage("--bag needs --topics TOPICS.toml (which topic is which copter's channel)")
        try:
            from .bags import read_bag
        except ImportError as exc:
            raise _Usage(f"reading bags needs the [import] extra ({exc}): pip install 'finkensim[import]'") \
                from None
        return read_bag(args.bag, args.topics), None
    if args.tracking is None:
        raise _Usage("an input is required: --tracking TRACK.csv [--readings READ.csv], or --bag FILE "
                     "--topics TOPICS.toml, or --paparazzi LOG.data --tracking TRACK.csv")
    return read_csv(args.tracking, args.readings), None


def run(args) -> int:
    """Run ``finkensim import`` with parsed ``args``; returns the exit code."""
    prog = getattr(args, "prog", "finkensim import")
    try:
        return _run(prog, args)
    except _Usage as exc:
        print(f"{prog}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return EXIT_USAGE


def _scenario(path: str):
    from ..config import ConfigError
    from ..scenario import load_scenario

    p = Path(path)
    if not p.is_file():
        raise _Usage(f"--config {path!r}: " + ("is not a file" if p.exists() else "does not exist"))
    try:
        return load_scenario(p)
    except (ConfigError, UnicodeDecodeError, OSError) as exc:
        raise _Usage(f"--config {path}: {exc}") from None


def _run(prog, args) -> int:
    import numpy as np

    from ..config import ConfigError
    from ..flightlog import DEFAULT_COPTER_RADIUS, FlightLogError, save
    from .align import build_flight

    t_start = time.perf_counter()
    W, L = _floats("--arena", args.arena, 2)
    if not (W > 0 and L > 0):
        raise _Usage(f"--arena {args.arena!r}: expected a positive width and length in m")
    yaw = np.radians(_floats("--sonar-yaw-deg", args.sonar_yaw_deg)) if args.sonar_yaw_deg else None
    clock = args.clock_offset
    if clock != "auto":
        try:
            clock = float(clock)
        except ValueError:
            raise _Usage(f"--clock-offset {args.clock_offset!r}: expected 'auto' or a number of seconds") \
                from None
    cfg = _scenario(args.config) if args.config else None
    radius = args.copter_radius
    if radius is None:
        radius = cfg.copters.radius if cfg is not None else DEFAULT_COPTER_RADIUS
    out = Path(args.out)
    if not str(args.out).strip() or out.is_dir():
        raise _Usage(f"--out {args.out!r}: expected a file name for the flight log")
    if not out.parent.exists():
        raise _Usage(f"--out {args.out!r}: directory {str(out.parent)!r} does not exist")
    try:
        rec, map_yaw = _recording(args)
        if yaw is None and map_yaw is not None:
            yaw = np.asarray(map_yaw)
        log = build_flight(rec, arena=(W, L), sonar_yaw=yaw, sonar_offset=args.sonar_offset, copter_radius=radius,
                           altitude=args.altitude, clock_offset=clock, rate=args.rate, max_offset=args.max_offset,
                           config=cfg)
        save(log, out)
    except (FlightLogError, ConfigError) as exc:
        raise _Usage(str(exc)) from None
    imp = log.meta["import"]
    c = imp["clock_offset"]
    unc = f" ± {c['uncertainty']:.4f}" if "uncertainty" in c else ""
    tb = imp["time_base"]
    print(f"{prog}: {log.n_copters} copters, {tb['samples']} samples at {tb['rate_hz']:.4g} Hz ({tb['from']}), "
          f"{log.t[-1] - log.t[0]:.1f} s; clock offset {c['seconds']:+.4f}{unc} s ({c['method']})")
    rates = ", ".join(f"{k} {v:.4g} Hz" for k, v in imp["rates_hz"].items() if v is not None)
    print(f"  rates: tracking {imp['tracking']['rate_hz']:.4g} Hz" + (f", {rates}" if rates else "")
          + f"; longest tracking gap {imp['tracking']['longest_gap_s']:.3f} s")
    print("  readings placed: " + (", ".join(f"{k} {v}" for k, v in imp["readings_placed"].items()) or "none"))
    for why, n in imp["dropped"].items():
        print(f"  not placed: {n} {why}")
    print(f"{prog}: wrote {out} in {time.perf_counter() - t_start:.1f} s")
    return 0
