"""Time `finkensim gap` on a 10-copter, 10-minute log (the issue's speed target: under 2 minutes).

    python examples/gap_timing.py [--out out/gap_timing] [--duration 600]

Simulates one flight (600 s by default) of 10 copters with bending walls (a withheld effect) and tracking noise,
writes it as a flight log, then runs the `finkensim gap` command on it with a rigid-wall model and
prints the wall-clock time of the diagnosis, its peak resident memory and its verdict.
"""
from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
from pathlib import Path

from finkensim.flightlog import save
from finkensim.gap.validate import CASES, generate


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/gap_timing")
    ap.add_argument("--duration", type=float, default=600.0, help="flight length, s")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    logs, _, truth = generate(CASES["wall_bulge"], seed=7, n_flights=1, duration=args.duration, n_copters=10)
    name = f"flight10x{args.duration:g}.npz"
    save(logs[0], out / name)
    (out / "rigid.toml").write_text('[walls]\nbending = false\n[sonar]\ncrosstalk = "off"\n')
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "finkensim.cli", "gap", str(out / name), "--config",
                    str(out / "rigid.toml"), "--out", str(out / "report"), "--no-progress"], check=True)
    elapsed = time.perf_counter() - t0
    peak_gb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024**2  # KiB on Linux
    print(f"finkensim gap on 10 copters x {args.duration:g} s: {elapsed:.1f} s wall clock, peak resident memory "
          f"{peak_gb:.2f} GB (true largest plate angle {truth['_max_amplitude_deg']:.1f} deg)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
