"""Episode metrics on hand-built trajectories with known answers, batching, and agreement with the world's counters."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse.csgraph import connected_components

from finkensim import metrics as M
from finkensim.config import Config
from finkensim.metrics import (METRICS, check_metric_names, cohesion, collision_onsets, coverage, episode_metrics,
                               fragmentation, near_wall, nearest_neighbour, wall_contact_onsets, wall_sticking)
from finkensim.behaviours.open_loop import RandomWalk
from finkensim.world import World

ARENA = (3.0, 4.0)
R = 0.15


def traj(*frames):
    """Pose (T, 1, N, 3) from frames, each a list of (x, y) per copter (yaw 0)."""
    xy = np.asarray(frames, dtype=float)  # (T, N, 2)
    pose = np.concatenate([xy, np.zeros(xy.shape[:-1] + (1,))], axis=-1)
    return pose[:, None]


# --------------------------------------------------------------------------- cohesion, nearest neighbour

def test_cohesion_known_values():
    # two copters 2 m apart: both 1 m from the centroid
    assert cohesion(traj([(1, 1), (1, 3)])) == pytest.approx([1.0])
    # four copters on the corners of a 2 m square: sqrt(2) m each
    assert cohesion(traj([(0.5, 0.5), (2.5, 0.5), (0.5, 2.5), (2.5, 2.5)])) == pytest.approx([math.sqrt(2)])
    # time average: 1 m, then 0.5 m
    assert cohesion(traj([(1, 1), (1, 3)], [(1, 1.5), (1, 2.5)])) == pytest.approx([0.75])
    # a single copter is its own centroid
    assert cohesion(traj([(1, 1)], [(2, 2)])) == pytest.approx([0.0])


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 4), st.integers(1, 5), st.integers(1, 40), st.integers(0, 2**32 - 1), st.sampled_from([2, 3]))
def test_cohesion_equals_the_numpy_formula_bit_for_bit(T, B, N, seed, width):
    """cohesion's per-copter centroid sum is numpy's own order for a C-ordered pose (golden tables rely on it)."""
    pose = np.random.default_rng(seed).uniform(-5.0, 5.0, size=(T, B, N, width))
    pos = pose[..., :2]
    expected = np.linalg.norm(pos - pos.mean(axis=2, keepdims=True), axis=-1).mean(axis=(0, 2))
    assert np.array_equal(cohesion(pose), expected)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 3), st.integers(1, 4), st.integers(1, 12), st.integers(0, 2**32 - 1), st.sampled_from([2, 3]),
       st.floats(-0.5, 0.5), st.floats(0.0, 0.3))
def test_wall_sticking_equals_the_numpy_formula_bit_for_bit(T, B, N, seed, width, wall_distance, radius):
    """near_wall (compiled) against the numpy form of the body gap, with non-finite coordinates mixed in."""
    rng = np.random.default_rng(seed)
    pose = rng.uniform(-0.5, 4.5, size=(T, B, N, width))
    special = rng.random(pose.shape) < 0.1
    pose[special] = rng.choice([np.nan, np.inf, -np.inf, 0.0, -0.0, 3.0, 4.0], size=int(special.sum()))
    x, y = pose[..., 0], pose[..., 1]
    gap = np.minimum(np.minimum(x, 3.0 - x), np.minimum(y, 4.0 - y)) - radius
    assert np.array_equal(near_wall(pose[..., :2], 3.0, 4.0, radius, wall_distance), gap <= wall_distance)
    np.testing.assert_array_equal(M._wall_gaps(pose[..., :2], 3.0, 4.0, radius), gap)  # wall_contact_onsets' gaps
    assert np.array_equal(wall_sticking(pose, (3.0, 4.0), radius, wall_distance), (gap <= wall_distance).mean(axis=(0, 2)))


def test_nearest_neighbour_known_values():
    # on a line: gaps 0.5 and 1.5 -> nearest 0.5, 0.5, 1.5
    assert nearest_neighbour(traj([(0.5, 2), (1.0, 2), (2.5, 2)])) == pytest.approx([2.5 / 3])
    assert nearest_neighbour(traj([(1, 1), (1, 3)], [(1, 1), (2, 1)])) == pytest.approx([1.5])
    assert np.isnan(nearest_neighbour(traj([(1, 1)]))).all()


# --------------------------------------------------------------------------- walls

def test_wall_sticking_uses_the_body_gap():
    # body gap = centre distance - radius: x = 0.449 -> gap 0.299 (counts), x = 0.451 -> 0.301 (does not)
    p = traj([(0.449, 2.0), (1.5, 2.0)], [(0.451, 2.0), (1.5, 3.551)], [(2.7, 2.0), (1.5, 0.2)])
    # copter 0: in, out, in (gap 0.15); copter 1: out (1.35), in (0.299), in (0.05) -> 4 of 6 copter-samples
    assert wall_sticking(p, ARENA, R) == pytest.approx([4 / 6])
    assert wall_sticking(p, ARENA, R, wall_distance=0.0) == pytest.approx([0.0])
    # measured from the body: a bigger copter at the same centre is within the band
    assert wall_sticking(traj([(0.6, 2.0)]), ARENA, 0.31) == pytest.approx([1.0])
    assert wall_sticking(traj([(0.6, 2.0)]), ARENA, 0.29) == pytest.approx([0.0])


def test_wall_contacts_count_onsets_with_the_models_hysteresis():
    r = R
    x = [r, r + 0.01, r, r + 0.05, r + 0.05, r, r]  # touch, 1 cm (still in contact), touch, leave, -, touch, stay
    p = traj(*[[(xi, 2.0)] for xi in x])
    assert wall_contact_onsets(p, ARENA, r) == pytest.approx([2.0])
    # the far walls too (W - r computed in floating point), and two copters add up
    p2 = traj([(ARENA[0] - r, 2.0), (1.5, ARENA[1] - r)], [(1.0, 2.0), (1.5, ARENA[1] - r)],
              [(ARENA[0] - r, 2.0), (1.5, 2.0)])
    assert wall_contact_onsets(p2, ARENA, r) == pytest.approx([3.0])
    # the final position counts as one more sample
    assert wall_contact_onsets(traj([(1.0, 2.0)]), ARENA, r, final_pos=[[[r, 2.0]]]) == pytest.approx([1.0])


# --------------------------------------------------------------------------- collisions

def test_collisions_count_pair_onsets():
    far, near = (1.0, 2.0), (1.2, 2.0)  # 0.2 m < 2 r = 0.3 m
    p = traj([(0.8, 2.0), (1.5, 3.0)],   # apart
             [(1.0, 2.0), (1.2, 2.0)],   # bump 1 begins
             [(1.0, 2.0), (1.25, 2.0)],  # still overlapping: same bump
             [(1.0, 2.0), (1.31, 2.0)],  # 0.31 m: apart
             [far, near])                # bump 2
    assert collision_onsets(p, R) == pytest.approx([2.0])
    # exactly 2 r apart is not an overlap
    assert collision_onsets(traj([(1.0, 2.0), (1.3, 2.0)]), R) == pytest.approx([0.0])
    # an overlap at the first sample is an onset
    assert collision_onsets(traj([(1.0, 2.0), (1.1, 2.0)]), R) == pytest.approx([1.0])


def test_three_copters_touching_at_once_are_three_pair_events():
    # all three pairwise overlapping -> 3 pair onsets; per-copter counting would give 3 copters / 2 = 1.5
    p = traj([(0.5, 0.5), (2.5, 0.5), (1.5, 3.0)], [(1.0, 2.0), (1.1, 2.0), (1.05, 2.08)])
    assert collision_onsets(p, R) == pytest.approx([3.0])
    # a chain: A-B and B-C overlap, A-C do not -> 2
    p = traj([(0.5, 0.5), (2.5, 0.5), (1.5, 3.0)], [(1.0, 2.0), (1.2, 2.0), (1.4, 2.0)])
    assert collision_onsets(p, R) == pytest.approx([2.0])
    # the final position is a last sample
    assert collision_onsets(traj([(1.0, 2.0), (2.0, 2.0)]), R, final_pos=[[[1.0, 2.0], [1.1, 2.0]]]) == pytest.approx([1.0])


def _collisions_reference(pos, radius):
    T, B, N, _ = pos.shape
    out = np.zeros(B)
    for b in range(B):
        for i in range(N):
            for j in range(i + 1, N):
                prev = False
                for t in range(T):
                    now = np.hypot(*(pos[t, b, i] - pos[t, b, j])) < 2 * radius
                    out[b] += now and not prev
                    prev = now
    return out


def test_contact_counts_agree_with_the_world_counters():
    cfg = Config().replace({"copters.n": 8, "behaviour.speed": 0.8, "behaviour.wall_margin": 0.0})
    world = World(cfg)
    state0 = world.init(n_envs=4, seed=5)
    final, tr = world.rollout(state0, 600, RandomWalk(cfg))
    m = episode_metrics(tr.pose, ARENA, R, final_pos=final.pos)
    np.testing.assert_array_equal(m["wall_contacts"], final.wall_contacts.sum(-1))
    assert m["wall_contacts"].sum() > 0, "the test needs some wall contacts"
    pos = np.concatenate([tr.pose[..., :2], final.pos[None]], axis=0)
    np.testing.assert_array_equal(m["collisions"], _collisions_reference(pos, R))
    assert m["collisions"].sum() > 0
    # every pair bump makes both copters' counters tick at most once: the per-copter sum bounds it
    assert np.all(final.collisions.sum(-1) <= 2 * m["collisions"])


# --------------------------------------------------------------------------- fragmentation, coverage

def test_fragmentation_known_values():
    # two close copters and one 3 m away: 2 groups
    assert fragmentation(traj([(0.5, 0.5), (1.5, 0.5), (0.5, 3.5)])) == pytest.approx([2.0])
    # links are transitive: A-B 2.0 m, B-C 2.0 m, A-C 4.0 m -> one group
    assert fragmentation(traj([(1.0, 0.0), (1.0, 2.0), (1.0, 4.0)])) == pytest.approx([1.0])
    # exactly 2.5 m apart is not linked ("closer than")
    assert fragmentation(traj([(0.25, 0.5), (0.25, 3.0)])) == pytest.approx([2.0])
    # time average: one group, then two
    assert fragmentation(traj([(0.5, 0.5), (0.5, 1.0)], [(0.5, 0.5), (0.5, 3.5)])) == pytest.approx([1.5])
    assert fragmentation(traj([(1, 1)])) == pytest.approx([1.0])


def test_fragmentation_matches_scipy_connected_components():
    rng = np.random.default_rng(0)
    pos = rng.uniform([0, 0], [6, 8], size=(30, 3, 9, 2))
    got = fragmentation(pos)
    want = np.zeros(3)
    for b in range(3):
        for t in range(30):
            d = np.linalg.norm(pos[t, b, :, None] - pos[t, b, None], axis=-1)
            want[b] += connected_components(d < 2.5, directed=False)[0]
    np.testing.assert_allclose(got, want / 30)
    assert np.ptp(got) > 0  # the example has varied answers


def test_coverage_known_values():
    n_cells = 12 * 16  # 0.25 m cells over 3 m x 4 m
    assert coverage(traj([(0.1, 0.1)], [(0.2, 0.2)]), ARENA) == pytest.approx([1 / n_cells])
    # a sweep along x at y = 0.1 visits the whole bottom row
    xs = np.linspace(0.15, 2.85, 100)
    assert coverage(traj(*[[(x, 0.1)] for x in xs]), ARENA) == pytest.approx([12 / n_cells])
    # a centre on a cell border belongs to the cell above it; two copters share a cell once
    assert coverage(traj([(0.25, 0.1), (0.3, 0.2)]), ARENA) == pytest.approx([1 / n_cells])
    # an arena that is not a whole number of cells: ceil(1.1 / 0.25) = 5 x 2 cells
    assert coverage(traj([(1.05, 0.1)]), (1.1, 0.5)) == pytest.approx([1 / 10])


# --------------------------------------------------------------------------- batching, blocks, names

def test_metrics_are_per_environment_and_blocking_does_not_change_them(monkeypatch):
    rng = np.random.default_rng(3)
    pose = np.concatenate([rng.uniform([R, R], [3 - R, 4 - R], size=(50, 4, 5, 2)), np.zeros((50, 4, 5, 1))], -1)
    final = rng.uniform([R, R], [3 - R, 4 - R], size=(4, 5, 2))
    full = episode_metrics(pose, ARENA, R, final_pos=final)
    assert set(full) == set(METRICS)
    for name, v in full.items():
        assert v.shape == (4,) and v.dtype == np.float64, name
    for b in range(4):
        single = episode_metrics(pose[:, b:b + 1], ARENA, R, final_pos=final[b:b + 1])
        for name in METRICS:
            np.testing.assert_allclose(single[name], full[name][b:b + 1], err_msg=name)
    monkeypatch.setattr(M, "_BLOCK_ELEMENTS", 7)  # one sample per block
    blocked = episode_metrics(pose, ARENA, R, final_pos=final)
    for name in METRICS:
        np.testing.assert_allclose(blocked[name], full[name], err_msg=name)


def test_metric_names_and_shapes_are_checked():
    assert check_metric_names(["coverage", "cohesion", "coverage"]) == ("coverage", "cohesion")  # file order (issue 40)
    m = episode_metrics(traj([(1, 1), (1, 3)]), ARENA, R, names=["cohesion"])
    assert list(m) == ["cohesion"]
    with pytest.raises(ValueError, match="did you mean 'cohesion'"):
        episode_metrics(traj([(1, 1)]), ARENA, R, names=["cohesio"])
    with pytest.raises(ValueError, match=r"pose has shape \(3, 2\)"):
        cohesion(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="final_pos has shape"):
        collision_onsets(traj([(1, 1)]), R, final_pos=np.zeros((2, 1, 2)))
    for name, info in METRICS.items():
        assert info.unit and info.doc, name
