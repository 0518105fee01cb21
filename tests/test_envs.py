"""finkensim.envs: the libraries' own checkers, seeding, vector = looped singles, readings = the closed loop."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("pettingzoo")

import finkensim.envs as fe  # noqa: E402
from finkensim.config import ConfigError  # noqa: E402
from finkensim.envs.gym_env import SwarmEnv, SwarmVectorEnv  # noqa: E402
from finkensim.metrics import coverage  # noqa: E402
from finkensim.swarm import SwarmSim  # noqa: E402
from finkensim.swarm.control import Controlled  # noqa: E402

SCEN = {"copters": {"n": 4}}


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        # our observation boxes are unbounded (sensor noise has no hard limit); gymnasium warns about that
        warnings.filterwarnings("ignore", message=".*Box observation space (minimum|maximum) value.*")
        yield


def test_controlled_readings_equal_the_hover_closed_loop():
    sim = SwarmSim({**SCEN, "behaviour": {"kind": "hover"}})
    s0 = sim.init(n_envs=2, seed=5)
    _, rec = sim.rollout(s0, 8, record=("pose", "sonar", "ranging", "imu_acc", "imu_gyro"))
    ctl = Controlled(sim)
    st = s0.copy()
    r = ctl.sense(st)
    for t in range(8):
        np.testing.assert_array_equal(st.world.pose, rec.pose[t])
        for name in ("sonar", "ranging", "imu_acc", "imu_gyro"):
            np.testing.assert_array_equal(getattr(r, name), getattr(rec, name)[t], err_msg=f"{name} at step {t}")
        st, r = ctl.step(st, np.zeros((2, 4, 2)))


def test_controlled_readings_written_into_given_arrays_equal_fresh_ones():
    """``out=``: the same readings, bit for bit, in arrays reused from step to step (stale values from a previous
    step, or garbage, are all overwritten); arrays of another shape are refused with the expected shapes."""
    sim = SwarmSim({**SCEN, "behaviour": {"kind": "hover"}})
    ctl = Controlled(sim)
    a, b = sim.init(n_envs=3, seed=2), sim.init(n_envs=3, seed=2)
    out = ctl.readings(3, 4)
    for arr in out:
        arr[...] = np.nan
    cmd = np.random.default_rng(1).uniform(-0.3, 0.3, (3, 4, 2))
    for t in range(5):
        a, fresh = ctl.step(a, cmd)
        b, reused = ctl.step(b, cmd, out)
        assert all(x is y for x, y in zip(reused, out))
        for name in fresh._fields:
            np.testing.assert_array_equal(getattr(reused, name), getattr(fresh, name), err_msg=f"{name} at step {t}")
    with pytest.raises(ValueError, match=r"expected C-contiguous float64 arrays of shapes"):
        ctl.step(b, cmd, ctl.readings(2, 4))


def test_gymnasium_check_env_and_render():
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make("finkensim/Swarm-v0", scenario=SCEN, max_steps=20, render_mode="rgb_array")
    check_env(env.unwrapped, skip_render_check=False)
    env.reset(seed=0)
    img = env.render()
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8


def test_pettingzoo_parallel_api_test():
    from pettingzoo.test import parallel_api_test

    parallel_api_test(fe.parallel_env(scenario=SCEN, max_steps=20), num_cycles=30)


def test_make_vec_is_native_and_autoresets_next_step():
    envs = gymnasium.make_vec("finkensim/Swarm-v0", num_envs=3, scenario=SCEN, max_steps=4)
    assert isinstance(envs.unwrapped, SwarmVectorEnv)
    obs, _ = envs.reset(seed=1)
    assert obs.shape == (3, 4, envs.unwrapped.core.obs_dim) and obs.dtype == np.float32
    assert envs.observation_space.contains(obs)
    for t in range(4):
        obs, rew, term, trunc, _ = envs.step(envs.action_space.sample())
        assert rew.shape == (3,) and not term.any() and trunc.all() == (t == 3)
    obs, rew, term, trunc, _ = envs.step(envs.action_space.sample())  # the autoreset step
    assert np.all(rew == 0) and not trunc.any()


def _actions(rng, B, T, N=4):
    return rng.uniform(-1, 1, size=(T, B, N, 2)).astype(np.float32)


def test_vector_env_equals_looped_single_envs_across_an_autoreset():
    B, T = 3, 7
    acts = _actions(np.random.default_rng(0), B, T)
    vec = SwarmVectorEnv(num_envs=B, scenario=SCEN, max_steps=3, task="coverage")
    singles = [SwarmEnv(scenario=SCEN, max_steps=3, task="coverage") for _ in range(B)]
    obs_v, _ = vec.reset(seed=10)
    obs_s = [e.reset(seed=10 + i)[0] for i, e in enumerate(singles)]
    np.testing.assert_array_equal(obs_v, np.stack(obs_s))
    for t in range(T):
        ov, rv, _, tv, _ = vec.step(acts[t])
        for i, e in enumerate(singles):
            if t == 3:  # vector autoreset step ↔ a plain reset of the single env
                o = e.reset()[0]
                assert rv[i] == 0 and not tv[i]
            else:
                o, r, _, tr, _ = e.step(acts[t, i])
                assert rv[i] == r and tv[i] == tr
            np.testing.assert_array_equal(ov[i], o)


def test_seeding_reproduces_and_distinguishes_episodes():
    env = SwarmEnv(scenario=SCEN, max_steps=5)
    a = np.full((4, 2), 0.3, dtype=np.float32)
    first = env.reset(seed=4)[0]
    run1 = [env.step(a)[0] for _ in range(3)]
    second = env.reset()[0]                                  # the next episode: new start, new noise
    assert not np.array_equal(first, second)
    again = env.reset(seed=4)[0]
    np.testing.assert_array_equal(first, again)
    np.testing.assert_array_equal(run1[-1], [env.step(a)[0] for _ in range(3)][-1])
    np.testing.assert_array_equal(second, env.reset()[0])
    assert not np.array_equal(first, SwarmEnv(scenario=SCEN).reset(seed=5)[0])


def test_pettingzoo_env_equals_the_gymnasium_env():
    pz = fe.parallel_env(scenario=SCEN, max_steps=5, task="wall_avoidance", pose=True)
    env = SwarmEnv(scenario=SCEN, max_steps=5, task="wall_avoidance", pose=True)
    obs_p, _ = pz.reset(seed=2)
    obs_g, _ = env.reset(seed=2)
    acts = _actions(np.random.default_rng(1), 1, 5)[:, 0]
    for t in range(5):
        np.testing.assert_array_equal(np.stack([obs_p[a] for a in pz.possible_agents]), obs_g)
        obs_p, rp, _, tp, _ = pz.step({a: acts[t, i] for i, a in enumerate(pz.possible_agents)})
        obs_g, rg, _, tg, _ = env.step(acts[t])
        assert all(v == rg for v in rp.values()) and all(v == tg for v in tp.values())
    assert pz.agents == []
    assert pz.state().shape == (12,)


def test_pose_block_is_the_true_pose():
    env = SwarmEnv(scenario=SCEN, pose=True)
    obs, _ = env.reset(seed=0)
    np.testing.assert_allclose(obs[:, -3:], env.core.state.world.pose[0], rtol=1e-6, atol=1e-6)


def test_observation_is_the_readings_in_layout_order():
    """sonar, ranging, IMU (acc x, y, gyro), pose — each reading rounded to float32, nothing else."""
    env = SwarmVectorEnv(num_envs=2, scenario=SCEN, pose=True)
    env.reset(seed=3)
    core = env.core
    r = core.ctl.sense(core.state.copy())
    expected = np.concatenate([r.sonar, r.ranging, r.imu_acc, r.imu_gyro[..., None], core.state.world.pose], axis=-1)
    assert [name for name, _ in core.layout] == ["sonar", "ranging", "imu", "pose"]
    np.testing.assert_array_equal(core.observe(r), expected.astype(np.float32))


@pytest.mark.parametrize("on, pose", [(("sonar",), False), (("ranging", "imu"), True), ((), True)])
def test_observation_blocks_of_a_partial_layout(on, pose):
    """The compiled assembly writes exactly the enabled blocks, in layout order, as float32."""
    scen = {**SCEN, **{k: {"enabled": k in on} for k in ("sonar", "ranging", "imu")}}
    env = SwarmVectorEnv(num_envs=3, scenario=scen, pose=pose)
    env.reset(seed=1)
    core = env.core
    r = core.ctl.sense(core.state.copy())
    parts = {"sonar": r.sonar, "ranging": r.ranging, "imu": np.concatenate([r.imu_acc, r.imu_gyro[..., None]], -1),
             "pose": core.state.world.pose}
    expected = np.concatenate([parts[name] for name, _ in core.layout], axis=-1).astype(np.float32)
    assert [name for name, _ in core.layout] == [k for k in ("sonar", "ranging", "imu") if k in on] + (["pose"] if pose else [])
    np.testing.assert_array_equal(core.observe(r), expected)


def test_coverage_rewards_sum_to_the_coverage_metric():
    vec = SwarmVectorEnv(num_envs=2, scenario=SCEN, task="coverage", max_steps=30)
    vec.reset(seed=0)
    poses = [vec.core.state.world.pos.copy()]
    total = np.zeros(2)
    for a in _actions(np.random.default_rng(2), 2, 30):
        _, r, _, _, _ = vec.step(a)
        total += r
        poses.append(vec.core.state.world.pos.copy())
    arena = vec.core.ctx.arena
    np.testing.assert_allclose(total, coverage(np.stack(poses), arena) - coverage(np.stack(poses[:1]), arena))


def test_clear_errors():
    with pytest.raises(ConfigError, match="task = 'cohesoin'.*did you mean 'cohesion'"):
        SwarmEnv(task="cohesoin")
    with pytest.raises(ConfigError, match="max_steps = 0"):
        SwarmEnv(max_steps=0)
    with pytest.raises(ConfigError, match="num_envs = 0"):
        SwarmVectorEnv(num_envs=0)
    env = SwarmVectorEnv(num_envs=2, scenario=SCEN)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"actions have shape \(4, 2\)"):
        env.step(np.zeros((4, 2)))
    with pytest.raises(ConfigError, match="seed"):
        env.reset(seed=[1, 2, 3])


def test_envs_benchmark_runs():
    from benchmarks import envs_bench

    rows = envs_bench.run(0.005, 1, lambda msg: None, threads=(1,), bs=(1, 2))
    assert [(r["env"], r["B"]) for r in rows] == [("gymnasium vector", 1), ("gymnasium vector", 2),
                                                  ("pettingzoo parallel", 1), ("pettingzoo parallel", 2)]
    assert all(r["env_steps_per_s"] > 0 for r in rows)
    assert "| gymnasium vector | 10 | 2 |" in envs_bench.markdown(rows)
    assert "VMAS's own env: not measured" in envs_bench.markdown(rows)
    vmas = dict(N=10, B=64, env_steps_per_s=5000.0, copter_steps_per_s=50000.0, vmas="1.5.2", threads=2)
    assert "| VMAS 1.5.2 env, comparison scenario (section (a)) | 10 | 64 | 5,000 | 50,000 | 2 |" in \
        envs_bench.markdown(rows, [vmas])
