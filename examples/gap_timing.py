"""Time `finkensim gap` on a 10-copter, 10-minute log (the issue's speed target: under 2 minutes).

    python examples/gap_timing.py [--out out/gap_timing] [--duration 600] [--profile]

Simulates one flight (600 s by default) of 10 copters with bending walls (a withheld effect) and tracking noise,
writes it as a flight log, then runs the `finkensim gap` command on it with a rigid-wall model and
prints the wall-clock time of the diagnosis, its peak resident memory and its verdict. ``--profile``: the command
runs in this process under cProfile on the CPU clock instead (imports included), and its CPU seconds and costliest
functions are printed (a reused log is not simulated again).
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import resource
import subprocess
import sys
import time
from pathlib import Path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/gap_timing")
    ap.add_argument("--duration", type=float, default=600.0, help="flight length, s")
    ap.add_argument("--profile", action="store_true", help="profile the command in this process (CPU clock)")
    ap.add_argument("--simulate-only", action="store_true", help="only write the flight log")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = f"flight10x{args.duration:g}.npz"
    (out / "rigid.toml").write_text('[walls]\nbending = false\n[sonar]\ncrosstalk = "off"\n')
    command = ["gap", str(out / name), "--config", str(out / "rigid.toml"), "--out", str(out / "report"),
               "--no-progress"]
    if args.profile:
        return profile(out / name, args.duration, command)
    truth = simulate(out / name, args.duration)
    if args.simulate_only:
        return 0
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "finkensim.cli", *command], check=True)
    elapsed = time.perf_counter() - t0
    peak_gb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024**2  # KiB on Linux
    print(f"finkensim gap on 10 copters x {args.duration:g} s: {elapsed:.1f} s wall clock, peak resident memory "
          f"{peak_gb:.2f} GB (true largest plate angle {truth['_max_amplitude_deg']:.1f} deg)")
    return 0


def simulate(path: Path, duration: float) -> dict:
    """Simulate the flight (10 copters, ``duration`` s, the wall_bulge case, seed 7) into ``path``; its truth."""
    from finkensim.flightlog import save
    from finkensim.gap.validation.cases import CASES, generate

    logs, _, truth = generate(CASES["wall_bulge"], seed=7, n_flights=1, duration=duration, n_copters=10)
    save(logs[0], path)
    return truth


def profile(log_path: Path, duration: float, command: list[str]) -> int:
    """Run ``finkensim`` with ``command`` in this process under cProfile on the CPU clock, its imports included
    (the log simulated first, in a subprocess, unless ``log_path`` exists); print its CPU seconds and the 30
    costliest functions by own and by cumulative time."""
    if not log_path.exists():
        subprocess.run([sys.executable, __file__, "--out", str(log_path.parent), "--duration", f"{duration:g}",
                        "--simulate-only"], check=True)
    prof = cProfile.Profile(time.process_time)
    t0 = time.process_time()
    prof.enable()
    from finkensim.cli import main as cli  # the imports are part of what a user waits for

    code = cli(command)
    prof.disable()
    print(f"finkensim {' '.join(command)}: {time.process_time() - t0:.1f} s CPU (imports included, under cProfile)")
    for order in ("tottime", "cumulative"):
        pstats.Stats(prof, stream=sys.stdout).sort_stats(order).print_stats(30)
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
