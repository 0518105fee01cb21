"""run_episode: one engine (SwarmSim) for every behaviour; no import cycle with scenario."""
from __future__ import annotations

import subprocess
import sys

import pytest

from finkensim.behaviours.open_loop import RandomWalk, hover
from finkensim.config import Config, ConfigError
from finkensim.episode import check_runnable, run_episode
from finkensim.metrics import episode_metrics
from finkensim.world import World


@pytest.mark.parametrize("kind, controller", [("random_walk", RandomWalk), ("hover", lambda cfg: hover)])
def test_open_loop_episode_flies_as_the_world_rollout(kind, controller):
    cfg = Config().replace({"behaviour.kind": kind, "copters.n": 4, "simulation.duration": 2.0,
                            "sonar.enabled": False, "behaviour.wall_check": "per_reading"})  # the check is moot
    got = run_episode(cfg, seed=3, env_id=2)
    world = World(cfg)
    final, traj = world.rollout(world.init(seed=3, env_ids=[2]), 40, controller(cfg))
    want = episode_metrics(traj.pose, (cfg.arena.width, cfg.arena.length), cfg.copters.radius, final_pos=final.pos)
    assert got == {name: float(v[0]) for name, v in want.items()}


def test_closed_loop_needs_are_checked():
    check_runnable(Config().replace({"behaviour.kind": "attraction_repulsion"}))
    with pytest.raises(ConfigError, match="needs sonar.enabled = true"):
        check_runnable(Config().replace({"behaviour.kind": "attraction_repulsion", "sonar.enabled": False}))


@pytest.mark.parametrize("first", ["finkensim.episode", "finkensim.scenario"])
def test_episode_and_scenario_import_alone(first):
    code = f"import {first}, sys; print('finkensim.' + ('scenario' if '{first}'.endswith('episode') else 'episode') " \
           f"in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
