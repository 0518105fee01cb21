"""PettingZoo environment over the batched simulator: one agent per copter.

    import finkensim.envs
    env = finkensim.envs.parallel_env(scenario={"copters": {"n": 10}}, task="cohesion")
    obs, infos = env.reset(seed=0)                 # {"copter_0": (D,) float32, ...}
    obs, rewards, terms, truncs, infos = env.step({a: env.action_space(a).sample() for a in env.agents})

Agent ``copter_i`` observes its own sensors (the (D,) row i of :mod:`finkensim.envs.core`'s layout) and
commands its body-frame velocity (2,) m/s; every agent receives the team reward of the task. All agents
are truncated together after ``max_steps``. Each step is one compiled call for the whole swarm (no Python
per copter beyond building the action array). Seeding as :class:`~finkensim.envs.gym_env.SwarmEnv`: the
same seed gives the same flight as ``gymnasium.make("finkensim/Swarm-v0")``.
"""
from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from pettingzoo import ParallelEnv

from .core import SwarmCore
from .gym_env import METADATA

__all__ = ["SwarmParallelEnv", "parallel_env"]


class SwarmParallelEnv(ParallelEnv):
    """One swarm as a PettingZoo ParallelEnv. Keyword arguments: those of
    :class:`~finkensim.envs.core.SwarmCore` (``scenario``, ``task``, ``task_kwargs``, ``max_steps``, ``pose``)
    and ``render_mode`` (None or ``"rgb_array"``)."""

    metadata = {**METADATA, "name": "finkensim_swarm_v0", "is_parallelizable": True}

    def __init__(self, render_mode: str | None = None, **kwargs: Any):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode = {render_mode!r}: expected None or 'rgb_array'")
        self.render_mode = render_mode
        self.core = SwarmCore(n_envs=1, **kwargs)
        self.possible_agents = [f"copter_{i}" for i in range(self.core.n_copters)]
        self.agents: list[str] = []
        self._obs_space = gym.spaces.Box(-np.inf, np.inf, shape=(self.core.obs_dim,), dtype=np.float32)
        v = self.core.max_speed
        self._act_space = gym.spaces.Box(-v, v, shape=(2,), dtype=np.float32)
        self._rng = None

    def observation_space(self, agent):
        return self._obs_space

    def action_space(self, agent):
        return self._act_space

    def _split(self, obs: np.ndarray) -> dict:
        return {a: obs[0, i] for i, a in enumerate(self.possible_agents)}

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        self.core.set_seeds(seed, self._rng)
        self.agents = list(self.possible_agents)
        obs = self.core.reset()
        return self._split(obs), {a: {} for a in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() after the episode ended: call reset() first")
        a = np.zeros((1, self.core.n_copters, 2))
        for i, agent in enumerate(self.possible_agents):
            if agent in actions and actions[agent] is not None:
                a[0, i] = actions[agent]
        obs, reward, truncated = self.core.step(a)
        agents = self.agents
        out = ({ag: o for ag, o in self._split(obs).items() if ag in agents},
               {ag: float(reward[0]) for ag in agents}, {ag: False for ag in agents},
               {ag: bool(truncated) for ag in agents}, {ag: {} for ag in agents})
        if truncated:
            self.agents = []
        return out

    def render(self):
        return self.core.render(0) if self.render_mode == "rgb_array" else None

    def state(self) -> np.ndarray:
        """The global state: every copter's pose (N, 3) x m, y m, yaw rad, flattened (float32)."""
        if self.core.state is None:
            raise RuntimeError("state() before reset(): reset the environment first")
        return self.core.state.world.pose[0].ravel().astype(np.float32)


def parallel_env(**kwargs: Any) -> SwarmParallelEnv:
    """A :class:`SwarmParallelEnv` (PettingZoo's ``parallel_env`` convention)."""
    return SwarmParallelEnv(**kwargs)
