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
about half of the cost per copter-step), so the grid column still grows with N. The "local" column shows it: the same
flight with the cross-talk off and the ranging off (the two sensors whose work per copter is one item per copter in
range), next to the mean number of copters in range of each (the cross-talk's: the other copters firing in the same
slot within its 6 m reach; the ranging's: those within its range), counted on the settled swarm.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from benchmarks.plotting import loglog_figure
from benchmarks.workloads import finken_config

AREA_PER_COPTER = 12.0 / 10  # m², the SwarmLab with 10 copters


def config(n: int, grid: bool, wall_check: str = "none"):
    length = math.sqrt(n * AREA_PER_COPTER * 4 / 3)
    cfg = finken_config(n, 1, 0.75 * length, length, {"grid_min_copters": 64 if grid else 2**62})
    return cfg.replace({"behaviour.wall_check": wall_check})


#: the flight without the work that grows with the copters in range (the "local" column)
LOCAL_ONLY = {"sonar.crosstalk": "off", "ranging.enabled": False}


def settled(n: int, grid: bool, wall_check: str = "none", updates=None):
    """(sim, state): the swarm of :func:`config` after a first rollout of 20 steps (compiles, leaves the start)."""
    from finkensim.swarm import SwarmSim

    sim = SwarmSim(config(n, grid, wall_check).replace(updates or {}))
    state, _ = sim.rollout(sim.init(n_envs=1, seed=1), 20, record=False)
    return sim, state


def us_per_copter_step(n: int, grid: bool, steps: int, wall_check: str = "none", updates=None, settled_run=None):
    """Best of 3 steady-state rollouts of ``steps`` steps, µs of thread CPU time per copter-step; ``updates``: config
    keys changed from :func:`config`; ``settled_run``: that flight's (sim, state) from :func:`settled`, if at hand."""
    sim, state = settled_run or settled(n, grid, wall_check, updates)
    best = math.inf
    for _ in range(3):
        t0 = time.thread_time()
        sim.rollout(state, steps, record=False)
        best = min(best, time.thread_time() - t0)
    return best / (steps * n) * 1e6


def copters_in_range(sim, state) -> tuple[float, float]:
    """Mean number of other copters each copter's cross-talk search finds (same firing slot, centres within
    2·(sonar max_range + |offset|)) and its ranging measures (centres within the ranging max_range), environment 0."""
    from scipy.spatial import cKDTree

    from finkensim.sensors.sonar import fire_slots

    cfg = sim.cfg
    pos = np.asarray(state.world.pos[0])
    slot = fire_slots(sim.sonar, cfg.simulation.seed, np.zeros(1, dtype=np.int64), 0, len(pos))[0]
    reach = 2.0 * (cfg.sonar.max_range + abs(cfg.sonar.offset))
    tree = cKDTree(pos)
    same_slot = [sum(slot[m] == slot[n] for m in near) - 1 for n, near in enumerate(tree.query_ball_point(pos, reach))]
    in_range = tree.query_ball_point(pos, cfg.ranging.max_range, return_length=True) - 1
    return float(np.mean(same_slot)), float(np.mean(in_range))


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
    """Yield {N, grid_us, brute_us (None above ``brute_max``), local_us, crosstalk_peers, ranging_peers} for each N of
    ``sizes``, as each is measured: local_us is the grid flight with :data:`LOCAL_ONLY`, the peers are
    :func:`copters_in_range`. Each timed rollout runs max(5, step_budget // N) steps."""
    for n in sizes:
        steps = max(5, step_budget // n)
        grid_run = settled(n, True, wall_check)  # timed, and counted for the copters in range
        crosstalk_peers, ranging_peers = copters_in_range(*grid_run)
        g = us_per_copter_step(n, True, steps, wall_check, settled_run=grid_run)
        b = us_per_copter_step(n, False, steps, wall_check) if n <= brute_max else None
        local = us_per_copter_step(n, True, steps, wall_check, LOCAL_ONLY)
        yield dict(N=n, grid_us=g, brute_us=b, local_us=local, crosstalk_peers=crosstalk_peers,
                   ranging_peers=ranging_peers)


def run(log=print, sizes=BENCH_SIZES, brute_max=BENCH_BRUTE_MAX, out_dir=None) -> dict:
    """Rows {N, grid_us, brute_us or None}, the grid column's spread and a markdown table (for ``make bench``);
    with ``out_dir`` also the figure ``engine_scaling.png`` there (:func:`figure`)."""
    rows = []
    for r in measure(sizes, brute_max):
        rows.append(r)
        g, b = r["grid_us"], r["brute_us"]
        log(f"(d) engine scaling N={r['N']:6d}  grid {g:7.2f} µs/copter-step" + (f"  brute {b:7.2f}" if b else "")
            + f"  local {r['local_us']:7.2f}")
    sp = spread([r["grid_us"] for r in rows])
    sp_local = spread([r["local_us"] for r in rows])
    L = ["## (d) The full FINken workload in the engine against N, lab density (benchmarks/engine_scaling.py)", "",
         "One environment, one thread; the arena grows with N (10 copters per 3 m × 4 m); the cell grid on from "
         "`simulation.grid_min_copters`. Local: the grid flight with the cross-talk and the ranging off; the copters "
         "in range of those two sensors (mean per copter) are what the rest of the cost grows with.", "",
         "| N | grid µs/copter-step | brute force µs/copter-step | brute/grid | local µs/copter-step "
         "| copters in cross-talk reach (same slot) | copters in ranging range |", "|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        b, g = r["brute_us"], r["grid_us"]
        brute, ratio = (f"{b:.2f}", f"{b / g:.1f}") if b else ("—", "—")
        L.append(f"| {r['N']:,} | {g:.2f} | {brute} | {ratio} | {r['local_us']:.2f} | {r['crosstalk_peers']:.1f} "
                 f"| {r['ranging_peers']:.1f} |")
    L += ["", f"Grid column spread: ±{100 * sp:.0f} % around its geometric mean (target ±30 %); local column "
          f"±{100 * sp_local:.0f} %."]
    if out_dir is not None and figure(rows, Path(out_dir) / "engine_scaling.png"):
        L += ["", "![full workload against N](engine_scaling.png)"]
    return dict(rows=rows, spread=sp, local_spread=sp_local, markdown="\n".join(L))


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
    print(f"{'N':>6} {'grid µs/copter-step':>20} {'brute µs/copter-step':>21} {'brute/grid':>11} {'local':>7} "
          f"{'cross-talk peers':>17} {'ranging peers':>14}")
    costs, local = [], []
    for r in measure(sizes, args.brute_max, 2_000 if args.quick else 20_000, args.wall_check):
        n, g, b = r["N"], r["grid_us"], r["brute_us"]
        costs.append(g)
        local.append(r["local_us"])
        brute = f"{b:>21.2f} {b / g:>11.2f}" if b is not None else f"{'':>21} {'':>11}"
        print(f"{n:>6} {g:>20.2f} {brute} {r['local_us']:>7.2f} {r['crosstalk_peers']:>17.1f} "
              f"{r['ranging_peers']:>14.1f}", flush=True)
    print(f"grid column: {min(costs):.2f} … {max(costs):.2f} µs per copter-step, ±{100 * spread(costs):.0f} % "
          f"around the geometric mean; local column ±{100 * spread(local):.0f} %")


if __name__ == "__main__":
    main()
