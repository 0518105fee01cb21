"""Config keys of the sensor parameters the gap diagnosis fits (sonar range scale, bias, cross-talk hearing; IMU
constant biases): the simulator flies them, with neutral defaults."""
import numpy as np
import pytest

import finkensim as fs
from finkensim.config import ConfigError
from finkensim.sensors.sonar_model import SonarModel

NO_ERRORS = {"sonar.error": "none", "sonar.crosstalk": "off", "walls.bending": False, "ranging.enabled": False,
             "imu.enabled": False}


def _fly(updates, n_steps=40):
    cfg = fs.load_config().replace({**NO_ERRORS, **updates})
    sim = fs.SwarmSim(cfg)
    _, rec = sim.rollout(sim.init(n_envs=2, seed=4), n_steps=n_steps, record=("sonar", "sonar_ideal", "pose"))
    return cfg, rec


def test_sonar_keys_reach_the_model():
    cfg = fs.load_config().replace({"sonar.range_scale": 1.07, "sonar.bias": -0.04,
                                    "sonar.crosstalk_hear_probability": 0.6})
    sp = SonarModel.from_config(cfg)
    assert (sp.range_scale, sp.bias, sp.crosstalk_hear_probability) == (1.07, -0.04, 0.6)
    default = SonarModel.from_config(fs.load_config())
    assert (default.range_scale, default.bias, default.crosstalk_hear_probability) == (1.0, 0.0, 1.0)


def test_the_simulator_flies_sonar_range_scale_and_bias():
    """Without errors an echo reads clip(range_scale · distance + bias, min_range, max_range); no echo reads
    max_range, as without the keys. Poses are unchanged (the sonar does not steer a random walk)."""
    _, plain = _fly({})
    cfg, scaled = _fly({"sonar.range_scale": 1.1, "sonar.bias": 0.05})
    np.testing.assert_array_equal(plain.pose, scaled.pose)
    ideal = plain.sonar_ideal
    echo = ideal < cfg.sonar.max_range
    assert echo.sum() > 100
    want = np.clip(1.1 * ideal + 0.05, cfg.sonar.min_range, cfg.sonar.max_range)
    np.testing.assert_allclose(scaled.sonar[echo], want[echo], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(scaled.sonar[~echo], plain.sonar[~echo])


@pytest.mark.parametrize("key, value, match", [
    ("sonar.range_scale", 0.1, r"sonar\.range_scale = 0\.1"),
    ("sonar.bias", 2.0, r"sonar\.bias = 2\.0"),
    ("sonar.crosstalk_hear_probability", 1.5, r"sonar\.crosstalk_hear_probability = 1\.5"),
    ("imu.acc_bias", [0.1], r"imu\.acc_bias"),
    ("imu.gyro_bias", "x", r"imu\.gyro_bias"),
])
def test_bad_values_get_named_errors(key, value, match):
    with pytest.raises(ConfigError, match=match):
        fs.load_config().replace({key: value})


def test_the_gap_effect_imu_bias_changes_the_simulators_imu_record():
    from finkensim.gap.attribute.effects import REGISTRY
    from finkensim.gap.model.params import ModelParams

    base = ModelParams.from_config(fs.load_config().replace({"imu.gyro_bias": 0.01}))
    fitted = REGISTRY["imu_bias"].apply(base, {"acc_x": 0.1, "acc_y": -0.2, "gyro": 0.02})
    assert (fitted.imu.acc_bias_x, fitted.imu.acc_bias_y) == (0.1, -0.2)
    assert fitted.imu.gyro_bias == pytest.approx(0.03, abs=1e-15)


def test_the_log_writer_adds_tracking_noise_through_the_tracking_model():
    """``log.tracking_sigma_*``: the logged poses are the true ones plus σ·z with the normals of the tracking
    stream (:func:`finkensim.sensors.tracking.tracked_poses`), meta states σ; the sensors are unchanged."""
    from finkensim.scenario import simulate_flight
    from finkensim.sensors.tracking import tracked_poses

    plain, _, _ = simulate_flight(fs.load_config(), duration=3.0, seed=2)
    cfg = fs.load_config().replace({"log.tracking_sigma_xy": 0.01, "log.tracking_sigma_yaw": 0.02})
    noisy, _, _ = simulate_flight(cfg, duration=3.0, seed=2, ideal=True)
    np.testing.assert_array_equal(noisy.ultrasonic, plain.ultrasonic)
    np.testing.assert_array_equal(noisy.extras["pose_true"], plain.pose)
    assert (noisy.meta["tracking_sigma_xy"], noisy.meta["tracking_sigma_yaw"]) == (0.01, 0.02)
    assert plain.meta["tracking_sigma_xy"] == 0.0
    err = noisy.pose - plain.pose
    err[..., 2] = np.angle(np.exp(1j * err[..., 2]))
    inside = (plain.pose[..., 0] > 0.05) & (plain.pose[..., 0] < 2.95) & (plain.pose[..., 1] > 0.05) \
        & (plain.pose[..., 1] < 3.95)
    pos, yaw = np.ascontiguousarray(plain.pose[..., :2]), np.ascontiguousarray(plain.pose[..., 2])
    want_pos, want_yaw = np.empty_like(pos), np.empty_like(yaw)
    tracked_poses(pos, yaw, 0.01, 0.02, 2, 0, want_pos, want_yaw)
    np.testing.assert_allclose(noisy.pose[..., :2][inside], want_pos[inside], rtol=0, atol=1e-12)
    # the noise is N(0, σ²): 3 s × 21 Hz × 6 copters = 366 samples, the sample sd within 15 % (≈ 4 standard errors)
    assert np.std(err[..., 0][inside]) == pytest.approx(0.01, rel=0.15)
    assert np.std(err[..., 2]) == pytest.approx(0.02, rel=0.15)
