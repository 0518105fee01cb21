"""Why wall_response.png leaves the amplitude law: the numbers behind its notes (docs/reliability.md).

    python examples/wall_response_explained.py [scenario.toml]

Flies the scenario (default: the built-in one, as `finkensim run`) and prints, over every plate and sample:
the samples above the law's peak (hinge controller overshoot) and how long their plate's motor had been on;
and the samples at 0.15-0.2 m from a copter body, how many lie in the first seconds (plates start at rest) and
how many below the contact limit asin(d / lever).
"""
from __future__ import annotations

import sys

import numpy as np

from finkensim.analysis import plate_distances, trajectory_arrays
from finkensim.arena import target_angles
from finkensim.scenario import simulate_flight
from finkensim.viz.walls import START_TRANSIENT_S


def main(path=None) -> None:
    log, traj, world = simulate_flight(path)
    hp, dt = world.arena.hinge, world.cfg.simulation.dt
    t, pose, theta = trajectory_arrays(traj, 0)
    d = plate_distances(world.arena, pose, world.cfg.copters.radius)
    th = np.rad2deg(theta)
    d, th = d.reshape(len(t), -1), th.reshape(len(t), -1)
    peak = float(np.rad2deg(target_angles(np.linspace(0.0, hp.threshold, 400), hp.threshold, hp.max_amplitude)).max())
    on = d < hp.threshold
    over = np.argwhere(th > peak + 1.0)
    since = []
    for k, s in over:
        j = k
        while j > 0 and on[j - 1, s]:
            j -= 1
        since.append((k - j) * dt)
    print(f"law peak {peak:.1f} deg; {len(over)} of {int(on.sum())} motor-on samples above it + 1 deg, largest "
          f"{th.max():.1f} deg; motor on for {np.quantile(since, [0.1, 0.5, 0.9]).round(1).tolist() if since else []} s "
          "(10/50/90 %) when it overshoots")
    near = (d > 0.15) & (d < 0.2)
    early = near & (np.asarray(t)[:, None] - t[0] < START_TRANSIENT_S)
    cap = np.rad2deg(np.arcsin(np.clip(d / world.arena.lever, 0.0, 1.0)))
    print(f"d in 0.15-0.2 m: {int(near.sum())} samples, {int(early.sum())} in the first {START_TRANSIENT_S:g} s "
          f"(median angle {np.median(th[early]) if early.any() else float('nan'):.1f} deg there, "
          f"{np.median(th[near & ~early]) if (near & ~early).any() else float('nan'):.1f} deg later); "
          f"{int((near & (th < cap - 3.0)).sum())} lie more than 3 deg below the contact limit")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
