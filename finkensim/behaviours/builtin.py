"""The built-in behaviours, registered through :func:`~.registry.register_behaviour` exactly as a user's are:
``hover``, ``random_walk`` (:mod:`.random_walk`) and ``attraction_repulsion`` (:mod:`.attraction`).

Their ``commands`` kernels call the per-environment kernels of their modules (``inline="always"``, so each is
compiled once into its ``commands``) with the numpy error model of the engine's kernels (:mod:`finkensim.kernels.outline`).
"""
from __future__ import annotations

from numba import njit

from .attraction import AttractionParams, attraction_env
from .random_walk import RandomWalkParams, random_walk_env
from .registry import Behaviour, register_behaviour

__all__ = ["hover_commands", "random_walk_commands", "attraction_commands", "HOVER", "RANDOM_WALK", "ATTRACTION"]


@njit(cache=True, error_model="numpy")
def hover_commands(inputs, params, memory, cmd_v, cmd_w):
    """Zero commands: cmd_v (N, 2) m/s and cmd_w (N,) rad/s set to 0 (the copters hold still)."""
    for n in range(cmd_v.shape[0]):
        cmd_v[n, 0] = 0.0
        cmd_v[n, 1] = 0.0
        cmd_w[n] = 0.0


@njit(cache=True, error_model="numpy")
def random_walk_commands(inputs, params, memory, cmd_v, cmd_w):
    """The bounded random walk (:func:`~.random_walk.random_walk_env`) from the true positions, world frame."""
    random_walk_env(inputs.pos, inputs.seed, inputs.env_id, inputs.step, params, cmd_v, cmd_w)


@njit(cache=True, error_model="numpy")
def attraction_commands(inputs, params, memory, cmd_v, cmd_w):
    """Attraction–repulsion on the sonar readings and wall flags (:func:`~.attraction.attraction_env`), body frame."""
    attraction_env(inputs.sonar, inputs.wall, inputs.seed, inputs.env_id, inputs.step, params, cmd_v, cmd_w)


def _random_walk_params(cfg) -> RandomWalkParams:
    return RandomWalkParams.from_config(cfg.behaviour, cfg.arena.width, cfg.arena.length)


HOVER = register_behaviour(Behaviour("hover", hover_commands, frame="world", cached=True,
                                     doc="zero commands: the copters hold still"))
RANDOM_WALK = register_behaviour(Behaviour("random_walk", random_walk_commands, _random_walk_params, frame="world",
                                           cached=True, doc="open-loop bounded random walk (behaviour.speed, "
                                                            "redraw_steps, wall_margin, yaw_rate_deg)"))
ATTRACTION = register_behaviour(Behaviour("attraction_repulsion", attraction_commands, AttractionParams.from_config,
                                          frame="body", sensors=("sonar",), cached=True,
                                          doc="the FINken attraction-repulsion controller on the four sonars"))
