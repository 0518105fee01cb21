"""simulate_flight / `finkensim run` with the closed-loop attraction-repulsion behaviour (finkensim.swarm)."""
from __future__ import annotations

import numpy as np
import pytest

from finkensim import flightlog
from finkensim.cli import main
from finkensim.config import ConfigError, config_from_dict
from finkensim.scenario import load_scenario, simulate_flight
from finkensim.sensors.imu import ImuModel, ideal_imu, imu_from_trajectory
from finkensim.sensors.ranging import RangingModel, ranging_readings
from finkensim.sensors.sonar import SonarModel, sonar_from_trajectory
from finkensim.swarm import SwarmSim

DURATION = 3.0  # s: 61 samples
SEED = 5


@pytest.fixture(scope="module")
def ar_cfg():
    return load_scenario().replace({"behaviour.kind": "attraction_repulsion", "behaviour.wall_check": "sequence",
                                    "copters.n": 4})


@pytest.fixture(scope="module")
def flight(ar_cfg):
    return simulate_flight(ar_cfg, duration=DURATION, seed=SEED, ideal=True)


def test_attraction_repulsion_flight_is_the_closed_loop(ar_cfg, flight):
    log, traj, world = flight
    T = int(round(DURATION / ar_cfg.simulation.dt)) + 1
    assert log.pose.shape == (T, 4, 3) and traj.pose.shape == (T, 1, 4, 3)
    assert log.meta["behaviour"] == "attraction_repulsion"
    assert config_from_dict(log.meta["config"]) == ar_cfg.replace({"simulation.duration": DURATION,
                                                                    "simulation.seed": SEED})
    flightlog.validate(log)
    # the same flight as SwarmSim's compiled rollout of one environment with this seed
    sim = SwarmSim(ar_cfg)
    _, rec = sim.rollout(sim.init(n_envs=1, seed=SEED), T)
    np.testing.assert_array_equal(log.pose, rec.pose[:, 0])
    np.testing.assert_array_equal(log.extras["wall_theta"], rec.theta[:, 0])
    # the log's sensors are the readings the behaviour acted on, and its wall judgements
    np.testing.assert_array_equal(log.ultrasonic, rec.sonar[:, 0])
    np.testing.assert_array_equal(log.ranging, rec.ranging[:, 0])
    np.testing.assert_array_equal(log.imu_acc, rec.imu_acc[:, 0])
    np.testing.assert_array_equal(log.imu_gyro, rec.imu_gyro[:, 0])
    np.testing.assert_array_equal(log.extras["ultrasonic_down"], rec.sonar_down[:, 0])
    flags = log.extras["ultrasonic_wall_flag"]
    assert flags.dtype == np.int8 and flags.shape == (T, 4, 4)
    np.testing.assert_array_equal(flags.astype(bool), rec.wall[:, 0])
    # the copters move (not hovering), and the behaviour's commands are what the world stepped with
    assert np.abs(np.diff(log.pose[:, :, :2], axis=0)).max() > 0
    np.testing.assert_allclose(np.diff(traj.pose[:, 0, :, :2], axis=0) / world.dt, traj.vel[1:, 0], atol=1e-9)


def test_recorded_sensors_equal_the_sensor_models_along_the_trajectory(flight):
    """Sensor blocks recorded in the closed loop = the batched sensor functions replayed on the trajectory."""
    log, traj, world = flight
    cfg, env_ids = world.cfg, np.array([0])
    sonar, ideal, hit, _ = sonar_from_trajectory(traj, world.arena, SonarModel.from_config(cfg), SEED, env_ids, 0,
                                                      return_ideal=True)
    np.testing.assert_array_equal(log.ultrasonic, sonar[:, 0])
    np.testing.assert_array_equal(log.extras["ultrasonic_ideal"], ideal[:, 0])
    np.testing.assert_array_equal(log.extras["ultrasonic_hit_type"], hit[:, 0])
    model = RangingModel.from_config(cfg.ranging)
    rows = np.stack([ranging_readings(np.ascontiguousarray(traj.pose[k, :, :, :2]), np.zeros((0, 2)), SEED, env_ids,
                                      k, model)[0] for k in range(traj.pose.shape[0])])
    np.testing.assert_array_equal(log.ranging, rows)
    acc, gyro = imu_from_trajectory(traj, ImuModel.from_config(cfg.imu, world.dt), SEED, env_ids, 0)
    np.testing.assert_array_equal(log.imu_acc, acc[:, 0])
    np.testing.assert_array_equal(log.imu_gyro, gyro[:, 0])
    acc_i, gyro_i = ideal_imu(traj.acc, traj.pose[..., 2], traj.yaw_rate)
    np.testing.assert_array_equal(log.extras["imu_acc_ideal"], acc_i[:, 0])
    # the ideal values are there and the readings differ from them (error models are on)
    assert np.abs(log.ultrasonic - log.extras["ultrasonic_ideal"]).max() > 0


def test_open_loop_flights_have_no_wall_flags():
    log, _, _ = simulate_flight(load_scenario().replace({"copters.n": 3}), duration=1.0, seed=1, ideal=False)
    assert log.meta["behaviour"] == "random_walk" and "ultrasonic_wall_flag" not in log.extras


def test_attraction_repulsion_needs_its_sonars():
    cfg = load_scenario().replace({"behaviour.kind": "attraction_repulsion", "sonar.enabled": False})
    with pytest.raises(ConfigError, match="needs sonar.enabled = true"):
        simulate_flight(cfg, duration=1.0)


def test_cli_run_attraction_repulsion(tmp_path, capsys):
    scenario = tmp_path / "ar.toml"
    scenario.write_text('[copters]\nn = 3\n\n[behaviour]\nkind = "attraction_repulsion"\nwall_check = "per_reading"\n'
                        '\n[simulation]\nduration = 2.0\nseed = 4\n')
    out = tmp_path / "o"
    assert main(["run", str(scenario), "--out", str(out), "--no-gif"]) == 0
    assert "attraction_repulsion" in capsys.readouterr().out
    log = flightlog.load(out / "flight.npz")
    assert log.pose.shape == (41, 3, 3) and log.extras["ultrasonic_wall_flag"].shape == (41, 3, 4)
    want, _, _ = simulate_flight(scenario, ideal=True)  # `finkensim run` stores the ideal values by default
    assert log == want
    assert (out / "arena.png").is_file() and (out / "sensors.png").is_file()
