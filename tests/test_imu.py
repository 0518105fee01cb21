"""Inertial sensor (finkensim.sensors.imu): kernel vs NumPy reference, noise statistics, body frame,
batch-size independence.

Statistical tests use a fixed seed (so they are deterministic) *and* sample sizes for which a correct
model would fail with negligible probability under any seed; each tolerance is derived where it is used.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.config import ConfigError, ImuConfig
from finkensim.sensors.imu import ImuModel, ImuState, ideal_imu, imu_from_trajectory, imu_step
from tests.naive.imu import ideal_ref, imu_step_ref, imu_trajectory_ref, turn_on_ref
from tests.stats import assert_mean_within_se, assert_within_se


class _Traj:
    """Minimal stand-in for world.Trajectory (the fields the IMU reads)."""

    def __init__(self, acc, yaw, yaw_rate):
        self.acc = acc
        self.pose = np.concatenate([np.zeros(acc.shape), yaw[..., None]], axis=-1)
        self.yaw_rate = yaw_rate


def _motion(rng, T, B, N):
    acc = rng.normal(0.0, 1.5, (T, B, N, 2))
    yaw = rng.uniform(-np.pi, np.pi, (T, B, N))
    yaw_rate = rng.normal(0.0, 1.0, (T, B, N))
    return acc, yaw, yaw_rate


DENS = dict(acc_density=0.05, acc_walk_density=0.2, gyro_density=0.01, gyro_walk_density=0.03, dt=0.04)


def _model(d=DENS):
    return ImuModel.from_densities(d["acc_density"], d["acc_walk_density"], d["gyro_density"],
                                   d["gyro_walk_density"], d["dt"])


def test_from_config_discretisation():
    cfg = ImuConfig()
    m = ImuModel.from_config(cfg, 0.05)
    assert m.acc_sigma == pytest.approx(cfg.acc_noise_density / np.sqrt(0.05), rel=1e-15)
    assert m.gyro_sigma == pytest.approx(cfg.gyro_noise_density / np.sqrt(0.05), rel=1e-15)
    assert m.acc_walk == pytest.approx(cfg.acc_bias_walk * np.sqrt(0.05), rel=1e-15)
    assert m.gyro_walk == pytest.approx(cfg.gyro_bias_walk * np.sqrt(0.05), rel=1e-15)
    assert m.dt == 0.05
    with pytest.raises(ConfigError, match="dt"):
        ImuModel.from_config(cfg, 0.0)


def test_kernel_matches_reference():
    rng = np.random.default_rng(1)
    T, B, N = 6, 3, 4
    acc, yaw, yaw_rate = _motion(rng, T, B, N)
    env_ids = np.array([7, 0, 123456789])
    seed, step0 = 2**40 + 3, 11
    params = _model()
    state = ImuState.turn_on(N, seed, env_ids, step=step0, acc_spread=0.1, gyro_spread=0.02)
    b0 = turn_on_ref(N, seed, env_ids, step0, 0.1, 0.02)
    np.testing.assert_allclose(state.bias, b0, rtol=0, atol=1e-15)
    ref_acc, ref_gyro, ref_bias = imu_trajectory_ref(acc, yaw, yaw_rate, b0, seed=seed, env_ids=env_ids,
                                                     step0=step0, **DENS)
    # batched step, one call per sample
    st_ = state.copy()
    for t in range(T):
        a, g = imu_step(acc[t], yaw[t], yaw_rate[t], st_, params, seed, env_ids, step0 + t)
        np.testing.assert_allclose(a, ref_acc[t], rtol=0, atol=1e-12)
        np.testing.assert_allclose(g, ref_gyro[t], rtol=0, atol=1e-12)
    np.testing.assert_allclose(st_.bias, ref_bias, rtol=0, atol=1e-12)
    # whole trajectory
    st2 = state.copy()
    ta, tg = imu_from_trajectory(_Traj(acc, yaw, yaw_rate), params, seed, env_ids, step0, bias=st2)
    np.testing.assert_allclose(ta, ref_acc, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tg, ref_gyro, rtol=0, atol=1e-12)
    np.testing.assert_allclose(st2.bias, ref_bias, rtol=0, atol=1e-12)


def test_trajectory_equals_repeated_steps_exactly():
    rng = np.random.default_rng(2)
    T, B, N = 5, 4, 3
    acc, yaw, yaw_rate = _motion(rng, T, B, N)
    env_ids = np.arange(10, 10 + B)
    params = _model()
    bias = np.zeros((B, N, 3))
    ta, tg = imu_from_trajectory(_Traj(acc, yaw, yaw_rate), params, 9, env_ids, 100)
    for t in range(T):
        a, g = imu_step(acc[t], yaw[t], yaw_rate[t], bias, params, 9, env_ids, 100 + t)
        np.testing.assert_array_equal(a, ta[t])
        np.testing.assert_array_equal(g, tg[t])


def test_white_noise_variance_matches_density():
    """Residual (reading − ideal) / (density/√dt) must be iid N(0, 1) with the walk switched off.

    n = 250·8·50 = 100 000 samples per channel. Tolerances:
      * variance: S = Σz² ~ χ²_n. Chernoff: P(|S/n − 1| > ε) ≤ 2·exp(−n(ε − ln(1+ε))/2); with
        ε = 6·√(2/n) = 0.0268 the exponent is n·3.53e-4/2 = 17.6, so a false failure has probability
        < 5e-8 per channel (≈ 6σ of the normal approximation).
      * mean and correlations (between channels, lag 1 in time): each is an average of n terms with
        variance 1 (independent unit normals), std 1/√n; the 6/√n bound fails with probability ≈ 2e-9.
    """
    d = dict(acc_density=0.2, acc_walk_density=0.0, gyro_density=0.01, gyro_walk_density=0.0, dt=0.02)
    params = _model(d)
    rng = np.random.default_rng(3)
    T, B, N = 50, 250, 8
    acc, yaw, yaw_rate = _motion(rng, T, B, N)
    ia, ig = imu_from_trajectory(_Traj(acc, yaw, yaw_rate), params, 12345, np.arange(B), 0)
    ideal_a, ideal_g = ideal_imu(acc, yaw, yaw_rate)
    z = np.concatenate([(ia - ideal_a) / params.acc_sigma, ((ig - ideal_g) / params.gyro_sigma)[..., None]], -1)
    assert params.acc_sigma == pytest.approx(0.2 / np.sqrt(0.02))
    n = T * B * N
    flat = z.reshape(n, 3)
    # 6 SE (docstring): the variance bound 6·√(2/n) is 2.7 % of 1, so a 1.4 % bias in the noise σ fails
    for c in range(3):
        assert_mean_within_se(flat[:, c], 0.0, n_se=6, se=1 / np.sqrt(n), what=f"mean of z, channel {c}")
        assert_mean_within_se(flat[:, c] ** 2, 1.0, n_se=6, se=np.sqrt(2 / n), what=f"variance of z, channel {c}")
    for c1, c2 in ((0, 1), (0, 2), (1, 2)):
        assert_mean_within_se(flat[:, c1] * flat[:, c2], 0.0, n_se=6, se=1 / np.sqrt(n),
                              what=f"correlation of z, channels {c1} and {c2}")
    for c in range(3):  # n·(T−1)/T lag-1 products
        assert_mean_within_se(z[1:, ..., c] * z[:-1, ..., c], 0.0, n_se=6, se=1 / np.sqrt(n * (T - 1) / T),
                              what=f"lag-1 autocorrelation of z, channel {c}")


def test_bias_random_walk_growth():
    """With white noise off and no motion, reading k is the bias b_k; Var(b_k) = walk²·dt·k.

    M = 500·40 = 20 000 independent copters. With known mean 0, Σ b_k² / (walk²·dt·k) ~ χ²_M, so the
    ratio to M has std √(2/M) = 0.01; tolerance ε = 6·√(2/M) = 0.06, for which the Chernoff bound
    2·exp(−M(ε − ln(1+ε))/2) = 2·exp(−17.3) < 1e-7 per (k, channel). The increment b_100 − b_25 must be
    uncorrelated with b_25 (independent increments): sample correlation of M pairs, std 1/√M, tol 6/√M.
    """
    d = dict(acc_density=0.0, acc_walk_density=0.3, gyro_density=0.0, gyro_walk_density=0.05, dt=0.05)
    params = _model(d)
    T, B, N = 101, 500, 40
    zeros = np.zeros((T, B, N, 2))
    yaw = np.full((T, B, N), 0.7)  # rotation must not touch the bias
    ia, ig = imu_from_trajectory(_Traj(zeros, yaw, np.zeros((T, B, N))), params, 777, np.arange(B) * 3 + 1, 40)
    b = np.concatenate([ia, ig[..., None]], -1).reshape(T, B * N, 3)  # (T, M, 3)
    M = B * N
    walk = np.array([0.3, 0.3, 0.05])
    np.testing.assert_array_equal(b[0], 0.0)
    # 6 SE (docstring): the ratio's bound 6·√(2/M) = 0.06 is 6 % of 1, so a 3 % bias in the walk density fails
    for k in (1, 5, 25, 100):
        for c in range(3):
            assert_mean_within_se(b[k, :, c] ** 2 / (walk[c] ** 2 * d["dt"] * k), 1.0, n_se=6, se=np.sqrt(2 / M),
                                  what=f"Var(b_{k}) / (walk²·dt·k), channel {c}")
    inc = b[100] - b[25]
    corr = np.mean(inc * b[25], axis=0) / np.sqrt(np.mean(inc**2, axis=0) * np.mean(b[25] ** 2, axis=0))
    for c in range(3):
        assert_within_se(corr[c], 0.0, 1 / np.sqrt(M), n_se=6,
                         what=f"correlation of b_100 − b_25 with b_25, channel {c}")


@pytest.mark.parametrize("yaw,acc,expected", [
    (np.pi / 2, (0.0, 1.5), (1.5, 0.0)),    # yawed 90°, accelerating along world +y → body +x (forward)
    (0.0, (0.3, -0.2), (0.3, -0.2)),         # body = world
    (np.pi, (1.0, 0.0), (-1.0, 0.0)),        # facing −x: world +x is backwards
    (-np.pi / 2, (2.0, 0.0), (0.0, 2.0)),    # facing −y: world +x is to the left (body +y)
])
def test_body_frame_rotation(yaw, acc, expected):
    a = np.array(acc, float).reshape(1, 1, 2)
    y = np.full((1, 1), yaw)
    w = np.full((1, 1), 0.4)
    ideal_a, ideal_g = ideal_imu(a, y, w)
    np.testing.assert_allclose(ideal_a[0, 0], expected, atol=1e-15)
    meas_a, meas_g = imu_step(a, y, w, np.zeros((1, 1, 3)), ImuModel.from_densities(0, 0, 0, 0, 0.05), 0,
                              [0], 0)
    np.testing.assert_allclose(meas_a[0, 0], expected, atol=1e-15)
    assert meas_g[0, 0] == 0.4


def test_world_copter_yawed_90_accelerating_along_y_reads_forward():
    from finkensim.world import World

    world = World({"copters": {"n": 1}})
    s = world.init(n_envs=1, positions=[[[1.5, 1.0]]], yaw=[[np.pi / 2]])
    s = world.step(s, cmd_vel=[[[0.0, 0.5]]])
    assert s.acc[0, 0, 1] > 0.1 and s.acc[0, 0, 0] == 0.0
    a, g = imu_step(s.acc, s.yaw, s.yaw_rate, np.zeros((1, 1, 3)), ImuModel.from_densities(0, 0, 0, 0, world.dt),
                    s.seed, s.env_ids, s.step)
    np.testing.assert_allclose(a[0, 0], [s.acc[0, 0, 1], 0.0], atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.floats(-10, 10), st.floats(-20, 20), st.floats(-20, 20))
def test_ideal_matches_rotation_matrix_and_preserves_norm(yaw, ax, ay):
    a = np.array([[[ax, ay]]])
    y = np.array([[yaw]])
    got, _ = ideal_imu(a, y, y)
    ref, _ = ideal_ref(a, y, y)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
    assert np.hypot(*got[0, 0]) == pytest.approx(np.hypot(ax, ay), rel=1e-12, abs=1e-12)


def test_zero_densities_read_ideal():
    cfg = ImuConfig(acc_noise_density=0.0, acc_bias_walk=0.0, gyro_noise_density=0.0, gyro_bias_walk=0.0)
    params = ImuModel.from_config(cfg, 0.05)
    rng = np.random.default_rng(4)
    T, B, N = 7, 5, 6
    acc, yaw, yaw_rate = _motion(rng, T, B, N)
    bias = np.zeros((B, N, 3))
    ia, ig = imu_from_trajectory(_Traj(acc, yaw, yaw_rate), params, 3, np.arange(B), 0, bias=bias)
    ideal_a, ideal_g = ideal_imu(acc, yaw, yaw_rate)
    np.testing.assert_array_equal(ia, ideal_a)
    np.testing.assert_array_equal(ig, ideal_g)
    np.testing.assert_array_equal(bias, 0.0)


def test_batch_size_independence():
    rng = np.random.default_rng(5)
    T, B, N = 4, 64, 5
    acc, yaw, yaw_rate = _motion(rng, T, B, N)
    params = _model()
    seed, step0 = 31, 1000
    env_ids = np.arange(B) + 500
    state = ImuState.turn_on(N, seed, env_ids, step=step0, acc_spread=0.05, gyro_spread=0.01)
    big_bias = state.bias.copy()
    big = [imu_step(acc[t], yaw[t], yaw_rate[t], big_bias, params, seed, env_ids, step0 + t) for t in range(T)]
    big_traj = imu_from_trajectory(_Traj(acc, yaw, yaw_rate), params, seed, env_ids, step0)
    for b in (0, 17, 63):
        one = ImuState.turn_on(N, seed, env_ids[b:b + 1], step=step0, acc_spread=0.05, gyro_spread=0.01)
        np.testing.assert_array_equal(one.bias[0], state.bias[b])
        for t in range(T):
            a, g = imu_step(acc[t, b:b + 1], yaw[t, b:b + 1], yaw_rate[t, b:b + 1], one, params, seed,
                            env_ids[b:b + 1], step0 + t)
            np.testing.assert_array_equal(a[0], big[t][0][b])
            np.testing.assert_array_equal(g[0], big[t][1][b])
        np.testing.assert_array_equal(one.bias[0], big_bias[b])
        sl = slice(b, b + 1)
        ta, tg = imu_from_trajectory(_Traj(acc[:, sl], yaw[:, sl], yaw_rate[:, sl]), params, seed, env_ids[sl],
                                     step0)
        np.testing.assert_array_equal(ta[:, 0], big_traj[0][:, b])
        np.testing.assert_array_equal(tg[:, 0], big_traj[1][:, b])


def test_shape_errors_name_the_argument():
    params = _model()
    with pytest.raises(ConfigError, match="bias"):
        imu_step(np.zeros((2, 3, 2)), np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3, 2)), params, 0, [0, 1], 0)
    with pytest.raises(ConfigError, match="bias"):  # a float32 copy could not be updated in place
        imu_step(np.zeros((2, 3, 2)), np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3, 3), np.float32), params,
                 0, [0, 1], 0)
    with pytest.raises(ConfigError, match="env_ids"):
        imu_step(np.zeros((2, 3, 2)), np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3, 3)), params, 0, [0], 0)
    with pytest.raises(ConfigError, match="yaw_rate"):
        imu_step(np.zeros((2, 3, 2)), np.zeros((2, 3)), np.zeros((3, 2)), np.zeros((2, 3, 3)), params, 0, [0, 1], 0)


@settings(max_examples=40, deadline=None)
@given(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(-0.5, 0.5), st.integers(0, 2**31))
def test_constant_biases_match_reference(bx, by, bg, seed):
    """``imu.acc_bias`` / ``imu.gyro_bias`` (ImuModel's constant biases) add to every reading, as the NumPy reference."""
    rng = np.random.default_rng(seed)
    B, N = 2, 3
    acc, yaw, yaw_rate = (a[0] for a in _motion(rng, 1, B, N))
    env_ids = np.array([0, 5])
    bias0 = rng.normal(0.0, 0.1, (B, N, 3))
    params = _model()._replace(acc_bias_x=bx, acc_bias_y=by, gyro_bias=bg)
    a, g = imu_step(acc, yaw, yaw_rate, bias0.copy(), params, seed, env_ids, 4)
    ref_a, ref_g, _ = imu_step_ref(acc, yaw, yaw_rate, bias0, seed=seed, env_ids=env_ids, step=4,
                                   constant=(bx, by, bg), **DENS)
    np.testing.assert_allclose(a, ref_a, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g, ref_g, rtol=0, atol=1e-12)


def test_constant_biases_come_from_the_config():
    m = ImuModel.from_config(ImuConfig(acc_bias=(0.1, -0.2), gyro_bias=0.03), 0.05)
    assert (m.acc_bias_x, m.acc_bias_y, m.gyro_bias) == (0.1, -0.2, 0.03)
    assert ImuModel.from_config(ImuConfig(), 0.05)[5:8] == (0.0, 0.0, 0.0)
