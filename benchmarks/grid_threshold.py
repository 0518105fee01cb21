"""Where the engine's cell grid starts to pay: World.step per copter-step with the grid off and on.

``python -m benchmarks.grid_threshold [--quick]``. One environment (one thread), copters at the lab's density
(the 3 m × 4 m arena holds 10; the arena grows with N, aspect 3 : 4), the compiled world step
(move, contacts, plate distances, hinges; copters flying straight, reflected by the walls), where the columns differ by the contact search (brute force O(N²) against
the grid's O(N)); then the virtual ranging alone (N × N readings: the grid draws only the pairs within range, the
rest read max_range without a random number). ``simulation.grid_min_copters`` is set from where the ratios cross 1.
Both variants give identical results (checked).
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np
from numba import njit

from benchmarks.breakdown import t_world
from finkensim.config import Config
from finkensim.kernels.cellgrid import engine_grid, env_grid, grid_params
from finkensim.sensors.ranging import RangingModel
from finkensim.sensors.ranging_kernels import ranging_grid_env
from finkensim.world import World

AREA_PER_COPTER = 12.0 / 10  # m², the SwarmLab with 10 copters


def world_step_us(n: int, grid: bool, steps: int) -> tuple[float, np.ndarray]:
    """µs per copter-step of the compiled world step (``benchmarks.breakdown.t_world``: every copter flies at
    0.2 m/s along its heading; thread CPU time, best of 3) and the final positions."""
    length = math.sqrt(n * AREA_PER_COPTER * 4 / 3)
    cfg = Config().replace({"copters.n": n, "arena.width": 0.75 * length, "arena.length": length,
                            "simulation.grid_min_copters": 0 if grid else 2**62})
    world = World(cfg)
    g = engine_grid(world.grid, 1, n)
    best = math.inf
    for _ in range(3):
        state = world.init(n_envs=1, seed=1)
        args = (state.arrays(), world.copter_params, world.hinge_params, world.geometry, world.dt, g)
        t_world(*args, 1)  # compile outside the timing
        t0 = time.thread_time()
        t_world(*args, steps)
        best = min(best, time.thread_time() - t0)
    return best / (steps * n) * 1e6, state.pos


@njit(cache=True)
def _ranging_loop(pos, beacons, p, g, out, reps):
    for r in range(reps):
        ranging_grid_env(pos, np.zeros(pos.shape[0]), beacons, (np.int64(1), np.int64(0), np.int64(r)), p, out, g,
                         env_grid(g, 0))


def ranging_us(n: int, grid: bool, reps: int) -> tuple[float, np.ndarray]:
    """µs per copter-step of the virtual ranging (mixture error, N × N readings), best of 3, and the readings."""
    length = math.sqrt(n * AREA_PER_COPTER * 4 / 3)
    rng = np.random.default_rng(0)
    pos = rng.uniform([0.0, 0.0], [0.75 * length, length], size=(n, 2))
    gp = grid_params(n, 0.75 * length, length, 0.2, min_copters=0 if grid else 2**62)
    g = engine_grid(gp, 1, n)
    p = RangingModel("mixture").params
    out = np.empty((n, n))
    beacons = np.zeros((0, 2))
    _ranging_loop(pos, beacons, p, g, out, 1)
    best = math.inf
    for _ in range(3):
        t0 = time.thread_time()
        _ranging_loop(pos, beacons, p, g, out, reps)
        best = min(best, time.thread_time() - t0)
    return best / (reps * n) * 1e6, out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer sizes and steps")
    args = ap.parse_args(argv)
    sizes = [16, 64, 256] if args.quick else [16, 32, 64, 128, 256, 512, 1024, 2048]
    steps = 50 if args.quick else 400
    print(f"{'N':>6} {'brute µs/copter-step':>22} {'grid µs/copter-step':>21} {'brute/grid':>11}")
    for n in sizes:
        brute, pb = world_step_us(n, False, steps)
        grid, pg = world_step_us(n, True, steps)
        assert np.array_equal(pb, pg), "grid and brute force disagree"
        print(f"{n:>6} {brute:>22.3f} {grid:>21.3f} {brute / grid:>11.2f}")
    print("\nvirtual ranging (mixture), µs per copter-step")
    print(f"{'N':>6} {'brute':>10} {'grid':>10} {'brute/grid':>11}")
    for n in sizes:
        reps = max(1, 20_000 // n) if args.quick else max(2, 200_000 // n)
        brute, ob = ranging_us(n, False, reps)
        grid, og = ranging_us(n, True, reps)
        assert np.array_equal(ob, og), "grid and brute force disagree"
        print(f"{n:>6} {brute:>10.3f} {grid:>10.3f} {brute / grid:>11.2f}")


if __name__ == "__main__":
    main()
