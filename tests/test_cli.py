"""`finkensim run` end to end, its error handling, and the scenario it runs by default."""
from __future__ import annotations

import math

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import finkensim
from finkensim import flightlog
from finkensim.cli import main
from finkensim.config import Config, config_from_dict
from finkensim.scenario import DEFAULT_SCENARIO_TOML, default_scenario_path, load_scenario, simulate_flight
from tests.stats import assert_median_within_se, assert_std_within_se, se_std_normal

CONSOLE_SCRIPT = Path(sys.executable).parent / "finkensim"


def _stderr_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


# ------------------------------------------------------------------------------------------
# the default scenario
# ------------------------------------------------------------------------------------------

def test_shipped_scenario_file_matches_embedded_text():
    assert default_scenario_path().read_text() == DEFAULT_SCENARIO_TOML


def test_default_scenario_is_six_copters_random_walk_for_60_s():
    cfg = load_scenario()
    assert cfg.copters.n == 6
    assert cfg.behaviour.kind == "random_walk"
    assert cfg.simulation.duration == 60.0
    assert cfg == load_scenario(default_scenario_path())


def test_simulate_flight_log_contents():
    log, traj, world = simulate_flight(None, duration=2.0, seed=7)
    n_steps = int(round(2.0 / world.dt))
    assert log.t.shape == (n_steps + 1,)
    assert log.t[0] == 0.0 and log.t[-1] == pytest.approx(2.0)
    assert log.pose.shape == (n_steps + 1, 6, 3)
    np.testing.assert_array_equal(log.pose, traj.pose[:, 0])
    assert list(log.copter_ids) == [f"copter{i}" for i in range(6)]
    np.testing.assert_array_equal(log.arena, [3.0, 4.0])
    assert log.meta["copter_radius"] == 0.15 and log.meta["altitude"] == 0.6
    assert log.meta["source"] == f"finkensim {finkensim.__version__}"
    rebuilt = config_from_dict(log.meta["config"])
    assert rebuilt == world.cfg
    assert rebuilt.simulation.duration == 2.0 and rebuilt.simulation.seed == 7
    assert log.extras["wall_theta"].shape == (n_steps + 1, world.arena.n_plates)
    flightlog.validate(log)


def test_simulate_flight_is_reproducible_and_seeded():
    a, _, _ = simulate_flight(None, duration=1.0, seed=3)
    b, _, _ = simulate_flight(None, duration=1.0, seed=3)
    c, _, _ = simulate_flight(None, duration=1.0, seed=4)
    assert a == b
    assert not np.array_equal(a.pose, c.pose)


def test_simulate_flight_runs_one_environment_whatever_n_envs():
    cfg = Config().replace({"simulation.n_envs": 5, "copters.n": 3, "behaviour.kind": "hover"})
    log, traj, world = simulate_flight(cfg, duration=0.5)
    assert traj.pose.shape[1] == 1
    assert log.pose.shape[1] == 3
    np.testing.assert_allclose(log.pose[-1], log.pose[0])  # hovering copters stay put


# ------------------------------------------------------------------------------------------
# finkensim run
# ------------------------------------------------------------------------------------------

def test_run_writes_valid_log_pictures_and_gif(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "--out", str(out), "--duration", "3", "--seed", "5"]) == 0
    stdout = capsys.readouterr().out
    for name in ("flight.npz", "arena.png", "wall_response.png", "sensors.png", "flight.gif"):
        assert (out / name).is_file(), name
        assert str(out / name) in stdout

    log = flightlog.load(out / "flight.npz")
    flightlog.validate(log)
    assert log.t[-1] == pytest.approx(3.0)
    assert log.pose.shape == (61, 6, 3)
    assert log.meta["config"]["simulation"]["seed"] == 5

    # sensor blocks and, by default, their error-free values
    T, N = 61, 6
    assert log.ultrasonic.shape == (T, N, 4) and log.ultrasonic_yaw.shape == (4,)
    assert log.ranging.shape == (T, N, N)
    assert log.imu_acc.shape == (T, N, 2) and log.imu_gyro.shape == (T, N)
    expected_extras = {"ultrasonic_ideal": (T, N, 4), "ultrasonic_hit_type": (T, N, 4), "ultrasonic_down": (T, N),
                       "ranging_ideal": (T, N, N), "imu_acc_ideal": (T, N, 2), "imu_gyro_ideal": (T, N)}
    for name, shape in expected_extras.items():
        assert name in log.extras, name
        assert log.extras[name].shape == shape, name
        assert np.all(np.isfinite(log.extras[name])), name
    assert np.all((log.ultrasonic >= 0.2) & (log.ultrasonic <= 3.0))
    np.testing.assert_array_equal(np.diagonal(log.ranging, axis1=1, axis2=2), 0.0)
    # the ideal values are the noise-free truth the readings scatter around
    # gyro error at step k = bias_k + white noise: Var = σ² + k·walk² (bias starts at 0), σ = density/√dt
    imu, dt = log.meta["config"]["imu"], log.meta["config"]["simulation"]["dt"]
    err = (log.imu_gyro - log.extras["imu_gyro_ideal"]).ravel()
    want = math.sqrt(imu["gyro_noise_density"] ** 2 / dt + imu["gyro_bias_walk"] ** 2 * dt * (T - 1) / 2)
    # 5 SE of a sample std of n = 366 normal values, σ/√(2(n−1)): ≈ 18.5 % of σ — this end-to-end run only detects
    # a gross error in the noise scale; tests/test_imu.py bounds it within 1.4 % (the walk part, 4e-5 of the
    # variance here, leaves the errors practically independent)
    assert_std_within_se(err, want, se=se_std_normal(want, err.size), ddof=0, what="gyro error std in the log")
    # in-range ranging errors: their median |reading − ideal| against the model's own, computed from 50 draws of the
    # ranging model at every logged ideal distance; SE of the log's median by bootstrap (≈ 0.003 m for ≤ 1 830
    # readings; 5 SE ≈ 0.015 m, ≈ 13 % of the ≈ 0.11 m median: again only a gross error, tests/test_ranging.py is tight)
    from finkensim.sensors.ranging import RangingModel

    ideal = log.extras["ranging_ideal"]
    in_range = (ideal > 0) & (ideal < log.meta["config"]["ranging"]["max_range"])
    abs_err = np.abs(log.ranging - ideal)
    assert np.median(abs_err) < 0.3
    x = ideal[in_range]
    model = RangingModel.from_config(config_from_dict(log.meta["config"]).ranging)
    want_med = np.median(np.abs(model.sample(np.tile(x, 50), seed=99) - np.tile(x, 50)))
    assert_median_within_se(abs_err[in_range], want_med, what="median |ranging reading − ideal| in the log")

    for name in ("arena.png", "wall_response.png", "sensors.png"):
        with Image.open(out / name) as im:
            assert im.format == "PNG" and min(im.size) > 300
    with Image.open(out / "flight.gif") as im:
        assert im.format == "GIF"
        assert 2 <= im.n_frames <= 150


