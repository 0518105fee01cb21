"""Reinforcement-learning environments over the batched simulator (needs the ``[rl]`` extra).

Importing this package registers the Gymnasium id ``finkensim/Swarm-v0``:

    import gymnasium, finkensim.envs
    env = gymnasium.make("finkensim/Swarm-v0", task="coverage")                # one swarm
    envs = gymnasium.make_vec("finkensim/Swarm-v0", num_envs=1024)             # B swarms, one compiled call
    pz = finkensim.envs.parallel_env(scenario="my.toml")                       # PettingZoo, one agent per copter

Keyword arguments (all entry points): ``scenario`` (TOML path/text, dict or Config; default the default
scenario), ``task`` (``"cohesion"``, ``"coverage"``, ``"wall_avoidance"`` or a task object, see
:mod:`finkensim.envs.tasks`), ``task_kwargs``, ``max_steps`` (default: the scenario's duration / dt),
``pose`` (add the privileged own pose to the observation), ``render_mode`` (None or ``"rgb_array"``).
"""
from __future__ import annotations

try:
    import gymnasium
except ImportError as e:  # pragma: no cover - depends on the installed extras
    raise ImportError("finkensim.envs needs gymnasium and pettingzoo: pip install 'finkensim[rl]'") from e

from .core import SwarmCore
from .gym_env import SwarmEnv, SwarmVectorEnv
from .tasks import TASKS, TaskContext, make_task, register_task

ENV_ID = "finkensim/Swarm-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="finkensim.envs.gym_env:SwarmEnv",
                       vector_entry_point="finkensim.envs.gym_env:SwarmVectorEnv")


def parallel_env(**kwargs):
    """A PettingZoo :class:`~finkensim.envs.pz_env.SwarmParallelEnv` (keyword arguments in the module doc)."""
    from .pz_env import parallel_env as make

    return make(**kwargs)


__all__ = ["ENV_ID", "SwarmCore", "SwarmEnv", "SwarmVectorEnv", "parallel_env", "TASKS", "TaskContext", "make_task",
           "register_task"]
