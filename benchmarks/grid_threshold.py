"""Where the engine's cell grid starts to pay: World.step per copter-step with the grid off and on.

``python -m benchmarks.grid_threshold [--quick]``. One environment (one thread), copters at the lab's density
(the 3 m × 4 m arena holds 10; the arena grows with N, aspect 3 : 4), random-walk commands, the full world step
(move, contacts, plate distances, hinges). The grid so far serves the copter contacts, so the columns differ by
the contact search (brute force O(N²) against the grid's O(N)); ``simulation.grid_min_copters`` is set from where
the ratio crosses 1. Both runs give identical states (checked).
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

from finkensim.config import Config
from finkensim.world import World

AREA_PER_COPTER = 12.0 / 10  # m², the SwarmLab with 10 copters


def world_step_us(n: int, grid: bool, steps: int) -> tuple[float, np.ndarray]:
    """µs per copter-step of World.step_inplace (thread CPU time, best of 3) and the final positions."""
    length = math.sqrt(n * AREA_PER_COPTER * 4 / 3)
    cfg = Config().replace({"copters.n": n, "arena.width": 0.75 * length, "arena.length": length,
                            "simulation.grid_min_copters": 0 if grid else 2**62})
    world = World(cfg)
    rng = np.random.default_rng(0)
    cmds = rng.normal(0.0, 0.3, size=(steps, 1, n, 2))
    best = math.inf
    for _ in range(3):
        state = world.init(n_envs=1, seed=1)
        world.step_inplace(state, cmds[0])  # compile outside the timing
        t0 = time.thread_time()
        for k in range(steps):
            world.step_inplace(state, cmds[k])
        best = min(best, time.thread_time() - t0)
    return best / (steps * n) * 1e6, state.pos


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer sizes and steps")
    args = ap.parse_args(argv)
    sizes = [16, 64, 256] if args.quick else [16, 32, 64, 128, 256, 512, 1024, 2048]
    steps = 20 if args.quick else 100
    print(f"{'N':>6} {'brute µs/copter-step':>22} {'grid µs/copter-step':>21} {'brute/grid':>11}")
    for n in sizes:
        brute, pb = world_step_us(n, False, steps)
        grid, pg = world_step_us(n, True, steps)
        assert np.array_equal(pb, pg), "grid and brute force disagree"
        print(f"{n:>6} {brute:>22.3f} {grid:>21.3f} {brute / grid:>11.2f}")


if __name__ == "__main__":
    main()