def test_run_no_ideal_leaves_out_ideal_values_but_draws_sensors(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "--out", str(out), "--duration", "1", "--seed", "2", "--no-gif", "--no-ideal"]) == 0
    log = flightlog.load(out / "flight.npz")
    assert log.ultrasonic is not None and log.ranging is not None and log.imu_acc is not None
    assert not any(name.endswith("_ideal") for name in log.extras)
    assert "ultrasonic_hit_type" not in log.extras
    with Image.open(out / "sensors.png") as im:
        assert im.format == "PNG" and min(im.size) > 300
    # --ideal is accepted (and is the default)
    assert main(["run", "--out", str(tmp_path / "o2"), "--duration", "0.5", "--no-gif", "--ideal"]) == 0
    assert "ranging_ideal" in flightlog.load(tmp_path / "o2" / "flight.npz").extras


def test_run_without_sensors_skips_sensor_picture(tmp_path):
    scenario = tmp_path / "s.toml"
    scenario.write_text("[sonar]\nenabled = false\n\n[ranging]\nenabled = false\n\n[imu]\nenabled = false\n")
    out = tmp_path / "o"
    assert main(["run", str(scenario), "--out", str(out), "--duration", "0.5", "--no-gif"]) == 0
    assert (out / "flight.npz").is_file() and not (out / "sensors.png").exists()


def test_plot_sensors_skips_missing_blocks():
    import dataclasses

    import matplotlib.pyplot as plt

    from finkensim import viz
    from finkensim.analysis import sonar_crosstalk_events

    log, _, _ = simulate_flight(None, duration=1.0, seed=3, ideal=True)

    def without(**blocks):
        fields = {f.name: getattr(log, f.name) for f in dataclasses.fields(log)}
        fields.update(blocks)
        return flightlog.FlightLog(**fields)

    no_sonar = dict(ultrasonic=None, ultrasonic_yaw=None, ultrasonic_offset=None)
    no_imu = dict(imu_acc=None, imu_gyro=None)
    cases = [
        (log, {"sonar", "ranging", "acc", "gyro", "acc_error", "gyro_error"}),
        (without(extras={"wall_theta": log.extras["wall_theta"]}), {"sonar", "ranging", "acc", "gyro"}),
        (without(**no_sonar, ranging=None), {"acc", "gyro", "acc_error", "gyro_error"}),
        (without(**no_imu, ranging=None), {"sonar"}),
        (without(**no_sonar, **no_imu), {"ranging"}),
    ]
    for case, panels in cases:
        fig, axes = viz.plot_sensors(case, copter=1)
        assert set(axes) == panels
        plt.close(fig)
    events = sonar_crosstalk_events(log)
    assert events.shape == log.ultrasonic.shape and events.dtype == bool
    with pytest.raises(ValueError, match="no sensor blocks"):
        viz.plot_sensors(without(**no_sonar, **no_imu, ranging=None))
    with pytest.raises(ValueError, match="copter"):
        viz.plot_sensors(log, copter=6)


