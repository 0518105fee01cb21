"""Bounded random walk: a random heading at cruise speed, redrawn every ``redraw_steps`` steps,
steered back inward near the walls. Deterministic in (seed, env, redraw epoch, copter).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..config import BehaviourConfig
from ..kernels.rng import STREAM_COMMAND, counter_key, uniform


class RandomWalkParams(NamedTuple):
    speed: float  # m/s
    redraw_steps: int
    wall_margin: float  # m
    max_yaw_rate: float  # rad/s
    width: float  # m
    length: float  # m

    @classmethod
    def from_config(cls, behaviour: BehaviourConfig, width: float, length: float) -> "RandomWalkParams":
        return cls(behaviour.speed, behaviour.redraw_steps, behaviour.wall_margin,
                   np.deg2rad(behaviour.yaw_rate_deg), width, length)


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def random_walk_env(pos, seed, env_id, step, random_walk, cmd_v, cmd_w):
    """Commands for one environment. pos (N, 2) m → writes cmd_v (N, 2) m/s and cmd_w (N,) rad/s."""
    epoch = step // random_walk.redraw_steps
    for n in range(pos.shape[0]):
        key = counter_key(seed, env_id, epoch, n, STREAM_COMMAND)
        heading = 2.0 * np.pi * uniform(key, 0)
        vx = random_walk.speed * np.cos(heading)
        vy = random_walk.speed * np.sin(heading)
        # bounded: near a wall, the component toward it is reversed
        if pos[n, 0] < random_walk.wall_margin and vx < 0.0:
            vx = -vx
        elif pos[n, 0] > random_walk.width - random_walk.wall_margin and vx > 0.0:
            vx = -vx
        if pos[n, 1] < random_walk.wall_margin and vy < 0.0:
            vy = -vy
        elif pos[n, 1] > random_walk.length - random_walk.wall_margin and vy > 0.0:
            vy = -vy
        cmd_v[n, 0] = vx
        cmd_v[n, 1] = vy
        cmd_w[n] = random_walk.max_yaw_rate * (2.0 * uniform(key, 1) - 1.0)
