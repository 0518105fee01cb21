"""check_determinism covers the closed loop: SwarmSim with every sensor and a behaviour, and it catches a
Python behaviour that leaks information between environments."""
from __future__ import annotations

import numpy as np
import pytest

from finkensim.determinism import check_determinism
from finkensim.config import load_config
from finkensim.swarm import SwarmSim


@pytest.mark.parametrize("updates", [
    {"behaviour.kind": "attraction_repulsion", "behaviour.wall_check": "sequence", "sonar.crosstalk": "geometric",
     "sonar.schedule": "random_offset"},
    {"profile": "seed", "behaviour.kind": "attraction_repulsion"},
    {"behaviour.kind": "random_walk"},
])
def test_swarm_runs_with_sensors_are_deterministic_and_batch_independent(updates):
    cfg = load_config().replace({"copters.n": 4, **updates})
    check_determinism(cfg, n_envs=3, n_steps=40, seed=3)
    check_determinism(SwarmSim(cfg), n_envs=2, n_steps=10, seed=1)


def test_a_python_behaviour_that_mixes_environments_is_caught():
    def leaky(readings, memory, params):
        r = readings.sonar  # (B, N, 4)
        v = np.zeros(r.shape[:2] + (2,))
        v[..., 0] = 0.1 * r.mean()  # the batch mean: environment k depends on the others
        return v, None

    with pytest.raises(AssertionError, match="lone env"):
        check_determinism(SwarmSim(load_config().replace({"copters.n": 3}), behaviour=leaky), n_envs=2, n_steps=5)


def test_a_controller_is_for_a_world_only():
    with pytest.raises(ValueError, match="only for a World"):
        check_determinism(SwarmSim(load_config()), controller=lambda world, state: None)
