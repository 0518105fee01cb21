"""One Monte-Carlo episode: config + seed → rollout → metrics. The unit of work of a sweep.

    from finkensim.episode import run_episode
    run_episode(cfg, seed=7)   # {"cohesion": 1.02, "nearest_neighbour": 0.81, ...}

An episode places ``copters.n`` copters at random (keyed by ``seed`` and ``env_id``), flies them
for round(simulation.duration / simulation.dt) steps with ``behaviour.kind`` and returns the
metrics of :mod:`finkensim.metrics` as plain floats. The open-loop behaviours (``random_walk``,
``hover``) run in :meth:`World.rollout <finkensim.world.World.rollout>`; behaviours that read
sensors (``attraction_repulsion``) run in the closed-loop compiled rollout of
:class:`finkensim.swarm.SwarmSim` (sonar, ranging, IMU, wall check) when that module is installed. :func:`check_runnable` tells, without running anything, whether a
config can be run.
"""
from __future__ import annotations

import importlib
from typing import Any, Iterable, Mapping

from .config import Config, ConfigError
from .metrics import episode_metrics
from .scenario import load_scenario

__all__ = ["OPEN_LOOP_BEHAVIOURS", "needs_sensors", "check_runnable", "run_episode"]

OPEN_LOOP_BEHAVIOURS = ("random_walk", "hover")  # compiled into World.rollout; no sensors needed


def needs_sensors(kind: str) -> bool:
    """True when ``behaviour.kind`` is a closed-loop controller (reads sensors; runs in finkensim.swarm)."""
    return kind not in OPEN_LOOP_BEHAVIOURS


def _swarm_module():
    """``finkensim.swarm`` if installed, else None (a swarm module that fails to import is an error)."""
    try:
        return importlib.import_module("finkensim.swarm")
    except ModuleNotFoundError as exc:
        if exc.name in ("finkensim.swarm",):
            return None
        raise


def check_runnable(cfg: Config) -> None:
    """Raise :class:`ConfigError` if :func:`run_episode` cannot run ``cfg``: a closed-loop behaviour without
    the swarm module, or a config the swarm rejects (e.g. attraction-repulsion with the sonars disabled)."""
    kind = cfg.behaviour.kind
    if not needs_sensors(kind):
        return
    swarm = _swarm_module()
    if swarm is None:
        raise ConfigError(
            f"behaviour.kind = {kind!r}: this behaviour reads sensors and needs the closed-loop swarm rollout "
            f"(finkensim.swarm), which is not installed; expected one of {', '.join(map(repr, OPEN_LOOP_BEHAVIOURS))}")
    swarm.SwarmSim(cfg)  # builds the sensor models and checks what the behaviour needs; runs nothing


def _rollout(cfg: Config, seed: int, env_id: int, n_steps: int):
    """(pose (T, 1, N, 3), final positions (1, N, 2)) of ``n_steps`` steps of the configured behaviour."""
    if needs_sensors(cfg.behaviour.kind):
        check_runnable(cfg)  # a clear error when finkensim.swarm is missing
        sim = _swarm_module().SwarmSim(cfg)  # the closed loop: sense -> behave -> step, compiled
        final, rec = sim.rollout(sim.init(seed=seed, env_ids=[env_id]), n_steps, record=("pose",))
        return rec.pose, final.world.pos
    from .world import World

    world = World(cfg)
    final, traj = world.rollout(world.init(seed=seed, env_ids=[env_id]), n_steps, controller=cfg.behaviour.kind)
    return traj.pose, final.pos


def run_episode(cfg: Config | str | Mapping[str, Any] | None, seed: int, env_id: int = 0,
                metrics: Iterable[str] | None = None) -> dict[str, float]:
    """Fly one episode of ``cfg`` and return its metrics (name → float, units in :data:`~finkensim.metrics.METRICS`).

    Args:
        cfg: a Config, TOML path or text, dict, or None (the default scenario). Its
            ``simulation.duration`` sets the length; ``simulation.seed`` is ignored in favour of ``seed``.
        seed: random seed of the episode (placement and behaviour noise).
        env_id: environment index keying the randomness (with ``seed``), as in :meth:`World.init`.
        metrics: subset of metric names (default: all).

    The trajectory has T = round(duration / dt) samples (t = 0 … duration − dt); the contact counts
    also include the state after the last step.
    """
    cfg = load_scenario(cfg)
    sim = cfg.simulation
    n_steps = int(round(sim.duration / sim.dt))
    if n_steps < 1:
        raise ConfigError(f"simulation.duration = {sim.duration!r}: expected at least one step of simulation.dt = {sim.dt!r} s")
    pose, final_pos = _rollout(cfg, int(seed), int(env_id), n_steps)
    values = episode_metrics(pose, (cfg.arena.width, cfg.arena.length), cfg.copters.radius,
                             final_pos=final_pos, names=metrics)
    return {name: float(v[0]) for name, v in values.items()}
