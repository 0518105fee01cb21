"""Mutation runs: does the suite catch a wrong model? (issue 16; not collected by pytest)

    python tests/mutation/run_mutations.py [NAME ...] [--out tests/mutation/results.md]

For each mutation below: copy the working tree's tracked files to a temporary directory, apply one textual change
to one kernel (the run stops if the text is not found exactly once), run the named test files there with a fresh
numba cache, and record which tests fail. A mutation that no test kills is a hole in the suite. The table of the
last run is written to ``--out`` (default: print only).
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: name -> (file, original text, mutated text, test files, what it models)
MUTATIONS = {
    "ranging_bias_2pct": (
        "finkensim/sensors/ranging_kernels.py", "    return y if y > 0.0 else 0.0\n",
        "    return 1.02 * y if y > 0.0 else 0.0\n", ["tests/test_ranging.py"],
        "a 2 % bias in the ranging sampler"),
    "echo_error_sign": (
        "finkensim/sensors/sonar_kernels.py", "    return y + sp.rayleigh_sign * (R - sp.rayleigh_s)\n",
        "    return y - sp.rayleigh_sign * (R - sp.rayleigh_s)\n", ["tests/test_sonar.py"],
        "a sign flip in the sonar echo error"),
    "firing_slot_swapped": (
        "finkensim/sensors/sonar_kernels.py", "        return n % sp.n_slots\n",
        "        return (sp.n_slots - 1 - n) % sp.n_slots\n", ["tests/test_sonar.py"],
        "round-robin firing slots in reverse order"),
    "hinge_substeps_off_by_one": (
        "finkensim/arena.py", "    for _ in range(hp.substeps):\n        for q in range(n_on):\n",
        "    for _ in range(hp.substeps - 1):\n        for q in range(n_on):\n", ["tests/test_arena.py"],
        "one hinge substep too few in the engine's wall step"),
    "velocity_lag_euler": (
        "finkensim/copters.py", "    return 1.0 if tau <= 0.0 else 1.0 - np.exp(-dt / tau)\n",
        "    return 1.0 if tau <= 0.0 else min(1.0, dt / tau)\n", ["tests/test_world.py"],
        "the copters' first-order lag discretised by explicit Euler instead of exactly"),
}


def tracked_files() -> list[str]:
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return [line for line in out.splitlines() if line]


def run_one(name: str) -> dict:
    path, old, new, tests, what = MUTATIONS[name]
    with tempfile.TemporaryDirectory(prefix=f"mutant-{name}-") as d:
        d = Path(d)
        for f in tracked_files():
            (d / f).parent.mkdir(parents=True, exist_ok=True)
            if (ROOT / f).is_file():
                shutil.copy2(ROOT / f, d / f)
        src = (d / path).read_text()
        if src.count(old) != 1:
            raise SystemExit(f"{name}: the text to mutate occurs {src.count(old)} times in {path}, expected once")
        (d / path).write_text(src.replace(old, new))
        env = dict(os.environ, NUMBA_CACHE_DIR=str(d / ".numba_cache"), MPLBACKEND="Agg", PYTHONPATH=str(d))
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rf", "-p", "no:cacheprovider", *tests], cwd=d,
                           env=env, capture_output=True, text=True)
        failed = sorted(set(re.findall(r"^FAILED (\S+)", p.stdout, flags=re.M)))
        summary = (p.stdout.strip().splitlines() or ["?"])[-1]
    return dict(name=name, what=what, file=path, tests=tests, failed=failed, summary=summary,
                seconds=time.perf_counter() - t0, killed=bool(failed))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help=f"mutations to run (default: all: {', '.join(MUTATIONS)})")
    ap.add_argument("--out", default=None, help="write the result table (markdown) here")
    a = ap.parse_args(argv)
    names = a.names or list(MUTATIONS)
    unknown = [n for n in names if n not in MUTATIONS]
    if unknown:
        raise SystemExit(f"unknown mutation {unknown[0]!r}; expected one of {', '.join(MUTATIONS)}")
    rows = []
    for n in names:
        r = run_one(n)
        rows.append(r)
        print(f"{n}: {'KILLED' if r['killed'] else 'SURVIVED'} by {len(r['failed'])} test(s) in {r['seconds']:.0f} s "
              f"({r['summary']})", flush=True)
        for f in r["failed"]:
            print(f"    {f}")
    lines = ["| mutation | what it breaks | tests run | killed | failing tests |", "|---|---|---|---|---|"]
    for r in rows:
        shown = ", ".join(f"`{f.split('::', 1)[1]}`" for f in r["failed"][:6]) + (" …" if len(r["failed"]) > 6 else "")
        lines.append(f"| `{r['name']}` | {r['what']} (`{r['file']}`) | {', '.join(r['tests'])} | "
                     f"{'yes' if r['killed'] else '**no**'} ({len(r['failed'])}) | {shown} |")
    table = "\n".join(lines) + "\n"
    print(table)
    if a.out:
        Path(a.out).write_text(table)
    return 0 if all(r["killed"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
