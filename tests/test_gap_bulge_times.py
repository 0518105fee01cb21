"""The wall bulge computed only at the replayed samples (``Flight.poses_with_bulge(..., times)``) is the one computed
on the whole log there, bit for bit (a bulge with a response time is always computed on the whole log)."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.gap.model.replay import Flight


def _flight(T, P, seed):
    rng = np.random.default_rng(seed)
    f = object.__new__(Flight)
    f.pos = rng.uniform(0, 4, (T, 3, 2))
    f.yaw = rng.uniform(-3, 3, (T, 3))
    f.theta_unit = rng.uniform(-0.3, 0.3, (T, P))
    f.plate_distance = rng.uniform(0.0, 2.0, (T, P))
    f.t = np.arange(T) * 0.01
    return f


@settings(max_examples=40, deadline=None)
@given(T=st.integers(2, 60), P=st.integers(1, 12), seed=st.integers(0, 10**6),
       amplitude=st.sampled_from([0.0, -0.1, 0.05, 0.3]), reach=st.floats(0.05, 1.5),
       shape=st.floats(1.0, 12.0), response=st.sampled_from([0.0, 0.0, 0.4]), data=st.data())
def test_bulge_at_times_is_the_whole_logs(T, P, seed, amplitude, reach, shape, response, data):
    f = _flight(T, P, seed)
    times = np.array(data.draw(st.lists(st.integers(0, T - 1), min_size=1, max_size=T)), dtype=np.int64)
    full = f.poses_with_bulge(amplitude, reach, response, shape)
    part = f.poses_with_bulge(amplitude, reach, response, shape, times=times)
    np.testing.assert_array_equal(part.bulge[times], full.bulge[times])
    for name in ("pos", "yaw", "theta"):
        assert getattr(part, name) is getattr(full, name)
