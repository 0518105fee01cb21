"""The full FINken workload in the engine itself, cost per copter-step against N at fixed density.

``python -m benchmarks.engine_scaling [--quick] [--sizes N ...]``. One environment (one thread: ``prange`` over a
single environment), the configuration of ``benchmarks.workloads.finken_config`` (bending walls, Rayleigh sonar with
geometric cross-talk, 2.5 m mixture ranging, IMU, attraction–repulsion without a wall check) in an arena that grows
with N at the lab's density (10 copters in 3 m × 4 m, aspect 3 : 4; the walls keep 16 plates each, so plates get
wider). ``SwarmSim.rollout`` without recording, thread CPU time (``time.thread_time``) of the steady state (a first
rollout compiles and settles the swarm), best of 3. Prints µs per copter-step with the cell grid (on from
``simulation.grid_min_copters``) and, up to ``--brute-max`` copters, with the brute force, and the spread of the grid
column (the target of issue #15: flat within ±30 % from N = 10 to 10 000).

The grid serves contacts, ranging, the sonar (rays and cross-talk) and the wall check. The ranging rows are still
N × N in memory, though without recording only the columns in range are written; the geometric cross-talk searches
a disc of 2·(max_range + offset) = 6 m, which the small arenas clip and the large ones do not (at N = 1000 it is
more than half of the cost per copter-step), so the grid column still grows with N.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from benchmarks.plotting import loglog_figure
from benchmarks.workloads import finken_config

AREA_PER_COPTER = 12.0 / 10  # m², the SwarmLab with 10 copters


def config(n: int, grid: bool, wall_check: str = "none"):
    length = math.sqrt(n * AREA_PER_COPTER * 4 / 3)
    cfg = finken_config(n, 1, 0.75 * length, length, {"grid_min_copters": 64 if grid else 2**62})
    return cfg.replace({"behaviour.wall_check": wall_check})


def us_per_copter_step(n: int, grid: bool, steps: int, wall_check: str = "none") -> float:
    from finkensim.swarm import SwarmSim

    sim = SwarmSim(config(n, grid, wall_check))
    state, _ = sim.rollout(sim.init(n_envs=1, seed=1), 20, record=False)  # compile, leave the start positions
    best = math.inf
    for _ in range(3):
        t0 = time.thread_time()
        sim.rollout(state, steps, record=False)
        best = min(best, time.thread_time() - t0)
    return best / (steps * n) * 1e6


#: ``make bench``'s sizes: the grid column to 10 000 copters, the brute force where it takes seconds, not hours
BENCH_SIZES = (10, 100, 1000, 10_000)
BENCH_BRUTE_MAX = 1000


def spread(costs) -> float:
    """Half the max/min ratio's log-spread around the geometric mean, as ±%: max / sqrt(max·min) − 1."""
    return max(costs) / math.sqrt(max(costs) * min(costs)) - 1.0


def figure(rows, path) -> Path | None:
    """Log-log figure of µs per copter-step against N (grid and brute force) with the ±30 % band of the target
    around the geometric mean of the grid column; rows as returned by :func:`run`. None without matplotlib."""
    n = [r["N"] for r in rows]
    g = [r["grid_us"] for r in rows]
    brute = [(r["N"], r["brute_us"]) for r in rows if r.get("brute_us")]

    def draw(ax):
        centre = math.sqrt(max(g) * min(g))
        ax.axhspan(centre / 1.3, centre * 1.3, color="0.85", label="target: flat within ±30 %")
        ax.plot(n, g, "o-", label="cell grid (on from 64 copters)")
        if brute:
            ax.plot(*zip(*brute), "s--", label="brute force")

    return loglog_figure(path, draw, "copters N (arena grows with N: 1.2 m² per copter)",
                         "µs per copter-step (one thread)", "Full FINken workload in the engine against N", dpi=110)