def test_run_user_scenario_and_no_gif(tmp_path):
    scenario = tmp_path / "s.toml"
    scenario.write_text('[copters]\nn = 3\n\n[behaviour]\nkind = "random_walk"\n\n[simulation]\nduration = 1.0\nseed = 2\n')
    out = tmp_path / "o"
    assert main(["run", str(scenario), "--out", str(out), "--no-gif"]) == 0
    assert not (out / "flight.gif").exists()
    log = flightlog.load(out / "flight.npz")
    assert log.pose.shape == (21, 3, 3)
    assert (out / "arena.png").is_file() and (out / "wall_response.png").is_file()
    assert (out / "sensors.png").is_file()


def test_bad_key_exits_2_naming_the_key(tmp_path, capsys):
    scenario = tmp_path / "bad.toml"
    scenario.write_text("[walls]\nn_segmentz = 12\n")
    assert main(["run", str(scenario), "--out", str(tmp_path / "o")]) == 2
    line = _stderr_line(capsys)
    assert "walls.n_segmentz" in line and "n_segments" in line
    assert not (tmp_path / "o" / "flight.npz").exists()


def test_bad_value_exits_2_naming_the_key(tmp_path, capsys):
    scenario = tmp_path / "bad.toml"
    scenario.write_text("[walls]\nthreshold = -1.0\n")
    assert main(["run", str(scenario), "--out", str(tmp_path / "o")]) == 2
    assert "walls.threshold" in _stderr_line(capsys)


def test_bad_toml_exits_2(tmp_path, capsys):
    scenario = tmp_path / "broken.toml"
    scenario.write_text("[walls\nthreshold = 1\n")
    assert main(["run", str(scenario), "--out", str(tmp_path / "o")]) == 2
    line = _stderr_line(capsys)
    assert "TOML" in line and "broken.toml" in line


def test_missing_file_exits_2(tmp_path, capsys):
    missing = tmp_path / "nope.toml"
    assert main(["run", str(missing), "--out", str(tmp_path / "o")]) == 2
    line = _stderr_line(capsys)
    assert "nope.toml" in line and "does not exist" in line


@pytest.mark.parametrize("argv, needle", [
    (["run", "--bogus"], "--bogus"),
    (["run", "--duration", "abc"], "--duration"),
    (["run", "--duration", "-1"], "simulation.duration"),
    (["run", "--duration", "0.001"], "simulation.duration"),
    (["run", "--seed", "-3"], "simulation.seed"),
    (["frobnicate"], "frobnicate"),
    ([], "command"),
])
def test_usage_errors_exit_2_with_one_line(argv, needle, tmp_path, capsys):
    if argv[:1] == ["run"]:
        argv = argv + ["--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert needle in _stderr_line(capsys)


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"finkensim {finkensim.__version__}"


@pytest.mark.skipif(not CONSOLE_SCRIPT.exists(), reason="console script not installed in this environment")
def test_console_script(tmp_path):
    env = {**os.environ, "MPLBACKEND": "Agg"}
    ok = subprocess.run([str(CONSOLE_SCRIPT), "run", "--duration", "1", "--no-gif", "--out", str(tmp_path / "o")],
                        capture_output=True, text=True, env=env, timeout=300)
    assert ok.returncode == 0, ok.stderr
    assert (tmp_path / "o" / "flight.npz").is_file()

    bad = subprocess.run([str(CONSOLE_SCRIPT), "run", str(tmp_path / "missing.toml")],
                         capture_output=True, text=True, env=env, timeout=300)
    assert bad.returncode == 2
    assert "Traceback" not in bad.stderr
    assert bad.stderr.strip().count("\n") == 0 and "missing.toml" in bad.stderr


def test_a_reader_that_goes_away_ends_the_command_quietly(monkeypatch, capsys):
    import io
    import sys

    from finkensim.cli import EXIT_BROKEN_PIPE

    class ClosedPipe(io.StringIO):
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

    from finkensim import cli

    def prints(args):
        print("a line nobody reads")
        return 0

    monkeypatch.setattr(cli, "cmd_run", prints)  # what `finkensim run ... | head -0` meets, without the flight
    monkeypatch.setattr(sys, "stdout", ClosedPipe())
    assert main(["run"]) == EXIT_BROKEN_PIPE
    assert "Traceback" not in capsys.readouterr().err


@pytest.mark.parametrize("extra,named", [(["--duration", "inf"], "--duration inf"), (["--duration", "nan"], "--duration nan"),
                                         (["--seed", "-1"], "--seed -1"), (["--trials", "0"], "--trials 0"),
                                         (["--out", ""], "--out ''"), (["--out", "/proc/x/y"], "/proc/x/y")])
def test_gap_validate_rejects_bad_arguments_by_name(extra, named, capsys):
    assert main(["gap-validate", "--cases", "null", *extra]) == 2
    err = capsys.readouterr().err
    assert named in err and "Traceback" not in err


def test_out_naming_a_file_is_a_usage_error(tmp_path, capsys):
    f = tmp_path / "a_file"
    f.write_text("x")
    assert main(["gap-validate", "--cases", "null", "--out", str(f)]) == 2
    assert "is a file: expected a directory" in capsys.readouterr().err
    assert f.read_text() == "x"
