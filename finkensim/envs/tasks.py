"""Reward tasks of the swarm environments: small pluggable functions of the batched state, built on
:mod:`finkensim.metrics`.

A task is an object with the :class:`Task` contract: ``reset(ctx, pos)`` (called at every reset, all B environments
at once) and ``reward(ctx, world) -> (B,) float64`` (called after every step with the new
:class:`~finkensim.world.WorldState`); it must be deterministic and pickle
(:func:`finkensim.plugin_checkers.check_task` checks one). ``ctx`` is a :class:`TaskContext` (arena size, copter radius, dt).
The reward is a team reward: every copter of an environment shares it (the PettingZoo env gives it
to each agent). Register your own with :func:`register_task`::

    class Centre:
        def reset(self, ctx, pos): pass
        def reward(self, ctx, world):
            c = np.array(ctx.arena) / 2
            return -np.linalg.norm(world.pos - c, axis=-1).mean(axis=-1)
    register_task("centre", Centre)
    env = gymnasium.make("finkensim/Swarm-v0", task="centre")
"""
from __future__ import annotations

from typing import Callable, NamedTuple, Protocol, runtime_checkable

import numpy as np

from ..config import ConfigError
from ..usertext import suggest
from ..metrics import COVERAGE_CELL, WALL_DISTANCE, cohesion, coverage_cells, wall_sticking

__all__ = ["Task", "TaskContext", "Cohesion", "Coverage", "WallAvoidance", "TASKS", "register_task", "make_task"]


class TaskContext(NamedTuple):
    """What a task may need besides the state: arena (width, length) m, copter radius m, dt s, copters n."""

    arena: tuple[float, float]
    radius: float
    dt: float
    n_copters: int


@runtime_checkable
class Task(Protocol):
    """The contract of a reward task (module doc). Observations are the copters' enabled sensors
    (:func:`~finkensim.envs.core.obs_layout`) and an episode ends by truncation at ``max_steps``, so a task defines
    the reward only."""

    def reset(self, ctx: TaskContext, pos) -> None:
        """Start an episode of every environment: pos (B, N, 2) m the copters' start positions."""

    def reward(self, ctx: TaskContext, world) -> np.ndarray:
        """The team reward (B,) float64 of the step that ended in ``world`` (a
        :class:`~finkensim.world.WorldState`)."""


class Cohesion:
    """Flocking without wall contact: reward = −cohesion (m, mean distance from the swarm centroid, as
    :func:`finkensim.metrics.cohesion`) − ``wall_weight`` · fraction of copters whose body is within
    ``wall_distance`` m of a wall (:func:`finkensim.metrics.wall_sticking`), per step."""

    def __init__(self, wall_weight: float = 1.0, wall_distance: float = WALL_DISTANCE):
        self.wall_weight = float(wall_weight)
        self.wall_distance = float(wall_distance)

    def reset(self, ctx: TaskContext, pos) -> None:
        pass

    def reward(self, ctx: TaskContext, world) -> np.ndarray:
        pose = world.pos[None]
        return -cohesion(pose) - self.wall_weight * wall_sticking(pose, ctx.arena, ctx.radius, self.wall_distance)


class Coverage:
    """Area coverage: reward = the fraction of the ``cell`` m grid (as :func:`finkensim.metrics.coverage`)
    first visited at this step, so an episode's return is its coverage minus the start cells'."""

    def __init__(self, cell: float = COVERAGE_CELL):
        self.cell = float(cell)
        self.visited = None

    def _mark(self, ctx: TaskContext, pos) -> np.ndarray:
        cells, n_cells = coverage_cells(pos, ctx.arena, self.cell)
        before = self.visited.sum(axis=1)
        rows = np.broadcast_to(np.arange(pos.shape[0])[:, None], cells.shape)
        self.visited[rows.ravel(), cells.ravel()] = True
        return (self.visited.sum(axis=1) - before) / n_cells

    def reset(self, ctx: TaskContext, pos) -> None:
        _, n_cells = coverage_cells(np.zeros((1, 2)), ctx.arena, self.cell)
        self.visited = np.zeros((pos.shape[0], n_cells), dtype=bool)
        self._mark(ctx, pos)

    def reward(self, ctx: TaskContext, world) -> np.ndarray:
        return self._mark(ctx, world.pos)


class WallAvoidance:
    """Wall avoidance: reward = −fraction of copters within ``wall_distance`` m of a wall
    (:func:`finkensim.metrics.wall_sticking`) − ``contact_weight`` · fraction of copters touching a wall now
    (the copter model's contact flag)."""

    def __init__(self, contact_weight: float = 1.0, wall_distance: float = WALL_DISTANCE):
        self.contact_weight = float(contact_weight)
        self.wall_distance = float(wall_distance)

    def reset(self, ctx: TaskContext, pos) -> None:
        pass

    def reward(self, ctx: TaskContext, world) -> np.ndarray:
        near = wall_sticking(world.pos[None], ctx.arena, ctx.radius, self.wall_distance)
        return -near - self.contact_weight * world.in_wall.mean(axis=-1)


#: Task name → factory (keyword arguments → task object).
TASKS: dict[str, Callable] = {"cohesion": Cohesion, "coverage": Coverage, "wall_avoidance": WallAvoidance}


def register_task(name: str, factory: Callable) -> None:
    """Make ``factory(**task_kwargs)`` available as ``task=name`` in the environments."""
    if not isinstance(name, str) or not name:
        raise ConfigError(f"task name {name!r}: expected a non-empty string")
    TASKS[name] = factory


def make_task(task, task_kwargs: dict | None = None):
    """A task object from a registered name (with ``task_kwargs``) or an object with ``reset`` and ``reward``."""
    if isinstance(task, str):
        if task not in TASKS:
            raise ConfigError(f"task = {task!r}{suggest(task, TASKS)}: expected one of {', '.join(map(repr, TASKS))} or an object "
                              "with reset(ctx, pos) and reward(ctx, world)")
        try:
            return TASKS[task](**(task_kwargs or {}))
        except TypeError as e:
            raise ConfigError(f"task_kwargs = {task_kwargs!r} for task {task!r}: {e}") from None
    if not (hasattr(task, "reset") and hasattr(task, "reward")):
        raise ConfigError(f"task = {task!r}: expected a name from {', '.join(map(repr, TASKS))} or an object with "
                          "reset(ctx, pos) and reward(ctx, world)")
    if task_kwargs:
        raise ConfigError("task_kwargs is only used with a task name")
    return task
