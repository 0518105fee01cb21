"""Gymnasium environments over the batched simulator: :class:`SwarmEnv` (one swarm) and
:class:`SwarmVectorEnv` (B swarms in one compiled call per step, a native
:class:`gymnasium.vector.VectorEnv`). Both are ``finkensim/Swarm-v0``:

    import gymnasium, finkensim.envs
    env = gymnasium.make("finkensim/Swarm-v0", scenario={"copters": {"n": 10}}, task="coverage")
    envs = gymnasium.make_vec("finkensim/Swarm-v0", num_envs=1024)     # batched natively

The whole swarm is the agent: observation (N, D) float32, action (N, 2) body-frame velocities m/s (see
:mod:`finkensim.envs.core` for the layout), one team reward per step. Episodes end by truncation after
``max_steps``; the vector env autoresets on the next step (``AutoresetMode.NEXT_STEP``).
"""
from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .core import SwarmCore

__all__ = ["SwarmEnv", "SwarmVectorEnv", "METADATA"]

METADATA = {"render_modes": ["rgb_array"], "render_fps": 20}


def _spaces(core: SwarmCore) -> tuple[gym.spaces.Box, gym.spaces.Box]:
    obs = gym.spaces.Box(-np.inf, np.inf, shape=(core.n_copters, core.obs_dim), dtype=np.float32)
    act = gym.spaces.Box(-core.max_speed, core.max_speed, shape=(core.n_copters, 2), dtype=np.float32)
    return obs, act


def _check_render_mode(render_mode):
    if render_mode not in (None, "rgb_array"):
        raise ValueError(f"render_mode = {render_mode!r}: expected None or 'rgb_array'")
    return render_mode


class SwarmEnv(gym.Env):
    """One swarm as a Gymnasium env. Keyword arguments: those of :class:`~finkensim.envs.core.SwarmCore`
    (``scenario``, ``task``, ``task_kwargs``, ``max_steps``, ``pose``) and ``render_mode`` (None or
    ``"rgb_array"``)."""

    metadata = METADATA

    def __init__(self, render_mode: str | None = None, **kwargs: Any):
        self.render_mode = _check_render_mode(render_mode)
        self.core = SwarmCore(n_envs=1, **kwargs)
        self.observation_space, self.action_space = _spaces(self.core)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.core.set_seeds(seed, self.np_random)
        return self.core.reset()[0], {}

    def step(self, action):
        obs, reward, truncated = self.core.step(np.asarray(action)[None])
        return obs[0], float(reward[0]), False, bool(truncated), {}

    def render(self):
        return self.core.render(0) if self.render_mode == "rgb_array" else None


class SwarmVectorEnv(VectorEnv):
    """B swarms as one Gymnasium vector env, stepped by one compiled call. Keyword arguments: ``num_envs`` (B)
    and those of :class:`SwarmEnv`. ``reset(seed=s)`` seeds sub-env i with s + i; ``render()`` returns a
    tuple of one frame per sub-env (mind B)."""

    metadata = {**METADATA, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, render_mode: str | None = None, **kwargs: Any):
        self.render_mode = _check_render_mode(render_mode)
        self.core = SwarmCore(n_envs=num_envs, **kwargs)
        self.num_envs = self.core.n_envs
        self.single_observation_space, self.single_action_space = _spaces(self.core)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._autoreset = False

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) or seed is None else None)
        self.core.set_seeds(seed, self.np_random)
        self._autoreset = False
        return self.core.reset(), {}

    def step(self, actions):
        B = self.num_envs
        if self._autoreset:
            self.core.set_seeds(None, self.np_random)
            self._autoreset = False
            return self.core.reset(), np.zeros(B), np.zeros(B, dtype=bool), np.zeros(B, dtype=bool), {}
        obs, reward, truncated = self.core.step(actions)
        self._autoreset = truncated
        return obs, reward, np.zeros(B, dtype=bool), np.full(B, truncated), {}

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        return tuple(self.core.render(b) for b in range(self.num_envs))
