"""The thread split of the batched entry points (finkensim.kernels.threads): any split, the same results."""
from __future__ import annotations

import multiprocessing
import os

import numba
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numba import njit

from finkensim.determinism import first_difference
from finkensim.config import Config
from finkensim.kernels import threads
from finkensim.kernels.threads import run_ranges, split_ranges
from finkensim.swarm import SwarmSim
from finkensim.swarm.control import PARALLEL_MIN_COPTERS, Controlled
from finkensim.swarm.kernel import PARALLEL_MIN_COPTER_STEPS


@given(st.integers(0, 10_000), st.integers(1, 64))
@settings(max_examples=200, deadline=None)
def test_split_ranges_cover_the_items_once_in_order(n, parts):
    ranges = split_ranges(n, parts)
    assert len(ranges) == parts and ranges[0][0] == 0 and ranges[-1][1] == n
    assert all(a[1] == b[0] for a, b in zip(ranges, ranges[1:]))  # contiguous, in order
    sizes = [i1 - i0 for i0, i1 in ranges]
    assert max(sizes) - min(sizes) <= 1 and (parts > n or min(sizes) >= 1)


@njit(nogil=True)
def _square_range(span, x, out):
    for i in range(span[0], span[1]):
        out[i] = x[i] * x[i]


@njit(nogil=True)
def _fail_at(span, bad):
    for i in range(span[0], span[1]):
        if i == bad:
            raise ValueError("item failed")


@pytest.mark.parametrize("n_threads", [1, 2])
@pytest.mark.parametrize("n", [0, 1, 2, 5, 1000])
def test_every_item_is_done_exactly_once(n, n_threads):
    x = np.arange(n, dtype=np.float64)
    out = np.full(n, np.nan)
    before = numba.get_num_threads()
    numba.set_num_threads(min(n_threads, numba.config.NUMBA_NUM_THREADS))
    try:
        run_ranges(_square_range, n, x, out)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(out, x * x)


@pytest.mark.parametrize("bad", [0, 999])  # the calling thread's range, the last thread's
def test_an_exception_in_any_range_is_raised_by_the_caller(bad):
    with pytest.raises(ValueError, match="item failed"):
        run_ranges(_fail_at, 1000, bad)


def _child_runs(q):
    numba.set_num_threads(2)  # split, whatever thread count the parent's thread had when it forked
    x = np.arange(100.0)
    out = np.zeros(100)
    run_ranges(_square_range, 100, x, out)
    q.put((bool(np.array_equal(out, x * x)), threads._pool_key[0] == os.getpid()))


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods() or numba.config.NUMBA_NUM_THREADS < 2,
                    reason="no fork on this platform, or one thread only")
def test_a_forked_child_gets_its_own_pool():
    run_ranges(_square_range, 100, np.arange(100.0), np.zeros(100))  # the parent's pool exists
    ctx = multiprocessing.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_child_runs, args=(q,))
    p.start()
    p.join(120)
    if p.is_alive():  # the child hung on the inherited pool, whose threads do not exist in it
        p.kill()
    assert p.exitcode == 0
    squared, own_pool = q.get(timeout=5)
    assert squared and own_pool  # the pool the child split its work on was made in the child


def _with_threads(k, fn):
    before = numba.get_num_threads()
    numba.set_num_threads(min(k, numba.config.NUMBA_NUM_THREADS))
    try:
        return fn()
    finally:
        numba.set_num_threads(before)


def _noisy_sim(n=4):
    return SwarmSim(Config().replace({"copters.n": n, "behaviour.kind": "attraction_repulsion",
                                      "behaviour.wall_check": "sequence", "ranging.beacons": [[1.5, 2.0]],
                                      "imu.acc_noise_density": 0.05}))


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread only")
def test_rollout_is_the_same_on_one_thread_and_on_several(monkeypatch):
    sim = _noisy_sim()
    state = sim.init(n_envs=5, seed=3)
    assert 5 * 4 * 30 < PARALLEL_MIN_COPTER_STEPS <= 5 * 4 * 60  # 60 steps of 5 × 4 copters split, 30 do not
    splits = []
    monkeypatch.setattr(threads, "split_ranges", lambda n, parts: splits.append(parts) or split_ranges(n, parts))
    one = _with_threads(1, lambda: sim.rollout(state, 60, record=True))
    many = _with_threads(2, lambda: sim.rollout(state, 60, record=True))
    short = _with_threads(2, lambda: sim.rollout(state, 30, record=True))
    assert splits == [2]  # only the second rollout was split
    assert first_difference(short[1].sonar, many[1].sonar[:30]) is None
    for name in ("pose", "sonar", "ranging", "imu_acc", "wall"):
        a, b = getattr(one[1], name), getattr(many[1], name)
        assert first_difference(a, b) is None, f"{name}: {first_difference(a, b)}"
    assert first_difference(one[0].world.pos, many[0].world.pos) is None


def test_controlled_step_is_the_same_on_one_thread_and_on_several():
    """The controlled step (the RL envs' compiled step) splits the environments over threads: on one thread and on
    two it gives the same readings and state bit for bit."""
    sim = _noisy_sim()
    B = PARALLEL_MIN_COPTERS // 4 + 3  # enough copters for the split
    ctl = Controlled(sim)
    cmd = np.random.default_rng(0).uniform(-0.3, 0.3, (B, 4, 2))

    def three_steps():
        state = sim.init(n_envs=B, seed=5)
        out = [ctl.sense(state)]
        for _ in range(3):
            state, obs = ctl.step(state, cmd)
            out.append(obs)
        return out, state

    (obs1, s1), (obs2, s2) = _with_threads(1, three_steps), _with_threads(2, three_steps)
    for a, b in zip(obs1, obs2):
        for x, y in zip(a, b):
            assert first_difference(x, y) is None
    assert first_difference(s1.world.pos, s2.world.pos) is None and first_difference(s1.imu_bias, s2.imu_bias) is None