def measure(sizes, brute_max, step_budget: int = 20_000, wall_check: str = "none"):
    """Yield {N, grid_us, brute_us (None above ``brute_max``)} for each N of ``sizes``, as each is measured; each
    timed rollout runs max(5, step_budget // N) steps."""
    for n in sizes:
        steps = max(5, step_budget // n)
        g = us_per_copter_step(n, True, steps, wall_check)
        b = us_per_copter_step(n, False, steps, wall_check) if n <= brute_max else None
        yield dict(N=n, grid_us=g, brute_us=b)


def run(log=print, sizes=BENCH_SIZES, brute_max=BENCH_BRUTE_MAX, out_dir=None) -> dict:
    """Rows {N, grid_us, brute_us or None}, the grid column's spread and a markdown table (for ``make bench``);
    with ``out_dir`` also the figure ``engine_scaling.png`` there (:func:`figure`)."""
    rows = []
    for r in measure(sizes, brute_max):
        rows.append(r)
        g, b = r["grid_us"], r["brute_us"]
        log(f"(d) engine scaling N={r['N']:6d}  grid {g:7.2f} µs/copter-step" + (f"  brute {b:7.2f}" if b else ""))
    sp = spread([r["grid_us"] for r in rows])
    L = ["## (d) The full FINken workload in the engine against N, lab density (benchmarks/engine_scaling.py)", "",
         "One environment, one thread; the arena grows with N (10 copters per 3 m × 4 m); the cell grid on from "
         "`simulation.grid_min_copters`.", "",
         "| N | grid µs/copter-step | brute force µs/copter-step | brute/grid |", "|---:|---:|---:|---:|"]
    for r in rows:
        b, g = r["brute_us"], r["grid_us"]
        brute, ratio = (f"{b:.2f}", f"{b / g:.1f}") if b else ("—", "—")
        L.append(f"| {r['N']:,} | {g:.2f} | {brute} | {ratio} |")
    L += ["", f"Grid column spread: ±{100 * sp:.0f} % around its geometric mean (target ±30 %)."]
    if out_dir is not None and figure(rows, Path(out_dir) / "engine_scaling.png"):
        L += ["", "![full workload against N](engine_scaling.png)"]
    return dict(rows=rows, spread=sp, markdown="\n".join(L))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N up to 256, fewer steps")
    ap.add_argument("--sizes", type=int, nargs="+", help="swarm sizes (default 10 … 4096)")
    ap.add_argument("--brute-max", type=int, default=1024, help="largest N timed with the brute force too")
    ap.add_argument("--wall-check", default="none", choices=("none", "per_reading", "sequence"),
                    help="the behaviour's wall check (default none, as in make bench's full workload)")
    ap.add_argument("--plot", nargs=2, metavar=("BENCH_JSON", "PNG"),
                    help="only redraw the figure from the section (d) rows of a make bench result (bench.json)")
    args = ap.parse_args(argv)
    if args.plot:
        rows = json.loads(Path(args.plot[0]).read_text())["engine_scaling"]["rows"]
        print(figure(rows, args.plot[1]))
        return
    sizes = args.sizes or ([10, 64, 256] if args.quick else [10, 32, 64, 128, 256, 512, 1024, 2048, 4096])
    print(f"{'N':>6} {'grid µs/copter-step':>20} {'brute µs/copter-step':>21} {'brute/grid':>11}")
    costs = []
    for r in measure(sizes, args.brute_max, 2_000 if args.quick else 20_000, args.wall_check):
        n, g, b = r["N"], r["grid_us"], r["brute_us"]
        costs.append(g)
        if b is not None:
            print(f"{n:>6} {g:>20.2f} {b:>21.2f} {b / g:>11.2f}", flush=True)
        else:
            print(f"{n:>6} {g:>20.2f} {'':>21} {'':>11}", flush=True)
    print(f"grid column: {min(costs):.2f} … {max(costs):.2f} µs per copter-step, ±{100 * spread(costs):.0f} % "
          f"around the geometric mean")


if __name__ == "__main__":
    main()
