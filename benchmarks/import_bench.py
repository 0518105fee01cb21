"""``python -m benchmarks.import_bench [--duration S] [--copters N]``: time `finkensim import` on a recording of the
size the issue names (10 copters x 10 minutes; tracking 100 Hz, 4 sonars at 20 Hz, ranging at 10 Hz, IMU at 100 Hz).

The recording is a flight simulated at 100 Hz and exported asynchronously (:func:`finkensim.importing.to_recording`,
jitter 0.1 period, clock offset 0.3 s) to CSV; the timed part is the whole CLI command (`--clock-offset auto`):
reading both CSVs, checking, estimating the offset, placing the readings, interpolating the poses, writing the
flight log. Prints one line per phase and the total.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0, help="flight length (s)")
    ap.add_argument("--copters", type=int, default=10)
    a = ap.parse_args(argv)

    import finkensim as fs
    from finkensim.importing import to_recording, write_csv

    cfg = fs.load_config({"simulation": {"dt": 0.01}, "copters": {"n": a.copters}})
    t0 = time.perf_counter()
    log, _, _ = fs.simulate_flight(cfg, duration=a.duration, seed=1)
    rec = to_recording(log, clock_offset=0.3, seed=1)
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        write_csv(rec, d / "track.csv", d / "read.csv")
        print(f"prepared {len(rec.tracking):,} tracking rows and {len(rec.readings):,} readings "
              f"({a.copters} copters x {a.duration:g} s) in {time.perf_counter() - t0:.1f} s", flush=True)
        cmd = [sys.executable, "-m", "finkensim.cli", "import", "--tracking", str(d / "track.csv"), "--readings",
               str(d / "read.csv"), "--arena", f"{cfg.arena.width},{cfg.arena.length}", "--sonar-yaw-deg",
               "0,90,180,-90", "--sonar-offset", str(cfg.sonar.offset), "--out", str(d / "flight.npz")]
        t1 = time.perf_counter()
        p = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t1
        print(p.stdout, end="")
        if p.returncode != 0:
            print(p.stderr, file=sys.stderr)
            return p.returncode
        print(f"finkensim import of {a.copters} copters x {a.duration:g} s: {wall:.1f} s wall clock "
              f"(whole command, process start included)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
