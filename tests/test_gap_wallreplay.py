"""The sonar replay with the walls apart from the copters (gap/model/wallreplay.py) against the whole replay
(gap/model/replay.py::sonar_draws, the simulator's own per-ray kernels): the same readings bit for bit."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.arena import Arena
from finkensim.config import Config
from finkensim.gap.model import replay as rp
from finkensim.gap.model.wallreplay import sonar_draws_split
from finkensim.sensors.sonar_model import CROSSTALK_OFF, SCHEDULE_RANDOM_OFFSET, wall_geometry
from finkensim.sensors.sonar import SonarModel


def _buffers(K, N, S, G):
    return [np.empty((K, N, S, G)), np.empty((K, N, S, G), np.int8), np.empty((K, N, S, G))]


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10**6), beam=st.sampled_from([(0.0, 1), (0.35, 5)]), noisy=st.booleans(),
       geometric=st.booleans())
def test_walls_replayed_alone_give_the_whole_replays_readings(seed, beam, noisy, geometric):
    rng = np.random.default_rng(seed)
    cfg = Config()
    arena = Arena.from_config(cfg.arena, cfg.walls)
    T, N, S, G = 6, 5, 4, 3
    pos = np.stack([rng.uniform([0.2, 0.2], [2.8, 3.8], size=(N, 2)) for _ in range(T)])
    yaw = rng.uniform(-np.pi, np.pi, size=(T, N))
    theta = rng.uniform(0, 0.5, size=(T, arena.n_plates))
    sp = SonarModel.from_config(cfg).with_beam(*beam)._replace(schedule=SCHEDULE_RANDOM_OFFSET, n_slots=2)
    if not geometric:
        sp = sp._replace(crosstalk=CROSSTALK_OFF)
    times = np.arange(T, dtype=np.int64)
    noise = rp.PoseNoise(0.01, 0.02, seed, 1) if noisy else rp.PoseNoise(0.0, 0.0, seed, 1)
    z = np.empty((T, G, N, 3))
    rp.pose_normal_table(times, N, G, seed, 1, z)
    need = rng.random((T, N, S)) < 0.7
    copters = np.empty((T, N, S, G, sp.ray_angles.shape[0]))
    kept_xt = None
    for gain, bulge in ((1.0, np.zeros_like(theta)), (0.0, rng.uniform(-0.1, 0.4, theta.shape)),
                        (2.0, rng.uniform(0.0, 0.2, theta.shape))):
        poses = rp.ReplayPoses(pos, yaw, theta, bulge)
        whole = _buffers(T, N, S, G)
        rp.sonar_draws(poses, wall_geometry(arena), sp, gain, times, noise, G, need, *whole, z=z)
        split = _buffers(T, N, S, G)
        record = kept_xt is None
        xt = split[2] if record else kept_xt
        sonar_draws_split(poses, wall_geometry(arena), sp, gain, times, noise, z, need, split[0], split[1], xt,
                          copters, record=record)
        kept_xt = xt
        assert split[0].tobytes() == whole[0].tobytes()
        assert split[1].tobytes() == whole[1].tobytes()
        assert xt.tobytes() == whole[2].tobytes()
