"""One Monte-Carlo episode: config + seed → rollout → metrics. The unit of work of a sweep.

    from finkensim.episode import run_episode
    run_episode(cfg, seed=7)   # {"cohesion": 1.02, "nearest_neighbour": 0.81, ...}

An episode places ``copters.n`` copters at random (keyed by ``seed`` and ``env_id``), flies them
for round(simulation.duration / simulation.dt) steps with ``behaviour.kind`` in the compiled loop of
:class:`finkensim.swarm.SwarmSim` and returns the metrics of :mod:`finkensim.metrics` as plain floats.
Behaviours that read sensors (``attraction_repulsion``) run with every enabled sensor and the wall
check; the open-loop ones (``random_walk``, ``hover``) run with the sensors off (they read none).
:func:`check_runnable` tells, without running anything, whether a config can be run.
"""
from __future__ import annotations

from typing import Any, Iterable, Mapping

from .behaviours.open_loop import OPEN_LOOP_BEHAVIOURS
from .config import Config, ConfigError
from .default_scenario import load_scenario
from .budget import check_memory, episode_arrays
from .metrics import episode_metrics
from .swarm import SwarmSim, needs_sensors

__all__ = ["OPEN_LOOP_BEHAVIOURS", "needs_sensors", "check_runnable", "run_episode"]


def check_runnable(cfg: Config) -> None:
    """Raise :class:`ConfigError` if :func:`run_episode` cannot run ``cfg``: a config the swarm rejects
    (e.g. attraction-repulsion with the sonars disabled). Runs nothing; the open-loop behaviours always run."""
    check_memory(episode_arrays(cfg), f"an episode of {cfg.simulation.duration:g} s of {cfg.copters.n} copters",
                 "shorten the sweep's duration, lower copters.n or raise simulation.dt")
    if needs_sensors(cfg.behaviour.kind):
        SwarmSim(cfg)  # builds the sensor models and checks what the behaviour needs


def _rollout(cfg: Config, seed: int, env_id: int, n_steps: int):
    """(pose (T, 1, N, 3) m/rad, final positions (1, N, 2) m) of ``n_steps`` steps of the configured behaviour."""
    sim = SwarmSim(cfg, sensors=needs_sensors(cfg.behaviour.kind))
    final, rec = sim.rollout(sim.init(seed=seed, env_ids=[env_id]), n_steps, record=("pose",))
    return rec.pose, final.world.pos


def run_episode(cfg: Config | str | Mapping[str, Any] | None, seed: int, env_id: int = 0,
                metrics: Iterable[str] | None = None) -> dict[str, float]:
    """Fly one episode of ``cfg`` and return its metrics (name → float, units in :data:`~finkensim.metrics.METRICS`).

    Parameters
    ----------
    cfg : Config, str, Mapping or None
        A Config, TOML path or text, dict, or None (the default scenario). Its ``simulation.duration`` (s)
        sets the length; ``simulation.seed`` is ignored in favour of ``seed``.
    seed : int
        Random seed of the episode (placement and behaviour noise).
    env_id : int
        Environment index keying the randomness (with ``seed``), as in :meth:`World.init`.
    metrics : iterable of str, optional
        Subset of metric names (default: all of :data:`~finkensim.metrics.METRICS`).

    Returns
    -------
    dict of str to float
        Metric name → value, in the unit :data:`~finkensim.metrics.METRICS` gives.

    Notes
    -----
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
