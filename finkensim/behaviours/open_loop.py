"""Open-loop controllers (no sensors) as callables for :meth:`World.rollout <finkensim.world.World.rollout>`.

    from finkensim.behaviours.open_loop import RandomWalk, hover
    final, traj = world.rollout(state, 1200, RandomWalk(world.cfg))

A controller is ``f(world, state) -> (cmd_vel (B, N, 2) m/s world frame, cmd_yaw_rate (B, N) rad/s)``,
called once per step. :class:`RandomWalk` runs the compiled bounded random walk
(:func:`~finkensim.behaviours.random_walk.random_walk_env`) over the batch, so a World rollout with it
flies exactly as ``SwarmSim(cfg, behaviour="random_walk")`` (which compiles the whole loop into one kernel).
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from numba import njit, prange

from ..config import Config, ConfigError, load_config
from .random_walk import RandomWalkParams, random_walk_env

__all__ = ["OPEN_LOOP_BEHAVIOURS", "RandomWalk", "hover", "open_loop_controller", "random_walk_batch"]

#: ``behaviour.kind`` values that read no sensor.
OPEN_LOOP_BEHAVIOURS = ("random_walk", "hover")


@njit(cache=True, parallel=True)
def random_walk_batch(pos, seed, env_ids, step, random_walk, cmd_v, cmd_w):
    """Random-walk commands of B environments at world step ``step``: pos (B, N, 2) m, env_ids (B,) int64,
    random_walk :class:`RandomWalkParams` → writes cmd_v (B, N, 2) m/s and cmd_w (B, N) rad/s."""
    for b in prange(pos.shape[0]):
        random_walk_env(pos[b], seed, env_ids[b], step, random_walk, cmd_v[b], cmd_w[b])


class RandomWalk:
    """The bounded random walk (``behaviour.kind = "random_walk"``) as a World rollout controller.

    Args: cfg — a :class:`~finkensim.config.Config` (or anything :func:`load_config` takes) whose
    ``behaviour`` and ``arena`` keys set the walk. Attribute ``params``: :class:`RandomWalkParams`.
    """

    def __init__(self, cfg: Config | str | dict | None = None):
        c = cfg if isinstance(cfg, Config) else load_config(cfg)
        self.params = RandomWalkParams.from_config(c.behaviour, c.arena.width, c.arena.length)

    def __call__(self, world, state) -> tuple[np.ndarray, np.ndarray]:
        B, N = state.n_envs, state.n_copters
        cmd_v = np.zeros((B, N, 2))
        cmd_w = np.zeros((B, N))
        random_walk_batch(np.ascontiguousarray(state.pos), int(state.seed), state.env_ids, int(state.step),
                          self.params, cmd_v, cmd_w)
        return cmd_v, cmd_w


def hover(world, state) -> tuple[np.ndarray, np.ndarray]:
    """Zero commands (B, N, 2) m/s and (B, N) rad/s: the copters hold still."""
    return np.zeros((state.n_envs, state.n_copters, 2)), np.zeros((state.n_envs, state.n_copters))


def open_loop_controller(cfg: Config) -> Callable:
    """The World rollout controller of ``cfg.behaviour.kind`` (``"random_walk"`` or ``"hover"``);
    :class:`ConfigError` for a behaviour that reads sensors (run those in :class:`finkensim.swarm.SwarmSim`)."""
    kind = cfg.behaviour.kind
    if kind == "random_walk":
        return RandomWalk(cfg)
    if kind == "hover":
        return hover
    raise ConfigError(f"behaviour.kind = {kind!r}: World.rollout runs only the open-loop behaviours "
                      f"{', '.join(map(repr, OPEN_LOOP_BEHAVIOURS))}; closed-loop ones run in finkensim.swarm.SwarmSim")
